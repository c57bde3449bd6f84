//! The composite height field H of paper Sec. 4: the per-source fields H_s combined on one grid.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Grid, PodVec, Raster};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// How the sources are combined where several observed a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Combine {
    /// The first source, in list order, that observed the cell (list the most trusted first).
    Priority,
    /// The highest observed value.
    Max,
    /// The mean of the observed values.
    Mean,
}

/// Params of [`CompositeHeight`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompositeHeightParams {
    /// How overlapping observations combine. Default Priority.
    #[serde(default = "priority")]
    pub combine: Combine,
    /// Cell size of H, metres; default: the site's.
    #[serde(default)]
    pub cell_m: Option<f64>,
}

fn priority() -> Combine {
    Combine::Priority
}

/// Combines height fields H_s into H on a site-aligned grid covering all of them; each source is
/// read at the cell centres (nearest cell), ⊥ (NaN) where no source observed anything.
pub struct CompositeHeight;

impl Stage for CompositeHeight {
    const KIND: &'static str = "CompositeHeight";
    const VERSION: u32 = 1;
    const DOC: &'static str = "composite height field H from the per-source fields H_s, Sec. 4";
    const INPUTS: &'static [InputSpec] = &[InputSpec::many(
        "sources",
        ArtifactType::Raster,
        "the height fields H_s, most trusted first",
    )];
    type Params = CompositeHeightParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("m")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::params::check_cell(p.cell_m)?;
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let sources: Vec<&Raster> = inputs.many("sources")?;
        if sources.is_empty() {
            return Err(StageError::Param(ParamError::new(
                "sources",
                "expected at least one height field",
            )));
        }
        let cell = p.cell_m.unwrap_or(ctx.site.cell_m);
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for s in &sources {
            let g = s.grid;
            lo = (lo.0.min(g.x0), lo.1.min(g.y0 - g.height as f64 * g.cell_m));
            hi = (hi.0.max(g.x0 + g.width as f64 * g.cell_m), hi.1.max(g.y0));
        }
        // Cell centres strictly inside the union of the sources' extents.
        let grid = Grid::covering_checked(
            (lo.0 + cell * 0.5, lo.1 + cell * 0.5),
            (hi.0 - cell * 0.5, hi.1 - cell * 0.5),
            cell,
        )
        .map_err(|m| {
            StageError::Param(ParamError::new(
                "cell_m",
                format!("{m}; use a coarser cell"),
            ))
        })?;
        let w = grid.width as usize;
        let mut data = vec![f32::NAN; grid.len()];
        data.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
            for (col, z) in out.iter_mut().enumerate() {
                let (x, y) = grid.center(col as u32, row as u32);
                let values = sources
                    .iter()
                    .filter_map(|s| s.grid.cell_of(x, y).map(|(c, r)| s.at(c, r)))
                    .filter(|v| v.is_finite());
                *z = match p.combine {
                    Combine::Priority => values.into_iter().next().unwrap_or(f32::NAN),
                    Combine::Max => values.fold(f32::NAN, f32::max),
                    Combine::Mean => {
                        let (s, n) = values.fold((0.0f64, 0u32), |(s, n), v| (s + v as f64, n + 1));
                        if n == 0 {
                            f32::NAN
                        } else {
                            (s / n as f64) as f32
                        }
                    }
                };
            }
        });
        Ok(Raster {
            grid,
            data: PodVec(data),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Artifact;
    use crate::site::Site;
    use crate::stage::Slot;
    use std::sync::Arc;

    #[test]
    fn priority_max_and_mean_over_overlapping_sources() {
        let a = Raster {
            grid: Grid {
                x0: 0.0,
                y0: 2.0,
                cell_m: 1.0,
                width: 2,
                height: 2,
            },
            data: PodVec(vec![1.0, f32::NAN, 1.0, 1.0]),
        };
        let b = Raster {
            grid: Grid {
                x0: 1.0,
                y0: 2.0,
                cell_m: 1.0,
                width: 2,
                height: 2,
            },
            data: PodVec(vec![5.0, 5.0, 5.0, 5.0]),
        };
        let inputs = Inputs::new().with(
            "sources",
            Slot::Many(vec![
                Arc::new(Artifact::Raster(a)),
                Arc::new(Artifact::Raster(b)),
            ]),
        );
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        let run = |combine| {
            CompositeHeight::run(
                &CompositeHeightParams {
                    combine,
                    cell_m: None,
                },
                &inputs,
                &Ctx::new(&site, &[]),
            )
            .unwrap()
        };
        let h = run(Combine::Priority);
        assert_eq!(
            h.grid,
            Grid {
                x0: 0.0,
                y0: 2.0,
                cell_m: 1.0,
                width: 3,
                height: 2
            }
        );
        assert_eq!(h.data.0, vec![1.0, 5.0, 5.0, 1.0, 1.0, 5.0]);
        assert_eq!(run(Combine::Max).data.0, vec![1.0, 5.0, 5.0, 1.0, 5.0, 5.0]);
        assert_eq!(
            run(Combine::Mean).data.0,
            vec![1.0, 5.0, 5.0, 1.0, 3.0, 5.0]
        );
    }
}
