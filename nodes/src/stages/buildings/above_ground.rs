//! The above-ground field A = max(H - T, 0) (paper Sec. 4.1).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, Raster};
use crate::stage::{Ctx, InputSpec, Inputs, Stage, StageError, Unit};

/// [`AboveGround`] has no parameters.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AboveGroundParams {}

/// The above-ground field A = max(H - T, 0) on H's grid (paper Sec. 4.1); no-data where H is.
pub struct AboveGround;

impl Stage for AboveGround {
    const KIND: &'static str = "AboveGround";
    const VERSION: u32 = 1;
    const DOC: &'static str = "above-ground field A = max(H - T, 0), Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("surface", ArtifactType::Raster, "the height field H"),
        InputSpec::one("terrain", ArtifactType::Raster, "the terrain T"),
    ];
    type Params = AboveGroundParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("m")
    }

    fn run(_: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        let h: &Raster = inputs.one("surface")?;
        let t: &Raster = inputs.one("terrain")?;
        let g = h.grid;
        let data = (0..g.len())
            .into_par_iter()
            .map(|i| {
                let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
                let tz = t.bilinear(x, y).unwrap_or(f64::NAN);
                let a = h.data[i] as f64 - tz;
                // f64::max would turn a missing H or T into 0 ("on the ground"); keep it missing.
                if a.is_nan() {
                    f32::NAN
                } else {
                    a.max(0.0) as f32
                }
            })
            .collect();
        Ok(Raster {
            grid: g,
            data: PodVec(data),
        })
    }
}
