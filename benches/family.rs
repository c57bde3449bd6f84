//! The test family's headline (issue 51): `cargo bench --bench family` runs
//! graphs/sweeps/family_test.ron and graphs/sweeps/family_ablation.ron through the cache
//! ($KODAMA_DAG_CACHE, else ./cache; about 25 min cold on 2 cores) and prints the full twin's
//! P2P RMSE mean and spread over the city-transmitter pairs, the share of pairs where it beats the
//! Sec. 4.1 solids, and each Sec. 4.2 stage's gain with its verdict. The tables land in
//! out/family_test and out/family_ablation, where `python3 scripts/family_table.py` reads them.
//! Figures go in BENCHMARKS.md; nothing here is asserted, as a bench's figures never are.

use std::path::{Path, PathBuf};

use kodama_dag::cache::Cache;
use kodama_dag::progress::{Mode, Reporter};
use kodama_dag::sweep::{SweepOptions, VariantResult, load_sweep, run_sweep};

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cache_dir = std::env::var_os("KODAMA_DAG_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("cache"));
    let cache = Cache::open(&cache_dir).expect("open the cache");
    let run = |name: &str| -> (Vec<String>, Vec<VariantResult>) {
        let sweep = load_sweep(
            &root.join("graphs/sweeps").join(format!("{name}.ron")),
            false,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let opts = SweepOptions {
            out_dir: root.join("out").join(name),
            ..Default::default()
        };
        let started = std::time::Instant::now();
        let results = run_sweep(
            &sweep,
            &cache,
            &opts,
            &Reporter::new(Mode::Quiet, 0),
            |i, n, v| eprintln!("{name}: variant {}/{n}: {}", i + 1, v.name()),
        )
        .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        eprintln!("{name}: {:.0} s", started.elapsed().as_secs_f64());
        (sweep.metrics, results)
    };
    let column = |metrics: &[String], results: &[VariantResult], key: &str| -> Vec<f64> {
        let k = metrics.iter().position(|m| m == key).expect(key);
        results.iter().map(|r| r.metrics[k]).collect()
    };

    let (metrics, family) = run("family_test");
    let twin = column(&metrics, &family, "twin_eval.p2p_rmse_db");
    let nlos = column(&metrics, &family, "twin_eval.nlos/p2p_rmse_db");
    let solids = column(&metrics, &family, "solids_eval.p2p_rmse_db");
    let (m, sd) = mean_sd(&twin);
    let (mn, sdn) = mean_sd(&nlos);
    let beats = twin.iter().zip(&solids).filter(|(t, s)| t < s).count();
    println!("test family, {} pairs:", twin.len());
    println!("  full twin P2P RMSE {m:.2} dB, spread {sd:.2} (target <= 6.5)");
    println!("  full twin NLOS P2P RMSE {mn:.2} dB, spread {sdn:.2} (target <= 8)");
    println!(
        "  ahead of the Sec. 4.1 solids on {beats} of {} pairs (target 80 %)",
        twin.len()
    );

    let (metrics, ablation) = run("family_ablation");
    let p2p = column(&metrics, &ablation, "twin_eval.p2p_rmse_db");
    let label = |r: &VariantResult, axis: &str| {
        r.variant
            .labels
            .iter()
            .find(|(a, _)| a == axis)
            .map(|(_, l)| l.clone())
            .expect(axis)
    };
    let full: std::collections::BTreeMap<String, f64> = ablation
        .iter()
        .zip(&p2p)
        .filter(|(r, _)| label(r, "stage") == "full")
        .map(|(r, x)| (label(r, "site"), *x))
        .collect();
    let mut stages: Vec<String> = Vec::new();
    for r in &ablation {
        let s = label(r, "stage");
        if !stages.contains(&s) {
            stages.push(s);
        }
    }
    println!("each Sec. 4.2 stage's gain (P2P without it minus with it):");
    for stage in stages.iter().filter(|s| *s != "full") {
        let gains: Vec<f64> = ablation
            .iter()
            .zip(&p2p)
            .filter(|(r, _)| &label(r, "stage") == stage)
            .map(|(r, x)| x - full[&label(r, "site")])
            .collect();
        let (g, sd) = mean_sd(&gains);
        let verdict = if g.abs() > sd { "shown" } else { "not shown" };
        println!("  {stage}: {g:+.2} dB, spread {sd:.2} ({verdict})");
    }
}

/// Mean and sample standard deviation.
fn mean_sd(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, var.sqrt())
}
