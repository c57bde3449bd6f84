//! Fuzz targets (issue 55, class 11): every reader of a file a user hands kodama-dag, and the RON
//! graph and sweep parsers, as a function of the file's bytes. Each must return (an artifact or
//! an error) for any bytes: no panic, no abort, no hang.
//!
//! Three drivers share these targets:
//! - `tests/corpus.rs` replays every file under `corpus/<target>/` (the seeds and what the
//!   coverage-guided campaign kept) and `crashes/<target>/` (inputs that once failed) on every
//!   `cargo test`;
//! - `tests/mutations.rs` mutates each target's seed through proptest (a bounded number of cases
//!   per `cargo test`, and a timed soak for `scripts/fuzz.sh`);
//! - `src/bin/afl.rs`, built by cargo-afl, is the coverage-guided campaign of
//!   `scripts/fuzz_afl.sh` (AFL++, 10 minutes a target).
//!
//! A target writes the bytes into a scratch folder beside the few fixed files the format refers
//! to (a scene's mesh, a tileset's tile, a view's image, a sweep's base graph: other targets'
//! seeds), then reads them the way a graph would.

use std::path::{Path, PathBuf};

use std::sync::OnceLock;

use kodama_nodes::{Ctx, Inputs, Site, Stage};
use serde_json::{Value, json};

/// Whether a target's reader accepted the file, and why not.
pub type Outcome = Result<(), String>;

/// A fuzz target: its name (its corpus folder's), how many of its seed's first bytes form the
/// header (where proptest's mutations aim half their changes), and how it reads a file's bytes
/// in a scratch folder.
pub struct Target {
    pub name: &'static str,
    pub head: usize,
    pub read: fn(&Path, &[u8]) -> Outcome,
}

/// Every target.
pub const TARGETS: &[Target] = &[
    Target {
        name: "ply",
        head: 200,
        read: read_ply,
    },
    Target {
        name: "sionna_xml",
        head: 400,
        read: read_sionna_xml,
    },
    Target {
        name: "glb",
        head: 1200,
        read: read_glb,
    },
    Target {
        name: "tileset_json",
        head: 300,
        read: read_tileset_json,
    },
    Target {
        name: "views_json",
        head: 600,
        read: read_views_json,
    },
    Target {
        name: "measurements_csv",
        head: 200,
        read: read_measurements_csv,
    },
    Target {
        name: "las",
        head: 240,
        read: read_las,
    },
    Target {
        name: "laz",
        head: 400,
        read: read_las,
    },
    Target {
        name: "geotiff",
        head: 250,
        read: read_geotiff,
    },
    Target {
        name: "osm_xml",
        head: 1600,
        read: read_osm_xml,
    },
    Target {
        name: "geojson",
        head: 400,
        read: read_geojson,
    },
    Target {
        name: "xyz",
        head: 100,
        read: read_xyz,
    },
    Target {
        name: "exr",
        head: 400,
        read: read_exr,
    },
    Target {
        name: "ron_graph",
        head: 400,
        read: read_ron_graph,
    },
    Target {
        name: "ron_sweep",
        head: 300,
        read: read_ron_sweep,
    },
];

/// The target named `name`.
pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

/// The folder of a target's committed corpus (its seed first, then what the campaign kept).
pub fn corpus_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(name)
}

/// The folder of a target's inputs that once panicked, aborted or hung: kept as regressions.
pub fn crashes_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crashes")
        .join(name)
}

/// The files of a corpus or crash folder, sorted (none when it does not exist).
pub fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && !is_note(p))
        .collect();
    files.sort();
    files
}

/// AFL++'s README.txt in a crash folder and our own notes are not inputs.
fn is_note(p: &Path) -> bool {
    p.extension().is_some_and(|e| e == "md" || e == "txt")
}

/// A target's seed: the corpus file whose name starts with `seed`.
pub fn seed(name: &str) -> std::io::Result<Vec<u8>> {
    let dir = corpus_dir(name);
    let path = files_in(&dir)
        .into_iter()
        .find(|p| {
            p.file_name()
                .is_some_and(|f| f.to_string_lossy().starts_with("seed"))
        })
        .ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no seed file in {}", dir.display()),
            )
        })?;
    std::fs::read(path)
}

/// The site every target reads into: the synthetic site's (EPSG:32618, Brooklyn).
pub fn site() -> Site {
    Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    }
}

/// Writes `bytes` to `dir/rel`, making its folder. A scratch folder that cannot be written is
/// the fuzzing machine's fault, not an input's: it stops the target.
pub fn write(dir: &Path, rel: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(rel);
    if let Some(parent) = p.parent() {
        std::fs::create_dir_all(parent).expect("the scratch folder is writable");
    }
    std::fs::write(&p, bytes).expect("the scratch folder is writable");
    p
}

/// Runs an ingest stage as the engine would: params validated first, the result dropped.
fn run_stage<S: Stage>(params: Value, files: &[PathBuf]) -> Outcome {
    let p: S::Params = serde_json::from_value(params).expect("a target's own params parse");
    let site = site();
    S::validate(&p).map_err(|e| format!("{}: {}", e.field, e.message))?;
    S::run(&p, &Inputs::new(), &Ctx::new(&site, files))
        .map(drop)
        .map_err(|e| e.to_string())
}

/// Another target's seed, as a file a target's input refers to: the PLY target's scene file is
/// the Sionna XML seed, the XML's mesh the PLY seed, the glb's tileset the tileset seed and so on.
fn fixed(name: &str) -> &'static [u8] {
    static SEEDS: OnceLock<Vec<(&'static str, Vec<u8>)>> = OnceLock::new();
    let seeds = SEEDS.get_or_init(|| {
        TARGETS
            .iter()
            .map(|t| (t.name, seed(t.name).expect("every target has a seed")))
            .collect()
    });
    &seeds.iter().find(|(n, _)| *n == name).expect("a target").1
}

fn read_ply(dir: &Path, bytes: &[u8]) -> Outcome {
    write(dir, "meshes/buildings.ply", bytes);
    let xml = write(dir, "scene.xml", fixed("sionna_xml"));
    kodama_nodes::io::sionna_xml::read_scene(&xml)
        .map(drop)
        .map_err(|e| e.to_string())
}

fn read_sionna_xml(dir: &Path, bytes: &[u8]) -> Outcome {
    write(dir, "meshes/buildings.ply", fixed("ply"));
    let xml = write(dir, "scene.xml", bytes);
    kodama_nodes::io::sionna_xml::read_scene(&xml)
        .map(drop)
        .map_err(|e| e.to_string())
}

fn read_tileset(dir: &Path) -> Outcome {
    run_stage::<kodama_nodes::stages::ingest::read_tiles::ReadTileset>(
        json!({"path": "tiles/tileset.json", "crs": "EPSG:32618"}),
        &[dir.join("tiles")],
    )
}

fn read_glb(dir: &Path, bytes: &[u8]) -> Outcome {
    write(dir, "tiles/a.glb", bytes);
    write(dir, "tiles/tileset.json", fixed("tileset_json"));
    read_tileset(dir)
}

fn read_tileset_json(dir: &Path, bytes: &[u8]) -> Outcome {
    write(dir, "tiles/a.glb", fixed("glb"));
    write(dir, "tiles/tileset.json", bytes);
    read_tileset(dir)
}

fn read_views_json(dir: &Path, bytes: &[u8]) -> Outcome {
    let img = dir.join("v/img.png");
    if !img.exists() {
        std::fs::create_dir_all(dir.join("v/material")).expect("the scratch folder is writable");
        image::RgbImage::new(8, 4)
            .save(&img)
            .expect("the scratch folder is writable");
        image::GrayImage::from_pixel(8, 4, image::Luma([1]))
            .save(dir.join("v/material/a.png"))
            .expect("the scratch folder is writable");
    }
    write(dir, "v/views.json", bytes);
    run_stage::<kodama_nodes::stages::ingest::read_views::ReadViews>(
        json!({"path": "v/views.json"}),
        &[dir.join("v")],
    )
}

/// A one-file ingest stage on `bytes` written as `name`: its params `params` with `path` set.
fn read_one_file<S: Stage>(dir: &Path, name: &str, bytes: &[u8], mut params: Value) -> Outcome {
    let p = write(dir, name, bytes);
    params["path"] = json!(name);
    run_stage::<S>(params, &[p])
}

fn read_measurements_csv(dir: &Path, bytes: &[u8]) -> Outcome {
    use kodama_nodes::stages::ingest::read_measurements::ReadMeasurements;
    read_one_file::<ReadMeasurements>(dir, "links.csv", bytes, json!({}))
}

fn read_las(dir: &Path, bytes: &[u8]) -> Outcome {
    // The reader tells LAS from LAZ by the header, not the name.
    use kodama_nodes::stages::ingest::read_las::ReadLas;
    read_one_file::<ReadLas>(dir, "p.las", bytes, json!({"crs": "EPSG:32618"}))
}

fn read_geotiff(dir: &Path, bytes: &[u8]) -> Outcome {
    use kodama_nodes::stages::ingest::read_raster::ReadRaster;
    read_one_file::<ReadRaster>(dir, "dsm.tif", bytes, json!({"crs": "EPSG:32618"}))
}

fn read_osm_xml(dir: &Path, bytes: &[u8]) -> Outcome {
    use kodama_nodes::stages::ingest::read_osm::ReadOsmBuildings;
    read_one_file::<ReadOsmBuildings>(dir, "b.osm", bytes, json!({}))
}

fn read_geojson(dir: &Path, bytes: &[u8]) -> Outcome {
    use kodama_nodes::stages::ingest::read_footprints::ReadFootprints;
    read_one_file::<ReadFootprints>(dir, "footprints.geojson", bytes, json!({}))
}

fn read_xyz(dir: &Path, bytes: &[u8]) -> Outcome {
    use kodama_nodes::stages::ingest::read_xyz::ReadXyz;
    read_one_file::<ReadXyz>(dir, "points.xyz", bytes, json!({}))
}

fn read_exr(dir: &Path, bytes: &[u8]) -> Outcome {
    let p = write(dir, "depth.exr", bytes);
    kodama_nodes::io::exr_io::read_exr(&p)
        .map(drop)
        .map_err(|e| e.to_string())
}

/// Loads the graph and renders its errors, as `kodama-dag run` and `explain` do: the renderer
/// slices the file's text at the spans the parser reports.
fn read_ron_graph(dir: &Path, bytes: &[u8]) -> Outcome {
    let p = write(dir, "graph.ron", bytes);
    kodama_dag::graph::load(&p, &Default::default())
        .map(drop)
        .map_err(|e| e.to_string())
}

/// Loads the sweep and every variant's graph, as `kodama-dag sweep --check` does.
fn read_ron_sweep(dir: &Path, bytes: &[u8]) -> Outcome {
    write(dir, "graph.ron", fixed("ron_graph"));
    let p = write(dir, "sweep.ron", bytes);
    let sweep = kodama_dag::sweep::load_sweep(&p, false)?;
    kodama_dag::sweep::check_variants(&sweep, &Default::default()).map(drop)
}
