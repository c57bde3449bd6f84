//! Our tracer against Sionna RT 2.2 on Sionna's own scenes: path gains of the links in
//! tests/fixtures/sionna_paths.csv (made by scripts/sionna_paths_fixture.py), same interactions
//! (line of sight and specular reflection to depth 3), same antennas (isotropic, V), 10^6 rays.

mod common;
use common::*;

use std::collections::BTreeMap;

use kodama_nodes::io::sionna_xml::read_scene;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::paths::{TraceOptions, trace_links};
use kodama_nodes::rf::scene::RfScene;

struct Row {
    tx: [f64; 3],
    rx: [f64; 3],
    freq: f64,
    depth: u32,
    sionna_db: f64,
    sionna_paths: usize,
}

fn fixture_rows() -> BTreeMap<String, Vec<Row>> {
    let mut out: BTreeMap<String, Vec<Row>> = BTreeMap::new();
    let mut r = csv::Reader::from_path(fixture("sionna_paths.csv")).unwrap();
    for rec in r.records() {
        let rec = rec.unwrap();
        let f = |i: usize| -> f64 { rec[i].parse().unwrap() };
        out.entry(rec[0].to_string()).or_default().push(Row {
            tx: [f(1), f(2), f(3)],
            rx: [f(4), f(5), f(6)],
            freq: f(7),
            depth: rec[8].parse().unwrap(),
            sionna_db: if &rec[9] == "-inf" {
                f64::NEG_INFINITY
            } else {
                f(9)
            },
            sionna_paths: rec[10].parse().unwrap(),
        });
    }
    out
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn path_gains_match_sionna_rt() {
    let mut all_diffs = Vec::new();
    for (name, rows) in fixture_rows() {
        let xml = shared(&format!("sionna-scenes/{name}/{name}.xml"));
        let scene = read_scene(&xml).unwrap();
        let freq = rows[0].freq;
        // Sionna's scene files give every material its default 0.1 m slab: trace them so.
        let rf = RfScene::new(&scene, freq, false)
            .unwrap()
            .with_uniform_thickness(kodama_nodes::rf::scene::SLAB_THICKNESS_M);
        let opt = TraceOptions {
            max_depth: rows[0].depth,
            los: true,
            reflection: true,
            transmission: false,
            diffraction: false,
            rays: 1_000_000,
            foliage_db_per_m: None,
            ..Default::default()
        };
        let links: Vec<_> = rows.iter().map(|r| (r.tx, r.rx)).collect();
        let ours = trace_links(
            &rf,
            &links,
            &Antenna::default(),
            &Antenna::default(),
            &opt,
            freq,
        );
        let (mut diffs, mut only_one) = (Vec::new(), 0);
        for (row, got) in rows.iter().zip(&ours) {
            match (row.sionna_db.is_finite(), got.gain_db.is_finite()) {
                (true, true) => diffs.push((got.gain_db - row.sionna_db).abs()),
                (false, false) => {}
                _ => {
                    only_one += 1;
                    println!(
                        "{name}: rx {:?}: Sionna {:.2} dB ({} paths), ours {:.2} dB ({} paths)",
                        row.rx,
                        row.sionna_db,
                        row.sionna_paths,
                        got.gain_db,
                        got.paths.len()
                    );
                }
            }
            if row.sionna_db.is_finite()
                && got.gain_db.is_finite()
                && (got.gain_db - row.sionna_db).abs() > 1.0
            {
                println!(
                    "{name}: rx {:?}: Sionna {:.2} dB ({} paths), ours {:.2} dB ({} paths)",
                    row.rx,
                    row.sionna_db,
                    row.sionna_paths,
                    got.gain_db,
                    got.paths.len()
                );
            }
        }
        let n = diffs.len();
        println!(
            "{name}: {} links, {n} with paths on both sides, {only_one} with paths on one side only; \
             |difference| median {:.3} dB, 90th percentile {:.3} dB",
            rows.len(),
            percentile(&mut diffs.clone(), 0.5),
            percentile(&mut diffs.clone(), 0.9)
        );
        all_diffs.extend(diffs);
    }
    let n = all_diffs.len();
    let (median, p90) = (
        percentile(&mut all_diffs.clone(), 0.5),
        percentile(&mut all_diffs, 0.9),
    );
    println!(
        "all: {n} links compared, |difference| median {median:.3} dB, 90th percentile {p90:.3} dB"
    );
    assert!(n >= 50, "{n}");
    assert!(median <= 1.0, "median {median}");
}
