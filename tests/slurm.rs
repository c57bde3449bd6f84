//! `kodama-dag submit --engine slurm` (issue 52): the job scripts it writes, run by hand and
//! through a real one-node Slurm cluster.
//!
//! The tests marked "needs Slurm" run against the cluster `.ci/run` starts
//! (`scripts/slurm_local.sh`, Debian's slurm-wlm and munge). Without one they skip, saying so;
//! under `CI=true` they fail instead, since `.ci/run` is meant to have started it.

mod common;
use common::*;

use std::path::{Path, PathBuf};
use std::process::Command;

/// A sweep over CHAIN's blur: truth, lidar, dsm, capped and pstats are shared by every variant;
/// smooth, resid and stats are each variant's own.
const SWEEP: &str = r#"Sweep(
    graph: "g.ron",
    axes: { "sigma": Grid(set: "smooth.sigma_m", values: [1.0, 2.0, 4.0]) },
    metrics: ["stats.mean", "stats.max"],
)"#;

/// Whether a Slurm cluster answers here. Without one the test skips with a line saying so, and
/// fails under CI=true. A loaded machine can leave slurmd unanswering for a while (`idle*`), so
/// its node gets a minute to come back before the cluster counts as absent.
fn slurm_up(test: &str) -> bool {
    let state = || {
        Command::new("sinfo")
            .args(["-h", "-o", "%T"])
            .output()
            .map(|o| {
                let s = String::from_utf8_lossy(&o.stdout).trim().to_string();
                if o.status.success() {
                    s
                } else {
                    format!(
                        "sinfo failed: {}",
                        String::from_utf8_lossy(&o.stderr).trim()
                    )
                }
            })
            .unwrap_or_else(|e| format!("sinfo did not run: {e}"))
    };
    let usable = |s: &str| {
        s.lines()
            .any(|l| ["idle", "mixed", "allocated"].contains(&l.trim()))
    };
    let mut seen = state();
    // Not at all (no sinfo, no configuration) is absent at once; a node that does not answer
    // yet is waited for.
    if !seen.starts_with("sinfo") {
        for _ in 0..60 {
            if usable(&seen) {
                break;
            }
            std::thread::sleep(std::time::Duration::from_secs(1));
            seen = state();
        }
    }
    let up = usable(&seen);
    if !up {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{test}: no Slurm cluster answers `sinfo` (last seen: {seen:?}; .ci/run starts one \
             with scripts/slurm_local.sh; see its output for why it did not)"
        );
        eprintln!(
            "{test}: skipped: no Slurm cluster answers `sinfo` (last seen: {seen:?}; start one \
             with `scripts/slurm_local.sh start DIR` and export SLURM_CONF)"
        );
    }
    up
}

/// The folder of submission `n` under `out`.
fn submission(env: &Env, n: u32) -> PathBuf {
    env.out().join("slurm").join(n.to_string())
}

/// Runs one of a submission's job scripts the way a compute node would, without Slurm.
fn run_script(script: &Path, task: Option<usize>) -> Run {
    let mut cmd = Command::new("bash");
    cmd.arg(script).env_remove("SLURM_CPUS_PER_TASK");
    if let Some(t) = task {
        cmd.env("SLURM_ARRAY_TASK_ID", t.to_string());
    }
    finish(cmd.output().expect("spawn bash"))
}

/// The node runs a sweep's variant task reported ("variant I: NAME: N node runs").
fn node_runs(stderr: &str) -> usize {
    stderr
        .lines()
        .find_map(|l| {
            l.strip_suffix(" node runs")?
                .rsplit(": ")
                .next()?
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no node-run count in {stderr}"))
}

/// The local sweep's table, from a cache and output folder of its own beside `env`'s: what
/// every submitted sweep must reproduce, byte for byte.
fn local_table(env: &Env) -> (Vec<u8>, Vec<u8>) {
    env.cli(&[
        "sweep",
        "s.ron",
        "--cache",
        "local-cache",
        "--out",
        "local-out",
        "-q",
    ])
    .ok();
    let out = env.path("local-out");
    (
        std::fs::read(out.join("table.csv")).unwrap(),
        std::fs::read(out.join("table.md")).unwrap(),
    )
}

/// `--dry-run` writes a readable chain (prefix, array, table) and submits nothing; the scripts,
/// run by hand as a compute node runs them, give the local sweep's table with each shared node
/// computed once, by the prefix. Runs everywhere: no Slurm needed.
#[test]
fn submitted_scripts_run_by_hand_give_the_local_table() {
    let env = Env::new();
    env.write("g.ron", CHAIN);
    env.write("s.ron", SWEEP);
    let r = env
        .cli(&[
            "submit",
            "s.ron",
            "--cache",
            "cache",
            "--out",
            "out",
            "--dry-run",
            "-j",
            "2",
            "--array-limit",
            "2",
            "--sbatch",
            "--partition=debug --comment='a b'",
        ])
        .ok();
    assert!(r.stderr.contains("nothing submitted"), "{}", r.stderr);
    let dir = submission(&env, 1);
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap();
    let submit = read("submit.sh");
    assert_eq!(r.stdout, submit, "--dry-run prints the sbatch commands");
    for want in [
        "prefix=$(sbatch --parsable --partition=debug '--comment=a b' prefix.sh)",
        "--dependency=afterok:${prefix%%;*} --kill-on-invalid-dep=yes --array=0-2%2",
        "--dependency=afterok:${prefix%%;*}:${variants%%;*} --kill-on-invalid-dep=yes",
    ] {
        assert!(submit.contains(want), "submit.sh lacks {want:?}:\n{submit}");
    }
    let prefix = read("prefix.sh");
    assert!(prefix.contains("up to capped, pstats"), "{prefix}");
    assert!(prefix.contains("#SBATCH --cpus-per-task=2"), "{prefix}");
    assert!(
        prefix.contains(" --prefix -j \"${SLURM_CPUS_PER_TASK:-2}\""),
        "{prefix}"
    );
    assert!(
        prefix.contains("the cluster's defaults apply"),
        "no run measured yet, so no --mem: {prefix}"
    );
    assert!(read("variants.sh").contains("--variant \"$SLURM_ARRAY_TASK_ID\""));
    assert!(env.blobs().is_empty(), "--dry-run ran nothing");

    // As the cluster would: the prefix, then each array task, then the table.
    let p = run_script(&dir.join("prefix.sh"), None);
    assert_eq!(p.code, 0, "{}", p.stderr);
    for task in 0..3 {
        let v = run_script(&dir.join("variants.sh"), Some(task));
        assert_eq!(v.code, 0, "{}", v.stderr);
        assert_eq!(
            node_runs(&v.stderr),
            3,
            "task {task} runs only its own cone (smooth, resid, stats): {}",
            v.stderr
        );
    }
    let t = run_script(&dir.join("table.sh"), None);
    assert_eq!(t.code, 0, "{}", t.stderr);
    assert!(
        t.stderr.contains("3 variants, 0 node runs in all"),
        "{}",
        t.stderr
    );
    let (csv, md) = local_table(&env);
    assert_eq!(std::fs::read(env.out().join("table.csv")).unwrap(), csv);
    assert_eq!(std::fs::read(env.out().join("table.md")).unwrap(), md);

    // Submitted again: every variant is cached, so only the table job is left, and the jobs now
    // ask for memory and time from the runs measured above.
    let r = env
        .cli(&[
            "submit",
            "s.ron",
            "--cache",
            "cache",
            "--out",
            "out",
            "--dry-run",
        ])
        .ok();
    assert!(
        r.stderr
            .contains("3 of 3 variants are in the cache already"),
        "{}",
        r.stderr
    );
    let dir = submission(&env, 2);
    assert!(!dir.join("variants.sh").exists() && !dir.join("prefix.sh").exists());
    let table = std::fs::read_to_string(dir.join("table.sh")).unwrap();
    assert!(table.contains("#SBATCH --mem=1024M"), "{table}");
    assert!(table.contains("#SBATCH --time=10"), "{table}");
    assert!(table.contains("peak RSS"), "{table}");
}

/// A graph is one job; its script, run by hand, gives what a local run gives.
#[test]
fn a_submitted_graph_is_one_run_job() {
    let env = Env::new();
    env.write("g.ron", CHAIN);
    env.cli(&[
        "submit",
        "g.ron",
        "--cache",
        "cache",
        "--out",
        "out",
        "--dry-run",
        "--target",
        "stats",
        "--set",
        "smooth.sigma_m=3.0",
    ])
    .ok();
    let script = submission(&env, 1).join("run.sh");
    let text = std::fs::read_to_string(&script).unwrap();
    assert!(text.contains(" --set smooth.sigma_m=3.0 "), "{text}");
    assert!(
        text.contains(" --target stats --json --quiet -j "),
        "{text}"
    );
    let by_hand = run_script(&script, None).ok();
    let local = Env::new();
    local.write("g.ron", CHAIN);
    let want = local
        .run(
            &local.path("g.ron"),
            &["--target", "stats", "--set", "smooth.sigma_m=3.0"],
        )
        .ok();
    assert_eq!(by_hand.digests(), want.digests());
}

/// `submit city.ron --dry-run` in 300 m tiles, into cache/ and out/.
fn submit_tiled_dry(env: &Env) -> Run {
    env.cli(&[
        "submit",
        "city.ron",
        "--cache",
        "cache",
        "--out",
        "out",
        "--dry-run",
        "--tile-m",
        "300",
    ])
    .ok()
}

/// The scene a local tiled run of TILED_CITY in 300 m tiles exports, from a cache of its own.
fn local_tiled_scene(env: &Env) -> Vec<u8> {
    env.cli(&[
        "run",
        "city.ron",
        "--cache",
        "local-cache",
        "--out",
        "local-out",
        "--quiet",
        "--tile-m",
        "300",
    ])
    .ok();
    std::fs::read(env.path("local-out").join("scene.glb")).unwrap()
}

/// A tiled graph is a prefix job (the city and its truth, made once), one array task per tile
/// and a merge job. The scripts, run by hand as compute nodes run them, give the local tiled
/// run's scene byte for byte; each tile task makes only its own tile's nodes, and the merge job
/// makes only the merges and what reads them. Runs everywhere: no Slurm needed.
#[test]
fn a_tiled_graph_is_prefix_tiles_and_merge() {
    let env = Env::new();
    env.write("city.ron", TILED_CITY);
    let r = submit_tiled_dry(&env);
    assert!(r.stderr.contains("4 tiles of 300 m, halo"), "{}", r.stderr);
    let dir = submission(&env, 1);
    let submit = std::fs::read_to_string(dir.join("submit.sh")).unwrap();
    assert!(submit.contains("--array=0-3 tiles.sh"), "{submit}");
    assert!(submit.contains("afterok:${tiles%%;*}"), "{submit}");
    let prefix = run_script(&dir.join("prefix.sh"), None).ok();
    assert_eq!(prefix.with_status("ran"), ids(&["city", "truth"]));
    for t in 0..4 {
        let task = run_script(&dir.join("tiles.sh"), Some(t)).ok();
        let ran = task.with_status("ran");
        let tile = ["x0y0", "x1y0", "x0y1", "x1y1"][t];
        assert_eq!(ran.len(), 9, "tile {t}: {ran:?}");
        assert!(
            ran.iter().all(|id| id.ends_with(&format!("@{tile}"))),
            "tile {t} made another tile's nodes: {ran:?}"
        );
    }
    let merge = run_script(&dir.join("merge.sh"), None).ok();
    assert_eq!(
        merge.with_status("ran"),
        ids(&["terrain2", "solids", "scene"])
    );
    let scene = std::fs::read(env.out().join("scene.glb")).unwrap();
    assert!(
        scene == local_tiled_scene(&env),
        "the scripts' scene differs from a local run's"
    );
}

/// TILED_CITY with two transmitters, each map bounded by its reach, and their best-server
/// layer over the merged scene.
fn tiled_city_with_radio() -> String {
    let radio = r#"
        "map_a": RadioMap(scene: "scene", terrain: "terrain2", tx: (150.0, 150.0, 25.0), freq_hz: 3.5e9,
                          cell_m: 10.0, reach_m: 200.0, options: (rays: 20000)),
        "map_b": RadioMap(scene: "scene", terrain: "terrain2", tx: (450.0, 420.0, 25.0), freq_hz: 3.5e9,
                          cell_m: 10.0, reach_m: 200.0, options: (rays: 20000)),
        "best":  Coverage(maps: ["map_a", "map_b"], layer: BestServer,
                          transmitters: [CoverageTx(id: "A", freq_hz: 3.5e9), CoverageTx(id: "B", freq_hz: 3.5e9)]),
    },
    outputs: { "best.tif": "best" },"#;
    let (head, _) = TILED_CITY.split_once("\n    },\n    outputs:").unwrap();
    format!("{head}{radio}\n)\n")
}

/// A tiled graph's radio work is partitioned by transmitter: after the tiles, a gather job
/// makes the merged scene and terrain once, a job array makes one transmitter's map per task
/// (`--radio I`, nothing else), and the merge job finds them cached and makes the best-server
/// layer. The scripts run by hand give the local tiled run's layer byte for byte.
#[test]
fn a_tiled_graphs_radio_is_one_array_task_per_transmitter() {
    let env = Env::new();
    let graph = tiled_city_with_radio();
    env.write("city.ron", &graph);
    submit_tiled_dry(&env);
    let dir = submission(&env, 1);
    let submit = std::fs::read_to_string(dir.join("submit.sh")).unwrap();
    assert!(submit.contains("--array=0-1 radio.sh"), "{submit}");
    let gather = std::fs::read_to_string(dir.join("gather-radio.sh")).unwrap();
    assert!(
        gather.contains(" --target terrain2 --target scene "),
        "{gather}"
    );
    run_script(&dir.join("prefix.sh"), None).ok();
    for t in 0..4 {
        run_script(&dir.join("tiles.sh"), Some(t)).ok();
    }
    let gathered = run_script(&dir.join("gather-radio.sh"), None).ok();
    assert_eq!(
        gathered.with_status("ran"),
        ids(&["terrain2", "solids", "scene"])
    );
    for (t, map) in ["map_a", "map_b"].iter().enumerate() {
        let task = run_script(&dir.join("radio.sh"), Some(t)).ok();
        assert_eq!(task.with_status("ran"), ids(&[map]));
    }
    let merge = run_script(&dir.join("merge.sh"), None).ok();
    assert_eq!(merge.with_status("ran"), ids(&["best"]));
    let local = Env::new();
    local.write("city.ron", &graph);
    local
        .cli(&[
            "run", "city.ron", "--cache", "cache", "--out", "out", "--quiet", "--tile-m", "300",
        ])
        .ok();
    let best = |e: &Env| std::fs::read(e.path("out").join("best.tif")).unwrap();
    assert!(
        best(&env) == best(&local),
        "the scripts' layer differs from a local run's"
    );
    // --radio names a radio node by its place; one past the last is a usage error.
    let r = env.cli(&[
        "run", "city.ron", "--cache", "cache", "--tile-m", "300", "--radio", "2",
    ]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("from 0 to 1, found 2"), "{}", r.stderr);
}

/// Needs Slurm. A tiled graph submitted and waited for gives the local tiled run's scene; submitted
/// again it queues only the merge job, every tile being cached.
#[test]
fn a_tiled_graph_through_slurm_gives_the_local_scene() {
    if !slurm_up("a_tiled_graph_through_slurm_gives_the_local_scene") {
        return;
    }
    let env = Env::new();
    env.write("city.ron", TILED_CITY);
    let submit = || {
        env.cli(&[
            "submit", "city.ron", "--cache", "cache", "--out", "out", "--tile-m", "300", "--wait",
            "--poll-s", "1",
        ])
    };
    let r = submit().ok();
    assert!(
        r.stdout.contains("prefix=") && r.stdout.contains("tiles=") && r.stdout.contains("merge="),
        "{}",
        r.stdout
    );
    let scene = std::fs::read(env.out().join("scene.glb")).unwrap();
    assert!(
        scene == local_tiled_scene(&env),
        "Slurm's scene differs from a local run's"
    );
    let again = submit().ok();
    assert!(
        again.stdout.starts_with("merge="),
        "only the merge job: {}",
        again.stdout
    );
}

/// Bad input exits 2 before anything is written or queued: a variant whose graph is invalid, a
/// --sbatch with unbalanced quotes, a poll interval out of range, --target on a sweep.
#[test]
fn bad_submissions_exit_2_and_queue_nothing() {
    let env = Env::new();
    env.write("g.ron", CHAIN);
    env.write("bad.ron", &SWEEP.replace("[1.0, 2.0, 4.0]", "[1.0, -2.0]"));
    env.write("s.ron", SWEEP);
    let cases: [(&[&str], &str); 4] = [
        (&["submit", "bad.ron", "--dry-run"], "sigma=-2.0"),
        (
            &["submit", "s.ron", "--dry-run", "--sbatch", "--comment='x"],
            "unbalanced quotes",
        ),
        (
            &["submit", "s.ron", "--dry-run", "--poll-s", "0"],
            "from 1 to 3600",
        ),
        (
            &["submit", "s.ron", "--dry-run", "--target", "stats"],
            "--target is for graphs",
        ),
    ];
    for (args, want) in cases {
        let r = env.cli(args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(want), "{args:?}: {}", r.stderr);
    }
    assert!(
        !env.path("out").exists(),
        "no scripts written for bad input"
    );
}

/// Needs Slurm. A sweep submitted and waited for gives the local sweep's table bytes; submitted
/// again it queues only the table job, which runs no node.
#[test]
fn a_sweep_through_slurm_gives_the_local_table() {
    if !slurm_up("a_sweep_through_slurm_gives_the_local_table") {
        return;
    }
    let env = Env::new();
    env.write("g.ron", CHAIN);
    env.write("s.ron", SWEEP);
    let submit = || {
        env.cli(&[
            "submit", "s.ron", "--cache", "cache", "--out", "out", "--wait", "--poll-s", "1",
        ])
    };
    let r = submit().ok();
    let (csv, md) = local_table(&env);
    assert_eq!(std::fs::read(env.out().join("table.csv")).unwrap(), csv);
    assert_eq!(std::fs::read(env.out().join("table.md")).unwrap(), md);
    assert!(
        r.stdout.contains("prefix=") && r.stdout.contains("variants="),
        "{}",
        r.stdout
    );
    let dir = submission(&env, 1);
    let logs: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("variants-"))
        .collect();
    assert_eq!(logs.len(), 3, "one log per array task: {logs:?}");
    for log in logs {
        let text = std::fs::read_to_string(dir.join(&log)).unwrap();
        assert_eq!(
            node_runs(&text),
            3,
            "{log}: only the variant's own cone ran: {text}"
        );
    }
    let again = submit().ok();
    assert!(
        again.stdout.starts_with("table="),
        "only the table job: {}",
        again.stdout
    );
    let table_log = std::fs::read_dir(submission(&env, 2))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_string_lossy().contains("table-"))
        .unwrap();
    let text = std::fs::read_to_string(table_log).unwrap();
    assert!(text.contains("3 variants, 0 node runs in all"), "{text}");
}

/// Needs Slurm. A variant that fails on the user's input fails its task with exit 2, which
/// `--wait` keeps; the table job is cancelled, not left pending; once the input is fixed, a
/// resubmission queues only the failed variant.
#[test]
fn a_failing_variant_keeps_exit_2_through_slurm() {
    if !slurm_up("a_failing_variant_keeps_exit_2_through_slurm") {
        return;
    }
    let env = Env::new();
    env.write(
        "g.ron",
        r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (0.0, 0.0), cell_m: 1.0),
    nodes: { "pts": ReadXyz(path: "a.xyz"), "stats": PointStats(points: "pts") },
)"#,
    );
    env.write("a.xyz", "x y z\n1 2 3\n4 5 6\n");
    env.write("b.xyz", "x y z\n1 2 3\n4 five 6\n");
    env.write(
        "s.ron",
        r#"Sweep(
    graph: "g.ron",
    axes: { "file": Switch({ "a": [], "b": ["pts.path=\"b.xyz\""] }) },
    metrics: ["stats.count"],
)"#,
    );
    let submit = || {
        env.cli(&[
            "submit", "s.ron", "--cache", "cache", "--out", "out", "--wait", "--poll-s", "1",
        ])
    };
    let r = submit();
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("b.xyz: line 3, column 3"),
        "the task's own error is shown: {}",
        r.stderr
    );
    assert!(
        r.stderr.contains("table") && r.stderr.contains("cancelled: a job it waits for failed"),
        "{}",
        r.stderr
    );
    assert!(!env.out().join("table.csv").exists());
    env.write("b.xyz", "x y z\n1 2 3\n4 5 6\n7 8 9\n");
    let r = submit().ok();
    assert!(
        r.stderr
            .contains("1 of 2 variants are in the cache already"),
        "{}",
        r.stderr
    );
    let csv = std::fs::read_to_string(env.out().join("table.csv")).unwrap();
    assert_eq!(csv, "file,stats.count\na,2.000000\nb,3.000000\n");
}

/// Needs Slurm. A job cancelled with SIGKILL while it writes to the cache (the writer paused
/// halfway by the fault-injection variable, which sbatch hands the job with the rest of the
/// environment) leaves nothing a later run trusts: every stored blob hashes to its name, and a
/// rerun gives a clean run's digests.
#[test]
fn a_job_killed_mid_write_leaves_nothing_trusted() {
    if !slurm_up("a_job_killed_mid_write_leaves_nothing_trusted") {
        return;
    }
    let env = Env::new();
    env.write("g.ron", CHAIN);
    let o = Command::new(BIN)
        .args(["submit", "g.ron", "--cache", "cache", "--out", "out"])
        .env("KODAMA_DAG_FAULT_SLOW_WRITE_MS", "5000")
        .current_dir(env.dir.path())
        .output()
        .unwrap();
    let r = finish(o).ok();
    let id = r
        .stdout
        .trim()
        .strip_prefix("run=")
        .expect("run=ID")
        .to_string();
    env.wait_for_half_written_blob(120);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    let k = Command::new("scancel")
        .args(["--signal=KILL", "--full", &id])
        .output()
        .unwrap();
    assert!(k.status.success(), "{}", String::from_utf8_lossy(&k.stderr));
    // Wait for Slurm to see the job gone before looking at the cache.
    loop {
        assert!(std::time::Instant::now() < deadline, "job {id} did not end");
        let q = Command::new("squeue")
            .args(["-h", "-t", "all", "-o", "%T", "-j", &id])
            .output()
            .unwrap();
        let state = String::from_utf8_lossy(&q.stdout).trim().to_string();
        if ["CANCELLED", "FAILED", "COMPLETED"].contains(&state.as_str()) {
            assert_ne!(state, "COMPLETED", "the job was to be killed mid-write");
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    for b in env.blobs() {
        let bytes = std::fs::read(&b).unwrap();
        assert_eq!(
            blake3::hash(&bytes).to_hex().as_str(),
            b.file_name().unwrap().to_str().unwrap()
        );
    }
    let rerun = env.run(&env.path("g.ron"), &[]).ok();
    let clean = Env::new();
    clean.write("g.ron", CHAIN);
    assert_eq!(
        rerun.digests(),
        clean.run(&clean.path("g.ron"), &[]).ok().digests()
    );
}
