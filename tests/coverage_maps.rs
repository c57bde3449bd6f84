//! Network-planning maps (issue 50) as a graph: two transmitters' radio maps over a small
//! synthetic city, Coverage's best server with its stats, and MapPlot marking the transmitters
//! read from a CSV. Few rays and 10 m cells, so it runs in seconds.

mod common;
use common::*;

const GRAPH: &str = r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    nodes: {
        "city":   SynthCity(seed: 3, size_m: (120.0, 90.0), blocks: (1, 1)),
        "truth":  TruthScene(city: "city"),
        "cells":  ReadMeasurements(path: "cells.csv"),
        "map_a":  RadioMap(scene: "truth", tx: (10.0, 10.0, 40.0), freq_hz: 3.69e9, cell_m: 10.0, options: (rays: 20000)),
        "map_b":  RadioMap(scene: "truth", tx: (110.0, 80.0, 40.0), freq_hz: 3.695e9, cell_m: 10.0, options: (rays: 20000)),
        "best":   Coverage(
            maps: ["map_a", "map_b"],
            transmitters: [
                CoverageTx(id: "A", eirp_dbm: 20.0, freq_hz: 3.69e9),
                CoverageTx(id: "B", eirp_dbm: 15.0, freq_hz: 3.695e9),
            ],
            layer: BestServer,
        ),
        "covered": Coverage(
            maps: ["map_a", "map_b"],
            transmitters: [
                CoverageTx(id: "A", eirp_dbm: 20.0, freq_hz: 3.69e9),
                CoverageTx(id: "B", eirp_dbm: 15.0, freq_hz: 3.695e9),
            ],
            layer: Covered(-90.0),
        ),
        "plot":   MapPlot(raster: "best", transmitters: "cells", name: "best_server",
                          title: "best server", units: "server", palette: Categorical,
                          categories: ["A", "B"]),
    },
    outputs: { "stats": "best.stats", "covered_stats": "covered.stats", "plot": "plot" },
)
"#;

const CELLS: &str = "tx_id,tx_x,tx_y,tx_z,tx_azimuth_deg,rx_x,rx_y,rx_z,freq_hz,path_loss_db
A,10.0,10.0,40.0,45.0,60.0,45.0,1.5,3.69e9,90.0
B,110.0,80.0,40.0,225.0,60.0,45.0,1.5,3.695e9,90.0
";

fn metrics(env: &Env, name: &str) -> serde_json::Map<String, serde_json::Value> {
    let path = env.out().join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let values = json.get("values").unwrap_or(&json);
    values.as_object().expect("an object of metrics").clone()
}

/// The run succeeds; every cell is counted once (no ray, below the floor or covered); the
/// servers share the covered cells; the threshold's coverage is within the floor's; the figure
/// is written.
#[test]
fn two_transmitters_give_a_best_server_map_with_consistent_stats() {
    let env = Env::new();
    env.write("cells.csv", CELLS);
    let g = env.write("coverage.ron", GRAPH);
    let run = env.run(&g, &[]).ok();
    assert_eq!(run.status("best"), "ran", "{:?}", run.statuses());
    let s = metrics(&env, "stats");
    let v = |k: &str| {
        s.get(k)
            .and_then(|v| v.as_f64())
            .unwrap_or_else(|| panic!("{k} missing: {s:?}"))
    };
    assert!(v("cells") > 0.0);
    assert_eq!(
        v("cells_no_ray") + v("cells_below_floor") + v("cells_covered"),
        v("cells")
    );
    assert!(v("cells_covered") > 0.0, "{s:?}");
    assert!((v("covered_fraction") - v("cells_covered") / v("cells")).abs() < 1e-12);
    assert!((v("covered_km2") - v("cells_covered") * 100.0 / 1e6).abs() < 1e-12);
    let share = v("serving_fraction/A") + v("serving_fraction/B");
    assert!((share - 1.0).abs() < 1e-9, "{share}");
    assert!(v("sinr_median_db").is_finite());
    assert_eq!(v("floor_dbm"), -140.0);
    let c = metrics(&env, "covered_stats");
    let above = c["covered_fraction_above_threshold"].as_f64().unwrap();
    assert!((0.0..=v("covered_fraction")).contains(&above), "{above}");
    let figure: Vec<_> = walk(&env.out())
        .into_iter()
        .filter(|p| p.file_name().is_some_and(|n| n == "best_server.png"))
        .collect();
    assert_eq!(figure.len(), 1, "{:?}", walk(&env.out()));
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}
