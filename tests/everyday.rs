//! The engine in everyday use: sweeps over a graph's parameters, resuming an interrupted sweep,
//! watch mode, and gc with a kept graph.

mod common;
use common::*;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

fn table(path: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(String::from))
                .collect()
        })
        .collect()
}

/// A 3 x 2 sweep over the demo graph: everything upstream of the swept nodes runs once, in the
/// first variant; each variant's metrics are what a single run with the same overrides gives.
#[test]
fn demo_sweep_shares_upstream_nodes_and_matches_single_runs() {
    let env = Env::new();
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/demo.ron");
    let sweep = env.write(
        "s.ron",
        &format!(
            r#"Sweep(
    graph: {demo:?},
    axes: {{
        "cell": Grid(set: "coverage.cell_m", values: [2.0, 4.0, 8.0]),
        "tolerance": Switch({{ "fine": [], "coarse": ["solids.tolerance_m=0.3"] }}),
    }},
    metrics: ["coverage_stats.mean", "footprint_score.iou"],
)"#
        ),
    );
    // The sweep sits in a temp folder, its base graph in the repository: allowed explicitly.
    // The engine's sharing is what is tested, not the street level: the demo's first 64 views
    // (of 416) keep its three runs quick.
    let r = env.sweep(&sweep, &["--allow-outside", "--set", "views.max_views=64"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rows = table(&env.out().join("table.csv"));
    assert_eq!(rows.len(), 6);
    // The run records of the variants: the lidar (upstream of everything swept) ran once.
    let runs_dir = env.cache().join("runs");
    let mut lidar_runs = 0;
    for entry in std::fs::read_dir(&runs_dir).unwrap() {
        for rec in std::fs::read_dir(entry.unwrap().path().join("records")).unwrap() {
            let p = rec.unwrap().path();
            let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
            for n in v["nodes"].as_array().unwrap() {
                if n["id"] == "lidar" && n["status"] == "ran" {
                    lidar_runs += 1;
                }
            }
        }
    }
    assert_eq!(
        lidar_runs, 1,
        "the shared upstream nodes run in one variant only"
    );
    // A single run of one variant, on a fresh cache, gives the same metrics.
    let single = Env::new();
    let one = single
        .run(
            &demo,
            &[
                "--set",
                "coverage.cell_m=4.0",
                "--set",
                "solids.tolerance_m=0.3",
                "--set",
                "views.max_views=64",
            ],
        )
        .ok();
    assert!(one.with_status("ran").len() > 20);
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(single.out().join("coverage_stats.json")).unwrap())
            .unwrap();
    let row = rows
        .iter()
        .find(|r| r["cell"] == "4.0" && r["tolerance"] == "coarse")
        .unwrap();
    let swept: f64 = row["coverage_stats.mean"].parse().unwrap();
    assert!(
        (swept - stats["mean"].as_f64().unwrap()).abs() < 1e-5,
        "{swept} vs {stats}"
    );
    // Different cells give different maps.
    let means: std::collections::BTreeSet<String> = rows
        .iter()
        .map(|r| r["coverage_stats.mean"].clone())
        .collect();
    assert!(means.len() >= 3, "{means:?}");
}

/// A sweep killed after two variants resumes: the finished variants rerun nothing.
#[test]
fn an_interrupted_sweep_resumes_without_redoing_variants() {
    let env = Env::new();
    let g = env.write("g.ron", CHAIN);
    let sweep = env.write(
        "s.ron",
        r#"Sweep(
    graph: "g.ron",
    axes: { "sigma": Grid(set: "smooth.sigma_m", values: [1.0, 2.0, 3.0, 4.0]) },
    metrics: ["stats.mean", "stats.std"],
)"#,
    );
    let _ = g;
    let args = |extra: &[&str]| {
        let mut a = vec![
            "sweep".to_string(),
            sweep.to_str().unwrap().to_string(),
            "--cache".into(),
            env.cache().to_str().unwrap().into(),
            "--out".into(),
            env.out().to_str().unwrap().into(),
            "-q".into(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let first = Command::new(BIN)
        .args(args(&[]))
        .env("KODAMA_DAG_FAULT_SWEEP_STOP_AFTER", "2")
        .current_dir(env.dir.path())
        .output()
        .unwrap();
    assert_eq!(first.status.code(), Some(1), "interrupted");
    assert!(
        !env.out().join("table.csv").exists(),
        "no table from a half sweep"
    );
    let again = Command::new(BIN)
        .args(args(&[]))
        .current_dir(env.dir.path())
        .output()
        .unwrap();
    assert_eq!(
        again.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    // The run records of this second invocation: one per variant, newest last.
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(stderr.contains("4 variants"), "{stderr}");
    let mut records: Vec<serde_json::Value> = Vec::new();
    for entry in std::fs::read_dir(env.cache().join("runs")).unwrap() {
        let mut files: Vec<_> = std::fs::read_dir(entry.unwrap().path().join("records"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for p in files {
            records.push(serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap());
        }
    }
    let ran = |r: &serde_json::Value| {
        r["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|n| n["status"] == "ran")
            .count()
    };
    // 2 variants before the interrupt, then 4 on resume.
    assert_eq!(records.len(), 6, "{records:?}");
    let resumed = &records[2..];
    assert_eq!(ran(&resumed[0]), 0, "variant 1 was finished");
    assert_eq!(ran(&resumed[1]), 0, "variant 2 was finished");
    assert!(ran(&resumed[2]) > 0 && ran(&resumed[3]) > 0);
    assert_eq!(table(&env.out().join("table.csv")).len(), 4);
}

/// `metrics_only`: each variant runs just what its metrics need; a node no metric reaches (the
/// point statistics here) never runs, no variant's outputs are written, and the metrics are the
/// ones a full sweep gives.
#[test]
fn a_metrics_only_sweep_runs_only_what_its_metrics_need() {
    let env = Env::new();
    env.write("g.ron", CHAIN);
    let sweep_text = |only: bool| {
        format!(
            r#"Sweep(
    graph: "g.ron",
    axes: {{ "sigma": Grid(set: "smooth.sigma_m", values: [1.0, 3.0]) }},
    metrics: ["stats.mean"],
    metrics_only: {only},
)"#
        )
    };
    let ran_ids = |cache: &Path| {
        let mut ids = std::collections::BTreeSet::new();
        for entry in std::fs::read_dir(cache.join("runs")).unwrap() {
            for rec in std::fs::read_dir(entry.unwrap().path().join("records")).unwrap() {
                let v: serde_json::Value =
                    serde_json::from_slice(&std::fs::read(rec.unwrap().path()).unwrap()).unwrap();
                for n in v["nodes"].as_array().unwrap() {
                    if n["status"] == "ran" {
                        ids.insert(n["id"].as_str().unwrap().to_string());
                    }
                }
            }
        }
        ids
    };
    let only = env.write("only.ron", &sweep_text(true));
    let r = env.sweep(&only, &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let ran = ran_ids(&env.cache());
    assert!(ran.contains("stats") && ran.contains("smooth"), "{ran:?}");
    assert!(!ran.contains("pstats"), "no metric needs pstats: {ran:?}");
    assert!(
        !env.out().join("variants").exists(),
        "a metrics-only sweep writes no variant's outputs"
    );
    let narrow = table(&env.out().join("table.csv"));

    let full_env = Env::new();
    full_env.write("g.ron", CHAIN);
    let all = full_env.write("all.ron", &sweep_text(false));
    let r = full_env.sweep(&all, &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(ran_ids(&full_env.cache()).contains("pstats"));
    let wide = table(&full_env.out().join("table.csv"));
    assert_eq!(narrow.len(), 2);
    for (a, b) in narrow.iter().zip(&wide) {
        assert_eq!(a["stats.mean"], b["stats.mean"]);
    }
}

/// Watch: an edit reruns only what it affects, a broken edit is reported and the watch goes on,
/// and the next good edit runs.
#[test]
fn watch_reruns_what_an_edit_affects_and_survives_a_broken_edit() {
    let env = Env::new();
    let g = env.write("g.ron", CHAIN);
    let mut child = Command::new(BIN)
        .args([
            "watch",
            g.to_str().unwrap(),
            "--cache",
            env.cache().to_str().unwrap(),
            "--out",
            env.out().to_str().unwrap(),
            "--json",
            "-q",
            "--debounce-ms",
            "200",
        ])
        .current_dir(env.dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (tx, rx) = mpsc::channel::<(bool, String)>();
    let out = child.stdout.take().unwrap();
    let err = child.stderr.take().unwrap();
    let t1 = tx.clone();
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines() {
            let _ = t1.send((true, l.unwrap_or_default()));
        }
    });
    std::thread::spawn(move || {
        for l in BufReader::new(err).lines() {
            let _ = tx.send((false, l.unwrap_or_default()));
        }
    });
    let timeout = Duration::from_secs(120);
    // Stdout and stderr arrive through two threads in no fixed order: keep both streams and read
    // each from its own cursor.
    struct Streams {
        rx: mpsc::Receiver<(bool, String)>,
        out: Vec<String>,
        err: Vec<String>,
        out_at: usize,
        err_at: usize,
    }
    impl Streams {
        fn pull(&mut self, timeout: Duration, what: &str) {
            let (is_out, line) = self
                .rx
                .recv_timeout(timeout)
                .unwrap_or_else(|_| panic!("{what} in time; stderr so far: {:?}", self.err));
            if is_out {
                self.out.push(line)
            } else {
                self.err.push(line)
            }
        }
        fn next_record(&mut self, timeout: Duration) -> serde_json::Value {
            while self.out_at >= self.out.len() {
                self.pull(timeout, "a run record");
            }
            self.out_at += 1;
            serde_json::from_str(&self.out[self.out_at - 1]).unwrap()
        }
        fn next_err_matching(&mut self, timeout: Duration, pat: &str) -> String {
            loop {
                while self.err_at >= self.err.len() {
                    self.pull(timeout, pat);
                }
                self.err_at += 1;
                if self.err[self.err_at - 1].contains(pat) {
                    return self.err[self.err_at - 1].clone();
                }
            }
        }
    }
    let mut st = Streams {
        rx,
        out: vec![],
        err: vec![],
        out_at: 0,
        err_at: 0,
    };
    let status = |r: &serde_json::Value, id: &str| -> String {
        r["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["id"] == id)
            .map(|n| n["status"].as_str().unwrap().to_string())
            .unwrap()
    };
    let first = st.next_record(timeout);
    assert_eq!(status(&first, "lidar"), "ran");
    st.next_err_matching(timeout, "watching");
    std::fs::write(&g, CHAIN.replace("sigma_m: 2.0", "sigma_m: 3.0")).unwrap();
    let second = st.next_record(timeout);
    assert_eq!(status(&second, "smooth"), "ran");
    assert_eq!(status(&second, "lidar"), "cached");
    assert_eq!(status(&second, "pstats"), "cached");
    st.next_err_matching(timeout, "watching");
    std::fs::write(&g, CHAIN.replace("sigma_m: 2.0", "sigma_m: ")).unwrap();
    // The broken graph is reported on stderr, and the watch goes on without a run.
    st.next_err_matching(timeout, "g.ron:");
    st.next_err_matching(timeout, "watching");
    assert_eq!(st.out_at, st.out.len(), "no run for a broken graph");
    std::fs::write(&g, CHAIN.replace("sigma_m: 2.0", "sigma_m: 4.0")).unwrap();
    let third = st.next_record(timeout);
    assert_eq!(status(&third, "smooth"), "ran");
    assert_eq!(status(&third, "dsm"), "cached");
    child.kill().unwrap();
    child.wait().unwrap();
}

/// gc down to nothing with a kept graph: the kept graph stays fully cached, the other does not.
#[test]
fn gc_keeps_what_a_kept_graph_needs() {
    let env = Env::new();
    let a = env.write("a.ron", CHAIN);
    let b = env.write(
        "b.ron",
        &CHAIN.replace("seed: 3, size_m", "seed: 4, size_m"),
    );
    env.run(&a, &[]).ok();
    env.run(&b, &[]).ok();
    let r = env.cli(&[
        "gc",
        "--cache",
        env.cache().to_str().unwrap(),
        "--max-bytes",
        "0",
        "--keep",
        a.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let again = env.run(&a, &[]).ok();
    assert!(
        again.with_status("ran").is_empty(),
        "{:?}",
        again.statuses()
    );
    let other = env.run(&b, &[]).ok();
    assert!(!other.with_status("ran").is_empty());
}

/// The family ablation runs the test family's own sites: its "site" axis is family_test's, choice
/// for choice, so the ablation's "full" rows are the headline's pairs. Every variant checks.
#[test]
fn the_family_ablation_runs_the_test_familys_sites() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/sweeps");
    let test = kodama_dag::sweep::load_sweep(&dir.join("family_test.ron"), false).unwrap();
    let ablation = kodama_dag::sweep::load_sweep(&dir.join("family_ablation.ron"), false).unwrap();
    let site = |s: &kodama_dag::sweep::Sweep| {
        s.axes
            .iter()
            .find(|(name, _)| name == "site")
            .map(|(_, c)| c.clone())
            .expect("a site axis")
    };
    assert_eq!(site(&test), site(&ablation));
    assert!(ablation.metrics_only);
    let env = Env::new();
    let r = env.cli(&[
        "sweep",
        dir.join("family_ablation.ron").to_str().unwrap(),
        "--dry-run",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(r.stdout.lines().count(), 8 * 5, "{}", r.stdout);
}

/// The committed ablation sweep loads, and every one of its variants is a valid graph.
#[test]
fn the_ablation_sweep_checks() {
    let env = Env::new();
    let sweep = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/sweeps/ablation.ron");
    let r = env.cli(&["sweep", sweep.to_str().unwrap(), "--dry-run"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(r.stdout.lines().count(), 16, "{}", r.stdout);
    // A sweep naming a node that is not there fails before running anything, exit 2.
    let bad = env.write(
        "bad.ron",
        &format!(
            "Sweep(graph: {:?}, axes: {{ \"x\": Grid(set: \"nope.sigma_m\", values: [1.0]) }}, metrics: [])",
            Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/demo.ron")
        ),
    );
    let r = env.sweep(&bad, &["--allow-outside"]);
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("nope"), "{}", r.stderr);
    assert!(
        !env.cache().join("cas").exists()
            || std::fs::read_dir(env.cache().join("cas"))
                .unwrap()
                .next()
                .is_none()
    );
}
