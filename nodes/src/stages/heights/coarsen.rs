//! Block aggregation of a raster onto a coarser grid: how the OSM baseline gets SRTM-like
//! (30 m) terrain from a fine one, and how any raster is brought to a coarser working cell.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Grid, PodVec, Raster};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// How the fine cells of one coarse cell combine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Aggregate {
    /// Their mean.
    Mean,
    /// Their minimum.
    Min,
    /// Their maximum.
    Max,
}

/// Params of [`Coarsen`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoarsenParams {
    /// The coarse cell, metres (at least the input's).
    pub cell_m: f64,
    /// How fine cells combine. Default `Mean`.
    #[serde(default = "mean")]
    pub mode: Aggregate,
}

fn mean() -> Aggregate {
    Aggregate::Mean
}

/// The raster on a grid of `cell_m` cells covering the same extent (anchored at its north-west
/// corner); each coarse cell combines the valid fine cells whose centres fall in it, NaN if none.
pub struct Coarsen;

impl Stage for Coarsen {
    const KIND: &'static str = "Coarsen";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "a raster block-aggregated (mean/min/max) onto a coarser grid, e.g. 30 m SRTM-like terrain";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "raster",
        ArtifactType::Raster,
        "the fine raster",
    )];
    type Params = CoarsenParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::SameAs("raster")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::params::check_cell(Some(p.cell_m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        let r: &Raster = inputs.one("raster")?;
        if p.cell_m < r.grid.cell_m {
            return Err(StageError::Failed(format!(
                "cell_m {} m is finer than the input's {} m cells",
                p.cell_m, r.grid.cell_m
            )));
        }
        Ok(coarsen(r, p.cell_m, p.mode))
    }
}

/// Block aggregation of `r` onto `cell_m` cells.
pub fn coarsen(r: &Raster, cell_m: f64, mode: Aggregate) -> Raster {
    let f = r.grid;
    let g = Grid {
        x0: f.x0,
        y0: f.y0,
        cell_m,
        width: ((f.width as f64 * f.cell_m / cell_m).ceil() as u32).max(1),
        height: ((f.height as f64 * f.cell_m / cell_m).ceil() as u32).max(1),
    };
    let mut acc = vec![(0.0f64, 0u32); g.len()];
    for row in 0..f.height {
        for col in 0..f.width {
            let v = r.at(col, row);
            if !v.is_finite() {
                continue;
            }
            let (x, y) = f.center(col, row);
            let Some((c, rr)) = g.cell_of(x, y) else {
                continue;
            };
            let a = &mut acc[(rr * g.width + c) as usize];
            let v = v as f64;
            a.0 = match (mode, a.1) {
                (_, 0) => v,
                (Aggregate::Mean, _) => a.0 + v,
                (Aggregate::Min, _) => a.0.min(v),
                (Aggregate::Max, _) => a.0.max(v),
            };
            a.1 += 1;
        }
    }
    let data = acc
        .into_iter()
        .map(|(v, n)| match (n, mode) {
            (0, _) => f32::NAN,
            (_, Aggregate::Mean) => (v / n as f64) as f32,
            _ => v as f32,
        })
        .collect();
    Raster {
        grid: g,
        data: PodVec(data),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_combine_their_valid_cells() {
        let r = Raster {
            grid: Grid {
                x0: 0.0,
                y0: 3.0,
                cell_m: 1.0,
                width: 3,
                height: 3,
            },
            data: PodVec(vec![1.0, 2.0, 9.0, 3.0, f32::NAN, 9.0, 4.0, 4.0, 4.0]),
        };
        let m = coarsen(&r, 2.0, Aggregate::Mean);
        assert_eq!((m.grid.width, m.grid.height), (2, 2));
        assert_eq!(m.data.to_vec(), vec![2.0, 9.0, 4.0, 4.0]);
        assert_eq!(coarsen(&r, 2.0, Aggregate::Min).data[0], 1.0);
        assert_eq!(coarsen(&r, 2.0, Aggregate::Max).data[0], 3.0);
    }
}
