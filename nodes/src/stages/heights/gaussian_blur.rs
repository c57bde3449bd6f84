//! Gaussian smoothing G_sigma of a height field (used by every terrain pass, paper eq. (1)).

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Raster};
use crate::raster::blur::gaussian_blur_with_progress;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// Params of [`GaussianBlur`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaussianBlurParams {
    /// Standard deviation of the kernel, metres.
    pub sigma_m: f64,
    /// Also fill no-data cells that have valid neighbours within the kernel. Default false.
    #[serde(default)]
    pub fill: bool,
}

/// Normalised, no-data-aware Gaussian filter.
pub struct GaussianBlur;

impl Stage for GaussianBlur {
    const KIND: &'static str = "GaussianBlur";
    const VERSION: u32 = 1;
    const DOC: &'static str = "no-data-aware Gaussian smoothing G_sigma of a raster, eq. (1)";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "raster",
        ArtifactType::Raster,
        "the raster to smooth",
    )];
    type Params = GaussianBlurParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::SameAs("raster")
    }

    /// The kernel's 3 sigma.
    fn reach_m(p: &Self::Params) -> f64 {
        3.0 * p.sigma_m
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.sigma_m >= 0.0 && p.sigma_m.is_finite()) {
            return Err(ParamError::new(
                "sigma_m",
                format!(
                    "expected a non-negative sigma in metres, found {}",
                    p.sigma_m
                ),
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let r: &Raster = inputs.one("raster")?;
        Ok(gaussian_blur_with_progress(
            r,
            p.sigma_m,
            p.fill,
            ctx.progress,
        ))
    }
}
