//! A tiled run's scenes into one: each object from the tile that owns it.

use crate::artifact::{ArtifactType, Mesh, ObjectClass, Scene, SceneObject};
use crate::site::{MergeTilesParams, Window};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Each tile keeps the objects whose owner point ([`Mesh::owner_point`]: a solid's volume
/// centroid, its footprint's for a prism) lies in its core, their ids prefixed with the tile's
/// name (`x1y0/building-12`); a building therefore comes whole from one tile, and no solid is
/// cut at a seam. A terrain (or an unsegmented surface) is no solid: its triangles are kept by
/// their centroids, and the tiles' pieces join into one object of that id. A graph that wants one
/// seamless terrain merges the terrain raster instead and assembles the scene after the merge.
/// Clutter and vegetation that two tiles both placed at a seam are kept once (`placed_twice`).
pub struct MergeScenes;

impl Stage for MergeScenes {
    const KIND: &'static str = "MergeScenes";
    // 2: clutter and vegetation placed by two tiles at a seam kept once (`placed_twice`).
    const VERSION: u32 = 2;
    const DOC: &'static str = "a tiled run's scenes into one, each object from the tile holding its centroid (added by the engine)";
    const INPUTS: &'static [InputSpec] = &[InputSpec::many(
        "tiles",
        ArtifactType::Scene,
        "each tile's scene, in the order of `tiles`",
    )];
    type Params = MergeTilesParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.validate().map_err(|(f, m)| ParamError::new(f, m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, _ctx: &Ctx) -> Result<Scene, StageError> {
        let parts: Vec<&Scene> = inputs.many("tiles")?;
        p.check_inputs(parts.len()).map_err(StageError::Failed)?;
        let mut surfaces: Vec<SceneObject> = Vec::new();
        let mut objects = Vec::new();
        let mut owners = Vec::new();
        for (t, (tile, scene)) in p.tiles.iter().zip(parts).enumerate() {
            for o in &scene.objects {
                if is_surface(o.class) {
                    let piece = triangles_in(&o.mesh, tile.core);
                    match surfaces.iter_mut().find(|s| s.id == o.id) {
                        Some(s) => s.mesh.append(&piece),
                        None => surfaces.push(SceneObject {
                            id: o.id.clone(),
                            class: o.class,
                            mesh: piece,
                        }),
                    }
                } else if o
                    .mesh
                    .owner_point()
                    .is_some_and(|(x, y)| tile.core.contains(x, y))
                {
                    objects.push(SceneObject {
                        id: format!("{}/{}", tile.name, o.id),
                        class: o.class,
                        mesh: o.mesh.clone(),
                    });
                    owners.push(t);
                }
            }
        }
        surfaces.retain(|s| !s.mesh.is_empty());
        let placed_twice = placed_twice(&objects, &owners, p);
        surfaces.extend(
            objects
                .into_iter()
                .zip(placed_twice)
                .filter_map(|(o, twice)| (!twice).then_some(o)),
        );
        Ok(Scene { objects: surfaces })
    }
}

/// Clutter and vegetation are placed by each tile from its own views, so an object that
/// straddles a seam can be placed by both tiles, a little apart, each placement's owner point
/// in its own tile's core (the street tiles' merge kept 276 clutter objects where the untiled run
/// placed 261: docs/benchmarks-log.md, 2026-11-29). Two placements of one class from different
/// tiles whose plan bounds overlap by at least this IoU are taken for one object.
const PLACED_TWICE_IOU: f64 = 0.5;

/// Classes placed from views, whose copies at a seam are merged.
fn placed_from_views(class: ObjectClass) -> bool {
    matches!(class, ObjectClass::Clutter | ObjectClass::Vegetation)
}

/// Per object (in `objects`' order, each from tile `owners[k]`), whether it is a second
/// placement of an object another tile placed ([`PLACED_TWICE_IOU`]): of each such pair the one
/// whose owner point lies deeper inside its tile's core stays (the tile whose views saw it from
/// more sides), the first listed on a tie. Neighbours are found through a grid of 16 m cells.
fn placed_twice(objects: &[SceneObject], owners: &[usize], p: &MergeTilesParams) -> Vec<bool> {
    const CELL_M: f64 = 16.0;
    let bounds: Vec<Option<PlanBox>> = objects
        .iter()
        .map(|o| {
            if placed_from_views(o.class) {
                o.mesh.plan_bounds()
            } else {
                None
            }
        })
        .collect();
    let cell = |v: f64| (v / CELL_M).floor() as i64;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
    for (k, b) in bounds.iter().enumerate() {
        if let Some((lo, hi)) = b {
            for cx in cell(lo.0)..=cell(hi.0) {
                for cy in cell(lo.1)..=cell(hi.1) {
                    grid.entry((cx, cy)).or_default().push(k);
                }
            }
        }
    }
    let depth = |k: usize| {
        let core = p.tiles[owners[k]].core;
        objects[k].mesh.owner_point().map_or(0.0, |(x, y)| {
            (x - core.min.0)
                .min(core.max.0 - x)
                .min(y - core.min.1)
                .min(core.max.1 - y)
        })
    };
    let mut twice = vec![false; objects.len()];
    for (a, b) in bounds.iter().enumerate() {
        let Some(ba) = b else { continue };
        // Candidates in ascending index order, each once: the outcome is the same whatever
        // order the grid's cells come in.
        let mut near: Vec<usize> = (cell(ba.0.0)..=cell(ba.1.0))
            .flat_map(|cx| (cell(ba.0.1)..=cell(ba.1.1)).map(move |cy| (cx, cy)))
            .flat_map(|c| grid.get(&c).into_iter().flatten().copied())
            .filter(|&o| o > a)
            .collect();
        near.sort_unstable();
        near.dedup();
        for o in near {
            let Some(bo) = bounds[o] else { continue };
            if owners[o] == owners[a]
                || objects[o].class != objects[a].class
                || iou(*ba, bo) < PLACED_TWICE_IOU
                || twice[a]
                || twice[o]
            {
                continue;
            }
            if depth(o) > depth(a) {
                twice[a] = true;
            } else {
                twice[o] = true;
            }
        }
    }
    twice
}

/// A plan box: (x, y) least, (x, y) most.
type PlanBox = ((f64, f64), (f64, f64));

/// Intersection over union of two plan boxes.
fn iou(a: PlanBox, b: PlanBox) -> f64 {
    let w = (a.1.0.min(b.1.0) - a.0.0.max(b.0.0)).max(0.0);
    let h = (a.1.1.min(b.1.1) - a.0.1.max(b.0.1)).max(0.0);
    let inter = w * h;
    let area = |r: PlanBox| (r.1.0 - r.0.0) * (r.1.1 - r.0.1);
    let union = area(a) + area(b) - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

/// Open surfaces, cut by triangle rather than owned whole.
fn is_surface(class: ObjectClass) -> bool {
    matches!(class, ObjectClass::Terrain | ObjectClass::Unsegmented)
}

/// The triangles of `mesh` whose centroids lie in `core`, with the vertices they use.
fn triangles_in(mesh: &Mesh, core: Window) -> Mesh {
    mesh.select_triangles(|ps| {
        let cx = (ps[0][0] as f64 + ps[1][0] as f64 + ps[2][0] as f64) / 3.0;
        let cy = (ps[0][1] as f64 + ps[1][1] as f64 + ps[2][1] as f64) / 3.0;
        core.contains(cx, cy)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::geom::mesh_build::cuboid;
    use crate::site::TileCore;
    use crate::stage::Slot;
    use crate::{Artifact, Site};
    use std::sync::Arc;

    fn thing(id: &str, class: ObjectClass, c: [f64; 2]) -> SceneObject {
        SceneObject {
            id: id.into(),
            class,
            mesh: cuboid(c, [4.4, 1.8, 1.5], 0.0, 0.0, Material::Metal),
        }
    }

    /// Two tiles split at x = 100. A car straddling the seam, placed 0.3 m apart by each tile,
    /// each placement's centre in its own core, is kept once: from the tile it lies deeper in.
    /// Two cars 3 m apart across the seam, a car placed twice within one tile and a building
    /// placed by both are not such copies and all stay.
    #[test]
    fn an_object_two_tiles_placed_at_a_seam_is_kept_once() {
        let core = |x0: f64, x1: f64| Window {
            min: (x0, 0.0),
            max: (x1, 100.0),
        };
        let p = MergeTilesParams {
            tiles: vec![
                TileCore {
                    name: "x0y0".into(),
                    core: core(0.0, 100.0),
                },
                TileCore {
                    name: "x1y0".into(),
                    core: core(100.0, 200.0),
                },
            ],
        };
        let c = ObjectClass::Clutter;
        let west = Scene {
            objects: vec![
                thing("car-1", c, [99.8, 50.0]),
                thing("car-2", c, [98.0, 20.0]),
                thing("car-3", c, [50.0, 80.0]),
                thing("car-4", c, [50.2, 80.0]),
                thing("house", ObjectClass::Building, [99.9, 5.0]),
            ],
        };
        let east = Scene {
            objects: vec![
                thing("car-1", c, [100.1, 50.0]),
                thing("car-2", c, [102.5, 20.0]),
                thing("house", ObjectClass::Building, [100.05, 5.0]),
            ],
        };
        let inputs = crate::stage::Inputs::new().with(
            "tiles",
            Slot::Many(vec![
                Arc::new(Artifact::Scene(west)),
                Arc::new(Artifact::Scene(east)),
            ]),
        );
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        let merged = MergeScenes::run(&p, &inputs, &Ctx::new(&site, &[])).unwrap();
        let mut ids: Vec<&str> = merged.objects.iter().map(|o| o.id.as_str()).collect();
        ids.sort_unstable();
        // car-1 is 0.2 m inside the west core and 0.1 m inside the east one: the west keeps it.
        assert_eq!(
            ids,
            [
                "x0y0/car-1",
                "x0y0/car-2",
                "x0y0/car-3",
                "x0y0/car-4",
                "x0y0/house",
                "x1y0/car-2",
                "x1y0/house"
            ]
        );
    }
}
