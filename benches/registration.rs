//! RegisterViews on a development set: how far the registered views stand from where they were
//! taken, and how long the search takes. The development set is five synthetic sites of their
//! own seeds (none of them the relief tests' site, whose figures BENCHMARKS.md reports), with
//! the demo's views (320 x 240 every 15 m, 0.5 m and 1 degree of pose noise, every other sensor
//! error at SynthViews' defaults), registered against their true wall prisms as the relief
//! tests register theirs. Changes to the search are judged here first.
//!
//! `cargo bench --bench registration -- [SEEDS...]` (default 21 to 25). Prints per site and in
//! all: views with a building, median and 90th percentile position error and median heading
//! error (metadata -> registered), seconds.

use std::time::Instant;

use kodama_nodes::artifact::{Pose, TerrainModel, ViewSet};
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::street::register_views::RegisterViews;
use kodama_nodes::street::registration::RegistrationParams;
use kodama_nodes::synth::synth_city::{SynthCityParams, generate};
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::synth::truth_scene::{TruthScene, TruthSceneParams, wall_prisms};
use kodama_nodes::{Artifact, Ctx, Inputs, Site, Stage};

fn slot(a: Artifact) -> Slot {
    Slot::One(std::sync::Arc::new(a))
}

/// The views' knobs, with or without their pose errors (every other error kept).
fn views_params(seed: u64, noisy: bool) -> SynthViewsParams {
    let p = SynthViewsParams {
        seed,
        size: (320, 240),
        spacing_m: 15.0,
        max_views: 96,
        pose_noise_m: 0.5,
        heading_noise_deg: 1.0,
        depth_scale: 0.8,
        depth_offset_m: 1.0,
        ..Default::default()
    };
    if noisy { p } else { p.with_true_poses() }
}

fn heading(p: &Pose) -> f64 {
    p.rotation[1][2].atan2(p.rotation[0][2])
}

/// The camera's pitch, radians: its forward axis's elevation.
fn pitch(p: &Pose) -> f64 {
    p.rotation[2][2].clamp(-1.0, 1.0).asin()
}

/// How far `a` stands from `b`: plan position m, heading degrees, height m, pitch degrees.
fn off(a: &Pose, b: &Pose) -> [f64; 4] {
    let d = (heading(a) - heading(b)).to_degrees();
    let d = (d + 180.0).rem_euclid(360.0) - 180.0;
    [
        (a.position[0] - b.position[0]).hypot(a.position[1] - b.position[1]),
        d.abs(),
        (a.position[2] - b.position[2]).abs(),
        (pitch(a) - pitch(b)).to_degrees().abs(),
    ]
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Errors before and after (see [`off`]) of every view that shows a building, and the
/// registration's seconds.
fn site_errors(seed: u64, ctx: &Ctx) -> (Vec<Errors>, f64) {
    let city = generate(&SynthCityParams {
        seed,
        size_m: (300.0, 200.0),
        blocks: (3, 2),
        terrain: TerrainModel {
            seed,
            size_m: (300.0, 200.0),
            relief_m: 2.0,
            ..Default::default()
        },
        ..Default::default()
    });
    let truth = TruthScene::run(
        &TruthSceneParams::default(),
        &Inputs::new().with("city", slot(Artifact::City(city.clone()))),
        ctx,
    )
    .expect("truth scene");
    let walls = wall_prisms(&city, &truth).expect("truth footprints extrude");
    let render = |noisy: bool| -> ViewSet {
        SynthViews::run(
            &views_params(seed, noisy),
            &Inputs::new()
                .with("scene", slot(Artifact::Scene(truth.clone())))
                .with("city", slot(Artifact::City(city.clone()))),
            ctx,
        )
        .expect("views")
    };
    let (noisy, taken) = (render(true), render(false));
    let t = Instant::now();
    let registered = RegisterViews::run(
        &RegistrationParams::default(),
        &Inputs::new()
            .with("views", slot(Artifact::Views(noisy.clone())))
            .with("scene", slot(Artifact::Scene(walls))),
        ctx,
    )
    .expect("registration");
    let secs = t.elapsed().as_secs_f64();
    let errors = noisy
        .views
        .iter()
        .zip(&registered.views)
        .zip(&taken.views)
        .filter(|((_, r), _)| {
            !r.pose_source
                .as_deref()
                .is_some_and(|s| s.contains("no building labelled"))
        })
        .map(|((n, r), t)| {
            assert_eq!(n.id, t.id, "the two renderings number their views alike");
            Errors {
                before: off(&n.pose, &t.pose),
                after: off(&r.pose, &t.pose),
            }
        })
        .collect();
    (errors, secs)
}

/// One view's errors against where it was taken, from its metadata and after registration.
struct Errors {
    before: [f64; 4],
    after: [f64; 4],
}

fn summary(label: &str, e: &[Errors], secs: f64) {
    let col = |k: usize, after: bool| -> Vec<f64> {
        e.iter()
            .map(|r| if after { r.after[k] } else { r.before[k] })
            .collect::<Vec<f64>>()
    };
    let q = |k: usize, after: bool, at: f64| quantile(&mut col(k, after), at);
    println!(
        "{label:>8} {:>5} views  position median {:.3} -> {:.3} m, p90 {:.3} -> {:.3} m; heading median {:.2} -> {:.2} deg; height median {:.3} -> {:.3} m; pitch median {:.2} -> {:.2} deg; {secs:.1} s",
        e.len(),
        q(0, false, 0.5),
        q(0, true, 0.5),
        q(0, false, 0.9),
        q(0, true, 0.9),
        q(1, false, 0.5),
        q(1, true, 0.5),
        q(2, false, 0.5),
        q(2, true, 0.5),
        q(3, false, 0.5),
        q(3, true, 0.5),
    );
}

fn main() {
    let seeds: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let seeds = if seeds.is_empty() {
        vec![21, 22, 23, 24, 25]
    } else {
        seeds
    };
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let ctx = Ctx::new(&site, &[]);
    println!(
        "RegisterViews, development set; {} threads",
        rayon::current_num_threads()
    );
    let (mut all, mut total) = (Vec::new(), 0.0);
    for seed in seeds {
        let (e, secs) = site_errors(seed, &ctx);
        summary(&format!("seed {seed}"), &e, secs);
        all.extend(e);
        total += secs;
    }
    summary("all", &all, total);
}
