//! Helpers for tests that run the real `kodama-dag` binary in a temporary folder.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

pub const BIN: &str = env!("CARGO_BIN_EXE_kodama-dag");

/// A small graph with a chain, a diamond and two leaves; runs in well under a second.
pub const CHAIN: &str = r#"
Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    nodes: {
        "truth":  SynthTerrain(seed: 3, size_m: (120.0, 80.0), relief_m: 2.0),
        "lidar":  SynthScan(surface: "truth", density_per_m2: 4.0, noise_m: 0.05, seed: 3),
        "dsm":    RasterizeSurface(points: "lidar", mode: Max),
        "capped": Clamp(raster: "dsm", max: 1000.0),
        "smooth": GaussianBlur(raster: "capped", sigma_m: 2.0),
        "resid":  Difference(a: "capped", b: "smooth"),
        "stats":  RasterStats(raster: "resid"),
        "pstats": PointStats(points: "lidar"),
    },
    outputs: { "dsm": "dsm", "stats": "stats" },
)
"#;

/// A 600 m x 600 m synthetic city through the Sec. 4.1 chain; `tiling` without a tile size runs
/// untiled until `--tile-m` gives one. The terrain raster and the solids are merged, and the
/// scene is assembled once over the merged terrain.
pub const TILED_CITY: &str = r#"
Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    tiling: Tiling(area: (min: (0.0, 0.0), max: (600.0, 600.0)), merge: ["terrain2", "solids"]),
    nodes: {
        "city":      SynthCity(seed: 11, size_m: (600.0, 600.0), blocks: (6, 6),
                               terrain: (seed: 11, size_m: (600.0, 600.0))),
        "truth":     TruthScene(city: "city"),
        "lidar":     SynthLidar(scene: "truth", density_per_m2: 8.0, noise_m: 0.05, seed: 11),
        "dsm":       RasterizeSurface(points: "lidar", mode: Max, max_gap_m: 1.0),
        "terrain1":  TerrainPass(surface: "dsm", coarse_m: 32.0, percentile: 5.0, n_min: 0.9, tau_m: 4.0, sigma_m: 2.0),
        "terrain2":  TerrainPass(surface: "dsm", previous: "terrain1", coarse_m: 8.0, percentile: 10.0, n_min: 0.9, tau_m: 1.0, sigma_m: 1.0),
        "above":     AboveGround(surface: "dsm", terrain: "terrain2"),
        "buildings": BuildingMask(above: "above", points: "lidar"),
        "roofs":     RoofClean(labels: "buildings", above: "above", points: "lidar", terrain: "terrain2"),
        "parts":     SplitBuildings(labels: "buildings", roofs: "roofs"),
        "solids":    BuildingSolids(labels: "parts", roofs: "roofs", terrain: "terrain2", points: "lidar"),
        "scene":     AssembleScene(terrain: "terrain2", objects: ["solids"]),
    },
    outputs: { "scene": "scene", "terrain": "terrain2", "scene.3dtiles": "scene" },
)
"#;

/// A small street-level graph: a view set, whose pixels are a part per view, and a stage that
/// reads the views.
pub const VIEWS: &str = r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    nodes: {
        "city":   SynthCity(seed: 3, size_m: (200.0, 150.0), blocks: (2, 2)),
        "truth":  TruthScene(city: "city"),
        "views":  SynthViews(scene: "truth", city: "city", size: (64, 48), max_views: 6),
        "charts": SurfaceCharts(scene: "truth"),
        "fused":  FuseViews(views: "views", scene: "truth", charts: "charts"),
    },
    outputs: {},
)"#;

/// A temporary working folder with its own cache and output folder.
pub struct Env {
    pub dir: tempfile::TempDir,
}

/// The real data in ../shared/data, read in place.
pub fn shared_data() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    assert!(p.is_dir(), "real test data missing: {}", p.display());
    p.canonicalize().unwrap()
}

/// One finished command.
pub struct Run {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

impl Env {
    pub fn new() -> Env {
        Env {
            dir: tempfile::tempdir().expect("temp dir"),
        }
    }
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    pub fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.path(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, text).unwrap();
        p
    }
    pub fn cache(&self) -> PathBuf {
        self.path("cache")
    }
    pub fn out(&self) -> PathBuf {
        self.path("out")
    }
    /// `kodama-dag run GRAPH --cache <env>/cache --out <env>/out --json --quiet EXTRA...`
    pub fn run(&self, graph: &Path, extra: &[&str]) -> Run {
        let mut cmd = self.run_cmd(graph, extra);
        finish(cmd.output().expect("spawn kodama-dag"))
    }
    pub fn run_cmd(&self, graph: &Path, extra: &[&str]) -> Command {
        let mut cmd = Command::new(BIN);
        cmd.arg("run")
            .arg(graph)
            .arg("--cache")
            .arg(self.cache())
            .arg("--out")
            .arg(self.out())
            .args(["--json", "--quiet"]);
        cmd.args(extra).current_dir(self.dir.path());
        cmd
    }
    pub fn cli(&self, args: &[&str]) -> Run {
        finish(
            Command::new(BIN)
                .args(args)
                .current_dir(self.dir.path())
                .output()
                .expect("spawn kodama-dag"),
        )
    }
    /// `kodama-dag sweep SWEEP --cache <env>/cache --out <env>/out -q EXTRA...`
    pub fn sweep(&self, sweep: &Path, extra: &[&str]) -> Run {
        let mut cmd = Command::new(BIN);
        cmd.arg("sweep")
            .arg(sweep)
            .arg("--cache")
            .arg(self.cache())
            .arg("--out")
            .arg(self.out())
            .arg("-q")
            .args(extra)
            .current_dir(self.dir.path());
        finish(cmd.output().expect("spawn kodama-dag"))
    }
    /// Every blob file in the cache's store.
    pub fn blobs(&self) -> Vec<PathBuf> {
        let mut out = Vec::new();
        for shard in std::fs::read_dir(self.cache().join("cas")).unwrap() {
            for f in std::fs::read_dir(shard.unwrap().path()).unwrap() {
                out.push(f.unwrap().path());
            }
        }
        out.sort();
        out
    }
    /// Waits (up to `secs`) until a blob-sized temp file is half written in the cache's tmp/ (the
    /// writer paused there by `KODAMA_DAG_FAULT_SLOW_WRITE_MS`): the moment to kill the writer.
    pub fn wait_for_half_written_blob(&self, secs: u64) {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(secs);
        let tmp = self.cache().join("tmp");
        loop {
            assert!(
                std::time::Instant::now() < deadline,
                "no write in progress seen"
            );
            let half_written = std::fs::read_dir(&tmp)
                .map(|d| {
                    d.filter_map(Result::ok)
                        .any(|e| e.metadata().is_ok_and(|m| m.len() > 10_000))
                })
                .unwrap_or(false);
            if half_written {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }
    /// Nothing half-written is visible: every stored blob hashes to its name.
    pub fn assert_blobs_intact(&self) {
        for b in self.blobs() {
            let bytes = std::fs::read(&b).unwrap();
            assert_eq!(
                blake3::hash(&bytes).to_hex().as_str(),
                b.file_name().unwrap().to_str().unwrap()
            );
        }
    }
    pub fn blob(&self, digest: &str) -> PathBuf {
        self.cache().join("cas").join(&digest[..2]).join(digest)
    }
}

pub fn finish(o: Output) -> Run {
    Run {
        code: o.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

impl Run {
    pub fn ok(self) -> Run {
        assert_eq!(self.code, 0, "exit {}\nstderr:\n{}", self.code, self.stderr);
        self
    }
    pub fn json(&self) -> Value {
        serde_json::from_str(&self.stdout)
            .unwrap_or_else(|e| panic!("not JSON ({e}): {}\nstderr: {}", self.stdout, self.stderr))
    }
    fn nodes(&self) -> Vec<Value> {
        self.json()["nodes"]
            .as_array()
            .expect("nodes array")
            .clone()
    }
    /// Node id -> status.
    pub fn statuses(&self) -> BTreeMap<String, String> {
        self.nodes()
            .iter()
            .map(|n| {
                (
                    n["id"].as_str().unwrap().to_owned(),
                    n["status"].as_str().unwrap().to_owned(),
                )
            })
            .collect()
    }
    /// Node id -> output digest.
    pub fn digests(&self) -> BTreeMap<String, String> {
        self.nodes()
            .iter()
            .map(|n| {
                (
                    n["id"].as_str().unwrap().to_owned(),
                    n["digest"].as_str().unwrap_or("").to_owned(),
                )
            })
            .collect()
    }
    pub fn node(&self, id: &str) -> Value {
        self.nodes()
            .into_iter()
            .find(|n| n["id"] == id)
            .unwrap_or_else(|| panic!("no node {id} in the record"))
    }
    pub fn status(&self, id: &str) -> String {
        self.node(id)["status"].as_str().unwrap().to_owned()
    }
    pub fn reason(&self, id: &str) -> String {
        self.node(id)["reason"].as_str().unwrap().to_owned()
    }
    /// Ids with the given status, sorted.
    pub fn with_status(&self, status: &str) -> Vec<String> {
        self.statuses()
            .into_iter()
            .filter(|(_, s)| s == status)
            .map(|(id, _)| id)
            .collect()
    }
}

pub fn ids(list: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = list.iter().map(|s| s.to_string()).collect();
    v.sort();
    v
}

/// The meshes of a glb whose node names contain "building", with their names.
pub fn building_meshes(glb: &Path) -> Vec<(String, kodama_nodes::artifact::Mesh)> {
    let (doc, buffers, _) = gltf::import(glb).unwrap_or_else(|e| panic!("{}: {e}", glb.display()));
    let mut out = Vec::new();
    for node in doc.nodes() {
        let name = node.name().unwrap_or_default().to_string();
        let Some(mesh) = node.mesh() else { continue };
        if !name.contains("building") {
            continue;
        }
        let mut m = kodama_nodes::artifact::Mesh::default();
        for prim in mesh.primitives() {
            let r = prim.reader(|b| Some(&buffers[b.index()]));
            if m.positions.is_empty() {
                m.positions = kodama_nodes::artifact::PodVec(r.read_positions().unwrap().collect());
            }
            let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
            m.triangles
                .extend(idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
            m.materials.extend(std::iter::repeat_n(0u8, idx.len() / 3));
        }
        out.push((name, m));
    }
    out
}
