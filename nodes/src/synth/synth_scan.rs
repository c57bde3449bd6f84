//! A seeded airborne-scan stand-in: points sampled from a surface with stratified jitter and noise.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, PointSet, Raster};
use crate::rng::{gaussian, mix, unit};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`SynthScan`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthScanParams {
    /// Mean point density, points per square metre. Default 8.
    pub density_per_m2: f64,
    /// Standard deviation of the vertical noise, metres. Default 0.05.
    pub noise_m: f64,
    /// Seed of the sample positions and noise. Default 1.
    pub seed: u64,
    /// ASPRS class given to every point. Default 2 (ground).
    pub class: u8,
}

impl Default for SynthScanParams {
    fn default() -> Self {
        SynthScanParams {
            density_per_m2: 8.0,
            noise_m: 0.05,
            seed: 1,
            class: 2,
        }
    }
}

/// Samples a surface raster as a LiDAR-like point set: one jittered sample per stratum of
/// 1/density m², z bilinearly interpolated plus Gaussian noise. No-data cells return no points.
pub struct SynthScan;

impl Stage for SynthScan {
    const KIND: &'static str = "SynthScan";
    const VERSION: u32 = 1;
    const DOC: &'static str = "samples a surface raster as a noisy LiDAR-like point set";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "surface",
        ArtifactType::Raster,
        "the surface the scanner sees",
    )];
    type Params = SynthScanParams;
    type Output = PointSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.density_per_m2 > 0.0 && p.density_per_m2 <= 1000.0) {
            return Err(ParamError::new(
                "density_per_m2",
                "expected a density in (0, 1000] points/m²",
            ));
        }
        if !(p.noise_m >= 0.0) {
            return Err(ParamError::new(
                "noise_m",
                "expected a non-negative noise in metres",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<PointSet, StageError> {
        let surface: &Raster = inputs.one("surface")?;
        let g = surface.grid;
        let step = 1.0 / p.density_per_m2.sqrt();
        let nx = ((g.width as f64 * g.cell_m) / step).floor() as u64;
        let ny = ((g.height as f64 * g.cell_m) / step).floor() as u64;
        ctx.progress.set_total(ny);
        let rows: Vec<Vec<[f32; 3]>> = (0..ny)
            .into_par_iter()
            .map(|j| {
                let mut out = Vec::with_capacity(nx as usize);
                for i in 0..nx {
                    let h = mix(p.seed ^ mix(j * nx + i));
                    let x = g.x0 + (i as f64 + unit(h)) * step;
                    let y = g.y0 - (j as f64 + unit(mix(h))) * step;
                    let Some(z) = surface.bilinear(x, y) else {
                        continue;
                    };
                    let z = z + p.noise_m * gaussian(mix(h ^ 0x5851_F42D_4C95_7F2D));
                    out.push([x as f32, y as f32, z as f32]);
                }
                ctx.progress.advance(1);
                out
            })
            .collect();
        let xyz: Vec<[f32; 3]> = rows.concat();
        let class = vec![p.class; xyz.len()];
        Ok(PointSet {
            xyz: PodVec(xyz),
            class: PodVec(class),
            ..Default::default()
        })
    }
}
