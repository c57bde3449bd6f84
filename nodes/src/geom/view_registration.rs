//! Pose refinement of street views against the twin's silhouettes.
//!
//! The paper registers views from their metadata alone (Sec. 4.2) and argues that classical
//! pose refinement has nothing to anchor to, since the landmarks it would use are the façade
//! features still missing from the scene. The building outlines are not missing: the twin of
//! Sec. 4.1 has them. So each view's reported position (east, north) and heading are moved
//! within a bounded window to where the twin, rendered from the view, best agrees with what the
//! view's own segmentation says is building, sky and ground. Relief is the stage that needs it:
//! half a metre of metadata error moves every window a view deposits by half a metre, which at
//! IoU 0.5 on a 1.4 m window loses most of them (BENCHMARKS.md, issue 13).
//!
//! The search, per view: a 7 x 7 x 5 grid over (dx, dy, dyaw) scored on a coarse pixel lattice,
//! then pattern searches from its best few poses on finer lattices kept near the label edges
//! (the only pixels a small move changes), with the metadata as a weak prior. A second pass runs
//! every view again with the window and door labels the placed views pooled (less its own) as a
//! further cue, which places the views that face one wall from edge to edge. Camera height,
//! pitch and roll are kept from the metadata. A view stays where its metadata put it when the
//! best pose does not beat the reported one by `min_gain`, lies on the edge of the search window,
//! or agrees on less than `min_agreement`: a flat wall seen head-on cannot say where along it
//! the camera stood, and a pose found in noise is worse than the metadata.

use std::collections::HashMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ObjectClass, Pose, Scene, View};
use crate::geom::raycast::SceneRays;
use crate::raster::morph::dilate_square;
use crate::stage::Progress;

/// Knobs of the refinement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegistrationParams {
    /// Largest horizontal move searched, each axis, metres. Default 1.5 (three standard
    /// deviations of phone-grade metadata after a provider's own structure from motion).
    pub search_m: f64,
    /// Largest heading change searched, degrees. Default 3.
    pub search_deg: f64,
    /// About this many pixels, on a regular lattice, score the coarse grid of poses; the
    /// refinement rounds use a lattice four times finer each way, kept to the pixels near a
    /// change of label. Default 1200 (every 8th pixel of a 320 x 240 view).
    pub samples: u32,
    /// The refined pose must beat the reported one by this share of the counted pixels.
    /// Default 0.005.
    pub min_gain: f64,
    /// The metadata as a prior: a candidate's agreement is lowered by this times its squared
    /// move in units of the search window (dx² / search_m² + dy² / search_m² + dyaw² /
    /// search_deg²), so that among poses the silhouettes barely tell apart the one nearer the
    /// metadata wins (heading and sideways move trade off for a distant wall). Default 0.005.
    pub prior_weight: f64,
    /// A view whose best pose still agrees on less than this share is left alone: the twin
    /// does not explain it (a missed wall, a view into a courtyard the twin lacks). Default 0.5.
    pub min_agreement: f64,
    /// Rays longer than this count as sky, metres. Default 2000.
    pub max_range_m: f64,
    /// The architectural class of walls, whose instances tell one building from the next.
    /// Default "wall".
    pub wall_class: String,
    /// The architectural class of roofs (neither wall nor façade feature). Default "roof".
    pub roof_class: String,
    /// Edge of the cells in which the placed views' façade labels are pooled for the second
    /// pass, metres. Default 0.25.
    pub consensus_cell_m: f64,
}

impl Default for RegistrationParams {
    fn default() -> Self {
        RegistrationParams {
            search_m: 1.5,
            search_deg: 3.0,
            samples: 1200,
            min_gain: 0.005,
            prior_weight: 0.005,
            min_agreement: 0.5,
            max_range_m: 2000.0,
            wall_class: "wall".into(),
            roof_class: "roof".into(),
            consensus_cell_m: 0.25,
        }
    }
}

impl RegistrationParams {
    /// A window of zero in position and heading: the metadata stands, as in the paper.
    pub fn is_off(&self) -> bool {
        self.search_m == 0.0 && self.search_deg == 0.0
    }

    /// Checks every knob: (field, message) of the first bad one.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let range = crate::params::check_in;
        range("search_m", self.search_m, 0.0, 20.0)?;
        range("search_deg", self.search_deg, 0.0, 30.0)?;
        if !(100..=1_000_000).contains(&self.samples) {
            return Err((
                "samples",
                format!("expected 100 to 10^6 pixels, got {}", self.samples),
            ));
        }
        range("min_gain", self.min_gain, 0.0, 1.0)?;
        range("prior_weight", self.prior_weight, 0.0, 10.0)?;
        range("min_agreement", self.min_agreement, -1.0, 1.0)?;
        range("max_range_m", self.max_range_m, 1.0, 100_000.0)?;
        range("consensus_cell_m", self.consensus_cell_m, 0.01, 10.0)?;
        Ok(())
    }
}

/// What a view's segmentation says a pixel shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Seen {
    Building,
    Sky,
    Ground,
    /// No depth to tell sky from ground: anything but a building.
    NotBuilding,
}

/// What the twin shows along a ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Rendered {
    Building,
    Sky,
    Ground,
    /// Clutter or vegetation in the scene: says nothing about the pose.
    Other,
}

/// +1 agreement, -1 disagreement, 0 when the pair says nothing (sky against the ground beyond
/// the terrain's edge, anything against clutter).
fn agreement(seen: Seen, rendered: Rendered) -> i32 {
    use Rendered as R;
    match (seen, rendered) {
        (_, R::Other) => 0,
        (Seen::Building, R::Building) => 1,
        (Seen::Building, _) => -1,
        (Seen::Sky, R::Sky) => 1,
        (Seen::Sky, R::Building) => -1,
        (Seen::Sky, R::Ground) => 0,
        (Seen::Ground, R::Ground) => 1,
        (Seen::Ground, R::Building) => -1,
        (Seen::Ground, R::Sky) => 0,
        (Seen::NotBuilding, R::Building) => -1,
        (Seen::NotBuilding, _) => 1,
    }
}

/// The outcome for one view.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refinement {
    /// Move applied east, north, metres (0 when not accepted).
    pub shift_m: [f64; 2],
    /// Heading change applied, degrees, counter-clockwise seen from above.
    pub yaw_deg: f64,
    /// Agreement (share of counted pixels, -1 to 1) at the reported and the best pose, on the
    /// fine lattice.
    pub before: f64,
    /// See `before`.
    pub after: f64,
    /// Whether the pose was moved.
    pub accepted: bool,
    /// Whether the move used the façade labels the other views agreed on (the second pass) as
    /// well as the silhouettes.
    pub by_facades: bool,
}

/// A sampled pixel: its camera-frame unit direction turned into the site frame by the reported
/// rotation, what the view says is there, the wall instance it shows (0 if not a wall), and the
/// next sample right of it and below it on the lattice (`u32::MAX`: none).
struct Sample {
    dir: [f64; 3],
    seen: Seen,
    wall: u16,
    facade: Facade,
    right: u32,
    down: u32,
}

/// What a building pixel shows of its façade.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Facade {
    /// Plain wall.
    Wall,
    /// A window, door, balcony or any other architectural instance on the wall.
    Feature,
    /// Not a façade (roof, not a building, unlabelled).
    None,
}

/// The lattice strides for `view`: the coarse one giving about `p.samples` pixels, the fine one
/// a quarter of it.
fn strides(view: &View, p: &RegistrationParams) -> (u32, u32) {
    let area = view.width as f64 * view.height as f64;
    let coarse = (area / p.samples as f64).sqrt().round().max(1.0) as u32;
    (coarse, (coarse / 4).max(1))
}

/// What the view says a pixel shows, or `None` where it says nothing the twin can be held to
/// (clutter in front, no depth where depth is given).
fn label(view: &View, px: usize, p: &RegistrationParams) -> Option<(Seen, u16, Facade)> {
    let arch = view.arch.as_ref()?;
    if view
        .clutter
        .as_ref()
        .is_some_and(|c| c.ids.get(px).is_some_and(|&id| id != 0))
    {
        return None;
    }
    let id = *arch.ids.get(px)?;
    let seen = if id != 0 {
        Seen::Building
    } else {
        match view.depth.as_ref().map(|d| d[px]) {
            Some(d) if d.is_infinite() && d > 0.0 => Seen::Sky,
            // Something near, unlabelled: the ground if the ray points down; above the horizon
            // it is a wall the segmentation missed, or a tree, and says nothing sure.
            Some(d) if d.is_finite() => {
                let w = view.width as usize;
                let (x, y) = ((px % w) as f64 + 0.5, (px / w) as f64 + 0.5);
                if view.pixel_ray(x, y).0[2] < -0.02 {
                    Seen::Ground
                } else {
                    return None;
                }
            }
            Some(_) => return None,
            None => Seen::NotBuilding,
        }
    };
    let class = (id != 0).then(|| arch.classes.get(&id)).flatten();
    let facade = match class {
        Some(k) if *k == p.wall_class => Facade::Wall,
        Some(k) if *k == p.roof_class => Facade::None,
        Some(_) => Facade::Feature,
        None => Facade::None,
    };
    let wall = if facade == Facade::Wall { id } else { 0 };
    Some((seen, wall, facade))
}

/// Pixels where the label changes (building, sky, ground, wall instance, and with `facades` the
/// edges of windows and doors): near them, and only there, a small move changes the agreement.
fn edges(view: &View, facades: bool, p: &RegistrationParams) -> Vec<bool> {
    let (w, h) = (view.width as usize, view.height as usize);
    let labels: Vec<Option<(Seen, u16, Facade)>> =
        (0..w * h).map(|px| label(view, px, p)).collect();
    let differ = |a: &Option<(Seen, u16, Facade)>, b: &Option<(Seen, u16, Facade)>| match (a, b) {
        (Some(a), Some(b)) => {
            a.0 != b.0 || (a.1 != 0 && b.1 != 0 && a.1 != b.1) || (facades && a.2 != b.2)
        }
        (None, None) => false,
        _ => true,
    };
    let mut edge = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            if (x + 1 < w && differ(&labels[k], &labels[k + 1]))
                || (y + 1 < h && differ(&labels[k], &labels[k + w]))
            {
                edge[k] = true;
            }
        }
    }
    edge
}

/// The labelled pixels on a lattice of `stride` (those in `keep` only, when given), with their
/// lattice neighbours.
fn samples(view: &View, stride: u32, keep: Option<&[bool]>, p: &RegistrationParams) -> Vec<Sample> {
    let n = (view.width * view.height) as usize;
    if view.arch.as_ref().is_none_or(|a| a.ids.len() != n)
        || view.depth.as_ref().is_some_and(|d| d.len() != n)
        || view.clutter.as_ref().is_some_and(|c| c.ids.len() != n)
    {
        return Vec::new();
    }
    let xs: Vec<u32> = (stride / 2..view.width).step_by(stride as usize).collect();
    let ys: Vec<u32> = (stride / 2..view.height).step_by(stride as usize).collect();
    let cols = xs.len();
    let mut at = vec![u32::MAX; cols * ys.len()];
    let mut out: Vec<Sample> = Vec::new();
    for (r, &y) in ys.iter().enumerate() {
        for (c, &x) in xs.iter().enumerate() {
            let px = (y * view.width + x) as usize;
            if keep.is_some_and(|k| !k[px]) {
                continue;
            }
            let Some((seen, wall, facade)) = label(view, px, p) else {
                continue;
            };
            let (dir, _) = view.pixel_ray(x as f64 + 0.5, y as f64 + 0.5);
            at[r * cols + c] = out.len() as u32;
            out.push(Sample {
                dir,
                seen,
                wall,
                facade,
                right: u32::MAX,
                down: u32::MAX,
            });
        }
    }
    for r in 0..ys.len() {
        for c in 0..cols {
            let k = at[r * cols + c];
            if k == u32::MAX {
                continue;
            }
            if c + 1 < cols {
                out[k as usize].right = at[r * cols + c + 1];
            }
            if r + 1 < ys.len() {
                out[k as usize].down = at[(r + 1) * cols + c];
            }
        }
    }
    out
}

/// What the twin shows along a ray: the class and, for a building, its object.
#[derive(Clone, Copy)]
struct Shown {
    rendered: Rendered,
    object: u32,
}

/// The twin: its rays, what each triangle is (in the order [`SceneRays`] numbers them), and
/// how far a ray may go before it counts as sky.
struct Twin<'a> {
    rays: &'a SceneRays,
    shown_by_triangle: &'a [Shown],
    max_range: f32,
}

/// The agreement share (-1 to 1) with the camera at `position` turned by `yaw` radians about
/// the vertical: the silhouettes (building, sky, ground) per sample, plus, for neighbouring
/// samples that show a wall in the view and a building in the twin, whether both say the same
/// about the two being one building or two (a party wall between row houses is where a flat
/// street front tells where along it the camera stood).
fn score(
    samples: &[Sample],
    twin: &Twin,
    consensus: Option<&OthersSay>,
    position: [f64; 3],
    yaw: f64,
) -> f64 {
    let (s, c) = yaw.sin_cos();
    let origin = position.map(|v| v as f32);
    let (mut total, mut counted) = (0i64, 0i64);
    let shown: Vec<Shown> = samples
        .iter()
        .map(|smp| {
            let d = smp.dir;
            let dir = [
                (c * d[0] - s * d[1]) as f32,
                (s * d[0] + c * d[1]) as f32,
                d[2] as f32,
            ];
            let hit = twin.rays.cast_index(origin, dir, 1e-3, twin.max_range);
            let sh = match hit {
                None => Shown {
                    rendered: Rendered::Sky,
                    object: u32::MAX,
                },
                Some((_, prim)) => twin.shown_by_triangle[prim as usize],
            };
            let a = agreement(smp.seen, sh.rendered);
            total += a as i64;
            counted += (a != 0) as i64;
            if let (Some(cons), Some((t, _))) = (consensus, hit)
                && sh.rendered == Rendered::Building
                && smp.facade != Facade::None
            {
                let at = std::array::from_fn(|k| position[k] + dir[k] as f64 * t as f64);
                if let Some(f) = cons.label_at(at) {
                    total += if f == smp.facade { 1 } else { -1 };
                    counted += 1;
                }
            }
            sh
        })
        .collect();
    for (k, smp) in samples.iter().enumerate() {
        if smp.wall == 0 || shown[k].rendered != Rendered::Building {
            continue;
        }
        for nb in [smp.right, smp.down] {
            let Some(o) = samples.get(nb as usize) else {
                continue;
            };
            let other = shown[nb as usize];
            if o.wall == 0 || other.rendered != Rendered::Building {
                continue;
            }
            let seen_split = o.wall != smp.wall;
            let shown_split = other.object != shown[k].object;
            total += if seen_split == shown_split { 1 } else { -1 };
            counted += 1;
        }
    }
    if counted == 0 {
        f64::NAN
    } else {
        total as f64 / counted as f64
    }
}

/// The façade labels of the views already placed, pooled in cells on the twin's walls: the
/// second pass places a view whose silhouettes could not (a street front seen whole, one wall
/// from edge to edge) by the windows and doors the placed views agree on.
struct Consensus {
    cell_m: f64,
    /// Cell -> (feature, wall) sample counts over every placed view.
    cells: HashMap<[i64; 3], [u32; 2]>,
}

/// One view's façade samples pooled in cells.
type Pool = HashMap<[i64; 3], [u32; 2]>;

impl Consensus {
    fn key(cell_m: f64, at: [f64; 3]) -> [i64; 3] {
        at.map(|v| (v / cell_m).floor() as i64)
    }

    /// `view`'s façade samples as seen from `pose`, pooled in cells.
    fn pool(cell_m: f64, view: &View, pose: &Pose, twin: &Twin, p: &RegistrationParams) -> Pool {
        let placed = View {
            pose: *pose,
            ..view.clone()
        };
        let origin = pose.position.map(|v| v as f32);
        let mut cells = Pool::new();
        let (_, fine_stride) = strides(view, p);
        for smp in samples(&placed, fine_stride, None, p) {
            if smp.facade == Facade::None {
                continue;
            }
            let dir = smp.dir.map(|c| c as f32);
            let Some((t, prim)) = twin.rays.cast_index(origin, dir, 1e-3, twin.max_range) else {
                continue;
            };
            if twin.shown_by_triangle[prim as usize].rendered != Rendered::Building {
                continue;
            }
            let at = std::array::from_fn(|k| pose.position[k] + smp.dir[k] * t as f64);
            let cell = cells.entry(Self::key(cell_m, at)).or_default();
            cell[(smp.facade == Facade::Wall) as usize] += 1;
        }
        cells
    }

    fn add(&mut self, pool: &Pool) {
        for (k, v) in pool {
            let c = self.cells.entry(*k).or_default();
            c[0] += v[0];
            c[1] += v[1];
        }
    }
}

/// The consensus as one view may use it: without what that view itself put in.
struct OthersSay<'a> {
    all: &'a Consensus,
    own: Option<&'a Pool>,
}

impl OthersSay<'_> {
    /// The majority label of the other views in the cell at `at`, if any saw it and they did not
    /// tie.
    fn label_at(&self, at: [f64; 3]) -> Option<Facade> {
        let key = Consensus::key(self.all.cell_m, at);
        let [mut f, mut w] = *self.all.cells.get(&key)?;
        if let Some(own) = self.own.and_then(|o| o.get(&key)) {
            f -= own[0];
            w -= own[1];
        }
        match f.cmp(&w) {
            std::cmp::Ordering::Greater => Some(Facade::Feature),
            std::cmp::Ordering::Less => Some(Facade::Wall),
            std::cmp::Ordering::Equal => None,
        }
    }
}

/// How many of the coarse grid's best poses start a fine search.
const STARTS: usize = 2;

/// The pattern search's moves: (right, forward, heading) in steps. Along each axis, and the
/// sideways moves paired with turns either way, the valley along which a distant wall lets
/// heading and position trade off.
const MOVES_AROUND: [(f64, f64, f64); 10] = [
    (1.0, 0.0, 0.0),
    (-1.0, 0.0, 0.0),
    (0.0, 1.0, 0.0),
    (0.0, -1.0, 0.0),
    (0.0, 0.0, 1.0),
    (0.0, 0.0, -1.0),
    (1.0, 0.0, 1.0),
    (1.0, 0.0, -1.0),
    (-1.0, 0.0, 1.0),
    (-1.0, 0.0, -1.0),
];

/// How many moves a level of the pattern search may make before its step is halved.
const MOVES: usize = 3;

/// One candidate: (dx, dy, yaw radians).
type Candidate = [f64; 3];

/// The best of `candidates` by agreement, ties to the smallest move (then the first listed), so
/// a flat score leaves the pose alone.
fn best_of(
    candidates: &[Candidate],
    eval: &dyn Fn(Candidate) -> f64,
    search_m: f64,
    search_rad: f64,
    prior_weight: f64,
) -> (Candidate, f64) {
    let size = |c: &Candidate| {
        let m = if search_m > 0.0 { search_m } else { 1.0 };
        let r = if search_rad > 0.0 { search_rad } else { 1.0 };
        (c[0] / m).powi(2) + (c[1] / m).powi(2) + (c[2] / r).powi(2)
    };
    let mut best = (candidates[0], f64::NEG_INFINITY);
    for &cand in candidates {
        let s = eval(cand) - prior_weight * size(&cand);
        if !s.is_finite() {
            continue;
        }
        if s > best.1 || (s == best.1 && size(&cand) < size(&best.0)) {
            best = (cand, s);
        }
    }
    best
}

/// Refines one view's pose against the twin. Returns the pose to use and what was done.
fn refine_view(
    view: &View,
    twin: &Twin,
    consensus: Option<&OthersSay>,
    start: Option<Candidate>,
    p: &RegistrationParams,
) -> (Pose, Refinement) {
    let unchanged = Refinement {
        shift_m: [0.0, 0.0],
        yaw_deg: 0.0,
        before: f64::NAN,
        after: f64::NAN,
        accepted: false,
        by_facades: consensus.is_some(),
    };
    // Samples per level of the search: the whole view on the coarse lattice for the grid; then
    // ever finer lattices kept ever closer to the edges, as the pose left to find shrinks. The
    // moves are judged, and the pose accepted, on the finest lattice within a coarse stride of
    // an edge.
    let (coarse_stride, fine_stride) = strides(view, p);
    let coarse = samples(view, coarse_stride, None, p);
    let edge = edges(view, consensus.is_some(), p);
    let near = |band: u32| dilate_square(&edge, view.width, view.height, band as i64);
    let fine = samples(view, fine_stride, Some(&near(coarse_stride)), p);
    // A view with no building in it has nothing to be placed by (nor anything for the façade
    // stages to take from it).
    if fine.is_empty() || !coarse.iter().any(|s| s.seen == Seen::Building) {
        return (view.pose, unchanged);
    }
    let mid = samples(
        view,
        (coarse_stride / 2).max(1),
        Some(&near(coarse_stride)),
        p,
    );
    let close = samples(
        view,
        fine_stride,
        Some(&near((coarse_stride / 2).max(1))),
        p,
    );
    let by_level: [&[Sample]; 3] = [&mid, &close, &fine];
    let at = |smp: &[Sample], c: Candidate| {
        let pos = [
            view.pose.position[0] + c[0],
            view.pose.position[1] + c[1],
            view.pose.position[2],
        ];
        score(smp, twin, consensus, pos, c[2])
    };
    let search_rad = p.search_deg.to_radians();
    // Coarse: 7 x 7 positions, 5 headings.
    let (step_m, step_rad) = (p.search_m / 3.0, search_rad / 2.0);
    let mut grid = Vec::with_capacity(245);
    for i in -3..=3 {
        for j in -3..=3 {
            for k in -2..=2 {
                grid.push([i as f64 * step_m, j as f64 * step_m, k as f64 * step_rad]);
            }
        }
    }
    // The best few of the coarse grid each start a pattern search on the fine lattice: the
    // `MOVES_AROUND` neighbours, moving while a neighbour is better (at most `MOVES` a level),
    // then half the step; at least three levels, more for a wide window, until the step is
    // under 7 cm (below the 10 cm texel of the façade charts). Heading and a sideways move
    // trade off along a narrow valley for a distant wall: one start can stop short in it.
    let prior = |c: &Candidate| {
        p.prior_weight
            * ((c[0] / p.search_m.max(1e-9)).powi(2)
                + (c[1] / p.search_m.max(1e-9)).powi(2)
                + (c[2] / search_rad.max(1e-9)).powi(2))
    };
    // A start given (the first pass's pose) skips the grid and searches from a quarter step.
    let starts: Vec<(Candidate, u32)> = match start {
        Some(c) => vec![(c, 2)],
        None => {
            let mut ranked: Vec<(f64, usize)> = grid
                .iter()
                .enumerate()
                .map(|(k, c)| (at(&coarse, *c) - prior(c), k))
                .filter(|(s, _)| s.is_finite())
                .collect();
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            ranked
                .iter()
                .take(STARTS)
                .map(|&(_, k)| (grid[k], 0))
                .collect()
        }
    };
    // The camera's right and forward axes in plan (rotation columns 0 and 2).
    let plan = |col: usize| {
        let r = view.pose.rotation;
        let (x, y) = (r[0][col], r[1][col]);
        let n = x.hypot(y);
        if n > 1e-9 { [x / n, y / n] } else { [1.0, 0.0] }
    };
    let (right, fwd) = (plan(0), plan(2));
    let mut best = [0.0; 3];
    let mut best_score = at(&fine, best) - prior(&best);
    for (first, from_level) in starts {
        let scale = (1u32 << from_level) as f64;
        let (mut here, mut sm, mut sr) = (first, step_m / scale, step_rad / scale);
        for level in from_level..8 {
            if level >= 3 && sm <= 0.07 {
                break;
            }
            sm /= 2.0;
            sr /= 2.0;
            for _ in 0..MOVES {
                let mut around = Vec::with_capacity(1 + MOVES_AROUND.len());
                around.push(here);
                for (a, b, k) in MOVES_AROUND {
                    // a and b along the camera's right and forward axes in plan.
                    around.push([
                        (here[0] + (a * right[0] + b * fwd[0]) * sm).clamp(-p.search_m, p.search_m),
                        (here[1] + (a * right[1] + b * fwd[1]) * sm).clamp(-p.search_m, p.search_m),
                        (here[2] + k * sr).clamp(-search_rad, search_rad),
                    ]);
                }
                let smp = by_level[(level as usize).min(by_level.len() - 1)];
                let next = best_of(
                    &around,
                    &|c| at(smp, c),
                    p.search_m,
                    search_rad,
                    p.prior_weight,
                )
                .0;
                if next == here {
                    break;
                }
                here = next;
            }
        }
        let s = at(&fine, here) - prior(&here);
        if s > best_score {
            (best, best_score) = (here, s);
        }
    }
    let (before, after) = (at(&fine, [0.0; 3]), at(&fine, best));
    if !before.is_finite() {
        return (view.pose, unchanged);
    }
    // A best pose on the window's edge means the truth lies beyond it, or that nothing within
    // it explains the view: either way not a pose to trust.
    let on_edge = (p.search_m > 0.0
        && (best[0].abs() >= 0.99 * p.search_m || best[1].abs() >= 0.99 * p.search_m))
        || (search_rad > 0.0 && best[2].abs() >= 0.99 * search_rad);
    let accepted =
        after.is_finite() && after - before >= p.min_gain && after >= p.min_agreement && !on_edge;
    let refinement = Refinement {
        shift_m: if accepted {
            [best[0], best[1]]
        } else {
            [0.0; 2]
        },
        yaw_deg: if accepted { best[2].to_degrees() } else { 0.0 },
        before,
        after: if accepted { after } else { before },
        accepted,
        by_facades: consensus.is_some(),
    };
    if !accepted {
        return (view.pose, refinement);
    }
    (turned(&view.pose, best), refinement)
}

/// `pose` moved by (dx, dy) and turned by yaw about the vertical through the camera.
fn turned(pose: &Pose, c: Candidate) -> Pose {
    let (s, co) = c[2].sin_cos();
    let r = pose.rotation;
    // Rows are the site axes: turning the camera about site z mixes the x and y rows.
    let rotation = [
        std::array::from_fn(|k| co * r[0][k] - s * r[1][k]),
        std::array::from_fn(|k| s * r[0][k] + co * r[1][k]),
        r[2],
    ];
    Pose {
        position: [
            pose.position[0] + c[0],
            pose.position[1] + c[1],
            pose.position[2],
        ],
        rotation,
    }
}

/// What each of the scene's triangles is, in the order [`SceneRays`] numbers them.
fn shown_by_triangle(scene: &Scene) -> Vec<Shown> {
    scene
        .objects
        .iter()
        .enumerate()
        .flat_map(|(k, o)| {
            let rendered = match o.class {
                ObjectClass::Building => Rendered::Building,
                ObjectClass::Terrain => Rendered::Ground,
                _ => Rendered::Other,
            };
            let shown = Shown {
                rendered,
                object: k as u32,
            };
            std::iter::repeat_n(shown, o.mesh.triangles.len())
        })
        .collect()
}

/// Refines every view's pose against `scene`; per view in order, its new pose and what was
/// done. Deterministic at any thread count (each view on its own).
pub fn register_views(
    scene: &Scene,
    views: &[View],
    p: &RegistrationParams,
    progress: &dyn Progress,
) -> Vec<(Pose, Refinement)> {
    if p.is_off() {
        return views
            .iter()
            .map(|v| {
                let kept = Refinement {
                    shift_m: [0.0; 2],
                    yaw_deg: 0.0,
                    before: f64::NAN,
                    after: f64::NAN,
                    accepted: false,
                    by_facades: false,
                };
                (v.pose, kept)
            })
            .collect();
    }
    let rays = SceneRays::new(scene);
    let by_triangle = shown_by_triangle(scene);
    let twin = Twin {
        rays: &rays,
        shown_by_triangle: &by_triangle,
        max_range: p.max_range_m as f32,
    };
    progress.set_total(views.len() as u64);
    let mut out: Vec<(Pose, Refinement)> = views
        .par_iter()
        .map(|v| {
            let r = refine_view(v, &twin, None, None, p);
            progress.advance(1);
            r
        })
        .collect();
    // Second pass: every view again, now also against the façade labels the views placed by
    // their silhouettes pooled (less its own), which places the views the silhouettes could not
    // and sharpens the rest. Pools are summed in view order: the same at any thread count.
    let pools: Vec<Option<Pool>> = views
        .par_iter()
        .zip(&out)
        .map(|(v, (pose, r))| {
            r.accepted
                .then(|| Consensus::pool(p.consensus_cell_m, v, pose, &twin, p))
        })
        .collect();
    let mut consensus = Consensus {
        cell_m: p.consensus_cell_m,
        cells: HashMap::new(),
    };
    for pool in pools.iter().flatten() {
        consensus.add(pool);
    }
    if consensus.cells.is_empty() {
        return out;
    }
    let second: Vec<(Pose, Refinement)> = views
        .par_iter()
        .zip(&pools)
        .zip(&out)
        .map(|((v, own), (_, first))| {
            let others = OthersSay {
                all: &consensus,
                own: own.as_ref(),
            };
            let start = first.accepted.then(|| {
                [
                    first.shift_m[0],
                    first.shift_m[1],
                    first.yaw_deg.to_radians(),
                ]
            });
            refine_view(v, &twin, Some(&others), start, p)
        })
        .collect();
    for (slot, s) in out.iter_mut().zip(second) {
        if s.1.accepted {
            *slot = s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Instances, Intrinsics, PodVec, SceneObject};
    use crate::geom::mesh_build::cuboid;
    use crate::rf::materials::Material;
    use crate::stage::NoProgress;

    /// A camera at `position` looking level along `heading` (radians from east).
    fn look(position: [f64; 3], heading: f64) -> Pose {
        let (s, c) = heading.sin_cos();
        let (right, down, fwd) = ([s, -c, 0.0], [0.0, 0.0, -1.0], [c, s, 0.0]);
        Pose {
            position,
            rotation: std::array::from_fn(|i| [right[i], down[i], fwd[i]]),
        }
    }

    fn object(id: &str, class: ObjectClass, mesh: crate::artifact::Mesh) -> SceneObject {
        SceneObject {
            id: id.into(),
            class,
            mesh,
        }
    }

    /// Ground, and buildings given as (centre, size).
    fn scene(buildings: &[([f64; 2], [f64; 3])]) -> Scene {
        let mut objects = vec![object(
            "terrain",
            ObjectClass::Terrain,
            cuboid(
                [0.0, 0.0],
                [600.0, 600.0, 1.0],
                0.0,
                -1.0,
                Material::Concrete,
            ),
        )];
        for (k, (c, s)) in buildings.iter().enumerate() {
            objects.push(object(
                &format!("building-{k}"),
                ObjectClass::Building,
                cuboid(*c, *s, 0.0, 0.0, Material::Brick),
            ));
        }
        Scene { objects }
    }

    /// What a segmentation and a depth model would give from `pose`: one wall instance per
    /// building, roofs, sky at infinite depth; reported at `reported`.
    fn view(scene: &Scene, pose: Pose, reported: Pose) -> View {
        let (w, h) = (320u32, 240u32);
        let f = 160.0;
        let mut v = View {
            id: "v".into(),
            width: w,
            height: h,
            intrinsics: Intrinsics {
                fx: f,
                fy: f,
                cx: 160.0,
                cy: 120.0,
            },
            pose,
            captured_at: None,
            pose_source: None,
            distortion: None,
            image: PodVec(vec![[0; 3]; (w * h) as usize]),
            arch: None,
            clutter: None,
            material: None,
            depth: None,
            normal: None,
        };
        let rays = SceneRays::new(scene);
        let mut ids = vec![0u16; (w * h) as usize];
        let mut depth = vec![f32::INFINITY; (w * h) as usize];
        let mut classes = std::collections::BTreeMap::new();
        for y in 0..h {
            for x in 0..w {
                let (dir, norm) = v.pixel_ray(x as f64 + 0.5, y as f64 + 0.5);
                let o = pose.position.map(|c| c as f32);
                let Some(hit) = rays.cast(o, dir.map(|c| c as f32), 1e-3, 2000.0) else {
                    continue;
                };
                let px = (y * w + x) as usize;
                depth[px] = (hit.t as f64 / norm) as f32;
                if scene.objects[hit.object].class == ObjectClass::Building {
                    let roof = hit.normal[2] > 0.7;
                    let id = (2 * hit.object + roof as usize) as u16;
                    ids[px] = id;
                    classes.insert(id, if roof { "roof" } else { "wall" }.to_string());
                }
            }
        }
        v.arch = Some(Instances {
            ids: PodVec(ids),
            classes,
        });
        v.depth = Some(PodVec(depth));
        v.pose = reported;
        v
    }

    fn moved(p: Pose, dx: f64, dy: f64, yaw_deg: f64) -> Pose {
        turned(&p, [dx, dy, yaw_deg.to_radians()])
    }

    fn heading(p: &Pose) -> f64 {
        p.rotation[1][2].atan2(p.rotation[0][2])
    }

    #[test]
    fn the_agreement_table_is_symmetric_where_it_should_be() {
        use Rendered as R;
        assert_eq!(agreement(Seen::Building, R::Building), 1);
        assert_eq!(agreement(Seen::Building, R::Sky), -1);
        assert_eq!(agreement(Seen::Ground, R::Building), -1);
        assert_eq!(agreement(Seen::Sky, R::Building), -1);
        // Beyond the terrain's edge the twin shows sky where the view sees far ground.
        assert_eq!(agreement(Seen::Sky, R::Ground), 0);
        assert_eq!(agreement(Seen::Ground, R::Sky), 0);
        // Clutter in the twin says nothing.
        assert_eq!(agreement(Seen::Building, R::Other), 0);
    }

    /// Two detached houses across the street: their ends and the gap between them pin the
    /// camera along the street, their eaves and bases across it.
    #[test]
    fn a_view_of_two_houses_is_moved_back_to_where_it_was() {
        let s = scene(&[
            ([-6.0, 12.0], [8.0, 6.0, 7.0]),
            ([6.0, 12.0], [9.0, 6.0, 9.0]),
        ]);
        let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
        let p = RegistrationParams::default();
        for (dx, dy, dyaw) in [(0.6, -0.4, 1.0), (-0.9, 0.3, -1.5), (0.2, 0.8, 0.5)] {
            let v = view(&s, truth, moved(truth, dx, dy, dyaw));
            let out = register_views(&s, std::slice::from_ref(&v), &p, &NoProgress);
            let (pose, r) = out[0];
            assert!(r.accepted, "{r:?}");
            let err = ((pose.position[0] - truth.position[0]).powi(2)
                + (pose.position[1] - truth.position[1]).powi(2))
            .sqrt();
            let yaw_err = (heading(&pose) - heading(&truth)).to_degrees();
            assert!(
                err <= 0.15,
                "moved ({dx}, {dy}): left {err:.3} m off, {r:?}"
            );
            assert!(
                yaw_err.abs() <= 0.4,
                "turned {dyaw}: left {yaw_err:.2} deg off"
            );
            assert!(r.after > r.before);
        }
    }

    /// One long wall filling the frame from edge to edge: nothing says where along it the
    /// camera stood, so the metadata stands.
    #[test]
    fn a_view_of_one_endless_wall_keeps_its_metadata() {
        let s = scene(&[([0.0, 10.0], [400.0, 6.0, 40.0])]);
        let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
        let reported = moved(truth, 0.8, 0.0, 0.0);
        let v = view(&s, truth, reported);
        let out = register_views(
            &s,
            std::slice::from_ref(&v),
            &RegistrationParams::default(),
            &NoProgress,
        );
        let (pose, r) = out[0];
        assert!(!r.accepted, "{r:?}");
        assert_eq!(pose, reported);
    }

    #[test]
    fn a_window_of_zero_keeps_the_metadata() {
        let s = scene(&[
            ([-6.0, 12.0], [8.0, 6.0, 7.0]),
            ([6.0, 12.0], [9.0, 6.0, 9.0]),
        ]);
        let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
        let reported = moved(truth, 0.6, -0.4, 1.0);
        let v = view(&s, truth, reported);
        let off = RegistrationParams {
            search_m: 0.0,
            search_deg: 0.0,
            ..Default::default()
        };
        let out = register_views(&s, std::slice::from_ref(&v), &off, &NoProgress);
        assert_eq!(out[0].0, reported);
        assert!(!out[0].1.accepted);
        // Heading alone: the position stays, the heading comes back.
        let yaw_only = RegistrationParams {
            search_m: 0.0,
            ..Default::default()
        };
        let v = view(&s, truth, moved(truth, 0.0, 0.0, 1.5));
        let (pose, r) = register_views(&s, std::slice::from_ref(&v), &yaw_only, &NoProgress)[0];
        assert!(r.accepted, "{r:?}");
        assert_eq!(pose.position, truth.position);
        assert!((heading(&pose) - heading(&truth)).to_degrees().abs() <= 0.4);
    }

    #[test]
    fn a_view_without_labels_is_left_alone_and_bad_knobs_are_refused() {
        let s = scene(&[([0.0, 12.0], [8.0, 6.0, 7.0])]);
        let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
        let mut v = view(&s, truth, moved(truth, 0.5, 0.0, 0.0));
        v.arch = None;
        let out = register_views(
            &s,
            std::slice::from_ref(&v),
            &RegistrationParams::default(),
            &NoProgress,
        );
        assert!(!out[0].1.accepted);
        assert_eq!(out[0].0, v.pose);
        for bad in [
            RegistrationParams {
                search_m: f64::NAN,
                ..Default::default()
            },
            RegistrationParams {
                search_m: 50.0,
                ..Default::default()
            },
            RegistrationParams {
                search_deg: -1.0,
                ..Default::default()
            },
            RegistrationParams {
                samples: 0,
                ..Default::default()
            },
            RegistrationParams {
                samples: 100_000_000,
                ..Default::default()
            },
            RegistrationParams {
                prior_weight: f64::INFINITY,
                ..Default::default()
            },
            RegistrationParams {
                consensus_cell_m: 0.0,
                ..Default::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        assert!(RegistrationParams::default().validate().is_ok());
    }
}
