//! Façade relief (paper Sec. 4.2.2, Fig. 2): per-view region relief votes from semantic and
//! geometric cues, fused onto the wall charts by the exposure-weighted operator of eq. (2)-(3)
//! at a high gamma, turned into a per-texel posterior over the displacement class by discrete
//! Bayesian fusion (eq. (4)), and extracted as rectangular instances with a depth.
//!
//! Per view: the reported depth is calibrated against the twin (a Theil-Sen affine fit of reported
//! depth against the ray-cast depth on wall pixels: monocular depth is affinely biased); regions
//! are connected pixels of one non-wall architectural instance, or unlabelled pixels (what
//! segmentation missed), kept when a dominant wall encloses them; each kept region is classified
//! recessed, neutral or protruding by `g(v)` over three cues: the depth step against the wall
//! plane fitted around it, the flow of its normals (side faces point toward the centre of a
//! recess and away from a protrusion's), and its semantic class as a prior.

pub mod carve;

mod calibrate;
mod extent;
mod instances;
mod layers;
mod lookup;
mod params;
mod posterior;
mod silhouette;
mod votes;

use std::collections::BTreeMap;
use std::sync::{Mutex, OnceLock};

use crate::artifact::{
    ChartKind, ChartSet, ReliefInstance, ReliefLayers, ReliefSet, ReliefStats, Scene, View,
    ViewSet, Views,
};
use crate::geom::raycast::SceneRays;
use crate::geom::theil_sen::median;
use crate::stage::{Progress, StageError};
use crate::street::fusion::{FusionParams, Vote, fuse_views_each};

pub use calibrate::depth_affine;
pub use params::{ClassRule, CueWeights, ReliefParams};
pub use posterior::{
    Cpt, CptRow, DeltaParams, ExpandedCpt, MeshState, RELIEF_CLASSES, level, mesh_delta,
    mesh_state_probabilities, relief_posterior,
};
pub use votes::{RegionVote, ViewRelief};

use instances::{ground_row, instances};
use layers::{Posterior, chart_layers, unobserved_layers};
use lookup::Lookup;
use votes::{MASKED, NEUTRAL, PROTRUDING, RECESSED, view_relief};

/// Façade relief over a chart set: per-view region votes, the fusion of eq. (2)-(3) at
/// gamma_fac, evidence levels, Delta from `mesh` (if any), the posterior of eq. (4), and the
/// instances. Deterministic at any thread count.
pub fn relief(
    scene: &Scene,
    charts: &ChartSet,
    views: Views,
    mesh: Option<&Scene>,
    p: &ReliefParams,
    progress: &dyn Progress,
) -> Result<ReliefSet, StageError> {
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
///
/// One pass over the views: each view's votes are made as the fusion reads it and dropped with
/// it; only its regions and counts are kept (a few per view), so memory does not grow with the
/// views' pixels.
fn relief_pass(ctx: &PassCtx, views: Views) -> Result<ReliefSet, StageError> {
    let j_ref = exposure_unit(views.set, ctx.p);
    let kept = Mutex::new(Vec::with_capacity(views.len()));
    let results = fuse_charts(ctx, views, &kept, j_ref)?;
    // The counts are sums: the order the views finished in does not change them.
    let kept = kept.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut stats = view_stats(&kept, views.len());
    let mut set = ReliefSet {
        with_mesh: ctx.deltas.is_some(),
        ..Default::default()
    };
    for (lay, inst, obs) in results {
        set.layers.push(lay);
        set.instances.extend(inst);
        stats.observed_texels += obs;
    }
    set.stats = stats;
    Ok(set)
}

/// What stays of one view's votes once the fusion has deposited them: its regions and counts.
struct KeptVotes {
    view: usize,
    regions: Vec<RegionVote>,
    candidates: u64,
    calibrated: bool,
}

/// The counts of the views' votes (the texel counts come later).
fn view_stats(kept: &[KeptVotes], views: usize) -> ReliefStats {
    let mut stats = ReliefStats {
        views: views as u64,
        ..Default::default()
    };
    for v in kept {
        stats.calibrated += v.calibrated as u64;
        stats.regions += v.candidates;
        stats.enclosed += v.regions.len() as u64;
        stats.recessed += v.regions.iter().filter(|r| r.sign < 0).count() as u64;
        stats.protruding += v.regions.iter().filter(|r| r.sign > 0).count() as u64;
    }
    stats
}

/// Every kept region in view order, and per chart the indices of its regions.
fn regions_by_chart(kept: &Mutex<Vec<KeptVotes>>) -> (Vec<RegionVote>, BTreeMap<u32, Vec<usize>>) {
    let mut kept = kept.lock().unwrap_or_else(|e| e.into_inner());
    kept.sort_by_key(|k| k.view);
    let all: Vec<RegionVote> = kept
        .iter()
        .flat_map(|k| k.regions.iter().cloned())
        .collect();
    let mut by_chart: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (i, r) in all.iter().enumerate() {
        by_chart.entry(r.chart).or_default().push(i);
    }
    (all, by_chart)
}

/// The exposure unit: one head-on view from ref_distance_m at the views' median focal length,
/// one ray per pixel: J_ref^gamma x (pixels per texel = J_ref texel²). Returns J_ref.
fn exposure_unit(views: &ViewSet, p: &ReliefParams) -> f64 {
    let mut focals: Vec<f64> = views.views.iter().map(|v| v.intrinsics.fx).collect();
    let f = median(&mut focals).unwrap_or(1.0);
    (f / p.ref_distance_m).powi(2)
}

/// The fusion of eq. (2)-(3) of every view's codes, and per chart, as soon as its fused layers
/// are blurred, its evidence, posterior and instances, so no chart's dense layers outlive its
/// own turn (all charts' at once were 1.5 GB on the 1 km² site). Each view's votes are made as
/// the fusion reads the view; its regions go to `kept`. Per chart: its stored layers, its
/// instances and its observed texels.
fn fuse_charts(
    ctx: &PassCtx,
    views: Views,
    kept: &Mutex<Vec<KeptVotes>>,
    j_ref: f64,
) -> Result<Vec<(ReliefLayers, Vec<ReliefInstance>, u64)>, StageError> {
    let (rays, lookup, charts, p) = (ctx.rays, ctx.lookup, ctx.charts, ctx.p);
    let prepare = |vi: usize, v: &View| {
        let mut r = view_relief(vi, v, rays, charts, lookup, p);
        kept.lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(KeptVotes {
                view: vi,
                regions: std::mem::take(&mut r.regions),
                candidates: r.candidates,
                calibrated: r.calibrated,
            });
        r
    };
    let vote = |r: &ViewRelief, _: &View, px: usize| -> Vote {
        match r.codes.get(px) {
            Some(&RECESSED) => Vote::Class(0),
            // No layer of neutral votes is read: a neutral pixel is exposure (R and P are
            // shares of it), which is what Seen deposits, without a grid of its own.
            Some(&NEUTRAL) => Vote::Seen,
            Some(&PROTRUDING) => Vote::Class(2),
            Some(&MASKED) => Vote::Masked,
            _ => Vote::Seen,
        }
    };
    let displace =
        |r: &ViewRelief, px: usize| -> f64 { r.displace.get(px).map_or(0.0, |&d| d as f64) };
    // The charts are finished after every view is deposited: by then every region is in.
    let regions = OnceLock::new();
    let fp = FusionParams {
        gamma: p.gamma,
        theta_max_deg: p.theta_max_deg,
        sigma_texels: p.sigma_texels,
        stride: p.stride,
    };
    let deltas = ctx.deltas;
    let with_mesh = deltas.is_some();
    let posterior = Posterior::new(p);
    let (results, _) = fuse_views_each(
        ctx.scene,
        rays,
        charts,
        views,
        &prepare,
        &vote,
        &displace,
        &fp,
        ctx.progress,
        |ci, c, l| {
            let w_ref = j_ref.powf(p.gamma) * j_ref * c.texel_m * c.texel_m;
            let delta = deltas.map(|d| &d[ci]).filter(|d| !d.is_empty());
            let l = l.filter(|l| l.w_exp.iter().any(|&w| w > 0.0));
            if c.kind != ChartKind::Wall || (l.is_none() && delta.is_none()) {
                return (unobserved_layers(c, with_mesh), Vec::new(), 0);
            }
            let (lay, observed) = chart_layers(c, l, delta, w_ref, &posterior, p);
            let (all, by_chart) = regions.get_or_init(|| regions_by_chart(kept));
            let regions: Vec<&RegionVote> = by_chart
                .get(&(ci as u32))
                .map_or(&[][..], Vec::as_slice)
                .iter()
                .map(|&i| &all[i])
                .collect();
            let ground = |u: f64| ground_row(c, rays, lookup, u);
            let inst = instances(ci as u32, c, &lay, &regions, with_mesh, j_ref, &ground, p);
            (lay.pack(c), inst, observed)
        },
    )?;
    Ok(results)
}
