//! Pose refinement of street views against the twin's silhouettes.
//!
//! The paper registers views from their metadata alone (Sec. 4.2) and argues that classical
//! pose refinement has nothing to anchor to, since the landmarks it would use are the façade
//! features still missing from the scene. The building outlines are not missing: the twin of
//! Sec. 4.1 has them. So each view's reported position (east, north) and heading are moved
//! within a bounded window to where the twin, rendered from the view, best agrees with what the
//! view's own segmentation says is building, sky and ground. Relief is the stage that needs it:
//! half a metre of metadata error moves every window a view deposits by half a metre, which at
//! IoU 0.5 on a 1.4 m window loses most of them (docs/benchmarks-log.md, 2026-11-25, commit d3e6605).
//!
//! The search, per view: a 7 x 7 x 5 grid over (dx, dy, dyaw) scored on a coarse pixel lattice,
//! then pattern searches from its best few poses on finer lattices kept near the label edges
//! (the only pixels a small move changes; on the finest, moves in plan only), with the metadata
//! as a weak prior. A second pass runs every view again with the window and door labels the
//! placed views pooled (less its own) as a further cue, which places the views that face one
//! wall from edge to edge. Camera height, pitch and the focal length are searched too (within
//! `search_height_m`, `search_pitch_deg`, `search_focal`: the first two move the silhouettes up
//! and down the image, the focal length spreads them from its centre); roll can be
//! (`search_roll_deg`, off by default: it tilts the silhouettes about the image centre, and
//! searched with the rest it did more harm than good).
//! A view stays where its metadata put it when the best pose does not beat the reported one by
//! `min_gain`, lies on the edge of the search window, or agrees on less than `min_agreement`: a
//! flat wall seen head-on cannot say where along it the camera stood, and a pose found in noise
//! is worse than the metadata.

mod consensus;
mod labels;
mod twin;

use std::cell::RefCell;
use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{Pose, Scene, View, Views};
use crate::geom::raycast::SceneRays;
use crate::raster::morph::dilate_square;
use crate::stage::{Progress, StageError};

use consensus::{Consensus, OthersSay, Pool};
use labels::{Sample, Seen, edges, samples, strides};
use twin::{Turn, Twin, scores, shown_by_triangle};

/// Knobs of the refinement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegistrationParams {
    /// Largest horizontal move searched, each axis, metres. Default 1.5 (three standard
    /// deviations of phone-grade metadata after a provider's own structure from motion).
    pub search_m: f64,
    /// Largest heading change searched, degrees. Default 3.
    pub search_deg: f64,
    /// Largest change of camera height searched, metres (0: the metadata's height stands).
    /// Default 1 (two standard deviations of SynthViews' default height noise). Height and
    /// pitch move the silhouettes up and down the image; left to the metadata, half a metre of
    /// height error took the demo site's median position error after registration from 0.10 to
    /// 0.47 m, the search trading it for a move along the camera's axis.
    pub search_height_m: f64,
    /// Largest pitch change searched, degrees (0: the metadata's pitch stands). Default 1.5.
    pub search_pitch_deg: f64,
    /// Largest roll change searched, degrees (0: the metadata's roll stands). Default 0. Half a
    /// degree of roll alone left to the metadata takes the relief's window recall / precision
    /// on the relief tests' site from 0.97 / 0.91 to 0.92 / 0.86, and searched within 1 degree
    /// back to 0.95 / 0.88; but with height, pitch and focal errors as well, searching roll too
    /// took them from 0.79 / 0.73 to 0.74 / 0.70 and balconies from 0.50 to 0.14 (a seventh
    /// dimension the pattern search trades against the others; `relief_by_error` in
    /// nodes/tests/relief.rs, 2026-11-28). Off until the search copes.
    pub search_roll_deg: f64,
    /// Largest relative change of the focal length searched (0: the metadata's stands).
    /// Default 0.05 (EXIF focal lengths are off by a few percent; 2 % left to the metadata
    /// took the demo site's median position error after registration from 0.11 to 0.35 m).
    pub search_focal: f64,
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
    /// Architectural classes that stand off the wall, whose pixels say nothing about the pose:
    /// the twin being registered has no relief yet, so a drainpipe at a corner or a balcony's
    /// side widens the view's building silhouette where the twin's ends, and pooled for the
    /// second pass such a feature lands on a different patch of the wall behind it from each
    /// view. Default ["balcony", "drainpipe"].
    pub off_wall_classes: Vec<String>,
    /// Edge of the cells in which the placed views' façade labels are pooled for the second
    /// pass, metres. Default 0.25.
    pub consensus_cell_m: f64,
}

impl Default for RegistrationParams {
    fn default() -> Self {
        RegistrationParams {
            search_m: 1.5,
            search_deg: 3.0,
            search_height_m: 1.0,
            search_pitch_deg: 1.5,
            search_roll_deg: 0.0,
            search_focal: 0.05,
            samples: 1200,
            min_gain: 0.005,
            prior_weight: 0.005,
            min_agreement: 0.5,
            max_range_m: 2000.0,
            wall_class: "wall".into(),
            roof_class: "roof".into(),
            off_wall_classes: vec!["balcony".into(), "drainpipe".into()],
            consensus_cell_m: 0.25,
        }
    }
}

impl RegistrationParams {
    /// A window of zero in position and heading: the metadata stands, as in the paper.
    pub fn is_off(&self) -> bool {
        self.search_m == 0.0 && self.search_deg == 0.0
    }

    /// A candidate's move in units of the search window, squared: dx² / search_m² + dy² /
    /// search_m² + dyaw² / search_deg², and likewise for height, pitch, focal length and roll
    /// (a dimension with no window adds nothing: its move is 0).
    fn move_size(&self, c: &Candidate) -> f64 {
        let per = |v: f64, window: f64| {
            if window > 0.0 {
                (v / window).powi(2)
            } else {
                0.0
            }
        };
        per(c[0], self.search_m)
            + per(c[1], self.search_m)
            + per(c[2], self.search_deg.to_radians())
            + per(c[3], self.search_height_m)
            + per(c[4], self.search_pitch_deg.to_radians())
            + per(c[5], self.search_focal)
            + per(c[6], self.search_roll_deg.to_radians())
    }

    /// What the metadata as a prior takes off a candidate's agreement.
    fn prior(&self, c: &Candidate) -> f64 {
        self.prior_weight * self.move_size(c)
    }

    /// Checks every knob: (field, message) of the first bad one.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let range = crate::params::check_in;
        range("search_m", self.search_m, 0.0, 20.0)?;
        range("search_deg", self.search_deg, 0.0, 30.0)?;
        range("search_height_m", self.search_height_m, 0.0, 20.0)?;
        range("search_pitch_deg", self.search_pitch_deg, 0.0, 30.0)?;
        range("search_roll_deg", self.search_roll_deg, 0.0, 30.0)?;
        range("search_focal", self.search_focal, 0.0, 0.5)?;
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
        if self.off_wall_classes.len() > MAX_OFF_WALL_CLASSES {
            return Err((
                "off_wall_classes",
                format!(
                    "expected at most {MAX_OFF_WALL_CLASSES} classes, got {}",
                    self.off_wall_classes.len()
                ),
            ));
        }
        Ok(())
    }
}

/// Most classes `off_wall_classes` may list (each pixel's class is looked up in it).
const MAX_OFF_WALL_CLASSES: usize = 64;

/// The outcome for one view.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refinement {
    /// Move applied east, north, metres (0 when not accepted).
    pub shift_m: [f64; 2],
    /// Heading change applied, degrees, counter-clockwise seen from above.
    pub yaw_deg: f64,
    /// Camera height change applied, metres.
    #[serde(default)]
    pub dz_m: f64,
    /// Pitch change applied, degrees (about the camera's right axis).
    #[serde(default)]
    pub pitch_deg: f64,
    /// Roll change applied, degrees (about the camera's forward axis).
    #[serde(default)]
    pub roll_deg: f64,
    /// The focal length's factor applied (1: unchanged).
    #[serde(default = "one")]
    pub focal_scale: f64,
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

fn one() -> f64 {
    1.0
}

/// How many of the coarse grid's best poses start a fine search.
const STARTS: usize = 2;

/// The pattern search's moves: (right, forward, heading) in steps. Along each axis, and the
/// sideways moves paired with turns either way, the valley along which a distant wall lets
/// heading and position trade off. The first `PLAN_MOVES` move the camera in plan only.
const MOVES_AROUND: [(f64, f64, f64, f64, f64, f64, f64); 20] = [
    (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0),
    (1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
    (1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0),
    (-1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
    (-1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0),
    // Height and pitch, and the two together the other way: raising the camera and pitching it
    // down move a distant roofline alike.
    (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, -1.0, -1.0, 0.0, 0.0),
    // The focal length: a wider or narrower view about the image centre.
    (0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0),
    (0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0),
    // Roll: the silhouettes tilted about the image centre.
    (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
    (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0),
];

/// How many of `MOVES_AROUND`, from the first, move the camera in plan (position and heading)
/// alone: the moves made on the finest lattice. Its steps (3 and 1.6 cm) are there for the
/// narrow features found along a wall (a 0.12 m drainpipe, see `FINEST_STEP_M`), which a
/// centimetre of height, pitch or focal length barely moves against features a metre or more
/// tall; the coarser levels have set those, and `settle_the_rest` looks at them once more at the
/// end. Searching them on every finest level cast a third of the rays for no shown gain: on the
/// development set (`cargo bench --bench registration`) the median position error 0.425 m
/// (0.424 m this way), height 0.143 m (0.152 m), pitch 0.37° (0.38°), within the per-site spread
/// of 0.13 m, in 37.9 s (28.9 s) (docs/benchmarks-log.md, 2026-11-29, twelfth session).
const PLAN_MOVES: usize = 10;

/// The pattern search stops once its step is under this, metres. A drainpipe is 0.12 m wide:
/// found at IoU 0.5 only within 4 cm along its wall, and a search that stopped at 6 cm steps
/// (the 10 cm façade texel's scale) left the views' median position error at 5-7 cm; at 1.6 cm
/// steps it is 2 cm (docs/benchmarks-log.md, 2026-11-27, commit 84fa211). The two levels past 6 cm, on the
/// finest lattice, took the registration of 416 views from 24 to 63 s.
const FINEST_STEP_M: f64 = 0.025;

/// How many moves a level of the pattern search may make before its step is halved.
const MOVES: usize = 3;

/// One candidate: (dx, dy, yaw radians, dz, pitch radians, relative focal change, roll radians).
type Candidate = [f64; 7];

/// The best of `candidates` by agreement (`agreements`, in the same order), ties to the
/// smallest move (then the first listed), so a flat score leaves the pose alone.
fn best_of(
    candidates: &[Candidate],
    agreements: &[f64],
    p: &RegistrationParams,
) -> (Candidate, f64) {
    let mut best = (candidates[0], f64::NEG_INFINITY);
    for (&cand, &a) in candidates.iter().zip(agreements) {
        let s = a - p.prior(&cand);
        if !s.is_finite() {
            continue;
        }
        if s > best.1 || (s == best.1 && p.move_size(&cand) < p.move_size(&best.0)) {
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
    let by_facades = consensus.is_some();
    // A view with no building in it has nothing to be placed by (nor anything for the façade
    // stages to take from it).
    let Some(lattices) = lattices(view, by_facades, p) else {
        return (view.pose, Refinement::unchanged(by_facades));
    };
    let poses = ScoredPoses {
        view,
        twin,
        consensus,
        lattices,
        scored: RefCell::default(),
    };
    let search_rad = p.search_deg.to_radians();
    // Coarse: 7 x 7 positions, 5 headings.
    let steps = Steps {
        step_m: p.search_m / 3.0,
        step_rad: search_rad / 2.0,
        search_rad,
    };
    let starts = search_starts(&poses, start, steps, p);
    let axes = plan_axes(&view.pose);
    // The metadata, or the first pass's pose, stands unless a search beats it.
    let mut best = start.unwrap_or([0.0; 7]);
    let mut best_score = poses.at(ON_FINEST, best) - p.prior(&best);
    for (first, from_level) in starts {
        let here = pattern_search(&poses, first, from_level, steps, axes, p);
        let s = poses.at(ON_FINEST, here) - p.prior(&here);
        if s > best_score {
            (best, best_score) = (here, s);
        }
    }
    let best = settle_the_rest(&poses, best, steps, axes, p);
    // The best pose found has the best agreement less the prior; where several poses agree
    // equally well (a sample lattice cannot tell poses apart finer than its spacing), the prior
    // picked the one nearest the metadata: the plateau's near edge, up to half a lattice step
    // off. Its middle is the better estimate.
    let best = plateau_middle(best, &|c| poses.at(ON_FINEST, c), axes, p);
    let (before, after) = (poses.at(ON_FINEST, [0.0; 7]), poses.at(ON_FINEST, best));
    verdict(view, best, (before, after), search_rad, by_facades, p)
}

impl Refinement {
    /// The move applied, as a candidate.
    fn candidate(&self) -> Candidate {
        [
            self.shift_m[0],
            self.shift_m[1],
            self.yaw_deg.to_radians(),
            self.dz_m,
            self.pitch_deg.to_radians(),
            self.focal_scale - 1.0,
            self.roll_deg.to_radians(),
        ]
    }

    /// The outcome of a view left where its metadata put it, before any pose was scored.
    fn unchanged(by_facades: bool) -> Refinement {
        Refinement {
            shift_m: [0.0, 0.0],
            yaw_deg: 0.0,
            dz_m: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
            focal_scale: 1.0,
            before: f64::NAN,
            after: f64::NAN,
            accepted: false,
            by_facades,
        }
    }
}

/// How many sample lattices the search uses, coarse to finest.
const LATTICES: usize = 5;
/// The lattice the coarse grid is scored on.
const ON_COARSE: usize = 0;
/// The lattice the moves are judged, and the pose accepted, on.
const ON_FINEST: usize = LATTICES - 1;

/// Samples per level of the search: the whole view on the coarse lattice for the grid; then ever
/// finer lattices kept ever closer to the edges, as the pose left to find shrinks. The moves are
/// judged, and the pose accepted, on the finest lattice within a coarse stride of an edge. The
/// lattices by level: the coarse grid's, then the pattern search's from level 0 on, its last one
/// for every level past it. None when the view shows no building or the fine lattice is empty.
/// A step of its own: every pose is scored on these, and they depend on the view alone.
fn lattices(
    view: &View,
    by_facades: bool,
    p: &RegistrationParams,
) -> Option<[Vec<Sample>; LATTICES]> {
    let (coarse_stride, fine_stride) = strides(view, p);
    let coarse = samples(view, coarse_stride, None, p);
    let edge = edges(view, by_facades, p);
    let near = |band: u32| dilate_square(&edge, view.width, view.height, band as i64);
    let fine = samples(view, fine_stride, Some(&near(coarse_stride)), p);
    if fine.is_empty() || !coarse.iter().any(|s| s.seen == Seen::Building) {
        return None;
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
    // Past the fine lattice's resolution: every pixel within a fine stride of an edge.
    let finest = samples(view, 1, Some(&near(fine_stride)), p);
    Some([coarse, mid, close, fine, finest])
}

/// One view's poses scored against the twin on its lattices, each score kept. A pattern search
/// comes back to poses it has scored (the pose it stands on, the one it came from, the best at
/// the end): a fifth of the rays of the demo's registration were such repeats. Looked up, never
/// iterated: the order of evaluation stays the search's.
struct ScoredPoses<'a> {
    view: &'a View,
    twin: &'a Twin<'a>,
    consensus: Option<&'a OthersSay<'a>>,
    lattices: [Vec<Sample>; LATTICES],
    scored: RefCell<HashMap<(usize, [u64; 7]), f64>>,
}

impl ScoredPoses<'_> {
    /// The agreement of candidate `c` on lattice `lattice`.
    fn at(&self, lattice: usize, c: Candidate) -> f64 {
        self.at_all(lattice, &[c])[0]
    }

    /// The agreements of `candidates` on lattice `lattice`, in order: those not scored before
    /// are cast together (see [`scores`]).
    fn at_all(&self, lattice: usize, candidates: &[Candidate]) -> Vec<f64> {
        let key = |c: &Candidate| (lattice, c.map(f64::to_bits));
        let mut fresh: Vec<Candidate> = Vec::new();
        {
            let scored = self.scored.borrow();
            for c in candidates {
                if !scored.contains_key(&key(c)) && !fresh.iter().any(|f| key(f) == key(c)) {
                    fresh.push(*c);
                }
            }
        }
        if !fresh.is_empty() {
            let view = self.view;
            let poses: Vec<([f64; 3], Turn)> = fresh
                .iter()
                .map(|c| {
                    let pos = [
                        view.pose.position[0] + c[0],
                        view.pose.position[1] + c[1],
                        view.pose.position[2] + c[3],
                    ];
                    (pos, Turn::of(&view.pose, *c))
                })
                .collect();
            let s = scores(&self.lattices[lattice], self.twin, self.consensus, &poses);
            let mut scored = self.scored.borrow_mut();
            for (c, s) in fresh.iter().zip(s) {
                scored.insert(key(c), s);
            }
        }
        let scored = self.scored.borrow();
        candidates.iter().map(|c| scored[&key(c)]).collect()
    }
}

/// The coarse grid's steps and the heading window, radians.
#[derive(Clone, Copy)]
struct Steps {
    /// The coarse grid's position step, metres.
    step_m: f64,
    /// The coarse grid's heading step.
    step_rad: f64,
    /// Largest heading change searched.
    search_rad: f64,
}

/// The poses the pattern searches start from, each with the level it starts at. The best few of
/// the coarse grid (7 x 7 positions, 5 headings) each start a pattern search on the fine lattice;
/// a start given (the first pass's pose) skips the grid and searches from a quarter step.
fn search_starts(
    poses: &ScoredPoses,
    start: Option<Candidate>,
    steps: Steps,
    p: &RegistrationParams,
) -> Vec<(Candidate, u32)> {
    let Steps {
        step_m, step_rad, ..
    } = steps;
    let mut grid = Vec::with_capacity(245);
    for i in -3..=3 {
        for j in -3..=3 {
            for k in -2..=2 {
                grid.push([
                    i as f64 * step_m,
                    j as f64 * step_m,
                    k as f64 * step_rad,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                ]);
            }
        }
    }
    match start {
        Some(c) => vec![(c, 2)],
        None => {
            // Scored a heading at a time: one pixel's rays from the 49 positions then point the
            // same way and start within the window, a packet; across headings they spread too
            // wide to be one.
            let mut agreements = vec![f64::NAN; grid.len()];
            for heading in 0..5 {
                let of: Vec<usize> = (heading..grid.len()).step_by(5).collect();
                let these: Vec<Candidate> = of.iter().map(|&k| grid[k]).collect();
                for (&k, a) in of.iter().zip(poses.at_all(ON_COARSE, &these)) {
                    agreements[k] = a;
                }
            }
            let mut ranked: Vec<(f64, usize)> = grid
                .iter()
                .zip(agreements)
                .enumerate()
                .map(|(k, (c, a))| (a - p.prior(c), k))
                .filter(|(s, _)| s.is_finite())
                .collect();
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            ranked
                .iter()
                .take(STARTS)
                .map(|&(_, k)| (grid[k], 0))
                .collect()
        }
    }
}

/// The camera's right and forward axes in plan (rotation columns 0 and 2): the pattern search
/// moves along them.
fn plan_axes(pose: &Pose) -> [[f64; 2]; 2] {
    let plan = |col: usize| {
        let r = pose.rotation;
        let (x, y) = (r[0][col], r[1][col]);
        let n = x.hypot(y);
        if n > 1e-9 { [x / n, y / n] } else { [1.0, 0.0] }
    };
    [plan(0), plan(2)]
}

/// One pattern search from `first`, starting at level `from_level`: the `MOVES_AROUND`
/// neighbours (on the finest lattice, the first `PLAN_MOVES` of them), moving while a neighbour
/// is better (at most `MOVES` a level), then half the step; at least three levels, more for a
/// wide window, until the step is under `FINEST_STEP_M`. Heading and a sideways move trade off
/// along a narrow valley for a distant wall: one start can stop short in it. Returns where the search stopped.
fn pattern_search(
    poses: &ScoredPoses,
    first: Candidate,
    from_level: u32,
    steps: Steps,
    axes: [[f64; 2]; 2],
    p: &RegistrationParams,
) -> Candidate {
    let mut here = first;
    for (level, (sm, sr)) in levels(steps, from_level) {
        for _ in 0..MOVES {
            let lattice = (level as usize + 1).min(ON_FINEST);
            let moves = if lattice == ON_FINEST {
                &MOVES_AROUND[..PLAN_MOVES]
            } else {
                &MOVES_AROUND[..]
            };
            let around = moves_around(here, moves, (sm, sr), axes, steps.search_rad, p);
            let next = best_of(&around, &poses.at_all(lattice, &around), p).0;
            if next == here {
                break;
            }
            here = next;
        }
    }
    here
}

/// The best pose once more on the finest lattice, by the moves the finest levels leave out
/// (height, pitch, focal length, roll) at their step, while one is better (at most `MOVES`):
/// a coarser level's step in the focal length, traded against a move along the camera's axis,
/// would otherwise stay (5 cm left on `a_view_of_two_houses_is_moved_back_to_where_it_was`).
/// Once per view rather than per level and start: on the development set the median position
/// error 0.424 m (0.425 searching every move on the finest lattice, 0.431 without this), in
/// 28.9 s (37.9 s, 26.2 s).
fn settle_the_rest(
    poses: &ScoredPoses,
    mut best: Candidate,
    steps: Steps,
    axes: [[f64; 2]; 2],
    p: &RegistrationParams,
) -> Candidate {
    let finest = finest_steps(steps);
    for _ in 0..MOVES {
        let around = moves_around(
            best,
            &MOVES_AROUND[PLAN_MOVES..],
            finest,
            axes,
            steps.search_rad,
            p,
        );
        let next = best_of(&around, &poses.at_all(ON_FINEST, &around), p).0;
        if next == best {
            break;
        }
        best = next;
    }
    best
}

/// The levels a pattern search from `from_level` goes through, each with its steps (metres,
/// radians): half the coarse grid's at level 0, halved each level; at least three levels, more
/// for a wide window, until the step is under `FINEST_STEP_M`.
fn levels(steps: Steps, from_level: u32) -> Vec<(u32, (f64, f64))> {
    let scale = (1u32 << from_level) as f64;
    let (mut sm, mut sr) = (steps.step_m / scale, steps.step_rad / scale);
    let mut out = Vec::new();
    for level in from_level..8 {
        if level >= 3 && sm <= FINEST_STEP_M {
            break;
        }
        sm /= 2.0;
        sr /= 2.0;
        out.push((level, (sm, sr)));
    }
    out
}

/// The steps of the pattern search's last level.
fn finest_steps(steps: Steps) -> (f64, f64) {
    levels(steps, 0)
        .last()
        .map_or((steps.step_m, steps.step_rad), |l| l.1)
}

/// `here` and its neighbours by `moves` (some of `MOVES_AROUND`) at steps `sm` metres and `sr`
/// radians, kept inside the search window.
fn moves_around(
    here: Candidate,
    moves: &[(f64, f64, f64, f64, f64, f64, f64)],
    (sm, sr): (f64, f64),
    [right, fwd]: [[f64; 2]; 2],
    search_rad: f64,
    p: &RegistrationParams,
) -> Vec<Candidate> {
    let mut around = Vec::with_capacity(1 + moves.len());
    around.push(here);
    let (hm, pr, fr, rr) = (
        p.search_height_m,
        p.search_pitch_deg.to_radians(),
        p.search_focal,
        p.search_roll_deg.to_radians(),
    );
    for &(a, b, k, z, t, f, r) in moves {
        if (z != 0.0 && hm == 0.0)
            || (t != 0.0 && pr == 0.0)
            || (f != 0.0 && fr == 0.0)
            || (r != 0.0 && rr == 0.0)
        {
            continue;
        }
        // a and b along the camera's right and forward axes in plan.
        around.push([
            (here[0] + (a * right[0] + b * fwd[0]) * sm).clamp(-p.search_m, p.search_m),
            (here[1] + (a * right[1] + b * fwd[1]) * sm).clamp(-p.search_m, p.search_m),
            (here[2] + k * sr).clamp(-search_rad, search_rad),
            (here[3] + z * sm).clamp(-hm, hm),
            (here[4] + t * sr).clamp(-pr, pr),
            // A relative focal step of sr moves the image's edge about as far as a turn of sr.
            (here[5] + f * sr).clamp(-fr, fr),
            (here[6] + r * sr).clamp(-rr, rr),
        ]);
    }
    around
}

/// The pose to use and the outcome, given the best pose found and the agreement `before` (at
/// the reported pose) and `after` (at the best): the best pose only where it beats the reported
/// one by `min_gain`, agrees on at least `min_agreement`, and does not lie on the window's edge.
/// A step of its own: the search proposes, this decides.
fn verdict(
    view: &View,
    best: Candidate,
    (before, after): (f64, f64),
    search_rad: f64,
    by_facades: bool,
    p: &RegistrationParams,
) -> (Pose, Refinement) {
    if !before.is_finite() {
        return (view.pose, Refinement::unchanged(by_facades));
    }
    // A best pose on the window's edge means the truth lies beyond it, or that nothing within
    // it explains the view: either way not a pose to trust.
    let on_edge = (p.search_m > 0.0
        && (best[0].abs() >= 0.99 * p.search_m || best[1].abs() >= 0.99 * p.search_m))
        || (search_rad > 0.0 && best[2].abs() >= 0.99 * search_rad)
        || (p.search_height_m > 0.0 && best[3].abs() >= 0.99 * p.search_height_m)
        || (p.search_pitch_deg > 0.0 && best[4].abs() >= 0.99 * p.search_pitch_deg.to_radians())
        || (p.search_focal > 0.0 && best[5].abs() >= 0.99 * p.search_focal)
        || (p.search_roll_deg > 0.0 && best[6].abs() >= 0.99 * p.search_roll_deg.to_radians());
    let accepted =
        after.is_finite() && after - before >= p.min_gain && after >= p.min_agreement && !on_edge;
    let refinement = Refinement {
        shift_m: if accepted {
            [best[0], best[1]]
        } else {
            [0.0; 2]
        },
        yaw_deg: if accepted { best[2].to_degrees() } else { 0.0 },
        dz_m: if accepted { best[3] } else { 0.0 },
        pitch_deg: if accepted { best[4].to_degrees() } else { 0.0 },
        roll_deg: if accepted { best[6].to_degrees() } else { 0.0 },
        focal_scale: if accepted { 1.0 + best[5] } else { 1.0 },
        before,
        after: if accepted { after } else { before },
        accepted,
        by_facades,
    };
    if !accepted {
        return (view.pose, refinement);
    }
    (turned(&view.pose, best), refinement)
}

/// The middle of the plateau of equal agreement around `best`, along each of `axes` in turn
/// (the camera's right and forward in plan): walked in `FINEST_STEP_M` / 2 steps each way,
/// at most `PLATEAU_STEPS`, while the agreement stays at its level at `best`.
fn plateau_middle(
    best: Candidate,
    agreement: &dyn Fn(Candidate) -> f64,
    axes: [[f64; 2]; 2],
    p: &RegistrationParams,
) -> Candidate {
    let top = agreement(best);
    if !top.is_finite() {
        return best;
    }
    let step = FINEST_STEP_M / 2.0;
    let at = |from: Candidate, axis: [f64; 2], k: f64| -> Candidate {
        [
            (from[0] + axis[0] * step * k).clamp(-p.search_m, p.search_m),
            (from[1] + axis[1] * step * k).clamp(-p.search_m, p.search_m),
            from[2],
            from[3],
            from[4],
            from[5],
            from[6],
        ]
    };
    let mut here = best;
    for axis in axes {
        let reach = |sign: f64| {
            (1..=PLATEAU_STEPS)
                .take_while(|&k| agreement(at(here, axis, sign * k as f64)) >= top)
                .count() as f64
        };
        let (back, ahead) = (reach(-1.0), reach(1.0));
        here = at(here, axis, (ahead - back) / 2.0);
    }
    if agreement(here) >= top { here } else { best }
}

/// How far `plateau_middle` walks each way along an axis, in its steps.
const PLATEAU_STEPS: usize = 8;

/// `pose` moved by (dx, dy, dz), rolled about its forward axis, pitched about its right axis,
/// then turned by yaw about the vertical through the camera (as [`Turn`] turns its rays).
fn turned(pose: &Pose, c: Candidate) -> Pose {
    let turn = Turn::of(pose, c);
    let r = pose.rotation;
    let cols: [[f64; 3]; 3] =
        std::array::from_fn(|col| turn.turn([r[0][col], r[1][col], r[2][col]]));
    Pose {
        position: [
            pose.position[0] + c[0],
            pose.position[1] + c[1],
            pose.position[2] + c[3],
        ],
        rotation: std::array::from_fn(|row| std::array::from_fn(|col| cols[col][row])),
    }
}

/// Refines every view's pose against `scene`; per view in order, its new pose and what was
/// done. Deterministic at any thread count (each view on its own). Views are read one at a time
/// in each pass, so memory does not grow with their number.
pub fn register_views(
    scene: &Scene,
    views: Views,
    p: &RegistrationParams,
    progress: &dyn Progress,
) -> Result<Vec<(Pose, Refinement)>, StageError> {
    if p.is_off() {
        return Ok(views
            .set
            .views
            .iter()
            .map(|v| {
                let kept = Refinement {
                    shift_m: [0.0; 2],
                    yaw_deg: 0.0,
                    dz_m: 0.0,
                    pitch_deg: 0.0,
                    roll_deg: 0.0,
                    focal_scale: 1.0,
                    before: f64::NAN,
                    after: f64::NAN,
                    accepted: false,
                    by_facades: false,
                };
                (v.pose, kept)
            })
            .collect());
    }
    let rays = SceneRays::new(scene);
    let by_triangle = shown_by_triangle(scene);
    let twin = Twin {
        rays: &rays,
        shown_by_triangle: &by_triangle,
        max_range: p.max_range_m as f32,
    };
    progress.set_total(views.len() as u64);
    // First pass, and each placed view's façade labels pooled for the second while it is loaded.
    let (mut out, pools): (Vec<(Pose, Refinement)>, Vec<Option<Pool>>) = views
        .map(|_, v| {
            let (pose, r) = refine_view(v, &twin, None, None, p);
            let pool = r.accepted.then(|| {
                let c = r.candidate();
                let at = [
                    v.pose.position[0] + c[0],
                    v.pose.position[1] + c[1],
                    v.pose.position[2] + c[3],
                ];
                twin.pool(p.consensus_cell_m, v, at, Turn::of(&v.pose, c), p)
            });
            progress.advance(1);
            ((pose, r), pool)
        })?
        .into_iter()
        .unzip();
    // Second pass: every view again, now also against the façade labels the views placed by
    // their silhouettes pooled (less its own), which places the views the silhouettes could not
    // and sharpens the rest. Pools are summed in view order: the same at any thread count.
    let mut consensus = Consensus {
        cell_m: p.consensus_cell_m,
        cells: Default::default(),
    };
    for pool in pools.iter().flatten() {
        consensus.add(pool);
    }
    if consensus.cells.is_empty() {
        return Ok(out);
    }
    let second: Vec<(Pose, Refinement)> = views.map(|k, v| {
        let others = OthersSay::new(&consensus, pools[k].as_ref());
        let first = &out[k].1;
        let start = first.accepted.then(|| first.candidate());
        refine_view(v, &twin, Some(&others), start, p)
    })?;
    for (slot, s) in out.iter_mut().zip(second) {
        if s.1.accepted {
            *slot = s;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
