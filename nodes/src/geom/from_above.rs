//! Casting straight down over a scene: the grid that covers it and the first surface below a
//! point. What rasterizing a scene into a height field and rendering an orthophoto share.

use crate::artifact::{Grid, ObjectClass, Scene};
use crate::geom::raycast::{Hit, SceneRays};
use crate::stage::StageError;

/// The grid over the scene's terrain (or, without terrain, all objects), aligned to the site.
pub fn scene_grid(scene: &Scene, cell: f64) -> Result<Grid, StageError> {
    let bounds = |terrain_only: bool| {
        scene
            .objects
            .iter()
            .filter(|o| !terrain_only || o.class == ObjectClass::Terrain)
            .flat_map(|o| o.mesh.positions.iter())
            .fold(
                (
                    (f64::INFINITY, f64::INFINITY),
                    (f64::NEG_INFINITY, f64::NEG_INFINITY),
                ),
                |(lo, hi), p| {
                    (
                        (lo.0.min(p[0] as f64), lo.1.min(p[1] as f64)),
                        (hi.0.max(p[0] as f64), hi.1.max(p[1] as f64)),
                    )
                },
            )
    };
    let (mut lo, mut hi) = bounds(true);
    if !lo.0.is_finite() {
        (lo, hi) = bounds(false);
    }
    if !lo.0.is_finite() {
        return Err(StageError::Failed("the scene is empty".into()));
    }
    // Cell centres inside the extent.
    Ok(Grid::covering(
        (lo.0 + cell / 2.0, lo.1 + cell / 2.0),
        (hi.0 - cell / 2.0, hi.1 - cell / 2.0),
        cell,
    ))
}

/// A height above every vertex of the scene, to cast down from.
pub fn top_z(scene: &Scene) -> f32 {
    scene
        .objects
        .iter()
        .flat_map(|o| o.mesh.positions.iter())
        .map(|p| p[2])
        .fold(f32::NEG_INFINITY, f32::max)
        + 10.0
}

/// The first surface of a kept class straight below (x, y), skipping others.
pub fn down(
    rays: &SceneRays,
    scene: &Scene,
    x: f64,
    y: f64,
    top: f32,
    keep: &dyn Fn(ObjectClass) -> bool,
) -> Option<Hit> {
    let mut tmin = 0.0f32;
    loop {
        let h = rays.cast(
            [x as f32, y as f32, top],
            [0.0, 0.0, -1.0],
            tmin,
            f32::INFINITY,
        )?;
        if keep(scene.objects[h.object].class) {
            return Some(h);
        }
        tmin = h.t + 1e-3;
    }
}
