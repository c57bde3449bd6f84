//! The cache under damage and contention: missing and corrupt blobs, a run killed mid-write,
//! two runs at once, failing nodes, gc.

mod common;

use common::*;

#[test]
fn deleted_blob_is_rebuilt_and_descendants_cut_off() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let clean = env.run(&g, &[]).ok();
    std::fs::remove_file(env.blob(&clean.digests()["lidar"])).unwrap();
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.status("lidar"), "ran");
    assert!(
        r.reason("lidar").contains("missing"),
        "{}",
        r.reason("lidar")
    );
    assert_eq!(
        r.with_status("cutoff"),
        ids(&["dsm", "capped", "smooth", "resid", "stats", "pstats"])
    );
    assert_eq!(r.digests(), clean.digests());
    assert!(env.blob(&clean.digests()["lidar"]).is_file());
}

fn corrupt(path: &std::path::Path) {
    let mut bytes = std::fs::read(path).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xFF;
    std::fs::write(path, bytes).unwrap();
}

/// A blob, or an action entry, replaced by a folder (or a symlink) heals: the thing in its
/// place is moved into the cache's tmp/ (nothing of it deleted) and the entry is made again.
/// Before, every later run that needed it failed (issue 55, class 10).
#[test]
fn a_blob_or_an_entry_replaced_by_a_folder_is_moved_aside_and_rebuilt() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let clean = env.run(&g, &[]).ok();
    let blob = env.blob(&clean.digests()["lidar"]);
    std::fs::remove_file(&blob).unwrap();
    std::fs::create_dir(&blob).unwrap();
    std::fs::write(blob.join("keep.txt"), "someone's file").unwrap();
    let r = env.run(&g, &["--set", "dsm.mode=Min"]).ok();
    assert_eq!(r.status("lidar"), "ran", "{}", r.stderr);
    assert_eq!(r.digests()["lidar"], clean.digests()["lidar"]);
    assert!(blob.is_file(), "the blob is a file again");
    let displaced: Vec<_> = std::fs::read_dir(env.cache().join("tmp"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("displaced-"))
        .collect();
    assert_eq!(displaced.len(), 1);
    assert_eq!(
        std::fs::read_to_string(displaced[0].path().join("keep.txt")).unwrap(),
        "someone's file"
    );

    // Every action entry a folder: the run makes them again.
    let ac = env.cache().join("ac");
    let mut entries = Vec::new();
    for shard in std::fs::read_dir(&ac).unwrap().flatten() {
        for e in std::fs::read_dir(shard.path()).unwrap().flatten() {
            entries.push(e.path());
        }
    }
    for e in &entries {
        std::fs::remove_file(e).unwrap();
        std::fs::create_dir(e).unwrap();
    }
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.digests(), clean.digests());
    let r = env.run(&g, &[]).ok();
    assert!(
        r.statuses().values().all(|s| s == "cached"),
        "{:?}",
        r.statuses()
    );
}

#[test]
fn corrupt_output_blob_is_detected_and_rebuilt() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let clean = env.run(&g, &[]).ok();
    let tif = std::fs::read(env.out().join("dsm.tif")).unwrap();
    std::fs::remove_file(env.out().join("dsm.tif")).unwrap();
    corrupt(&env.blob(&clean.digests()["dsm"]));
    // Same size, so the stat check passes; exporting the output reads and verifies it.
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.status("dsm"), "ran");
    assert!(r.reason("dsm").contains("corrupt"), "{}", r.reason("dsm"));
    assert!(
        r.stderr.contains("warning"),
        "a warning is printed: {}",
        r.stderr
    );
    assert_eq!(r.digests(), clean.digests());
    assert_eq!(std::fs::read(env.out().join("dsm.tif")).unwrap(), tif);
}

#[test]
fn corrupt_input_blob_is_rebuilt_when_a_consumer_reads_it() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let clean = env.run(&g, &[]).ok();
    corrupt(&env.blob(&clean.digests()["lidar"]));
    let r = env.run(&g, &["--set", "dsm.mode=Min"]).ok();
    assert_eq!(r.status("dsm"), "ran");
    assert_eq!(r.status("lidar"), "ran");
    assert!(
        r.reason("lidar").contains("corrupt"),
        "{}",
        r.reason("lidar")
    );
    assert_eq!(r.digests()["lidar"], clean.digests()["lidar"]);
    let bytes = std::fs::read(env.blob(&clean.digests()["lidar"])).unwrap();
    assert_eq!(
        blake3::hash(&bytes).to_hex().as_str(),
        clean.digests()["lidar"],
        "the store holds good bytes again"
    );
}

#[test]
fn run_killed_while_writing_leaves_a_cache_the_next_run_completes() {
    let clean_env = Env::new();
    let clean = clean_env
        .run(&clean_env.write("chain.ron", CHAIN), &[])
        .ok();

    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let mut child = env
        .run_cmd(&g, &[])
        .env("KODAMA_DAG_FAULT_SLOW_WRITE_MS", "5000")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Wait until a blob-sized temp file is half written (the writer pauses there), then kill.
    env.wait_for_half_written_blob(60);
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    // Nothing half-written is visible: every stored blob hashes to its name, no output exists.
    env.assert_blobs_intact();
    assert!(!env.out().join("dsm.tif").exists());
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.digests(), clean.digests());
    assert_eq!(
        std::fs::read(env.out().join("dsm.tif")).unwrap(),
        std::fs::read(clean_env.out().join("dsm.tif")).unwrap()
    );
}

#[test]
fn two_concurrent_runs_on_one_cache_agree() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    // Slow writes widen the window in which both processes write the same entries.
    let spawn = |out: &str| {
        let mut cmd = std::process::Command::new(BIN);
        cmd.arg("run")
            .arg(&g)
            .arg("--cache")
            .arg(env.cache())
            .arg("--out")
            .arg(env.path(out))
            .args(["--json", "--quiet"]);
        cmd.env("KODAMA_DAG_FAULT_SLOW_WRITE_MS", "20")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped());
        cmd.spawn().unwrap()
    };
    let (a, b) = (spawn("out_a"), spawn("out_b"));
    let (a, b) = (
        finish(a.wait_with_output().unwrap()).ok(),
        finish(b.wait_with_output().unwrap()).ok(),
    );
    assert_eq!(a.digests(), b.digests());
    for f in ["dsm.tif", "stats.json"] {
        assert_eq!(
            std::fs::read(env.path("out_a").join(f)).unwrap(),
            std::fs::read(env.path("out_b").join(f)).unwrap()
        );
    }
    let again = env.run(&g, &[]).ok();
    assert_eq!(again.with_status("cached").len(), 8);
    assert_eq!(again.digests(), a.digests());
}

/// Runs sharing one `--out` with folder outputs (a Sionna scene folder, 3D Tiles) all succeed
/// and leave whole folders: each replaces the folder by moving the old one aside and renaming
/// its own in, and tries again when another's landed first. Before, 6 of 30 such runs failed
/// (issue 55, class 10).
#[test]
fn runs_sharing_an_output_folder_with_folder_outputs_all_succeed() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (0.0, 0.0), cell_m: 1.0),
    nodes: {
        "t": SynthTerrain(size_m: (400.0, 300.0)),
        "scene": AssembleScene(terrain: "t", objects: []),
    },
    outputs: {
        "a.sionna": "scene", "b.sionna": "scene", "c.sionna": "scene",
        "a.3dtiles": "scene", "b.3dtiles": "scene", "c.3dtiles": "scene",
    },
)
"#,
    );
    // One run first, so that the others race only over the outputs, not the cache.
    env.run(&g, &[]).ok();
    let expected = files_below(&env.out());
    for round in 0..3 {
        // Gone, so that every run writes every output at once.
        std::fs::remove_dir_all(env.out()).unwrap();
        let children: Vec<_> = (0..12)
            .map(|_| {
                env.run_cmd(&g, &[])
                    .stdout(std::process::Stdio::piped())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for c in children {
            let r = finish(c.wait_with_output().unwrap());
            assert_eq!(r.code, 0, "round {round}: {}", r.stderr);
        }
        assert_eq!(files_below(&env.out()), expected, "round {round}");
    }
}

/// Every output file below `dir` with its content digest, sorted by relative path (the record of
/// what was exported, whose times differ run to run, left out).
fn files_below(dir: &std::path::Path) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().to_string();
                if rel != ".kodama-outputs.json" {
                    let digest = blake3::hash(&std::fs::read(&p).unwrap());
                    out.push((rel, digest.to_hex().to_string()));
                }
            }
        }
    }
    out.sort();
    out
}

const TWO_BRANCHES: &str = r#"
Graph(
    site: Site(crs: "EPSG:32618", origin: (1000.0, 2000.0), cell_m: 1.0),
    nodes: {
        "empty":  ReadXyz(path: "empty.xyz"),
        "grid":   RasterizeSurface(points: "empty", mode: Max),
        "gstats": RasterStats(raster: "grid"),
        "truth":  SynthTerrain(size_m: (60.0, 40.0)),
        "tstats": RasterStats(raster: "truth"),
    },
    outputs: { "gstats": "gstats", "tstats": "tstats" },
)
"#;

#[test]
fn a_failing_node_stops_only_its_descendants_and_is_never_cached() {
    let env = Env::new();
    // A file with no points is refused where it is read (bad input: exit 2), and only its
    // branch stops.
    env.write("empty.xyz", "x y z\n");
    let g = env.write("g.ron", TWO_BRANCHES);
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert_eq!(r.status("empty"), "failed");
    assert!(
        r.node("empty")["error"]
            .as_str()
            .unwrap()
            .contains("empty.xyz")
    );
    assert_eq!(r.status("grid"), "skipped");
    assert_eq!(r.reason("grid"), "input \"empty\" failed");
    assert_eq!(r.status("gstats"), "skipped");
    assert_eq!(r.reason("gstats"), "input \"grid\" was skipped");
    assert_eq!(r.with_status("ran"), ids(&["truth", "tstats"]));
    assert!(env.out().join("tstats.json").is_file());
    assert!(!env.out().join("gstats.json").exists());
    let again = env.run(&g, &[]);
    assert_eq!(again.code, 2);
    assert_eq!(again.status("empty"), "failed", "failures are not cached");
    assert_eq!(again.status("tstats"), "cached");
    // Fixing the data fixes the run.
    env.write("empty.xyz", "x y z\n1001 2001 5\n1010 2010 6\n");
    let fixed = env.run(&g, &[]).ok();
    assert_eq!(fixed.status("empty"), "ran");
    assert_eq!(fixed.status("gstats"), "ran");
    assert_eq!(fixed.status("tstats"), "cached");
}

#[test]
fn bad_input_data_is_exit_2_naming_file_and_place() {
    let env = Env::new();
    env.write("empty.xyz", "1 2 3\n4 five 6\n");
    let g = env.write("g.ron", TWO_BRANCHES);
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("empty.xyz: line 2, column 3: expected a number, found \"five\""),
        "{}",
        r.stderr
    );
}

#[test]
fn gc_bounds_the_cache_and_runs_rebuild_what_it_evicted() {
    let env = Env::new();
    let g = env.write("chain.ron", CHAIN);
    let clean = env.run(&g, &[]).ok();
    env.run(&g, &["--set", "smooth.sigma_m=4"]).ok();
    let total: u64 = env
        .blobs()
        .iter()
        .map(|b| b.metadata().unwrap().len())
        .sum();
    let bound = total / 2;
    let out = env
        .cli(&[
            "gc",
            "--cache",
            env.cache().to_str().unwrap(),
            "--max-bytes",
            &bound.to_string(),
        ])
        .ok();
    assert!(out.stdout.contains("removed"), "{}", out.stdout);
    let after: u64 = env
        .blobs()
        .iter()
        .map(|b| b.metadata().unwrap().len())
        .sum();
    assert!(after <= bound, "{after} > {bound}");
    // The most recently used artifacts (the sigma 4 run) are the ones kept.
    let r = env.run(&g, &["--set", "smooth.sigma_m=4"]).ok();
    assert!(r.with_status("ran").len() < 8, "{:?}", r.statuses());
    env.cli(&[
        "gc",
        "--cache",
        env.cache().to_str().unwrap(),
        "--max-bytes",
        "0",
    ])
    .ok();
    assert!(env.blobs().is_empty());
    let r = env.run(&g, &[]).ok();
    assert_eq!(
        r.with_status("ran").len(),
        8,
        "everything evicted runs again"
    );
    assert_eq!(r.digests(), clean.digests());
}

/// The parts the action entries in the cache name: their digests.
fn parts(env: &Env) -> Vec<String> {
    let mut out = Vec::new();
    for shard in std::fs::read_dir(env.cache().join("ac")).unwrap() {
        for entry in std::fs::read_dir(shard.unwrap().path()).unwrap() {
            let text = std::fs::read_to_string(entry.unwrap().path()).unwrap();
            for line in text.lines() {
                if let Some(rest) = line.strip_prefix("part blake3:") {
                    out.push(rest.split(' ').next().unwrap().to_string());
                }
            }
        }
    }
    out
}

#[test]
fn a_view_sets_parts_ride_with_it_and_a_missing_part_is_a_miss() {
    let env = Env::new();
    let g = env.write("views.ron", VIEWS);
    let clean = env.run(&g, &[]).ok();
    let parts = parts(&env);
    assert_eq!(parts.len(), 6, "one part per view: {parts:?}");
    assert!(parts.iter().all(|p| env.blob(p).is_file()));
    // The view set's own blob is small: the pixels are not in it.
    let set = env.blob(&clean.digests()["views"]);
    let part = env.blob(&parts[0]);
    assert!(
        set.metadata().unwrap().len() < part.metadata().unwrap().len(),
        "the set's blob holds heads only"
    );
    std::fs::remove_file(env.blob(&parts[2])).unwrap();
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.status("views"), "ran");
    assert!(r.reason("views").contains("part"), "{}", r.reason("views"));
    assert_eq!(r.status("fused"), "cutoff");
    assert_eq!(r.digests(), clean.digests());
    assert!(env.blob(&parts[2]).is_file());
}

#[test]
fn a_corrupt_part_fails_its_reader_by_name_and_the_next_run_rebuilds_it() {
    let env = Env::new();
    let g = env.write("views.ron", VIEWS);
    let clean = env.run(&g, &[]).ok();
    let part = parts(&env)[1].clone();
    corrupt(&env.blob(&part));
    // Same size: the entry still looks whole; the stage reading the view finds it out.
    let r = env.run(&g, &["--set", "fused.stride=2"]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains(&format!("part blake3:{part}")) && r.stderr.contains("run again"),
        "{}",
        r.stderr
    );
    // The bad part was dropped on reading it, so the set is rebuilt.
    let r = env.run(&g, &["--set", "fused.stride=2"]).ok();
    assert_eq!(r.status("views"), "ran");
    assert_eq!(r.digests()["views"], clean.digests()["views"]);
    env.assert_blobs_intact();
}

#[test]
fn gc_keeps_a_kept_graphs_parts_and_drops_entries_whose_parts_it_evicted() {
    let env = Env::new();
    let g = env.write("views.ron", VIEWS);
    env.run(&g, &[]).ok();
    let cache = env.cache();
    env.cli(&[
        "gc",
        "--cache",
        cache.to_str().unwrap(),
        "--max-bytes",
        "0",
        "--keep",
        g.to_str().unwrap(),
    ])
    .ok();
    assert!(parts(&env).iter().all(|p| env.blob(p).is_file()));
    let r = env.run(&g, &[]).ok();
    assert!(r.with_status("ran").is_empty(), "{:?}", r.statuses());
    env.cli(&["gc", "--cache", cache.to_str().unwrap(), "--max-bytes", "0"])
        .ok();
    assert!(parts(&env).is_empty(), "no entry names a part gc removed");
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.status("views"), "ran");
}
