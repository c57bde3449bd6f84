//! Per-surface ITU-R P.2040 materials (paper Sec. 4.2.3, eq. (5)) on the synthetic site, scored
//! against the city's truth: the synthetic views' material maps (with the demo's label noise and
//! pose errors) fused onto charts of the true walls must give each façade texel its true material
//! (glass in windows, wood in doors, metal drainpipes and railings, the façade's material
//! elsewhere), and the materials applied to the scene must leave every building a checked solid.
//!
//! As in tests/fusion.rs, the charts are made on the buildings' true outlines extruded to the eave,
//! so what is scored is the material fusion, not the building reconstruction.
//!
//! Run with `--nocapture` for the confusion matrices.

mod common;
use common::*;

use std::collections::BTreeMap;

use kodama_nodes::artifact::Material;
use kodama_nodes::artifact::{
    ChartKind, ChartSet, City, FeatureKind, MaterialLayers, MaterialSource, Scene, ViewSet,
};
use kodama_nodes::geom::mesh_check::check_solid;
use kodama_nodes::stages::street::apply_materials::{ApplyMaterials, ApplyMaterialsParams};
use kodama_nodes::stages::street::fuse_materials::{FuseMaterials, FuseMaterialsParams};
use kodama_nodes::stages::street::surface_charts::{SurfaceCharts, SurfaceChartsParams};
use kodama_nodes::synth::synth_city::generate;
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::synth::truth_scene::wall_prisms;
use kodama_nodes::{Artifact, Ctx, Inputs, Stage};

struct Site {
    city: City,
    walls: Scene,
    charts: ChartSet,
    views: ViewSet,
}

/// The demo's view params (graphs/demo.ron "views": label noise at SynthViews' default 5 %,
/// 10 % of instances missed, 0.5 m and 1 degree pose noise), on the small city.
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

/// The demo's label noise (5 % of (view, object) pairs reported as a random class, 10 % of
/// instances missed) with the views' true poses.
fn label_noise() -> SynthViewsParams {
    demo_views().with_true_poses()
}

fn site(views: SynthViewsParams) -> Site {
    let city = generate(&small_city());
    let truth = scene_of(&city);
    let s = common::site();
    let ctx = Ctx::new(&s, &[]);
    let views: ViewSet = SynthViews::run(
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
        charts,
        views,
    }
}

fn fuse(s: &Site, p: &FuseMaterialsParams) -> MaterialLayers {
    let site = common::site();
    let ctx = Ctx::new(&site, &[]);
    FuseMaterials::run(
        p,
        &Inputs::new()
            .with("views", slot(Artifact::Views(s.views.clone())))
            .with("scene", slot(Artifact::Scene(s.walls.clone())))
            .with("charts", slot(Artifact::Charts(s.charts.clone()))),
        &ctx,
    )
    .unwrap()
}

/// The true material at a façade texel centre: what the truth scene shows there from the street.
fn truth_at(city: &City, building: &str, p: [f64; 3]) -> Material {
    let b = city.buildings.iter().find(|b| b.id == building).unwrap();
    match b.feature_at(p, 1e-3).map(|k| &b.features[k]) {
        Some(f) => match f.kind {
            FeatureKind::Window => Material::Glass,
            FeatureKind::Door => Material::Wood,
            FeatureKind::Drainpipe => Material::Metal,
            // The slab's edge, then the railing in front of the wall.
            FeatureKind::Balcony if p[2] < f.z.0 + 0.15 => Material::Concrete,
            FeatureKind::Balcony => Material::Metal,
        },
        None => b.facade,
    }
}

fn name(m: u8) -> &'static str {
    Material::from_u8(m)
        .and_then(|m| m.itu_type())
        .unwrap_or("?")
}

struct Score {
    observed: (usize, usize),
    all: (usize, usize),
    facade: usize,
    confusion: BTreeMap<(u8, u8), usize>,
}

impl Score {
    fn observed(&self) -> f64 {
        self.observed.1 as f64 / self.observed.0.max(1) as f64
    }
    fn all(&self) -> f64 {
        self.all.1 as f64 / self.all.0.max(1) as f64
    }
}

/// Accuracy over observed façade texels and over every façade texel, and the confusion matrix
/// (truth, chosen) over every façade texel.
fn score(s: &Site, m: &MaterialLayers) -> Score {
    score_where(s, m, false)
}

fn score_where(s: &Site, m: &MaterialLayers, observed_only: bool) -> Score {
    let mut out = Score {
        observed: (0, 0),
        all: (0, 0),
        facade: 0,
        confusion: BTreeMap::new(),
    };
    for (c, cm) in s.charts.charts.iter().zip(&m.charts) {
        if c.kind != ChartKind::Wall {
            continue;
        }
        for j in 0..c.height {
            for i in 0..c.width {
                let k = (j * c.width + i) as usize;
                if c.triangle_at[k] == u32::MAX {
                    continue;
                }
                out.facade += 1;
                let truth = truth_at(&s.city, &c.building, c.texel_center(i, j)) as u8;
                let got = cm.material[k];
                let right = (got == truth) as usize;
                out.all.0 += 1;
                out.all.1 += right;
                if cm.source[k] == MaterialSource::Observed as u8 {
                    out.observed.0 += 1;
                    out.observed.1 += right;
                }
                if !observed_only || cm.source[k] == MaterialSource::Observed as u8 {
                    *out.confusion.entry((truth, got)).or_insert(0) += 1;
                }
            }
        }
    }
    out
}

fn print_confusion(title: &str, c: &BTreeMap<(u8, u8), usize>) {
    let mut classes: Vec<u8> = c.keys().flat_map(|&(a, b)| [a, b]).collect();
    classes.sort();
    classes.dedup();
    println!("{title} (rows truth, columns fused; texels)");
    print!("{:>12}", "");
    for &g in &classes {
        print!("{:>10}", name(g));
    }
    println!();
    for &t in &classes {
        print!("{:>12}", name(t));
        for &g in &classes {
            print!("{:>10}", c.get(&(t, g)).copied().unwrap_or(0));
        }
        println!();
    }
}

#[test]
fn noisy_labels_give_the_true_facade_materials() {
    let s = site(label_noise());
    let t0 = std::time::Instant::now();
    let m = fuse(&s, &FuseMaterialsParams::default());
    let fuse_s = t0.elapsed().as_secs_f64();
    let sc = score(&s, &m);
    print_confusion("all façade texels, after extension", &sc.confusion);
    println!(
        "{} views, {} façade texels: {:.1} % observed, accuracy {:.2} % over observed, {:.2} % over all after extension (fusion {fuse_s:.2} s)",
        s.views.views.len(),
        sc.facade,
        100.0 * sc.observed.0 as f64 / sc.facade as f64,
        100.0 * sc.observed(),
        100.0 * sc.all()
    );
    println!(
        "sources: {:?}; refined {} pixels in {} instances; masked rays {}",
        m.stats.by_source, m.stats.refined_pixels, m.stats.refined_instances, m.stats.masked_rays
    );
    assert!(sc.observed.0 > 100_000, "only {} observed", sc.observed.0);
    assert!(
        sc.observed() >= 0.90,
        "observed façade texels right at {:.3}",
        sc.observed()
    );
    assert!(
        sc.all() >= 0.80,
        "all façade texels right at {:.3}",
        sc.all()
    );
    // Every surface texel has a material and a source; W_exp and hits are kept.
    for (c, cm) in s.charts.charts.iter().zip(&m.charts) {
        for k in 0..c.len() {
            let on = c.triangle_at[k] != u32::MAX;
            assert_eq!(on, cm.source[k] != MaterialSource::Off as u8);
            assert_eq!(on, Material::from_u8(cm.material[k]).is_some());
        }
    }
    assert!(m.stats.refined_pixels > 0 && m.stats.masked_rays > 0);

    // Without extension only the observed texels are right (the rest take the default).
    let plain = fuse(
        &s,
        &FuseMaterialsParams {
            extend: false,
            ..Default::default()
        },
    );
    let sp = score(&s, &plain);
    println!(
        "extension off: {:.2} % over all façade texels",
        100.0 * sp.all()
    );
    assert_eq!(sp.observed, sc.observed);
    assert!(sp.all() < sc.all());
}

/// The demo's views as they are, pose errors too (0.5 m, 1 degree): window boundaries move by
/// a good part of a window per view. Measured, with floors below what was measured.
#[test]
fn pose_errors_cost_material_accuracy_and_are_measured() {
    let raw = site(demo_views());
    let m = fuse(&raw, &FuseMaterialsParams::default());
    let sc = score(&raw, &m);
    print_confusion(
        "demo views with pose errors, all façade texels",
        &sc.confusion,
    );
    println!(
        "demo views with pose errors: {:.1} % observed, accuracy {:.2} % over observed, {:.2} % over all",
        100.0 * sc.observed.0 as f64 / sc.facade as f64,
        100.0 * sc.observed(),
        100.0 * sc.all()
    );
    // 0.78 with the near-oracle views; 0.769 / 0.777 with the sensors of issue 51.
    assert!(
        sc.observed() >= 0.75 && sc.all() >= 0.75,
        "{} {}",
        sc.observed(),
        sc.all()
    );
    // The same views registered against the walls first, as the demo graph does.
    let views = register_views(&raw.views, &raw.walls);
    let reg = Site { views, ..raw };
    let sr = score(&reg, &fuse(&reg, &FuseMaterialsParams::default()));
    println!(
        "demo views registered: {:.1} % observed, accuracy {:.2} % over observed, {:.2} % over all",
        100.0 * sr.observed.0 as f64 / sr.facade as f64,
        100.0 * sr.observed(),
        100.0 * sr.all()
    );
    assert!(
        sr.observed() > sc.observed() + 0.01,
        "registration must help: {} against {}",
        sr.observed(),
        sc.observed()
    );
}

#[test]
fn refinement_and_clutter_masking_help() {
    let s = site(label_noise());
    let full = score(&s, &fuse(&s, &FuseMaterialsParams::default()));
    let bare = score(
        &s,
        &fuse(
            &s,
            &FuseMaterialsParams {
                refine: BTreeMap::new(),
                mask_clutter: false,
                ..Default::default()
            },
        ),
    );
    println!(
        "observed accuracy {:.2} % with refinement and masking, {:.2} % without",
        100.0 * full.observed(),
        100.0 * bare.observed()
    );
    assert!(full.observed() > bare.observed());
}

#[test]
fn the_glass_weight_moves_the_argmax() {
    let s = site(SynthViewsParams {
        max_views: 24,
        ..demo_views()
    });
    let base = fuse(&s, &FuseMaterialsParams::default());
    let heavy = fuse(
        &s,
        &FuseMaterialsParams {
            weights: BTreeMap::from([("glass".to_string(), 2.0)]),
            ..Default::default()
        },
    );
    let light = fuse(
        &s,
        &FuseMaterialsParams {
            weights: BTreeMap::from([("glass".to_string(), 0.5)]),
            ..Default::default()
        },
    );
    let glass = |m: &MaterialLayers| m.stats.by_material[Material::Glass as usize];
    println!(
        "glass texels: mu 0.5 {}, mu 1 {}, mu 2 {}",
        glass(&light),
        glass(&base),
        glass(&heavy)
    );
    assert!(glass(&light) < glass(&base) && glass(&base) < glass(&heavy));
    // The votes themselves do not depend on the weights: only the choice does.
    assert_eq!(base.fused, heavy.fused);
}

#[test]
fn applied_materials_keep_every_building_a_solid() {
    let s = site(label_noise());
    let m = fuse(&s, &FuseMaterialsParams::default());
    let site = common::site();
    let ctx = Ctx::new(&site, &[]);
    let t0 = std::time::Instant::now();
    let out = ApplyMaterials::run(
        &ApplyMaterialsParams::default(),
        &Inputs::new()
            .with("scene", slot(Artifact::Scene(s.walls.clone())))
            .with("charts", slot(Artifact::Charts(s.charts.clone())))
            .with("materials", slot(Artifact::Materials(m.clone()))),
        &ctx,
    )
    .unwrap();
    let apply_s = t0.elapsed().as_secs_f64();
    let (mut before, mut after) = (0, 0);
    let mut area: BTreeMap<u8, f64> = BTreeMap::new();
    for (o, b) in out.objects.iter().zip(&s.walls.objects) {
        before += b.mesh.len();
        after += o.mesh.len();
        if o.class != kodama_nodes::artifact::ObjectClass::Building {
            assert_eq!(o, b);
            continue;
        }
        check_solid(&o.mesh).unwrap_or_else(|e| panic!("{}: {e}", o.id));
        assert!((o.mesh.volume() - b.mesh.volume()).abs() < 1e-3 * b.mesh.volume().abs());
        for (t, &mat) in o.mesh.triangles.iter().zip(o.mesh.materials.iter()) {
            let [a, bb, c] = t.map(|i| o.mesh.positions[i as usize].map(f64::from));
            let (e1, e2) = (
                [bb[0] - a[0], bb[1] - a[1], bb[2] - a[2]],
                [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
            );
            let n = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            // Walls only: compare with the texel areas.
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if len > 0.0 && (n[2] / len).abs() < 0.5 {
                *area.entry(mat).or_insert(0.0) += len / 2.0;
            }
        }
    }
    // Wall area per material in the mesh against the texel map's.
    let mut texel_area: BTreeMap<u8, f64> = BTreeMap::new();
    for (c, cm) in s.charts.charts.iter().zip(&m.charts) {
        if c.kind == ChartKind::Wall {
            for &x in cm.material.iter().filter(|&&x| x != 255) {
                *texel_area.entry(x).or_insert(0.0) += c.texel_m * c.texel_m;
            }
        }
    }
    println!(
        "applied: {before} -> {after} triangles in {apply_s:.2} s; wall area by material (mesh vs texels, m²):"
    );
    for (mat, a) in &texel_area {
        let got = area.get(mat).copied().unwrap_or(0.0);
        println!("  {:>10} {got:10.1} {a:10.1}", name(*mat));
        if *a > 200.0 {
            assert!(
                (got - a).abs() < 0.15 * a,
                "{}: {got} m² in the mesh, {a} m² of texels",
                name(*mat)
            );
        }
    }
}

#[test]
fn material_fusion_is_the_same_at_any_thread_count() {
    let s = site(SynthViewsParams {
        max_views: 12,
        size: (160, 120),
        ..demo_views()
    });
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| fuse(&s, &FuseMaterialsParams::default()))
    };
    assert!(run(1) == run(2));
}

/// Every material the pipeline gives a surface on its own (each RMSNet class's target, the OSM
/// baseline's concrete, the clutter's metal and wood) has its permittivity and conductivity at
/// every carrier of the paper's sites (Painiitty 3.6, Brooklyn 6.75 and 16.95, Boulder 28 GHz)
/// without `extrapolate`: a site graph never stops in Trace on a material out of its range.
#[test]
fn every_assigned_material_is_defined_at_every_site_carrier() {
    use kodama_nodes::artifact::RMSNET_CLASSES;
    use kodama_nodes::street::materials::fusion::{PixelTarget, rmsnet_target};
    let mut assigned = vec![Material::Concrete, Material::Metal, Material::Wood];
    for class in RMSNET_CLASSES {
        if let Some(PixelTarget::Surface(m) | PixelTarget::Ground(m)) = rmsnet_target(class) {
            assigned.push(m);
        }
    }
    assigned.sort_by_key(|m| *m as u8);
    assigned.dedup();
    assert!(assigned.len() >= 9, "{assigned:?}");
    for f_ghz in [3.6, 6.75, 16.95, 28.0] {
        for m in &assigned {
            let (eps, sigma) = m
                .eps_sigma(f_ghz * 1e9, false)
                .unwrap_or_else(|e| panic!("{m:?} at {f_ghz} GHz: {e}"));
            assert!(eps >= 1.0 && sigma >= 0.0 && eps.is_finite() && sigma.is_finite());
        }
    }
}
