//! Incremental runs: what a second run, a `--set` and an unchanged output do, on the run record.

mod common;
use common::*;

#[test]
fn second_run_is_all_cached() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let first = env.run(&g, &[]).ok();
    assert_eq!(first.with_status("ran").len(), 8, "{:?}", first.statuses());
    let second = env.run(&g, &[]).ok();
    assert_eq!(
        second.with_status("cached").len(),
        8,
        "{:?}",
        second.statuses()
    );
    assert_eq!(first.digests(), second.digests());
    assert_eq!(second.reason("smooth"), "unchanged");
}

#[test]
fn set_reruns_exactly_the_node_and_its_descendants() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    env.run(&g, &[]).ok();
    let r = env.run(&g, &["--set", "smooth.sigma_m=3.0"]).ok();
    assert_eq!(r.with_status("ran"), ids(&["smooth", "resid", "stats"]));
    assert_eq!(
        r.with_status("cached"),
        ids(&["truth", "lidar", "dsm", "capped", "pstats"])
    );
    assert_eq!(r.reason("smooth"), "param `sigma_m`: 2.0 -> 3.0");
    assert_eq!(r.reason("resid"), "input `b` changed");
    // Going back to the graph as written finds everything in the cache.
    let back = env.run(&g, &[]).ok();
    assert_eq!(back.with_status("cached").len(), 8, "{:?}", back.statuses());
}

#[test]
fn unchanged_output_cuts_off_descendants() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let before = env.run(&g, &[]).ok();
    // No cell is above 1000 m, so raising the cap reproduces the same raster.
    let r = env.run(&g, &["--set", "capped.max=2000.0"]).ok();
    assert_eq!(r.with_status("ran"), ids(&["capped"]));
    assert_eq!(r.with_status("cutoff"), ids(&["smooth", "resid", "stats"]));
    assert_eq!(
        r.with_status("cached"),
        ids(&["truth", "lidar", "dsm", "pstats"])
    );
    assert_eq!(r.digests(), before.digests());
}

#[test]
fn editing_the_graph_file_is_a_change_like_set() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    env.run(&g, &[]).ok();
    env.write("chain.ron", &CHAIN.replace("mode: Max", "mode: Mean"));
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.status("dsm"), "ran");
    assert_eq!(r.reason("dsm"), "param `mode`: \"Max\" -> \"Mean\"");
    assert_eq!(r.with_status("cached"), ids(&["truth", "lidar", "pstats"]));
}

#[test]
fn explain_predicts_without_running() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    env.run(&g, &[]).ok();
    let e = env
        .cli(&[
            "explain",
            g.to_str().unwrap(),
            "--cache",
            env.cache().to_str().unwrap(),
            "--json",
            "--set",
            "smooth.sigma_m=5",
        ])
        .ok();
    let plan: std::collections::BTreeMap<String, (String, String)> = e.json()["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            (
                n["id"].as_str().unwrap().into(),
                (
                    n["plan"].as_str().unwrap().into(),
                    n["reason"].as_str().unwrap().into(),
                ),
            )
        })
        .collect();
    assert_eq!(
        plan["smooth"],
        ("run".into(), "param `sigma_m`: 2.0 -> 5.0".into())
    );
    assert_eq!(plan["resid"].0, "maybe");
    assert_eq!(plan["dsm"].0, "cached");
    // Nothing ran: the real run still has to run smooth.
    let r = env.run(&g, &["--set", "smooth.sigma_m=5"]).ok();
    assert_eq!(r.status("smooth"), "ran");
}

#[test]
fn target_runs_only_what_it_needs() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let r = env.run(&g, &["--target", "pstats"]).ok();
    assert_eq!(r.with_status("ran"), ids(&["truth", "lidar", "pstats"]));
    assert!(
        r.json()["outputs"].as_object().unwrap().is_empty(),
        "no output node was targeted"
    );
    let bad = env.run(&g, &["--target", "pstat"]);
    assert_eq!(bad.code, 2);
    assert!(
        bad.stderr.contains("did you mean `pstats`"),
        "{}",
        bad.stderr
    );
}

#[test]
fn identical_digests_at_one_and_two_threads() {
    let (a, b) = (Env::new(), Env::new());
    let ga = a.write("chain.ron", CHAIN);
    let gb = b.write("chain.ron", CHAIN);
    let one = a.run(&ga, &["--jobs", "1"]).ok();
    let two = b.run(&gb, &["--jobs", "2"]).ok();
    assert_eq!(one.digests(), two.digests());
    for f in ["dsm.tif", "stats.json"] {
        assert_eq!(
            std::fs::read(a.out().join(f)).unwrap(),
            std::fs::read(b.out().join(f)).unwrap(),
            "{f}"
        );
    }
}

#[test]
fn outputs_are_written_as_files() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let r = env.run(&g, &[]).ok();
    let outputs = r.json()["outputs"].clone();
    let tif = std::fs::read(outputs["dsm"].as_str().unwrap()).unwrap();
    assert_eq!(&tif[..4], b"II*\0", "a little-endian TIFF");
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(env.out().join("stats.json")).unwrap()).unwrap();
    assert_eq!(stats["cells"], 240.0 * 160.0);
}

#[test]
fn graph_renders_as_dot_and_mermaid() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let dot = env
        .cli(&["graph", g.to_str().unwrap(), "--format", "dot"])
        .ok()
        .stdout;
    assert!(dot.contains("\"capped\" -> \"smooth\";"), "{dot}");
    assert!(dot.contains("\"smooth\" -> \"resid\";"));
    assert_eq!(dot.matches(" -> ").count(), 8);
    let mermaid = env
        .cli(&["graph", g.to_str().unwrap(), "--format", "mermaid"])
        .ok()
        .stdout;
    assert!(mermaid.starts_with("flowchart LR"));
    assert_eq!(mermaid.matches(" --> ").count(), 8);
}

#[test]
fn unchanged_outputs_are_not_rewritten_but_edited_ones_are() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    env.run(&g, &[]).ok();
    let tif = env.out().join("dsm.tif");
    let mtime = || std::fs::metadata(&tif).unwrap().modified().unwrap();
    let first = mtime();
    std::thread::sleep(std::time::Duration::from_millis(20));
    env.run(&g, &[]).ok();
    assert_eq!(mtime(), first, "a no-op rerun leaves the output file alone");
    let original = std::fs::read(&tif).unwrap();
    std::fs::write(&tif, b"edited by hand").unwrap();
    let r = env.run(&g, &[]).ok();
    assert_eq!(
        std::fs::read(&tif).unwrap(),
        original,
        "an edited output is rewritten from the cache"
    );
    assert_eq!(
        r.json()["outputs"]["dsm"].as_str().unwrap(),
        tif.to_str().unwrap()
    );
}

#[test]
fn an_output_name_can_choose_the_format_and_folders_are_written_whole() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 1.0),
    nodes: {
        "city":  SynthCity(size_m: (120.0, 100.0), blocks: (2, 2), street_m: 14.0, terrain: (size_m: (120.0, 100.0))),
        "truth": TruthScene(city: "city"),
    },
    outputs: { "truth": "truth", "tiles.3dtiles": "truth" },
)"#,
    );
    let r = env.run(&g, &[]).ok();
    let outputs = r.json()["outputs"].clone();
    assert!(outputs["truth"].as_str().unwrap().ends_with("truth.glb"));
    let tiles = std::path::PathBuf::from(outputs["tiles.3dtiles"].as_str().unwrap());
    assert!(tiles.join("tileset.json").is_file() && tiles.join("tiles").is_dir());
    let entries = std::fs::read_dir(env.out())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect::<Vec<_>>();
    assert!(
        entries.iter().all(|e| !e.contains(".tmp")),
        "no temp folders left: {entries:?}"
    );
    let before = std::fs::metadata(tiles.join("tileset.json"))
        .unwrap()
        .modified()
        .unwrap();
    env.run(&g, &[]).ok();
    assert_eq!(
        std::fs::metadata(tiles.join("tileset.json"))
            .unwrap()
            .modified()
            .unwrap(),
        before,
        "not rewritten"
    );
}
