//! graphs/duke.ron on the real Duke CBRS drive test against an independent computation of the
//! same scores (scripts/duke_reference.py: numpy + pyproj; its output is the committed fixture).

mod common;
use common::*;

use std::path::Path;

#[test]
fn duke_scores_match_the_numpy_reference() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let data = root.join("../shared/data");
    assert!(data.is_dir(), "real test data missing: {}", data.display());
    let env = Env::new();
    env.run(
        &root.join("graphs/duke.ron"),
        &["--data", data.to_str().unwrap()],
    )
    .ok();
    let ours: serde_json::Value =
        serde_json::from_slice(&std::fs::read(env.out().join("uma_eval.json")).unwrap()).unwrap();
    let reference =
        std::fs::read_to_string(root.join("tests/fixtures/duke_reference.csv")).unwrap();
    let mut compared = 0;
    for line in reference.lines().skip(1) {
        let (key, value) = line.split_once(',').unwrap();
        let want: f64 = value.parse().unwrap();
        let got = ours[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} missing"));
        // Projections (proj4rs here, PROJ there) agree to millimetres: 1e-3 dB is plenty.
        assert!((got - want).abs() < 1e-3, "{key}: ours {got}, numpy {want}");
        compared += 1;
    }
    assert_eq!(compared, 16);
    println!(
        "duke: 3GPP UMa P2P RMSE {:.3} dB over {} readings, per-cell offsets fitted; matches numpy",
        ours["p2p_rmse_db"].as_f64().unwrap(),
        ours["links"]
    );
    assert!(env.out().join("report/report.md").exists());
}
