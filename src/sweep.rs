//! Sweeps: one base graph run over the product of parameter grids and ablation switches, every
//! variant through the same cache, and one table of chosen metrics per variant.
//!
//! ```ron
//! Sweep(
//!     graph: "../demo.ron",
//!     axes: {
//!         "roof_tolerance": Grid(set: "solids.tolerance_m", values: [0.1, 0.3]),
//!         "terrain": Switch({ "eq1": [], "coarse": ["terrain2=Coarsen(raster: \"terrain1\", cell_m: 8.0)"] }),
//!     },
//!     metrics: ["footprint_score.iou", "terrain_error_stats.rmse"],
//! )
//! ```
//!
//! A `Grid` sets one parameter to each value; a `Switch` names variants by the `--set` overrides
//! they apply (`NODE.PARAM=VALUE`, or `NODE=Kind(...)` to swap a stage). Variants run one after
//! another so a node they share is computed once, by the first, and every later variant finds it in
//! the cache; within a variant nodes run in parallel. An interrupted sweep resumes where it
//! stopped: finished variants are all cache hits.
//!
//! `metrics_only: true` runs in each variant only the nodes its metrics need: an ablation over a
//! family of cities then traces the links and skips the radio maps, plots and report it would
//! otherwise redraw per variant, and writes no variant's outputs (the table is what it is for).

use std::path::{Path, PathBuf};

use kodama_nodes::Artifact;
use kodama_nodes::artifact::Metrics;
use kodama_nodes::io::csv_text;

use crate::cache::{Cache, Digest, write_atomic};
use crate::exec::{RunError, RunOptions, run};
use crate::graph::{Graph, LoadOptions, load};
use crate::progress::Reporter;
use crate::record::{RunRecord, Status};
use crate::syntax::{self, Ast, Value};

/// A loaded sweep file.
#[derive(Clone, Debug)]
pub struct Sweep {
    /// The sweep file.
    pub path: PathBuf,
    /// Its stem (the default output folder).
    pub name: String,
    /// The base graph, resolved against the sweep file's folder.
    pub graph: PathBuf,
    /// Axes in file order: name, then its choices.
    pub axes: Vec<(String, Vec<Choice>)>,
    /// `NODE.KEY` of each metric reported.
    pub metrics: Vec<String>,
    /// Run only the nodes the metrics need and write no variant's outputs (default false: every
    /// node, every output written).
    pub metrics_only: bool,
}

/// One choice on an axis: its label and the overrides it applies.
pub type Choice = (String, Vec<String>);

/// One point of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// (axis, label) per axis.
    pub labels: Vec<(String, String)>,
    /// The overrides, in axis order.
    pub sets: Vec<String>,
}

impl Variant {
    /// `axis=label,axis=label`: the variant's name and (sanitised) output folder.
    pub fn name(&self) -> String {
        self.labels
            .iter()
            .map(|(a, l)| format!("{a}={l}"))
            .collect::<Vec<_>>()
            .join(",")
    }
}

fn err(path: &Path, at: &Ast, msg: impl std::fmt::Display) -> String {
    format!("{}:{}:{}: {msg}", path.display(), at.span.line, at.span.col)
}

fn string(path: &Path, a: &Ast, what: &str) -> Result<String, String> {
    match &a.v {
        Value::Str(s) => Ok(s.clone()),
        v => Err(err(
            path,
            a,
            format!("expected {what} as a string, found {}", v.describe()),
        )),
    }
}

/// The most variants a sweep may have: each is a full graph load and run, so more is a mistake in
/// the axes, and the product of a few long axes would otherwise exhaust memory before anything
/// runs.
pub const MAX_VARIANTS: usize = 10_000;

/// Reads and checks a sweep file. Its base graph must lie in the sweep file's folder or the one
/// above it (sweeps sit in `graphs/sweeps/` beside the graphs they vary), unless `allow_outside`.
pub fn load_sweep(path: &Path, allow_outside: bool) -> Result<Sweep, String> {
    let ast = parse_file(path, "the sweep file")?;
    let Value::Struct { name, fields } = &ast.v else {
        return Err(err(
            path,
            &ast,
            "expected `Sweep(graph: ..., axes: {...}, metrics: [...])`",
        ));
    };
    if name.as_ref().is_some_and(|n| n.name != "Sweep") {
        return Err(err(path, &ast, "expected `Sweep(...)`"));
    }
    let (mut graph, mut axes, mut metrics) = (None, Vec::new(), Vec::new());
    let mut metrics_only = false;
    for (n, v) in fields {
        match n.name.as_str() {
            "metrics_only" => match v.v {
                Value::Bool(b) => metrics_only = b,
                ref other => {
                    return Err(err(
                        path,
                        v,
                        format!("expected true or false, found {}", other.describe()),
                    ));
                }
            },
            "graph" => graph = Some((v, string(path, v, "the base graph's path")?)),
            "metrics" => {
                let Value::List(items) = &v.v else {
                    return Err(err(path, v, "expected a list of \"NODE.KEY\" metric names"));
                };
                for m in items {
                    let m_s = string(path, m, "a metric")?;
                    if !m_s.contains('.') {
                        return Err(err(path, m, format!("expected NODE.KEY, found {m_s:?}")));
                    }
                    metrics.push(m_s);
                }
            }
            "axes" => {
                let Value::Map(entries) = &v.v else {
                    return Err(err(
                        path,
                        v,
                        "expected a map of axis name -> Grid(...) or Switch({...})",
                    ));
                };
                for (k, a) in entries {
                    let axis = string(path, k, "an axis name")?;
                    axes.push((axis, axis_variants(path, a)?));
                }
            }
            other => {
                return Err(format!(
                    "{}:{}:{}: unknown field `{other}`; expected graph, axes, metrics or metrics_only",
                    path.display(),
                    n.span.line,
                    n.span.col
                ));
            }
        }
    }
    let count = axes
        .iter()
        .fold(1usize, |n, (_, choices)| n.saturating_mul(choices.len()));
    if count > MAX_VARIANTS {
        return Err(err(
            path,
            &ast,
            format!(
                "{count} variants (the product of the axes) is more than the {MAX_VARIANTS} a sweep runs"
            ),
        ));
    }
    let (graph_ast, graph) = graph.ok_or_else(|| err(path, &ast, "missing field `graph`"))?;
    let base = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let graph = base.join(graph);
    check_base_graph(&graph, base, allow_outside).map_err(|m| err(path, graph_ast, m))?;
    Ok(Sweep {
        path: path.to_path_buf(),
        name: crate::graph::folder_name(path, "sweep"),
        graph,
        axes,
        metrics,
        metrics_only,
    })
}

/// The RON syntax tree of a file; errors name the file (as `what`) and the place.
fn parse_file(path: &Path, what: &str) -> Result<Ast, String> {
    let text = crate::graph::read_graph_text(path)
        .map_err(|e| format!("{}: cannot read {what}: {e}", path.display()))?;
    syntax::parse(&text, 0, 1, 1).map_err(|e| {
        format!(
            "{}:{}:{}: {}",
            path.display(),
            e.span.line,
            e.span.col,
            e.message
        )
    })
}

/// Whether `path` holds a sweep (`Sweep(...)`) rather than a graph: what `submit` is given.
pub fn is_sweep_file(path: &Path) -> Result<bool, String> {
    let ast = parse_file(path, "the file")?;
    Ok(matches!(&ast.v, Value::Struct { name: Some(n), .. } if n.name == "Sweep"))
}

/// The base graph: a regular file inside the sweep's folder or its parent, unless allowed out.
fn check_base_graph(graph: &Path, base: &Path, allow_outside: bool) -> Result<(), String> {
    let meta =
        std::fs::metadata(graph).map_err(|e| format!("the base graph {}: {e}", graph.display()))?;
    if !meta.is_file() {
        return Err(format!(
            "the base graph {} is {}, not a graph file",
            graph.display(),
            if meta.is_dir() {
                "a folder"
            } else {
                crate::cache::describe_file_type(&meta.file_type())
            }
        ));
    }
    if allow_outside {
        return Ok(());
    }
    let root = std::fs::canonicalize(base)
        .map_err(|e| format!("the sweep's folder {}: {e}", base.display()))?;
    let root = root.parent().map(Path::to_path_buf).unwrap_or(root);
    let target = std::fs::canonicalize(graph)
        .map_err(|e| format!("the base graph {}: {e}", graph.display()))?;
    if !target.starts_with(&root) {
        return Err(format!(
            "the base graph {} is outside {} (a sweep's graph lies in its folder or the one \
             above); pass --allow-outside to use it",
            target.display(),
            root.display()
        ));
    }
    Ok(())
}

fn axis_variants(path: &Path, a: &Ast) -> Result<Vec<Choice>, String> {
    match &a.v {
        Value::Struct {
            name: Some(n),
            fields,
        } if n.name == "Grid" => {
            let (mut set, mut values) = (None, None);
            for (f, v) in fields {
                match f.name.as_str() {
                    "set" => set = Some(string(path, v, "NODE.PARAM")?),
                    "values" => match &v.v {
                        Value::List(items) if !items.is_empty() => values = Some(items.clone()),
                        _ => return Err(err(path, v, "expected a non-empty list of values")),
                    },
                    other => {
                        return Err(err(
                            path,
                            v,
                            format!("unknown Grid field `{other}`; expected set or values"),
                        ));
                    }
                }
            }
            let set = set.ok_or_else(|| err(path, a, "Grid needs `set: \"NODE.PARAM\"`"))?;
            if !set.contains('.') {
                return Err(err(
                    path,
                    a,
                    format!("expected set: \"NODE.PARAM\", found {set:?}"),
                ));
            }
            Ok(values
                .ok_or_else(|| err(path, a, "Grid needs `values: [...]`"))?
                .iter()
                .map(|v| {
                    let text = v.to_ron();
                    (
                        text.trim_matches('"').to_string(),
                        vec![format!("{set}={text}")],
                    )
                })
                .collect())
        }
        Value::Call { name, args } if name.name == "Switch" && args.len() == 1 => {
            let Value::Map(entries) = &args[0].v else {
                return Err(err(
                    path,
                    &args[0],
                    "expected Switch({ \"label\": [\"NODE.PARAM=VALUE\", ...], ... })",
                ));
            };
            let mut out = Vec::new();
            for (k, v) in entries {
                let label = string(path, k, "a variant label")?;
                let Value::List(items) = &v.v else {
                    return Err(err(path, v, "expected a list of overrides"));
                };
                let sets = items
                    .iter()
                    .map(|i| string(path, i, "an override NODE.PARAM=VALUE or NODE=Kind(...)"))
                    .collect::<Result<Vec<_>, _>>()?;
                out.push((label, sets));
            }
            if out.is_empty() {
                return Err(err(path, a, "a Switch needs at least one variant"));
            }
            Ok(out)
        }
        v => Err(err(
            path,
            a,
            format!(
                "expected Grid(set: ..., values: [...]) or Switch({{...}}), found {}",
                v.describe()
            ),
        )),
    }
}

impl Sweep {
    /// Every variant: the product of the axes, first axis slowest.
    pub fn variants(&self) -> Vec<Variant> {
        let mut out = vec![Variant {
            labels: vec![],
            sets: vec![],
        }];
        for (axis, choices) in &self.axes {
            out = out
                .into_iter()
                .flat_map(|v| {
                    choices.iter().map(move |(label, sets)| {
                        let mut n = v.clone();
                        n.labels.push((axis.clone(), label.clone()));
                        n.sets.extend(sets.iter().cloned());
                        n
                    })
                })
                .collect();
        }
        out
    }
}

/// Options of a sweep run.
#[derive(Clone, Debug, Default)]
pub struct SweepOptions {
    /// Data folder for the base graph.
    pub data_dir: Option<PathBuf>,
    /// Overrides applied to every variant, before the variant's own.
    pub sets: Vec<String>,
    /// Where the table and each variant's outputs go.
    pub out_dir: PathBuf,
    /// Worker threads per variant.
    pub jobs: Option<usize>,
    /// Let the base graph's data paths reach outside its folder (or `--data`).
    pub allow_outside: bool,
}

/// One variant's result.
#[derive(Clone, Debug)]
pub struct VariantResult {
    /// The variant.
    pub variant: Variant,
    /// Its run record.
    pub record: RunRecord,
    /// The metrics asked for, NaN where missing.
    pub metrics: Vec<f64>,
}

/// Why a sweep stopped.
#[derive(Debug)]
pub enum SweepError {
    /// A variant's graph is invalid (exit 2).
    Graph(String),
    /// A run could not start or finish.
    Run(RunError),
    /// A variant had failed nodes (exit 1); the sweep stops there.
    Failed(String),
}

impl std::fmt::Display for SweepError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SweepError::Graph(m) | SweepError::Failed(m) => f.write_str(m),
            SweepError::Run(e) => write!(f, "{e}"),
        }
    }
}

/// Runs every variant in order through `cache`, then writes `table.md` and `table.csv` to the
/// output folder. `on_variant` hears of each variant as it starts.
pub fn run_sweep(
    sweep: &Sweep,
    cache: &Cache,
    opts: &SweepOptions,
    reporter: &Reporter,
    mut on_variant: impl FnMut(usize, usize, &Variant),
) -> Result<Vec<VariantResult>, SweepError> {
    let variants = sweep.variants();
    let graphs = checked_graphs(sweep, opts, &variants)?;
    let stop_after: Option<usize> = std::env::var("KODAMA_DAG_FAULT_SWEEP_STOP_AFTER")
        .ok()
        .and_then(|v| v.parse().ok());
    let mut results = Vec::new();
    for (i, (v, g)) in variants.iter().zip(&graphs).enumerate() {
        if stop_after == Some(i) {
            // Fault injection for the resume test: as if the sweep were killed here.
            std::process::exit(1);
        }
        on_variant(i, variants.len(), v);
        results.push(run_variant(sweep, cache, opts, reporter, i, v, g)?);
    }
    write_tables(sweep, &opts.out_dir, cache, &results)
        .map_err(|e| SweepError::Run(RunError::Io(e)))?;
    Ok(results)
}

/// Runs variant `index` alone, as the whole sweep would run it, and writes no table: one task
/// of a job array (`kodama-dag sweep --variant I`); the table is a later, all-hits sweep.
pub fn run_one_variant(
    sweep: &Sweep,
    cache: &Cache,
    opts: &SweepOptions,
    reporter: &Reporter,
    index: usize,
) -> Result<VariantResult, SweepError> {
    let variants = sweep.variants();
    let Some(v) = variants.get(index) else {
        return Err(SweepError::Graph(format!(
            "{}: --variant {index}: the sweep has {} variants, numbered from 0",
            sweep.path.display(),
            variants.len()
        )));
    };
    // One task of an array loads its own graph only: the submission checked every variant.
    check_folders(sweep, &variants)?;
    let g = checked_graph(sweep, opts, v)?;
    run_variant(sweep, cache, opts, reporter, index, v, &g)
}

/// Runs the nodes every variant shares (the prefix `kodama-dag submit` gives its own job, so
/// that the variants' tasks find them cached instead of racing to compute them); the ids run,
/// empty when the variants share nothing.
pub fn run_prefix(
    sweep: &Sweep,
    cache: &Cache,
    opts: &SweepOptions,
    reporter: &Reporter,
) -> Result<Vec<String>, SweepError> {
    let variants = sweep.variants();
    let graphs = checked_graphs(sweep, opts, &variants)?;
    let targets = shared_prefix(sweep, &graphs);
    if targets.is_empty() {
        return Ok(targets);
    }
    let run_opts = RunOptions {
        jobs: opts.jobs,
        targets: targets.clone(),
        out_dir: None,
    };
    let record = run(&graphs[0], cache, &run_opts, reporter).map_err(SweepError::Run)?;
    if let Some(f) = record.nodes.iter().find(|n| n.status == Status::Failed) {
        return Err(SweepError::Failed(format!(
            "the shared prefix: node {:?} failed: {}",
            f.id,
            f.error.as_deref().unwrap_or(&f.reason)
        )));
    }
    Ok(targets)
}

/// Runs one variant's graph (the nodes its metrics need when `metrics_only`) and reads its
/// metrics. The first variant settles whether each metric names a value its node reports.
fn run_variant(
    sweep: &Sweep,
    cache: &Cache,
    opts: &SweepOptions,
    reporter: &Reporter,
    i: usize,
    v: &Variant,
    g: &Graph,
) -> Result<VariantResult, SweepError> {
    let run_opts = RunOptions {
        jobs: opts.jobs,
        targets: variant_targets(sweep),
        out_dir: (!sweep.metrics_only)
            .then(|| opts.out_dir.join("variants").join(folder_name(&v.name()))),
    };
    let record = run(g, cache, &run_opts, reporter).map_err(SweepError::Run)?;
    if let Some(f) = record.nodes.iter().find(|n| n.status == Status::Failed) {
        let msg = format!(
            "variant {}: node {:?} failed: {}",
            v.name(),
            f.id,
            f.error.as_deref().unwrap_or(&f.reason)
        );
        // A failure of the user's input keeps its meaning (exit 2) wherever the variant ran.
        return Err(if f.user_error {
            SweepError::Graph(msg)
        } else {
            SweepError::Failed(msg)
        });
    }
    if let Some((name, e)) = record.output_errors.iter().next() {
        return Err(SweepError::Failed(format!(
            "variant {}: output {name:?} was not written: {}",
            v.name(),
            e.error
        )));
    }
    let mut metrics = Vec::with_capacity(sweep.metrics.len());
    for m in &sweep.metrics {
        match metric(cache, &record, m) {
            Ok(x) => metrics.push(x),
            // Known only once the metrics node has run: a key it never reports is a typo in
            // the sweep file, not a missing value, so the first variant settles it.
            Err(keys) if i == 0 => {
                let hint = syntax::did_you_mean(
                    m.split_once('.').map_or("", |(_, k)| k),
                    keys.iter().map(String::as_str),
                )
                .map(|k| format!("; did you mean `{k}`?"))
                .unwrap_or_default();
                return Err(SweepError::Graph(format!(
                    "{}: metric {m:?} names nothing: its node reports {}{hint}",
                    sweep.path.display(),
                    if keys.is_empty() {
                        "no values".to_string()
                    } else {
                        keys.join(", ")
                    }
                )));
            }
            Err(_) => metrics.push(f64::NAN),
        }
    }
    Ok(VariantResult {
        variant: v.clone(),
        record,
        metrics,
    })
}

/// What each variant runs: the metric nodes and their ancestors when `metrics_only`, else all.
pub fn variant_targets(sweep: &Sweep) -> Vec<String> {
    if sweep.metrics_only {
        metric_nodes(&sweep.metrics)
    } else {
        vec![]
    }
}

/// The nodes every variant computes alike, as the fewest targets that run them all: a node is
/// shared when it has the same id, kind, VERSION, params, files and (shared) inputs in every
/// variant's graph, so its action key is the same in all of them. Only nodes some variant needs
/// count; a shared node whose consumers are all shared is run through them.
pub fn shared_prefix(sweep: &Sweep, graphs: &[Graph]) -> Vec<String> {
    let Some(first) = graphs.first() else {
        return vec![];
    };
    let keys: Vec<Vec<[u8; 32]>> = graphs.iter().map(structure_keys).collect();
    let targets = variant_targets(sweep);
    let mut needed = vec![false; first.nodes.len()];
    for g in graphs {
        let idx: Vec<usize> = targets.iter().filter_map(|t| g.index(t)).collect();
        for (i, need) in g.needed(&idx).iter().enumerate() {
            if *need && let Some(j) = first.index(&g.nodes[i].id) {
                needed[j] = true;
            }
        }
    }
    let shared: Vec<bool> = (0..first.nodes.len())
        .map(|i| {
            needed[i]
                && graphs.iter().zip(&keys).all(|(g, k)| {
                    g.index(&first.nodes[i].id)
                        .is_some_and(|j| k[j] == keys[0][i])
                })
        })
        .collect();
    let consumers = first.consumers();
    (0..first.nodes.len())
        .filter(|&i| shared[i] && !consumers[i].iter().any(|&c| shared[c]))
        .map(|i| first.nodes[i].id.clone())
        .collect()
}

/// Per node, a digest of what determines its action key apart from file contents (which every
/// variant reads alike): kind, VERSION, site, canonical params, file paths, and its inputs'
/// digests of the same kind.
fn structure_keys(g: &Graph) -> Vec<[u8; 32]> {
    let site = crate::key::site_digest(&g.site);
    let mut keys: Vec<[u8; 32]> = Vec::with_capacity(g.nodes.len());
    for n in &g.nodes {
        let mut h = blake3::Hasher::new();
        crate::key::put(&mut h, n.kind.name.as_bytes());
        h.update(&n.kind.version.to_le_bytes());
        h.update(crate::key::node_site(&site, n).as_bytes());
        crate::key::put(&mut h, &n.params.canonical());
        for f in &n.files {
            crate::key::put(&mut h, f.path.as_os_str().as_encoded_bytes());
        }
        for input in &n.inputs {
            h.update(&(input.len() as u64).to_le_bytes());
            for &j in input {
                h.update(&keys[j]);
            }
        }
        keys.push(*h.finalize().as_bytes());
    }
    keys
}

/// The nodes the metrics name, each once, in the metrics' order.
fn metric_nodes(metrics: &[String]) -> Vec<String> {
    let mut nodes: Vec<String> = Vec::new();
    for m in metrics {
        let (node, _) = m.split_once('.').expect("checked on load");
        if !nodes.iter().any(|n| n == node) {
            nodes.push(node.to_string());
        }
    }
    nodes
}

/// Every variant's graph, loaded and checked, with the metric names checked against it.
pub fn checked_graphs(
    sweep: &Sweep,
    opts: &SweepOptions,
    variants: &[Variant],
) -> Result<Vec<Graph>, SweepError> {
    check_folders(sweep, variants)?;
    variants
        .iter()
        .map(|v| checked_graph(sweep, opts, v))
        .collect()
}

/// No two variants write the same output folder.
fn check_folders(sweep: &Sweep, variants: &[Variant]) -> Result<(), SweepError> {
    let mut folders = std::collections::HashMap::new();
    for v in variants {
        let folder = folder_name(&v.name());
        if let Some(first) = folders.insert(folder.to_lowercase(), v.name()) {
            return Err(SweepError::Graph(format!(
                "{}: variants {first:?} and {:?} would write the same folder {folder:?}; \
                 give their labels distinct letters or digits",
                sweep.path.display(),
                v.name()
            )));
        }
    }
    Ok(())
}

/// One variant's graph, loaded and checked, with the metric names checked against it.
fn checked_graph(sweep: &Sweep, opts: &SweepOptions, v: &Variant) -> Result<Graph, SweepError> {
    let g = load_variant(sweep, opts, v)?;
    for m in &sweep.metrics {
        let (node, _) = m.split_once('.').expect("checked on load");
        let Some(n) = g.nodes.iter().find(|n| n.id == node) else {
            return Err(SweepError::Graph(format!(
                "{}: metric {m:?}: the graph has no node {node:?}",
                sweep.path.display()
            )));
        };
        if n.kind.output != kodama_nodes::ArtifactType::Metrics {
            return Err(SweepError::Graph(format!(
                "{}: metric {m:?}: node {node:?} makes {}, not Metrics",
                sweep.path.display(),
                n.kind.output
            )));
        }
    }
    Ok(g)
}

/// Loads every variant's graph and checks the metric names, running nothing: the variants.
pub fn check_variants(sweep: &Sweep, opts: &SweepOptions) -> Result<Vec<Variant>, String> {
    let variants = sweep.variants();
    checked_graphs(sweep, opts, &variants).map_err(|e| e.to_string())?;
    Ok(variants)
}

fn load_variant(sweep: &Sweep, opts: &SweepOptions, v: &Variant) -> Result<Graph, SweepError> {
    let lo = LoadOptions {
        data_dir: opts.data_dir.clone(),
        sets: opts.sets.iter().chain(&v.sets).cloned().collect(),
        allow_outside: opts.allow_outside,
        tiles: Default::default(),
    };
    load(&sweep.graph, &lo).map_err(|e| SweepError::Graph(format!("variant {}:\n{e}", v.name())))
}

/// The value of `NODE.KEY` in the Metrics artifact the run produced for NODE: NaN where the
/// artifact cannot be had; the keys it has when it has no KEY.
fn metric(cache: &Cache, record: &RunRecord, m: &str) -> Result<f64, Vec<String>> {
    let (node, key) = m.split_once('.').expect("checked on load");
    let values = record
        .nodes
        .iter()
        .find(|n| n.id == node)
        .and_then(|n| n.digest.as_deref())
        .and_then(|d| Digest::from_hex(d).ok())
        .and_then(|d| cache.get_blob(&d).ok())
        .and_then(|b| rmp_serde::from_slice::<Artifact>(&b).ok())
        .and_then(|a| match a {
            Artifact::Metrics(Metrics { values }) => Some(values),
            _ => None,
        });
    match values {
        None => Ok(f64::NAN),
        Some(v) => v
            .get(key)
            .copied()
            .ok_or_else(|| v.keys().cloned().collect()),
    }
}

/// A variant name as a folder name.
fn folder_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "=,.-_".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The base graph as the sweep file names it (relative to the sweep's folder), so that the table
/// reads the same however the sweep file was named on the command line (a submitted job names
/// it by its absolute path).
fn written_graph(sweep: &Sweep) -> &Path {
    let folder = sweep
        .path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    sweep.graph.strip_prefix(folder).unwrap_or(&sweep.graph)
}

fn write_tables(
    sweep: &Sweep,
    out: &Path,
    cache: &Cache,
    results: &[VariantResult],
) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let axes: Vec<&str> = sweep.axes.iter().map(|(a, _)| a.as_str()).collect();
    let header: Vec<String> = axes
        .iter()
        .map(|a| a.to_string())
        .chain(sweep.metrics.iter().cloned())
        .collect();
    let fmt = |v: f64| {
        if v.is_finite() {
            format!("{v:.6}")
        } else {
            "NaN".into()
        }
    };
    let mut md = format!(
        "# Sweep {}\n\nBase graph: `{}`\n\n| {} |\n|{}\n",
        sweep.name,
        written_graph(sweep).display(),
        header.join(" | "),
        "---|".repeat(header.len())
    );
    let mut csv = csv_text::row(&header) + "\n";
    for r in results {
        let row: Vec<String> = r
            .variant
            .labels
            .iter()
            .map(|(_, l)| l.clone())
            .chain(r.metrics.iter().map(|&v| fmt(v)))
            .collect();
        md.push_str(&format!("| {} |\n", row.join(" | ")));
        csv.push_str(&(csv_text::row(&row) + "\n"));
    }
    let tmp = cache.root().join("tmp");
    for (name, text) in [("table.md", md), ("table.csv", csv)] {
        write_atomic(&tmp, &out.join(name), text.as_bytes())
            .map_err(|e| format!("{}: {e}", out.join(name).display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_multiply_in_file_order() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.ron");
        std::fs::write(
            &p,
            r#"Sweep(
    graph: "g.ron",
    axes: {
        "a": Grid(set: "n.x", values: [1.0, 2.5, "three"]),
        "b": Switch({ "on": [], "off": ["n=Other(y: 2)", "m.z=true"] }),
    },
    metrics: ["stats.mean"],
)"#,
        )
        .unwrap();
        std::fs::write(dir.path().join("g.ron"), "Graph()").unwrap();
        let s = load_sweep(&p, false).unwrap();
        let v = s.variants();
        assert_eq!(v.len(), 6);
        assert_eq!(v[0].name(), "a=1.0,b=on");
        assert_eq!(
            v[1].sets,
            vec![
                "n.x=1.0".to_string(),
                "n=Other(y: 2)".into(),
                "m.z=true".into()
            ]
        );
        assert_eq!(v[5].name(), "a=three,b=off");
        assert_eq!(v[4].sets, vec!["n.x=\"three\"".to_string()]);
        std::fs::write(
            &p,
            "Sweep(graph: \"g.ron\", axes: { \"a\": Grid(set: \"nx\", values: [1]) })",
        )
        .unwrap();
        let e = load_sweep(&p, false).unwrap_err();
        assert!(e.contains("s.ron:1:") && e.contains("NODE.PARAM"), "{e}");
    }
}
