//! Every kind of graph error: exit 2, before anything runs, with file:line:col, the node, and what
//! was expected.

mod common;
use common::*;

const SITE: &str = r#"site: Site(crs: "EPSG:32618", origin: (0.0, 0.0), cell_m: 1.0)"#;

/// Runs a graph whose `nodes` block is `nodes`; asserts exit 2, nothing cached, and returns stderr.
fn fails(nodes: &str, extra: &[&str]) -> String {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        &format!("Graph(\n    {SITE},\n    nodes: {{\n{nodes}\n    }},\n)\n"),
    );
    let r = env.run(&g, extra);
    assert_eq!(r.code, 2, "stderr: {}", r.stderr);
    assert!(r.stdout.is_empty(), "no run record for an invalid graph");
    assert!(
        !env.cache().join("cas").exists() || env.blobs().is_empty(),
        "nothing ran"
    );
    r.stderr
}

fn has(stderr: &str, needle: &str) {
    assert!(stderr.contains(needle), "expected {needle:?} in:\n{stderr}");
}

#[test]
fn unknown_node_kind_suggests_the_nearest() {
    let e = fails(r#"        "t": SynthTerain(size_m: (50.0, 40.0)),"#, &[]);
    has(
        &e,
        "g.ron:4:14: node \"t\": unknown node kind `SynthTerain`; did you mean `SynthTerrain`?",
    );
}

#[test]
fn unknown_field_suggests_the_nearest() {
    let e = fails(
        r#"        "t": SynthTerrain(size_m: (50.0, 40.0), releif_m: 3.0),"#,
        &[],
    );
    has(
        &e,
        "g.ron:4:49: node \"t\": unknown field `releif_m`; did you mean `relief_m`?",
    );
}

/// Inside a nested struct (an antenna of a radio map) and through `--set` into one, a typo is
/// the same error, where it once loaded and changed nothing.
#[test]
fn unknown_nested_field_suggests_the_nearest() {
    let nodes = r#"        "t": SynthTerrain(size_m: (50.0, 40.0)),
        "scene": AssembleScene(terrain: "t", objects: []),
        "map": RadioMap(scene: "scene", tx: (0.0, 0.0, 10.0), freq_hz: 3.5e9, antenna: (pattern: Isotropic, polarization: V, azimuth_deg: 0.0, tilt_deg: 0.0, downtilt_deg: 10.0)),"#;
    let e = fails(nodes, &[]);
    has(&e, "unknown field `downtilt_deg`; did you mean `tilt_deg`?");
    let ok = nodes.replace(", downtilt_deg: 10.0", "");
    let e = fails(&ok, &["--set", "map.antenna.downtilt_deg=10"]);
    has(&e, "unknown field `downtilt_deg`");
}

#[test]
fn missing_input() {
    let e = fails(r#"        "b": GaussianBlur(sigma_m: 1.0),"#, &[]);
    has(
        &e,
        "g.ron:4:14: node \"b\": missing input `raster`: expected the id of a Raster node",
    );
}

#[test]
fn input_naming_an_unknown_node() {
    let e = fails(
        "        \"t\": SynthTerrain(),\n        \"b\": GaussianBlur(raster: \"tt\", sigma_m: 1.0),",
        &[],
    );
    has(
        &e,
        "g.ron:5:35: node \"b\": input `raster`: unknown node `tt`; did you mean `t`?",
    );
}

#[test]
fn input_of_the_wrong_type() {
    let e = fails(
        "        \"t\": SynthTerrain(),\n        \"p\": PointStats(points: \"t\"),",
        &[],
    );
    has(
        &e,
        "g.ron:5:33: node \"p\": input `points` expects a Points node, but \"t\" (SynthTerrain) produces Raster",
    );
}

#[test]
fn cycle_is_printed() {
    let e = fails(
        "        \"t\": SynthTerrain(),\n        \"a\": Difference(a: \"t\", b: \"c\"),\n        \"b\": GaussianBlur(raster: \"a\", sigma_m: 1.0),\n        \"c\": Clamp(raster: \"b\", min: 0.0),",
        &[],
    );
    has(
        &e,
        "g.ron:5:14: node \"a\": cycle: \"a\" -> \"b\" -> \"c\" -> \"a\"",
    );
}

#[test]
fn invalid_values() {
    let e = fails(
        "        \"t\": SynthTerrain(),\n        \"b\": GaussianBlur(raster: \"t\", sigma_m: -1.0),",
        &[],
    );
    has(
        &e,
        "g.ron:5:49: node \"b\": invalid `sigma_m`: expected a non-negative sigma in metres, found -1",
    );
    let e = fails(r#"        "t": SynthTerrain(octaves: "four"),"#, &[]);
    has(
        &e,
        "g.ron:4:36: node \"t\": expected u32, found string \"four\"",
    );
    let e = fails(
        r#"        "d": RasterizeSurface(points: "d", mode: Maximum),"#,
        &[],
    );
    has(&e, "unknown variant `Maximum`");
}

#[test]
fn bad_site() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        "Graph(\n  site: Site(crs: \"WGS84\", origin: (0.0, 0.0), cell_m: 1.0),\n  nodes: {},\n)\n",
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2);
    has(
        &r.stderr,
        "g.ron:2:19: invalid `crs`: expected a CRS of the form \"EPSG:<code>\"",
    );
}

#[test]
fn syntax_error() {
    let e = fails(r#"        "t": SynthTerrain(size_m: (50.0, 40.0),"#, &[]);
    has(&e, "g.ron:5:5: expected a field name, found `}`");
}

#[test]
fn missing_data_file_names_every_one() {
    let e = fails(
        "        \"a\": ReadXyz(path: \"a.xyz\"),\n        \"b\": ReadXyz(path: \"sub/b.xyz\"),",
        &[],
    );
    has(&e, "g.ron:4:28: node \"a\": file not found:");
    has(&e, "g.ron:5:28: node \"b\": file not found:");
    has(
        &e,
        "sub/b.xyz (`path` resolves against the graph file's folder)",
    );
}

#[test]
fn bad_set_arguments() {
    let nodes =
        "        \"t\": SynthTerrain(),\n        \"b\": GaussianBlur(raster: \"t\", sigma_m: 1.0),";
    has(
        &fails(nodes, &["--set", "bb.sigma_m=2"]),
        "--set bb.sigma_m=2 (column 1): unknown node `bb`; did you mean `b`?",
    );
    has(
        &fails(nodes, &["--set", "b.sigma=2"]),
        "node \"b\": unknown field `sigma`; did you mean `sigma_m`?",
    );
    has(
        &fails(nodes, &["--set", "b.sigma_m=abc"]),
        "--set b.sigma_m=abc (column 11): node \"b\": expected a number, found identifier `abc`",
    );
    has(
        &fails(nodes, &["--set", "b=2"]),
        "node \"b\": expected a node definition `Kind(field: value, ...)`, found integer",
    );
    has(
        &fails(nodes, &["--set", "b=Blur(raster: \"t\")"]),
        "unknown node kind `Blur`",
    );
    has(
        &fails(nodes, &["--set", "b.sigma_m.x=2"]),
        "--set b.sigma_m.x=2 (column 1): node \"b\": `x` names an entry, but the value it is in is float `1`, not a map or struct",
    );
}

#[test]
fn set_can_replace_a_whole_node() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        &format!("Graph(\n    {SITE},\n    nodes: {{ \"t\": SynthTerrain(), \"b\": GaussianBlur(raster: \"t\", sigma_m: 1.0), \"s\": RasterStats(raster: \"b\") }},\n)\n"),
    );
    let r = env
        .run(&g, &["--set", "b=Clamp(raster: \"t\", max: 0.0)"])
        .ok();
    assert_eq!(r.status("b"), "ran");
    let node = r.node("b");
    assert_eq!(node["kind"], "Clamp");
}

#[test]
fn data_paths_resolve_against_data_dir() {
    let env = Env::new();
    env.write("elsewhere/pts.xyz", "x y z\n1 1 1\n2 2 2\n");
    let g = env.write("g.ron", &format!("Graph(\n    {SITE},\n    nodes: {{ \"p\": ReadXyz(path: \"pts.xyz\"), \"s\": PointStats(points: \"p\") }},\n)\n"));
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2);
    let r = env
        .run(&g, &["--data", env.path("elsewhere").to_str().unwrap()])
        .ok();
    assert_eq!(r.status("s"), "ran");
}

#[test]
fn an_output_format_the_type_cannot_take() {
    let env = Env::new();
    let g = env.write("g.ron", &format!("Graph(\n    {SITE},\n    nodes: {{ \"t\": SynthTerrain() }},\n    outputs: {{ \"t.las\": \"t\" }},\n)\n"));
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2);
    has(
        &r.stderr,
        "g.ron:4:16: output \"t.las\": Raster outputs are written as tif, exr or png, not .las",
    );
}

/// The paper's sites are graphs over data the user downloads: without it, explain names every
/// missing file, then the missing site folder with the recipe that fills it and the docs page,
/// and exits 2.
#[test]
fn site_graphs_without_their_data_name_each_missing_file_and_the_recipe() {
    let env = Env::new();
    let common = ["measurements.csv", "mapillary", "view_outputs", "osm.osm"];
    let own: [(&str, &[&str]); 3] = [
        (
            "brooklyn",
            &["lidar", "dem.tif", "ortho.tif", "srtm/N40W074.hgt"],
        ),
        (
            "boulder",
            &["lidar", "dem.tif", "ortho.tif", "srtm/N39W106.hgt"],
        ),
        ("painiitty", &["tiles", "dem30.tif"]),
    ];
    for (site, files) in own {
        let g = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("graphs/{site}.ron"));
        let data = env.dir.path().join(format!("data-{site}"));
        std::fs::create_dir_all(&data).unwrap();
        let r = env.cli(&[
            "explain",
            g.to_str().unwrap(),
            "--data",
            data.to_str().unwrap(),
        ]);
        assert_eq!(r.code, 2, "{site}: {}", r.stderr);
        for f in common.iter().chain(files) {
            assert!(
                r.stderr.contains(&format!(
                    "file not found: {}",
                    data.join(site).join(f).display()
                )),
                "{site}/{f}: {}",
                r.stderr
            );
        }
        has(
            &r.stderr,
            &format!(
                "this graph's data is missing: {}. `python3 scripts/site_data.py {site} --out DATA` downloads",
                data.join(site).display()
            ),
        );
        has(
            &r.stderr,
            &format!("docs/sites.md#{site} says what each input is"),
        );
    }
}
