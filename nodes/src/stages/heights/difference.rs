//! The difference of two rasters: reconstruction error against a reference.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, Raster};
use crate::stage::{Ctx, InputSpec, Inputs, Stage, StageError, Unit};

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

    fn unit(_p: &Self::Params) -> Unit {
        Unit::SameAs("a")
    }

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
