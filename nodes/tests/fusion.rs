//! Exposure-weighted multi-view fusion (eq. (2)-(3)) on the synthetic site, scored against the
//! city's truth: the synthetic views' architectural labels fused onto charts of the true walls
//! must reproduce each texel's true façade label (window, door, balcony, drainpipe or wall).
//!
//! The charts are made on the buildings' true outlines extruded to the eave (the walls the views
//! look at, without the relief the views' labels describe), so what is scored is the operator,
//! not the building reconstruction.

mod common;
use common::*;

use kodama_nodes::artifact::{ChartKind, ChartSet, City, TexelLayers, ViewSet};
use kodama_nodes::stages::street::fuse_views::{FuseViews, FuseViewsParams};
use kodama_nodes::stages::street::surface_charts::{SurfaceCharts, SurfaceChartsParams};
use kodama_nodes::synth::synth_city::generate;
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::synth::truth_scene::wall_prisms;
use kodama_nodes::{Artifact, Ctx, Inputs, Stage};

struct Fused {
    city: City,
    charts: ChartSet,
    layers: TexelLayers,
}

fn fuse(views: SynthViewsParams) -> Fused {
    let city = generate(&small_city());
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
    let layers = FuseViews::run(
        &FuseViewsParams::default(),
        &Inputs::new()
            .with("views", slot(Artifact::Views(set)))
            .with("scene", slot(Artifact::Scene(walls)))
            .with("charts", slot(Artifact::Charts(charts.clone()))),
        &ctx,
    )
    .unwrap();
    Fused {
        city,
        charts,
        layers,
    }
}

/// Perfect views: every error knob off (SynthViews' defaults are the honest sensors).
fn perfect() -> SynthViewsParams {
    SynthViewsParams {
        size: (320, 240),
        spacing_m: 15.0,
        max_views: 80,
        ..SynthViewsParams::exact()
    }
}

/// Scores: (share of façade texels observed, share of observed façade texels whose fused label
/// is the true one, observed texels).
fn score(f: &Fused) -> (f64, f64, usize) {
    let (mut facade, mut observed, mut right) = (0usize, 0usize, 0usize);
    let mut confusion = std::collections::BTreeMap::new();
    for (c, l) in f.charts.charts.iter().zip(&f.layers.charts) {
        if c.kind != ChartKind::Wall {
            continue;
        }
        let b = f
            .city
            .buildings
            .iter()
            .find(|b| b.id == c.building)
            .unwrap();
        for j in 0..c.height {
            for i in 0..c.width {
                let k = (j * c.width + i) as usize;
                if c.triangle_at[k] == u32::MAX {
                    continue;
                }
                facade += 1;
                if l.w_exp[k] <= 0.0 {
                    continue;
                }
                let Some(won) = l.winner(k) else { continue };
                observed += 1;
                let truth = match b.feature_at(c.texel_center(i, j), 1e-3) {
                    Some(n) => format!("{:?}", b.features[n].kind).to_lowercase(),
                    None => "wall".to_owned(),
                };
                let got = &f.layers.classes[won as usize];
                *confusion
                    .entry((truth.clone(), got.clone()))
                    .or_insert(0usize) += 1;
                if *got == truth {
                    right += 1;
                }
            }
        }
    }
    println!("confusion (truth, fused): {confusion:?}");
    (
        observed as f64 / facade as f64,
        right as f64 / observed as f64,
        observed,
    )
}

/// The perfect views fused once, shared by the tests that read them.
fn perfect_fused() -> &'static Fused {
    static F: std::sync::OnceLock<Fused> = std::sync::OnceLock::new();
    F.get_or_init(|| fuse(perfect()))
}

#[test]
fn perfect_views_reproduce_the_true_facade_labels() {
    let f = perfect_fused();
    // Every texel a ray landed in has exposure.
    for (c, l) in f.charts.charts.iter().zip(&f.layers.charts) {
        for k in 0..c.len() {
            if c.triangle_at[k] != u32::MAX && l.hits[k] > 0 {
                assert!(
                    l.w_exp[k] > 0.0,
                    "{} texel {k}: hit but no exposure",
                    c.building
                );
            }
        }
    }
    let (seen, accuracy, n) = score(f);
    println!(
        "perfect views: {:.1} % of facade texels observed ({n}), labels right at {:.2} %",
        100.0 * seen,
        100.0 * accuracy
    );
    assert!(n > 10_000, "only {n} texels observed");
    assert!(accuracy >= 0.95, "fused labels right at {:.3}", accuracy);
    let s = f.layers.stats;
    assert!(s.accepted > 0 && s.accepted <= s.chart_hits && s.chart_hits <= s.rays);
}

#[test]
fn pose_noise_costs_label_accuracy_and_is_measured() {
    let f = fuse(SynthViewsParams {
        pose_noise_m: 1.0,
        heading_noise_deg: 2.0,
        ..perfect()
    });
    let (seen, accuracy, _) = score(&f);
    println!(
        "pose noise 1 m, 2 deg: {:.1} % observed, labels right at {:.2} %",
        100.0 * seen,
        100.0 * accuracy
    );
    // Noise blurs boundaries; most of a façade is plain wall or window interior and stays right.
    assert!(accuracy > 0.6 && accuracy < 0.99, "{accuracy}");
}

#[test]
fn fusion_is_the_same_at_any_thread_count() {
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                fuse(SynthViewsParams {
                    max_views: 12,
                    size: (160, 120),
                    ..perfect()
                })
                .layers
            })
    };
    assert!(run(1) == run(3));
}

/// The draped glb, read back with the `gltf` crate: one quad per chart, lifted off its surface,
/// and at every labelled texel's centre the texture shows the colour the glb's own legend gives
/// that texel's winning class.
#[test]
fn the_draped_glb_shows_each_texel_where_it_lies() {
    let f = perfect_fused();
    let bytes = kodama_nodes::io::export::write_chart_glb(&f.layers).unwrap();
    let (doc, buffers, images) = gltf::import_slice(&bytes).unwrap();
    let json: serde_json::Value =
        serde_json::from_slice(&gltf::Glb::from_slice(&bytes).unwrap().json).unwrap();
    let variants: Vec<&str> = json["extensions"]["KHR_materials_variants"]["variants"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["name"].as_str().unwrap())
        .collect();
    assert_eq!(variants, ["label", "exposure", "hits"]);
    let legend: Vec<[u8; 3]> = json["materials"][0]["extras"]["legend"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| serde_json::from_value(e["colour"].clone()).unwrap())
        .collect();
    assert_eq!(legend.len(), f.layers.classes.len());

    let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|b| Some(&buffers[b.index()]));
    let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    let uv: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
    let img = &images[0];
    assert_eq!(img.format, gltf::image::Format::R8G8B8A8);
    let colour_at = |t: [f64; 2]| {
        let (x, y) = (
            (t[0] * img.width as f64) as usize,
            (t[1] * img.height as f64) as usize,
        );
        let k = 4 * (y * img.width as usize + x);
        [img.pixels[k], img.pixels[k + 1], img.pixels[k + 2]]
    };
    let nonempty: Vec<usize> = (0..f.charts.charts.len())
        .filter(|&c| !f.charts.charts[c].is_empty())
        .collect();
    assert_eq!(pos.len(), 4 * nonempty.len(), "one quad per chart");
    let (mut checked, mut wrong) = (0usize, 0usize);
    for (q, &ci) in nonempty.iter().enumerate() {
        let (c, l) = (&f.charts.charts[ci], &f.layers.charts[ci]);
        // Corner 0 is texel coordinate (0, 0), lifted 2 cm along the normal, in glTF's y-up.
        let o = c.world_of(0.0, 0.0);
        let lifted: [f64; 3] = std::array::from_fn(|k| o[k] + 0.02 * c.normal[k]);
        let want = [lifted[0], lifted[2], -lifted[1]];
        for k in 0..3 {
            assert!(
                (pos[4 * q][k] as f64 - want[k]).abs() < 1e-3,
                "chart {ci} corner"
            );
        }
        let (t0, t1, t3) = (uv[4 * q], uv[4 * q + 1], uv[4 * q + 3]);
        for j in (0..c.height).step_by(3) {
            for i in (0..c.width).step_by(3) {
                let k = (j * c.width + i) as usize;
                let Some(won) = l.winner(k) else { continue };
                let (a, b) = (
                    (i as f64 + 0.5) / c.width as f64,
                    (j as f64 + 0.5) / c.height as f64,
                );
                let t = [0, 1].map(|d| {
                    t0[d] as f64 + a * (t1[d] - t0[d]) as f64 + b * (t3[d] - t0[d]) as f64
                });
                checked += 1;
                if colour_at(t) != legend[won as usize] {
                    wrong += 1;
                }
            }
        }
    }
    assert!(checked > 1000, "only {checked} labelled texels checked");
    assert_eq!(
        wrong, 0,
        "{wrong} of {checked} texels show another class's colour"
    );
}
