//! The scene grammar: where each class of clutter may stand (the ground, the roads, the
//! buildings and canopies), each rule's effect counted.

use std::collections::BTreeMap;

use rayon::prelude::*;

use crate::artifact::{ObjectClass, Raster, Scene, ViewHead};
use crate::geom::from_above::{down, top_z};
use crate::geom::polygon::convex_hull;
use crate::geom::raycast::SceneRays;

use super::assets::AssetKind;
use super::clustering::Cluster;
use super::config::ClutterConfig;
use super::track::Track;

/// What the grammar knows of the ground: the terrain, where the twin's buildings stand and how
/// far each cell is from one, and where the cameras drove (the roads).
pub struct Ground<'a> {
    terrain: &'a Raster,
    building: Vec<bool>,
    dist: Vec<f32>,
    track: Track,
    /// Canopy outlines (convex hulls of the canopy objects' vertices): trees from the views inside
    /// one are the canopy already.
    canopies: Vec<Vec<[f64; 2]>>,
}

impl<'a> Ground<'a> {
    /// Building cells on the terrain's grid (the first surface below each cell centre is a
    /// building), their distance transform, the camera positions, and canopy outlines.
    pub fn new(
        terrain: &'a Raster,
        twin: &Scene,
        views: &[ViewHead],
        canopies: Option<&Scene>,
    ) -> Ground<'a> {
        let g = terrain.grid;
        let rays = SceneRays::new(twin);
        let top = top_z(twin);
        let building: Vec<bool> = (0..g.height)
            .into_par_iter()
            .flat_map_iter(|r| {
                let rays = &rays;
                (0..g.width).map(move |c| {
                    let (x, y) = g.center(c, r);
                    down(rays, twin, x, y, top, &|cl| {
                        matches!(cl, ObjectClass::Building | ObjectClass::Terrain)
                    })
                    .is_some_and(|h| twin.objects[h.object].class == ObjectClass::Building)
                })
            })
            .collect();
        let dist = distance_transform(&building, g.width as usize, g.height as usize, g.cell_m);
        let canopies = canopies
            .map(|s| {
                s.objects
                    .iter()
                    .filter(|o| o.class == ObjectClass::Vegetation)
                    .map(|o| {
                        convex_hull(
                            o.mesh
                                .positions
                                .iter()
                                .map(|p| [p[0] as f64, p[1] as f64])
                                .collect(),
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        Ground {
            terrain,
            building,
            dist,
            track: Track::new(views),
            canopies,
        }
    }

    fn cell(&self, x: f64, y: f64) -> Option<usize> {
        let g = self.terrain.grid;
        g.cell_of(x, y)
            .map(|(c, r)| r as usize * g.width as usize + c as usize)
    }

    fn is_building(&self, x: f64, y: f64) -> bool {
        self.cell(x, y).is_some_and(|i| self.building[i])
    }

    fn building_dist(&self, x: f64, y: f64) -> f64 {
        self.cell(x, y).map_or(0.0, |i| self.dist[i] as f64)
    }

    fn road(&self, p: [f64; 2]) -> Option<([f64; 2], f64)> {
        self.track.road(p)
    }

    /// Free distance from `p` along `dir` before a building or the grid's edge, up to `max`.
    fn free_run(&self, p: [f64; 2], dir: [f64; 2], max: f64) -> f64 {
        let step = self.terrain.grid.cell_m / 2.0;
        let mut s = step;
        while s < max {
            let (x, y) = (p[0] + dir[0] * s, p[1] + dir[1] * s);
            match self.cell(x, y) {
                Some(i) if !self.building[i] => s += step,
                _ => return s,
            }
        }
        max
    }

    fn in_canopy(&self, p: [f64; 2]) -> bool {
        self.canopies
            .iter()
            .any(|h| h.len() >= 3 && crate::artifact::point_in_ring(p, h))
    }
}

/// Chamfer (3-4) distance to the nearest `true` cell, metres; `f32::MAX` without any.
pub(crate) fn distance_transform(mask: &[bool], w: usize, h: usize, cell: f64) -> Vec<f32> {
    let inf = f32::MAX / 4.0;
    let mut d: Vec<f32> = mask.iter().map(|&m| if m { 0.0 } else { inf }).collect();
    let (a, b) = (cell as f32, cell as f32 * std::f32::consts::SQRT_2);
    for r in 0..h {
        for c in 0..w {
            let i = r * w + c;
            let mut v = d[i];
            if c > 0 {
                v = v.min(d[i - 1] + a);
            }
            if r > 0 {
                v = v.min(d[i - w] + a);
                if c > 0 {
                    v = v.min(d[i - w - 1] + b);
                }
                if c + 1 < w {
                    v = v.min(d[i - w + 1] + b);
                }
            }
            d[i] = v;
        }
    }
    for r in (0..h).rev() {
        for c in (0..w).rev() {
            let i = r * w + c;
            let mut v = d[i];
            if c + 1 < w {
                v = v.min(d[i + 1] + a);
            }
            if r + 1 < h {
                v = v.min(d[i + w] + a);
                if c + 1 < w {
                    v = v.min(d[i + w + 1] + b);
                }
                if c > 0 {
                    v = v.min(d[i + w - 1] + b);
                }
            }
            d[i] = v;
        }
    }
    d
}

/// A clutter object that survived the grammar.
#[derive(Clone, Debug, PartialEq)]
pub struct Placed {
    /// Class name.
    pub class: String,
    /// Asset.
    pub kind: AssetKind,
    /// Centre.
    pub xy: [f64; 2],
    /// Terrain height there.
    pub ground_z: f64,
    /// Radians counter-clockwise from +x.
    pub heading: f64,
    /// Height scale of the asset.
    pub height_scale: f64,
    /// Views that saw it.
    pub views: usize,
}

/// The scene grammar, each rule's effect counted in `counts` (`grammar_*`): nothing inside a
/// building; everything on the terrain (objects off it are dropped, the others stand on it);
/// vehicles on the road (within `road_half_width_m` of the nearest street axis the track draws,
/// and at least `vehicle_building_gap_m` from a building), not in intersections (free of
/// buildings for `intersection_run_m` on both sides across the street), aligned with the
/// street; roadside furniture at road edges and on sidewalks (not within `roadside_min_m` of
/// that axis); trees from the views not inside a canopy.
pub fn grammar(
    clusters: Vec<Cluster>,
    ground: &Ground,
    cfg: &ClutterConfig,
    counts: &mut BTreeMap<String, usize>,
) -> Vec<Placed> {
    let mut bump = |name: &str| *counts.entry(format!("grammar_{name}")).or_default() += 1;
    let mut out = Vec::new();
    for c in clusters {
        let [x, y] = c.xy;
        if c.views < cfg.min_views {
            bump("dropped_few_views");
            continue;
        }
        if ground.is_building(x, y) {
            bump("dropped_inside_building");
            continue;
        }
        let Some(gz) = ground.terrain.bilinear(x, y) else {
            bump("dropped_off_terrain");
            continue;
        };
        let standing = c.kind != AssetKind::Sign;
        if standing && (c.z.0 - gz).abs() > 0.5 {
            bump("moved_onto_terrain");
        }
        let road = ground.road(c.xy);
        let mut heading = c.heading.unwrap_or(0.0);
        if c.kind.is_vehicle() {
            let Some((axis, lateral)) = road else {
                bump("dropped_vehicle_no_road");
                continue;
            };
            if lateral > cfg.road_half_width_m {
                bump("dropped_vehicle_off_road");
                continue;
            }
            if ground.building_dist(x, y) < cfg.vehicle_building_gap_m {
                bump("dropped_vehicle_on_sidewalk");
                continue;
            }
            let across = [-axis[1], axis[0]];
            let run = |s: f64| {
                ground.free_run(
                    c.xy,
                    [across[0] * s, across[1] * s],
                    cfg.intersection_run_m + 1.0,
                )
            };
            if run(1.0) > cfg.intersection_run_m && run(-1.0) > cfg.intersection_run_m {
                bump("vehicle_in_intersection");
                if cfg.drop_vehicles_in_intersections {
                    bump("dropped_vehicle_in_intersection");
                    continue;
                }
            }
            let street = axis[1].atan2(axis[0]);
            let turn = |h: f64| {
                let d = (h - street).rem_euclid(std::f64::consts::PI);
                d.min(std::f64::consts::PI - d)
            };
            if c.heading.is_none_or(|h| turn(h) > 20f64.to_radians()) {
                bump("vehicle_aligned_with_street");
            }
            heading = street;
        } else if c.kind.is_roadside() {
            if let Some((axis, lateral)) = road {
                if lateral < cfg.roadside_min_m {
                    bump("dropped_roadside_in_carriageway");
                    continue;
                }
                heading = axis[1].atan2(axis[0]);
            }
        } else if c.kind == AssetKind::SmallTree && ground.in_canopy(c.xy) {
            bump("dropped_tree_in_canopy");
            continue;
        } else if let Some((axis, _)) = road {
            heading = axis[1].atan2(axis[0]);
        }
        // Height from the lifted top above the terrain, within a third of the asset's.
        let h = kind_height(c.kind);
        let height_scale = ((c.z.1 - gz) / h).clamp(0.75, 1.33);
        out.push(Placed {
            class: c.class,
            kind: c.kind,
            xy: c.xy,
            ground_z: gz,
            heading,
            height_scale: if height_scale.is_finite() {
                height_scale
            } else {
                1.0
            },
            views: c.views,
        });
    }
    out
}

fn kind_height(kind: AssetKind) -> f64 {
    kind.size()[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_and_distance() {
        let h = convex_hull(vec![
            [0.0, 0.0],
            [1.0, 0.0],
            [0.5, 0.5],
            [1.0, 1.0],
            [0.0, 1.0],
        ]);
        assert_eq!(h.len(), 4);
        assert!(crate::artifact::ring_area(&h) > 0.99);
        let mut m = vec![false; 25];
        m[12] = true;
        let d = distance_transform(&m, 5, 5, 1.0);
        assert_eq!(d[12], 0.0);
        assert_eq!(d[13], 1.0);
        assert!((d[18] - std::f32::consts::SQRT_2).abs() < 1e-6);
    }
}
