//! Our tracer against Sionna RT 2.2 on Sionna's own scenes: path gains of the links in
//! tests/fixtures/sionna_paths.csv (line of sight and specular reflection to depth 3) and
//! sionna_paths_refraction.csv (the same links with transmission through every surface too),
//! both made by scripts/sionna_paths_fixture.py; same antennas (isotropic, V), 10^6 rays.

mod common;
use common::*;

use std::collections::BTreeMap;

use kodama_nodes::io::sionna_xml::read_scene;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::path::TraceOptions;
use kodama_nodes::rf::paths::trace_links;
use kodama_nodes::rf::scene::RfScene;

struct Row {
    tx: [f64; 3],
    rx: [f64; 3],
    freq: f64,
    depth: u32,
    sionna_db: f64,
    sionna_paths: usize,
}

fn fixture_rows(file: &str) -> BTreeMap<String, Vec<Row>> {
    let mut out: BTreeMap<String, Vec<Row>> = BTreeMap::new();
    let mut r = csv::Reader::from_path(fixture(file)).unwrap();
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

/// Over every link of a fixture: how many have paths on both sides, the median and 90th
/// percentile of their |difference|, and how many have paths on one side only.
struct Summary {
    n: usize,
    median: f64,
    p90: f64,
    one_side: usize,
    /// The same per scene.
    scenes: BTreeMap<String, Summary>,
}

/// Traces the links of `file` with the interactions given and compares them with Sionna's,
/// printing the figures under `label`.
fn compare(file: &str, label: &str, transmission: bool, diffraction: bool) -> Summary {
    compare_with(file, label, transmission, diffraction, true)
}

/// [`compare`], with or without wedges where two shapes meet (Sionna's own scenes: walls and
/// roofs are separate shapes, and Sionna RT 2.2 finds a wedge's faces only within one).
fn compare_with(
    file: &str,
    label: &str,
    transmission: bool,
    diffraction: bool,
    wedges_across_objects: bool,
) -> Summary {
    let (mut all_diffs, mut all_one_side) = (Vec::new(), 0);
    let mut scenes = BTreeMap::new();
    for (name, rows) in fixture_rows(file) {
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
            transmission,
            diffraction,
            rays: 1_000_000,
            foliage_db_per_m: None,
            wedges_across_objects,
            // Sionna's UTD takes faces and edges unbounded: like with like.
            finite_faces: false,
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
        let scene = Summary {
            n,
            median: percentile(&mut diffs.clone(), 0.5),
            p90: percentile(&mut diffs.clone(), 0.9),
            one_side: only_one,
            scenes: BTreeMap::new(),
        };
        println!(
            "{name}: {} links, {n} with paths on both sides, {only_one} with paths on one side only; \
             |difference| median {:.3} dB, 90th percentile {:.3} dB",
            rows.len(),
            scene.median,
            scene.p90
        );
        scenes.insert(name.clone(), scene);
        all_diffs.extend(diffs);
        all_one_side += only_one;
    }
    let s = Summary {
        n: all_diffs.len(),
        median: percentile(&mut all_diffs.clone(), 0.5),
        p90: percentile(&mut all_diffs, 0.9),
        one_side: all_one_side,
        scenes,
    };
    println!(
        "all, {label}: {} links compared, {} with paths on one side only; |difference| median \
         {:.3} dB, 90th percentile {:.3} dB",
        s.n, s.one_side, s.median, s.p90
    );
    s
}

#[test]
fn path_gains_match_sionna_rt() {
    let Summary {
        n,
        median,
        p90,
        one_side,
        ..
    } = compare("sionna_paths.csv", "LOS + specular", false, false);
    // Measured: median 0.000 dB, 90th percentile 0.005 dB, no link one-sided.
    assert!(n >= 50, "{n}");
    assert!(median <= 0.1, "median {median}");
    assert!(p90 <= 0.5, "90th percentile {p90}");
    assert_eq!(one_side, 0, "links with paths on one side only");
}

#[test]
fn path_gains_with_transmission_match_sionna_rt() {
    let Summary {
        n,
        median,
        p90,
        one_side,
        ..
    } = compare(
        "sionna_paths_refraction.csv",
        "with transmission",
        true,
        false,
    );
    // Measured: median 0.000 dB, 90th percentile 0.093 dB over 100 links. One munich link
    // (rx (33.1, -97.5)) has one path of ours at -112.9 dB through walls where Sionna finds none:
    // allowed, and no more.
    assert!(n >= 80, "{n}");
    assert!(median <= 0.1, "median {median}");
    assert!(p90 <= 0.5, "90th percentile {p90}");
    assert!(
        one_side <= 1,
        "{one_side} links with paths on one side only"
    );
}

#[test]
fn path_gains_at_depth_five_match_sionna_rt() {
    let Summary {
        n,
        median,
        p90,
        one_side,
        ..
    } = compare("sionna_paths_depth5.csv", "depth 5", false, false);
    // Measured: median 0.000 dB, 90th percentile 0.116 dB over 85 links, none one-sided.
    assert!(n >= 80, "{n}");
    assert!(median <= 0.1, "median {median}");
    assert!(p90 <= 0.5, "90th percentile {p90}");
    assert_eq!(one_side, 0, "links with paths on one side only");
}

#[test]
fn path_gains_at_depth_eight_match_sionna_rt() {
    let Summary {
        n,
        median,
        p90,
        one_side,
        ..
    } = compare("sionna_paths_depth8.csv", "depth 8", false, false);
    // Measured: median 0.001 dB, 90th percentile 0.179 dB over 92 links. At depth 8 a link's
    // only path can be one eight-bounce sequence that one shooter's 10^6 rays find and the
    // other's miss: two munich links have one such path of ours (-147.3 and -106.7 dB) and none
    // of Sionna's. Allowed, and no more.
    assert!(n >= 80, "{n}");
    assert!(median <= 0.1, "median {median}");
    assert!(p90 <= 0.5, "90th percentile {p90}");
    assert!(
        one_side <= 2,
        "{one_side} links with paths on one side only"
    );
}

#[test]
fn path_gains_with_diffraction_against_sionna_rt() {
    let Summary {
        n,
        median,
        p90,
        one_side,
        scenes,
    } = compare(
        "sionna_paths_diffraction.csv",
        "with diffraction",
        false,
        true,
    );
    // Not a match everywhere yet (issue 17). Measured since diffraction chains with reflections
    // before and after the edge, as Sionna's does: median 0.139 dB and 90th percentile 4.12 dB
    // over 109 links, 17 of 130 one-sided (first order alone: 0.150 / 6.30 dB, 19 one-sided;
    // before wedges came from the faces' geometry: 91 links, 34 one-sided, 6.41 dB). What is
    // left is munich's: Sionna ignores edges between two shapes (its walls and roofs are
    // separate meshes) where we diffract, so links there get paths it has not. These bounds
    // hold today's figures, so that a regression shows; they are not the target (median and
    // 90th percentile <= 0.5 dB).
    assert!(n >= 100, "{n}");
    assert!(median <= 0.5, "median {median}");
    assert!(p90 <= 4.5, "90th percentile {p90}");
    assert!(
        one_side <= 18,
        "{one_side} links with paths on one side only"
    );
    // In the street canyon every wedge is inside one shape, so the models coincide: median
    // 0.113 dB, 90th percentile 2.37 dB (0.216 / 4.32 with first-order diffraction alone).
    let canyon = &scenes["simple_street_canyon"];
    assert_eq!(canyon.one_side, 0, "one-sided links in the canyon");
    assert!(canyon.median <= 0.15, "canyon median {}", canyon.median);
    assert!(canyon.p90 <= 3.0, "canyon 90th percentile {}", canyon.p90);
    // With Sionna's wedges (within one shape only) munich comes to the canyon's figures:
    // measured 107 links, 3 one-sided, median 0.082 dB, 90th percentile 2.95 dB (munich alone
    // with ours: 18 one-sided, 7.63 dB; 2026-11-26).
    let within = compare_with(
        "sionna_paths_diffraction.csv",
        "with diffraction, wedges within shapes",
        false,
        true,
        false,
    );
    assert!(within.n >= 100, "{}", within.n);
    assert!(within.median <= 0.15, "median {}", within.median);
    assert!(within.p90 <= 3.3, "90th percentile {}", within.p90);
    assert!(within.one_side <= 4, "{} one-sided", within.one_side);
}

/// First-order edge diffraction alone around one closed box (marble, then metal), against
/// tests/fixtures/sionna_wedge.csv (scripts/sionna_wedge_fixture.py): two transmitters, receivers
/// on a circle round the box at 1.5 m and 12 m, lit, grazing and deep-shadow geometries over its
/// vertical corners and roof edges.
#[test]
fn path_gains_over_one_box_match_sionna_rt() {
    let mut r = csv::Reader::from_path(fixture("sionna_wedge.csv")).unwrap();
    let mut groups: BTreeMap<String, Vec<(LinkEndsRow, f64)>> = BTreeMap::new();
    for rec in r.records() {
        let rec = rec.unwrap();
        let f = |i: usize| -> f64 { rec[i].parse().unwrap() };
        let db = if &rec[8] == "-inf" {
            f64::NEG_INFINITY
        } else {
            f(8)
        };
        groups
            .entry(rec[0].to_string())
            .or_default()
            .push((([f(1), f(2), f(3)], [f(4), f(5), f(6)]), db));
    }
    let opt = TraceOptions {
        finite_faces: false,
        ..diffraction_only(100_000)
    };
    let ant = Antenna::default();
    for (name, rows) in &groups {
        let rf = fixture_box(name);
        let links: Vec<_> = rows.iter().map(|r| r.0).collect();
        let ours = trace_links(&rf, &links, &ant, &ant, &opt, 3.5e9);
        let (mut diffs, mut one_side) = (Vec::new(), 0);
        for ((l, sionna), got) in rows.iter().zip(&ours) {
            match (sionna.is_finite(), got.gain_db.is_finite()) {
                (true, true) => diffs.push((got.gain_db - sionna).abs()),
                (false, false) => {}
                _ => one_side += 1,
            }
            if !(sionna.is_finite() && got.gain_db.is_finite())
                || (got.gain_db - sionna).abs() > 1.0
            {
                println!(
                    "{name}: tx {:?} rx {:?}: Sionna {sionna:.2} dB, ours {:.2} dB ({} paths)",
                    l.0,
                    l.1,
                    got.gain_db,
                    got.paths.len()
                );
            }
        }
        let n = diffs.len();
        let median = percentile(&mut diffs, 0.5);
        let p90 = percentile(&mut diffs, 0.9);
        println!(
            "box, {name}: {n} links compared, {one_side} with paths on one side only; |difference| median {median:.3} dB, 90th percentile {p90:.3} dB"
        );
        // Not a match yet (issue 17). Measured: marble median 0.86 dB, 90th percentile 8.43
        // (1.74 and 8.28 with face factors square to the edge only); metal 1.09 and 7.73; every
        // link diffracted on both sides. The two tracers find the same edges and now take the
        // same face factors (each face's reflection at the incident ray's angle, in rotated
        // bases); they combine them differently: Sionna RT 2.2 sums R0 (D1 - D4) + Rn (D2 - D3),
        // with Rn = -I where the n-face is unlit; ours is Kouyoumjian-Pathak with Luebbers' D1 + D2
        // - Rn D3 - R0 D4. On metal the largest gaps are lit-region links near the incident shadow
        // boundary (tx (40, 30, 20), rx (-23.8, 19.1, 1.5): Sionna -113.3 dB, ours -99.7 dB,
        // which is what the PEC soft coefficient |D1 + D2 - D3 - D4| = 0.41 gives by hand), at a
        // corner whose n-face the transmitter does not light: there Sionna's sum leaves the exact
        // solution and ours follows it (diffraction_by_a_conducting_wedge_against_the_exact_solution).
        // These bounds hold today's figures so that a regression shows; they are not the target.
        assert!(n >= 140, "{name}: {n}");
        assert_eq!(one_side, 0, "{name}: links with paths on one side only");
        assert!(median <= 2.0, "{name}: median {median}");
        assert!(p90 <= 9.0, "{name}: 90th percentile {p90}");
    }
}

type LinkEndsRow = ([f64; 3], [f64; 3]);

/// The box of scripts/sionna_wedge_fixture.py (x, y in [0, 20], z in [0, 30]) in the fixture's
/// material `name`, at 3.5 GHz.
fn fixture_box(name: &str) -> RfScene {
    use kodama_nodes::artifact::Material;
    use kodama_nodes::artifact::{ObjectClass, Scene, SceneObject};
    use kodama_nodes::geom::mesh_build::cuboid;
    let material = match name {
        "marble" => Material::Marble,
        "metal" => Material::Metal,
        other => panic!("no material {other}"),
    };
    let scene = Scene {
        objects: vec![SceneObject {
            id: "box".into(),
            class: ObjectClass::Building,
            mesh: cuboid([10.0, 10.0], [20.0, 20.0, 30.0], 0.0, 0.0, material),
        }],
    };
    RfScene::new(&scene, 3.5e9, false).unwrap()
}

/// Edge diffraction in radio maps around the same box (marble, then metal), against Sionna RT
/// 2.2's RadioMapSolver with diffraction alone: tests/fixtures/sionna_wedge_map.csv
/// (scripts/sionna_wedge_map_fixture.py), 2 m cells at 1.5 m round the box.
#[test]
fn radio_map_diffraction_over_one_box_against_sionna_rt() {
    use kodama_nodes::artifact::Grid;
    use kodama_nodes::rf::map_plane::MapPlane;
    use kodama_nodes::rf::radiomap::radio_map;
    let mut r = csv::Reader::from_path(fixture("sionna_wedge_map.csv")).unwrap();
    let mut groups: BTreeMap<String, Vec<(u32, u32, f64)>> = BTreeMap::new();
    for rec in r.records() {
        let rec = rec.unwrap();
        groups.entry(rec[0].to_string()).or_default().push((
            rec[1].parse().unwrap(),
            rec[2].parse().unwrap(),
            rec[5].parse().unwrap(),
        ));
    }
    let plane = MapPlane::plane(
        Grid {
            x0: -40.0,
            y0: 60.0,
            cell_m: 2.0,
            width: 50,
            height: 50,
        },
        1.5,
    );
    let opt = TraceOptions {
        finite_faces: false,
        ..diffraction_only(4_000_000)
    };
    let tx = glam::DVec3::new(40.0, 30.0, 20.0);
    for (name, cells) in &groups {
        let rf = fixture_box(name);
        let map = radio_map(&rf, tx, &Antenna::default(), &plane, &opt, 3.5e9);
        let Agreement {
            n,
            one_side,
            median,
            p90,
            bias,
        } = agreement(cells, |c, row| reached_db(&map, c, row));
        println!(
            "box map, {name}: {n} cells compared, {one_side} reached by one side only; ours - \
             Sionna median {bias:+.3} dB, |difference| median {median:.3} dB, 90th percentile \
             {p90:.3} dB"
        );
        // The map's estimator agrees with our own links cell by cell (rf_trace.rs,
        // a_diffracted_radio_map_is_the_mean_of_the_diffracted_paths); what is left here is the
        // coefficients' difference the link check above shows (ARCHITECTURE.md). Measured: marble
        // median -0.07 dB, |difference| median 0.89, 90th percentile 4.78; metal -0.42, 1.18,
        // 7.94; one cell reached on one side only. Regression bounds, not the target.
        let (max_median, max_p90) = if name == "metal" {
            (1.5, 9.0)
        } else {
            (1.2, 5.5)
        };
        assert!(n >= 2390, "{name}: {n} cells");
        assert!(one_side <= 3, "{name}: {one_side} cells on one side only");
        assert!(bias.abs() <= 0.8, "{name}: median difference {bias}");
        assert!(median <= max_median, "{name}: median {median}");
        assert!(p90 <= max_p90, "{name}: 90th percentile {p90}");
    }
}

/// Specular and diffuse reflection in radio maps, against Sionna RT 2.2's RadioMapSolver on its
/// street canyon: tests/fixtures/sionna_diffuse_map.csv (scripts/sionna_diffuse_map_fixture.py),
/// every surface with S = 0.5 (Lambertian), line of sight, specular and diffuse reflection to
/// depth 2, 2 m cells at 1.5 m. Both are Monte Carlo estimates of the same sum (Sionna's event
/// probabilities: specular r (1 - S²), diffuse r S²).
#[test]
fn radio_map_with_diffuse_reflection_against_sionna_rt() {
    use kodama_nodes::artifact::Grid;
    use kodama_nodes::rf::map_plane::MapPlane;
    use kodama_nodes::rf::radiomap::radio_map;
    let cells = map_cells("sionna_diffuse_map.csv");
    let rf = sionna_scene("simple_street_canyon");
    let plane = MapPlane::plane(
        Grid {
            x0: -50.0,
            y0: 30.0,
            cell_m: 2.0,
            width: 50,
            height: 30,
        },
        1.5,
    );
    let opt = TraceOptions {
        max_depth: 2,
        los: true,
        reflection: true,
        transmission: false,
        diffuse: true,
        scattering_coefficient: 0.5,
        rays: 4_000_000,
        ..Default::default()
    };
    let tx = glam::DVec3::new(-33.0, 0.0, 32.0);
    let map = radio_map(&rf, tx, &Antenna::default(), &plane, &opt, 3.5e9);
    let Agreement {
        n,
        one_side,
        median,
        p90,
        bias,
    } = agreement(&cells, |c, row| reached_db(&map, c, row));
    println!(
        "street canyon map, specular + diffuse (S 0.5, depth 2): {n} cells compared, {one_side} \
         reached by one side only; ours - Sionna median {bias:+.3} dB, |difference| median \
         {median:.3} dB, 90th percentile {p90:.3} dB"
    );
    assert!(n >= 800, "{n} cells");
    assert!(one_side <= 20, "{one_side} cells reached by one side only");
    assert!(bias.abs() < 0.5, "bias {bias}");
    assert!(median < MAP_DIFFUSE_MEDIAN_DB, "median {median}");
    assert!(p90 < MAP_DIFFUSE_P90_DB, "p90 {p90}");
}

/// Bounds of the diffuse map's agreement with Sionna's, above what was measured (4 x 10^6 rays
/// against Sionna's 10^7 samples: 857 cells, 6 one-sided, median difference -0.007 dB,
/// |difference| median 0.074 dB, 90th percentile 1.455 dB; the spread is the two estimators'
/// Monte Carlo noise in the weakest cells).
const MAP_DIFFUSE_MEDIAN_DB: f64 = 0.25;
const MAP_DIFFUSE_P90_DB: f64 = 2.5;

/// Radio maps at the paper's settings against Sionna RT 2.2 on munich: 12 interactions, LOS,
/// specular and diffuse reflection (S = 0.3), refraction and diffraction (Sionna's edges, its
/// unbounded faces), 5 m cells at 1.5 m over Sionna's default plane.
/// tests/fixtures/sionna_munich_map_d12.csv (scripts/sionna_munich_map_fixture.py) holds the
/// cells where Sionna's 10^7- and 10^8-sample maps agree within 1 dB. A map this deep is a Monte
/// Carlo estimate whose far cells few rare paths reach: each tracer against itself, 10^7 against
/// 10^8 rays, differs over all cells by a median 2.8-2.9 dB and a 90th percentile of 15-16 dB,
/// which is also what ours against Sionna's gives there. So the comparison is over the cells
/// where both have converged: the fixture's, where our own 10^7- and 10^8-ray maps agree within
/// 1 dB too.
#[test]
fn radio_map_at_depth_twelve_against_sionna_rt() {
    use kodama_nodes::rf::map_plane::default_plane;
    use kodama_nodes::rf::radiomap::radio_map;
    let cells = map_cells("sionna_munich_map_d12.csv");
    let rf = sionna_scene("munich");
    let plane = default_plane(&rf, 5.0, 1.5);
    assert_eq!((plane.grid.width, plane.grid.height), (296, 242));
    let opt = |rays: u32| TraceOptions {
        max_depth: 12,
        los: true,
        reflection: true,
        transmission: true,
        diffraction: true,
        diffuse: true,
        scattering_coefficient: 0.3,
        rays,
        wedges_across_objects: false,
        finite_faces: false,
        ..Default::default()
    };
    let tx = glam::DVec3::new(8.5, 21.0, 27.0);
    let map = |rays| radio_map(&rf, tx, &Antenna::default(), &plane, &opt(rays), 3.5e9);
    let (coarse, fine) = (map(10_000_000), map(100_000_000));
    // Our value where our own two maps agree within 1 dB; a cell where they do not counts as
    // one we have not reached.
    let converged = |c, row| {
        let (a, b) = (reached_db(&coarse, c, row)?, reached_db(&fine, c, row)?);
        ((a - b).abs() < 1.0).then_some(b)
    };
    let Agreement {
        n,
        median,
        p90,
        bias,
        ..
    } = agreement(&cells, converged);
    println!(
        "munich map at depth 12 (LOS, specular + diffuse S 0.3, refraction, diffraction): {n} of \
         {} converged Sionna cells converged here too; ours - Sionna median {bias:+.3} dB, \
         |difference| median {median:.3} dB, 90th percentile {p90:.3} dB",
        cells.len()
    );
    // Issue 54's target: median |difference| <= 0.5 dB, 90th percentile <= 3 dB.
    assert!(n >= 3000, "{n} cells");
    assert!(bias.abs() < 0.25, "bias {bias}");
    assert!(median <= 0.5, "median {median}");
    assert!(p90 <= 3.0, "p90 {p90}");
}

/// A map fixture's cells: column, row (row 0 at the north edge) and Sionna's path gain in dB
/// (-inf where no sample landed), from the columns `col, row, x, y, path_gain_db`.
fn map_cells(file: &str) -> Vec<(u32, u32, f64)> {
    let mut r = csv::Reader::from_path(fixture(file)).unwrap();
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            (
                rec[0].parse().unwrap(),
                rec[1].parse().unwrap(),
                rec[4].parse().unwrap(),
            )
        })
        .collect()
}

/// One of Sionna's own scenes at 3.5 GHz, every material at Sionna's default 0.1 m slab (what
/// its scene files give).
fn sionna_scene(name: &str) -> RfScene {
    let xml = shared(&format!("sionna-scenes/{name}/{name}.xml"));
    RfScene::new(&read_scene(&xml).unwrap(), 3.5e9, false)
        .unwrap()
        .with_uniform_thickness(kodama_nodes::rf::scene::SLAB_THICKNESS_M)
}

/// A map's path gain in dB at a cell, `None` where no ray arrived.
fn reached_db(map: &kodama_nodes::artifact::Raster, col: u32, row: u32) -> Option<f64> {
    let v = map.at(col, row) as f64;
    (v > 0.0).then(|| 10.0 * v.log10())
}

/// How a map agrees with Sionna's cells.
struct Agreement {
    /// Cells both reach.
    n: usize,
    /// Cells one side reaches and the other does not.
    one_side: usize,
    /// |ours - Sionna|: median and 90th percentile, dB.
    median: f64,
    p90: f64,
    /// Median of ours - Sionna, dB.
    bias: f64,
}

/// `ours` (dB at a cell, `None` where not reached) against Sionna's `cells`.
fn agreement(cells: &[(u32, u32, f64)], ours: impl Fn(u32, u32) -> Option<f64>) -> Agreement {
    let (mut diffs, mut signed, mut one_side) = (Vec::new(), Vec::new(), 0);
    for &(c, row, sionna) in cells {
        match (sionna.is_finite(), ours(c, row)) {
            (true, Some(o)) => {
                signed.push(o - sionna);
                diffs.push((o - sionna).abs());
            }
            (false, None) => {}
            _ => one_side += 1,
        }
    }
    Agreement {
        n: diffs.len(),
        one_side,
        median: percentile(&mut diffs, 0.5),
        p90: percentile(&mut diffs, 0.9),
        bias: percentile(&mut signed, 0.5),
    }
}

/// Edge diffraction by a perfectly conducting wedge against its exact solution, with Sionna RT
/// beside it: tests/fixtures/pec_wedge.csv (scripts/pec_wedge_fixture.py). The reference is
/// neither tracer: the eigenfunction series of the infinite wedge, whose diffracted field gives
/// the exact coefficient D(φ, φ'), applied with a point source's spreading. Two wedges (n = 1.5,
/// a building's corner; n = 1.75, 45° inside), a source lighting both faces and one lighting
/// face 0 only, both polarisations; our defaults, diffraction alone.
#[test]
fn diffraction_by_a_conducting_wedge_against_the_exact_solution() {
    let mut r = csv::Reader::from_path(fixture("pec_wedge.csv")).unwrap();
    // (n, φ'/π, polarisation) -> (tx, rx, exact dB, Sionna dB) per receiver.
    type Case = (String, String, String);
    let mut cases: BTreeMap<Case, Vec<LinkEndsRow>> = BTreeMap::new();
    let mut refs: BTreeMap<Case, Vec<(f64, f64)>> = BTreeMap::new();
    for rec in r.records() {
        let rec = rec.unwrap();
        let f = |i: usize| -> f64 { rec[i].parse().unwrap() };
        let key = (rec[0].to_string(), rec[1].to_string(), rec[3].to_string());
        cases
            .entry(key.clone())
            .or_default()
            .push(([f(4), f(5), f(6)], [f(7), f(8), f(9)]));
        refs.entry(key).or_default().push((f(10), f(11)));
    }
    let opt = diffraction_only(100_000);
    let (mut ours_all, mut sionna_all) = (Vec::new(), Vec::new());
    for (key, links) in &cases {
        let (n, phi_s, pol) = key;
        let rf = conducting_wedge(n.parse().unwrap());
        let ant = iso_antenna(pol);
        let got = trace_links(&rf, links, &ant, &ant, &opt, 3.5e9);
        let (mut ours, mut sionna) = (Vec::new(), Vec::new());
        for (g, (exact, s)) in got.iter().zip(&refs[key]) {
            ours.push((g.gain_db - exact).abs());
            sionna.push((s - exact).abs());
        }
        ours_all.extend_from_slice(&ours);
        sionna_all.extend_from_slice(&sionna);
        let n_links = ours.len();
        let (om, o90) = (percentile(&mut ours, 0.5), percentile(&mut ours, 0.9));
        let (sm, s90) = (percentile(&mut sionna, 0.5), percentile(&mut sionna, 0.9));
        println!(
            "wedge n {n}, φ' {phi_s}π, {pol}: {n_links} receivers; |ours - exact| median {om:.3} dB, \
             90th percentile {o90:.3} dB; |Sionna RT - exact| median {sm:.3} dB, 90th percentile \
             {s90:.3} dB"
        );
        // Measured: medians 0.000-0.007 dB, 90th percentiles 0.001-0.153 dB. Sionna RT 2.2
        // matches the exact field only for V with both faces lit; elsewhere medians 4.2-11.5 dB.
        assert_eq!(n_links, 25, "{key:?}");
        assert!(
            om <= 0.02 && o90 <= 0.3,
            "{key:?}: ours median {om}, p90 {o90}"
        );
    }
    let (om, o90) = (
        percentile(&mut ours_all, 0.5),
        percentile(&mut ours_all, 0.9),
    );
    let (sm, s90) = (
        percentile(&mut sionna_all, 0.5),
        percentile(&mut sionna_all, 0.9),
    );
    println!(
        "conducting wedges, all {} links: |ours - exact| median {om:.3} dB, 90th percentile \
         {o90:.3} dB; |Sionna RT - exact| median {sm:.3} dB, 90th percentile {s90:.3} dB",
        ours_all.len()
    );
    assert!(
        om < sm && o90 < s90,
        "ours is no closer to the exact solution than Sionna RT"
    );
}

/// Edge diffraction by lossy wedges against Maliuzhinets' exact solution, with Sionna RT beside
/// it: tests/fixtures/impedance_wedge.csv (scripts/impedance_wedge_fixture.py). The reference is
/// neither tracer: the far-field coefficient of the impedance wedge, its faces the Leontovich
/// impedance of the material's half-space. The wedges of the conducting test in ITU wet ground
/// and concrete (slabs 2 m thick, so both tracers reflect as a half-space), receivers at least
/// 0.06 π from every shadow boundary (where the far field is the whole diffracted field).
/// `luebbers` is Luebbers' heuristic with the reference's own faces, computed by the script.
#[test]
fn diffraction_by_a_lossy_wedge_against_maliuzhinets() {
    use kodama_nodes::artifact::Material;
    let mut r = csv::Reader::from_path(fixture("impedance_wedge.csv")).unwrap();
    // (material, n, φ'/π, polarisation) -> links, and (exact, Luebbers, Sionna) dB per link.
    type Case = (String, String, String, String);
    let mut cases: BTreeMap<Case, Vec<LinkEndsRow>> = BTreeMap::new();
    let mut refs: BTreeMap<Case, Vec<[f64; 3]>> = BTreeMap::new();
    for rec in r.records() {
        let rec = rec.unwrap();
        let f = |i: usize| -> f64 { rec[i].parse().unwrap() };
        let key = (
            rec[0].to_string(),
            rec[1].to_string(),
            rec[2].to_string(),
            rec[4].to_string(),
        );
        cases
            .entry(key.clone())
            .or_default()
            .push(([f(5), f(6), f(7)], [f(8), f(9), f(10)]));
        refs.entry(key).or_default().push([f(11), f(12), f(13)]);
    }
    let opt = diffraction_only(100_000);
    let mut all: BTreeMap<&str, [Vec<f64>; 3]> = BTreeMap::new();
    for (key, links) in &cases {
        let (material, n, phi_s, pol) = key;
        let m = match material.as_str() {
            "wet_ground" => Material::WetGround,
            "concrete" => Material::Concrete,
            other => panic!("material {other}"),
        };
        let rf = prism_wedge(n.parse().unwrap(), m).with_thickness(m, 2.0);
        let ant = iso_antenna(pol);
        let got = trace_links(&rf, links, &ant, &ant, &opt, 3.5e9);
        let mut errs: [Vec<f64>; 3] = Default::default();
        for (g, [exact, lue, sionna]) in got.iter().zip(&refs[key]) {
            errs[0].push((g.gain_db - exact).abs());
            errs[1].push((sionna - exact).abs());
            errs[2].push((lue - exact).abs());
        }
        let totals = all.entry(material.as_str()).or_default();
        for (t, e) in totals.iter_mut().zip(&errs) {
            t.extend_from_slice(e);
        }
        let [o, s, l] = errs.map(|mut e| (percentile(&mut e, 0.5), percentile(&mut e, 0.9)));
        println!(
            "{material} wedge n {n}, φ' {phi_s}π, {pol}: {} receivers; |ours - exact| median \
             {:.3} dB, 90th percentile {:.3} dB; |Sionna RT - exact| {:.3} / {:.3} dB; \
             |Luebbers - exact| {:.3} / {:.3} dB",
            links.len(),
            o.0,
            o.1,
            s.0,
            s.1,
            l.0,
            l.1
        );
    }
    for (material, errs) in &mut all {
        let [o, s, l] = errs
            .each_mut()
            .map(|e| (percentile(e, 0.5), percentile(e, 0.9)));
        println!(
            "{material} wedges, all {} links: |ours - exact| median {:.3} dB, 90th percentile \
             {:.3} dB; |Sionna RT - exact| {:.3} / {:.3} dB; |Luebbers - exact| {:.3} / {:.3} dB",
            errs[0].len(),
            o.0,
            o.1,
            s.0,
            s.1,
            l.0,
            l.1
        );
        // Measured: wet ground 2.037 / 11.308 dB (Sionna RT 4.013 / 14.109), concrete 3.456 /
        // 15.509 dB (4.195 / 17.685). Neither heuristic follows the exact solution: both are
        // within a dB of it only where both faces are lit (ours) or for V with one face lit
        // (Sionna's); a regression bound, and ours the closer over each material's links.
        let (bound_median, bound_p90) = match *material {
            "wet_ground" => (2.3, 12.0),
            _ => (3.8, 16.2),
        };
        assert!(
            o.0 <= bound_median && o.1 <= bound_p90,
            "{material}: ours median {} dB, 90th percentile {} dB",
            o.0,
            o.1
        );
        assert!(
            o.0 < s.0 && o.1 < s.1,
            "{material}: ours is no closer to Maliuzhinets' solution than Sionna RT"
        );
    }
}

/// The isotropic antenna polarised as a fixture's column names it (`V` or `H`).
fn iso_antenna(pol: &str) -> Antenna {
    use kodama_nodes::rf::antenna::Polarization;
    Antenna {
        polarization: if pol == "V" {
            Polarization::V
        } else {
            Polarization::H
        },
        ..Antenna::default()
    }
}

/// The closed metal prism of scripts/pec_wedge_fixture.py: its edge the z axis, face 0 along -y,
/// face n at n π from it, both 400 m long, 600 m tall.
fn conducting_wedge(n: f64) -> RfScene {
    prism_wedge(n, kodama_nodes::artifact::Material::Metal)
}

/// The prism wedge of `conducting_wedge` made of `material`.
fn prism_wedge(n: f64, material: kodama_nodes::artifact::Material) -> RfScene {
    use kodama_nodes::artifact::{ObjectClass, Polygon, Scene, SceneObject};
    use kodama_nodes::geom::mesh_build::prism;
    let world = |a: f64| {
        let t = a - std::f64::consts::FRAC_PI_2;
        [400.0 * t.cos(), 400.0 * t.sin()].map(|c| (c * 1e9).round() / 1e9)
    };
    // Counter-clockwise seen from above.
    let exterior = vec![[0.0, 0.0], world(n * std::f64::consts::PI), world(0.0)];
    let poly = Polygon {
        exterior,
        holes: vec![],
    };
    let mesh = prism(&poly, -300.0, 300.0, material, material).unwrap();
    let scene = Scene {
        objects: vec![SceneObject {
            id: "wedge".into(),
            class: ObjectClass::Building,
            mesh,
        }],
    };
    RfScene::new(&scene, 3.5e9, false).unwrap()
}
