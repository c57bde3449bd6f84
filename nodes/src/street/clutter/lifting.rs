//! Lifting (paper Sec. 4.2.4): each view's depth calibrated against the twin with a Theil-Sen
//! affine fit, and its clutter instances lifted to world positions.

use std::collections::BTreeMap;

use crate::artifact::{Scene, View, Views};
use crate::geom::raycast::SceneRays;
use crate::geom::theil_sen::{LineFit, median, theil_sen};
use crate::stage::StageError;

use super::assets::AssetKind;
use super::config::ClutterConfig;
use super::spread::Spread;
use super::track::Track;

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
pub fn calibrate(
    views: Views,
    twin: &Scene,
    cfg: &ClutterConfig,
) -> Result<Vec<Option<Calibration>>, StageError> {
    let rays = SceneRays::new(twin);
    let samples: Vec<Vec<(f64, f64)>> =
        views.map(|_, v| calibration_samples(v, &rays, cfg.calib_stride))?;
    let fit = |s: &[(f64, f64)], seed: u64| {
        let (xs, ys): (Vec<f64>, Vec<f64>) = s.iter().copied().unzip();
        theil_sen(&xs, &ys, 0.5, 20_000, seed).filter(|f| f.slope > 0.0)
    };
    let pooled_samples: Vec<(f64, f64)> = samples.iter().flatten().copied().collect();
    let pooled = fit(&pooled_samples, cfg.seed ^ 0xF00D);
    Ok(samples
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
        .collect())
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
    let (pixels, border) = instance_pixels(view, &inst.ids);
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
        let Some(lifted) = LiftedInstance::lift(&px, view, depth, cal, cfg) else {
            continue;
        };
        let (mx, my) = lifted.median_xy();
        let z = lifted.z_range();
        let heading = lifted.main_axis_heading();
        let xy = lifted.centre(kind, track, heading, mx, my);
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

/// The pixels of each clutter instance of `view` (instance ids `ids`, 0 for none), and which
/// instances touch the image border. A step of its own: one pass over the image groups what the
/// per-instance steps then lift one by one.
fn instance_pixels(
    view: &View,
    ids: &[u16],
) -> (BTreeMap<u16, Vec<(u32, u32)>>, BTreeMap<u16, bool>) {
    let mut pixels: BTreeMap<u16, Vec<(u32, u32)>> = BTreeMap::new();
    let mut border: BTreeMap<u16, bool> = BTreeMap::new();
    for (i, &id) in ids.iter().enumerate() {
        if id == 0 {
            continue;
        }
        let (u, v) = (i as u32 % view.width, i as u32 / view.width);
        pixels.entry(id).or_default().push((u, v));
        if u == 0 || v == 0 || u + 1 == view.width || v + 1 == view.height {
            border.insert(id, true);
        }
    }
    (pixels, border)
}

/// One instance's pixels back-projected to the site frame, with what its centre is read from:
/// where each point's pixel ends its image row, which image side is cut, and the camera.
struct LiftedInstance {
    /// The lifted points, site frame.
    pts: Vec<[f64; 3]>,
    /// Which image side of its row each lifted point's pixel ends the instance on (-1 left, +1
    /// right, 0 neither).
    row_end: Vec<i8>,
    /// The image side on which the instance is cut off ([`hidden_side`]).
    hidden_side: Option<i8>,
    /// The camera's position.
    o: [f64; 3],
}

impl LiftedInstance {
    /// The pixels `px` lifted at their calibrated depth (`cal` on the view's `depth`), leaving out
    /// those nearer than 0.3 m or beyond `max_range_m`; None when fewer than `min_pixels` remain.
    fn lift(
        px: &[(u32, u32)],
        view: &View,
        depth: &[f32],
        cal: &Calibration,
        cfg: &ClutterConfig,
    ) -> Option<LiftedInstance> {
        let o = view.pose.position;
        let mut pts = Vec::with_capacity(px.len());
        let mut row_end = Vec::with_capacity(px.len());
        let ends = row_ends(px);
        let hidden_side = hidden_side(&ends, depth, view.width);
        for &(u, v) in px {
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
        (pts.len() >= cfg.min_pixels).then_some(LiftedInstance {
            pts,
            row_end,
            hidden_side,
            o,
        })
    }

    /// The per-coordinate median of the points on the ground plane.
    fn median_xy(&self) -> (f64, f64) {
        let mut xs: Vec<f64> = self.pts.iter().map(|p| p[0]).collect();
        let mut ys: Vec<f64> = self.pts.iter().map(|p| p[1]).collect();
        (
            median(&mut xs).unwrap_or(0.0),
            median(&mut ys).unwrap_or(0.0),
        )
    }

    /// The lowest and highest point, as the 5th and 95th percentile of z.
    fn z_range(&self) -> (f64, f64) {
        let mut zs: Vec<f64> = self.pts.iter().map(|p| p[2]).collect();
        (percentile(&mut zs, 0.05), percentile(&mut zs, 0.95))
    }

    /// Main horizontal axis of the points (principal component), radians (mod pi), when the
    /// spread along it is more than four times the spread across it.
    fn main_axis_heading(&self) -> Option<f64> {
        let spread = Spread::of(self.pts.iter().map(|p| [p[0], p[1]]));
        let (sxx, syy, sxy) = (spread.sxx, spread.syy, spread.sxy);
        let tr = sxx + syy;
        let det = sxx * syy - sxy * sxy;
        let disc = (tr * tr / 4.0 - det).max(0.0).sqrt();
        let (l1, l2) = (tr / 2.0 + disc, tr / 2.0 - disc);
        (l1 > 4.0 * l2.max(1e-12)).then(|| spread.axis_angle())
    }

    /// The asset's centre on the ground plane, from the median (`mx`, `my`): along its side for
    /// an elongated asset with a known axis, else behind the median. A vehicle's axis is the
    /// road's where the track knows it, else the points' main axis (`heading`).
    fn centre(
        &self,
        kind: AssetKind,
        track: Option<&Track>,
        heading: Option<f64>,
        mx: f64,
        my: f64,
    ) -> [f64; 2] {
        let o = self.o;
        let (vx, vy) = (mx - o[0], my - o[1]);
        let vl = vx.hypot(vy).max(1e-9);
        let view_dir = [vx / vl, vy / vl];
        let size = kind.size();
        let axis = kind
            .is_vehicle()
            .then(|| track.and_then(|t| t.road([mx, my])).map(|r| r.0))
            .flatten()
            .or(heading.map(|h| [h.cos(), h.sin()]));
        match axis {
            Some(a) if size[0] >= 2.0 * size[1] => self.centre_beside_axis(kind, a, view_dir),
            _ => self.centre_behind_median(kind, mx, my, view_dir),
        }
    }

    /// An elongated asset seen along its side: the centre of the visible extent along the axis
    /// `a`, and half the width behind the median of the side facing the camera.
    fn centre_beside_axis(&self, kind: AssetKind, a: [f64; 2], view_dir: [f64; 2]) -> [f64; 2] {
        let mut nrm = [-a[1], a[0]];
        if nrm[0] * view_dir[0] + nrm[1] * view_dir[1] < 0.0 {
            nrm = [-nrm[0], -nrm[1]];
        }
        let along: Vec<f64> = self.pts.iter().map(|p| p[0] * a[0] + p[1] * a[1]).collect();
        let mut across: Vec<f64> = self
            .pts
            .iter()
            .map(|p| p[0] * nrm[0] + p[1] * nrm[1])
            .collect();
        let s = self.centre_along_axis(along, a, kind.size()[0]);
        let q = median(&mut across).unwrap_or(0.0) + kind.visible_depth();
        [a[0] * s + nrm[0] * q, a[1] * s + nrm[1] * q]
    }

    /// Where along the axis `a` an asset of length `length` has its centre, from the points'
    /// coordinates `along` it: the middle of their extent, or, seen short of its length, half a
    /// length from the end that shows. A step of its own: which end shows is read from the image
    /// ends, the cut side and the camera.
    fn centre_along_axis(&self, mut along: Vec<f64>, a: [f64; 2], length: f64) -> f64 {
        // Where along the axis the instance's left and right image ends lie (before the
        // percentiles sort `along`).
        let side_along = |side: i8| {
            let v: Vec<f64> = along
                .iter()
                .zip(&self.row_end)
                .filter(|(_, e)| **e == side)
                .map(|(s, _)| *s)
                .collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        let image_ends = [side_along(-1), side_along(1)];
        let (s0, s1) = (percentile(&mut along, 0.03), percentile(&mut along, 0.97));
        // Whether the image's left and right run along the asset's axis: seen end-on, they are
        // its sides, and neither the border nor an occluder says which end shows.
        let lengthwise = matches!(image_ends,
            [Some(lo), Some(hi)] if (lo - hi).abs() > 0.25 * (s1 - s0));
        // Seen short of its length, the asset shows one end whole: the end the image's side edge
        // or a nearer object does not hide, else the end nearer the camera (the far end hides
        // behind the body). Its centre is half a length from there.
        let o = self.o;
        let near = o[0] * a[0] + o[1] * a[1];
        if s1 - s0 < 0.8 * length {
            let hidden = self
                .hidden_side
                .and_then(|side| image_ends[(side > 0) as usize])
                .filter(|_| lengthwise);
            let low_end = if let Some(hidden) = hidden {
                // The image's edge or something nearer hides one end: the other end is the
                // asset's.
                hidden > (s0 + s1) / 2.0
            } else {
                (near - s0).abs() < (near - s1).abs()
            };
            if low_end {
                s0 + length / 2.0
            } else {
                s1 - length / 2.0
            }
        } else {
            (s0 + s1) / 2.0
        }
    }

    /// Otherwise the median (`mx`, `my`) pushed back along the viewing direction by the depth of
    /// the asset's visible surface in front of its centre, and, for a round asset seen narrower
    /// than it is with one side hidden (a tree in a row behind the next one's crown, or cut by
    /// the frame), moved across the view to half a width from the side that shows.
    fn centre_behind_median(
        &self,
        kind: AssetKind,
        mx: f64,
        my: f64,
        view_dir: [f64; 2],
    ) -> [f64; 2] {
        let o = self.o;
        let back = kind.visible_depth();
        let across = [view_dir[1], -view_dir[0]];
        let at = (mx - o[0]) * across[0] + (my - o[1]) * across[1];
        let shift = self
            .hidden_side
            .and_then(|side| {
                centre_across(&self.pts, &self.row_end, o, across, side, kind.size()[1])
            })
            .map_or(0.0, |c| c - at);
        [
            mx + view_dir[0] * back + across[0] * shift,
            my + view_dir[1] * back + across[1] * shift,
        ]
    }
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
}
