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

use rayon::prelude::*;

use crate::artifact::{
    ChartKind, ChartSet, ReliefInstance, ReliefLayers, ReliefSet, ReliefStats, Scene, View,
};
use crate::geom::raycast::SceneRays;
use crate::geom::theil_sen::median;
use crate::stage::Progress;
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
    let (rays, lookup, charts, p) = (ctx.rays, ctx.lookup, ctx.charts, ctx.p);
    let per_view: Vec<ViewRelief> = views
        .par_iter()
        .enumerate()
        .map(|(vi, v)| view_relief(vi, v, rays, charts, lookup, p))
        .collect();
    let mut stats = view_stats(&per_view, views.len());
    let j_ref = exposure_unit(views, p);
    let mut regions_by_chart: BTreeMap<u32, Vec<&RegionVote>> = BTreeMap::new();
    for v in &per_view {
        for r in &v.regions {
            regions_by_chart.entry(r.chart).or_default().push(r);
        }
    }
    let results = fuse_charts(ctx, views, &per_view, &regions_by_chart, j_ref);
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
    set
}

/// The counts of the views' votes (the texel counts come later).
fn view_stats(per_view: &[ViewRelief], views: usize) -> ReliefStats {
    let mut stats = ReliefStats {
        views: views as u64,
        ..Default::default()
    };
    for v in per_view {
        stats.calibrated += v.calibrated as u64;
        stats.regions += v.candidates;
        stats.enclosed += v.regions.len() as u64;
        stats.recessed += v.regions.iter().filter(|r| r.sign < 0).count() as u64;
        stats.protruding += v.regions.iter().filter(|r| r.sign > 0).count() as u64;
    }
    stats
}

/// The exposure unit: one head-on view from ref_distance_m at the views' median focal length,
/// one ray per pixel: J_ref^gamma x (pixels per texel = J_ref texel²). Returns J_ref.
fn exposure_unit(views: &[View], p: &ReliefParams) -> f64 {
    let mut focals: Vec<f64> = views.iter().map(|v| v.intrinsics.fx).collect();
    let f = median(&mut focals).unwrap_or(1.0);
    (f / p.ref_distance_m).powi(2)
}

/// The fusion of eq. (2)-(3) of every view's codes, and per chart, as soon as its fused layers
/// are blurred, its evidence, posterior and instances, so no chart's dense layers outlive its
/// own turn (all charts' at once were 1.5 GB on the 1 km² site). Per chart: its stored layers,
/// its instances and its observed texels.
fn fuse_charts(
    ctx: &PassCtx,
    views: &[View],
    per_view: &[ViewRelief],
    regions_by_chart: &BTreeMap<u32, Vec<&RegionVote>>,
    j_ref: f64,
) -> Vec<(ReliefLayers, Vec<ReliefInstance>, u64)> {
    let (rays, lookup, charts, p) = (ctx.rays, ctx.lookup, ctx.charts, ctx.p);
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
    let deltas = ctx.deltas;
    let with_mesh = deltas.is_some();
    let posterior = Posterior::new(p);
    let (results, _) = fuse_views_each(
        ctx.scene,
        rays,
        charts,
        views,
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
            let regions = regions_by_chart
                .get(&(ci as u32))
                .map(Vec::as_slice)
                .unwrap_or(&[]);
            let ground = |u: f64| ground_row(c, rays, lookup, u);
            let inst = instances(ci as u32, c, &lay, regions, with_mesh, j_ref, &ground, p);
            (lay.pack(c), inst, observed)
        },
    );
    results
}
