//! One view's relief votes: its regions (connected pixels of one non-wall instance, or
//! unlabelled pixels a wall encloses), their cues (depth step, normal flow, semantic prior),
//! g(v), and the per-pixel codes the fusion deposits.

use std::collections::BTreeMap;

use glam::DVec3;

use crate::artifact::{ChartSet, Instances, View};
use crate::geom::raycast::SceneRays;
use crate::raster::label::label_regions;
use crate::raster::morph::dilate;

use super::calibrate::{calibrate, median_se};
use super::lookup::Lookup;
use super::params::ReliefParams;
use super::silhouette::past_silhouette;

/// What one kept region of one view said, located on a chart.
#[derive(Clone, Debug, PartialEq)]
pub struct RegionVote {
    /// View index.
    pub view: u32,
    /// Chart its centre ray hit.
    pub chart: u32,
    /// Its centre in texel coordinates (after the protrusion displacement).
    pub uv: (f64, f64),
    /// Semantic class (`unknown` for unlabelled pixels).
    pub class: String,
    /// g(v): -1, 0, +1.
    pub sign: i8,
    /// Depth step against the surrounding wall plane, metres, + out; NaN where not measured.
    pub step_m: f64,
    /// Pixels.
    pub pixels: u32,
}

/// Per-pixel codes of a view's relief labels.
pub(super) const RECESSED: i8 = -1;
pub(super) const NEUTRAL: i8 = 0;
pub(super) const PROTRUDING: i8 = 1;
const SEEN: i8 = 2;
pub(super) const MASKED: i8 = 3;

/// One view's labels: per pixel a code, the displacement of protruding pixels, and its regions.
pub struct ViewRelief {
    pub(super) codes: Vec<i8>,
    pub(super) displace: Vec<f32>,
    /// Kept regions.
    pub regions: Vec<RegionVote>,
    /// Candidate regions before the enclosure test.
    pub candidates: u64,
    /// Whether the depth calibrated.
    pub calibrated: bool,
}

/// Region key of the unlabelled pixels with a depth that face sideways: walls and features the
/// segmentation missed.
const UNLABELLED: u32 = 1 << 16;

/// Region key of the unlabelled pixels that face up: the ground, roofs. Kept apart from
/// [`UNLABELLED`], or a missed drainpipe or door that reaches the ground joins the street's
/// whole surface in one region that nothing encloses, and its pixels vote for a flat wall.
const UNLABELLED_LEVEL: u32 = UNLABELLED + 1;

/// A pixel whose normal's upward component is at least this faces up (45 degrees).
const LEVEL_NZ: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// A region's mean width in pixels (pixels over its longer side) under which its faces are not
/// told apart by their normals: at a few pixels across every pixel borders a silhouette, where
/// the depth and normal a model predicts mix the feature with the wall behind it (a drainpipe
/// 1-3 pixels across read 0.1-0.2 m prouder on its "front" pixels than it stands).
const FACE_MIN_PX: f64 = 4.0;

/// What every step of one view's relief reads: the view, the twin, the parameters, the view's
/// model outputs (those of the view's size) and its depth calibration.
struct ViewCtx<'a> {
    vi: usize,
    view: &'a View,
    rays: &'a SceneRays,
    charts: &'a ChartSet,
    lookup: &'a Lookup,
    p: &'a ReliefParams,
    arch: &'a Instances,
    depth: Option<&'a [f32]>,
    normals: Option<&'a [[f32; 3]]>,
    /// (a, b) with reported depth = a z + b.
    cal: Option<(f64, f64)>,
    origin: [f32; 3],
}

/// A pixel the clutter mask removes from the relief.
fn masked(view: &View, p: &ReliefParams, px: usize) -> bool {
    p.mask_clutter
        && view
            .clutter
            .as_ref()
            .is_some_and(|c| c.ids.get(px).is_some_and(|&id| id != 0))
}

impl ViewCtx<'_> {
    fn masked(&self, px: usize) -> bool {
        masked(self.view, self.p, px)
    }

    fn class_of(&self, px: usize) -> Option<&str> {
        let id = self.arch.ids[px];
        (id != 0)
            .then(|| self.arch.classes.get(&id).map(String::as_str))
            .flatten()
    }

    fn is_wall(&self, px: usize) -> bool {
        self.class_of(px) == Some(self.p.wall_class.as_str())
    }

    fn is_ground(&self, px: usize) -> bool {
        self.arch.ids[px] == 0 && !self.masked(px)
    }

    fn is_sky(&self, px: usize) -> bool {
        self.arch.ids[px] == 0 && self.depth.is_some_and(|d| !d[px].is_finite())
    }

    /// A pixel's calibrated point in the site frame; None without a finite depth.
    fn point(&self, px: usize, (a, b): (f64, f64)) -> Option<DVec3> {
        let view = self.view;
        let w = view.width;
        let d = self.depth?[px] as f64;
        if !d.is_finite() {
            return None;
        }
        let z = (d - b) / a;
        let (x, y) = ((px as u32 % w) as f64 + 0.5, (px as u32 / w) as f64 + 0.5);
        let (dir, norm) = view.pixel_ray(x, y);
        Some(DVec3::from(view.pose.position) + DVec3::from(dir) * z * norm)
    }

    /// A side-face pixel: its normal further than `cos_side` (as a cosine) from the wall's `nrm`.
    fn is_side(&self, q: u32, nrm: DVec3, cos_side: f64) -> bool {
        self.normals.is_some_and(|nm| {
            let ns = self.view.pose.to_site(nm[q as usize].map(|c| c as f64));
            DVec3::from(ns).dot(nrm) < cos_side
        })
    }

    /// The wall chart a pixel's ray meets first, if any.
    fn wall_chart_at(&self, px: usize) -> Option<u32> {
        let w = self.view.width;
        let (x, y) = (
            (px % w as usize) as f64 + 0.5,
            (px / w as usize) as f64 + 0.5,
        );
        let (d, _) = self.view.pixel_ray(x, y);
        self.rays
            .cast(self.origin, d.map(|c| c as f32), 1e-3, 2000.0)
            .and_then(|h| self.lookup.wall_chart(self.charts, h.object, h.triangle))
    }
}

/// The relief labels of one view: regions, their cues, g(v), and the per-pixel codes.
pub(super) fn view_relief(
    vi: usize,
    view: &View,
    rays: &SceneRays,
    charts: &ChartSet,
    lookup: &Lookup,
    p: &ReliefParams,
) -> ViewRelief {
    let (w, h) = (view.width, view.height);
    let n = (w * h) as usize;
    let mut out = ViewRelief {
        codes: vec![SEEN; n],
        displace: Vec::new(),
        regions: Vec::new(),
        candidates: 0,
        calibrated: false,
    };
    let Some(arch) = view.arch.as_ref().filter(|a| a.ids.len() == n) else {
        for (px, c) in out.codes.iter_mut().enumerate() {
            if masked(view, p, px) {
                *c = MASKED;
            }
        }
        return out;
    };
    let mut cx = ViewCtx {
        vi,
        view,
        rays,
        charts,
        lookup,
        p,
        arch,
        depth: view.depth.as_ref().filter(|d| d.len() == n).map(|d| &d[..]),
        normals: view
            .normal
            .as_ref()
            .filter(|d| d.len() == n)
            .map(|d| &d[..]),
        cal: None,
        origin: view.pose.position.map(|c| c as f32),
    };
    let cal = cx.depth.and_then(|_| {
        calibrate(view, rays, charts, lookup, &|px| cx.is_wall(px), &|px| {
            cx.is_ground(px)
        })
    });
    cx.cal = cal;
    out.calibrated = cal.is_some();
    let members = region_members(&cx, &mut out.codes);
    out.candidates = members.len() as u64;
    let mut kept = vec![false; members.len()];
    for (ri, pixels) in members.values().enumerate() {
        kept[ri] = judge_region(&cx, pixels, &mut out);
    }
    // A labelled region the view could not judge (no wall around it, or its centre ray on no
    // wall) says nothing about the relief there: its pixels neither vote nor count as exposure,
    // which as exposure alone they would, for flat wall. Unlabelled pixels stay exposure: most
    // are wall the segmentation missed.
    for (ri, pixels) in members.values().enumerate() {
        if !kept[ri] && arch.ids[pixels[0] as usize] != 0 {
            for &q in pixels {
                out.codes[q as usize] = MASKED;
            }
        }
    }
    out
}

/// The view's candidate regions, label -> pixels: connected pixels of one non-wall instance, or
/// of the unlabelled pixels with a depth (facing sideways or up apart). Marks masked pixels
/// MASKED and wall pixels NEUTRAL in `codes`.
fn region_members(cx: &ViewCtx, codes: &mut [i8]) -> BTreeMap<u32, Vec<u32>> {
    let (view, arch, p) = (cx.view, cx.arch, cx.p);
    let (w, h) = (view.width, view.height);
    let n = (w * h) as usize;
    // Region keys: a non-wall instance's id, or all unlabelled pixels with a depth.
    let mut key = vec![0u32; n];
    for px in 0..n {
        if cx.masked(px) {
            codes[px] = MASKED;
            continue;
        }
        let id = arch.ids[px];
        if id == 0 {
            let has_depth = cx.depth.is_some_and(|d| d[px].is_finite());
            if has_depth {
                let level = cx
                    .normals
                    .is_some_and(|nm| view.pose.to_site(nm[px].map(|c| c as f64))[2] >= LEVEL_NZ);
                key[px] = if level { UNLABELLED_LEVEL } else { UNLABELLED };
            }
            continue;
        }
        match arch.classes.get(&id) {
            Some(c) if *c == p.wall_class => codes[px] = NEUTRAL,
            Some(c) if p.ignore_classes.contains(c) => {}
            _ => key[px] = id as u32,
        }
    }
    let labels = label_regions(&key, w, h, p.min_region_px as usize);
    let mut members: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (px, &l) in labels.iter().enumerate() {
        if l != 0 {
            members.entry(l).or_default().push(px as u32);
        }
    }
    members
}

/// A region's pixel bounding box (inclusive) and centre.
struct RegionBox {
    x0: u32,
    y0: u32,
    x1: u32,
    y1: u32,
    cx: f64,
    cy: f64,
}

fn region_box(pixels: &[u32], w: u32) -> RegionBox {
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
    let (mut sx, mut sy) = (0.0, 0.0);
    for &q in pixels {
        let (x, y) = (q % w, q / w);
        x0 = x0.min(x);
        y0 = y0.min(y);
        x1 = x1.max(x);
        y1 = y1.max(y);
        sx += x as f64 + 0.5;
        sy += y as f64 + 0.5;
    }
    let (cx, cy) = (sx / pixels.len() as f64, sy / pixels.len() as f64);
    RegionBox {
        x0,
        y0,
        x1,
        y1,
        cx,
        cy,
    }
}

/// The ring around a region (`ring_px` wide): its pixels that count (not masked, not sky), the
/// wall pixels among them with their wall id, and the unlabelled ones.
struct Ring {
    total: u32,
    walls: Vec<(usize, u16)>,
    plain: Vec<usize>,
}

fn ring(cx: &ViewCtx, pixels: &[u32], b: &RegionBox, codes: &[i8]) -> Ring {
    let (w, h) = (cx.view.width, cx.view.height);
    let r = cx.p.ring_px as i64;
    // Bounding box, then the ring in a crop around it.
    let bx0 = (b.x0 as i64 - r).max(0) as u32;
    let by0 = (b.y0 as i64 - r).max(0) as u32;
    let bx1 = (b.x1 as i64 + r).min(w as i64 - 1) as u32;
    let by1 = (b.y1 as i64 + r).min(h as i64 - 1) as u32;
    let (cw, ch) = (bx1 - bx0 + 1, by1 - by0 + 1);
    let mut mask = vec![false; (cw * ch) as usize];
    for &q in pixels {
        let (x, y) = (q % w - bx0, q / w - by0);
        mask[(y * cw + x) as usize] = true;
    }
    let grown = dilate(&mask, cw, ch, r);
    let mut out = Ring {
        total: 0,
        walls: Vec::new(),
        plain: Vec::new(),
    };
    for yy in 0..ch {
        for xx in 0..cw {
            let k = (yy * cw + xx) as usize;
            if !grown[k] || mask[k] {
                continue;
            }
            let px = ((yy + by0) * w + xx + bx0) as usize;
            // Sky past a wall's edge (no label, no depth) neither encloses a region nor
            // speaks against it: a drainpipe by a corner has it on one side.
            if codes[px] == MASKED || cx.is_sky(px) {
                continue;
            }
            out.total += 1;
            if cx.is_wall(px) {
                out.walls.push((px, cx.arch.ids[px]));
            } else if cx.arch.ids[px] == 0 {
                out.plain.push(px);
            }
        }
    }
    out
}

/// The semantic class of the region whose first pixel is `first` (`unknown` unlabelled).
fn region_class(arch: &Instances, first: usize) -> String {
    match arch.ids[first] {
        0 => "unknown".to_owned(),
        id => arch
            .classes
            .get(&id)
            .cloned()
            .unwrap_or_else(|| "unknown".into()),
    }
}

/// Judges one candidate region: its vote pushed onto `out.regions` and its pixels' codes set.
/// Whether it was kept.
fn judge_region(cx: &ViewCtx, pixels: &[u32], out: &mut ViewRelief) -> bool {
    let (view, charts, p, cal) = (cx.view, cx.charts, cx.p, cx.cal);
    let w = view.width;
    let class = region_class(cx.arch, pixels[0] as usize);
    let b = region_box(pixels, w);
    let ring = ring(cx, pixels, &b, &out.codes);
    // Enclosed by walls: the two façades of a corner are often two instances, each holding
    // half the ring of a feature at the corner.
    let walls = ring.walls.len();
    let enough = |n: usize| n > 0 && n as f64 >= p.enclosure_min * ring.total as f64;
    let walled = enough(walls);
    // The region's chart: where its centre ray meets the twin.
    let (dir, _) = view.pixel_ray(b.cx, b.cy);
    let hit = cx.rays.cast(cx.origin, dir.map(|c| c as f32), 1e-3, 2000.0);
    if let Some(vote) = past_corner_vote(cx, pixels, &b, &class, dir, hit.map(|h| h.t as f64)) {
        for &q in pixels {
            out.codes[q as usize] = MASKED;
        }
        out.regions.push(vote);
        return true;
    }
    if !walled && (cal.is_none() || ring.plain.is_empty()) {
        return false;
    }
    let Some(hit) = hit else {
        return false;
    };
    let Some(ci) = cx.lookup.wall_chart(charts, hit.object, hit.triangle) else {
        return false;
    };
    let chart = &charts.charts[ci as usize];
    let nrm = DVec3::from(chart.normal);
    // Where the segmentation missed the wall (its pixels unlabelled), the depth still tells
    // it: unlabelled ring pixels that lie on the chart's plane enclose as wall.
    let on_plane: Vec<usize> = match cal {
        Some(cal) if !walled => {
            let plane = DVec3::from(chart.origin).dot(nrm);
            ring.plain
                .iter()
                .copied()
                .filter(|&px| {
                    cx.point(px, cal)
                        .is_some_and(|x| (x.dot(nrm) - plane).abs() <= p.plane_tol_m)
                })
                .collect()
        }
        _ => Vec::new(),
    };
    if !walled && !enough(walls + on_plane.len()) {
        return false;
    }
    let wall_id = region_wall(&ring.walls, ci, |px| cx.wall_chart_at(px));
    // A side-face pixel: its normal further than side_angle_deg from the wall's.
    let cos_side = p.side_angle_deg.to_radians().cos();
    let is_side = |q: u32| cx.is_side(q, nrm, cos_side);
    let wall_ring = ring
        .walls
        .iter()
        .filter(|&&(_, id)| id == wall_id)
        .map(|&(px, _)| px)
        .chain(on_plane.iter().copied());
    let (step, v_depth) = depth_cue(cx, pixels, &b, wall_ring, nrm, &is_side);
    let v_normal = normal_cue(cx, pixels, &b, &is_side);
    let v_sem = p
        .classes
        .iter()
        .find(|c| c.name == class)
        .map_or(0.0, |c| c.prior as f64);
    let score =
        p.weights.semantic * v_sem + p.weights.depth * v_depth + p.weights.normal * v_normal;
    let sign: i8 = if score >= p.score_min && score > 0.0 {
        1
    } else if score <= -p.score_min && score < 0.0 {
        -1
    } else {
        0
    };
    let disp = deposit(cx, pixels, &class, sign, step, &is_side, out);
    let t = hit.t as f64 - disp / (-nrm.dot(DVec3::from(dir))).max(1e-3);
    let at: [f64; 3] = std::array::from_fn(|k| view.pose.position[k] + dir[k] * t);
    out.regions.push(RegionVote {
        view: cx.vi as u32,
        chart: ci,
        uv: chart.uv_of(at),
        class,
        sign,
        step_m: step,
        pixels: pixels.len() as u32,
    });
    true
}

/// A protruding feature by a corner, seen from the street round it, stands past the twin's
/// silhouette, against the sky or a street behind: its centre ray (`dir`, meeting the twin at
/// `hit`) meets nothing, or something well beyond where its pixels' depth puts it, and no wall
/// encloses it. It stands on the wall this view sees from behind, whose end that ray passes
/// within the class's depth and the region's half-width. Its pixels say nothing of the surfaces
/// their rays meet, so only the region votes, by its label. None where the region is not such a
/// feature.
fn past_corner_vote(
    cx: &ViewCtx,
    pixels: &[u32],
    b: &RegionBox,
    class: &str,
    dir: [f64; 3],
    hit_t: Option<f64>,
) -> Option<RegionVote> {
    let p = cx.p;
    let prior = p
        .classes
        .iter()
        .find(|c| c.name == class)
        .map_or(0, |c| c.prior);
    let (true, Some(cal)) = (prior > 0, cx.cal) else {
        return None;
    };
    let depth = |q: usize| cx.point(q, cal);
    let reach = p.depth_range(class, 1).1;
    let seen = (pixels, (b.x0, b.x1, b.cy), DVec3::from(dir));
    let (ci, at) = past_silhouette(cx.view, seen, hit_t, depth, cx.charts, reach)?;
    let score = p.weights.semantic * prior as f64;
    let sign: i8 = if score >= p.score_min { 1 } else { 0 };
    Some(RegionVote {
        view: cx.vi as u32,
        chart: ci,
        uv: cx.charts.charts[ci as usize].uv_of(at.to_array()),
        class: class.to_owned(),
        sign,
        step_m: f64::NAN,
        pixels: pixels.len() as u32,
    })
}

/// Depth cue: (the step, metres, + out, NaN where not measured; its sign where significant, else
/// 0) of the region against the plane with the wall's normal `nrm` fitted to `wall_ring` (the
/// ring pixels on the region's own wall). What spoils a region's median lies between the wall
/// and the feature's face: a jamb, a reveal or a slab's underside (balconies read 0.15 m short
/// over all their pixels), or the wall the mask spills onto (on a 0.12 m drainpipe, more of its
/// pixels than its front). The median over the faces parallel to the wall and the median over
/// all pixels both err toward the wall, so of the two the one farther from it is taken; on a
/// region under FACE_MIN_PX across, all pixels.
fn depth_cue(
    cx: &ViewCtx,
    pixels: &[u32],
    b: &RegionBox,
    wall_ring: impl Iterator<Item = usize>,
    nrm: DVec3,
    is_side: &dyn Fn(u32) -> bool,
) -> (f64, f64) {
    let p = cx.p;
    let mut step = f64::NAN;
    let mut v_depth = 0.0;
    let Some(cal) = cx.cal else {
        return (step, v_depth);
    };
    let mut ring_s: Vec<f64> = wall_ring
        .filter_map(|px| cx.point(px, cal))
        .map(|x| x.dot(nrm))
        .collect();
    // Each pixel's offset from the wall, and whether it lies on a face parallel to it.
    let at: Vec<(f64, bool)> = pixels
        .iter()
        .filter_map(|&q| cx.point(q as usize, cal).map(|x| (x.dot(nrm), !is_side(q))))
        .collect();
    let across = pixels.len() as f64 / (b.x1 - b.x0 + 1).max(b.y1 - b.y0 + 1) as f64;
    let mut front_s: Vec<f64> = if across >= FACE_MIN_PX {
        at.iter().filter(|a| a.1).map(|a| a.0).collect()
    } else {
        Vec::new()
    };
    let mut reg_s: Vec<f64> = at.iter().map(|a| a.0).collect();
    if ring_s.len() >= 5 && reg_s.len() >= 5 {
        let (off, se0) = median_se(&mut ring_s);
        let (mut m, mut se1) = median_se(&mut reg_s);
        if front_s.len() >= 5 {
            let (mf, sef) = median_se(&mut front_s);
            if (mf - off).abs() > (m - off).abs() {
                (m, se1) = (mf, sef);
            }
        }
        step = m - off;
        let se = (se0 * se0 + se1 * se1).sqrt().max(1e-4);
        if step.abs() >= p.min_step_m && step.abs() / se >= p.step_z_min {
            v_depth = step.signum();
        }
    }
    (step, v_depth)
}

/// Normal cue: side faces' normals point toward a recess's centre, away from a protrusion's
/// (image-plane flow). Its sign where enough of the region is side faces that agree, else 0.
fn normal_cue(cx: &ViewCtx, pixels: &[u32], b: &RegionBox, is_side: &dyn Fn(u32) -> bool) -> f64 {
    let (p, w) = (cx.p, cx.view.width);
    let mut v_normal = 0.0;
    if let Some(nm) = cx.normals {
        let (mut side, mut flow) = (0u32, 0.0);
        for &q in pixels {
            if !is_side(q) {
                continue;
            }
            let nc = nm[q as usize].map(|c| c as f64);
            side += 1;
            let (x, y) = ((q % w) as f64 + 0.5 - b.cx, (q / w) as f64 + 0.5 - b.cy);
            let f = nc[0] * x + nc[1] * y;
            flow += if f > 0.0 {
                1.0
            } else if f < 0.0 {
                -1.0
            } else {
                0.0
            };
        }
        if side as f64 >= p.min_side_share * pixels.len() as f64 && side > 0 {
            let f = flow / side as f64;
            if f.abs() >= p.flow_min {
                v_normal = f.signum();
            }
        }
    }
    v_normal
}

/// A region's pixels' codes (`sign`) and, for a protrusion, its displacement: it is deposited on
/// the plane where it stands, its measured `step` within its class's range. Returns that
/// displacement (0 for none).
fn deposit(
    cx: &ViewCtx,
    pixels: &[u32],
    class: &str,
    sign: i8,
    step: f64,
    is_side: &dyn Fn(u32) -> bool,
    out: &mut ViewRelief,
) -> f64 {
    let n = out.codes.len();
    // A protrusion is deposited on the plane where it stands.
    let disp = if sign > 0 && step.is_finite() && step > 0.0 {
        let (_, hi) = cx.p.depth_range(class, 1);
        step.min(hi)
    } else {
        0.0
    };
    if disp > 0.0 && out.displace.is_empty() {
        out.displace = vec![0.0; n];
    }
    // Only a protrusion's front face lies on the plane it is deposited on: a side-face
    // pixel met at a smaller offset would land up to `disp` x tan(theta) short of where it
    // stands, on the wall beside it (a drainpipe by a corner smeared over the corner's
    // texels). Side faces, told by their normals, neither vote nor count as exposure.
    for &q in pixels {
        if disp > 0.0 && is_side(q) {
            out.codes[q as usize] = MASKED;
            continue;
        }
        out.codes[q as usize] = sign;
        if disp > 0.0 {
            out.displace[q as usize] = disp as f32;
        }
    }
    disp
}

/// The wall instance a region stands on, among those in its ring (`ring`: pixel and wall id):
/// the one whose ring pixels' rays (`chart_at`; three of them: first, middle and last) meet the
/// region's chart `chart` most often, then the one with most ring pixels. At a corner the other
/// façade can hold as much of the ring, and the depth step must be measured against the region's
/// own wall.
fn region_wall(ring: &[(usize, u16)], chart: u32, chart_at: impl Fn(usize) -> Option<u32>) -> u16 {
    let mut by_id: BTreeMap<u16, Vec<usize>> = BTreeMap::new();
    for &(px, id) in ring {
        by_id.entry(id).or_default().push(px);
    }
    let score = |pxs: &Vec<usize>| -> (u32, usize) {
        let meets = if by_id.len() == 1 {
            0
        } else {
            [0, pxs.len() / 2, pxs.len() - 1]
                .iter()
                .filter(|&&k| chart_at(pxs[k]) == Some(chart))
                .count() as u32
        };
        (meets, pxs.len())
    };
    by_id
        .iter()
        .map(|(&id, pxs)| (score(pxs), id))
        .max_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)))
        .map_or(0, |(_, id)| id)
}
