//! What the cache trusts (issue 55, class 1): an input that moves while a run reads it never
//! lands in the cache under its old content's key.

mod common;
use common::*;

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

const GRAPH: &str = r#"
Graph(
    site: Site(crs: "EPSG:32618", origin: (0.0, 0.0), cell_m: 1.0),
    nodes: {
        "pts":   ReadXyz(path: "pts.xyz"),
        "stats": PointStats(points: "pts"),
    },
    outputs: { "stats": "stats" },
)
"#;

const A: &str = "x y z\n1 2 3\n4 5 6\n";
const B: &str = "x y z\n1 2 3\n4 5 6\n7 8 9\n";
const C: &str = "x y z\n1 2 3\n";

/// A clean run of GRAPH on `content` in a fresh folder: the digests and the exported stats.
fn clean(content: &str) -> (std::collections::BTreeMap<String, String>, Vec<u8>) {
    let env = Env::new();
    env.write("pts.xyz", content);
    let r = env.run(&env.write("g.ron", GRAPH), &[]).ok();
    (
        r.digests(),
        std::fs::read(env.out().join("stats.json")).unwrap(),
    )
}

/// Starts GRAPH with every cache write pausing halfway (`KODAMA_DAG_FAULT_SLOW_WRITE_MS`, the
/// kill-during-write test's fault injection), so the run is held while it records the stat of
/// `pts.xyz`: after the file was digested, before any stage reads it.
fn spawn_slow(env: &Env) -> Child {
    env.run_cmd(&env.path("g.ron"), &[])
        .env("KODAMA_DAG_FAULT_SLOW_WRITE_MS", "1000")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn kodama-dag")
}

/// Waits for a half-written stat-cache entry (a temp file in the cache's tmp/ starting with
/// `{"path"`) not in `seen`, and returns its name.
fn wait_for_stat_write(env: &Env, seen: &mut BTreeSet<PathBuf>) -> PathBuf {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        assert!(Instant::now() < deadline, "no stat entry written");
        for e in std::fs::read_dir(env.cache().join("tmp"))
            .into_iter()
            .flatten()
            .flatten()
        {
            let p = e.path();
            let is_stat = std::fs::read(&p).is_ok_and(|b| b.starts_with(b"{\"path\""));
            if is_stat && seen.insert(p.clone()) {
                return p;
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn finish_child(child: Child) -> Run {
    finish(child.wait_with_output().unwrap())
}

/// Class 1. A save during a run, then an undo: the stage read the saved file while its key was
/// the original's. The result must not be stored under the original's key: the next run on the
/// original content gives the original artifact, not a hit on the edited one.
#[test]
fn an_input_edited_during_a_run_then_undone_is_never_a_hit_on_the_edit() {
    let (digests_a, stats_a) = clean(A);
    let (digests_b, stats_b) = clean(B);
    assert_ne!(digests_a["pts"], digests_b["pts"]);

    let env = Env::new();
    env.write("pts.xyz", A);
    env.write("g.ron", GRAPH);
    let child = spawn_slow(&env);
    wait_for_stat_write(&env, &mut BTreeSet::new());
    env.write("pts.xyz", B); // the save
    let r = finish_child(child).ok();
    // What the run recorded and exported is the saved file's result.
    assert_eq!(r.status("pts"), "ran");
    assert_eq!(r.digests(), digests_b);
    assert_eq!(
        std::fs::read(env.out().join("stats.json")).unwrap(),
        stats_b
    );

    env.write("pts.xyz", A); // the undo
    let again = env.run(&env.path("g.ron"), &[]).ok();
    assert_eq!(
        again.status("pts"),
        "ran",
        "the original content's key holds nothing: {:?}",
        again.statuses()
    );
    assert_eq!(again.digests(), digests_a, "the original artifact");
    assert_eq!(
        std::fs::read(env.out().join("stats.json")).unwrap(),
        stats_a
    );
    // And the edit's own key holds the edit's result.
    env.write("pts.xyz", B);
    let b = env.run(&env.path("g.ron"), &[]).ok();
    assert_eq!(b.status("pts"), "cached");
    assert_eq!(b.digests(), digests_b);
    // The node saw its input move, dropped what it had made, ran again on the saved content,
    // and said so.
    assert!(
        r.reason("pts").contains("while it ran, so it ran again"),
        "{}",
        r.reason("pts")
    );
    assert!(r.stderr.contains("changed size"), "{}", r.stderr);
}

/// Class 1. An input that moves again while the node reruns fails the node, with a message that
/// says so; nothing is stored or exported for it, and the next run on the settled file is right.
#[test]
fn an_input_that_keeps_moving_fails_the_node_and_stores_nothing() {
    let (digests_c, stats_c) = clean(C);
    let env = Env::new();
    env.write("pts.xyz", A);
    env.write("g.ron", GRAPH);
    let child = spawn_slow(&env);
    let mut seen = BTreeSet::new();
    wait_for_stat_write(&env, &mut seen);
    env.write("pts.xyz", B);
    // The rerun digests the file afresh (another stat entry): it moves again meanwhile.
    wait_for_stat_write(&env, &mut seen);
    env.write("pts.xyz", C);
    let r = finish_child(child);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_eq!(r.status("pts"), "failed");
    let error = r.node("pts")["error"].as_str().unwrap().to_owned();
    assert!(
        error.contains("while it ran again") && error.contains("pts.xyz"),
        "{error}"
    );
    assert_eq!(r.status("stats"), "skipped");
    assert!(!env.out().join("stats.json").exists());
    assert!(env.blobs().is_empty(), "nothing was stored");

    let settled = env.run(&env.path("g.ron"), &[]).ok();
    assert_eq!(settled.digests(), digests_c);
    assert_eq!(
        std::fs::read(env.out().join("stats.json")).unwrap(),
        stats_c
    );
}
