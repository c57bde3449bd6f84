//! Façade relief (paper Sec. 4.2.2, eq. (4)): per-texel posteriors over the displacement class
//! and the recessed and protruding instances extracted from them, each with the evidence that
//! decided it.

use serde::{Deserialize, Serialize};

use super::SparseLayer;

/// Per-texel relief layers of one chart, in raster order (`v` rows of `width` texels). Each
/// layer keeps only the texels that carry a value: NaN or zero everywhere else, which on a
/// street-level site is most of every chart (the back of every building, the storeys no view
/// reached).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReliefLayers {
    /// Texels along `u`.
    pub width: u32,
    /// Texels along `v`.
    pub height: u32,
    /// Exposure W_exp over the reference exposure (one head-on view from the reference
    /// distance), 0 where no view saw the texel; texels under the threshold are unobserved.
    pub exposure: SparseLayer,
    /// Recessed evidence E^-/W_exp, NaN where unobserved.
    pub recessed: SparseLayer,
    /// Protruding evidence E^+/W_exp, NaN where unobserved.
    pub protruding: SparseLayer,
    /// Signed discrepancy Delta to the source mesh along the outward normal, metres (positive:
    /// the mesh stands in front of our façade); NaN where the mesh was not hit; of length 0
    /// when the relief was given no mesh.
    pub delta: SparseLayer,
    /// Posterior Pr(Y = recessed | e) of eq. (4), NaN where there is no evidence at all.
    pub pr_recessed: SparseLayer,
    /// Posterior Pr(Y = protruding | e), NaN likewise.
    pub pr_protruding: SparseLayer,
}

/// One recessed or protruding feature found on a chart: a rectangle in the chart's texel frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReliefInstance {
    /// Index of the chart it lies on.
    pub chart: u32,
    /// The building's object id.
    pub building: String,
    /// -1 recessed, +1 protruding.
    pub sign: i8,
    /// Semantic class (the views' architectural class, or `unknown` where only geometric cues
    /// found it).
    pub class: String,
    /// Rectangle in continuous texel coordinates: u0, v0, u1, v1.
    pub rect: [f64; 4],
    /// Its corners in the site frame (counter-clockwise seen from outside), metres.
    pub corners: [[f64; 3]; 4],
    /// Depth into (recess) or out of (protrusion) the wall, metres, after the per-class clamp.
    pub depth_m: f64,
    /// The depth the views measured (weighted median of their region steps), before the clamp;
    /// `None` where no view measured it.
    pub measured_depth_m: Option<f64>,
    /// Mean posterior of its class over its texels.
    pub posterior: f64,
    /// Mean exposure over its texels (in reference exposures).
    pub exposure: f64,
    /// Texels in the component.
    pub texels: u32,
    /// Distinct views whose regions voted for it.
    pub views: u32,
    /// Share of its texels where the source mesh's discrepancy state agrees with its sign
    /// (Pr(d = its sign | Delta) > 0.5); `None` without a source mesh.
    pub delta_agreement: Option<f64>,
}

/// Counts behind a relief run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReliefStats {
    /// Views given.
    pub views: u64,
    /// Views whose depth calibrated against the twin (robust affine fit on wall pixels).
    pub calibrated: u64,
    /// Candidate regions (connected pixel regions of one non-wall instance, or unlabelled).
    pub regions: u64,
    /// Regions kept (enclosed by a dominant wall).
    pub enclosed: u64,
    /// Kept regions classified recessed.
    pub recessed: u64,
    /// Kept regions classified protruding.
    pub protruding: u64,
    /// Wall texels with exposure above the threshold.
    pub observed_texels: u64,
}

/// The relief of a set of charts: layers per chart and the instances.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReliefSet {
    /// One per chart of the chart set, in its order.
    pub layers: Vec<ReliefLayers>,
    /// Instances, by chart then sign then raster order.
    pub instances: Vec<ReliefInstance>,
    /// Whether a source mesh gave Delta.
    pub with_mesh: bool,
    /// Counts.
    pub stats: ReliefStats,
}
