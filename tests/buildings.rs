//! The building chain of Sec. 4.1 end to end through the CLI: the demo graph and the real Delft
//! AHN3 tile. Every building mesh in the exported glb files is read back and passes the mesh
//! checker; the Delft footprints, derived from the LiDAR alone, are scored against the BGT.

mod common;
use common::*;

use std::path::{Path, PathBuf};

use kodama_nodes::geom::mesh_check::check_solid;

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

fn check_all(glb: &Path) -> usize {
    let meshes = building_meshes(glb);
    for (name, m) in &meshes {
        check_solid(m).unwrap_or_else(|e| panic!("{}: {name}: {e}", glb.display()));
    }
    meshes.len()
}

/// The same scene as CityJSON passes the official validator (cjval: the schema and the checks
/// it cannot express), with a Solid (or solid parts) for every building the glb holds.
fn check_cityjson(path: &Path, solids: usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let v = cjval::CJValidator::from_str(&text);
    let errors: Vec<String> = v
        .validate()
        .iter()
        .filter(|(_, s)| s.has_errors())
        .map(|(check, s)| format!("{check}: {s}"))
        .collect();
    assert!(errors.is_empty(), "{}: {errors:#?}", path.display());
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let buildings = doc["CityObjects"]
        .as_object()
        .unwrap()
        .values()
        .filter(|o| o["type"] == "Building")
        .count();
    let solids_written = doc["CityObjects"]
        .as_object()
        .unwrap()
        .values()
        .filter(|o| o["geometry"][0]["type"] == "Solid")
        .count();
    println!(
        "{}: valid CityJSON, {buildings} buildings, {solids_written} solids",
        path.display()
    );
    assert_eq!(
        buildings, solids,
        "one Building per building mesh of the glb"
    );
    assert!(
        solids_written >= solids,
        "every building closed: {solids_written}"
    );
}

#[test]
fn demo_scenes_hold_only_valid_building_solids() {
    let env = Env::new();
    env.run(&repo("graphs/demo.ron"), &[]).ok();
    let kodama = check_all(&env.out().join("scene.glb"));
    let baseline = check_all(&env.out().join("osm_scene.glb"));
    println!(
        "demo: {kodama} KODAMA building solids, {baseline} OSM-baseline prisms, all pass the checker"
    );
    assert!(kodama >= 65, "{kodama}");
    // The OSM-like map misses some buildings (OsmLike drops 10 %).
    assert!((55..72).contains(&baseline), "{baseline}");
    check_report(&env.out().join("report"));
}

/// The full twin's P2P RMSE on the demo's default city, dB: 8.49 with TerrainPass v2 (8.21
/// before it) measured on SynthCity v3's
/// varied façades (BENCHMARKS.md, "The demo's Table 1 since issue 51"; 8.30 on v2's uniform
/// ones, 7.92 before PlaceClutter v5), inside about +-1 dB of 8.30, about the range
/// four seeds of the views' noise alone gave the full twin before (5.77-6.86 dB). Outside it, a
/// change moved the headline: measure the test family again (graphs/sweeps/family_test.ron)
/// and restate both.
const DEMO_TWIN_P2P_DB: (f64, f64) = (7.3, 9.3);

/// The models of the demo's Table 1, in its column order.
const DEMO_MODELS: [&str; 4] = ["KODAMA twin", "Sec. 4.1 solids", "OSM baseline", "3GPP UMi"];

/// The demo's report (paper Table 1 on the synthetic site): the full twin's P2P RMSE inside its
/// stated band and ahead of the OSM baseline and of 3GPP, every model scored on every link, and
/// plots that decode.
fn check_report(dir: &Path) {
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    println!("{md}");
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("metrics.json")).unwrap()).unwrap();
    let rmse = |m: &str| metrics[m]["p2p_rmse_db"].as_f64().unwrap();
    let (twin, osm, gpp) = (rmse("KODAMA twin"), rmse("OSM baseline"), rmse("3GPP UMi"));
    assert!(
        twin < osm && twin < gpp,
        "twin {twin}, OSM {osm}, 3GPP {gpp}"
    );
    // The headline, guarded: the full twin's P2P RMSE on the default city (README.md,
    // BENCHMARKS.md) inside a band of the spread the views' noise alone gives it.
    assert!(
        (DEMO_TWIN_P2P_DB.0..=DEMO_TWIN_P2P_DB.1).contains(&twin),
        "full twin P2P {twin} dB outside {DEMO_TWIN_P2P_DB:?}"
    );
    // Table 1's trend lines (issue 49): a fitted model's PD and CI RMSE, the gap between its line
    // and the measured line on the same links, never exceed its P2P RMSE; the twin's trend is
    // closer to the measured one than 3GPP's; the report states its definitions itself.
    let get = |m: &str, k: &str| metrics[m][k].as_f64().unwrap();
    for m in ["KODAMA twin", "Sec. 4.1 solids", "OSM baseline"] {
        for k in ["pd_rmse_db", "ci_rmse_db"] {
            assert!(get(m, k) <= get(m, "p2p_rmse_db"), "{m} {k}");
        }
    }
    assert!(get("KODAMA twin", "pd_rmse_db") < get("3GPP UMi", "pd_rmse_db"));
    assert!(md.contains("How each figure is computed") && !md.contains("rf.md"));
    let links = metrics["KODAMA twin"]["links"].as_f64().unwrap();
    for m in DEMO_MODELS {
        assert_eq!(metrics[m]["links_scored"].as_f64().unwrap(), links, "{m}");
    }
    assert!(links > 100.0, "{links}");
    // Every figure in both encodings: the charts at print size, the maps at the orthophoto's
    // resolution or finer (400 m at 0.5 m: at least 800 pixels across).
    for plot in [
        "scatter",
        "error_cdf",
        "path_loss_distance",
        "radio_map",
        "footprints",
        "terrain_error",
        "clutter",
        "relief",
        "materials",
    ] {
        let img = image::open(dir.join(format!("plots/{plot}.png"))).unwrap();
        assert!(
            img.width() >= 1000 && img.height() >= 700,
            "{plot}: {:?}",
            (img.width(), img.height())
        );
        let svg = std::fs::read_to_string(dir.join(format!("plots/{plot}.svg"))).unwrap();
        assert!(
            svg.contains("<svg") && svg.trim_end().ends_with("</svg>"),
            "{plot}.svg"
        );
        assert!(
            md.contains(&format!("plots/{plot}.png")),
            "report.md shows {plot}"
        );
    }
    for chart in ["scatter", "error_cdf", "path_loss_distance"] {
        let img = image::open(dir.join(format!("plots/{chart}.png"))).unwrap();
        assert_eq!((img.width(), img.height()), (1600, 1000), "{chart}");
    }
    let csv = std::fs::read_to_string(dir.join("table.csv")).unwrap();
    assert!(
        csv.starts_with(
            "site,metric,KODAMA twin,Sec. 4.1 solids,OSM baseline,3GPP UMi\nsynthetic,P2P RMSE (dB),"
        ),
        "{csv}"
    );
    check_links_csv(dir, &metrics, links as usize);
    check_report_in_browser(dir);
}

/// links.csv lists every link as it was scored: each model's error column gives back its P2P
/// RMSE, over all links and over the LOS ones.
fn check_links_csv(dir: &Path, metrics: &serde_json::Value, links: usize) {
    let text = std::fs::read_to_string(dir.join("links.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), links);
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let los = col("los");
    for m in DEMO_MODELS {
        let err = col(&format!("{m} error_db"));
        let rmse = |keep: &dyn Fn(&[&str]) -> bool| {
            let e: Vec<f64> = rows
                .iter()
                .filter(|r| keep(r))
                .map(|r| r[err].parse::<f64>().unwrap())
                .collect();
            (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt()
        };
        for (key, got) in [
            ("p2p_rmse_db", rmse(&|_| true)),
            ("los/p2p_rmse_db", rmse(&|r| r[los] == "1")),
        ] {
            let want = metrics[m][key].as_f64().unwrap();
            assert!(
                (got - want).abs() < 2e-3,
                "{m} {key}: links.csv {got}, metrics {want}"
            );
        }
    }
}

/// A Chromium to drive: `$KODAMA_CHROMIUM`, else the usual names on PATH.
fn find_chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("KODAMA_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    [
        "chromium",
        "chromium-browser",
        "google-chrome",
        "google-chrome-stable",
    ]
    .iter()
    .flat_map(|n| std::env::split_paths(&path).map(move |d| d.join(n)))
    .find(|p| p.is_file())
}

/// Runs headless Chromium with software WebGL on `url`, with `extra` arguments, killed after
/// two minutes; its stdout.
fn chromium(browser: &Path, url: &str, extra: &[&str]) -> String {
    let profile = tempfile::tempdir().unwrap();
    let mut child = std::process::Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--window-size=1280,1400",
            "--virtual-time-budget=30000",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .args(extra)
        .arg(url)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut stdout, &mut s).ok();
        s
    });
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > std::time::Duration::from_secs(120) {
            child.kill().ok();
            panic!(
                "{} did not finish {url} within 2 minutes",
                browser.display()
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    reader.join().unwrap()
}

/// report.html in a real browser: the page finishes its first frame, the 3D view is not blank
/// (over a fifth of the canvas differs from the background), and no script error is reported.
/// A screenshot lands beside the report. Skipped, saying so, where no Chromium is installed;
/// under CI=true that fails instead, since .ci/run installs Debian's.
fn check_report_in_browser(dir: &Path) {
    let Some(browser) = find_chromium() else {
        let why = "report.html browser check: no Chromium found (install Debian's `chromium`, \
                   or set KODAMA_CHROMIUM)";
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{why}; .ci/run installs it, see its output for why it did not"
        );
        eprintln!("SKIPPED: {why}");
        return;
    };
    let url = format!(
        "file://{}",
        dir.join("report.html").canonicalize().unwrap().display()
    );
    let dom = chromium(&browser, &url, &["--dump-dom"]);
    let body = dom
        .split("<body")
        .nth(1)
        .and_then(|b| b.split('>').next())
        .unwrap_or_else(|| panic!("no <body> in what Chromium dumped: {dom:.300}"));
    let attr = |name: &str| {
        body.split(&format!("{name}=\""))
            .nth(1)
            .and_then(|v| v.split('"').next())
            .map(str::to_owned)
    };
    assert!(
        attr("data-errors").is_none(),
        "script errors: {}",
        dom.split("id=\"errors\">")
            .nth(1)
            .unwrap_or("")
            .split('<')
            .next()
            .unwrap_or("")
    );
    assert_eq!(
        attr("data-ready").as_deref(),
        Some("1"),
        "never drew: {body}"
    );
    let nonblank: f64 = attr("data-nonblank").unwrap().parse().unwrap();
    println!(
        "report.html in {}: {:.1} % of the 3D view drawn",
        browser.display(),
        100.0 * nonblank
    );
    assert!(nonblank > 0.2, "the 3D view is nearly blank: {nonblank}");
    let shot = dir.join("screenshot.png");
    chromium(
        &browser,
        &url,
        &[&format!("--screenshot={}", shot.display())],
    );
    let img = image::open(&shot).unwrap();
    assert!(img.width() >= 1000, "screenshot {} wide", img.width());
}

#[test]
fn delft_tile_footprints_and_solids() {
    let data = repo("../shared/data");
    assert!(data.is_dir(), "real test data missing: {}", data.display());
    let env = Env::new();
    env.run(
        &repo("graphs/delft.ron"),
        &["--data", data.to_str().unwrap()],
    )
    .ok();
    let solids = check_all(&env.out().join("scene.glb"));
    check_cityjson(&env.out().join("scene.city.json"), solids);
    let score: serde_json::Value =
        serde_json::from_slice(&std::fs::read(env.out().join("footprint_score.json")).unwrap())
            .unwrap();
    let get = |k: &str| {
        score[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} missing: {score}"))
    };
    println!(
        "delft: {solids} building solids pass the checker; against the BGT ({} buildings scored): \
         per-building IoU mean {:.3} (median {:.3}), merge-tolerant block IoU mean {:.3} over {} \
         blocks, footprint IoU {:.3}; the building returns' own cells over the same blocks {:.3}",
        get("buildings_scored"),
        get("building_iou_mean"),
        get("building_iou_median"),
        get("block_iou_mean"),
        get("blocks_scored"),
        get("iou"),
        get("iou_returns"),
    );
    assert!(solids > 50, "{solids}");
    assert!(get("iou") >= 0.8, "footprint IoU {}", get("iou"));
    // The outlines come within a few hundredths of the returns they are traced from: what
    // separates both from the BGT is what the returns show (eaves, annexes), not the tracing.
    assert!(
        get("iou") >= get("iou_returns") - 0.03,
        "footprint IoU {} against the returns' {}",
        get("iou"),
        get("iou_returns")
    );
    assert!(get("block_iou_mean") >= 0.65);
    // The derived footprints are the LiDAR's: they must not be the BGT's own polygons.
    let ours = std::fs::read_to_string(env.out().join("building_footprints.geojson")).unwrap();
    assert!(
        !ours.contains("b31e1feb1"),
        "BGT ids leaked into the derived footprints"
    );
}

/// Real LiDAR with no building class (Autzen: classes 1 and 2 only) over a river bank, its trees
/// and a footbridge: the geometric cues find high, smooth candidates (the bridge deck, banks the
/// terrain missed, tree clumps) and drop every one, for being too narrow, letting the laser
/// through or standing on no walls; the stage says so.
#[test]
fn autzen_without_a_building_class_makes_no_bridge_or_tree_a_building() {
    let data = repo("../shared/data");
    assert!(data.is_dir(), "real test data missing: {}", data.display());
    let env = Env::new();
    let r = env
        .run(
            &repo("graphs/autzen.ron"),
            &["--data", data.to_str().unwrap()],
        )
        .ok();
    let fp: serde_json::Value = serde_json::from_slice(
        &std::fs::read(env.out().join("building_footprints.geojson")).unwrap(),
    )
    .unwrap();
    let n = fp["features"].as_array().unwrap().len();
    assert_eq!(n, 0, "buildings where Autzen has none: {fp}");
    assert!(
        r.stderr.contains("building candidates from geometric cues")
            && r.stderr.contains("give the stage footprints or a mask"),
        "{}",
        r.stderr
    );
    // Without the cues the same chain makes the footbridge and the banks buildings.
    let bare = env
        .run(
            &repo("graphs/autzen.ron"),
            &[
                "--data",
                data.to_str().unwrap(),
                "--set",
                "buildings.min_width_m=0.0",
                "--set",
                "buildings.max_pass_through=1.0",
                "--set",
                "buildings.min_walled=0.0",
            ],
        )
        .ok();
    drop(bare);
    let fp: serde_json::Value = serde_json::from_slice(
        &std::fs::read(env.out().join("building_footprints.geojson")).unwrap(),
    )
    .unwrap();
    let n = fp["features"].as_array().unwrap().len();
    assert!(n >= 5, "{n} candidates without the cues");
}
