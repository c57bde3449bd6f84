//! Façade relief (paper Sec. 4.2.2, Fig. 2): per-view region relief votes from semantic and
//! geometric cues, fused onto the wall charts by the exposure-weighted operator of eq. (2)-(3)
//! at a high gamma, turned into a per-texel posterior over the displacement class by discrete
//! Bayesian fusion (eq. (4)), and extracted as rectangular instances with a depth.
//!
//! Per view: the reported depth is calibrated against the twin (a robust affine fit of reported
//! depth against the ray-cast depth on wall pixels: monocular depth is affinely biased); regions
//! are connected pixels of one non-wall architectural instance, or unlabelled pixels (what
//! segmentation missed), kept when a dominant wall encloses them; each kept region is classified
//! recessed, neutral or protruding by `g(v)` over three cues: the depth step against the wall
//! plane fitted around it, the flow of its normals (side faces point toward the centre of a
//! recess and away from a protrusion's), and its semantic class as a prior.

pub mod carve;

use std::collections::{BTreeMap, BTreeSet};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{
    ChartKind, ChartLayers, ChartSet, PodVec, ReliefInstance, ReliefLayers, ReliefSet, ReliefStats,
    Scene, SparseLayer, View,
};
use crate::geom::raycast::SceneRays;
use crate::geom::union_find::UnionFind;
use crate::raster::label::label_components;
use crate::raster::label::label_regions;
use crate::raster::morph::{close_within, dilate, erode, on_support};
use crate::stage::Progress;
use crate::street::fusion::{ChartLookup, FusionParams, Vote, fuse_views_each};

/// The displacement classes Y, in the order every probability triple uses.
pub const RELIEF_CLASSES: [&str; 3] = ["recessed", "neutral", "protruding"];

/// Per semantic class: its prior sign, the depths it may be carved at, and whether it runs up
/// the wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassRule {
    /// The architectural class name the views use.
    pub name: String,
    /// The semantic cue v_semantic: -1 recessed, 0 none, +1 protruding.
    pub prior: i8,
    /// Depth range, metres (min, max): an instance's measured depth is clamped into it.
    pub depth_m: (f64, f64),
    /// The feature runs the wall's height (a downpipe, from its gutter at the eave to the
    /// ground): an instance reaches up to the wall's top and down to the terrain through texels
    /// the views did not observe or that hold some of its evidence, and through flat wall the
    /// views saw well enough to have resolved it (with `width_m`, the exposure of a view that
    /// sees its widest across as one pixel) for less than `run_stop_m`; pieces of it that then
    /// overlap are one instance. Default false.
    #[serde(default, alias = "runs_up")]
    pub runs_full_height: bool,
    /// Width range across the wall, metres (min, max), for a class whose width the evidence
    /// cannot tell: a feature not much wider than a texel reads as wide as the fusion's kernel
    /// plus the views' registration scatter (a 0.12 m drainpipe reads 0.2-0.3 m), so its
    /// rectangle keeps the evidence's centre and takes a width within this range. None (the
    /// default): the evidence's width.
    #[serde(default)]
    pub width_m: Option<(f64, f64)>,
}

/// Weights of the cues in g(v).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CueWeights {
    /// The class prior.
    pub semantic: f64,
    /// The depth step against the surrounding wall plane.
    pub depth: f64,
    /// The normal flow.
    pub normal: f64,
}

/// The conditional probability table of eq. (4), stored as the two small tables it is built
/// from (see [`Cpt::expand`]) plus optional explicit rows that replace derived ones.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Cpt {
    /// Pr(Y | R, P) from the images alone (the latent mesh state unknown): 9 triples (recessed,
    /// neutral, protruding), R level major (R = 0, P = 0..2; R = 1, ...).
    pub image: Vec<(f64, f64, f64)>,
    /// Pr(d | Y): for Y = recessed, neutral, protruding (rows) the probability that a source
    /// mesh shows the façade behind (d = in), at (flush) or in front of (out) ours.
    pub mesh: Vec<(f64, f64, f64)>,
    /// Pr(Y) where no view observed the texel (used with a mesh only).
    pub prior: (f64, f64, f64),
    /// Rows that replace derived ones: Pr(Y | d, R, P) given outright.
    pub rows: Vec<CptRow>,
}

/// One explicit row of the CPT.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CptRow {
    /// The latent mesh state.
    pub d: MeshState,
    /// Recessed evidence level (0, 1, 2).
    pub r: u8,
    /// Protruding evidence level (0, 1, 2).
    pub p: u8,
    /// Pr(Y = recessed, neutral, protruding).
    pub y: (f64, f64, f64),
}

/// The latent mesh-discrepancy state d of eq. (4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum MeshState {
    /// The source mesh lies behind our façade.
    In,
    /// It agrees with our façade.
    Flush,
    /// It stands in front of our façade.
    Out,
    /// No information (no source mesh, or none found along the normal).
    Unknown,
}

impl Default for Cpt {
    /// The defaults, and why:
    /// - `image`: a texel most of whose exposure voted recessed (R = 2, share >= the upper level)
    ///   is recessed with 0.85; some votes (R = 1) give 0.35, not enough alone (a view whose
    ///   region spilled over, or one view among many), but enough with a mesh that agrees; no
    ///   votes either way is flat with 0.94 (the wall was seen and looked flat). Conflicting
    ///   strong votes (R = P = 2, e.g. a window behind a balcony railing) split evenly between
    ///   the two relief classes. The table is symmetric in R and P.
    /// - `mesh`: a photogrammetry mesh is right about a recess 70 % of the time (it smooths
    ///   shallow relief: 25 % flush), and shows spurious relief on a flat wall 10 % of the time.
    /// - `prior`: 10 % of façade area is recessed, 10 % protruding (the synthetic city's windows
    ///   cover about 15 % of its walls), 80 % flat.
    fn default() -> Self {
        Cpt {
            image: vec![
                (0.03, 0.94, 0.03),
                (0.03, 0.62, 0.35),
                (0.03, 0.12, 0.85),
                (0.35, 0.62, 0.03),
                (0.25, 0.50, 0.25),
                (0.15, 0.25, 0.60),
                (0.85, 0.12, 0.03),
                (0.60, 0.25, 0.15),
                (0.45, 0.10, 0.45),
            ],
            mesh: vec![(0.70, 0.25, 0.05), (0.05, 0.90, 0.05), (0.05, 0.25, 0.70)],
            prior: (0.1, 0.8, 0.1),
            rows: Vec::new(),
        }
    }
}

/// The CPT expanded to every (d, R, P): Pr(Y | d, R, P), and Pr(Y | d) where unobserved.
#[derive(Clone, Debug, PartialEq)]
pub struct ExpandedCpt {
    /// `[d][r][p]` -> (recessed, neutral, protruding); d in the order In, Flush, Out, Unknown.
    pub observed: [[[[f64; 3]; 3]; 3]; 4],
    /// `[d]` -> Pr(Y | d, unobserved); `None` for Unknown (no evidence at all).
    pub unobserved: [Option<[f64; 3]>; 4],
}

fn tri(t: (f64, f64, f64)) -> [f64; 3] {
    [t.0, t.1, t.2]
}

fn normalised(y: [f64; 3]) -> [f64; 3] {
    let s: f64 = y.iter().sum();
    if s > 0.0 {
        y.map(|v| v / s)
    } else {
        [0.0, 1.0, 0.0]
    }
}

fn check_triple(t: (f64, f64, f64), what: &str) -> Result<(), String> {
    let y = tri(t);
    if y.iter().any(|v| !v.is_finite() || *v < 0.0) || (y.iter().sum::<f64>() - 1.0).abs() > 1e-6 {
        return Err(format!(
            "{what}: expected three probabilities summing to 1, got {t:?}"
        ));
    }
    Ok(())
}

fn state_index(d: MeshState) -> usize {
    match d {
        MeshState::In => 0,
        MeshState::Flush => 1,
        MeshState::Out => 2,
        MeshState::Unknown => 3,
    }
}

impl Cpt {
    /// Checks shapes and that every row is a distribution.
    pub fn validate(&self) -> Result<(), String> {
        if self.image.len() != 9 {
            return Err(format!(
                "cpt.image: expected 9 rows (R 0..2 x P 0..2), got {}",
                self.image.len()
            ));
        }
        if self.mesh.len() != 3 {
            return Err(format!(
                "cpt.mesh: expected 3 rows (Y = recessed, neutral, protruding), got {}",
                self.mesh.len()
            ));
        }
        for (k, t) in self.image.iter().enumerate() {
            check_triple(*t, &format!("cpt.image[{k}]"))?;
        }
        for (k, t) in self.mesh.iter().enumerate() {
            check_triple(*t, &format!("cpt.mesh[{k}]"))?;
        }
        check_triple(self.prior, "cpt.prior")?;
        let mut seen = BTreeSet::new();
        for (k, row) in self.rows.iter().enumerate() {
            if row.r > 2 || row.p > 2 {
                return Err(format!("cpt.rows[{k}]: levels are 0, 1 or 2"));
            }
            check_triple(row.y, &format!("cpt.rows[{k}].y"))?;
            if !seen.insert((state_index(row.d), row.r, row.p)) {
                return Err(format!(
                    "cpt.rows[{k}]: ({:?}, {}, {}) given twice",
                    row.d, row.r, row.p
                ));
            }
        }
        Ok(())
    }

    /// The full table: Pr(Y | Unknown, R, P) is `image`; for a mesh state d,
    /// Pr(Y | d, R, P) ∝ Pr(Y | R, P) Pr(d | Y) (the mesh and the views err independently given
    /// the true class); unobserved, Pr(Y | d) ∝ Pr(Y) Pr(d | Y). Explicit `rows` then replace
    /// derived entries.
    pub fn expand(&self) -> ExpandedCpt {
        let mut observed = [[[[0.0; 3]; 3]; 3]; 4];
        let mut unobserved = [None; 4];
        for (d, by_r) in observed.iter_mut().enumerate() {
            for (r, by_p) in by_r.iter_mut().enumerate() {
                for (p, row) in by_p.iter_mut().enumerate() {
                    let img = tri(self.image[r * 3 + p]);
                    *row = if d == 3 {
                        img
                    } else {
                        normalised(std::array::from_fn(|y| img[y] * tri(self.mesh[y])[d]))
                    };
                }
            }
            if d < 3 {
                let prior = tri(self.prior);
                unobserved[d] = Some(normalised(std::array::from_fn(|y| {
                    prior[y] * tri(self.mesh[y])[d]
                })));
            }
        }
        for row in &self.rows {
            observed[state_index(row.d)][row.r as usize][row.p as usize] = tri(row.y);
        }
        ExpandedCpt {
            observed,
            unobserved,
        }
    }
}

/// How the source mesh's discrepancy Delta becomes Pr(d | Delta).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeltaParams {
    /// |Delta| at which in (or out) and flush are equally likely, metres.
    pub tau_m: f64,
    /// Width of the logistic transition, metres (the mesh's noise).
    pub scale_m: f64,
    /// Weight of the mesh: Pr(d = Unknown | Delta) = 1 - trust.
    pub trust: f64,
    /// How far along the normal to look for the mesh, each way, metres.
    pub search_m: f64,
}

impl Default for DeltaParams {
    fn default() -> Self {
        DeltaParams {
            tau_m: 0.1,
            scale_m: 0.03,
            trust: 0.8,
            search_m: 1.0,
        }
    }
}

/// Pr(d | Delta) over (In, Flush, Out, Unknown): logistic in Delta around ±tau, scaled by the
/// mesh's trust; all Unknown when Delta is not finite (no mesh there).
pub fn mesh_state_probabilities(delta: f64, p: &DeltaParams) -> [f64; 4] {
    if !delta.is_finite() {
        return [0.0, 0.0, 0.0, 1.0];
    }
    let s = |x: f64| 1.0 / (1.0 + (-x / p.scale_m).exp());
    let pin = s(-delta - p.tau_m);
    let pout = s(delta - p.tau_m);
    let flush = (1.0 - pin - pout).max(0.0);
    let t = p.trust;
    [t * pin, t * flush, t * pout, 1.0 - t]
}

/// Eq. (4), discrete Bayesian fusion of the evidence e_q = (R_q, P_q, Delta_q):
///
/// Pr(Y_q = y | e_q) = Σ_d Pr(Y_q = y | d, R_q, P_q) Pr(d | Delta_q),
///
/// with `levels` the discretised (R, P), `None` where the texel is unobserved, and `pd` =
/// Pr(d | Delta) over (In, Flush, Out, Unknown). Returns (recessed, neutral, protruding), or
/// `None` where there is no evidence at all (unobserved and no mesh): an unobserved texel is
/// never evidence for a flat wall.
pub fn relief_posterior(
    cpt: &ExpandedCpt,
    levels: Option<(u8, u8)>,
    pd: [f64; 4],
) -> Option<[f64; 3]> {
    let mut y = [0.0; 3];
    let mut mass = 0.0;
    for (d, w) in pd.iter().enumerate() {
        if *w <= 0.0 {
            continue;
        }
        let row = match levels {
            Some((r, p)) => cpt.observed[d][r.min(2) as usize][p.min(2) as usize],
            None => match cpt.unobserved[d] {
                Some(row) => row,
                None => continue,
            },
        };
        for k in 0..3 {
            y[k] += w * row[k];
        }
        mass += w;
    }
    // Unobserved, the Unknown state carries no row: what remains is conditioned on the mesh.
    (mass > 0.0).then(|| y.map(|v| v / mass))
}

/// Discretises an evidence share into levels 0, 1, 2 at the two thresholds.
pub fn level(share: f64, levels: (f64, f64)) -> u8 {
    if share >= levels.1 {
        2
    } else if share >= levels.0 {
        1
    } else {
        0
    }
}

/// Everything the relief needs, named as in the paper where it has a name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReliefParams {
    /// gamma_fac: the stage exponent on the Jacobian, high (close, head-on views dominate).
    /// Default 2.
    pub gamma: f64,
    /// Angle gate theta_max, degrees. Default 70.
    pub theta_max_deg: f64,
    /// Kernel sigma, texels. Default 0.5 (a drainpipe is about one texel wide).
    pub sigma_texels: f64,
    /// One fusion ray every `stride` pixels each way. Default 1.
    pub stride: u32,
    /// Clutter pixels neither vote nor count as exposure. Default true.
    pub mask_clutter: bool,
    /// The architectural class of the walls regions must sit in. Default "wall".
    pub wall_class: String,
    /// Classes that never form regions (roofs). Default ["roof"].
    pub ignore_classes: Vec<String>,
    /// Per class: prior sign, depth range, and whether it runs up the wall. Default: windows
    /// and doors recessed 0.1-0.3 m, balconies protruding 0.3-1.5 m, drainpipes protruding
    /// 0.05-0.3 m and running up to the eave.
    pub classes: Vec<ClassRule>,
    /// Depth range of recesses of no known class, metres. Default (0.05, 0.5).
    pub unknown_recess_m: (f64, f64),
    /// Depth range of protrusions of no known class, metres. Default (0.05, 1.5).
    pub unknown_protrusion_m: (f64, f64),
    /// Smallest region, pixels. Default 6.
    pub min_region_px: u32,
    /// Width of the ring around a region where its enclosing wall is looked for, pixels.
    /// Default 3.
    pub ring_px: u32,
    /// Share of the ring (clutter and sky aside) walls must hold. Default 0.5.
    pub enclosure_min: f64,
    /// Unlabelled ring pixels whose calibrated depth puts them this close to the region's chart
    /// plane count as wall (a wall the segmentation missed), metres. Default 0.3.
    pub plane_tol_m: f64,
    /// Smallest depth step that counts, metres. Default 0.05. A protruding instance needs its
    /// views to have measured it standing out at least this far: the class in the image alone
    /// does not say which wall a protrusion stands on (a drainpipe round the corner, seen
    /// past it, lands on the near wall's last texels).
    pub min_step_m: f64,
    /// And its significance: step over its standard error. Default 3.
    pub step_z_min: f64,
    /// A pixel whose normal is further than this from the wall's is a side face, degrees.
    /// Default 30.
    pub side_angle_deg: f64,
    /// Share of side-face pixels needed for the normal cue. Default 0.05.
    pub min_side_share: f64,
    /// Agreement of the side faces' flow needed for the normal cue, in [0, 1]. Default 0.3.
    pub flow_min: f64,
    /// Cue weights in g(v).
    pub weights: CueWeights,
    /// |score| needed for a non-neutral region label. Default 1.
    pub score_min: f64,
    /// Exposure unit: one head-on view from this far, metres. Default 30.
    pub ref_distance_m: f64,
    /// Texels with less exposure (in those units) stay unobserved. Default 1.
    pub exposure_min: f64,
    /// Thresholds discretising R and P into levels 0, 1, 2. Default (0.2, 0.5).
    pub levels: (f64, f64),
    /// The CPT of eq. (4).
    pub cpt: Cpt,
    /// Pr(d | Delta).
    pub delta: DeltaParams,
    /// Posterior an instance's texels need. Default 0.5.
    pub threshold: f64,
    /// Lower posterior through which texels over `threshold` join into one instance
    /// (hysteresis); the instance's extent is still its texels over `threshold`. Default 0.3:
    /// a texel with some votes (R or P at level 1 gives 0.35 in the default CPT), not a texel
    /// that looked flat (0.03).
    pub grow_threshold: f64,
    /// Morphological opening radius for recesses and protrusions, texels. Default (1, 0): a
    /// drainpipe is one texel wide.
    pub open_texels: (u32, u32),
    /// Closing radius, texels. Default 1.
    pub close_texels: u32,
    /// Smallest instance, texels. Default 6.
    pub min_texels: u32,
    /// Widest stretch of unobserved texels (or texels with some evidence) across which two
    /// pieces of one feature join, texels. Default 5: a balcony slab's shadow on a drainpipe.
    pub bridge_texels: u32,
    /// The stretch of flat wall, seen well enough to have resolved it, that stops a feature
    /// running the wall's height (`ClassRule::runs_full_height`), metres. Default 3, a storey:
    /// a pipe the one close view's segmentation missed, or far views read flat, over part of
    /// its run goes on; one that ends stops.
    pub run_stop_m: f64,
}

impl Default for ReliefParams {
    fn default() -> Self {
        let rule = |name: &str, prior, depth_m, runs_full_height, width_m| ClassRule {
            name: name.into(),
            prior,
            depth_m,
            runs_full_height,
            width_m,
        };
        ReliefParams {
            gamma: 2.0,
            theta_max_deg: 70.0,
            sigma_texels: 0.5,
            stride: 1,
            mask_clutter: true,
            wall_class: "wall".into(),
            ignore_classes: vec!["roof".into()],
            classes: vec![
                rule("window", -1, (0.1, 0.3), false, None),
                rule("door", -1, (0.1, 0.3), false, None),
                rule("balcony", 1, (0.3, 1.5), false, None),
                // Views see a drainpipe between balconies and parked cars, in pieces, and rarely
                // up to the eave from the street: it runs there all the same. Downpipes are
                // made 50 to 150 mm across (EN 12200's nominal sizes).
                rule("drainpipe", 1, (0.05, 0.3), true, Some((0.05, 0.15))),
            ],
            unknown_recess_m: (0.05, 0.5),
            unknown_protrusion_m: (0.05, 1.5),
            min_region_px: 6,
            ring_px: 3,
            enclosure_min: 0.5,
            plane_tol_m: 0.3,
            min_step_m: 0.05,
            step_z_min: 3.0,
            side_angle_deg: 30.0,
            min_side_share: 0.05,
            flow_min: 0.3,
            weights: CueWeights {
                semantic: 1.0,
                depth: 2.0,
                normal: 1.0,
            },
            score_min: 1.0,
            ref_distance_m: 30.0,
            exposure_min: 1.0,
            levels: (0.2, 0.5),
            cpt: Cpt::default(),
            delta: DeltaParams::default(),
            threshold: 0.5,
            grow_threshold: 0.3,
            open_texels: (1, 0),
            close_texels: 1,
            min_texels: 6,
            bridge_texels: 5,
            run_stop_m: 3.0,
        }
    }
}

impl ReliefParams {
    /// Checks every knob: (field, message) of the first bad one.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let range = crate::params::check_in;
        range("gamma", self.gamma, 0.0, 8.0)?;
        range("theta_max_deg", self.theta_max_deg, 1.0, 90.0)?;
        range("sigma_texels", self.sigma_texels, 0.0, 8.0)?;
        if !(1..=64).contains(&self.stride) {
            return Err(("stride", "expected 1 to 64 pixels".into()));
        }
        let depth_range = |name: &'static str, r: (f64, f64)| {
            if r.0.is_finite() && r.1.is_finite() && r.0 >= 0.0 && r.0 <= r.1 && r.1 <= 10.0 {
                Ok(())
            } else {
                Err((name, format!("expected 0 <= min <= max <= 10 m, got {r:?}")))
            }
        };
        for c in &self.classes {
            depth_range("classes", c.depth_m)?;
            if let Some(w) = c.width_m {
                depth_range("classes", w)?;
            }
            if !(-1..=1).contains(&c.prior) {
                return Err(("classes", format!("{}: prior is -1, 0 or 1", c.name)));
            }
        }
        let names: BTreeSet<&str> = self.classes.iter().map(|c| c.name.as_str()).collect();
        if names.len() != self.classes.len() {
            return Err(("classes", "a class is listed twice".into()));
        }
        depth_range("unknown_recess_m", self.unknown_recess_m)?;
        depth_range("unknown_protrusion_m", self.unknown_protrusion_m)?;
        if !(1..=100_000).contains(&self.min_region_px) {
            return Err(("min_region_px", "expected 1 to 100000 pixels".into()));
        }
        if !(1..=32).contains(&self.ring_px) {
            return Err(("ring_px", "expected 1 to 32 pixels".into()));
        }
        range("enclosure_min", self.enclosure_min, 0.0, 1.0)?;
        range("plane_tol_m", self.plane_tol_m, 0.0, 10.0)?;
        range("min_step_m", self.min_step_m, 0.0, 5.0)?;
        range("step_z_min", self.step_z_min, 0.0, 100.0)?;
        range("side_angle_deg", self.side_angle_deg, 1.0, 89.0)?;
        range("min_side_share", self.min_side_share, 0.0, 1.0)?;
        range("flow_min", self.flow_min, 0.0, 1.0)?;
        range("weights.semantic", self.weights.semantic, 0.0, 100.0)?;
        range("weights.depth", self.weights.depth, 0.0, 100.0)?;
        range("weights.normal", self.weights.normal, 0.0, 100.0)?;
        range("score_min", self.score_min, 0.0, 1000.0)?;
        range("ref_distance_m", self.ref_distance_m, 0.1, 10_000.0)?;
        range("exposure_min", self.exposure_min, 0.0, 1e9)?;
        range("levels", self.levels.0, 0.0, 1.0)?;
        range("levels", self.levels.1, self.levels.0, 1.0)?;
        self.cpt.validate().map_err(|m| ("cpt", m))?;
        range("delta.tau_m", self.delta.tau_m, 0.0, 10.0)?;
        range("delta.scale_m", self.delta.scale_m, 1e-4, 10.0)?;
        range("delta.trust", self.delta.trust, 0.0, 1.0)?;
        range("delta.search_m", self.delta.search_m, 0.01, 50.0)?;
        range("threshold", self.threshold, 0.0, 1.0)?;
        range("grow_threshold", self.grow_threshold, 0.0, self.threshold)?;
        if self.open_texels.0 > 16 || self.open_texels.1 > 16 || self.close_texels > 16 {
            return Err(("open_texels", "expected radii of at most 16 texels".into()));
        }
        if !(1..=1_000_000).contains(&self.min_texels) {
            return Err(("min_texels", "expected 1 to 10^6 texels".into()));
        }
        if self.bridge_texels > 1000 {
            return Err(("bridge_texels", "expected 0 to 1000 texels".into()));
        }
        range("run_stop_m", self.run_stop_m, 0.0, 1000.0)?;
        Ok(())
    }

    /// The depth range of an instance of `class` and `sign`.
    pub fn depth_range(&self, class: &str, sign: i8) -> (f64, f64) {
        match self.classes.iter().find(|c| c.name == class) {
            Some(c) => c.depth_m,
            None if sign < 0 => self.unknown_recess_m,
            None => self.unknown_protrusion_m,
        }
    }
}

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
const RECESSED: i8 = -1;
const NEUTRAL: i8 = 0;
const PROTRUDING: i8 = 1;
const SEEN: i8 = 2;
const MASKED: i8 = 3;

/// One view's labels: per pixel a code, the displacement of protruding pixels, and its regions.
pub struct ViewRelief {
    codes: Vec<i8>,
    displace: Vec<f32>,
    /// Kept regions.
    pub regions: Vec<RegionVote>,
    /// Candidate regions before the enclosure test.
    pub candidates: u64,
    /// Whether the depth calibrated.
    pub calibrated: bool,
}

/// Object and triangle -> chart index, and which objects are terrain.
struct Lookup {
    charts: ChartLookup,
    terrain: Vec<bool>,
}

impl Lookup {
    fn new(scene: &Scene, charts: &ChartSet) -> Lookup {
        let terrain = scene
            .objects
            .iter()
            .map(|o| o.class == crate::artifact::ObjectClass::Terrain)
            .collect();
        Lookup {
            charts: ChartLookup::new(scene, charts),
            terrain,
        }
    }

    fn wall_chart(&self, charts: &ChartSet, object: usize, tri: usize) -> Option<u32> {
        let c = self.charts.chart(object, tri)?;
        (charts.charts[c as usize].kind == ChartKind::Wall).then_some(c)
    }
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// Median and its standard error (1.4826 MAD x 1.2533 / sqrt(n)).
fn median_se(v: &mut [f64]) -> (f64, f64) {
    let m = median(v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    let mad = median(&mut dev);
    (m, 1.4826 * mad * 1.2533 / (v.len() as f64).sqrt())
}

/// Robust affine fit y = a x + b: least squares, then refits on the points within three robust
/// standard deviations of the line, four times. `None` when too few points or too little spread
/// in x to separate scale from offset.
pub fn robust_affine(xs: &[f64], ys: &[f64]) -> Option<(f64, f64)> {
    let n = xs.len();
    if n < 30 {
        return None;
    }
    let mut keep = vec![true; n];
    let mut fit = None;
    for _ in 0..5 {
        let (mut sx, mut sy, mut c) = (0.0, 0.0, 0.0);
        for i in 0..n {
            if keep[i] {
                sx += xs[i];
                sy += ys[i];
                c += 1.0;
            }
        }
        if c < 30.0 {
            return None;
        }
        let (mx, my) = (sx / c, sy / c);
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for i in 0..n {
            if keep[i] {
                sxx += (xs[i] - mx) * (xs[i] - mx);
                sxy += (xs[i] - mx) * (ys[i] - my);
            }
        }
        // Depth must spread over at least 1 m (std) to tell scale from offset.
        if sxx / c < 1.0 {
            return None;
        }
        let a = sxy / sxx;
        let b = my - a * mx;
        fit = Some((a, b));
        let mut res: Vec<f64> = (0..n).map(|i| (ys[i] - a * xs[i] - b).abs()).collect();
        let mad = median(&mut res.clone()).max(1e-6);
        for i in 0..n {
            keep[i] = res[i] <= 3.0 * 1.4826 * mad;
        }
        res.clear();
    }
    fit.filter(|(a, b)| *a > 0.0 && a.is_finite() && b.is_finite())
}

/// Calibrates a view's reported depth against the twin: (a, b) with reported = a z + b, from
/// wall pixels whose ray hits a wall chart and unlabelled pixels whose ray hits the terrain
/// (every 4th pixel each way): the ground spreads the depths a head-on wall alone does not.
fn calibrate(
    view: &View,
    rays: &SceneRays,
    charts: &ChartSet,
    lookup: &Lookup,
    is_wall: &dyn Fn(usize) -> bool,
    is_ground: &dyn Fn(usize) -> bool,
) -> Option<(f64, f64)> {
    let depth = view.depth.as_ref()?;
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    let origin = view.pose.position.map(|c| c as f32);
    for y in (2..view.height).step_by(4) {
        for x in (2..view.width).step_by(4) {
            let px = (y * view.width + x) as usize;
            let d = depth.get(px).copied().unwrap_or(f32::NAN) as f64;
            let (wall, ground) = (is_wall(px), is_ground(px));
            if !d.is_finite() || !(wall || ground) {
                continue;
            }
            let (dir, norm) = view.pixel_ray(x as f64 + 0.5, y as f64 + 0.5);
            let Some(hit) = rays.cast(origin, dir.map(|c| c as f32), 1e-3, 2000.0) else {
                continue;
            };
            let ok = if wall {
                lookup
                    .wall_chart(charts, hit.object, hit.triangle)
                    .is_some()
            } else {
                lookup.terrain.get(hit.object).copied().unwrap_or(false)
            };
            if !ok {
                continue;
            }
            xs.push(hit.t as f64 / norm);
            ys.push(d);
        }
    }
    robust_affine(&xs, &ys)
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

/// The relief labels of one view: regions, their cues, g(v), and the per-pixel codes.
fn view_relief(
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
    let masked = |px: usize| {
        p.mask_clutter
            && view
                .clutter
                .as_ref()
                .is_some_and(|c| c.ids.get(px).is_some_and(|&id| id != 0))
    };
    let Some(arch) = view.arch.as_ref().filter(|a| a.ids.len() == n) else {
        for (px, c) in out.codes.iter_mut().enumerate() {
            if masked(px) {
                *c = MASKED;
            }
        }
        return out;
    };
    let class_of = |px: usize| -> Option<&str> {
        let id = arch.ids[px];
        (id != 0)
            .then(|| arch.classes.get(&id).map(String::as_str))
            .flatten()
    };
    let is_wall = |px: usize| class_of(px) == Some(p.wall_class.as_str());
    let depth = view.depth.as_ref().filter(|d| d.len() == n);
    let normals = view.normal.as_ref().filter(|d| d.len() == n);
    let is_ground = |px: usize| arch.ids[px] == 0 && !masked(px);
    let is_sky = |px: usize| arch.ids[px] == 0 && depth.is_some_and(|d| !d[px].is_finite());
    let cal = depth.and_then(|_| calibrate(view, rays, charts, lookup, &is_wall, &is_ground));
    out.calibrated = cal.is_some();
    // Region keys: a non-wall instance's id, or all unlabelled pixels with a depth.
    let mut key = vec![0u32; n];
    for px in 0..n {
        if masked(px) {
            out.codes[px] = MASKED;
            continue;
        }
        let id = arch.ids[px];
        if id == 0 {
            let has_depth = depth.is_some_and(|d| d[px].is_finite());
            if has_depth {
                let level = normals
                    .is_some_and(|nm| view.pose.to_site(nm[px].map(|c| c as f64))[2] >= LEVEL_NZ);
                key[px] = if level { UNLABELLED_LEVEL } else { UNLABELLED };
            }
            continue;
        }
        match arch.classes.get(&id) {
            Some(c) if *c == p.wall_class => out.codes[px] = NEUTRAL,
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
    out.candidates = members.len() as u64;
    let origin = view.pose.position.map(|c| c as f32);
    let point = |px: usize, (a, b): (f64, f64)| -> Option<[f64; 3]> {
        let d = depth?[px] as f64;
        if !d.is_finite() {
            return None;
        }
        let z = (d - b) / a;
        let (x, y) = ((px as u32 % w) as f64 + 0.5, (px as u32 / w) as f64 + 0.5);
        let (dir, norm) = view.pixel_ray(x, y);
        Some(std::array::from_fn(|k| {
            view.pose.position[k] + dir[k] * z * norm
        }))
    };
    let r = p.ring_px as i64;
    let mut kept = vec![false; members.len()];
    for (ri, pixels) in members.values().enumerate() {
        let first = pixels[0] as usize;
        let class = match arch.ids[first] {
            0 => "unknown".to_owned(),
            id => arch
                .classes
                .get(&id)
                .cloned()
                .unwrap_or_else(|| "unknown".into()),
        };
        // Bounding box, then the ring in a crop around it.
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
        let bx0 = (x0 as i64 - r).max(0) as u32;
        let by0 = (y0 as i64 - r).max(0) as u32;
        let bx1 = (x1 as i64 + r).min(w as i64 - 1) as u32;
        let by1 = (y1 as i64 + r).min(h as i64 - 1) as u32;
        let (cw, ch) = (bx1 - bx0 + 1, by1 - by0 + 1);
        let mut mask = vec![false; (cw * ch) as usize];
        for &q in pixels {
            let (x, y) = (q % w - bx0, q / w - by0);
            mask[(y * cw + x) as usize] = true;
        }
        let grown = dilate(&mask, cw, ch, r);
        let mut ring_total = 0u32;
        let mut ring_px: Vec<(usize, u16)> = Vec::new();
        let mut ring_plain: Vec<usize> = Vec::new();
        for yy in 0..ch {
            for xx in 0..cw {
                let k = (yy * cw + xx) as usize;
                if !grown[k] || mask[k] {
                    continue;
                }
                let px = ((yy + by0) * w + xx + bx0) as usize;
                // Sky past a wall's edge (no label, no depth) neither encloses a region nor
                // speaks against it: a drainpipe by a corner has it on one side.
                if out.codes[px] == MASKED || is_sky(px) {
                    continue;
                }
                ring_total += 1;
                if is_wall(px) {
                    ring_px.push((px, arch.ids[px]));
                } else if arch.ids[px] == 0 {
                    ring_plain.push(px);
                }
            }
        }
        // Enclosed by walls: the two façades of a corner are often two instances, each holding
        // half the ring of a feature at the corner.
        let walls = ring_px.len();
        let enough = |n: usize| n > 0 && n as f64 >= p.enclosure_min * ring_total as f64;
        let walled = enough(walls);
        // The region's chart: where its centre ray meets the twin.
        let (dir, _) = view.pixel_ray(cx, cy);
        let hit = rays.cast(origin, dir.map(|c| c as f32), 1e-3, 2000.0);
        // A protruding feature by a corner, seen from the street round it, stands past the
        // twin's silhouette, against the sky or a street behind: its centre ray meets nothing,
        // or something well beyond where its pixels' depth puts it, and no wall encloses it.
        // It stands on the wall this view sees from behind, whose end that ray passes within
        // the class's depth and the region's half-width. Its pixels say nothing of the
        // surfaces their rays meet, so only the region votes, by its label.
        let prior = p
            .classes
            .iter()
            .find(|c| c.name == class)
            .map_or(0, |c| c.prior);
        if let (true, Some(cal)) = (prior > 0, cal) {
            let depth = |q: usize| point(q, cal);
            let reach = p.depth_range(&class, 1).1;
            let seen = (pixels.as_slice(), (x0, x1, cy), dir);
            let hit_t = hit.map(|h| h.t as f64);
            if let Some((ci, at)) = past_silhouette(view, seen, hit_t, depth, charts, reach) {
                let score = p.weights.semantic * prior as f64;
                let sign: i8 = if score >= p.score_min { 1 } else { 0 };
                for &q in pixels {
                    out.codes[q as usize] = MASKED;
                }
                kept[ri] = true;
                out.regions.push(RegionVote {
                    view: vi as u32,
                    chart: ci,
                    uv: charts.charts[ci as usize].uv_of(at),
                    class,
                    sign,
                    step_m: f64::NAN,
                    pixels: pixels.len() as u32,
                });
                continue;
            }
        }
        if !walled && (cal.is_none() || ring_plain.is_empty()) {
            continue;
        }
        let Some(hit) = hit else {
            continue;
        };
        let Some(ci) = lookup.wall_chart(charts, hit.object, hit.triangle) else {
            continue;
        };
        let chart = &charts.charts[ci as usize];
        let nrm = chart.normal;
        // Where the segmentation missed the wall (its pixels unlabelled), the depth still tells
        // it: unlabelled ring pixels that lie on the chart's plane enclose as wall.
        let on_plane: Vec<usize> = match cal {
            Some(cal) if !walled => {
                let plane = dot(chart.origin, nrm);
                ring_plain
                    .iter()
                    .copied()
                    .filter(|&px| {
                        point(px, cal).is_some_and(|x| (dot(x, nrm) - plane).abs() <= p.plane_tol_m)
                    })
                    .collect()
            }
            _ => Vec::new(),
        };
        if !walled && !enough(walls + on_plane.len()) {
            continue;
        }
        let wall_id = region_wall(&ring_px, ci, |px| {
            let (x, y) = (
                (px % w as usize) as f64 + 0.5,
                (px / w as usize) as f64 + 0.5,
            );
            let (d, _) = view.pixel_ray(x, y);
            rays.cast(origin, d.map(|c| c as f32), 1e-3, 2000.0)
                .and_then(|h| lookup.wall_chart(charts, h.object, h.triangle))
        });
        // A side-face pixel: its normal further than side_angle_deg from the wall's.
        let cos_side = p.side_angle_deg.to_radians().cos();
        let is_side = |q: u32| {
            normals.is_some_and(|nm| {
                let ns = view.pose.to_site(nm[q as usize].map(|c| c as f64));
                dot(ns, nrm) < cos_side
            })
        };
        // Depth cue: step against the plane with the wall's normal fitted to the ring. What
        // spoils a region's median lies between the wall and the feature's face: a jamb, a
        // reveal or a slab's underside (balconies read 0.15 m short over all their pixels), or
        // the wall the mask spills onto (on a 0.12 m drainpipe, more of its pixels than its
        // front). The median over the faces parallel to the wall and the median over all
        // pixels both err toward the wall, so of the two the one farther from it is taken;
        // on a region under FACE_MIN_PX across, all pixels.
        let mut step = f64::NAN;
        let mut v_depth = 0.0;
        if let Some(cal) = cal {
            let mut ring_s: Vec<f64> = ring_px
                .iter()
                .filter(|&&(_, id)| id == wall_id)
                .map(|&(px, _)| px)
                .chain(on_plane.iter().copied())
                .filter_map(|px| point(px, cal))
                .map(|x| dot(x, nrm))
                .collect();
            // Each pixel's offset from the wall, and whether it lies on a face parallel to it.
            let at: Vec<(f64, bool)> = pixels
                .iter()
                .filter_map(|&q| point(q as usize, cal).map(|x| (dot(x, nrm), !is_side(q))))
                .collect();
            let across = pixels.len() as f64 / (x1 - x0 + 1).max(y1 - y0 + 1) as f64;
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
        }
        // Normal cue: side faces' normals point toward a recess's centre, away from a
        // protrusion's (image-plane flow).
        let mut v_normal = 0.0;
        if let Some(nm) = normals {
            let (mut side, mut flow) = (0u32, 0.0);
            for &q in pixels {
                if !is_side(q) {
                    continue;
                }
                let nc = nm[q as usize].map(|c| c as f64);
                side += 1;
                let (x, y) = ((q % w) as f64 + 0.5 - cx, (q / w) as f64 + 0.5 - cy);
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
        // A protrusion is deposited on the plane where it stands.
        let disp = if sign > 0 && step.is_finite() && step > 0.0 {
            let (_, hi) = p.depth_range(&class, 1);
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
        let t = hit.t as f64 - disp / (-dot(nrm, dir)).max(1e-3);
        let at: [f64; 3] = std::array::from_fn(|k| view.pose.position[k] + dir[k] * t);
        kept[ri] = true;
        out.regions.push(RegionVote {
            view: vi as u32,
            chart: ci,
            uv: chart.uv_of(at),
            class,
            sign,
            step_m: step,
            pixels: pixels.len() as u32,
        });
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

/// How far (as a share of the range its pixels' depth gives) a region's centre ray may run past
/// that range before the region counts as standing past the twin's silhouette, and how far from
/// it the wall end it stands by may lie: the calibrated depth of a thin feature errs by 5-10 %.
const SILHOUETTE_DEPTH_SLACK: f64 = 0.25;

/// Where a region that may stand past the twin's silhouette stands (see [`silhouette_edge`]):
/// `seen` its pixels, its first and last pixel columns and centre row, and its centre ray;
/// `hit` how far that ray meets the twin; `point` a pixel's calibrated point; `reach` its
/// class's deepest protrusion. None where its pixels' depth gives no range, or where the ray
/// meets the twin about where that depth puts the region.
fn past_silhouette(
    view: &View,
    (pixels, (x0, x1, cy), dir): (&[u32], (u32, u32, f64), [f64; 3]),
    hit: Option<f64>,
    point: impl Fn(usize) -> Option<[f64; 3]>,
    charts: &ChartSet,
    reach: f64,
) -> Option<(u32, [f64; 3])> {
    let eye = view.pose.position;
    let mut range: Vec<f64> = pixels
        .iter()
        .filter_map(|&q| point(q as usize))
        .map(|x| (0..3).map(|k| (x[k] - eye[k]).powi(2)).sum::<f64>().sqrt())
        .collect();
    if range.len() < 5 {
        return None;
    }
    let range = median(&mut range);
    let slack = (SILHOUETTE_DEPTH_SLACK * range).max(1.0);
    if hit.is_some_and(|t| t <= range + slack) {
        return None;
    }
    let (l, _) = view.pixel_ray(x0 as f64, cy);
    let (r, _) = view.pixel_ray(x1 as f64 + 1.0, cy);
    let cos = dot(l, r) / (dot(l, l) * dot(r, r)).sqrt();
    let half_width = 0.5 * cos.clamp(-1.0, 1.0).acos() * range;
    silhouette_edge(
        charts,
        eye,
        dir,
        reach + half_width,
        (range - slack, range + slack),
    )
}

/// The wall end a ray from `eye` along unit `dir` passes within `reach` of, on the wall's outer
/// side, at a distance along the ray within `range`, for a wall whose face `eye` lies behind
/// (a view sees a feature past a corner only on the wall round it): the chart and the nearest
/// point of that end. The closest such end if several.
fn silhouette_edge(
    charts: &ChartSet,
    eye: [f64; 3],
    dir: [f64; 3],
    reach: f64,
    range: (f64, f64),
) -> Option<(u32, [f64; 3])> {
    let mut best: Option<(f64, u32, [f64; 3])> = None;
    for (ci, c) in charts.charts.iter().enumerate() {
        if c.kind != ChartKind::Wall || c.width == 0 || c.height == 0 {
            continue;
        }
        let n = c.normal;
        let rel = |x: [f64; 3]| std::array::from_fn::<f64, 3, _>(|k| x[k] - c.origin[k]);
        if dot(rel(eye), n) >= 0.0 {
            continue;
        }
        let up: [f64; 3] = c.v_axis.map(|x| x * c.height as f64 * c.texel_m);
        for end in [0.0, c.width as f64 * c.texel_m] {
            let a: [f64; 3] = std::array::from_fn(|k| c.origin[k] + c.u_axis[k] * end);
            // Closest approach of the ray and the segment a + s up, s in [0, 1].
            let w0: [f64; 3] = std::array::from_fn(|k| eye[k] - a[k]);
            let (b, cc, d, e) = (dot(dir, up), dot(up, up), dot(dir, w0), dot(up, w0));
            let denom = cc - b * b;
            if denom <= 1e-9 * cc {
                continue;
            }
            let s = ((e - b * d) / denom).clamp(0.0, 1.0);
            let t = s * b - d;
            if t < range.0 || t > range.1 {
                continue;
            }
            let on_ray: [f64; 3] = std::array::from_fn(|k| eye[k] + dir[k] * t);
            let on_end: [f64; 3] = std::array::from_fn(|k| a[k] + up[k] * s);
            let gap = (0..3)
                .map(|k| (on_ray[k] - on_end[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            if gap > reach || dot(rel(on_ray), n) < 0.0 {
                continue;
            }
            if best.is_none_or(|(g, _, _)| gap < g) {
                best = Some((gap, ci as u32, on_end));
            }
        }
    }
    best.map(|(_, ci, at)| (ci, at))
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

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Delta_q on every wall texel: the signed distance from our façade to the source mesh along
/// the outward normal (positive: the mesh stands in front), found by casting from `search_m` in
/// front of the texel back through it to the first mesh face that faces the same way (within
/// 45 degrees: the ground and the sides of openings are passed through); NaN where there is none
/// within `search_m` either way.
pub fn mesh_delta(charts: &ChartSet, mesh: &Scene, search_m: f64) -> Vec<Vec<f32>> {
    let rays = SceneRays::new(mesh);
    charts
        .charts
        .par_iter()
        .map(|c| {
            if c.kind != ChartKind::Wall {
                return Vec::new();
            }
            let mut out = vec![f32::NAN; c.len()];
            let dir = c.normal.map(|v| -v as f32);
            for j in 0..c.height {
                for i in 0..c.width {
                    let k = (j * c.width + i) as usize;
                    if c.triangle_at[k] == u32::MAX {
                        continue;
                    }
                    let x = c.texel_center(i, j);
                    let o: [f32; 3] =
                        std::array::from_fn(|a| (x[a] + c.normal[a] * search_m) as f32);
                    // The first surface facing the way the wall does (not the ground, not a
                    // side face): up to four tries past what is not.
                    let mut tmin = 0.0f32;
                    for _ in 0..4 {
                        let Some(hit) = rays.cast(o, dir, tmin, (2.0 * search_m) as f32) else {
                            break;
                        };
                        let facing: f64 = (0..3).map(|a| hit.normal[a] as f64 * c.normal[a]).sum();
                        if facing >= 0.7 {
                            out[k] = (search_m - hit.t as f64) as f32;
                            break;
                        }
                        tmin = hit.t + 1e-3;
                    }
                }
            }
            out
        })
        .collect()
}

/// Façade relief over a chart set: per-view region votes, the fusion of eq. (2)-(3) at
/// gamma_fac, evidence levels, Delta from `mesh` (if any), the posterior of eq. (4), and the
/// instances. Deterministic at any thread count.
pub fn relief(
    scene: &Scene,
    charts: &ChartSet,
    views: &[View],
    mesh: Option<&Scene>,
    p: &ReliefParams,
    progress: &dyn Progress,
) -> ReliefSet {
    let rays = SceneRays::new(scene);
    let lookup = Lookup::new(scene, charts);
    let deltas = mesh.map(|m| mesh_delta(charts, m, p.delta.search_m));
    let ctx = PassCtx {
        scene,
        rays: &rays,
        lookup: &lookup,
        charts,
        deltas: deltas.as_deref(),
        p,
        progress,
    };
    relief_pass(&ctx, views)
}

/// What a pass reads besides the views.
struct PassCtx<'a> {
    scene: &'a Scene,
    rays: &'a SceneRays,
    lookup: &'a Lookup,
    charts: &'a ChartSet,
    deltas: Option<&'a [Vec<f32>]>,
    p: &'a ReliefParams,
    progress: &'a dyn Progress,
}

/// Region votes per view, the fusion, evidence, posterior and instances.
fn relief_pass(ctx: &PassCtx, views: &[View]) -> ReliefSet {
    let (scene, rays, lookup, charts, p, progress) = (
        ctx.scene,
        ctx.rays,
        ctx.lookup,
        ctx.charts,
        ctx.p,
        ctx.progress,
    );
    let per_view: Vec<ViewRelief> = views
        .par_iter()
        .enumerate()
        .map(|(vi, v)| view_relief(vi, v, rays, charts, lookup, p))
        .collect();
    let mut stats = ReliefStats {
        views: views.len() as u64,
        ..Default::default()
    };
    for v in &per_view {
        stats.calibrated += v.calibrated as u64;
        stats.regions += v.candidates;
        stats.enclosed += v.regions.len() as u64;
        stats.recessed += v.regions.iter().filter(|r| r.sign < 0).count() as u64;
        stats.protruding += v.regions.iter().filter(|r| r.sign > 0).count() as u64;
    }
    let vote = |k: usize, px: usize| -> Vote {
        match per_view.get(k).and_then(|r| r.codes.get(px)) {
            Some(&RECESSED) => Vote::Class(0),
            // No layer of neutral votes is read: a neutral pixel is exposure (R and P are
            // shares of it), which is what Seen deposits, without a grid of its own.
            Some(&NEUTRAL) => Vote::Seen,
            Some(&PROTRUDING) => Vote::Class(2),
            Some(&MASKED) => Vote::Masked,
            _ => Vote::Seen,
        }
    };
    let displace = |k: usize, px: usize| -> f64 {
        per_view
            .get(k)
            .and_then(|r| r.displace.get(px))
            .map_or(0.0, |&d| d as f64)
    };
    let fp = FusionParams {
        gamma: p.gamma,
        theta_max_deg: p.theta_max_deg,
        sigma_texels: p.sigma_texels,
        stride: p.stride,
    };
    // The exposure unit: one head-on view from ref_distance_m at the views' median focal
    // length, one ray per pixel: J_ref^gamma x (pixels per texel = J_ref texel²).
    let mut focals: Vec<f64> = views.iter().map(|v| v.intrinsics.fx).collect();
    let f = if focals.is_empty() {
        1.0
    } else {
        median(&mut focals)
    };
    let j_ref = (f / p.ref_distance_m).powi(2);
    let deltas = ctx.deltas;
    let with_mesh = deltas.is_some();
    let cpt = p.cpt.expand();
    // Most texels of a seen chart are unseen and out of the mesh's reach: one posterior for all.
    let unseen = relief_posterior(&cpt, None, mesh_state_probabilities(f64::NAN, &p.delta));
    let mut regions_by_chart: BTreeMap<u32, Vec<&RegionVote>> = BTreeMap::new();
    for v in &per_view {
        for r in &v.regions {
            regions_by_chart.entry(r.chart).or_default().push(r);
        }
    }
    // Each chart's relief is made as soon as its fused layers are blurred, so no chart's dense
    // layers outlive its own turn (all charts' at once were 1.5 GB on the 1 km² site).
    let (results, _): (Vec<(ReliefLayers, Vec<ReliefInstance>, u64)>, _) = fuse_views_each(
        scene,
        rays,
        charts,
        views,
        &vote,
        &displace,
        &fp,
        progress,
        |ci, c, l| {
            let w_ref = j_ref.powf(p.gamma) * j_ref * c.texel_m * c.texel_m;
            let delta = deltas.map(|d| &d[ci]).filter(|d| !d.is_empty());
            let l = l.filter(|l| l.w_exp.iter().any(|&w| w > 0.0));
            if c.kind != ChartKind::Wall || (l.is_none() && delta.is_none()) {
                return (unobserved_layers(c, with_mesh), Vec::new(), 0);
            }
            // Unseen but reached by the mesh: Delta alone.
            let l = l.unwrap_or_else(|| ChartLayers {
                width: c.width,
                height: c.height,
                w_exp: PodVec(vec![0.0; c.len()]),
                hits: PodVec::default(),
                votes: Vec::new(),
            });
            let votes = |k: u16| l.votes.iter().find(|(c, _)| *c == k).map(|(_, v)| v);
            let (em, ep) = (votes(0), votes(2));
            let n = c.len();
            let mut lay = DenseLayers::unobserved(n, delta.is_some());
            let mut observed = 0u64;
            for k in 0..n {
                if c.triangle_at[k] == u32::MAX {
                    continue;
                }
                let wexp = l.w_exp[k] as f64;
                let e = wexp / w_ref;
                lay.exposure[k] = e as f32;
                let levels = if e >= p.exposure_min && wexp > 0.0 {
                    observed += 1;
                    let r = em.map_or(0.0, |v| v[k] as f64) / wexp;
                    let pp = ep.map_or(0.0, |v| v[k] as f64) / wexp;
                    lay.recessed[k] = r as f32;
                    lay.protruding[k] = pp as f32;
                    Some((level(r, p.levels), level(pp, p.levels)))
                } else {
                    None
                };
                let dq = delta.map_or(f64::NAN, |d| d[k] as f64);
                if let Some(slot) = lay.delta.get_mut(k) {
                    *slot = dq as f32;
                }
                let posterior = if levels.is_none() && dq.is_nan() {
                    unseen
                } else {
                    relief_posterior(&cpt, levels, mesh_state_probabilities(dq, &p.delta))
                };
                if let Some(y) = posterior {
                    lay.pr_recessed[k] = y[0] as f32;
                    lay.pr_protruding[k] = y[2] as f32;
                }
            }
            drop(l);
            let regions = regions_by_chart
                .get(&(ci as u32))
                .map(Vec::as_slice)
                .unwrap_or(&[]);
            let ground = |u: f64| ground_row(c, rays, lookup, u);
            let inst = instances(ci as u32, c, &lay, regions, with_mesh, j_ref, &ground, p);
            (lay.pack(c), inst, observed)
        },
    );
    let mut set = ReliefSet {
        with_mesh,
        ..Default::default()
    };
    for (lay, inst, obs) in results {
        set.layers.push(lay);
        set.instances.extend(inst);
        stats.observed_texels += obs;
    }
    set.stats = stats;
    set
}

/// The stored layers of a chart no view saw and no mesh reached (or not a wall).
fn unobserved_layers(c: &crate::artifact::Chart, with_mesh: bool) -> ReliefLayers {
    let n = c.len() as u32;
    let nan = SparseLayer::filled(f32::NAN, n);
    ReliefLayers {
        width: c.width,
        height: c.height,
        exposure: SparseLayer::filled(0.0, n),
        recessed: nan.clone(),
        protruding: nan.clone(),
        delta: if with_mesh {
            nan.clone()
        } else {
            SparseLayer::filled(f32::NAN, 0)
        },
        pr_recessed: nan.clone(),
        pr_protruding: nan,
    }
}

/// One chart's relief layers while they are made: dense, in raster order, with the meaning of
/// [`ReliefLayers`]' fields.
#[cfg_attr(test, derive(Clone))]
struct DenseLayers {
    exposure: Vec<f32>,
    recessed: Vec<f32>,
    protruding: Vec<f32>,
    /// Empty without a source mesh.
    delta: Vec<f32>,
    pr_recessed: Vec<f32>,
    pr_protruding: Vec<f32>,
}

impl DenseLayers {
    /// `n` texels no view saw: no exposure, no evidence, no posterior.
    fn unobserved(n: usize, with_mesh: bool) -> DenseLayers {
        DenseLayers {
            exposure: vec![0.0; n],
            recessed: vec![f32::NAN; n],
            protruding: vec![f32::NAN; n],
            // Without a source mesh the layer would be NaN throughout.
            delta: if with_mesh {
                vec![f32::NAN; n]
            } else {
                Vec::new()
            },
            pr_recessed: vec![f32::NAN; n],
            pr_protruding: vec![f32::NAN; n],
        }
    }

    /// The layers as stored: the texels that carry a value.
    fn pack(&self, c: &crate::artifact::Chart) -> ReliefLayers {
        let nan = |v: &[f32]| SparseLayer::from_dense(v, f32::NAN);
        ReliefLayers {
            width: c.width,
            height: c.height,
            exposure: SparseLayer::from_dense(&self.exposure, 0.0),
            recessed: nan(&self.recessed),
            protruding: nan(&self.protruding),
            delta: nan(&self.delta),
            pr_recessed: nan(&self.pr_recessed),
            pr_protruding: nan(&self.pr_protruding),
        }
    }
}

/// Threshold, opening, closing and connected components of one chart's posteriors (pieces
/// joined across unobserved stretches), each component a rectangle (where its evidence falls to
/// half its peak) with a class, a depth and its evidence.
#[allow(clippy::too_many_arguments)]
fn instances(
    ci: u32,
    c: &crate::artifact::Chart,
    lay: &DenseLayers,
    regions: &[&RegionVote],
    with_mesh: bool,
    j_ref: f64,
    ground: &dyn Fn(f64) -> Option<f64>,
    p: &ReliefParams,
) -> Vec<ReliefInstance> {
    let (w, h) = (c.width, c.height);
    let n = c.len();
    let mut out = Vec::new();
    for sign in [-1i8, 1] {
        let (mine, other) = if sign < 0 {
            (&lay.pr_recessed, &lay.pr_protruding)
        } else {
            (&lay.pr_protruding, &lay.pr_recessed)
        };
        // Over `threshold`, ahead of the other relief class and of flat; or (grown) over
        // `threshold` and ahead of the other relief class.
        let over = |k: usize, threshold: f64, grown: bool| {
            let (a, b) = (mine[k] as f64, other[k] as f64);
            a.is_finite() && a >= threshold && a >= b && (grown || a >= 1.0 - a - b)
        };
        let mut mask: Vec<bool> = (0..n).map(|k| over(k, p.threshold, false)).collect();
        // Nothing over the threshold, nothing the morphology could make an instance of.
        if !mask.contains(&true) {
            continue;
        }
        let open = if sign < 0 {
            p.open_texels.0
        } else {
            p.open_texels.1
        } as i64;
        let close = p.close_texels as i64;
        mask = on_support(&mask, w, h, open.max(close) as u32, |m, w, h| {
            let opened = if open > 0 {
                dilate(&erode(m, w, h, open), w, h, open)
            } else {
                m.to_vec()
            };
            if close > 0 {
                close_within(&opened, w, h, close)
            } else {
                opened
            }
        });
        if close > 0 {
            // Closing never reaches off the surface.
            for (k, m) in mask.iter_mut().enumerate() {
                *m &= c.triangle_at[k] != u32::MAX;
            }
        }
        // Hysteresis: texels over the threshold (the core) are grouped through texels over the
        // lower `grow_threshold`, so a thin feature whose evidence straddles two texel columns
        // (a 0.12 m drainpipe on 0.1 m texels reads about half in each) stays one instance
        // rather than breaking wherever both halves dip under the threshold. The rectangle and
        // the evidence come from the core alone.
        let grown: Vec<bool> = (0..n)
            .map(|k| mask[k] || (c.triangle_at[k] != u32::MAX && over(k, p.grow_threshold, true)))
            .collect();
        let labels = label_components(&grown, w, h, 1);
        let mut comps: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
        for (k, &l) in labels.iter().enumerate() {
            if l != 0 && mask[k] {
                comps.entry(l).or_default().push(k);
            }
        }
        let passable = |k: usize| {
            c.triangle_at[k] != u32::MAX
                && (!(lay.exposure[k] as f64 >= p.exposure_min) || grown[k])
        };
        let comps = bridge_gaps(comps.into_values().collect(), w, p.bridge_texels, &passable);
        let evidence = if sign < 0 {
            &lay.recessed
        } else {
            &lay.protruding
        };
        // The evidence's blur: the kernel and the bilinear deposit (a triangle of variance 1/6).
        let spread = (p.sigma_texels * p.sigma_texels + 1.0 / 6.0).sqrt();
        // The regions that voted inside a rectangle (with the deposit's slack).
        let inside = |rect: [f64; 4]| -> Vec<&RegionVote> {
            let slack = 2.0;
            regions
                .iter()
                .copied()
                .filter(|r| {
                    r.sign == sign
                        && r.uv.0 >= rect[0] - slack
                        && r.uv.0 <= rect[2] + slack
                        && r.uv.1 >= rect[1] - slack
                        && r.uv.1 <= rect[3] + slack
                })
                .collect()
        };
        // Class by pixel-weighted majority of the regions inside (named classes first).
        let class_of = |inside: &[&RegionVote]| -> String {
            let mut by_class: BTreeMap<&str, u64> = BTreeMap::new();
            for r in inside {
                *by_class.entry(r.class.as_str()).or_default() += r.pixels as u64;
            }
            by_class
                .iter()
                .filter(|(c, _)| **c != "unknown")
                .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
                .map_or("unknown", |(c, _)| c)
                .to_owned()
        };
        // A piece of a class that runs the wall's height (a downpipe, from its gutter to the
        // ground) reaches up and down to where a storey of observed flat wall, the surface's
        // end or the terrain stops it, and pieces that then overlap are one feature. Flat wall
        // counts only where the views saw it well enough to have resolved the feature: an
        // exposure over what one view resolving the class's widest (`width_m`) across gives,
        // (1 / (w² J_ref))^(gamma + 1) in exposure units (a far view sees a 0.12 m pipe under a
        // pixel wide and reads the wall flat).
        let stop_exposure = |class: &str| -> Option<f64> {
            let r = p
                .classes
                .iter()
                .find(|r| r.name == class && r.runs_full_height)?;
            let resolve = r
                .width_m
                .map_or(0.0, |(_, hi)| (1.0 / (hi * hi * j_ref)).powf(p.gamma + 1.0));
            Some(resolve.max(p.exposure_min))
        };
        let pieces: Vec<(Vec<usize>, [f64; 4])> = comps
            .into_iter()
            .filter(|t| t.len() >= p.min_texels as usize)
            .map(|t| {
                let rect = extent(&t, evidence, w, h, spread);
                (t, rect)
            })
            .collect();
        let up: Vec<Option<f64>> = pieces
            .iter()
            .map(|(_, rect)| stop_exposure(&class_of(&inside(*rect))))
            .collect();
        let stop_rows = ((p.run_stop_m / c.texel_m).ceil() as usize).max(1);
        let reach = |rect: [f64; 4], stop: f64| {
            let floor = ground(0.5 * (rect[0] + rect[2])).unwrap_or(0.0);
            run_full_height(rect, w, h, floor, stop_rows, |k| {
                if c.triangle_at[k] == u32::MAX {
                    Row::Off
                } else if !(lay.exposure[k] as f64 >= stop) || grown[k] {
                    Row::Passable
                } else {
                    Row::Flat
                }
            })
        };
        let reached: Vec<[f64; 4]> = pieces
            .iter()
            .zip(&up)
            .map(|((_, rect), u)| u.map_or(*rect, |stop| reach(*rect, stop)))
            .collect();
        let mut sets = UnionFind::new(pieces.len());
        for x in 0..pieces.len() {
            for y in x + 1..pieces.len() {
                if up[x].is_some() && up[y].is_some() && one_column(&reached[x], &reached[y]) {
                    sets.join(x as u32, y as u32);
                }
            }
        }
        let mut groups: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
        for (x, name) in sets.names().into_iter().enumerate() {
            groups.entry(name).or_default().push(x);
        }
        for members in groups.into_values() {
            let (texels, rect) = if let [one] = members[..] {
                (pieces[one].0.clone(), reached[one])
            } else {
                let mut t: Vec<usize> = members
                    .iter()
                    .flat_map(|&x| pieces[x].0.iter().copied())
                    .collect();
                t.sort_unstable();
                // Pieces join only when both run up, so the group's first has a stop.
                let stop = up[members[0]].unwrap_or(p.exposure_min);
                let rect = reach(extent(&t, evidence, w, h, spread), stop);
                (t, rect)
            };
            let m = texels.len() as f64;
            let mean = |l: &[f32]| {
                texels
                    .iter()
                    .map(|&k| l[k] as f64)
                    .filter(|v| v.is_finite())
                    .sum::<f64>()
                    / m
            };
            let posterior = mean(mine);
            // Closing can join a few texels over the threshold with more under it: what comes
            // out must still clear the threshold on average, or it is noise the morphology grew.
            if posterior < p.threshold {
                continue;
            }
            let exposure = mean(&lay.exposure);
            let delta_agreement = with_mesh.then(|| {
                let d = if sign < 0 { 0 } else { 2 };
                // Pr(d | Delta) again from the stored Delta (f32 both times: the same values the
                // posterior used), rather than kept for every texel of every chart.
                texels
                    .iter()
                    .filter(|&&k| {
                        let dq = lay.delta.get(k).map_or(f64::NAN, |&x| x as f64);
                        mesh_state_probabilities(dq, &p.delta)[d] > 0.5
                    })
                    .count() as f64
                    / m
            });
            // The regions that voted for it: class by majority, depth by pixel-weighted median
            // of the measured steps.
            let inside = inside(rect);
            let class = class_of(&inside);
            let mut steps: Vec<(f64, f64)> = inside
                .iter()
                .filter(|r| r.step_m.is_finite() && r.step_m * sign as f64 > 0.0)
                .map(|r| (r.step_m.abs(), r.pixels as f64))
                .collect();
            let measured = weighted_median(&mut steps);
            // A protrusion is deposited on the plane its measured step gives; with none, the
            // class alone put it on this wall.
            if sign > 0 && !measured.is_some_and(|d| d >= p.min_step_m) {
                continue;
            }
            let (lo, hi) = p.depth_range(&class, sign);
            let depth_m = measured.unwrap_or((lo + hi) / 2.0).clamp(lo, hi);
            let rect = match p.classes.iter().find(|r| r.name == class) {
                Some(ClassRule {
                    width_m: Some(range),
                    ..
                }) => within_width(rect, *range, c.texel_m, w, evidence),
                _ => rect,
            };
            let views: BTreeSet<u32> = inside.iter().map(|r| r.view).collect();
            let corners = [
                c.world_of(rect[0], rect[1]),
                c.world_of(rect[2], rect[1]),
                c.world_of(rect[2], rect[3]),
                c.world_of(rect[0], rect[3]),
            ];
            out.push(ReliefInstance {
                chart: ci,
                building: c.building.clone(),
                sign,
                class,
                rect,
                corners,
                depth_m,
                measured_depth_m: measured,
                posterior,
                exposure,
                texels: texels.len() as u32,
                views: views.len() as u32,
                delta_agreement,
            });
        }
    }
    out
}

/// `rect` narrowed or widened along `u` to a width within `range` (metres; the chart's texels
/// are `texel_m`) about the centroid of the mean `evidence` of its columns and
/// [`CENTROID_REACH`] more each side (a side the chart's end bounds leaves the rectangle's
/// middle off the feature's), kept on the chart's `w` texels.
fn within_width(
    rect: [f64; 4],
    range: (f64, f64),
    texel_m: f64,
    w: u32,
    evidence: &[f32],
) -> [f64; 4] {
    let width = (rect[2] - rect[0]).clamp(range.0 / texel_m, range.1 / texel_m);
    let rows = rect[1].floor() as usize..(rect[3].ceil() as usize).min(evidence.len() / w as usize);
    // The rectangle's own columns cut the blurred evidence's tails unevenly (a 1.2-texel pipe
    // read as [0.7, 1.7] has its centroid pulled 0.4 texel toward the cut side): the centroid
    // is taken over CENTROID_REACH more columns each side, above the window's lowest column
    // mean (the wall's own level, which would pull it toward the window's middle).
    let lo = (rect[0] - CENTROID_REACH).floor().max(0.0) as usize;
    let hi = ((rect[2] + CENTROID_REACH).ceil() as usize).min(w as usize);
    let means: Vec<(usize, f64)> = (lo..hi)
        .map(|i| {
            let m = mean_finite(evidence, &mut rows.clone().map(|j| j * w as usize + i));
            (i, m)
        })
        .filter(|m| m.1.is_finite())
        .collect();
    let floor = means.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
    let (mut sum, mut weight) = (0.0, 0.0);
    for (i, mean) in means {
        sum += (mean - floor) * (i as f64 + 0.5);
        weight += mean - floor;
    }
    let centre = if weight > 0.0 {
        sum / weight
    } else {
        0.5 * (rect[0] + rect[2])
    };
    let u0 = (centre - width / 2.0).clamp(0.0, (w as f64 - width).max(0.0));
    [u0, rect[1], (u0 + width).min(w as f64), rect[3]]
}

/// Columns beyond a thin feature's rectangle its evidence's centroid is taken over: three
/// times the spread of the fusion's blur (sigma 0.5 texel and the bilinear deposit, 0.65).
const CENTROID_REACH: f64 = 2.0;

/// What a row of a running feature's columns holds: a texel it may pass (unobserved, or with
/// some of its evidence), only observed flat wall, or only texels off the surface.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Row {
    Passable,
    Flat,
    Off,
}

/// `rect` run up to the surface's top and down to row `floor` (the terrain) through its columns:
/// through every row where one of its columns' texels `passes`, and through fewer than `stop`
/// rows in a row of observed flat wall; a row off the surface ends the run. A side stays at the
/// last passable row it reached.
fn run_full_height(
    rect: [f64; 4],
    w: u32,
    h: u32,
    floor: f64,
    stop: usize,
    passes: impl Fn(usize) -> Row,
) -> [f64; 4] {
    let (wu, hu) = (w as usize, h as usize);
    let i0 = (rect[0].floor().max(0.0) as usize).min(wu - 1);
    let i1 = (rect[2].ceil() as usize).clamp(i0 + 1, wu);
    let row = |j: usize| {
        let mut row = Row::Off;
        for i in i0..i1 {
            match passes(j * wu + i) {
                Row::Passable => return Row::Passable,
                Row::Flat => row = Row::Flat,
                Row::Off => {}
            }
        }
        row
    };
    // The last passable row reached along `rows`, or None.
    let run = |rows: &mut dyn Iterator<Item = usize>| {
        let (mut last, mut flat) = (None, 0);
        for j in rows {
            match row(j) {
                Row::Off => break,
                Row::Flat => {
                    flat += 1;
                    if flat >= stop {
                        break;
                    }
                }
                Row::Passable => {
                    flat = 0;
                    last = Some(j);
                }
            }
        }
        last
    };
    let top = run(&mut ((rect[3].ceil() as usize).min(hu)..hu)).map_or(rect[3], |j| (j + 1) as f64);
    let first_below = (rect[1].floor().max(0.0) as usize).min(hu);
    let bottom = run(&mut (0..first_below)
        .rev()
        .take_while(|&j| (j + 1) as f64 > floor))
    .map_or(rect[1], |j| (j as f64).max(floor).min(rect[1]));
    [rect[0], bottom, rect[2], top]
}

/// The chart row where the terrain meets a wall chart at column `u`: a ray cast straight down
/// from the chart's top, just outside the wall, that meets the terrain first. None where it
/// meets something else (a neighbour's roof) or nothing.
fn ground_row(
    c: &crate::artifact::Chart,
    rays: &SceneRays,
    lookup: &Lookup,
    u: f64,
) -> Option<f64> {
    const OUTSIDE_M: f64 = 0.3;
    let top = c.world_of(u, c.height as f64);
    let from: [f64; 3] = std::array::from_fn(|k| top[k] + c.normal[k] * OUTSIDE_M);
    let hit = rays.cast(from.map(|x| x as f32), [0.0, 0.0, -1.0], 1e-3, 1e5)?;
    lookup.terrain.get(hit.object).copied().filter(|&t| t)?;
    Some(c.uv_of([top[0], top[1], from[2] - hit.t as f64]).1)
}

/// Whether two rectangles are pieces of one upright feature: they overlap along `u` over half
/// the narrower one's width, and their `v` spans meet.
fn one_column(a: &[f64; 4], b: &[f64; 4]) -> bool {
    let overlap = a[2].min(b[2]) - a[0].max(b[0]);
    let narrower = (a[2] - a[0]).min(b[2] - b[0]);
    overlap > 0.0 && 2.0 * overlap >= narrower && a[1] <= b[3] && b[1] <= a[3]
}

/// Texel box of a set of texels: (i0, j0, i1, j1), inclusive.
fn texel_box(texels: &[usize], w: u32) -> [usize; 4] {
    let w = w as usize;
    texels.iter().fold([usize::MAX, usize::MAX, 0, 0], |b, &k| {
        let (i, j) = (k % w, k / w);
        [b[0].min(i), b[1].min(j), b[2].max(i), b[3].max(j)]
    })
}

/// Joins components that face each other across a stretch at most `gap` texels wide where every
/// line across has a `passable` texel (unobserved, or with some evidence) within their overlap:
/// one feature seen in pieces (a drainpipe whose storeys a balcony slab hides from the views)
/// rather than several. They must overlap across the gap over half the narrower one's span, and
/// a line of observed flat wall stops the join, so a row of windows stays a row of windows.
fn bridge_gaps(
    comps: Vec<Vec<usize>>,
    w: u32,
    gap: u32,
    passable: impl Fn(usize) -> bool,
) -> Vec<Vec<usize>> {
    if gap == 0 || comps.len() < 2 {
        return comps;
    }
    let boxes: Vec<[usize; 4]> = comps.iter().map(|t| texel_box(t, w)).collect();
    let wu = w as usize;
    // Along axis `a` (0: u, 1: v) box `y` follows box `x` across a passable gap.
    let faces = |x: &[usize; 4], y: &[usize; 4], a: usize| -> bool {
        let b = 1 - a;
        if y[a] <= x[a + 2] || y[a] - x[a + 2] - 1 > gap as usize {
            return false;
        }
        let (lo, hi) = (x[b].max(y[b]), x[b + 2].min(y[b + 2]));
        let narrower = (x[b + 2] - x[b]).min(y[b + 2] - y[b]) + 1;
        if hi < lo || 2 * (hi - lo + 1) < narrower {
            return false;
        }
        (x[a + 2] + 1..y[a]).all(|s| {
            (lo..=hi).any(|t| {
                let (i, j) = if a == 0 { (s, t) } else { (t, s) };
                passable(j * wu + i)
            })
        })
    };
    let mut sets = UnionFind::new(comps.len());
    for x in 0..boxes.len() {
        for y in 0..boxes.len() {
            if x != y && (faces(&boxes[x], &boxes[y], 0) || faces(&boxes[x], &boxes[y], 1)) {
                sets.join(x as u32, y as u32);
            }
        }
    }
    let mut joined: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (x, name) in sets.names().into_iter().enumerate() {
        joined.entry(name).or_default().extend_from_slice(&comps[x]);
    }
    joined
        .into_values()
        .map(|mut t| {
            t.sort_unstable();
            t
        })
        .collect()
}

/// How far the evidence reaches past an instance's texels: the fusion kernel's and the bilinear
/// deposit's spread.
const EXTENT_REACH: usize = 3;

/// An instance's rectangle (u0, v0, u1, v1) in texels: along each axis, where its evidence
/// profile (the layer's mean across the instance's span, per texel column or row) falls to half
/// its peak, interpolated between texel centres. A feature narrower than two texels (a drainpipe)
/// gets its width and place from how its evidence splits between the columns, not from the
/// whole texels that cleared the threshold.
fn extent(texels: &[usize], evidence: &[f32], w: u32, h: u32, spread: f64) -> [f64; 4] {
    let b = texel_box(texels, w);
    let (wu, hu) = (w as usize, h as usize);
    let span = |lo: usize, hi: usize, len: usize| {
        (
            lo.saturating_sub(EXTENT_REACH),
            (hi + EXTENT_REACH).min(len - 1),
        )
    };
    let (ua, ub) = span(b[0], b[2], wu);
    let (va, vb) = span(b[1], b[3], hu);
    let cols: Vec<f64> = (ua..=ub)
        .map(|i| mean_finite(evidence, &mut (b[1]..=b[3]).map(|j| j * wu + i)))
        .collect();
    let rows: Vec<f64> = (va..=vb)
        .map(|j| mean_finite(evidence, &mut (b[0]..=b[2]).map(|i| j * wu + i)))
        .collect();
    let (u0, u1) = deblurred(half_peak_edges(&cols, b[0] - ua, b[2] - ua), spread);
    let (v0, v1) = deblurred(half_peak_edges(&rows, b[1] - va, b[3] - va), spread);
    [
        (ua as f64 + u0).max(0.0),
        (va as f64 + v0).max(0.0),
        (ua as f64 + u1).min(w as f64),
        (va as f64 + v1).min(h as f64),
    ]
}

/// Mean of the finite `evidence` at `cells`, NaN where none is.
fn mean_finite(evidence: &[f32], cells: &mut dyn Iterator<Item = usize>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for k in cells {
        let e = evidence[k] as f64;
        if e.is_finite() {
            s += e;
            n += 1;
        }
    }
    if n == 0 { f64::NAN } else { s / n as f64 }
}

/// Narrowest rectangle the extent gives, texels: a feature whose evidence is no wider than the
/// fusion's own spread has a width the evidence cannot tell, and the rectangle must stay one to
/// carve.
const MIN_WIDTH_TEXELS: f64 = 0.5;

/// The half-peak interval narrowed to the box whose blur by a Gaussian of standard deviation
/// `spread` (texels) reads as wide, each side that is a half-peak crossing moved in by its share
/// of the blur; a side bounded by the chart's end or by unobserved texels, where the evidence
/// does not fall toward it, stays. The fusion
/// widens every feature by its kernel and its bilinear deposit: a 0.12 m drainpipe (1.2 texels)
/// reads about 1.75 texels wide at half its peak; a 1.4 m window is unchanged to a hundredth of
/// a texel.
fn deblurred(e: HalfPeak, spread: f64) -> (f64, f64) {
    let measured = e.hi - e.lo;
    let sides = e.lo_blurred as u8 + e.hi_blurred as u8;
    if spread <= 0.0 || measured <= 0.0 || sides == 0 {
        return (e.lo, e.hi);
    }
    // What a box of width `a` reads as with `sides` of its edges blurred.
    let reads = |a: f64| a + sides as f64 * (blurred_width(a, spread) - a) / 2.0;
    let floor = MIN_WIDTH_TEXELS.min(measured);
    let width = if reads(0.0) >= measured {
        floor
    } else {
        // `reads` grows with the width and exceeds it: bisect on [0, measured].
        let (mut lo, mut hi) = (0.0, measured);
        for _ in 0..48 {
            let mid = 0.5 * (lo + hi);
            if reads(mid) < measured {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (0.5 * (lo + hi)).max(floor)
    };
    match (e.lo_blurred, e.hi_blurred) {
        (true, true) => {
            let c = 0.5 * (e.lo + e.hi);
            (c - width / 2.0, c + width / 2.0)
        }
        (false, _) => (e.lo, e.lo + width),
        (true, false) => (e.hi - width, e.hi),
    }
}

/// Half-peak width of a box of width `a` convolved with a Gaussian of standard deviation `s`:
/// 2x where Phi((x + a/2) / s) - Phi((x - a/2) / s) is half its value at 0.
fn blurred_width(a: f64, s: f64) -> f64 {
    if a < 1e-6 * s {
        // The limit, a point: the Gaussian's own full width at half maximum.
        return 2.0 * (2.0 * std::f64::consts::LN_2).sqrt() * s;
    }
    let f = |x: f64| phi((x + a / 2.0) / s) - phi((x - a / 2.0) / s);
    let half = f(0.0) / 2.0;
    let (mut lo, mut hi) = (0.0, a / 2.0 + 6.0 * s);
    for _ in 0..48 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > half {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo + hi
}

/// The standard normal distribution function, by erf (Abramowitz and Stegun 7.1.26, absolute
/// error under 1.5e-7).
fn phi(x: f64) -> f64 {
    let z = x / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * z.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-z * z).exp();
    0.5 * (1.0 + erf.copysign(z))
}

/// Where a profile crosses half its peak on each side, and whether each side is such a crossing
/// (blurred by the fusion) rather than a bound (the profile's end, an unobserved texel).
#[derive(Clone, Copy, Debug)]
struct HalfPeak {
    lo: f64,
    hi: f64,
    lo_blurred: bool,
    hi_blurred: bool,
}

/// Where `profile` (values at texel centres k + 0.5, NaN unobserved) crosses half its peak over
/// the core span [lo, hi], one crossing each side, searched outward from the core's ends (inward
/// where an end is already under half); an unobserved texel or the profile's end bounds the
/// search at a texel edge.
fn half_peak_edges(profile: &[f64], lo: usize, hi: usize) -> HalfPeak {
    let peak = profile[lo..=hi]
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    if peak <= 0.0 {
        return HalfPeak {
            lo: lo as f64,
            hi: hi as f64 + 1.0,
            lo_blurred: false,
            hi_blurred: false,
        };
    }
    let level = peak / 2.0;
    let above = |k: usize| profile[k] >= level;
    // Past an unobserved texel or the profile's end there is no neighbour to cross to, but the
    // profile may still be seen falling toward it (a drainpipe 0.1 m from a corner reads
    // highest one texel in from the chart's end): the line through the last two texels gives
    // the crossing when it falls within the bound; where the profile does not fall, or falls
    // to half its peak only past the bound, the feature runs to the bound.
    let toward_bound = |inner: usize, further_in: Option<usize>, bound: f64| -> (f64, bool) {
        let (a, b) = match further_in {
            Some(j) if profile[j].is_finite() => (profile[inner], profile[j]),
            _ => return (bound, false),
        };
        if b <= a {
            return (bound, false);
        }
        let centre = inner as f64 + 0.5;
        let x = centre + (bound - centre).signum() * (a - level) / (b - a);
        if (x - bound) * (centre - bound) >= 0.0 {
            (x, true)
        } else {
            (bound, false)
        }
    };
    // The crossing between texel `inner` (at or over the level) and its neighbour `outer`.
    let cross = |inner: usize, outer: usize| -> (f64, bool) {
        let (a, b) = (profile[inner], profile[outer]);
        if !b.is_finite() {
            let (bound, further_in) = if outer < inner {
                (inner as f64, Some(inner + 1).filter(|&j| j < profile.len()))
            } else {
                (inner as f64 + 1.0, inner.checked_sub(1))
            };
            return toward_bound(inner, further_in, bound);
        }
        let f = (a - level) / (a - b);
        let (ci, co) = (inner as f64 + 0.5, outer as f64 + 0.5);
        (ci + (co - ci) * f, true)
    };
    // Innermost texel over the level from each end of the core.
    let first = (lo..=hi).find(|&k| above(k)).unwrap_or(lo);
    let last = (lo..=hi).rev().find(|&k| above(k)).unwrap_or(hi);
    let mut l = first;
    while l > 0 && profile[l - 1].is_finite() && above(l - 1) {
        l -= 1;
    }
    let mut r = last;
    while r + 1 < profile.len() && profile[r + 1].is_finite() && above(r + 1) {
        r += 1;
    }
    let (left, lo_blurred) = if l == 0 {
        toward_bound(0, (profile.len() > 1).then_some(1), 0.0)
    } else {
        cross(l, l - 1)
    };
    let (right, hi_blurred) = if r + 1 == profile.len() {
        toward_bound(r, r.checked_sub(1), profile.len() as f64)
    } else {
        cross(r, r + 1)
    };
    HalfPeak {
        lo: left,
        hi: right,
        lo_blurred,
        hi_blurred,
    }
}

fn weighted_median(v: &mut [(f64, f64)]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|x| x.1).sum();
    let mut acc = 0.0;
    for x in v.iter() {
        acc += x.1;
        if acc >= total / 2.0 {
            return Some(x.0);
        }
    }
    v.last().map(|x| x.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_affine_recovers_scale_and_offset_despite_outliers() {
        let xs: Vec<f64> = (0..200).map(|i| 5.0 + i as f64 * 0.1).collect();
        let mut ys: Vec<f64> = xs.iter().map(|x| 0.8 * x + 1.0).collect();
        for k in (0..200).step_by(10) {
            ys[k] -= 3.0; // balconies in front of the wall
        }
        let (a, b) = robust_affine(&xs, &ys).unwrap();
        assert!((a - 0.8).abs() < 1e-9 && (b - 1.0).abs() < 1e-9, "{a} {b}");
        // No spread, no fit.
        assert!(robust_affine(&vec![10.0; 100], &vec![9.0; 100]).is_none());
    }

    #[test]
    fn a_feature_past_a_corner_stands_on_the_wall_seen_from_behind() {
        let charts = ChartSet {
            charts: vec![crate::artifact::Chart::flat_wall(100, 100)],
        };
        let ray = |eye: [f64; 3], to: [f64; 3]| {
            let d: [f64; 3] = std::array::from_fn(|k| to[k] - eye[k]);
            let n = dot(d, d).sqrt();
            (d.map(|c| c / n), n)
        };
        let eye = [12.0, 10.0, 1.5];
        let (dir, dist) = ray(eye, [10.05, -0.08, 5.0]);
        let around = (dist - 2.0, dist + 2.0);
        let (ci, at) = silhouette_edge(&charts, eye, dir, 0.3, around).unwrap();
        let (u, v) = charts.charts[ci as usize].uv_of(at);
        assert_eq!(u, 100.0);
        assert!((v - 50.0).abs() < 2.0, "{v}");
        // Not where its depth puts it farther off, nor beyond the reach of the wall's end.
        assert!(silhouette_edge(&charts, eye, dir, 0.3, (dist + 5.0, dist + 9.0)).is_none());
        assert!(silhouette_edge(&charts, eye, dir, 0.01, around).is_none());
        // A view the wall faces sees a feature there on the wall, not past it.
        let front = [12.0, -10.0, 1.5];
        let (dir, dist) = ray(front, [10.05, -0.08, 5.0]);
        assert!(silhouette_edge(&charts, front, dir, 0.3, (dist - 2.0, dist + 2.0)).is_none());
        // Nor on a ray that crosses the wall's plane inside its end (into the building).
        let (dir, dist) = ray(eye, [10.05, 1.0, 5.0]);
        assert!(silhouette_edge(&charts, eye, dir, 0.3, (dist - 2.0, dist + 2.0)).is_none());
    }

    #[test]
    fn a_thin_protrusion_whose_evidence_dips_stays_one_instance() {
        // A pipe down column 3, one texel from the chart's edge: two rows in every six its
        // evidence dips to "some votes" (0.35), as when it straddles two texel columns.
        let (w, h) = (12u32, 64u32);
        let c = crate::artifact::Chart::flat_wall(w, h);
        let n = c.len();
        let mut pr = vec![0.03f32; n];
        for j in 0..h {
            pr[(j * w + 3) as usize] = if j % 6 >= 4 { 0.35 } else { 0.85 };
        }
        let lay = seen_layers(w, h, pr, vec![0.0; n]);
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        // The views measured it standing out all along.
        let at: Vec<(f64, f64)> = (0..h).map(|j| (3.5, j as f64 + 0.5)).collect();
        let votes = measured_out("unknown", &at);
        let votes: Vec<&RegionVote> = votes.iter().collect();
        let one = instances(0, &c, &lay, &votes, false, 1e12, &|_| None, &p);
        assert_eq!(one.len(), 1, "{one:?}");
        // The extent is the core's: one column wide, never grown over the gap to the edge.
        let r = one[0].rect;
        assert!(
            r[0] > 2.9 && r[2] < 4.1 && r[1] < 0.5 && r[3] > 63.5,
            "{r:?}"
        );
        let without = ReliefParams {
            grow_threshold: p.threshold,
            ..p
        };
        // Without the hysteresis (closing bridges one row, not two): a piece per stretch.
        assert_eq!(
            instances(0, &c, &lay, &votes, false, 1e12, &|_| None, &without).len(),
            11
        );
    }

    /// Layers of a `w` x `h` chart seen everywhere (exposure 10) with protruding posterior and
    /// evidence `pr` and `e`.
    fn seen_layers(w: u32, h: u32, pr: Vec<f32>, e: Vec<f32>) -> DenseLayers {
        let n = (w * h) as usize;
        DenseLayers {
            exposure: vec![10.0; n],
            recessed: vec![0.0; n],
            protruding: e,
            delta: vec![f32::NAN; n],
            pr_recessed: vec![0.03; n],
            pr_protruding: pr,
        }
    }

    /// Protruding posterior and evidence of a pipe down column 3 of a `w`-wide chart of `n`
    /// texels, on `rows`; flat elsewhere.
    fn pipe_in_column_3(w: u32, n: usize, rows: impl Iterator<Item = u32>) -> (Vec<f32>, Vec<f32>) {
        let mut pr = vec![0.03f32; n];
        let mut e = vec![0.0f32; n];
        for j in rows {
            pr[(j * w + 3) as usize] = 0.85;
            e[(j * w + 3) as usize] = 0.9;
        }
        (pr, e)
    }

    /// Makes `rows` of `lay` unobserved (no exposure, no evidence, no posterior).
    fn unobserve(lay: &mut DenseLayers, w: u32, rows: std::ops::Range<u32>) {
        for j in rows {
            for i in 0..w {
                let k = (j * w + i) as usize;
                lay.exposure[k] = 0.0;
                lay.protruding[k] = f32::NAN;
                lay.pr_protruding[k] = f32::NAN;
                lay.pr_recessed[k] = f32::NAN;
            }
        }
    }

    /// Region votes that measured a protrusion standing 0.15 m out, one at each of `at` (texel
    /// coordinates), of class `class`.
    fn measured_out(class: &str, at: &[(f64, f64)]) -> Vec<RegionVote> {
        at.iter()
            .map(|&uv| RegionVote {
                view: 0,
                chart: 0,
                uv,
                class: class.into(),
                sign: 1,
                step_m: 0.15,
                pixels: 50,
            })
            .collect()
    }

    #[test]
    fn a_thin_feature_sits_where_its_evidence_splits_between_columns() {
        // Evidence all in column 3 (a pipe centred on it), then split evenly between columns 3
        // and 4 (a pipe on their common edge): the posterior clears the threshold in column 3
        // alone both times, the rectangle follows the evidence.
        let (w, h) = (10u32, 30u32);
        let c = crate::artifact::Chart::flat_wall(w, h);
        let n = c.len();
        let mut pr = vec![0.03f32; n];
        for j in 0..h {
            pr[(j * w + 3) as usize] = 0.85;
        }
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let centre = |split: bool| {
            let mut e = vec![0.0f32; n];
            for j in 0..h {
                e[(j * w + 2) as usize] = 0.3;
                e[(j * w + 3) as usize] = 0.8;
                e[(j * w + 4) as usize] = if split { 0.8 } else { 0.3 };
                e[(j * w + 5) as usize] = if split { 0.3 } else { 0.0 };
            }
            let votes = measured_out("unknown", &[(3.5, 15.0)]);
            let votes: Vec<&RegionVote> = votes.iter().collect();
            let one = instances(
                0,
                &c,
                &seen_layers(w, h, pr.clone(), e),
                &votes,
                false,
                1e12,
                &|_| None,
                &p,
            );
            assert_eq!(one.len(), 1, "{one:?}");
            let r = one[0].rect;
            assert!(r[1] < 0.5 && r[3] > 29.5, "{r:?}");
            ((r[0] + r[2]) / 2.0, r[2] - r[0])
        };
        let (on_column, width) = centre(false);
        assert!(
            (on_column - 3.5).abs() < 1e-9 && width < 2.0,
            "{on_column} {width}"
        );
        let (on_edge, width) = centre(true);
        assert!(
            (on_edge - 4.0).abs() < 1e-9 && width < 3.0,
            "{on_edge} {width}"
        );
    }

    #[test]
    fn pieces_join_across_an_unobserved_stretch_not_across_observed_wall() {
        // A pipe down column 3, rows 0-19 and 24-43; rows 20-23 between them unobserved (a
        // balcony slab hid them), then observed and flat.
        let (w, h) = (10u32, 44u32);
        let c = crate::artifact::Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), (0..20).chain(24..44));
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let mut hidden = seen_layers(w, h, pr.clone(), e.clone());
        unobserve(&mut hidden, w, 20..24);
        let votes = measured_out("unknown", &[(3.5, 10.0), (3.5, 34.0)]);
        let votes: Vec<&RegionVote> = votes.iter().collect();
        let one = instances(0, &c, &hidden, &votes, false, 1e12, &|_| None, &p);
        assert_eq!(one.len(), 1, "{one:?}");
        assert!(
            one[0].rect[1] < 0.5 && one[0].rect[3] > 43.5,
            "{:?}",
            one[0].rect
        );
        let narrow = ReliefParams {
            bridge_texels: 3,
            ..p.clone()
        };
        assert_eq!(
            instances(0, &c, &hidden, &votes, false, 1e12, &|_| None, &narrow).len(),
            2
        );
        let flat = seen_layers(w, h, pr, e);
        assert_eq!(
            instances(0, &c, &flat, &votes, false, 1e12, &|_| None, &p).len(),
            2
        );
    }

    #[test]
    fn a_protrusion_no_view_measured_standing_out_is_dropped() {
        // The pipe of `pieces_join_...`, seen whole: found when a view measured it 0.15 m out,
        // dropped with no step or a step under `min_step_m` (the class in the image alone).
        let (w, h) = (10u32, 30u32);
        let c = crate::artifact::Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), 0..h);
        let lay = seen_layers(w, h, pr, e);
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let found = |step_m: f64| {
            let mut votes = measured_out("unknown", &[(3.5, 15.0)]);
            votes[0].step_m = step_m;
            let votes: Vec<&RegionVote> = votes.iter().collect();
            instances(0, &c, &lay, &votes, false, 1e12, &|_| None, &p).len()
        };
        assert_eq!(found(0.15), 1);
        assert_eq!(found(0.02), 0);
        assert_eq!(found(f64::NAN), 0);
        assert!(instances(0, &c, &lay, &[], false, 1e12, &|_| None, &p).is_empty());
    }

    #[test]
    fn a_drainpipe_runs_the_walls_height_unless_a_storey_of_flat_wall_stops_it() {
        // A pipe seen in column 3 on rows 0-9 and 30-34 of a 50-row wall (0.1 m texels); the
        // rows between and above are unobserved (`hidden`) or observed flat (`flat_between`).
        let (w, h) = (10u32, 50u32);
        let c = crate::artifact::Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), (0..10).chain(30..35));
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let mut hidden = seen_layers(w, h, pr.clone(), e.clone());
        unobserve(&mut hidden, w, 10..30);
        unobserve(&mut hidden, w, 35..50);
        let run_with = |lay: &DenseLayers, class: &str, p: &ReliefParams, j_ref: f64| {
            let votes = measured_out(class, &[(3.5, 5.0), (3.5, 32.0)]);
            let votes: Vec<&RegionVote> = votes.iter().collect();
            let mut r: Vec<[f64; 4]> = instances(0, &c, lay, &votes, false, j_ref, &|_| None, p)
                .iter()
                .map(|i| i.rect)
                .collect();
            r.sort_by(|a, b| a[1].total_cmp(&b[1]));
            r
        };
        let run = |lay: &DenseLayers, class: &str| run_with(lay, class, &p, 1e12);
        // A drainpipe: the two pieces are one, up to the wall's top.
        let pipe = run(&hidden, "drainpipe");
        assert_eq!(pipe.len(), 1, "{pipe:?}");
        assert!(pipe[0][1] < 0.5 && pipe[0][3] == 50.0, "{pipe:?}");
        // A feature of no such class stays where it was seen: two pieces (20 rows apart, past
        // `bridge_texels`).
        let other = run(&hidden, "unknown");
        assert_eq!(other.len(), 2, "{other:?}");
        assert!(other[0][3] < 10.5 && other[1][3] < 35.5, "{other:?}");
        // 2 m of observed flat wall between the pieces, under the default storey (3 m): one
        // pipe. With `run_stop_m` at 1 m it stops both: the lower piece stays under it, the
        // upper runs up only.
        let mut flat_between = seen_layers(w, h, pr, e);
        unobserve(&mut flat_between, w, 35..50);
        let pipe = run(&flat_between, "drainpipe");
        assert_eq!(pipe.len(), 1, "{pipe:?}");
        assert!(pipe[0][1] < 0.5 && pipe[0][3] == 50.0, "{pipe:?}");
        let metre = ReliefParams {
            run_stop_m: 1.0,
            ..p.clone()
        };
        let pipe = run_with(&flat_between, "drainpipe", &metre, 1e12);
        assert_eq!(pipe.len(), 2, "{pipe:?}");
        assert!(pipe[0][3] < 10.5, "{pipe:?}");
        assert!(pipe[1][1] > 29.5 && pipe[1][3] == 50.0, "{pipe:?}");
        // Flat only to views too far to have resolved a pipe: it runs through, even a metre of
        // it. The reference view sees 28.4 pixels a square metre (f = 160 px at 30 m);
        // resolving 0.15 m across takes 44.4, (44.4 / 28.4)^3 = 3.8 reference exposures at
        // gamma 2.
        let j_ref = (160.0f64 / 30.0).powi(2);
        let far = |e: f32| {
            let mut lay = flat_between.clone();
            for j in 10..30 {
                for i in 0..w {
                    lay.exposure[(j * w + i) as usize] = e;
                }
            }
            run_with(&lay, "drainpipe", &metre, j_ref)
        };
        let through = far(3.0);
        assert_eq!(through.len(), 1, "{through:?}");
        assert!(through[0][1] < 0.5 && through[0][3] == 50.0);
        assert_eq!(far(4.5).len(), 2);
    }

    #[test]
    fn the_ground_under_a_wall_is_the_terrain_not_a_neighbours_roof() {
        use crate::artifact::Material;
        use crate::artifact::{ObjectClass, SceneObject};
        use crate::geom::charts::{ChartSpec, building_charts};
        use crate::geom::mesh_build::cuboid;
        // A 6 m box standing on its base at z = 0 in a terrain slab whose top is at 0.55 m,
        // and a 2 m shed against its south wall's west half.
        let object = |id: &str, class, mesh| SceneObject {
            id: id.into(),
            class,
            mesh,
        };
        let scene = Scene {
            objects: vec![
                object(
                    "building-0",
                    ObjectClass::Building,
                    cuboid([12.0, 21.5], [4.0, 3.0, 6.0], 0.0, 0.0, Material::Concrete),
                ),
                object(
                    "terrain",
                    ObjectClass::Terrain,
                    cuboid(
                        [12.0, 21.5],
                        [40.0, 40.0, 1.0],
                        0.0,
                        -0.45,
                        Material::Concrete,
                    ),
                ),
                object(
                    "shed",
                    ObjectClass::Building,
                    cuboid([11.0, 19.0], [2.0, 2.0, 2.0], 0.0, 0.0, Material::Concrete),
                ),
            ],
        };
        let charts = building_charts(&scene, &ChartSpec::default()).unwrap();
        let rays = SceneRays::new(&scene);
        let lookup = Lookup::new(&scene, &charts);
        let south = charts
            .charts
            .iter()
            .find(|c| c.building == "building-0" && c.kind == ChartKind::Wall && c.normal[1] < -0.9)
            .unwrap();
        let row = |x: f64| {
            let (u, _) = south.uv_of([x, 20.0, 3.0]);
            ground_row(south, &rays, &lookup, u)
        };
        // 0.55 m above the wall's foot (z = 0) on 0.1 m texels.
        let v = row(13.5).unwrap();
        assert!((v - 5.5).abs() < 1e-3, "{v}");
        // Over the shed's roof: no ground there.
        assert_eq!(row(10.5), None);
    }

    #[test]
    fn a_drainpipe_runs_down_to_the_ground_and_no_further() {
        // Seen on rows 30-34 only; the wall below runs on underground to row 0, unobserved.
        let (w, h) = (10u32, 50u32);
        let c = crate::artifact::Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), 30..35);
        let mut lay = seen_layers(w, h, pr, e);
        unobserve(&mut lay, w, 0..30);
        unobserve(&mut lay, w, 35..50);
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let votes = measured_out("drainpipe", &[(3.5, 32.0)]);
        let votes: Vec<&RegionVote> = votes.iter().collect();
        let at = |ground: &dyn Fn(f64) -> Option<f64>| {
            let r = instances(0, &c, &lay, &votes, false, 1e12, ground, &p);
            assert_eq!(r.len(), 1, "{r:?}");
            r[0].rect
        };
        let r = at(&|u| (u > 3.0 && u < 4.0).then_some(12.4));
        assert!(r[1] == 12.4 && r[3] == 50.0, "{r:?}");
        // No terrain found under it: down to the wall's foot.
        let r = at(&|_| None);
        assert!(r[1] == 0.0 && r[3] == 50.0, "{r:?}");
    }

    #[test]
    fn the_blur_comes_off_a_thin_feature_and_not_off_a_wide_one() {
        // Known values: a point blurred by a Gaussian reads its FWHM, 2 sqrt(2 ln 2) sigma; a
        // wide box reads its own width; Phi(1.959964) = 0.975.
        let s = 0.645;
        assert!((blurred_width(0.0, s) - 2.354_820 * s).abs() < 1e-5);
        assert!((blurred_width(14.0, s) - 14.0).abs() < 1e-6);
        assert!((phi(1.959_964) - 0.975).abs() < 1e-6 && (phi(0.0) - 0.5).abs() < 1e-7);
        let both = |a: f64| {
            let b = blurred_width(a, s);
            HalfPeak {
                lo: 5.0 - b / 2.0,
                hi: 5.0 + b / 2.0,
                lo_blurred: true,
                hi_blurred: true,
            }
        };
        for a in [0.6, 1.2, 3.0, 14.0] {
            let (lo, hi) = deblurred(both(a), s);
            assert!(
                (hi - lo - a).abs() < 1e-6 && (lo + hi - 10.0).abs() < 1e-9,
                "{a}"
            );
        }
        // A side bounded by the chart's end stays; only the blurred side moves in.
        let b = both(1.2);
        let (lo, hi) = deblurred(
            HalfPeak {
                lo: 0.0,
                hi: b.hi - b.lo - (b.hi - b.lo - 1.2) / 2.0,
                lo_blurred: false,
                hi_blurred: true,
            },
            s,
        );
        assert!(lo == 0.0 && (hi - 1.2).abs() < 1e-6, "{lo} {hi}");
        // Narrower than the blur alone reads: the floor.
        let (lo, hi) = deblurred(
            HalfPeak {
                lo: 0.0,
                hi: 1.0,
                lo_blurred: true,
                hi_blurred: true,
            },
            s,
        );
        assert!((hi - lo - MIN_WIDTH_TEXELS).abs() < 1e-12);
    }

    #[test]
    fn a_side_at_the_charts_end_is_extrapolated_where_the_evidence_falls_toward_it() {
        // A drainpipe 0.1 m from a corner, as the demo city's views read it: highest one texel
        // in from the chart's end, falling toward the end and away from it.
        let e = half_peak_edges(&[0.535, 0.867, 0.516, 0.026, 0.0], 0, 2);
        let level = 0.867 / 2.0;
        let lo = 0.5 - (0.535 - level) / (0.867 - 0.535);
        let hi = 2.5 + (0.516 - level) / (0.516 - 0.026);
        assert!(e.lo_blurred && (e.lo - lo).abs() < 1e-12, "{e:?}");
        assert!(e.hi_blurred && (e.hi - hi).abs() < 1e-12, "{e:?}");
        // Level to the end: cut by the chart, the bound stays.
        let e = half_peak_edges(&[0.9, 0.9, 0.5, 0.0], 0, 2);
        assert!(!e.lo_blurred && e.lo == 0.0, "{e:?}");
        // Falling, but reaching half the peak only past the end: the bound stays.
        let e = half_peak_edges(&[0.8, 0.9, 0.2], 0, 1);
        assert!(!e.lo_blurred && e.lo == 0.0, "{e:?}");
        // An unobserved texel bounds as the end does: extrapolated toward it, mirrored.
        let e = half_peak_edges(&[0.0, 0.026, 0.516, 0.867, 0.535, f64::NAN], 2, 4);
        assert!(e.hi_blurred && (e.hi - (5.0 - lo)).abs() < 1e-12, "{e:?}");
    }

    #[test]
    fn a_drainpipe_takes_its_classs_width_about_the_evidence_centroid() {
        // Evidence over columns 0..3 centred on column 1.5 (texel centres k + 0.5), two rows.
        let w = 6;
        let rows = |row: [f32; 6]| -> Vec<f32> { row.iter().chain(row.iter()).copied().collect() };
        let evidence = rows([0.5, 1.0, 1.0, 0.5, 0.0, 0.0]);
        let r = within_width([0.0, 0.0, 4.0, 2.0], (0.05, 0.15), 0.1, w, &evidence);
        assert!((r[2] - r[0] - 1.5).abs() < 1e-9, "{r:?}");
        assert!((r[0] + r[2] - 4.0).abs() < 1e-9, "{r:?}");
        assert_eq!((r[1], r[3]), (0.0, 2.0));
        // A rectangle that cuts the evidence on one side (columns 1-2 of a peak on column 2):
        // the centroid is the whole peak's, not pulled toward the cut (2.27 within the cut).
        let peak = rows([0.0, 0.3, 1.0, 0.3, 0.0, 0.0]);
        let r = within_width([1.6, 0.0, 2.4, 2.0], (0.05, 0.15), 0.1, w, &peak);
        assert!(
            (r[0] - 2.1).abs() < 1e-9 && (r[2] - 2.9).abs() < 1e-9,
            "{r:?}"
        );
        // The wall's own level under the peak does not pull it toward the window's middle
        // (1.83 with it).
        let raised = rows([0.7, 1.2, 0.7, 0.2, 0.2, 0.2]);
        let r = within_width([0.0, 0.0, 3.0, 2.0], (0.05, 0.15), 0.1, w, &raised);
        assert!((r[0] + r[2] - 3.0).abs() < 1e-9, "{r:?}");
        // Narrower than the class: widened about the centroid, and kept on the chart where that
        // would reach past its end.
        let edge = rows([1.0, 0.3, 0.0, 0.0, 0.0, 0.0]);
        let centre = (0.5 + 0.3 * 1.5) / 1.3; // 0.3 as f32: to 1e-6
        let r = within_width([0.0, 0.0, 0.2, 2.0], (0.05, 0.15), 0.1, w, &edge);
        assert!(
            (r[0] - (centre - 0.25)).abs() < 1e-6 && (r[2] - (centre + 0.25)).abs() < 1e-6,
            "{r:?} {centre}"
        );
        let r = within_width([0.0, 0.0, 0.2, 2.0], (0.15, 0.3), 0.1, w, &edge);
        assert!(r[0] == 0.0 && (r[2] - 1.5).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn a_class_width_range_is_refused_out_of_order_or_not_finite() {
        for bad in [
            (0.2, 0.1),
            (f64::NAN, 0.1),
            (0.05, f64::INFINITY),
            (-0.1, 0.1),
        ] {
            let mut p = ReliefParams::default();
            p.classes[3].width_m = Some(bad);
            assert_eq!(p.validate().map_err(|e| e.0), Err("classes"), "{bad:?}");
        }
    }

    #[test]
    fn grow_threshold_is_refused_above_the_threshold_or_not_finite() {
        for g in [0.6, f64::NAN, -0.1] {
            let p = ReliefParams {
                grow_threshold: g,
                ..Default::default()
            };
            assert_eq!(p.validate().map_err(|e| e.0), Err("grow_threshold"), "{g}");
        }
        assert!(ReliefParams::default().validate().is_ok());
    }

    #[test]
    fn plane_tolerance_bridge_width_and_run_stop_are_refused_out_of_range() {
        for t in [f64::NAN, f64::INFINITY, -0.1, 11.0] {
            let p = ReliefParams {
                plane_tol_m: t,
                ..Default::default()
            };
            assert_eq!(p.validate().map_err(|e| e.0), Err("plane_tol_m"), "{t}");
        }
        let p = ReliefParams {
            bridge_texels: 1001,
            ..Default::default()
        };
        assert_eq!(p.validate().map_err(|e| e.0), Err("bridge_texels"));
        for m in [f64::NAN, f64::NEG_INFINITY, -1.0, 1001.0] {
            let p = ReliefParams {
                run_stop_m: m,
                ..Default::default()
            };
            assert_eq!(p.validate().map_err(|e| e.0), Err("run_stop_m"), "{m}");
        }
    }

    #[test]
    fn weighted_median_follows_the_weights() {
        let mut v = vec![(0.25, 10.0), (0.1, 1.0), (0.3, 2.0)];
        assert_eq!(weighted_median(&mut v), Some(0.25));
        let mut v = vec![(0.25, 1.0), (0.1, 10.0)];
        assert_eq!(weighted_median(&mut v), Some(0.1));
    }
}
