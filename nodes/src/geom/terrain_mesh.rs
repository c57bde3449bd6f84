//! The terrain raster as a triangle mesh.

use crate::artifact::Material;
use crate::artifact::{Grid, Mesh, ObjectClass, Raster, SceneObject};
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

/// The terrain as a regular triangulated surface with a vertex at each corner of `over`'s
/// cells (bilinear between the terrain's cell centres, clamped at its rim): the part of
/// [`terrain_mesh`] at `over.cell_m` under a window of the map's lattice, made from the terrain
/// cells near it alone, so that a map of a few hundred metres of a city does not mesh the
/// city's ground. No-data cells are filled from their neighbours within that part.
pub fn terrain_mesh_over(terrain: &Raster, over: Grid, material: Material) -> Result<Mesh, String> {
    let c = over.cell_m;
    let south = over.y0 - over.height as f64 * c;
    let east = over.x0 + over.width as f64 * c;
    // Two terrain cells and a map cell beyond the window: every vertex's bilinear neighbours.
    let margin = 2.0 * terrain.grid.cell_m + c;
    let mut t = terrain
        .cropped((
            over.x0 - margin,
            south - margin,
            east + margin,
            over.y0 + margin,
        ))
        .ok_or("the map's window lies off the terrain")?;
    if !t.data.iter().any(|v| v.is_finite()) {
        return Err("the terrain raster has no data under the map's window".into());
    }
    let g = t.grid;
    fill_gaps(&mut t, g.width.max(g.height));
    // Clamped to the whole terrain's extent, as `terrain_mesh` clamps: past its rim the
    // ground stays level.
    let tg = terrain.grid;
    let (tw, ts) = (
        tg.x0 + tg.width as f64 * tg.cell_m,
        tg.y0 - tg.height as f64 * tg.cell_m,
    );
    let clamp = |x: f64, lo: f64, hi: f64| x.min(hi).max(lo);
    let mesh = height_surface(
        [over.x0, south],
        over.width + 1,
        over.height + 1,
        c,
        |x, y| {
            t.bilinear(clamp(x, tg.x0, tw), clamp(y, ts, tg.y0))
                .unwrap_or(f64::NAN)
        },
        material,
    );
    if mesh.positions.iter().any(|p| !p[2].is_finite()) {
        return Err("the terrain raster could not be filled under the map's window".into());
    }
    Ok(mesh)
}
