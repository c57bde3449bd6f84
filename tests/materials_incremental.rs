//! The card's promise for materials (issue 14): changing one class weight reruns exactly the
//! material fusion node and what depends on it; the views, charts and scene come from the cache.

mod common;
use common::*;

const GRAPH: &str = r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    nodes: {
        "city":      SynthCity(seed: 3, size_m: (120.0, 90.0), blocks: (1, 1)),
        "truth":     TruthScene(city: "city"),
        "views":     SynthViews(scene: "truth", city: "city", size: (96, 72), spacing_m: 20.0, max_views: 8),
        "charts":    SurfaceCharts(scene: "truth", wall_texel_m: 0.2, roof_texel_m: 0.5),
        "materials": FuseMaterials(views: "views", scene: "truth", charts: "charts", weights: {"glass": 1.2}),
        "twin":      ApplyMaterials(scene: "truth", charts: "charts", materials: "materials"),
        "dsm":       RasterizeScene(scene: "truth"),
    },
    outputs: {
        "materials": "materials",
        "twin.sionna": "twin",
    },
)
"#;

#[test]
fn a_material_weight_reruns_only_the_material_nodes() {
    let env = Env::new();
    let g = env.write("materials.ron", GRAPH);
    let first = env.run(&g, &[]).ok();
    assert_eq!(first.with_status("ran").len(), 7, "{:?}", first.statuses());
    let r = env.run(&g, &["--set", "materials.weights.glass=2.0"]).ok();
    assert_eq!(r.status("materials"), "ran", "{:?}", r.statuses());
    assert!(
        ["ran", "cutoff"].contains(&r.status("twin").as_str()),
        "{:?}",
        r.statuses()
    );
    assert_eq!(
        r.with_status("cached"),
        ids(&["charts", "city", "dsm", "truth", "views"]),
        "{:?}",
        r.statuses()
    );
    // Back to the graph as written: all from the cache.
    let back = env.run(&g, &[]).ok();
    assert_eq!(back.with_status("cached").len(), 7, "{:?}", back.statuses());
    // The exports: the material atlas and a Sionna scene with one shape per building and
    // material, each material with its own slab thickness.
    assert!(env.out().join("materials/materials.json").exists());
    let xml = std::fs::read_to_string(env.out().join("twin.sionna/scene.xml")).unwrap();
    assert!(xml.contains("value=\"0.2\""), "{xml}");
    assert!(xml.contains("mesh-building-0-itu_"), "{xml}");
}

/// The same promise on the demo itself, as the card states it: `kodama-dag run graphs/demo.ron
/// --set materials.weights.glass=2.0` reruns the material fusion and what depends on it; the
/// views, charts, relief, solids and clutter come from the cache.
#[test]
fn the_demo_reruns_only_the_material_nodes_for_a_glass_weight() {
    let env = Env::new();
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/demo.ron");
    // The demo's first 64 views (of 416) keep the test quick; what reruns does not depend on
    // how many there are.
    let few = ["--set", "views.max_views=64"];
    env.run(&demo, &[&["--target", "twin"][..], &few].concat())
        .ok();
    let r = env
        .run(
            &demo,
            &[
                &["--target", "twin", "--set", "materials.weights.glass=2.0"][..],
                &few,
            ]
            .concat(),
        )
        .ok();
    assert_eq!(r.status("materials"), "ran", "{:?}", r.statuses());
    for id in ["painted", "carved", "twin"] {
        assert!(
            ["ran", "cutoff"].contains(&r.status(id).as_str()),
            "{id}: {:?}",
            r.statuses()
        );
    }
    for id in [
        "views", "charts", "relief", "solids", "scene", "clutter", "canopies", "lidar",
    ] {
        assert_eq!(r.status(id), "cached", "{id}: {:?}", r.statuses());
    }
}
