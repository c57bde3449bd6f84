//! Clamping a raster's values into a range.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, Raster};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

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

    fn unit(_p: &Self::Params) -> Unit {
        Unit::SameAs("raster")
    }

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
