//! Engine benchmarks (divan): `cargo bench --bench engine`. Figures go in BENCHMARKS.md.

use std::path::{Path, PathBuf};
use std::sync::LazyLock;

use divan::counter::BytesCount;
use divan::{Bencher, black_box};
use kodama_dag::cache::{Cache, digest_bytes};
use kodama_dag::exec::{RunOptions, run};
use kodama_dag::graph::{Graph, LoadOptions, load};
use kodama_dag::progress::{Mode, Reporter};
use kodama_nodes::Artifact;
use kodama_nodes::artifact::{Grid, PodVec, Raster};

fn main() {
    divan::main();
}

static TMP: LazyLock<tempfile::TempDir> = LazyLock::new(|| tempfile::tempdir().unwrap());

/// A 2000 x 2000 f32 raster (16 MB), non-constant so nothing compresses or short-circuits.
fn raster_4m(seed: u32) -> Artifact {
    let grid = Grid {
        x0: 0.0,
        y0: 1000.0,
        cell_m: 0.5,
        width: 2000,
        height: 2000,
    };
    let data = (0..grid.len() as u32)
        .map(|i| ((i ^ seed).wrapping_mul(2_654_435_761) >> 8) as f32 * 1e-3)
        .collect();
    Artifact::Raster(Raster {
        grid,
        data: PodVec(data),
    })
}

const RASTER_BYTES: u64 = 2000 * 2000 * 4;

#[divan::bench]
fn raster_4m_encode_and_hash(b: Bencher) {
    let a = raster_4m(1);
    b.counter(BytesCount::new(RASTER_BYTES)).bench(|| {
        let bytes = rmp_serde::to_vec(black_box(&a)).unwrap();
        digest_bytes(&bytes)
    });
}

#[divan::bench]
fn raster_4m_encode_hash_and_store(b: Bencher) {
    let cache = Cache::open(&TMP.path().join("store")).unwrap();
    let mut seed = 0;
    b.counter(BytesCount::new(RASTER_BYTES))
        .with_inputs(|| {
            seed += 1;
            raster_4m(seed)
        })
        .bench_local_values(|a| {
            let bytes = rmp_serde::to_vec(&a).unwrap();
            cache.put_blob_with(|w| w.write_all(&bytes)).unwrap().0
        });
}

#[divan::bench]
fn raster_4m_load_verify_decode(b: Bencher) {
    let cache = Cache::open(&TMP.path().join("load")).unwrap();
    let bytes = rmp_serde::to_vec(&raster_4m(7)).unwrap();
    let (d, _) = cache.put_blob_with(|w| w.write_all(&bytes)).unwrap();
    b.counter(BytesCount::new(RASTER_BYTES)).bench(|| {
        let bytes = cache.get_blob(&d).unwrap();
        rmp_serde::from_slice::<Artifact>(&bytes).unwrap()
    });
}

fn big_file() -> PathBuf {
    let p = TMP.path().join("input.bin");
    if !p.exists() {
        let data: Vec<u8> = (0..256u32 << 20 >> 2)
            .flat_map(|i| i.wrapping_mul(2_654_435_761).to_le_bytes())
            .collect();
        std::fs::write(&p, data).unwrap();
    }
    p
}

/// Hashing an input file's content (256 MiB, page-cache warm): what a changed input costs.
#[divan::bench(sample_count = 10)]
fn input_file_digest_256mib(b: Bencher) {
    let p = big_file();
    b.counter(BytesCount::new(256u64 << 20))
        .bench(|| kodama_dag::cache::hash_file(&p).unwrap());
}

/// The same file through the stat cache: what an unchanged input costs.
#[divan::bench]
fn input_file_digest_stat_hit(b: Bencher) {
    let p = big_file();
    let cache = Cache::open(&TMP.path().join("stat")).unwrap();
    cache.file_digest(&p).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(2100)); // past the racy-timestamp window
    cache.file_digest(&p).unwrap();
    b.bench(|| cache.file_digest(&p).unwrap());
}

/// A graph of `n` nodes: one tiny terrain and a binary tree of clamps below it, each with its own
/// bound so every node has its own key and output. Stage work is microseconds, so a cold run
/// measures the engine: keys, scheduling, encoding, hashing, atomic writes.
fn tree_graph(dir: &Path, n: usize) -> PathBuf {
    let mut s = String::from(
        "Graph(\n  site: Site(crs: \"EPSG:32618\", origin: (0.0, 0.0), cell_m: 1.0),\n  nodes: {\n",
    );
    s.push_str("    \"n0\": SynthTerrain(size_m: (4.0, 4.0)),\n");
    for i in 1..n {
        s.push_str(&format!(
            "    \"n{i}\": Clamp(raster: \"n{}\", max: {}.5),\n",
            (i - 1) / 2,
            1000 + i
        ));
    }
    s.push_str("  },\n)\n");
    let p = dir.join(format!("tree{n}.ron"));
    std::fs::write(&p, s).unwrap();
    p
}

fn run_quiet(g: &Graph, cache: &Cache) {
    let reporter = Reporter::new(Mode::Quiet, g.nodes.len());
    let opts = RunOptions {
        jobs: None,
        targets: vec![],
        out_dir: Some(TMP.path().join("out")),
    };
    run(g, cache, &opts, &reporter).unwrap();
}

/// Load, check, key and look up a fully cached 1,000-node graph (what `run` does on a no-op).
#[divan::bench(sample_count = 20)]
fn noop_rerun_1000_nodes(b: Bencher) {
    let dir = TMP.path().join("noop");
    std::fs::create_dir_all(&dir).unwrap();
    let path = tree_graph(&dir, 1000);
    let cache = Cache::open(&dir.join("cache")).unwrap();
    run_quiet(&load(&path, &LoadOptions::default()).unwrap(), &cache);
    b.bench(|| {
        let g = load(&path, &LoadOptions::default()).unwrap();
        run_quiet(&g, &cache);
    });
}

/// A cold run of 1,000 near-empty nodes on an empty cache: divide by 1,000 for the engine's
/// overhead per node.
#[divan::bench(sample_count = 10)]
fn cold_run_1000_tiny_nodes(b: Bencher) {
    let dir = TMP.path().join("cold");
    std::fs::create_dir_all(&dir).unwrap();
    let path = tree_graph(&dir, 1000);
    let mut k = 0;
    b.with_inputs(|| {
        k += 1;
        let g = load(&path, &LoadOptions::default()).unwrap();
        (g, Cache::open(&dir.join(format!("cache{k}"))).unwrap())
    })
    .bench_local_values(|(g, cache)| run_quiet(&g, &cache));
}
