//! Meshes onto the site grid as a height field H_s, by casting rays down from above (paper Sec. 4:
//! photogrammetric meshes and 3D Tiles become height fields this way).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, ObjectClass, PodVec, Raster, Scene};
use crate::geom::from_above::{BAND_ROWS, down_rows, scene_grid, top_z};
use crate::geom::raycast::SceneRays;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// Params of [`RasterizeScene`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
#[derive(Default)]
pub struct RasterizeSceneParams {
    /// Cell size, metres; default: the site's.
    pub cell_m: Option<f64>,
    /// Only surfaces of these classes (e.g. `[Terrain]` for a bare-earth DEM); default: all.
    pub classes: Option<Vec<ObjectClass>>,
}

/// The highest surface of a scene (of the chosen classes) at every cell centre.
pub struct RasterizeScene;

impl Stage for RasterizeScene {
    const KIND: &'static str = "RasterizeScene";
    const VERSION: u32 = 1;
    const DOC: &'static str = "scene meshes -> height field by casting rays from above (DSM, or DEM from terrain only), Sec. 4";
    const INPUTS: &'static [InputSpec] =
        &[InputSpec::one("scene", ArtifactType::Scene, "the scene")];
    type Params = RasterizeSceneParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("m")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::params::check_cell(p.cell_m)?;
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
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
        let keep = |c: ObjectClass| p.classes.as_ref().is_none_or(|k| k.contains(&c));
        ctx.progress.set_total(grid.height as u64);
        let w = grid.width as usize;
        let mut data = vec![f32::NAN; grid.len()];
        data.par_chunks_mut(w * BAND_ROWS)
            .enumerate()
            .for_each(|(band, out)| {
                let rows = (out.len() / w) as u32;
                let first = (band * BAND_ROWS) as u32;
                let hits = down_rows(&rays, scene, &grid, first, rows, top, &keep);
                for (z, h) in out.iter_mut().zip(hits) {
                    if let Some(h) = h {
                        *z = top - h.t;
                    }
                }
                ctx.progress.advance(rows as u64);
            });
        Ok(Raster {
            grid,
            data: PodVec(data),
        })
    }
}
