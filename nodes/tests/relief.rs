//! Façade relief (Sec. 4.2.2, eq. (4)) on the synthetic site, scored against the city's truth:
//! recessed windows and doors, protruding balconies and drainpipes, matched on their wall's chart
//! at IoU >= 0.5; the posterior of eq. (4) against hand-computed values; Delta from a source mesh;
//! and the Booleans: every carved solid checked, and read back closed from the glb. The views are
//! registered against the walls first (RegisterViews, as the demo graph does), and that
//! registration is scored against the poses the views were rendered from.
//!
//! As in `fusion.rs`, the charts are made on the buildings' true outlines extruded to the eave
//! (the walls without relief), so what is scored is the relief, not the building reconstruction.
//!
//! `cargo test -p kodama-nodes --test relief -- --nocapture` prints the per-class figures.

mod common;
use common::*;

use std::collections::BTreeMap;
use std::sync::OnceLock;
use std::time::Instant;

use kodama_nodes::artifact::{ChartKind, ChartSet, City, FeatureKind, ReliefSet, Scene, ViewSet};
use kodama_nodes::geom::mesh_check::check_solid;
use kodama_nodes::io::export::write_glb;
use kodama_nodes::stages::street::relief::Relief;
use kodama_nodes::stages::street::surface_charts::{SurfaceCharts, SurfaceChartsParams};
use kodama_nodes::street::relief::carve::{CarveOutcome, CarveParams, DropKind, carve_scene};
use kodama_nodes::street::relief::{
    Cpt, CptRow, DeltaParams, MeshState, ReliefParams, level, mesh_state_probabilities,
    relief_posterior,
};
use kodama_nodes::synth::synth_city::{SynthCityParams, generate};
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::synth::truth_scene::wall_prisms;
use kodama_nodes::{Artifact, Ctx, Inputs, Stage};

// ---------------------------------------------------------------------------------------------
// Eq. (4) by hand.

/// The default CPT's numbers, restated here so the test does not read them from the code.
const IMAGE: [[f64; 3]; 9] = [
    [0.03, 0.94, 0.03],
    [0.03, 0.62, 0.35],
    [0.03, 0.12, 0.85],
    [0.35, 0.62, 0.03],
    [0.25, 0.50, 0.25],
    [0.15, 0.25, 0.60],
    [0.85, 0.12, 0.03],
    [0.60, 0.25, 0.15],
    [0.45, 0.10, 0.45],
];

#[test]
fn eq4_without_a_mesh_is_the_image_row() {
    let cpt = Cpt::default().expand();
    let none = mesh_state_probabilities(f64::NAN, &DeltaParams::default());
    assert_eq!(none, [0.0, 0.0, 0.0, 1.0]);
    for r in 0..3u8 {
        for p in 0..3u8 {
            let y = relief_posterior(&cpt, Some((r, p)), none).unwrap();
            let want = IMAGE[(r * 3 + p) as usize];
            for k in 0..3 {
                assert!((y[k] - want[k]).abs() < 1e-12, "R {r} P {p}: {y:?}");
            }
        }
    }
    // Unobserved and no mesh: no evidence, no posterior (never evidence for a flat wall).
    assert_eq!(relief_posterior(&cpt, None, none), None);
    // The levels.
    assert_eq!(level(0.1, (0.2, 0.5)), 0);
    assert_eq!(level(0.2, (0.2, 0.5)), 1);
    assert_eq!(level(0.7, (0.2, 0.5)), 2);
}

#[test]
fn eq4_with_a_mesh_matches_hand_computed_values() {
    let dp = DeltaParams::default(); // tau 0.1 m, scale 0.03 m, trust 0.8
    // The mesh lies 0.25 m behind our wall: Pr(d | Delta) by hand.
    let s = |x: f64| 1.0 / (1.0 + (-x).exp());
    let pin = s((0.25 - 0.1) / 0.03);
    let pout = s((-0.25 - 0.1) / 0.03);
    let want_pd = [0.8 * pin, 0.8 * (1.0 - pin - pout), 0.8 * pout, 0.2];
    let pd = mesh_state_probabilities(-0.25, &dp);
    for k in 0..4 {
        assert!((pd[k] - want_pd[k]).abs() < 1e-12, "{pd:?} vs {want_pd:?}");
    }
    assert!((pd[0] - 0.794_648).abs() < 1e-5);
    let cpt = Cpt::default().expand();

    // (a) No view saw the texel; the mesh shows a recess. Pr(Y | d, unobserved) ∝ Pr(Y) Pr(d | Y)
    // with Pr(Y) = (0.1, 0.8, 0.1) and Pr(d | Y) rows (0.7, 0.25, 0.05), (0.05, 0.9, 0.05),
    // (0.05, 0.25, 0.7); the Unknown state carries nothing, so the sum is over 0.8 of the mass.
    let rin = [0.07 / 0.115, 0.04 / 0.115, 0.005 / 0.115];
    let rflush = [0.025 / 0.77, 0.72 / 0.77, 0.025 / 0.77];
    let rout = [0.005 / 0.115, 0.04 / 0.115, 0.07 / 0.115];
    let want: Vec<f64> = (0..3)
        .map(|k| (pd[0] * rin[k] + pd[1] * rflush[k] + pd[2] * rout[k]) / 0.8)
        .collect();
    let y = relief_posterior(&cpt, None, pd).unwrap();
    for k in 0..3 {
        assert!((y[k] - want[k]).abs() < 1e-12, "{y:?} vs {want:?}");
    }
    assert!(
        (y[0] - 0.6049).abs() < 1e-3,
        "the mesh alone makes it a recess: {y:?}"
    );

    // (b) Many views saw it flat (R = P = 0), the mesh says recess: the views win.
    // Pr(Y | In, 0, 0) ∝ (0.03 x 0.7, 0.94 x 0.05, 0.03 x 0.05) = (0.021, 0.047, 0.0015).
    let oin = [0.021 / 0.0695, 0.047 / 0.0695, 0.0015 / 0.0695];
    let oflush = [0.0075 / 0.861, 0.846 / 0.861, 0.0075 / 0.861];
    let oout = [0.0015 / 0.0695, 0.047 / 0.0695, 0.021 / 0.0695];
    let unk = IMAGE[0];
    let want: Vec<f64> = (0..3)
        .map(|k| pd[0] * oin[k] + pd[1] * oflush[k] + pd[2] * oout[k] + pd[3] * unk[k])
        .collect();
    let y = relief_posterior(&cpt, Some((0, 0)), pd).unwrap();
    for k in 0..3 {
        assert!((y[k] - want[k]).abs() < 1e-12, "{y:?} vs {want:?}");
    }
    assert!((y[0] - 0.2462).abs() < 1e-3 && y[1] > 0.7, "{y:?}");

    // (c) Some views say recess (R = 1): alone 0.35, with the mesh agreeing a recess.
    let y = relief_posterior(&cpt, Some((1, 0)), pd).unwrap();
    assert!(y[0] > 0.5, "{y:?}");
    // (d) A confident recess (R = 2) outweighs a mesh that says flush.
    let flush = mesh_state_probabilities(0.0, &dp);
    let y = relief_posterior(&cpt, Some((2, 0)), flush).unwrap();
    assert!(y[0] > 0.5, "{y:?}");
}

#[test]
fn explicit_rows_replace_derived_ones_and_bad_tables_are_refused() {
    let mut cpt = Cpt::default();
    cpt.rows.push(CptRow {
        d: MeshState::Unknown,
        r: 1,
        p: 0,
        y: (0.6, 0.4, 0.0),
    });
    cpt.validate().unwrap();
    let e = cpt.expand();
    assert_eq!(e.observed[3][1][0], [0.6, 0.4, 0.0]);
    let mut twice = cpt.clone();
    twice.rows.push(twice.rows[0].clone());
    assert!(twice.validate().unwrap_err().contains("twice"));
    let mut bad = Cpt::default();
    bad.image[4] = (0.5, 0.5, 0.5);
    assert!(bad.validate().unwrap_err().contains("summing to 1"));
    bad = Cpt::default();
    bad.mesh.pop();
    assert!(bad.validate().is_err());
    let p = ReliefParams {
        gamma: f64::NAN,
        ..Default::default()
    };
    assert_eq!(p.validate().unwrap_err().0, "gamma");
    let p = ReliefParams {
        levels: (0.6, 0.5),
        ..Default::default()
    };
    assert_eq!(p.validate().unwrap_err().0, "levels");
}

// ---------------------------------------------------------------------------------------------
// The synthetic site.

struct Site {
    city: City,
    walls: Scene,
    truth: Scene,
    charts: ChartSet,
    views: ViewSet,
}

/// The demo's view knobs (graphs/demo.ron "views"): 320 x 240, a station every 15 m, 64 views,
/// 0.5 m and 1 degree pose noise, depth reported as about 0.8 z + 1 m; every other sensor error
/// at SynthViews' defaults (height, pitch, roll and focal noise; depth warp, far-range growth and
/// edge bleeding; normal noise; mask boundaries, misses, merges, spurious and confused
/// instances; 5 % of materials wrong).
fn demo_views() -> SynthViewsParams {
    SynthViewsParams {
        size: (320, 240),
        spacing_m: 15.0,
        max_views: 64,
        pose_noise_m: 0.5,
        heading_noise_deg: 1.0,
        depth_scale: 0.8,
        depth_offset_m: 1.0,
        ..Default::default()
    }
}

/// `p` with the reported poses and focal lengths the true ones (every other error kept).
fn true_poses(p: SynthViewsParams) -> SynthViewsParams {
    p.with_true_poses()
}

fn make_site(views: SynthViewsParams) -> Site {
    make_site_in(&small_city(), views)
}

fn make_site_in(city: &SynthCityParams, views: SynthViewsParams) -> Site {
    let city = generate(city);
    let truth = scene_of(&city);
    let s = site();
    let ctx = Ctx::new(&s, &[]);
    let set: ViewSet = SynthViews::run(
        &views,
        &Inputs::new()
            .with("scene", slot(Artifact::Scene(truth.clone())))
            .with("city", slot(Artifact::City(city.clone()))),
        &ctx,
    )
    .unwrap();
    let walls = wall_prisms(&city, &truth).unwrap();
    let charts = SurfaceCharts::run(
        &SurfaceChartsParams::default(),
        &Inputs::new().with("scene", slot(Artifact::Scene(walls.clone()))),
        &ctx,
    )
    .unwrap();
    Site {
        city,
        walls,
        truth,
        charts,
        views: set,
    }
}

fn demo_site() -> &'static Site {
    static S: OnceLock<Site> = OnceLock::new();
    S.get_or_init(|| make_site(demo_views()))
}

/// The demo site's views after registration, and how long it took.
fn demo_registered_timed() -> &'static (ViewSet, f64) {
    static V: OnceLock<(ViewSet, f64)> = OnceLock::new();
    V.get_or_init(|| {
        let s = demo_site();
        let t = Instant::now();
        let v = register_views(&s.views, &s.walls);
        (v, t.elapsed().as_secs_f64())
    })
}

fn demo_registered() -> &'static ViewSet {
    &demo_registered_timed().0
}

fn run_relief(s: &Site, views: &ViewSet, mesh: Option<&Scene>, p: &ReliefParams) -> ReliefSet {
    let st = site();
    let ctx = Ctx::new(&st, &[]);
    let mut inputs = Inputs::new()
        .with("views", slot(Artifact::Views(views.clone())))
        .with("scene", slot(Artifact::Scene(s.walls.clone())))
        .with("charts", slot(Artifact::Charts(s.charts.clone())));
    if let Some(m) = mesh {
        inputs = inputs.with(
            "mesh",
            kodama_nodes::stage::Slot::Optional(Some(std::sync::Arc::new(Artifact::Scene(
                m.clone(),
            )))),
        );
    }
    Relief::run(p, &inputs, &ctx).unwrap()
}

fn demo_relief() -> &'static (ReliefSet, f64) {
    static R: OnceLock<(ReliefSet, f64)> = OnceLock::new();
    R.get_or_init(|| {
        let s = demo_site();
        let views = demo_registered();
        let t = Instant::now();
        let r = run_relief(s, views, None, &ReliefParams::default());
        (r, t.elapsed().as_secs_f64())
    })
}

/// A true feature on a chart: class, sign, true depth, chart, rect (u0, v0, u1, v1) in texels.
struct TrueFeature {
    class: &'static str,
    sign: i8,
    depth_m: f64,
    chart: usize,
    rect: [f64; 4],
}

fn class_name(k: FeatureKind) -> &'static str {
    match k {
        FeatureKind::Window => "window",
        FeatureKind::Door => "door",
        FeatureKind::Balcony => "balcony",
        FeatureKind::Drainpipe => "drainpipe",
    }
}

/// Every feature of the city on the wall chart of its edge.
fn true_features(city: &City, charts: &ChartSet) -> Vec<TrueFeature> {
    let mut out = Vec::new();
    for b in &city.buildings {
        for f in &b.features {
            let ring = if f.ring == 0 {
                &b.footprint.exterior
            } else {
                &b.footprint.holes[f.ring - 1]
            };
            let (a, c) = (ring[f.edge], ring[(f.edge + 1) % ring.len()]);
            let len = (c[0] - a[0]).hypot(c[1] - a[1]);
            let t = [(c[0] - a[0]) / len, (c[1] - a[1]) / len];
            // The solid is left of the edge: outward is to the right.
            let out_n = [t[1], -t[0]];
            let p = |s: f64, z: f64| [a[0] + t[0] * s, a[1] + t[1] * s, z];
            let found = charts.charts.iter().enumerate().find(|(_, ch)| {
                ch.building == b.id
                    && ch.kind == ChartKind::Wall
                    && ch.normal[0] * out_n[0] + ch.normal[1] * out_n[1] > 0.999
                    && {
                        let q = p((f.along.0 + f.along.1) / 2.0, (f.z.0 + f.z.1) / 2.0);
                        let d: f64 = (0..3).map(|k| (q[k] - ch.origin[k]) * ch.normal[k]).sum();
                        let (u, v) = ch.uv_of(q);
                        d.abs() < 0.05
                            && u >= 0.0
                            && v >= 0.0
                            && u <= ch.width as f64
                            && v <= ch.height as f64
                    }
            });
            let Some((ci, ch)) = found else { continue };
            // What can be seen: from the terrain up (drainpipes start below it, at the solid's
            // base).
            let mid = p((f.along.0 + f.along.1) / 2.0, 0.0);
            let ground = kodama_nodes::artifact::height_at(&city.terrain, mid[0], mid[1]);
            let (u0, v0) = ch.uv_of(p(f.along.0, f.z.0.max(ground)));
            let (u1, v1) = ch.uv_of(p(f.along.1, f.z.1));
            out.push(TrueFeature {
                class: class_name(f.kind),
                sign: if f.depth_m < 0.0 { -1 } else { 1 },
                depth_m: f.depth_m.abs(),
                chart: ci,
                rect: [u0.min(u1), v0.min(v1), u0.max(u1), v0.max(v1)],
            });
        }
    }
    out
}

fn iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let i = w * h;
    let u = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - i;
    if u > 0.0 { i / u } else { 0.0 }
}

/// Share of a true feature's texels the views observed (exposure over the threshold).
fn observed_share(r: &ReliefSet, f: &TrueFeature, exposure_min: f64) -> f64 {
    let l = &r.layers[f.chart];
    let (mut n, mut seen) = (0, 0);
    for j in f.rect[1].floor() as u32..f.rect[3].ceil() as u32 {
        for i in f.rect[0].floor() as u32..f.rect[2].ceil() as u32 {
            if i >= l.width || j >= l.height {
                continue;
            }
            n += 1;
            if l.exposure.get((j * l.width + i) as usize) as f64 >= exposure_min {
                seen += 1;
            }
        }
    }
    if n == 0 { 0.0 } else { seen as f64 / n as f64 }
}

#[derive(Default, Debug, Clone, Copy)]
struct ClassScore {
    truth: usize,
    observed: usize,
    found: usize,
    instances: usize,
    correct: usize,
}

struct Scores {
    by_class: BTreeMap<&'static str, ClassScore>,
    depth_errors: BTreeMap<&'static str, Vec<f64>>,
}

impl Scores {
    fn recall(&self, c: &str) -> f64 {
        let s = self.by_class[c];
        s.found as f64 / s.observed.max(1) as f64
    }
    fn precision(&self, c: &str) -> f64 {
        let s = self.by_class[c];
        s.correct as f64 / s.instances.max(1) as f64
    }
    fn median_depth_error(&self) -> f64 {
        let mut all: Vec<f64> = self.depth_errors.values().flatten().copied().collect();
        all.sort_by(f64::total_cmp);
        if all.is_empty() {
            f64::NAN
        } else {
            all[all.len() / 2]
        }
    }
}

/// Matches instances to true features on the same chart with the same sign at IoU >= 0.5 (each
/// used once, best IoU first). Recall is over the features the views observed (half their
/// texels exposed); precision over the instances, by the class the instance was given.
fn score(s: &Site, r: &ReliefSet, p: &ReliefParams) -> Scores {
    score_against(s, r, r, p)
}

/// [`score`] with recall over the features `seen` observed (a run with more views).
fn score_against(s: &Site, r: &ReliefSet, seen: &ReliefSet, p: &ReliefParams) -> Scores {
    let truth = true_features(&s.city, &s.charts);
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (ti, t) in truth.iter().enumerate() {
        for (ii, inst) in r.instances.iter().enumerate() {
            if inst.chart as usize == t.chart && inst.sign == t.sign {
                let x = iou(inst.rect, t.rect);
                if x >= 0.5 {
                    pairs.push((x, ti, ii));
                }
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let (mut t_used, mut i_used) = (vec![false; truth.len()], vec![false; r.instances.len()]);
    let mut depth_errors: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    for (_, ti, ii) in pairs {
        if t_used[ti] || i_used[ii] {
            continue;
        }
        t_used[ti] = true;
        i_used[ii] = true;
        depth_errors
            .entry(truth[ti].class)
            .or_default()
            .push((r.instances[ii].depth_m - truth[ti].depth_m).abs());
    }
    let mut by_class: BTreeMap<&'static str, ClassScore> = BTreeMap::new();
    for c in ["window", "door", "balcony", "drainpipe", "unknown"] {
        by_class.insert(c, ClassScore::default());
    }
    for (ti, t) in truth.iter().enumerate() {
        let e = by_class.get_mut(t.class).unwrap();
        e.truth += 1;
        if observed_share(seen, t, p.exposure_min) >= 0.5 {
            e.observed += 1;
            e.found += t_used[ti] as usize;
        }
    }
    for (ii, inst) in r.instances.iter().enumerate() {
        let key = ["window", "door", "balcony", "drainpipe"]
            .into_iter()
            .find(|c| *c == inst.class)
            .unwrap_or("unknown");
        let e = by_class.get_mut(key).unwrap();
        e.instances += 1;
        e.correct += i_used[ii] as usize;
    }
    Scores {
        by_class,
        depth_errors,
    }
}

/// Each class of `floors` (class, recall, precision) observed at least `min_observed` times and
/// found at least at its floors.
fn assert_floors(sc: &Scores, min_observed: usize, floors: &[(&str, f64, f64)]) {
    for &(c, recall, precision) in floors {
        assert!(
            sc.by_class[c].observed >= min_observed,
            "{c}: {:?}",
            sc.by_class[c]
        );
        assert!(sc.recall(c) >= recall, "{c} recall {}", sc.recall(c));
        assert!(
            sc.precision(c) >= precision,
            "{c} precision {}",
            sc.precision(c)
        );
    }
}

fn print_scores(label: &str, sc: &Scores) {
    println!("{label}");
    for (c, s) in &sc.by_class {
        let mut d = sc.depth_errors.get(c).cloned().unwrap_or_default();
        d.sort_by(f64::total_cmp);
        let med = d.get(d.len() / 2).copied().unwrap_or(f64::NAN);
        println!(
            "  {c:9} truth {:4} observed {:4} found {:4} recall {:.3} | instances {:4} correct {:4} precision {:.3} | median depth error {med:.3} m",
            s.truth,
            s.observed,
            s.found,
            s.found as f64 / s.observed.max(1) as f64,
            s.instances,
            s.correct,
            s.correct as f64 / s.instances.max(1) as f64,
        );
    }
    println!(
        "  median depth error, all matched: {:.3} m",
        sc.median_depth_error()
    );
}

#[test]
fn relief_on_the_synthetic_site_with_the_demo_view_knobs() {
    let s = demo_site();
    let (r, secs) = demo_relief();
    println!(
        "relief on the registered views: {} views ({} calibrated), {} candidate regions, {} enclosed ({} recessed, {} protruding), {} observed wall texels, {} instances, {secs:.2} s",
        r.stats.views,
        r.stats.calibrated,
        r.stats.regions,
        r.stats.enclosed,
        r.stats.recessed,
        r.stats.protruding,
        r.stats.observed_texels,
        r.instances.len()
    );
    let p = ReliefParams::default();
    let sc = score(s, r, &p);
    print_scores(
        "demo view knobs (pose noise 0.5 m, 1 deg), views registered:",
        &sc,
    );
    // Affine depth (0.8 z + 1 m) calibrates on every view (walls and ground spread the depths).
    assert_eq!(r.stats.calibrated, r.stats.views);
    assert!(sc.by_class["window"].observed > 50);
    // The targets were 0.8 recall and precision per class, met with the near-oracle sensors
    // before issue 51 (drainpipes, the hard class at 0.12 m wide, six of seven). With the
    // sensors of issue 51 the views' poses err in height, pitch, roll and focal length as well,
    // and that alone takes windows from 0.97 / 0.91 to 0.79 / 0.73 (`relief_by_error`); with
    // every error on, windows come to 0.61 / 0.60 (435 observed), doors 0.50 / 0.70 (8),
    // balconies 0.50 / 0.50 (14), drainpipes 0.25 / 0.21 (8) (2026-11-28). The floors below
    // hold those levels: windows firmly, the classes of a handful of instances loosely (one
    // door is an eighth of the class).
    assert_floors(
        &sc,
        5,
        &[
            ("window", 0.55, 0.55),
            ("door", 0.35, 0.5),
            ("balcony", 0.35, 0.35),
            ("drainpipe", 0.12, 0.1),
        ],
    );
    assert!(
        sc.median_depth_error() <= 0.06,
        "{}",
        sc.median_depth_error()
    );
    for i in &r.instances {
        assert!(i.posterior >= 0.5 && i.posterior <= 1.0, "{i:?}");
        assert!(i.depth_m > 0.0 && i.rect[0] < i.rect[2] && i.rect[1] < i.rect[3]);
        assert!(i.delta_agreement.is_none());
    }
    // The same views as their metadata placed them: half a metre of pose error moves each
    // view's deposits whole, and at IoU 0.5 on 1.4 m windows most of them are lost.
    let raw = run_relief(s, &s.views, None, &p);
    let sc_raw = score(s, &raw, &p);
    print_scores(
        "demo view knobs, views as the metadata placed them:",
        &sc_raw,
    );
    assert!(
        sc_raw.recall("window") + 0.3 < sc.recall("window"),
        "registration must find windows the metadata loses: {} against {}",
        sc_raw.recall("window"),
        sc.recall("window")
    );
    // Recall against the share of views kept (every view k with k mod 10 under 7, under 4),
    // each subset registered on its own, over the features the full set observed.
    let mut curve = Vec::new();
    for keep in [10usize, 7, 4] {
        let sub = ViewSet {
            views: s
                .views
                .views
                .iter()
                .enumerate()
                .filter(|(k, _)| k % 10 < keep)
                .map(|(_, v)| v.clone())
                .collect(),
            material_classes: s.views.material_classes.clone(),
        };
        let rk = if keep == 10 {
            r.clone()
        } else {
            run_relief(s, &register_views(&sub, &s.walls), None, &p)
        };
        let sk = score_against(s, &rk, r, &p);
        println!(
            "views kept {:3} %: recall window {:.3} door {:.3} balcony {:.3} drainpipe {:.3}",
            keep * 10,
            sk.recall("window"),
            sk.recall("door"),
            sk.recall("balcony"),
            sk.recall("drainpipe")
        );
        curve.push(sk.recall("window"));
    }
    assert!(
        curve[2] < curve[0],
        "fewer views, fewer windows found: {curve:?}"
    );
}

/// The demo city (400 m x 300 m, 72 buildings) with every street photographed (416 views, the
/// street-level sweep's twin), registered: a sample large enough to score the thin classes (49
/// observed drainpipes against the 8 above). With the near-oracle sensors before issue 51,
/// windows, doors and balconies met the 0.8 and drainpipes came to 0.80 / 0.83 (the
/// history of each step is in docs/benchmarks-log.md). With the sensors of issue 51 (poses off
/// in six degrees of freedom and the focal length, depth warped, masks merged, missed and
/// confused): windows 0.558 / 0.579 (3109 observed), doors 0.692 / 0.609 (26), balconies 0.253 /
/// 0.324 (79; their median depth error 0.20 m), drainpipes 0.286 / 0.291 (49) (2026-11-28).
/// On SynthCity v3's varied façades: windows 0.551 / 0.573 (3142), doors 0.680 / 0.623 (25),
/// balconies 0.333 / 0.329 (75), drainpipes 0.294 / 0.296 (51), median depth error 0.053 m
/// (2026-11-28). The floors hold those levels. Slow (416 views rendered, registered and fused: about 6
/// minutes on 2 cores), so run on request: `cargo test -p kodama-nodes --test relief
/// relief_on_every_street -- --ignored --nocapture`.
#[test]
#[ignore = "slow (416 views, about 6 minutes on 2 cores); passes: run with --ignored"]
fn relief_on_every_street_of_the_demo_city() {
    let s = make_site_in(
        &SynthCityParams::default(),
        SynthViewsParams {
            max_views: 1000,
            ..demo_views()
        },
    );
    assert!(s.views.views.len() > 400, "{} views", s.views.views.len());
    let views = register_views(&s.views, &s.walls);
    let p = ReliefParams::default();
    let r = run_relief(&s, &views, None, &p);
    let sc = score(&s, &r, &p);
    print_scores("the demo city, every street, views registered:", &sc);
    assert_floors(
        &sc,
        20,
        &[
            ("window", 0.5, 0.52),
            ("door", 0.6, 0.55),
            ("balcony", 0.2, 0.27),
            ("drainpipe", 0.22, 0.23),
        ],
    );
    let mut d = sc.depth_errors["balcony"].clone();
    d.sort_by(f64::total_cmp);
    assert!(
        d[d.len() / 2] <= 0.25,
        "balcony median depth error {}",
        d[d.len() / 2]
    );
    assert!(
        sc.median_depth_error() <= 0.06,
        "{}",
        sc.median_depth_error()
    );
}

/// `views` as a segmentation model would give them that missed every instance of `class`: its
/// pixels unlabelled.
fn missing_class(views: &ViewSet, class: &str) -> ViewSet {
    let mut views = loaded(views);
    for v in &mut views.views {
        if let Some(arch) = v.arch.as_mut() {
            let missed: Vec<u16> = arch
                .classes
                .iter()
                .filter(|(_, c)| c.as_str() == class)
                .map(|(&id, _)| id)
                .collect();
            for id in arch.ids.iter_mut() {
                if missed.contains(id) {
                    *id = 0;
                }
            }
            arch.classes.retain(|id, _| !missed.contains(id));
        }
    }
    stored(views.views, views.material_classes)
}

/// The segmentation model missing every wall (each view's wall pixels unlabelled, as the demo's
/// missed instances do to one wall in ten): the calibrated depth puts the unlabelled pixels
/// around a window on its wall's plane, so windows are still enclosed and found. With the
/// near-oracle sensors 0.7 of the windows the labelled walls gave were found so; with those of
/// issue 51 (depth warped and bled across edges, normals 12 degrees off) 0.19 (2026-11-28),
/// and without the depth to tell the walls, none: the depth still carries what the labels lost,
/// but far less of it.
#[test]
fn windows_are_found_where_the_segmentation_missed_the_walls() {
    let s = demo_site();
    let views = missing_class(demo_registered(), "wall");
    let p = ReliefParams::default();
    let r = run_relief(s, &views, None, &p);
    let sc = score_against(s, &r, &demo_relief().0, &p);
    print_scores("every wall missed by the segmentation:", &sc);
    // Without the depth to tell the walls, nothing is enclosed.
    let blind = ReliefParams {
        plane_tol_m: 0.0,
        ..p
    };
    let none = score_against(
        s,
        &run_relief(s, &views, None, &blind),
        &demo_relief().0,
        &blind,
    );
    println!(
        "window recall with the walls missed: {:.3} by the depth, {:.3} without it",
        sc.recall("window"),
        none.recall("window")
    );
    assert!(sc.recall("window") >= 0.15, "{}", sc.recall("window"));
    assert!(sc.precision("window") >= 0.5, "{}", sc.precision("window"));
    assert!(
        none.recall("window") < 0.5 * sc.recall("window"),
        "{}",
        none.recall("window")
    );
}

/// Mean protruding evidence (E+ / W_exp) over the observed texels of the true drainpipes, and
/// how many texels that is.
fn drainpipe_evidence(s: &Site, r: &ReliefSet, p: &ReliefParams) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0usize);
    for t in true_features(&s.city, &s.charts)
        .iter()
        .filter(|t| t.class == "drainpipe")
    {
        let l = &r.layers[t.chart];
        for j in t.rect[1].floor() as u32..(t.rect[3].ceil() as u32).min(l.height) {
            for i in t.rect[0].floor() as u32..(t.rect[2].ceil() as u32).min(l.width) {
                let k = (j * l.width + i) as usize;
                if l.exposure.get(k) as f64 >= p.exposure_min {
                    sum += l.protruding.get(k) as f64;
                    n += 1;
                }
            }
        }
    }
    (sum / n.max(1) as f64, n)
}

/// The segmentation model missing every drainpipe (each view's pipe pixels unlabelled, as the
/// demo's missed instances do to one instance in ten): a pipe reaches the ground, and its
/// unlabelled pixels are kept apart from the ground's by their normals, so the wall encloses
/// them and their depth step reads the pipe standing out. Joined to the street's surface they
/// were one region nothing enclosed, whose pixels voted for a flat wall where the pipe stands:
/// mean protruding evidence over the pipes' texels 0.29, against 0.46 (0.54 with the pipes
/// labelled) with the near-oracle sensors. With those of issue 51 (normals 12 degrees off,
/// depth warped and bled across edges, poses off in six degrees of freedom) 0.218 missed
/// against 0.294 labelled (2026-11-28): the pipe keeps three quarters of its evidence.
#[test]
fn a_drainpipe_the_segmentation_missed_still_reads_as_standing_out() {
    let s = demo_site();
    let views = missing_class(demo_registered(), "drainpipe");
    let p = ReliefParams::default();
    let r = run_relief(s, &views, None, &p);
    print_scores(
        "every drainpipe missed by the segmentation:",
        &score_against(s, &r, &demo_relief().0, &p),
    );
    let (missed, n) = drainpipe_evidence(s, &r, &p);
    let (labelled, _) = drainpipe_evidence(s, &demo_relief().0, &p);
    println!(
        "protruding evidence over {n} observed pipe texels: {missed:.3} missed, {labelled:.3} labelled"
    );
    assert!(
        missed >= 0.6 * labelled && missed >= 0.15,
        "{missed} against {labelled}"
    );
}

/// Registration against the walls, scored against the poses the views were rendered from
/// (SynthViews with the noise off gives them, station for station): the views that show a
/// building come back to within a few centimetres, and the few that stay off are bounded.
#[test]
fn registration_brings_the_views_back_to_where_they_were_taken() {
    let noisy = demo_site();
    let (reg, secs) = demo_registered_timed();
    let truth = make_site(true_poses(demo_views()));
    let heading = |p: &kodama_nodes::artifact::Pose| p.rotation[1][2].atan2(p.rotation[0][2]);
    // What the registration does not search: height and pitch (kept from the metadata).
    let pitch = |p: &kodama_nodes::artifact::Pose| p.rotation[2][2].asin().to_degrees();
    let (mut dz, mut dpitch): (Vec<f64>, Vec<f64>) = noisy
        .views
        .views
        .iter()
        .zip(&truth.views.views)
        .map(|(n, t)| {
            (
                (n.pose.position[2] - t.pose.position[2]).abs(),
                (pitch(&n.pose) - pitch(&t.pose)).abs(),
            )
        })
        .unzip();
    dz.sort_by(f64::total_cmp);
    dpitch.sort_by(f64::total_cmp);
    println!(
        "not searched: height error median {:.3} m, pitch error median {:.2} deg",
        dz[dz.len() / 2],
        dpitch[dpitch.len() / 2]
    );
    let off = |a: &kodama_nodes::artifact::Pose, b: &kodama_nodes::artifact::Pose| {
        (
            (a.position[0] - b.position[0]).hypot(a.position[1] - b.position[1]),
            (heading(a) - heading(b)).to_degrees().abs(),
        )
    };
    let (mut before, mut after, mut yaw_before, mut yaw_after) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut moved = 0;
    for ((n, r), t) in loaded(&noisy.views)
        .views
        .iter()
        .zip(&reg.views)
        .zip(&truth.views.views)
    {
        assert_eq!(n.id, t.id);
        let sees_a_building = n
            .arch
            .as_ref()
            .is_some_and(|a| a.ids.iter().any(|&i| i != 0));
        moved += (r.pose != n.pose) as usize;
        if !sees_a_building {
            // Nothing to place it by, and nothing the façade stages take from it.
            assert_eq!(r.pose, n.pose, "{}", n.id);
            continue;
        }
        let (b, yb) = off(&n.pose, &t.pose);
        let (a, ya) = off(&r.pose, &t.pose);
        before.push(b);
        after.push(a);
        yaw_before.push(yb);
        yaw_after.push(ya);
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let q90 = |v: &Vec<f64>| v[(v.len() * 9) / 10];
    let (mb, ma) = (med(&mut before), med(&mut after));
    let (yb, ya) = (med(&mut yaw_before), med(&mut yaw_after));
    println!(
        "registration: {} views showing a building, {moved} moved, {secs:.2} s; position error median {mb:.3} -> {ma:.3} m, 90th percentile {:.3} -> {:.3} m; heading error median {yb:.2} -> {ya:.2} deg",
        before.len(),
        q90(&before),
        q90(&after)
    );
    assert!(before.len() >= 30);
    // With the near-oracle views (exact masks, depth and normals, poses off in x, y and heading
    // only) the median came to 0.02 m, the 90th percentile to 0.25 m and the heading to 0.08
    // deg. With the honest sensors of issue 51 (masks, depth, normals as real models give them;
    // height, pitch, roll and focal off too) it comes to 0.383 m from 0.651, the 90th percentile
    // goes from 1.09 to 1.19 m (a few views are pulled further off) and the heading from 0.55 to
    // 0.41 deg: registration still helps the typical view, and that is what is held here.
    assert!(ma < 0.7 * mb, "{mb:.3} -> {ma:.3}");
    assert!(ya < yb, "heading {yb:.2} -> {ya:.2} deg");
}

/// Registration gives the same poses at any thread count.
#[test]
fn registration_is_the_same_at_any_thread_count() {
    let s = demo_site();
    let sub = ViewSet {
        views: s.views.views.iter().step_by(4).cloned().collect(),
        material_classes: s.views.material_classes.clone(),
    };
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| register_views(&sub, &s.walls));
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap()
        .install(|| register_views(&sub, &s.walls));
    assert_eq!(one, two);
}

/// The same site and view knobs, but the views' reported poses are their true ones (pose noise
/// off; depth still affinely biased and noisy, 10 % of instances missed, materials wrong 5 %):
/// what the relief does with perfect registration, the ceiling for the test above.
#[test]
fn relief_with_the_true_poses_meets_the_targets() {
    let s = make_site(true_poses(demo_views()));
    let p = ReliefParams::default();
    let t = Instant::now();
    let r = run_relief(&s, &s.views, None, &p);
    let secs = t.elapsed().as_secs_f64();
    let sc = score(&s, &r, &p);
    print_scores(&format!("true poses ({secs:.2} s):"), &sc);
    // 0.8 each with the near-oracle masks; with the masks of issue 51 (boundaries off, 10 %
    // missed, neighbours merged, spurious windows, classes confused) windows come to 0.76 recall
    // and 0.75 precision, doors 0.75 and 0.89, balconies 0.93 and 0.93. On SynthCity v3's
    // façades (depths drawn per building, bays, shopfronts): windows 0.80 / 0.78, doors 0.88 /
    // 1.00, balconies 1.00 / 0.93, the median depth error 0.052 m (0.05 before: the depths the
    // views measure now vary from building to building, and the floor is 0.06).
    for c in ["window", "door", "balcony"] {
        assert!(sc.by_class[c].observed >= 5, "{c}: {:?}", sc.by_class[c]);
        assert!(sc.recall(c) >= 0.7, "{c} recall {}", sc.recall(c));
        assert!(sc.precision(c) >= 0.7, "{c} precision {}", sc.precision(c));
    }
    assert!(
        sc.median_depth_error() <= 0.06,
        "{}",
        sc.median_depth_error()
    );
    // Recall against the share of views kept, over what the full set observed.
    let mut curve = Vec::new();
    for keep in [7usize, 4] {
        let sub = ViewSet {
            views: s
                .views
                .views
                .iter()
                .enumerate()
                .filter(|(k, _)| k % 10 < keep)
                .map(|(_, v)| v.clone())
                .collect(),
            material_classes: s.views.material_classes.clone(),
        };
        let sk = score_against(&s, &run_relief(&s, &sub, None, &p), &r, &p);
        println!(
            "true poses, views kept {:3} %: recall window {:.3} door {:.3} balcony {:.3} drainpipe {:.3}",
            keep * 10,
            sk.recall("window"),
            sk.recall("door"),
            sk.recall("balcony"),
            sk.recall("drainpipe")
        );
        curve.push(sk.recall("window"));
    }
    assert!(curve[1] < sc.recall("window"), "{curve:?}");
}

// ---------------------------------------------------------------------------------------------
// Booleans.

/// Welds a glb node's primitives by exact position and checks every directed edge appears once
/// and its reverse once: closed and consistently wound. Returns the triangle count.
fn glb_node_is_closed(node: &gltf::Node, buffers: &[gltf::buffer::Data]) -> Result<usize, String> {
    let mesh = node.mesh().ok_or("node without a mesh")?;
    let mut ids: BTreeMap<[u32; 3], u32> = BTreeMap::new();
    let mut tris: Vec<[u32; 3]> = Vec::new();
    for prim in mesh.primitives() {
        let r = prim.reader(|b| Some(&buffers[b.index()]));
        let pos: Vec<[f32; 3]> = r.read_positions().ok_or("no positions")?.collect();
        let idx: Vec<u32> = r.read_indices().ok_or("no indices")?.into_u32().collect();
        let weld: Vec<u32> = pos
            .iter()
            .map(|p| {
                let key = p.map(f32::to_bits);
                let n = ids.len() as u32;
                *ids.entry(key).or_insert(n)
            })
            .collect();
        for t in idx.chunks_exact(3) {
            tris.push([
                weld[t[0] as usize],
                weld[t[1] as usize],
                weld[t[2] as usize],
            ]);
        }
    }
    let mut edges: BTreeMap<(u32, u32), i32> = BTreeMap::new();
    for t in &tris {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &edges {
        if n != 1 || edges.get(&(b, a)) != Some(&1) {
            return Err(format!(
                "edge ({a}, {b}) used {n} times, reverse {:?}",
                edges.get(&(b, a))
            ));
        }
    }
    Ok(tris.len())
}

#[test]
fn carved_solids_pass_the_solid_check_and_read_back_closed_from_the_glb() {
    let s = demo_site();
    let (r, _) = demo_relief();
    let t = Instant::now();
    let (carved, report) = carve_scene(&s.walls, &s.charts, r, &CarveParams::default()).unwrap();
    let secs = t.elapsed().as_secs_f64();
    let dropped: Vec<&String> = report
        .outcomes
        .iter()
        .filter_map(|o| match o {
            CarveOutcome::Dropped(_, w) => Some(w),
            CarveOutcome::Carved => None,
        })
        .collect();
    let n_carved = report.outcomes.len() - dropped.len();
    println!(
        "carve: {} instances, {n_carved} carved, {} dropped, {} buildings, {secs:.2} s",
        report.outcomes.len(),
        dropped.len(),
        report.buildings.len()
    );
    let mut reasons: BTreeMap<String, usize> = BTreeMap::new();
    for d in &dropped {
        *reasons.entry(d.chars().take(60).collect()).or_default() += 1;
    }
    println!("  dropped because: {reasons:?}");
    let m = report.metrics(r);
    assert_eq!(m.get("carved"), Some(n_carved as f64));
    let by_kind: f64 = DropKind::ALL
        .iter()
        .map(|k| m.get(&format!("dropped/{}", k.name())).unwrap())
        .sum();
    assert_eq!(by_kind, dropped.len() as f64, "{m:?}");
    println!(
        "  by kind: {:?}",
        DropKind::ALL.map(|k| (k.name(), m.get(&format!("dropped/{}", k.name())).unwrap()))
    );
    for b in &report.buildings {
        println!(
            "  {:12} triangles {:6} -> {:6} ({} carved, {} dropped)",
            b.id, b.triangles_before, b.triangles_after, b.carved, b.dropped
        );
    }
    assert!(
        n_carved as f64 >= 0.8 * report.outcomes.len() as f64,
        "{reasons:?}"
    );
    // Every carved building passes the solid check, and got more triangles.
    for b in &report.buildings {
        let o = carved.objects.iter().find(|o| o.id == b.id).unwrap();
        check_solid(&o.mesh).unwrap_or_else(|e| panic!("{}: {e}", b.id));
        if b.carved > 0 {
            assert!(b.triangles_after > b.triangles_before, "{b:?}");
        }
    }
    // Carved faces took their materials: glass at the back of windows, wood for doors,
    // metal or concrete for protrusions, where the relief found them.
    let has = |m: u8| carved.objects.iter().any(|o| o.mesh.materials.contains(&m));
    use kodama_nodes::artifact::Material;
    assert!(has(Material::Glass as u8));
    if r.instances.iter().any(|i| i.class == "door") {
        assert!(has(Material::Wood as u8));
    }
    // Volume: recesses took some away, protrusions added some; the sum matches the instances'
    // prisms to within their overlaps.
    let vol = |sc: &Scene| -> f64 {
        sc.objects
            .iter()
            .filter(|o| o.id.starts_with("building"))
            .map(|o| o.mesh.volume())
            .sum()
    };
    let expect: f64 = r
        .instances
        .iter()
        .zip(&report.outcomes)
        .filter(|(_, o)| **o == CarveOutcome::Carved)
        .map(|(i, _)| {
            let c = &s.charts.charts[i.chart as usize];
            let a = (i.rect[2] - i.rect[0]) * (i.rect[3] - i.rect[1]) * c.texel_m * c.texel_m;
            i.sign as f64 * a * i.depth_m
        })
        .sum();
    let got = vol(&carved) - vol(&s.walls);
    println!("  volume change {got:.2} m3, instances' prisms {expect:.2} m3");
    assert!(
        (got - expect).abs() <= 0.05 * expect.abs() + 1.0,
        "{got} vs {expect}"
    );
    // Written to glb and read back: every building node closed and consistently wound.
    let glb = write_glb(&carved).unwrap();
    let (doc, buffers, _) = gltf::import_slice(&glb).unwrap();
    let mut checked = 0;
    for node in doc.nodes() {
        let name = node.name().unwrap_or_default().to_owned();
        if let Some(b) = report.buildings.iter().find(|b| b.id == name) {
            let n = glb_node_is_closed(&node, &buffers).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(n, b.triangles_after);
            checked += 1;
        }
    }
    assert_eq!(checked, report.buildings.len());
}

// ---------------------------------------------------------------------------------------------
// Delta from a source mesh.

#[test]
fn delta_finds_recesses_the_views_miss_and_yields_where_many_views_disagree() {
    let s = demo_site();
    let p = ReliefParams::default();
    // (a) No view at all; the source mesh is the truth, whose windows are recesses as deep as
    // their building's draw (or bays): the posterior comes from the mesh alone (eq. (4)'s
    // unobserved rows), and the windows are found.
    let none = ViewSet {
        views: Vec::new(),
        material_classes: s.views.material_classes.clone(),
    };
    let r = run_relief(s, &none, Some(&s.truth), &p);
    assert!(r.with_mesh && r.stats.observed_texels == 0);
    let truth = true_features(&s.city, &s.charts);
    let windows: Vec<&TrueFeature> = truth.iter().filter(|t| t.class == "window").collect();
    let found = windows
        .iter()
        .filter(|t| {
            r.instances
                .iter()
                .any(|i| i.chart as usize == t.chart && i.sign < 0 && iou(i.rect, t.rect) >= 0.5)
        })
        .count();
    println!("mesh only: {found} of {} windows found", windows.len());
    assert!(found as f64 >= 0.8 * windows.len() as f64);
    for i in r.instances.iter().filter(|i| i.sign < 0) {
        assert_eq!(i.views, 0);
        assert!(i.delta_agreement.unwrap() > 0.5, "{i:?}");
    }
    // The posterior at a window centre is eq. (4) by hand: unobserved, Delta the window's own
    // depth, signed (in: negative).
    let t = windows[0];
    let l = &r.layers[t.chart];
    let (cu, cv) = (
        ((t.rect[0] + t.rect[2]) / 2.0) as u32,
        ((t.rect[1] + t.rect[3]) / 2.0) as u32,
    );
    let k = (cv * l.width + cu) as usize;
    let true_delta = t.sign as f64 * t.depth_m;
    assert!(
        (l.delta.get(k) as f64 - true_delta).abs() < 0.01,
        "{} against {true_delta}",
        l.delta.get(k)
    );
    let pd = mesh_state_probabilities(l.delta.get(k) as f64, &p.delta);
    let want = relief_posterior(&p.cpt.expand(), None, pd).unwrap();
    assert!((l.pr_recessed.get(k) as f64 - want[0]).abs() < 1e-6);

    // (b) The mesh is wrong: every wall 0.3 m further east than ours, so west-facing walls look
    // recessed to it everywhere. Where many views saw a plain wall, the views win.
    let mut shifted = s.walls.clone();
    for o in &mut shifted.objects {
        for q in o.mesh.positions.iter_mut() {
            q[0] += 0.3;
        }
    }
    let r = run_relief(s, demo_registered(), Some(&shifted), &p);
    let (mut checked, mut flat, mut no_mesh) = (0usize, 0usize, 0usize);
    for (ci, c) in s.charts.charts.iter().enumerate() {
        if c.kind != ChartKind::Wall || c.normal[0] > -0.99 {
            continue;
        }
        let l = &r.layers[ci];
        for (k, rr) in l.recessed.kept() {
            let (rr, pp) = (rr as f64, l.protruding.get(k) as f64);
            if !(rr.is_finite() && rr < 0.05 && pp < 0.05 && l.exposure.get(k) >= 5.0) {
                continue;
            }
            // Where the shifted mesh lies past Delta's search along the normal (at a wall's
            // ends, where the shift leaves its neighbour's corner), there is no Delta.
            if !l.delta.get(k).is_finite() {
                no_mesh += 1;
                continue;
            }
            assert!((l.delta.get(k) + 0.3).abs() < 0.02, "{}", l.delta.get(k));
            checked += 1;
            flat += (l.pr_recessed.get(k) < 0.5) as usize;
            let pd = mesh_state_probabilities(l.delta.get(k) as f64, &p.delta);
            let want = relief_posterior(&p.cpt.expand(), Some((0, 0)), pd).unwrap();
            assert!((l.pr_recessed.get(k) as f64 - want[0]).abs() < 1e-6);
        }
    }
    println!(
        "wrong mesh: {flat} of {checked} well-observed flat texels stay flat ({no_mesh} without a Delta)"
    );
    assert!(checked > 1000 && flat == checked && no_mesh * 10 < checked);
}

// ---------------------------------------------------------------------------------------------
// Determinism.

#[test]
fn relief_is_the_same_at_any_thread_count() {
    let s = demo_site();
    let few = ViewSet {
        views: s.views.views[..16].to_vec(),
        material_classes: s.views.material_classes.clone(),
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let r = run_relief(s, &few, None, &ReliefParams::default());
                let c = carve_scene(&s.walls, &s.charts, &r, &CarveParams::default()).unwrap();
                (r, c.0)
            })
    };
    let (a, b) = (run(1), run(3));
    assert!(!a.0.instances.is_empty());
    // Byte-compared: the layers hold NaN (unobserved), which is never == itself.
    let bytes = |r: &ReliefSet| rmp_serde::to_vec(r).unwrap();
    assert!(bytes(&a.0) == bytes(&b.0), "relief differs");
    assert!(a.1 == b.1, "carved scene differs");
}

/// Which metadata error the registration does not cope with: the demo site's views registered
/// with the image errors at their defaults and one pose error at a time (the others off), the
/// median position and heading error after registration printed. Slow (a registration per row):
/// `cargo test -p kodama-nodes --test relief registration_by_error -- --ignored --nocapture`.
#[test]
#[ignore]
fn registration_by_error() {
    let truth = make_site(true_poses(demo_views()));
    let xy = SynthViewsParams {
        pose_noise_m: 0.5,
        heading_noise_deg: 1.0,
        ..true_poses(demo_views())
    };
    let rows = [
        ("x, y, yaw only", xy.clone()),
        (
            "+ focal 2 %",
            SynthViewsParams {
                focal_noise: 0.02,
                ..xy.clone()
            },
        ),
        (
            "+ height 0.5 m",
            SynthViewsParams {
                height_noise_m: 0.5,
                ..xy.clone()
            },
        ),
        (
            "+ pitch, roll 0.5 deg",
            SynthViewsParams {
                pitch_noise_deg: 0.5,
                roll_noise_deg: 0.5,
                ..xy.clone()
            },
        ),
        ("all (the defaults)", demo_views()),
    ];
    let heading = |p: &kodama_nodes::artifact::Pose| p.rotation[1][2].atan2(p.rotation[0][2]);
    for (name, p) in rows {
        let s = make_site(p);
        let reg = register_views(&s.views, &s.walls);
        let (mut pos, mut yaw) = (Vec::new(), Vec::new());
        for (r, t) in loaded(&reg).views.iter().zip(&truth.views.views) {
            if !r
                .arch
                .as_ref()
                .is_some_and(|a| a.ids.iter().any(|&i| i != 0))
            {
                continue;
            }
            pos.push(
                (r.pose.position[0] - t.pose.position[0])
                    .hypot(r.pose.position[1] - t.pose.position[1]),
            );
            yaw.push((heading(&r.pose) - heading(&t.pose)).to_degrees().abs());
        }
        pos.sort_by(f64::total_cmp);
        yaw.sort_by(f64::total_cmp);
        println!(
            "{name}: position error median {:.3} m, 90th percentile {:.3} m; heading median {:.2} deg",
            pos[pos.len() / 2],
            pos[pos.len() * 9 / 10],
            yaw[yaw.len() / 2]
        );
    }
}

/// Which sensor error costs the relief what: the demo site's views with the poses as the demo
/// knobs report them (0.5 m, 1 degree), registered, and every other error off but one group at
/// a time; window, door and balcony recall and precision printed per row. Slow (a site and a
/// registration per row): `cargo test -p kodama-nodes --test relief relief_by_error --
/// --ignored --nocapture`.
#[test]
#[ignore]
fn relief_by_error() {
    let exact = SynthViewsParams {
        size: (320, 240),
        spacing_m: 15.0,
        max_views: 64,
        depth_scale: 0.8,
        depth_offset_m: 1.0,
        ..SynthViewsParams::exact()
    };
    let d = SynthViewsParams::default();
    let xy = SynthViewsParams {
        pose_noise_m: 0.5,
        heading_noise_deg: 1.0,
        ..exact.clone()
    };
    let rows = [
        ("exact, true poses", exact.clone()),
        ("x, y, yaw noise, registered", xy.clone()),
        (
            "+ height, pitch, roll, focal",
            SynthViewsParams {
                height_noise_m: d.height_noise_m,
                pitch_noise_deg: d.pitch_noise_deg,
                roll_noise_deg: d.roll_noise_deg,
                focal_noise: d.focal_noise,
                ..xy.clone()
            },
        ),
        (
            "+ height",
            SynthViewsParams {
                height_noise_m: d.height_noise_m,
                ..xy.clone()
            },
        ),
        (
            "+ pitch",
            SynthViewsParams {
                pitch_noise_deg: d.pitch_noise_deg,
                ..xy.clone()
            },
        ),
        (
            "+ roll",
            SynthViewsParams {
                roll_noise_deg: d.roll_noise_deg,
                ..xy.clone()
            },
        ),
        (
            "+ focal",
            SynthViewsParams {
                focal_noise: d.focal_noise,
                ..xy.clone()
            },
        ),
        (
            "+ depth errors",
            SynthViewsParams {
                depth_noise: d.depth_noise,
                depth_scale_jitter: d.depth_scale_jitter,
                depth_offset_jitter_m: d.depth_offset_jitter_m,
                depth_warp: d.depth_warp,
                depth_far_m: d.depth_far_m,
                depth_edge_px: d.depth_edge_px,
                ..xy.clone()
            },
        ),
        (
            "+ normal errors",
            SynthViewsParams {
                normal_noise_deg: d.normal_noise_deg,
                normal_edge_px: d.normal_edge_px,
                ..xy.clone()
            },
        ),
        (
            "+ mask boundaries",
            SynthViewsParams {
                instance_boundary_px: d.instance_boundary_px,
                ..xy.clone()
            },
        ),
        (
            "+ missed instances",
            SynthViewsParams {
                instance_miss: d.instance_miss,
                ..xy.clone()
            },
        ),
        (
            "+ merged, spurious, confused",
            SynthViewsParams {
                instance_merge: d.instance_merge,
                instance_spurious: d.instance_spurious,
                class_confusion: d.class_confusion,
                ..xy.clone()
            },
        ),
        ("all (the demo knobs)", demo_views()),
    ];
    let p = ReliefParams::default();
    for (k, (name, v)) in rows.into_iter().enumerate() {
        let s = make_site(v);
        let views = if k == 0 {
            s.views.clone()
        } else {
            register_views(&s.views, &s.walls)
        };
        let sc = score(&s, &run_relief(&s, &views, None, &p), &p);
        let f = |c: &str| format!("{c} {:.2}/{:.2}", sc.recall(c), sc.precision(c));
        println!(
            "{name:32} {} {} {} {} depth {:.3} m",
            f("window"),
            f("door"),
            f("balcony"),
            f("drainpipe"),
            sc.median_depth_error()
        );
    }
}
