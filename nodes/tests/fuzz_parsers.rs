//! Fuzzing the readers (issue 19): a valid seed file of each format, mutated (bytes flipped,
//! inserted, cut, overwritten with NaN, infinities and huge counts), must give `Ok` or an error,
//! never a panic, an abort or a hang.
//!
//! `cargo test` runs a bounded number of cases per target through proptest (64, or
//! `PROPTEST_CASES`); `scripts/fuzz.sh` runs the ignored `soak` test for a fixed time per target
//! and prints how many cases ran and how many panicked.

mod common;
mod hostile;
use common::*;
use hostile::*;

use std::path::{Path, PathBuf};

use kodama_nodes::{Ctx, Inputs, Stage};
use proptest::prelude::*;
use serde_json::{Value, json};

/// One change to a seed file.
#[derive(Clone, Debug)]
enum Mutation {
    /// Byte at (position modulo length) set.
    Set(usize, u8),
    /// Bytes inserted at a position.
    Insert(usize, Vec<u8>),
    /// A range removed.
    Remove(usize, usize),
    /// The file cut at a position.
    Truncate(usize),
    /// 8 bytes at a position overwritten with a hostile value.
    Value(usize, u8),
}

/// Values that break readers that trust them: NaN, infinities, zero, the largest counts.
fn hostile_value(k: u8) -> [u8; 8] {
    match k % 8 {
        0 => f64::NAN.to_le_bytes(),
        1 => f64::INFINITY.to_le_bytes(),
        2 => f64::NEG_INFINITY.to_le_bytes(),
        3 => 0u64.to_le_bytes(),
        4 => u64::MAX.to_le_bytes(),
        5 => (u32::MAX as u64 | (u32::MAX as u64) << 32).to_le_bytes(),
        6 => {
            let mut b = f32::NAN.to_le_bytes().to_vec();
            b.extend(f32::INFINITY.to_le_bytes());
            b.try_into().unwrap()
        }
        _ => 1e300f64.to_le_bytes(),
    }
}

fn apply(seed: &[u8], ms: &[Mutation]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for m in ms {
        let n = b.len().max(1);
        match m {
            Mutation::Set(at, v) => {
                if !b.is_empty() {
                    b[at % n] = *v;
                }
            }
            Mutation::Insert(at, bytes) => {
                let at = at % (b.len() + 1);
                b.splice(at..at, bytes.iter().copied());
            }
            Mutation::Remove(at, len) => {
                let at = at % n;
                let end = (at + len % 64).min(b.len());
                if at < end {
                    b.drain(at..end);
                }
            }
            Mutation::Truncate(at) => b.truncate(at % n),
            Mutation::Value(at, k) => {
                let at = at % n;
                for (i, v) in hostile_value(*k).into_iter().enumerate() {
                    if let Some(x) = b.get_mut(at + i) {
                        *x = v;
                    }
                }
            }
        }
    }
    b
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), any::<u8>()).prop_map(|(a, v)| Mutation::Set(a, v)),
        1 => (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(a, v)| Mutation::Insert(a, v)),
        1 => (any::<usize>(), any::<usize>()).prop_map(|(a, l)| Mutation::Remove(a, l)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
        3 => (any::<usize>(), any::<u8>()).prop_map(|(a, k)| Mutation::Value(a, k)),
    ]
}

/// Mutations biased to a file's first `head` bytes, where headers and their counts live.
fn mutations(head: usize) -> impl Strategy<Value = Vec<Mutation>> {
    proptest::collection::vec(mutation(), 1..6).prop_map(move |ms| {
        ms.into_iter()
            .enumerate()
            .map(|(i, m)| match m {
                Mutation::Set(a, v) if i % 2 == 0 => Mutation::Set(a % head, v),
                Mutation::Value(a, k) if i % 2 == 0 => Mutation::Value(a % head, k),
                m => m,
            })
            .collect()
    })
}

fn run_stage<S: Stage>(params: Value, files: &[PathBuf]) {
    let p: S::Params = serde_json::from_value(params).unwrap();
    let site = site();
    if S::validate(&p).is_ok() {
        let _ = S::run(&p, &Inputs::new(), &Ctx::new(&site, files));
    }
}

/// A fuzz target: its name, its seed file, how many of its first bytes form the header, and how
/// it reads a mutated copy placed in a folder.
struct Target {
    name: &'static str,
    seed: fn() -> Vec<u8>,
    head: usize,
    read: fn(&Path, &[u8]),
}

fn seed_ply() -> Vec<u8> {
    let (p, t) = tetra();
    kodama_nodes::io::sionna_xml::write_ply(&p, &t)
}

fn read_ply(dir: &Path, bytes: &[u8]) {
    write(dir, "meshes/buildings.ply", bytes);
    let xml = write(dir, "scene.xml", SCENE_XML);
    let _ = kodama_nodes::io::sionna_xml::read_scene(&xml);
}

fn read_xml(dir: &Path, bytes: &[u8]) {
    write(dir, "meshes/buildings.ply", seed_ply());
    let xml = write(dir, "scene.xml", bytes);
    let _ = kodama_nodes::io::sionna_xml::read_scene(&xml);
}

fn read_glb(dir: &Path, bytes: &[u8]) {
    write(dir, "tiles/a.glb", bytes);
    write(dir, "tiles/tileset.json", TILESET);
    run_stage::<kodama_nodes::stages::ingest::read_tiles::ReadTileset>(
        json!({"path": "tiles/tileset.json", "crs": "EPSG:32618"}),
        &[dir.join("tiles")],
    );
}

fn seed_views() -> Vec<u8> {
    json!({
        "material_classes": ["glass", "brick"],
        "views": [{"id": "a", "image": "img.png", "width": 8, "height": 4,
                   "intrinsics": {"fx": 4, "fy": 4, "cx": 4, "cy": 2},
                   "pose": {"x": 0, "y": 0, "z": 2},
                   "orientation": {"quat_wxyz": [1, 0, 0, 0]},
                   "distortion": [0.1, 0.01]},
                  {"id": 2, "image": "img.png", "width": 8, "height": 4,
                   "intrinsics": {"hfov_deg": 90},
                   "pose": {"lat": 40.7, "lon": -74.0, "alt_m": 10},
                   "orientation": {"heading_deg": 90, "pitch_deg": 5}}]
    })
    .to_string()
    .into_bytes()
}

fn read_views(dir: &Path, bytes: &[u8]) {
    let img = dir.join("v/img.png");
    if !img.exists() {
        std::fs::create_dir_all(dir.join("v/material")).unwrap();
        image::RgbImage::new(8, 4).save(&img).unwrap();
        image::GrayImage::from_pixel(8, 4, image::Luma([1]))
            .save(dir.join("v/material/a.png"))
            .unwrap();
    }
    write(dir, "v/views.json", bytes);
    run_stage::<kodama_nodes::stages::ingest::read_views::ReadViews>(
        json!({"path": "v/views.json"}),
        &[dir.join("v")],
    );
}

fn seed_csv() -> Vec<u8> {
    b"tx_id,tx_x,tx_y,tx_z,rx_lat,rx_lon,rx_height_m,freq_hz,path_loss_db,rx_power_dbm,los\n\
      a,0,0,30,40.70,-74.00,1.5,3.5e9,100,,1\n\
      a,0,0,30,40.71,-74.01,1.5,3.5e9,,-80,0\n"
        .to_vec()
}

fn read_csv(dir: &Path, bytes: &[u8]) {
    let p = write(dir, "links.csv", bytes);
    run_stage::<kodama_nodes::stages::ingest::read_measurements::ReadMeasurements>(
        json!({"path": "links.csv"}),
        &[p],
    );
}

fn seed_las() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::read(las_file(dir.path(), "s.las", 20, false)).unwrap()
}

fn seed_laz() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::read(las_file(dir.path(), "s.laz", 200, true)).unwrap()
}

fn read_las(dir: &Path, bytes: &[u8]) {
    let p = write(dir, "p.las", bytes);
    run_stage::<kodama_nodes::stages::ingest::read_las::ReadLas>(
        json!({"path": "p.las", "crs": "EPSG:32618"}),
        &[p],
    );
}

fn seed_tiff() -> Vec<u8> {
    tiff(
        4,
        3,
        [1.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 583200.0, 4506600.0, 0.0],
    )
}

fn read_tiff(dir: &Path, bytes: &[u8]) {
    let p = write(dir, "dsm.tif", bytes);
    run_stage::<kodama_nodes::stages::ingest::read_raster::ReadRaster>(
        json!({"path": "dsm.tif", "crs": "EPSG:32618"}),
        &[p],
    );
}

fn read_osm_xml(dir: &Path, bytes: &[u8]) {
    let p = write(dir, "b.osm", bytes);
    run_stage::<kodama_nodes::stages::ingest::read_osm::ReadOsmBuildings>(
        json!({"path": "b.osm"}),
        &[p],
    );
}

const TARGETS: &[Target] = &[
    Target {
        name: "ply",
        seed: seed_ply,
        head: 200,
        read: read_ply,
    },
    Target {
        name: "sionna_xml",
        seed: || SCENE_XML.as_bytes().to_vec(),
        head: 400,
        read: read_xml,
    },
    Target {
        name: "glb",
        seed: || glb_with_x(1.0),
        head: 1200,
        read: read_glb,
    },
    Target {
        name: "views_json",
        seed: seed_views,
        head: 600,
        read: read_views,
    },
    Target {
        name: "measurements_csv",
        seed: seed_csv,
        head: 200,
        read: read_csv,
    },
    Target {
        name: "las_header",
        seed: seed_las,
        head: 240,
        read: read_las,
    },
    Target {
        name: "laz_header",
        seed: seed_laz,
        head: 400,
        read: read_las,
    },
    Target {
        name: "osm_xml",
        seed: || OSM_XML.as_bytes().to_vec(),
        head: 1600,
        read: read_osm_xml,
    },
    Target {
        name: "geotiff_tags",
        seed: seed_tiff,
        head: 250,
        read: read_tiff,
    },
];

fn target(name: &str) -> &'static Target {
    TARGETS.iter().find(|t| t.name == name).unwrap()
}

fn config() -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(64);
    ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn check(name: &str, ms: &[Mutation]) {
    let t = target(name);
    let seed = (t.seed)();
    let dir = tempfile::tempdir().unwrap();
    (t.read)(dir.path(), &apply(&seed, ms));
}

macro_rules! fuzz_target {
    ($fn_name:ident, $name:literal) => {
        proptest! {
            #![proptest_config(config())]
            #[test]
            fn $fn_name(ms in mutations(target($name).head)) {
                check($name, &ms);
            }
        }
    };
}

fuzz_target!(ply_never_panics, "ply");
fuzz_target!(sionna_xml_never_panics, "sionna_xml");
fuzz_target!(glb_never_panics, "glb");
fuzz_target!(views_json_never_panics, "views_json");
fuzz_target!(measurements_csv_never_panics, "measurements_csv");
fuzz_target!(las_header_never_panics, "las_header");
fuzz_target!(laz_header_never_panics, "laz_header");
fuzz_target!(geotiff_tags_never_panics, "geotiff_tags");
fuzz_target!(osm_xml_never_panics, "osm_xml");

/// The seeds themselves read (so the fuzzing starts from files the readers accept).
#[test]
fn every_seed_reads() {
    for t in TARGETS {
        let dir = tempfile::tempdir().unwrap();
        (t.read)(dir.path(), &(t.seed)());
    }
}

/// `FUZZ_TARGET` (or every target) for `FUZZ_SECONDS` each (default 10): mutations from a
/// seeded generator, every panic caught and counted. Prints `target: N cases, P panics` and fails
/// if any panicked. Run by `scripts/fuzz.sh`.
#[test]
#[ignore]
fn soak() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
    let seconds: u64 = std::env::var("FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10);
    let only = std::env::var("FUZZ_TARGET").ok();
    // Panics are counted, not printed per case; the last one's place is kept for the report.
    static LAST: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);
    std::panic::set_hook(Box::new(|info| {
        *LAST.lock().unwrap() = Some(info.to_string());
    }));
    let mut total_panics = 0;
    for t in TARGETS
        .iter()
        .filter(|t| only.as_deref().is_none_or(|o| o == t.name))
    {
        let seed = (t.seed)();
        let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[19; 32]);
        let mut runner = TestRunner::new_with_rng(Config::default(), rng);
        let strategy = mutations(t.head);
        let dir = tempfile::tempdir().unwrap();
        let start = std::time::Instant::now();
        let (mut cases, mut panics, mut slowest) = (0u64, 0u64, 0f64);
        let mut first_panic = None;
        while start.elapsed().as_secs() < seconds {
            let ms = strategy.new_tree(&mut runner).unwrap().current();
            let bytes = apply(&seed, &ms);
            let t0 = std::time::Instant::now();
            let ok = std::panic::catch_unwind(|| (t.read)(dir.path(), &bytes)).is_ok();
            slowest = slowest.max(t0.elapsed().as_secs_f64());
            cases += 1;
            if !ok {
                panics += 1;
                let at = LAST.lock().unwrap().take().unwrap_or_default();
                first_panic.get_or_insert((ms, at));
            }
        }
        println!(
            "{}: {cases} cases in {seconds} s, {panics} panics, slowest case {:.3} s",
            t.name, slowest
        );
        if let Some((ms, at)) = first_panic {
            println!("  first panicking mutations: {ms:?}\n  {at}");
        }
        total_panics += panics;
    }
    let _ = std::panic::take_hook();
    assert_eq!(total_panics, 0, "some inputs panicked");
}
