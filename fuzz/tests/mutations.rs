//! proptest's mutations of each target's seed (issue 19): bytes flipped, inserted, cut,
//! overwritten with NaN, infinities and huge counts. Each must give `Ok` or an error, never a
//! panic, an abort or a hang.
//!
//! `cargo test` runs a bounded number of cases per target (64, or `PROPTEST_CASES`);
//! `scripts/fuzz.sh` runs the ignored `soak` test for a fixed time per target and prints how
//! many cases ran and how many panicked. The coverage-guided campaign is `scripts/fuzz_afl.sh`.

use kodama_fuzz::{TARGETS, Target, seed, target};
use proptest::prelude::*;

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

fn named(name: &str) -> &'static Target {
    target(name).unwrap()
}

fn check(name: &str, ms: &[Mutation]) {
    let seed = seed(name).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let _ = (named(name).read)(dir.path(), &apply(&seed, ms));
}

macro_rules! fuzz_target {
    ($fn_name:ident, $name:literal) => {
        proptest! {
            #![proptest_config(config())]
            #[test]
            fn $fn_name(ms in mutations(named($name).head)) {
                check($name, &ms);
            }
        }
    };
}

fuzz_target!(ply_never_panics, "ply");
fuzz_target!(sionna_xml_never_panics, "sionna_xml");
fuzz_target!(glb_never_panics, "glb");
fuzz_target!(tileset_json_never_panics, "tileset_json");
fuzz_target!(views_json_never_panics, "views_json");
fuzz_target!(measurements_csv_never_panics, "measurements_csv");
fuzz_target!(las_never_panics, "las");
fuzz_target!(laz_never_panics, "laz");
fuzz_target!(geotiff_never_panics, "geotiff");
fuzz_target!(osm_xml_never_panics, "osm_xml");
fuzz_target!(geojson_never_panics, "geojson");
fuzz_target!(xyz_never_panics, "xyz");
fuzz_target!(exr_never_panics, "exr");
fuzz_target!(ron_graph_never_panics, "ron_graph");
fuzz_target!(ron_sweep_never_panics, "ron_sweep");

/// Every target has a proptest case above.
#[test]
fn every_target_is_mutated() {
    let this = include_str!("mutations.rs");
    for t in TARGETS {
        assert!(
            this.contains(&format!(
                "fuzz_target!({}_never_panics, \"{}\")",
                t.name, t.name
            )),
            "{} has no proptest target",
            t.name
        );
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
        let seed = seed(t.name).unwrap();
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
