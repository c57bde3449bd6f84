//! Clutter from street views (paper Sec. 4.2.4): each view's depth calibrated against the twin
//! with a Theil-Sen affine fit, clutter instances lifted to world positions, repeated detections
//! clustered across views, non-maximum suppression by class and distance, a scene grammar whose
//! every rule's effect is counted, and the survivors instantiated from the asset library.

pub mod assets;

use std::collections::BTreeMap;

use rayon::prelude::*;

use crate::artifact::{Metrics, ObjectClass, Raster, Scene, SceneObject, View};
use crate::geom::from_above::{down, top_z};
use crate::geom::polygon::convex_hull;
use crate::geom::raycast::SceneRays;
use crate::geom::theil_sen::{LineFit, median, theil_sen, weighted_median};
use crate::street::clutter::assets::AssetKind;

/// Knobs of the clutter chain.
#[derive(Clone, Debug)]
pub struct ClutterConfig {
    /// View class name -> asset.
    pub classes: BTreeMap<String, AssetKind>,
    /// One calibration ray every `calib_stride` pixels each way.
    pub calib_stride: u32,
    /// At least this many calibration samples per view, else the pooled fit of all views.
    pub min_calib_samples: usize,
    /// Instances with fewer pixels are ignored.
    pub min_pixels: usize,
    /// Lifted points farther than this from the camera are ignored, metres.
    pub max_range_m: f64,
    /// Detections of one class within this many metres (times the class length, at least 1 m)
    /// join one cluster.
    pub cluster_factor: f64,
    /// A cluster within this many class lengths (at least 1.5 m) of a stronger one of its class
    /// is suppressed.
    pub nms_factor: f64,
    /// Clusters seen from fewer distinct views are dropped.
    pub min_views: usize,
    /// Vehicles farther than this from the nearest street axis the camera track draws are
    /// off the road, metres.
    pub road_half_width_m: f64,
    /// Vehicles closer than this to a building are on the sidewalk, metres.
    pub vehicle_building_gap_m: f64,
    /// Roadside furniture closer than this to the nearest street axis the track draws is in
    /// the carriageway, metres.
    pub roadside_min_m: f64,
    /// A point free of buildings this far on both sides across the street is in an intersection.
    pub intersection_run_m: f64,
    /// Whether vehicles in intersections are dropped.
    pub drop_vehicles_in_intersections: bool,
    /// Seed of the Theil-Sen pair draws.
    pub seed: u64,
}

impl Default for ClutterConfig {
    fn default() -> Self {
        ClutterConfig {
            classes: default_classes(),
            calib_stride: 6,
            min_calib_samples: 50,
            min_pixels: 12,
            max_range_m: 45.0,
            cluster_factor: 0.6,
            nms_factor: 1.0,
            min_views: 1,
            road_half_width_m: 7.0,
            vehicle_building_gap_m: 2.0,
            roadside_min_m: 4.0,
            intersection_run_m: 20.0,
            drop_vehicles_in_intersections: true,
            seed: 7,
        }
    }
}

/// The default class table: the names the synthetic views and common clutter models use.
pub fn default_classes() -> BTreeMap<String, AssetKind> {
    [
        ("car", AssetKind::Car),
        ("van", AssetKind::Van),
        ("truck", AssetKind::Van),
        ("bus", AssetKind::Bus),
        ("pole", AssetKind::Pole),
        ("sign", AssetKind::Sign),
        ("bench", AssetKind::Bench),
        ("shelter", AssetKind::Shelter),
        ("hydrant", AssetKind::Hydrant),
        ("tree", AssetKind::SmallTree),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// A view's depth calibration d_hat = a d + b.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// The fit (slope a, intercept b).
    pub fit: LineFit,
    /// Samples it was fitted on.
    pub samples: usize,
    /// True when the view had too few samples and the pooled fit stands in.
    pub pooled: bool,
}

/// The unit ray of pixel (`u`, `v`)'s centre in the site frame and its camera-frame z component
/// per unit length (depth = t * that).
fn pixel_ray(view: &View, u: u32, v: u32) -> ([f64; 3], f64) {
    let (dir, norm) = view.pixel_ray(u as f64 + 0.5, v as f64 + 0.5);
    (dir, 1.0 / norm)
}

/// (predicted depth d, twin depth along the axis) at every `stride`-th pixel with a finite depth
/// and no clutter instance, where the ray hits the twin.
pub fn calibration_samples(view: &View, rays: &SceneRays, stride: u32) -> Vec<(f64, f64)> {
    let Some(depth) = view.depth.as_ref() else {
        return vec![];
    };
    let clutter = view.clutter.as_ref().map(|c| &c.ids);
    let origin = view.pose.position.map(|c| c as f32);
    let stride = stride.max(1);
    let mut out = Vec::new();
    for v in (stride / 2..view.height).step_by(stride as usize) {
        for u in (stride / 2..view.width).step_by(stride as usize) {
            let i = (v * view.width + u) as usize;
            let d = depth.get(i).copied().unwrap_or(f32::NAN) as f64;
            if !d.is_finite() || clutter.is_some_and(|c| c.get(i).is_some_and(|&id| id != 0)) {
                continue;
            }
            let (dir, zf) = pixel_ray(view, u, v);
            if let Some(h) = rays.cast(origin, dir.map(|c| c as f32), 1e-3, 1000.0) {
                out.push((d, h.t as f64 * zf));
            }
        }
    }
    out
}

/// Per view: the Theil-Sen fit of twin depth on predicted depth, or the pooled fit of every
/// view's samples where a view has fewer than `min_calib_samples`. `None` for a view when no fit
/// exists at all.
pub fn calibrate(views: &[View], twin: &Scene, cfg: &ClutterConfig) -> Vec<Option<Calibration>> {
    let rays = SceneRays::new(twin);
    let samples: Vec<Vec<(f64, f64)>> = views
        .par_iter()
        .map(|v| calibration_samples(v, &rays, cfg.calib_stride))
        .collect();
    let fit = |s: &[(f64, f64)], seed: u64| {
        let (xs, ys): (Vec<f64>, Vec<f64>) = s.iter().copied().unzip();
        theil_sen(&xs, &ys, 0.5, 20_000, seed).filter(|f| f.slope > 0.0)
    };
    let pooled_samples: Vec<(f64, f64)> = samples.iter().flatten().copied().collect();
    let pooled = fit(&pooled_samples, cfg.seed ^ 0xF00D);
    samples
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let own = (s.len() >= cfg.min_calib_samples)
                .then(|| fit(s, cfg.seed ^ k as u64))
                .flatten();
            match own {
                Some(fit) => Some(Calibration {
                    fit,
                    samples: s.len(),
                    pooled: false,
                }),
                None => pooled.map(|fit| Calibration {
                    fit,
                    samples: pooled_samples.len(),
                    pooled: true,
                }),
            }
        })
        .collect()
}

/// One clutter instance of one view, lifted to the site frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// The view's class name.
    pub class: String,
    /// The asset it becomes.
    pub kind: AssetKind,
    /// Index of the view.
    pub view: usize,
    /// Estimated centre on the ground plane.
    pub xy: [f64; 2],
    /// Lowest and highest lifted point (5th and 95th percentile), site z.
    pub z: (f64, f64),
    /// Heading of the visible points' main horizontal axis, radians (mod pi), when elongated.
    pub heading: Option<f64>,
    /// Pixels.
    pub pixels: usize,
    /// Weight in clustering: pixels, a quarter for instances cut by the image border.
    pub weight: f64,
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    v[k]
}

/// Lifts the clutter instances of `view` with calibration `cal`: the pixels' back-projected points
/// (calibrated depth), their z range and the main axis of their horizontal spread; the centre is
/// the per-coordinate median pushed back along the horizontal viewing direction by the depth of
/// the asset's visible surface (the points lie on the side facing the camera), or, for an
/// elongated asset seen along its side, the middle of the points' extent along that side (half
/// a length from the end that shows when it is seen short) and half the asset's width behind
/// it; a round asset seen narrower than it is with one image side hidden, half its width in from
/// the side that shows.
pub fn lift_view(
    k: usize,
    view: &View,
    cal: &Calibration,
    track: Option<&Track>,
    cfg: &ClutterConfig,
) -> Vec<Detection> {
    let (Some(inst), Some(depth)) = (view.clutter.as_ref(), view.depth.as_ref()) else {
        return vec![];
    };
    let mut pixels: BTreeMap<u16, Vec<(u32, u32)>> = BTreeMap::new();
    let mut border: BTreeMap<u16, bool> = BTreeMap::new();
    for (i, &id) in inst.ids.iter().enumerate() {
        if id == 0 {
            continue;
        }
        let (u, v) = (i as u32 % view.width, i as u32 / view.width);
        pixels.entry(id).or_default().push((u, v));
        if u == 0 || v == 0 || u + 1 == view.width || v + 1 == view.height {
            border.insert(id, true);
        }
    }
    let o = view.pose.position;
    let mut out = Vec::new();
    for (id, px) in pixels {
        let Some(class) = inst.classes.get(&id) else {
            continue;
        };
        let Some(&kind) = cfg.classes.get(class) else {
            continue;
        };
        if px.len() < cfg.min_pixels {
            continue;
        }
        let mut pts = Vec::with_capacity(px.len());
        // Which image side of its row each lifted point's pixel ends the instance on, if any.
        let mut row_end = Vec::with_capacity(px.len());
        let ends = row_ends(&px);
        let hidden_side = hidden_side(&ends, depth, view.width);
        for &(u, v) in &px {
            let d = depth[(v * view.width + u) as usize] as f64;
            let dh = cal.fit.eval(d);
            if !(dh > 0.3) {
                continue;
            }
            let (dir, zf) = pixel_ray(view, u, v);
            let t = dh / zf;
            if t > cfg.max_range_m {
                continue;
            }
            pts.push([o[0] + dir[0] * t, o[1] + dir[1] * t, o[2] + dir[2] * t]);
            row_end.push(ends.get(&v).map_or(0i8, |&(lo, hi)| {
                if u == lo {
                    -1
                } else if u == hi {
                    1
                } else {
                    0
                }
            }));
        }
        if pts.len() < cfg.min_pixels {
            continue;
        }
        let mut xs: Vec<f64> = pts.iter().map(|p| p[0]).collect();
        let mut ys: Vec<f64> = pts.iter().map(|p| p[1]).collect();
        let mut zs: Vec<f64> = pts.iter().map(|p| p[2]).collect();
        let (mx, my) = (
            median(&mut xs).unwrap_or(0.0),
            median(&mut ys).unwrap_or(0.0),
        );
        let z = (percentile(&mut zs, 0.05), percentile(&mut zs, 0.95));
        // Main horizontal axis of the points (principal component).
        let spread = Spread::of(pts.iter().map(|p| [p[0], p[1]]));
        let (sxx, syy, sxy) = (spread.sxx, spread.syy, spread.sxy);
        let tr = sxx + syy;
        let det = sxx * syy - sxy * sxy;
        let disc = (tr * tr / 4.0 - det).max(0.0).sqrt();
        let (l1, l2) = (tr / 2.0 + disc, tr / 2.0 - disc);
        let heading = (l1 > 4.0 * l2.max(1e-12)).then(|| spread.axis_angle());
        let (vx, vy) = (mx - o[0], my - o[1]);
        let vl = vx.hypot(vy).max(1e-9);
        let view_dir = [vx / vl, vy / vl];
        let size = kind.size();
        // A vehicle's axis is the road's where the track knows it, else the points' main axis.
        let axis = kind
            .is_vehicle()
            .then(|| track.and_then(|t| t.road([mx, my])).map(|r| r.0))
            .flatten()
            .or(heading.map(|h| [h.cos(), h.sin()]));
        let xy = match axis {
            // An elongated asset seen along its side: the centre of the visible extent along the
            // axis, and half the width behind the median of the side facing the camera.
            Some(a) if size[0] >= 2.0 * size[1] => {
                let mut nrm = [-a[1], a[0]];
                if nrm[0] * view_dir[0] + nrm[1] * view_dir[1] < 0.0 {
                    nrm = [-nrm[0], -nrm[1]];
                }
                let mut along: Vec<f64> = pts.iter().map(|p| p[0] * a[0] + p[1] * a[1]).collect();
                let mut across: Vec<f64> =
                    pts.iter().map(|p| p[0] * nrm[0] + p[1] * nrm[1]).collect();
                // Where along the axis the instance's left and right image ends lie (before the
                // percentiles sort `along`).
                let side_along = |side: i8| {
                    let v: Vec<f64> = along
                        .iter()
                        .zip(&row_end)
                        .filter(|(_, e)| **e == side)
                        .map(|(s, _)| *s)
                        .collect();
                    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
                };
                let image_ends = [side_along(-1), side_along(1)];
                let (s0, s1) = (percentile(&mut along, 0.03), percentile(&mut along, 0.97));
                // Whether the image's left and right run along the asset's axis: seen end-on,
                // they are its sides, and neither the border nor an occluder says which end
                // shows.
                let lengthwise = matches!(image_ends,
                    [Some(lo), Some(hi)] if (lo - hi).abs() > 0.25 * (s1 - s0));
                // Seen short of its length, the asset shows one end whole: the end the image's
                // side edge or a nearer object does not hide, else the end nearer the camera
                // (the far end hides behind the body). Its centre is half a length from there.
                let near = o[0] * a[0] + o[1] * a[1];
                let s = if s1 - s0 < 0.8 * size[0] {
                    let hidden = hidden_side
                        .and_then(|side| image_ends[(side > 0) as usize])
                        .filter(|_| lengthwise);
                    let low_end = if let Some(hidden) = hidden {
                        // The image's edge or something nearer hides one end: the other end is
                        // the asset's.
                        hidden > (s0 + s1) / 2.0
                    } else {
                        (near - s0).abs() < (near - s1).abs()
                    };
                    if low_end {
                        s0 + size[0] / 2.0
                    } else {
                        s1 - size[0] / 2.0
                    }
                } else {
                    (s0 + s1) / 2.0
                };
                let q = median(&mut across).unwrap_or(0.0) + kind.visible_depth();
                [a[0] * s + nrm[0] * q, a[1] * s + nrm[1] * q]
            }
            // Otherwise the median pushed back along the viewing direction by the depth of the
            // asset's visible surface in front of its centre, and, for a round asset seen
            // narrower than it is with one side hidden (a tree in a row behind the next one's
            // crown, or cut by the frame), moved across the view to half a width from the side
            // that shows.
            _ => {
                let back = kind.visible_depth();
                let across = [view_dir[1], -view_dir[0]];
                let at = (mx - o[0]) * across[0] + (my - o[1]) * across[1];
                let shift = hidden_side
                    .and_then(|side| centre_across(&pts, &row_end, o, across, side, size[1]))
                    .map_or(0.0, |c| c - at);
                [
                    mx + view_dir[0] * back + across[0] * shift,
                    my + view_dir[1] * back + across[1] * shift,
                ]
            }
        };
        let weight = px.len() as f64 * if border.contains_key(&id) { 0.25 } else { 1.0 };
        out.push(Detection {
            class: class.clone(),
            kind,
            view: k,
            xy,
            z,
            heading,
            pixels: px.len(),
            weight,
        });
    }
    out
}

/// Where across the view (the coordinate along `across` from the camera at `o`, metres) a round
/// asset of width `width` stands, from its lifted points `pts`, when the image side `hidden` (-1
/// left, +1 right) is cut: half a width in from the end that shows. `None` when the points span
/// most of the width (nothing hidden to correct for) or when their left and right image ends do
/// not say which way the image's left runs across the view. `row_end` is each point's image row
/// end (-1, 0, +1).
fn centre_across(
    pts: &[[f64; 3]],
    row_end: &[i8],
    o: [f64; 3],
    across: [f64; 2],
    hidden: i8,
    width: f64,
) -> Option<f64> {
    let lateral: Vec<f64> = pts
        .iter()
        .map(|p| (p[0] - o[0]) * across[0] + (p[1] - o[1]) * across[1])
        .collect();
    let mean_at = |side: i8| {
        let v: Vec<f64> = lateral
            .iter()
            .zip(row_end)
            .filter(|(_, e)| **e == side)
            .map(|(l, _)| *l)
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    let (left, right) = (mean_at(-1)?, mean_at(1)?);
    if left == right {
        return None;
    }
    let mut sorted = lateral;
    let (l0, l1) = (percentile(&mut sorted, 0.03), percentile(&mut sorted, 0.97));
    if l1 - l0 >= 0.9 * width {
        return None;
    }
    // The side that shows, in `across` coordinates: the image's right when the left is hidden.
    let shows_high = (hidden < 0) == (right > left);
    Some(if shows_high {
        l1 - width / 2.0
    } else {
        l0 + width / 2.0
    })
}

/// Per image row of an instance, its leftmost and rightmost pixel.
fn row_ends(px: &[(u32, u32)]) -> BTreeMap<u32, (u32, u32)> {
    let mut ends: BTreeMap<u32, (u32, u32)> = BTreeMap::new();
    for &(u, v) in px {
        let e = ends.entry(v).or_insert((u, u));
        e.0 = e.0.min(u);
        e.1 = e.1.max(u);
    }
    ends
}

/// The image side (-1 left, +1 right) on which the instance is cut off, when one side is and
/// the other is not: in most rows that end lies on the image's edge, or the pixel just beyond
/// it reports a depth nearer than the end pixel's by more than half a metre (reported depths
/// keep their order under the affine bias), where an object's own end shows what lies behind
/// it. A vehicle parked behind another, or half out of the frame, is seen short of its length;
/// its centre is half a length from the end that shows, not from the hidden one. (The top and
/// bottom edges cut every part of a close vehicle alike and say nothing about its ends.)
fn hidden_side(ends: &BTreeMap<u32, (u32, u32)>, depth: &[f32], width: u32) -> Option<i8> {
    const GAP: f32 = 0.5;
    let mut share = [(0u32, 0u32); 2];
    for (&v, &(lo, hi)) in ends {
        let row = (v * width) as usize;
        let sides = [
            (lo, (lo > 1).then(|| lo - 1)),
            (hi, (hi + 2 < width).then_some(hi + 1)),
        ];
        for (k, (end, beyond)) in sides.into_iter().enumerate() {
            let Some(b) = beyond else {
                share[k] = (share[k].0 + 1, share[k].1 + 1);
                continue;
            };
            let (Some(&de), Some(&db)) =
                (depth.get(row + end as usize), depth.get(row + b as usize))
            else {
                continue;
            };
            if db.is_finite() && de.is_finite() {
                share[k].1 += 1;
                share[k].0 += (db < de - GAP) as u32;
            }
        }
    }
    let hidden = |(n, of): (u32, u32)| of > 0 && 2 * n > of;
    match (hidden(share[0]), hidden(share[1])) {
        (true, false) => Some(-1),
        (false, true) => Some(1),
        _ => None,
    }
}

/// Detections of one object, merged.
#[derive(Clone, Debug, PartialEq)]
pub struct Cluster {
    /// Class name.
    pub class: String,
    /// Asset.
    pub kind: AssetKind,
    /// Weighted median of the members' centres.
    pub xy: [f64; 2],
    /// Weighted median of the members' z ranges.
    pub z: (f64, f64),
    /// The strongest member's heading, if any member had one.
    pub heading: Option<f64>,
    /// Distinct views.
    pub views: usize,
    /// Sum of the members' weights.
    pub score: f64,
}

fn class_length(kind: AssetKind) -> f64 {
    let s = kind.size();
    s[0].max(s[1])
}

/// Greedy clustering per class: the strongest unassigned detection gathers every unassigned one
/// of its class within `cluster_factor` x the class length (at least 1 m); the cluster sits at
/// the weighted median of its members. Deterministic: ties are broken by view and input order.
pub fn cluster(dets: &[Detection], cfg: &ClutterConfig) -> Vec<Cluster> {
    let mut order: Vec<usize> = (0..dets.len()).collect();
    order.sort_by(|&a, &b| {
        dets[b]
            .weight
            .total_cmp(&dets[a].weight)
            .then(dets[a].view.cmp(&dets[b].view))
            .then(a.cmp(&b))
    });
    let mut used = vec![false; dets.len()];
    let mut out = Vec::new();
    for &s in &order {
        if used[s] {
            continue;
        }
        let seed = &dets[s];
        let r = (cfg.cluster_factor * class_length(seed.kind)).max(1.0);
        let members: Vec<usize> = order
            .iter()
            .copied()
            .filter(|&j| {
                !used[j]
                    && dets[j].class == seed.class
                    && (dets[j].xy[0] - seed.xy[0]).hypot(dets[j].xy[1] - seed.xy[1]) <= r
            })
            .collect();
        for &j in &members {
            used[j] = true;
        }
        let col = |f: &dyn Fn(&Detection) -> f64| {
            let mut v: Vec<(f64, f64)> = members
                .iter()
                .map(|&j| (f(&dets[j]), dets[j].weight))
                .collect();
            weighted_median(&mut v).unwrap_or(0.0)
        };
        let mut views: Vec<usize> = members.iter().map(|&j| dets[j].view).collect();
        views.sort_unstable();
        views.dedup();
        out.push(Cluster {
            class: seed.class.clone(),
            kind: seed.kind,
            xy: [col(&|d| d.xy[0]), col(&|d| d.xy[1])],
            z: (col(&|d| d.z.0), col(&|d| d.z.1)),
            heading: members.iter().find_map(|&j| dets[j].heading),
            views: views.len(),
            score: members.iter().map(|&j| dets[j].weight).sum(),
        });
    }
    out
}

/// Non-maximum suppression by class and distance: clusters in order of score (views first), each
/// suppressed when a kept one of its class lies within `nms_factor` x the class length (at least
/// 1.5 m). Returns the kept clusters and the number suppressed.
pub fn nms(mut clusters: Vec<Cluster>, cfg: &ClutterConfig) -> (Vec<Cluster>, usize) {
    clusters.sort_by(|a, b| {
        b.views
            .cmp(&a.views)
            .then(b.score.total_cmp(&a.score))
            .then(a.xy[0].total_cmp(&b.xy[0]))
            .then(a.xy[1].total_cmp(&b.xy[1]))
    });
    let mut kept: Vec<Cluster> = Vec::new();
    let mut suppressed = 0;
    for c in clusters {
        let r = (cfg.nms_factor * class_length(c.kind)).max(1.5);
        if kept
            .iter()
            .any(|k| k.class == c.class && (k.xy[0] - c.xy[0]).hypot(k.xy[1] - c.xy[1]) < r)
        {
            suppressed += 1;
        } else {
            kept.push(c);
        }
    }
    (kept, suppressed)
}

/// Where the cameras drove: street-view cars drive on roads, so the camera positions trace the
/// road axes.
pub struct Track {
    positions: Vec<[f64; 2]>,
}

impl Track {
    /// The views' positions.
    pub fn new(views: &[View]) -> Track {
        Track {
            positions: views
                .iter()
                .map(|v| [v.pose.position[0], v.pose.position[1]])
                .collect(),
        }
    }

    /// The road at `p`: of the streets the cameras drove within 30 m of it ([`Track::roads`]),
    /// the one whose axis passes nearest, as (unit axis, `p`'s distance from that axis).
    pub fn road(&self, p: [f64; 2]) -> Option<([f64; 2], f64)> {
        self.roads(p).into_iter().min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The streets the cameras drove within 30 m of `p`: lines through the camera positions
    /// there, each holding at least three of them (within `ROAD_TOL_M` of it) spread over 5 m
    /// along it, found strongest first, each with `p`'s distance from it. At a crossing the
    /// positions of both streets are in reach, and one axis fitted to them all runs
    /// diagonally between the two (a lamp post on a corner's pavement read as standing in the
    /// carriageway): each street is a line of its own.
    pub fn roads(&self, p: [f64; 2]) -> Vec<([f64; 2], f64)> {
        let mut near: Vec<[f64; 2]> = self
            .positions
            .iter()
            .copied()
            .filter(|q| (q[0] - p[0]).hypot(q[1] - p[1]) < 30.0)
            .collect();
        // Bounded work however dense the views: the nearest positions speak for the roads.
        if near.len() > ROAD_MAX_POSITIONS {
            near.sort_by(|a, b| {
                let da = (a[0] - p[0]).hypot(a[1] - p[1]);
                let db = (b[0] - p[0]).hypot(b[1] - p[1]);
                da.total_cmp(&db)
                    .then(a[0].total_cmp(&b[0]))
                    .then(a[1].total_cmp(&b[1]))
            });
            near.truncate(ROAD_MAX_POSITIONS);
        }
        let mut roads = Vec::new();
        while near.len() >= 3 && roads.len() < 4 {
            let Some((axis, centre, inliers)) = strongest_line(&near) else {
                break;
            };
            let (lo, hi) = inliers
                .iter()
                .map(|&k| (near[k][0] - centre[0]) * axis[0] + (near[k][1] - centre[1]) * axis[1])
                .fold((f64::MAX, f64::MIN), |(lo, hi), s| (lo.min(s), hi.max(s)));
            if hi - lo < 5.0 {
                break;
            }
            let lateral = ((p[0] - centre[0]) * -axis[1] + (p[1] - centre[1]) * axis[0]).abs();
            roads.push((axis, lateral));
            near = near
                .into_iter()
                .enumerate()
                .filter(|(k, _)| !inliers.contains(k))
                .map(|(_, q)| q)
                .collect();
        }
        roads
    }
}

/// Camera positions this close to a street's line are on it, metres: street-view cars keep
/// their lane, and a reported position is off by a metre or less.
const ROAD_TOL_M: f64 = 1.5;

/// Most camera positions a road query looks at (the nearest).
const ROAD_MAX_POSITIONS: usize = 48;

/// The line through two of `points` at least 5 m apart that the most points lie within
/// `ROAD_TOL_M` of (the first such pair on ties), refitted to those points: its unit axis, the
/// inliers' centroid and their indices; None with fewer than three on any line.
fn strongest_line(points: &[[f64; 2]]) -> Option<([f64; 2], [f64; 2], Vec<usize>)> {
    let inliers_of = |a: [f64; 2], axis: [f64; 2]| -> Vec<usize> {
        (0..points.len())
            .filter(|&k| {
                let (dx, dy) = (points[k][0] - a[0], points[k][1] - a[1]);
                (dx * -axis[1] + dy * axis[0]).abs() <= ROAD_TOL_M
            })
            .collect()
    };
    let mut best: Option<Vec<usize>> = None;
    for i in 0..points.len() {
        for j in i + 1..points.len() {
            let (dx, dy) = (points[j][0] - points[i][0], points[j][1] - points[i][1]);
            let len = dx.hypot(dy);
            if len < 5.0 {
                continue;
            }
            let inl = inliers_of(points[i], [dx / len, dy / len]);
            if best.as_ref().is_none_or(|b| inl.len() > b.len()) {
                best = Some(inl);
            }
        }
    }
    let inliers = best.filter(|b| b.len() >= 3)?;
    let spread = Spread::of(inliers.iter().map(|&k| points[k]));
    let a = spread.axis_angle();
    Some(([a.cos(), a.sin()], spread.centre, inliers))
}

/// Points' centroid and second moments about it (sums of dx², dy², dx dy).
struct Spread {
    centre: [f64; 2],
    sxx: f64,
    syy: f64,
    sxy: f64,
}

impl Spread {
    fn of(points: impl Iterator<Item = [f64; 2]> + Clone) -> Spread {
        let n = points.clone().count() as f64;
        let centre = [
            points.clone().map(|p| p[0]).sum::<f64>() / n,
            points.clone().map(|p| p[1]).sum::<f64>() / n,
        ];
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for p in points {
            let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
            sxx += dx * dx;
            syy += dy * dy;
            sxy += dx * dy;
        }
        Spread {
            centre,
            sxx,
            syy,
            sxy,
        }
    }

    /// Direction of the principal axis, radians.
    fn axis_angle(&self) -> f64 {
        0.5 * (2.0 * self.sxy).atan2(self.sxx - self.syy)
    }
}

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
        views: &[View],
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

/// The whole chain over a view set: calibration, lifting, clustering, NMS, grammar. Returns the
/// placed objects and the counts (detections, clusters, suppressed, each grammar rule, placed per
/// class, calibration figures).
pub fn place_clutter(
    views: &[View],
    twin: &Scene,
    terrain: &Raster,
    canopies: Option<&Scene>,
    cfg: &ClutterConfig,
) -> (Vec<Placed>, Metrics) {
    let cals = calibrate(views, twin, cfg);
    let track = Track::new(views);
    let dets: Vec<Detection> = views
        .par_iter()
        .zip(cals.par_iter())
        .enumerate()
        .flat_map_iter(|(k, (v, c))| {
            c.map(|c| lift_view(k, v, &c, Some(&track), cfg))
                .unwrap_or_default()
        })
        .collect();
    let mut m = Metrics::default();
    let fitted: Vec<&Calibration> = cals.iter().flatten().collect();
    m.set("views", views.len() as f64);
    m.set(
        "calibration_views_uncalibrated",
        cals.iter().filter(|c| c.is_none()).count() as f64,
    );
    m.set(
        "calibration_views_pooled",
        fitted.iter().filter(|c| c.pooled).count() as f64,
    );
    if !fitted.is_empty() {
        let mut a: Vec<f64> = fitted.iter().map(|c| c.fit.slope).collect();
        let mut b: Vec<f64> = fitted.iter().map(|c| c.fit.intercept).collect();
        m.set(
            "calibration_median_slope",
            median(&mut a).unwrap_or(f64::NAN),
        );
        m.set(
            "calibration_median_intercept_m",
            median(&mut b).unwrap_or(f64::NAN),
        );
    }
    m.set("detections", dets.len() as f64);
    let clusters = cluster(&dets, cfg);
    m.set("clusters", clusters.len() as f64);
    let (kept, suppressed) = nms(clusters, cfg);
    m.set("nms_suppressed", suppressed as f64);
    let ground = Ground::new(terrain, twin, views, canopies);
    let mut counts = BTreeMap::new();
    let mut placed = grammar(kept, &ground, cfg, &mut counts);
    placed.sort_by(|a, b| {
        a.class
            .cmp(&b.class)
            .then(a.xy[0].total_cmp(&b.xy[0]))
            .then(a.xy[1].total_cmp(&b.xy[1]))
    });
    for (k, v) in counts {
        m.set(k, v as f64);
    }
    for p in &placed {
        let key = format!("placed_{}", p.class);
        let n = m.get(&key).unwrap_or(0.0);
        m.set(key, n + 1.0);
    }
    m.set("placed", placed.len() as f64);
    (placed, m)
}

/// The placed objects as scene objects from the asset library, ids `<class>-<n>` (and
/// `<class>-<n>-trunk` for a tree's trunk), sunk 0.1 m into the terrain so slopes leave no gap.
pub fn instantiate(placed: &[Placed]) -> Scene {
    let mut n: BTreeMap<&str, usize> = BTreeMap::new();
    let mut objects = Vec::new();
    for p in placed {
        let k = n.entry(p.class.as_str()).or_default();
        let id = format!("{}-{}", p.class, *k);
        *k += 1;
        for part in p
            .kind
            .build(p.xy, p.heading, p.ground_z - 0.1, p.height_scale)
        {
            objects.push(SceneObject {
                id: format!("{id}{}", part.suffix),
                class: part.class,
                mesh: part.mesh,
            });
        }
    }
    Scene { objects }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hidden_end_is_the_one_cut_by_the_frame_or_by_something_nearer() {
        // A car 10 m away spans columns 5-14 of rows 2-5 in a 20-wide image; behind it (beyond
        // both ends) the street at 30 m.
        let (w, h) = (20u32, 8u32);
        let px: Vec<(u32, u32)> = (2..6).flat_map(|v| (5..15).map(move |u| (u, v))).collect();
        let ends = row_ends(&px);
        assert_eq!(ends[&3], (5, 14));
        let mut depth = vec![30.0f32; (w * h) as usize];
        for &(u, v) in &px {
            depth[(v * w + u) as usize] = 10.0;
        }
        assert_eq!(hidden_side(&ends, &depth, w), None, "both ends show");
        // A nearer car just right of it, at 6 m: its right end is hidden.
        for v in 0..h {
            depth[(v * w + 15) as usize] = 6.0;
        }
        assert_eq!(hidden_side(&ends, &depth, w), Some(1));
        // The same car cut by the frame's left edge instead: its left end is hidden.
        let px: Vec<(u32, u32)> = (2..6).flat_map(|v| (0..10).map(move |u| (u, v))).collect();
        let mut depth = vec![30.0f32; (w * h) as usize];
        for &(u, v) in &px {
            depth[(v * w + u) as usize] = 10.0;
        }
        assert_eq!(hidden_side(&row_ends(&px), &depth, w), Some(-1));
        // Cut by the bottom edge only (a close car's lower rows): nothing said about its ends.
        let px: Vec<(u32, u32)> = (4..8).flat_map(|v| (5..15).map(move |u| (u, v))).collect();
        let mut depth = vec![30.0f32; (w * h) as usize];
        for &(u, v) in &px {
            depth[(v * w + u) as usize] = 10.0;
        }
        assert_eq!(hidden_side(&row_ends(&px), &depth, w), None);
    }

    /// A crown 5.8 m wide, 20 m ahead of a camera looking along +y, of which only the part from
    /// x = -1 to x = 2.9 shows (the left hidden behind a nearer crown): its centre is half a
    /// width in from the right edge, at x = 0, not at the visible part's middle. With the image's
    /// left on the other side, or the whole width in view, nothing moves.
    #[test]
    fn a_crown_half_hidden_is_placed_from_the_side_that_shows() {
        let o = [0.0, 0.0, 1.5];
        // Looking along +y, the image's right is +x: `across` = (dir.y, -dir.x) = (1, 0).
        let across = [1.0, 0.0];
        let points = |x0: f64, x1: f64| {
            let mut pts = Vec::new();
            let mut ends = Vec::new();
            for row in 0..10 {
                for k in 0..=20 {
                    let x = x0 + (x1 - x0) * k as f64 / 20.0;
                    pts.push([x, 20.0, 3.0 + row as f64 * 0.3]);
                    ends.push(if k == 0 {
                        -1
                    } else if k == 20 {
                        1
                    } else {
                        0
                    });
                }
            }
            (pts, ends)
        };
        let (pts, ends) = points(-1.0, 2.9);
        let c = centre_across(&pts, &ends, o, across, -1, 5.8).unwrap();
        assert!(c.abs() < 1e-9, "{c}");
        // Hidden on the right instead: the left edge shows, the centre is half a width right of it.
        let c = centre_across(&pts, &ends, o, across, 1, 5.8).unwrap();
        assert!((c - 1.9).abs() < 1e-9, "{c}");
        // Mirrored image (left ends at high x): the hidden left is the high side.
        let flipped: Vec<i8> = ends.iter().map(|e| -e).collect();
        let c = centre_across(&pts, &flipped, o, across, -1, 5.8).unwrap();
        assert!((c - 1.9).abs() < 1e-9, "{c}");
        // The whole crown in view: nothing to correct.
        let (pts, ends) = points(-2.9, 2.9);
        assert_eq!(centre_across(&pts, &ends, o, across, -1, 5.8), None);
    }

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

    #[test]
    fn a_crossing_is_two_streets_not_one_axis_between_them() {
        // Cameras every 5 m along y = 9 and along x = 200, a few centimetres off their lines.
        let mut positions = Vec::new();
        for k in -6..=6 {
            let s = 5.0 * k as f64;
            let wobble = 0.05 * ((k * 7) % 3) as f64;
            positions.push([200.0 + s, 9.0 + wobble]);
            if k != 0 {
                positions.push([200.0 + wobble, 9.0 + s]);
            }
        }
        let track = Track { positions };
        // A lamp post on the corner's pavement: 6.3 m from one axis, 8.5 m from the other.
        let (axis, lateral) = track.road([206.3, 17.5]).unwrap();
        assert!((lateral - 6.3).abs() < 0.1, "lateral {lateral}");
        assert!(axis[0].abs() < 0.02, "axis {axis:?}");
        assert_eq!(track.roads([206.3, 17.5]).len(), 2);
        // A post in the middle of the crossing street's carriageway.
        let (_, lateral) = track.road([199.6, 94.6 - 85.0]).unwrap();
        assert!(lateral < 0.7, "lateral {lateral}");
        // One straight street: one road, the distance from its axis.
        let straight = Track {
            positions: (0..12).map(|k| [5.0 * k as f64, 3.0]).collect(),
        };
        let roads = straight.roads([20.0, 11.5]);
        assert_eq!(roads.len(), 1);
        assert!((roads[0].1 - 8.5).abs() < 1e-9);
        // Too few positions, or all at one place: no road.
        let parked = Track {
            positions: vec![[0.0, 0.0]; 10],
        };
        assert!(parked.road([0.0, 5.0]).is_none());
    }

    #[test]
    fn clustering_merges_views_and_nms_suppresses_neighbours() {
        let det = |view: usize, x: f64, w: f64| Detection {
            class: "car".into(),
            kind: AssetKind::Car,
            view,
            xy: [x, 0.0],
            z: (0.0, 1.5),
            heading: None,
            pixels: w as usize,
            weight: w,
        };
        let cfg = ClutterConfig::default();
        // Three views of one car within 0.5 m, and a fourth detection 4 m on.
        let dets = vec![
            det(0, 10.0, 100.0),
            det(1, 10.4, 80.0),
            det(2, 9.8, 50.0),
            det(3, 14.0, 20.0),
        ];
        let cl = cluster(&dets, &cfg);
        assert_eq!(cl.len(), 2);
        assert_eq!(cl[0].views, 3);
        assert_eq!(cl[0].xy[0], 10.0);
        let (kept, suppressed) = nms(cl, &cfg);
        assert_eq!((kept.len(), suppressed), (1, 1));
    }
}
