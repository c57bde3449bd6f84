//! The orthophoto a camera straight above a scene would take: the synthetic site's aerial image.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::{ArtifactType, Ortho, PodVec, Scene};
use crate::geom::from_above::{BAND_ROWS, down_rows, scene_grid, top_z};
use crate::geom::raycast::{Hit, SceneRays, tile_order};
use crate::io::export::material_color;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`RenderOrtho`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RenderOrthoParams {
    /// Pixel size, metres; default: the site's cell.
    pub cell_m: Option<f64>,
    /// Sun elevation, degrees. Default 50.
    pub sun_elevation_deg: f64,
    /// Sun azimuth, degrees clockwise from north. Default 150.
    pub sun_azimuth_deg: f64,
}

impl Default for RenderOrthoParams {
    fn default() -> Self {
        RenderOrthoParams {
            cell_m: None,
            sun_elevation_deg: 50.0,
            sun_azimuth_deg: 150.0,
        }
    }
}

/// A true orthophoto of a scene: each pixel the colour of the material straight below, shaded by
/// the sun (Lambert), darkened where the surface is in a cast shadow.
pub struct RenderOrtho;

impl Stage for RenderOrtho {
    const KIND: &'static str = "RenderOrtho";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "true orthophoto of a scene: material colours, sun shading and cast shadows";
    const INPUTS: &'static [InputSpec] =
        &[InputSpec::one("scene", ArtifactType::Scene, "the scene")];
    type Params = RenderOrthoParams;
    type Output = Ortho;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::params::check_cell(p.cell_m)?;
        if !(p.sun_elevation_deg > 0.0 && p.sun_elevation_deg <= 90.0) {
            return Err(ParamError::new(
                "sun_elevation_deg",
                "expected an elevation in (0, 90] degrees",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Ortho, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let grid = scene_grid(scene, p.cell_m.unwrap_or(ctx.site.cell_m))?;
        grid.check_size().map_err(|m| {
            StageError::Param(ParamError::new(
                "cell_m",
                format!("{m}; use a coarser cell"),
            ))
        })?;
        let rays = SceneRays::new(scene);
        let top = top_z(scene);
        let (el, az) = (
            p.sun_elevation_deg.to_radians(),
            p.sun_azimuth_deg.to_radians(),
        );
        let sun = [
            (el.cos() * az.sin()) as f32,
            (el.cos() * az.cos()) as f32,
            el.sin() as f32,
        ];
        ctx.progress.set_total(grid.height as u64);
        let w = grid.width as usize;
        let mut rgb = vec![[0u8; 3]; grid.len()];
        let mut valid = vec![0u8; grid.len()];
        rgb.par_chunks_mut(w * BAND_ROWS)
            .zip(valid.par_chunks_mut(w * BAND_ROWS))
            .enumerate()
            .for_each(|(band, (px, ok))| {
                let rows = (px.len() / w) as u32;
                let first = (band * BAND_ROWS) as u32;
                let hits = down_rows(&rays, scene, &grid, first, rows, top, &|_| true);
                // The shadow rays run parallel from nearby points: packets too, in tiles.
                let order = tile_order(grid.width, rows);
                let lit: Vec<(usize, Hit, [f32; 3])> = order
                    .iter()
                    .filter_map(|&i| {
                        let h = hits[i as usize]?;
                        let (x, y) = grid.center(i % grid.width, first + i / grid.width);
                        Some((i as usize, h, [x as f32, y as f32, top - h.t + 0.05]))
                    })
                    .collect();
                let shadow_rays: Vec<_> = lit.iter().map(|&(_, _, p0)| (p0, sun)).collect();
                let shadows = rays.cast_coherent(&shadow_rays, 1e-2, f32::INFINITY);
                for (&(i, h, _), shadow) in lit.iter().zip(shadows) {
                    let m = scene.objects[h.object]
                        .mesh
                        .materials
                        .get(h.triangle)
                        .copied()
                        .and_then(Material::from_u8)
                        .unwrap_or(Material::Concrete);
                    let n = h.normal;
                    let lambert = (n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2]).max(0.0);
                    let light = 0.35 + 0.65 * if shadow.is_some() { 0.0 } else { lambert };
                    let c = material_color(m);
                    px[i] = c.map(|v| (255.0 * (v * light).clamp(0.0, 1.0).powf(1.0 / 2.2)) as u8);
                    ok[i] = 1;
                }
                ctx.progress.advance(rows as u64);
            });
        Ok(Ortho {
            grid,
            rgb: PodVec(rgb),
            valid: PodVec(valid),
        })
    }
}
