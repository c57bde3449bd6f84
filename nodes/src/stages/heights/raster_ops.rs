//! Cell-wise raster arithmetic, e.g. the above-ground field A = max(H - T, 0) of Sec. 4.1.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, Raster};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`Clamp`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClampParams {
    /// Lower bound; none if absent.
    #[serde(default)]
    pub min: Option<f64>,
    /// Upper bound; none if absent.
    #[serde(default)]
    pub max: Option<f64>,
}

/// Clamps every valid cell into `[min, max]`; no-data stays no-data.
pub struct Clamp;

impl Stage for Clamp {
    const KIND: &'static str = "Clamp";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "clamps raster values into [min, max], e.g. A = max(H - T, 0), Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "raster",
        ArtifactType::Raster,
        "the raster to clamp",
    )];
    type Params = ClampParams;
    type Output = Raster;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if let (Some(lo), Some(hi)) = (p.min, p.max)
            && lo > hi
        {
            return Err(ParamError::new(
                "max",
                format!("expected max >= min ({lo}), found {hi}"),
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        let r: &Raster = inputs.one("raster")?;
        let (lo, hi) = (
            p.min.unwrap_or(f64::NEG_INFINITY) as f32,
            p.max.unwrap_or(f64::INFINITY) as f32,
        );
        let data = r
            .data
            .par_iter()
            .map(|&v| if v.is_nan() { v } else { v.clamp(lo, hi) })
            .collect();
        Ok(Raster {
            grid: r.grid,
            data: PodVec(data),
        })
    }
}

/// [`Difference`] has no parameters.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DifferenceParams {}

/// `a - b` on the grid of `a`; `b` is sampled at `a`'s cell centres (nearest cell), so the two may
/// have different grids. No-data in either gives no-data.
pub struct Difference;

impl Stage for Difference {
    const KIND: &'static str = "Difference";
    const VERSION: u32 = 1;
    const DOC: &'static str = "cell-wise a - b on a's grid, e.g. H - T, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("a", ArtifactType::Raster, "minuend"),
        InputSpec::one(
            "b",
            ArtifactType::Raster,
            "subtrahend, resampled to a's grid",
        ),
    ];
    type Params = DifferenceParams;
    type Output = Raster;

    fn run(_: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        let a: &Raster = inputs.one("a")?;
        let b: &Raster = inputs.one("b")?;
        let g = a.grid;
        let w = g.width.max(1) as usize;
        let data = a
            .data
            .par_iter()
            .enumerate()
            .map(|(i, &va)| {
                let (col, row) = ((i % w) as u32, (i / w) as u32);
                let (x, y) = g.center(col, row);
                match b.grid.cell_of(x, y) {
                    Some((bc, br)) => va - b.at(bc, br),
                    None => f32::NAN,
                }
            })
            .collect();
        Ok(Raster {
            grid: g,
            data: PodVec(data),
        })
    }
}
