//! Exposure-weighted fusion throughput (eq. (2)-(3)): views/s and pixel rays/s fusing synthetic
//! street views of the demo city onto the charts of its true walls.
//!
//! `cargo bench --bench fusion -- [VIEWS...]` (default 16 100 1000). Figures go in BENCHMARKS.md.

use std::time::Instant;

use kodama_nodes::artifact::ViewSet;
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::street::fuse_views::{FuseViews, FuseViewsParams};
use kodama_nodes::stages::street::surface_charts::{SurfaceCharts, SurfaceChartsParams};
use kodama_nodes::synth::synth_city::{SynthCityParams, generate};
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::synth::truth_scene::{TruthScene, TruthSceneParams, wall_prisms};
use kodama_nodes::{Artifact, Ctx, Inputs, Site, Stage};

fn slot(a: Artifact) -> Slot {
    Slot::One(std::sync::Arc::new(a))
}

fn main() {
    let counts: Vec<u32> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let counts = if counts.is_empty() {
        vec![16, 100, 1000]
    } else {
        counts
    };
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let ctx = Ctx::new(&site, &[]);
    let city = generate(&SynthCityParams::default());
    let truth = TruthScene::run(
        &TruthSceneParams::default(),
        &Inputs::new().with("city", slot(Artifact::City(city.clone()))),
        &ctx,
    )
    .expect("truth scene");
    let scene = wall_prisms(&city, &truth).expect("truth footprints extrude");
    let charts = SurfaceCharts::run(
        &SurfaceChartsParams::default(),
        &Inputs::new().with("scene", slot(Artifact::Scene(scene.clone()))),
        &ctx,
    )
    .expect("charts");
    let texels: usize = charts.charts.iter().map(|c| c.len()).sum();
    println!(
        "demo city: {} charts, {texels} texels; {} threads",
        charts.charts.len(),
        rayon::current_num_threads()
    );
    for n in counts {
        let views: ViewSet = SynthViews::run(
            &SynthViewsParams {
                size: (480, 360),
                spacing_m: 4.0,
                max_views: n,
                ..Default::default()
            },
            &Inputs::new()
                .with("scene", slot(Artifact::Scene(truth.clone())))
                .with("city", slot(Artifact::City(city.clone()))),
            &ctx,
        )
        .expect("views");
        let got = views.views.len();
        let inputs = Inputs::new()
            .with("views", slot(Artifact::Views(views)))
            .with("scene", slot(Artifact::Scene(scene.clone())))
            .with("charts", slot(Artifact::Charts(charts.clone())));
        let t = Instant::now();
        let out = FuseViews::run(&FuseViewsParams::default(), &inputs, &ctx).expect("fusion");
        let s = t.elapsed().as_secs_f64();
        println!(
            "{got} views of 480 x 360: {s:.2} s, {:.1} views/s, {:.2} M rays/s, {:.2} M chart hits/s",
            got as f64 / s,
            out.stats.rays as f64 / s / 1e6,
            out.stats.chart_hits as f64 / s / 1e6
        );
    }
}
