//! Stages with side outputs (reports): a report is made by its node's one run, cached under the
//! node's key, named in graphs as `"node.report"`, planned by `explain` and exported like any
//! output. The carve's outcomes come from the carve itself, not from a second carve.

mod common;
use common::*;

const GRAPH: &str = r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    nodes: {
        "city":     SynthCity(seed: 3, size_m: (120.0, 90.0), blocks: (1, 1)),
        "truth":    TruthScene(city: "city"),
        "views":    SynthViews(scene: "truth", city: "city", size: (96, 72), spacing_m: 20.0, max_views: 8),
        "charts":   SurfaceCharts(scene: "truth", wall_texel_m: 0.2, roof_texel_m: 0.5),
        "relief":   Relief(views: "views", scene: "truth", charts: "charts"),
        "carved":   CarveRelief(scene: "truth", charts: "charts", relief: "relief"),
    },
    outputs: {
        "outcomes": "carved.outcomes",
    },
)
"#;

fn graph() -> String {
    GRAPH.to_string()
}

#[test]
fn a_report_comes_from_its_node_s_run_and_its_cache_entry() {
    let env = Env::new();
    let g = env.write("carve.ron", &graph());
    let first = env.run(&g, &[]).ok();
    assert_eq!(first.status("carved"), "ran", "{:?}", first.statuses());
    assert_eq!(first.status("carved.outcomes"), "ran");
    assert_eq!(first.reason("carved.outcomes"), "report of \"carved\"");
    assert_eq!(
        first.node("carved.outcomes")["kind"],
        "CarveRelief.outcomes"
    );
    // The export is the carve's metrics: what it carved and dropped.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(env.out().join("outcomes.json")).unwrap())
            .unwrap();
    let text = json.to_string();
    assert!(text.contains("carved"), "{text}");
    let digest = first.digests()["carved.outcomes"].clone();

    // Again: both from the cache, nothing runs.
    let again = env.run(&g, &[]).ok();
    assert_eq!(again.status("carved"), "cached", "{:?}", again.statuses());
    assert_eq!(again.status("carved.outcomes"), "cached");
    assert_eq!(again.digests()["carved.outcomes"], digest);

    // explain plans the report with its node.
    let plan = env.cli(&[
        "explain",
        g.to_str().unwrap(),
        "--cache",
        env.cache().to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(plan.code, 0, "{}", plan.stderr);
    assert!(
        plan.stdout.contains("carved.outcomes") && plan.stdout.contains("report of"),
        "{}",
        plan.stdout
    );

    // The report's blob lost: the carve runs again and makes the same report.
    std::fs::remove_file(env.blob(&digest)).unwrap();
    let healed = env.run(&g, &[]).ok();
    assert_eq!(healed.status("carved"), "ran", "{:?}", healed.statuses());
    assert_eq!(healed.digests()["carved.outcomes"], digest);
    assert!(env.blob(&digest).exists());
}

/// A report that the node does not make, or a report of a node that makes none, is a graph
/// error with the place and the node ids there are; a report given as an input is type-checked
/// as its kind declares it.
#[test]
fn an_unknown_report_is_a_graph_error() {
    let env = Env::new();
    for (bad, what) in [
        ("carved.outcome", "carved.outcome"),
        ("charts.outcomes", "charts.outcomes"),
    ] {
        let g = env.write(
            "bad.ron",
            &graph().replace(
                "\"outcomes\": \"carved.outcomes\"",
                &format!("\"outcomes\": \"{bad}\""),
            ),
        );
        let r = env.run(&g, &[]);
        assert_eq!(r.code, 2, "{bad}: {}", r.stderr);
        assert!(r.stderr.contains(what), "{bad}: {}", r.stderr);
        assert!(
            r.stderr.contains("did you mean `carved.outcomes`"),
            "{bad}: {}",
            r.stderr
        );
    }
}

#[test]
fn a_report_as_an_input_is_type_checked() {
    let env = Env::new();
    let g = env.write(
        "typed.ron",
        &graph().replace(
            "    },\n    outputs",
            "        \"stats\":    RasterStats(raster: \"carved.outcomes\"),\n    },\n    outputs",
        ),
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("\"carved.outcomes\" (CarveRelief.outcomes) produces Metrics"),
        "{}",
        r.stderr
    );
}
