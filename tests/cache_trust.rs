//! What the cache trusts (issue 55, classes 1 and 2): an input that moves while a run reads it
//! never lands in the cache under its old content's key, and gc deletes only from a folder that
//! is a kodama-dag cache, only files the engine named.

mod common;
use common::*;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
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

/// Every file below `dir`, relative, with its bytes.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_path_buf();
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

fn gc(env: &Env, cache: &Path) -> Run {
    env.cli(&["gc", "--cache", cache.to_str().unwrap(), "--max-bytes", "0"])
}

/// Class 2. gc on a folder that is not a cache (here one with tmp/, cas/ and ac/ of its own)
/// refuses it with exit 2, naming the folder and what was expected, and touches nothing; nor
/// does a run make it a cache.
#[test]
fn gc_refuses_a_folder_that_is_not_a_cache() {
    let env = Env::new();
    let photos = env.path("photos");
    env.write("photos/tmp/draft.txt", "unsaved work");
    env.write("photos/cas/a.jpg", "a photo");
    env.write("photos/ac/b.txt", "notes");
    env.write("photos/readme.txt", "mine");
    let before = snapshot(&photos);

    let r = gc(&env, &photos);
    assert_eq!(r.code, 2, "{}\n{}", r.stdout, r.stderr);
    assert!(
        r.stderr
            .contains(&format!("{} is not a kodama-dag cache", photos.display()))
            && r.stderr
                .contains("expected a folder made by `kodama-dag run --cache`"),
        "{}",
        r.stderr
    );
    assert_eq!(snapshot(&photos), before, "nothing deleted or created");

    // A run refuses to adopt it as well (it would write the marker over foreign files).
    env.write("pts.xyz", A);
    let g = env.write("g.ron", GRAPH);
    let r = env.cli(&[
        "run",
        g.to_str().unwrap(),
        "--cache",
        photos.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("is not a kodama-dag cache") && r.stderr.contains("cas/a.jpg"),
        "{}",
        r.stderr
    );
    assert_eq!(snapshot(&photos), before);

    // A folder that does not exist is not created, and an empty one is not a cache.
    let missing = env.path("nowhere");
    let r = gc(&env, &missing);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("does not exist"), "{}", r.stderr);
    assert!(!missing.exists());
    std::fs::create_dir(&missing).unwrap();
    assert_eq!(gc(&env, &missing).code, 2);
    assert!(snapshot(&missing).is_empty());
}

/// Class 2. A cache without its marker (FORMAT lost) is recognised by its exact layout and the
/// engine's names, marked, and collected; one foreign file in it makes it a folder gc refuses.
/// In a marked cache, gc deletes only what the engine named and says what it left.
#[test]
fn gc_collects_only_caches_and_only_what_the_engine_named() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let clean = env.run(&g, &[]).ok();
    let format = std::fs::read(env.cache().join("FORMAT")).unwrap();

    // One foreign file beside the blobs of an unmarked cache: refused, nothing deleted.
    std::fs::remove_file(env.cache().join("FORMAT")).unwrap();
    env.write("cache/cas/notes.txt", "mine");
    let blobs = named_blobs(&env);
    let r = gc(&env, &env.cache());
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("cas/notes.txt"), "{}", r.stderr);
    assert_eq!(named_blobs(&env), blobs);

    // Without it: recognised, marked again, collected.
    std::fs::remove_file(env.cache().join("cas/notes.txt")).unwrap();
    let r = gc(&env, &env.cache()).ok();
    assert!(r.stdout.contains("removed"), "{}", r.stdout);
    assert_eq!(std::fs::read(env.cache().join("FORMAT")).unwrap(), format);
    assert!(named_blobs(&env).is_empty());
    let again = env.run(&g, &[]).ok();
    assert_eq!(again.with_status("ran").len(), 8);
    assert_eq!(again.digests(), clean.digests());

    // Marked: files the engine did not name are left, and reported.
    env.write("cache/cas/ab/notes.txt", "mine");
    env.write("cache/tmp/keep.txt", "mine");
    let r = gc(&env, &env.cache()).ok();
    assert!(r.stderr.contains("left alone 2 entries"), "{}", r.stderr);
    assert_eq!(
        std::fs::read_to_string(env.cache().join("cas/ab/notes.txt")).unwrap(),
        "mine"
    );
    assert_eq!(
        std::fs::read_to_string(env.cache().join("tmp/keep.txt")).unwrap(),
        "mine"
    );
    assert!(named_blobs(&env).is_empty());
}

/// The blobs the engine named (64 hex digits) in `env`'s cache, ignoring anything planted.
fn named_blobs(env: &Env) -> Vec<PathBuf> {
    snapshot(&env.cache().join("cas"))
        .into_iter()
        .map(|(p, _)| p)
        .filter(|p| p.file_name().is_some_and(|n| n.len() == 64))
        .collect()
}

/// A folder input that holds the run's own cache and output folder (a project folder read
/// whole, `./cache` and `./out` inside it): what the run writes there does not move the input,
/// so the next run is all hits. Before, every run gave the folder a new digest: such nodes were
/// never cached, and `watch` reran itself forever (issue 55, class 4). A second cache inside the
/// folder (another run's) is left out too; a file of the user's beside them still counts.
#[test]
fn a_folder_input_holding_the_cache_and_the_outputs_is_a_hit_on_the_next_run() {
    let env = Env::new();
    let las = shared_data().join("autzen/autzen_trim.las");
    std::fs::copy(&las, env.path("a.las")).unwrap();
    let g = env.write(
        "g.ron",
        "Graph(\n  site: Site(crs: \"EPSG:32610\", origin: (494000.0, 4877000.0), cell_m: 1.0),\n  nodes: { \"p\": ReadLas(path: \".\"), \"s\": PointStats(points: \"p\") },\n  outputs: { \"s\": \"s\" },\n)\n",
    );
    assert_eq!(env.run(&g, &[]).ok().status("p"), "ran");
    assert_eq!(env.run(&g, &[]).ok().status("p"), "cached");
    // explain, told the same output folder, plans the same keys.
    let r = env.cli(&[
        "explain",
        g.to_str().unwrap(),
        "--cache",
        env.cache().to_str().unwrap(),
        "--out",
        env.out().to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let plan: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    for n in plan["nodes"].as_array().unwrap() {
        assert_eq!(n["plan"], "cached", "{n}");
    }
    // Another run's cache in the same folder.
    let other = env.path("other_cache");
    let r = env.cli(&[
        "run",
        g.to_str().unwrap(),
        "--cache",
        other.to_str().unwrap(),
        "--out",
        env.out().to_str().unwrap(),
        "--json",
        "--quiet",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(env.run(&g, &[]).ok().status("p"), "cached");
    // A file of the user's is still part of the input.
    env.write("notes.txt", "a new file in the folder input");
    assert_eq!(env.run(&g, &[]).ok().status("p"), "ran");
}
