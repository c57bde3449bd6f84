//! The terrain raster as a triangle mesh.

use crate::artifact::Material;
use crate::artifact::{Mesh, ObjectClass, Raster, SceneObject};
use crate::geom::mesh_build::height_surface;
use crate::raster::gap_fill::fill_gaps;

/// The id every scene gives its ground.
pub const TERRAIN_ID: &str = "terrain";

/// The terrain as a scene's ground object ([`TERRAIN_ID`], class Terrain), meshed by
/// [`terrain_mesh`].
pub fn terrain_object(
    terrain: &Raster,
    step: f64,
    material: Material,
) -> Result<SceneObject, String> {
    Ok(SceneObject {
        id: TERRAIN_ID.into(),
        class: ObjectClass::Terrain,
        mesh: terrain_mesh(terrain, step, material)?,
    })
}

/// The terrain raster as a regular triangulated surface over its whole extent, vertices every
/// `step` metres (bilinear between cell centres, clamped at the rim); no-data cells are filled
/// from their neighbours first.
pub fn terrain_mesh(terrain: &Raster, step: f64, material: Material) -> Result<Mesh, String> {
    let g = terrain.grid;
    if !terrain.data.iter().any(|v| v.is_finite()) {
        return Err("the terrain raster has no data".into());
    }
    let mut t = terrain.clone();
    fill_gaps(&mut t, g.width.max(g.height));
    let (w, h) = (g.width as f64 * g.cell_m, g.height as f64 * g.cell_m);
    let nx = (w / step).ceil() as u32 + 1;
    let ny = (h / step).ceil() as u32 + 1;
    let south = g.y0 - h;
    // The last row and column may overshoot the extent by less than a step: pull them back.
    let clamp = |x: f64, lo: f64, hi: f64| x.min(hi).max(lo);
    let mut mesh = height_surface(
        [g.x0, south],
        nx,
        ny,
        step,
        |x, y| {
            t.bilinear(clamp(x, g.x0, g.x0 + w), clamp(y, south, g.y0))
                .unwrap_or(f64::NAN)
        },
        material,
    );
    for p in mesh.positions.iter_mut() {
        p[0] = p[0].min((g.x0 + w) as f32);
        p[1] = p[1].min(g.y0 as f32);
    }
    if mesh.positions.iter().any(|p| !p[2].is_finite()) {
        return Err("the terrain raster could not be filled".into());
    }
    Ok(mesh)
}
