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
    down_from(rays, scene, x, y, top, 0.0, keep)
}

/// Rows this many at a time make the 8 x 8 tiles [`down_rows`] casts as packets.
pub const BAND_ROWS: usize = 8;

/// [`down`] at the centre of every cell of `rows` rows of `grid` from row `first`, row-major.
/// The first casts go in 8 x 8 tiles of parallel rays (packets); a cell whose first surface is
/// of a class not kept goes on alone, as [`down`] does.
pub fn down_rows(
    rays: &SceneRays,
    scene: &Scene,
    grid: &Grid,
    first: u32,
    rows: u32,
    top: f32,
    keep: &dyn Fn(ObjectClass) -> bool,
) -> Vec<Option<Hit>> {
    let origin = |col: u32, row: u32| {
        let (x, y) = grid.center(col, first + row);
        [x as f32, y as f32, top]
    };
    let hits = rays.cast_grid(
        grid.width,
        rows,
        |c, r| (origin(c, r), [0.0, 0.0, -1.0]),
        0.0,
        f32::INFINITY,
    );
    hits.into_iter()
        .enumerate()
        .map(|(i, h)| {
            let h = h?;
            if keep(scene.objects[h.object].class) {
                return Some(h);
            }
            let (col, row) = (i as u32 % grid.width, i as u32 / grid.width);
            let (x, y) = grid.center(col, first + row);
            down_from(rays, scene, x, y, top, h.t + 1e-3, keep)
        })
        .collect()
}

fn down_from(
    rays: &SceneRays,
    scene: &Scene,
    x: f64,
    y: f64,
    top: f32,
    mut tmin: f32,
    keep: &dyn Fn(ObjectClass) -> bool,
) -> Option<Hit> {
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
