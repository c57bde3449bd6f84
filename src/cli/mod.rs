//! The `kodama-dag` command line. Exit codes: 0 success, 1 a node (or the cache) failed,
//! 2 bad usage or an invalid graph or input. The binary (`src/main.rs`) and the Python
//! package's `kodama-dag` script (`python -m kodama_dag`) both call [`main`].
//!
//! The top of the crate: nothing in the engine imports it. Its `rf_commands` wrap the radio of
//! `kodama_nodes::rf` for `trace` and `radiomap`; the engine's modules stay free of radio.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use clap::{Args, Parser, Subcommand, ValueEnum};

pub mod kinds;
mod rf_commands;

use crate::cache::{Cache, gc};
use crate::exec::{RunError, RunOptions, run};
use crate::explain::{Plan, explain};
use crate::graph::{Graph, LoadOptions, load, to_dot, to_mermaid};
use crate::progress::{Mode, Reporter};
use crate::record::Status;

#[derive(Parser)]
#[command(
    name = "kodama-dag",
    version,
    about = "RF digital twins from off-the-shelf geospatial data, as a cached dataflow graph"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Share the cache through an S3 bucket: s3://BUCKET/PREFIX (default:
    /// $KODAMA_DAG_REMOTE_CACHE). Endpoint and credentials from the AWS_* variables (README,
    /// "A cache shared through S3").
    #[arg(long, global = true, value_name = "s3://BUCKET/PREFIX")]
    remote_cache: Option<String>,
}

/// The remote cache's URL for the command running, from `--remote-cache` or the environment.
/// Set by each [`main`] call (a Python process may make several).
static REMOTE_CACHE: std::sync::RwLock<Option<String>> = std::sync::RwLock::new(None);

fn remote_cache_url() -> Option<String> {
    REMOTE_CACHE.read().map_or(None, |u| u.clone())
}

#[derive(Subcommand)]
enum Command {
    /// Trace links through a Sionna RT scene: path gains per tx/rx pair, as CSV.
    Trace(rf_commands::TraceArgs),
    /// A radio map of a Sionna RT scene from one transmitter (GeoTIFF, EXR or PNG, dB).
    Radiomap(rf_commands::RadiomapArgs),
    /// Run a graph: only nodes whose inputs or params changed run; the rest come from the cache.
    Run {
        #[command(flatten)]
        graph: GraphArgs,
        /// Cache directory (default: $KODAMA_DAG_CACHE, else ./cache).
        #[arg(long)]
        cache: Option<PathBuf>,
        /// Where the declared outputs go (default: out/<graph name>/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Run only this node and what it needs (repeatable).
        #[arg(long = "target", value_name = "NODE")]
        targets: Vec<String>,
        /// In a tiled run, make only tile I's nodes (numbered row by row from the south-west, as
        /// `explain` lists them) and what they need: one task of a job array.
        #[arg(long, value_name = "I")]
        tile: Option<usize>,
        /// In a tiled run, only the nodes of tile phase K: with --tile, that tile's; alone, the
        /// nodes made once that tiles of phase K+1 wait for (0: the shared upstream).
        #[arg(long, value_name = "K")]
        phase: Option<u32>,
        /// Make only the I-th radio node (RadioMap or Trace, in graph order) and what it needs:
        /// one task of a tiled run's radio job array.
        #[arg(long, value_name = "I", conflicts_with_all = ["tile", "phase"])]
        radio: Option<usize>,
        /// Worker threads (default: all cores; at most 4 per core).
        #[arg(long, short, value_parser = parse_jobs)]
        jobs: Option<usize>,
        /// Print the run record as one JSON object on stdout.
        #[arg(long)]
        json: bool,
        /// Print only warnings and errors.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Rerun a graph whenever the graph file or an input it reads changes.
    Watch {
        #[command(flatten)]
        graph: GraphArgs,
        /// Cache directory (default: $KODAMA_DAG_CACHE, else ./cache).
        #[arg(long)]
        cache: Option<PathBuf>,
        /// Where the declared outputs go (default: out/<graph name>/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores; at most 4 per core).
        #[arg(long, short, value_parser = parse_jobs)]
        jobs: Option<usize>,
        /// Print each run record as one JSON line on stdout.
        #[arg(long)]
        json: bool,
        /// Print only warnings and errors.
        #[arg(long, short)]
        quiet: bool,
        /// Quiet time after a change before rerunning, milliseconds.
        #[arg(long, default_value_t = 300)]
        debounce_ms: u64,
    },
    /// Run a sweep file: a base graph over grids of parameters and ablation switches.
    Sweep(SweepArgs),
    /// Submit a graph or a sweep to a cluster's scheduler as a chain of batch jobs over a shared
    /// cache (README, "Running on a cluster").
    Submit(SubmitArgs),
    /// Say what `run` would do and why, without running anything.
    Explain {
        #[command(flatten)]
        graph: GraphArgs,
        /// Cache directory (default: $KODAMA_DAG_CACHE, else ./cache).
        #[arg(long)]
        cache: Option<PathBuf>,
        /// The output folder `run` would write (default: out/<graph name>): left out of folder
        /// inputs' digests as `run` leaves it out, so the plan names the keys `run` would use.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Explain only this node and what it needs (repeatable).
        #[arg(long = "target", value_name = "NODE")]
        targets: Vec<String>,
        /// Print the plan as JSON on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Serve a folder (a report) on localhost, for browsers that refuse file:// pages.
    Serve {
        /// The folder, e.g. out/demo/report.
        dir: PathBuf,
        /// Port on 127.0.0.1 (0: any free port).
        #[arg(long, default_value_t = 8000)]
        port: u16,
    },
    /// Evict least recently used artifacts until the cache holds at most --max-bytes.
    Gc(GcArgs),
    /// Print the graph as Graphviz dot or Mermaid.
    Graph {
        #[command(flatten)]
        graph: GraphArgs,
        /// Output format.
        #[arg(long, value_enum, default_value = "dot")]
        format: Format,
    },
    /// List the node kinds with their inputs and outputs; with a KIND, that kind's inputs and
    /// every param with its type, default and documentation.
    Kinds {
        /// One kind to describe (`RadioMap`, `Trace`, ...).
        kind: Option<String>,
    },
}

/// `sweep` arguments.
#[derive(Args)]
struct SweepArgs {
    /// The sweep file (RON).
    sweep: PathBuf,
    /// Resolve the base graph's data paths against this folder.
    #[arg(long)]
    data: Option<PathBuf>,
    /// Override applied to every variant: NODE.PARAM=VALUE (repeatable).
    #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
    sets: Vec<String>,
    /// Cache directory (default: $KODAMA_DAG_CACHE, else ./cache).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Where the table and each variant's outputs go (default: out/<sweep name>/).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Worker threads per variant (default: all cores; at most 4 per core).
    #[arg(long, short, value_parser = parse_jobs)]
    jobs: Option<usize>,
    /// Print only warnings, errors and the table.
    #[arg(long, short)]
    quiet: bool,
    /// Check every variant's graph and list the variants, without running anything.
    #[arg(long)]
    dry_run: bool,
    /// Let the base graph lie outside the sweep's folder and the one above it, and its data
    /// paths leave its folder (or --data).
    #[arg(long)]
    allow_outside: bool,
    /// Run only variant I (numbered from 0 in --dry-run's order) and write no table: one task
    /// of a job array.
    #[arg(long, value_name = "I", conflicts_with_all = ["dry_run", "prefix"])]
    variant: Option<usize>,
    /// Run only the nodes every variant shares, and write no table: the prefix job of a
    /// submitted sweep.
    #[arg(long, conflicts_with = "dry_run")]
    prefix: bool,
}

/// `submit` arguments.
#[derive(Args)]
struct SubmitArgs {
    /// The graph or sweep file (RON).
    file: PathBuf,
    /// The scheduler.
    #[arg(long, value_enum, default_value = "slurm")]
    engine: Engine,
    /// Options added to every sbatch command, e.g. "--partition=gpu --account=rf" (split as a
    /// shell splits words; they override the scripts' #SBATCH lines).
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true)]
    sbatch: Option<String>,
    /// Resolve data paths against this folder.
    #[arg(long)]
    data: Option<PathBuf>,
    /// Override one parameter in every job: NODE.PARAM=VALUE (repeatable).
    #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
    sets: Vec<String>,
    /// Cache directory, on a filesystem every node of the cluster mounts at the same path
    /// (default: $KODAMA_DAG_CACHE, else ./cache).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Where outputs, tables, job scripts and logs go (default: out/<name>/); the scripts and
    /// logs in its slurm/<n>/.
    #[arg(long)]
    out: Option<PathBuf>,
    /// A graph's nodes to run, with what they need (repeatable; graphs only).
    #[arg(long = "target", value_name = "NODE")]
    targets: Vec<String>,
    /// Run the graph in tiles of this side, metres: a job array per tile phase (graphs only).
    #[arg(long, value_name = "M", value_parser = parse_metres)]
    tile_m: Option<f64>,
    /// The halo around each tile, metres (default: the stages' reach plus half a building).
    #[arg(long, value_name = "M", value_parser = parse_metres)]
    halo_m: Option<f64>,
    /// CPUs per job (--cpus-per-task, and kodama-dag's -j); default 1.
    #[arg(long, short, value_parser = parse_jobs)]
    jobs: Option<usize>,
    /// Let data paths (and a sweep's base graph) leave their folders.
    #[arg(long)]
    allow_outside: bool,
    /// Run at most this many of a sweep's variant tasks at once (--array=...%K).
    #[arg(long, value_name = "K", value_parser = parse_jobs)]
    array_limit: Option<usize>,
    /// Write the job scripts and print the sbatch commands, submitting nothing.
    #[arg(long)]
    dry_run: bool,
    /// Wait for the jobs to end, then exit as a local run would (0, 1, or 2 for bad input).
    #[arg(long)]
    wait: bool,
    /// Seconds between two looks at squeue while waiting (1-3600).
    #[arg(long, default_value_t = 15, value_parser = parse_poll)]
    poll_s: u64,
}

#[derive(Clone, Copy, ValueEnum)]
enum Engine {
    /// Slurm, through sbatch and squeue.
    Slurm,
}

fn parse_poll(s: &str) -> Result<u64, String> {
    match s.trim().parse::<u64>() {
        Ok(n) if (1..=3600).contains(&n) => Ok(n),
        _ => Err(format!(
            "expected whole seconds from 1 to 3600, found {s:?}"
        )),
    }
}

/// `gc` arguments.
#[derive(Args)]
struct GcArgs {
    /// Cache directory (default: $KODAMA_DAG_CACHE, else ./cache).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Size bound, in bytes or with a unit: 500M, 2G, 1GiB.
    #[arg(long, value_parser = parse_bytes)]
    max_bytes: u64,
    /// Never evict what this graph's last run produced (repeatable).
    #[arg(long, value_name = "GRAPH")]
    keep: Vec<PathBuf>,
    /// Resolve the kept graphs' data paths against this folder.
    #[arg(long)]
    data: Option<PathBuf>,
    /// Let the kept graphs' data paths leave their folder (or --data).
    #[arg(long)]
    allow_outside: bool,
}

#[derive(Args)]
struct GraphArgs {
    /// The graph file (RON).
    graph: PathBuf,
    /// Resolve data paths against this folder instead of the graph file's.
    #[arg(long)]
    data: Option<PathBuf>,
    /// Override one parameter for this run: NODE.PARAM=VALUE, VALUE in RON syntax (repeatable).
    #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
    sets: Vec<String>,
    /// Let data paths leave the graph file's folder (or --data): `..`, absolute paths, symlinks.
    #[arg(long)]
    allow_outside: bool,
    /// Run in square tiles of this side, metres, over the graph's `tiling` area (README,
    /// "City scale: tiles").
    #[arg(long, value_name = "M", value_parser = parse_metres)]
    tile_m: Option<f64>,
    /// The halo around each tile, metres (default: the stages' reach plus half a building).
    #[arg(long, value_name = "M", value_parser = parse_metres)]
    halo_m: Option<f64>,
}

fn parse_metres(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!(
            "expected a finite, non-negative length in metres, found {s:?}"
        )),
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum Format {
    Dot,
    Mermaid,
}

fn parse_jobs(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(0) => Err("expected at least 1 worker thread".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("expected a number of threads, found {s:?}")),
    }
}

fn parse_bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let split = s
        .find(|c: char| !c.is_ascii_digit() && c != '.')
        .unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let n: f64 = num
        .parse()
        .map_err(|_| format!("expected a size like 500M or 2G, found {s:?}"))?;
    let mult: u64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "k" | "kb" => 1_000,
        "kib" => 1 << 10,
        "m" | "mb" => 1_000_000,
        "mib" => 1 << 20,
        "g" | "gb" => 1_000_000_000,
        "gib" => 1 << 30,
        "t" | "tb" => 1_000_000_000_000,
        "tib" => 1 << 40,
        other => {
            return Err(format!(
                "unknown size unit {other:?}; expected K, M, G, T, KiB, MiB, GiB or TiB"
            ));
        }
    };
    Ok((n * mult as f64) as u64)
}

/// A failure the CLI reports: message and exit code.
struct Fail(u8, String);

impl From<RunError> for Fail {
    fn from(e: RunError) -> Fail {
        match e {
            RunError::Usage(m) => Fail(2, format!("error: {m}")),
            RunError::Io(m) => Fail(1, format!("error: {m}")),
        }
    }
}

fn load_graph(args: &GraphArgs) -> Result<Graph, Fail> {
    let opts = LoadOptions {
        data_dir: args.data.clone(),
        sets: args.sets.clone(),
        allow_outside: args.allow_outside,
        tiles: crate::graph::TileOverrides {
            tile_m: args.tile_m,
            halo_m: args.halo_m,
        },
    };
    if let Some(d) = &args.data
        && !d.is_dir()
    {
        return Err(Fail(
            2,
            format!("error: --data {}: not a directory", d.display()),
        ));
    }
    load(&args.graph, &opts).map_err(|e| Fail(2, e.to_string()))
}

fn cache_dir(dir: Option<PathBuf>) -> PathBuf {
    dir.or_else(|| std::env::var_os("KODAMA_DAG_CACHE").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from("cache"))
}

/// A cache error as the CLI reports it: a folder that is not a cache is the user's (exit 2).
fn cache_fail(dir: &std::path::Path, e: std::io::Error) -> Fail {
    match crate::cache::NotACache::of(&e) {
        Some(n) => Fail(2, format!("error: {n}")),
        None => Fail(
            1,
            format!("error: cannot open the cache at {}: {e}", dir.display()),
        ),
    }
}

/// Opens the cache, creating it if needed (run, sweep, watch, explain, submit), with its remote
/// tier when one is given; a remote that cannot be reached or is not a cache is exit 2.
fn open_cache(dir: Option<PathBuf>) -> Result<Cache, Fail> {
    let dir = cache_dir(dir);
    let cache = Cache::open(&dir).map_err(|e| cache_fail(&dir, e))?;
    match remote_cache_url() {
        None => Ok(cache),
        Some(url) => {
            let remote =
                crate::cache::Remote::open(&url).map_err(|m| Fail(2, format!("error: {m}")))?;
            Ok(cache.with_remote(remote))
        }
    }
}

/// Runs `g` once and reports it as `run` does; the exit code.
fn run_once(
    g: &Graph,
    cache: &Cache,
    out_dir: PathBuf,
    targets: Vec<String>,
    jobs: Option<usize>,
    json: bool,
    quiet: bool,
) -> Result<u8, Fail> {
    let total = g
        .needed(&crate::exec::target_indices(g, &targets)?)
        .iter()
        .filter(|x| **x)
        .count();
    let reporter = Reporter::new(Mode::detect(quiet), total);
    let record = run(
        g,
        cache,
        &RunOptions {
            jobs,
            targets,
            out_dir: Some(out_dir),
        },
        &reporter,
    )?;
    if json {
        println!(
            "{}",
            serde_json::to_string(&record).expect("records serialize")
        );
    }
    let failed: Vec<_> = record
        .nodes
        .iter()
        .filter(|n| n.status == Status::Failed)
        .collect();
    for n in &failed {
        eprintln!(
            "{}",
            crate::progress::for_terminal(&format!(
                "error: node \"{}\" ({}) failed: {}",
                n.id,
                n.kind,
                n.error.as_deref().unwrap_or("?")
            ))
        );
    }
    for (name, e) in &record.output_errors {
        eprintln!(
            "{}",
            crate::progress::for_terminal(&format!(
                "error: output \"{name}\" was not written: {}",
                e.error
            ))
        );
    }
    if !quiet {
        for path in record.outputs.values() {
            let html = Path::new(path).join("report.html");
            if html.is_file() {
                eprintln!(
                    "report: {} (if a browser refuses it from disk: kodama-dag serve {path})",
                    html.display()
                );
            }
        }
    }
    let user_error =
        failed.iter().any(|n| n.user_error) || record.output_errors.values().any(|e| e.user_error);
    Ok(match () {
        _ if user_error => 2,
        _ if !failed.is_empty() || !record.output_errors.is_empty() => 1,
        _ => 0,
    })
}

/// `watch`: run, then rerun on every relevant change until interrupted. A graph that does not
/// load (or a run that fails) is reported and the watch goes on. Interrupting is safe at any
/// moment: every cache and output write is atomic.
fn watch_loop(
    args: GraphArgs,
    cache: Option<PathBuf>,
    out: Option<PathBuf>,
    jobs: Option<usize>,
    json: bool,
    quiet: bool,
    debounce_ms: u64,
) -> Result<u8, Fail> {
    let mut cache = open_cache(cache)?;
    let mut ignore =
        vec![std::fs::canonicalize(cache.root()).unwrap_or_else(|_| cache.root().to_path_buf())];
    // The inputs of the last graph that loaded: kept while the graph does not load (an input was
    // deleted), so that recreating the input is seen.
    let mut inputs: Vec<PathBuf> = Vec::new();
    loop {
        let loaded = load_graph(&args);
        let out_dir = match (&out, &loaded) {
            (Some(o), _) => o.clone(),
            (None, Ok(g)) => Path::new("out").join(&g.name),
            (None, Err(_)) => {
                Path::new("out").join(crate::graph::folder_name(&args.graph, "graph"))
            }
        };
        cache.writes_outputs_to(&out_dir);
        if let Ok(o) = std::fs::canonicalize(&out_dir) {
            ignore.push(o);
        }
        // Watch before running, so an edit made during the run is not missed.
        let mut paths = crate::watch::watched_paths(&args.graph, loaded.as_ref().ok());
        if loaded.is_ok() {
            inputs = paths.clone();
        } else {
            paths.extend(inputs.iter().cloned());
            paths.sort();
            paths.dedup();
        }
        let (_watcher, rx) = crate::watch::watcher(&paths).map_err(|e| {
            Fail(
                1,
                format!("error: cannot watch {}: {e}", args.graph.display()),
            )
        })?;
        match &loaded {
            Ok(g) => match run_once(g, &cache, out_dir, vec![], jobs, json, quiet) {
                Ok(_) => {}
                Err(Fail(_, msg)) => eprintln!("{}", crate::progress::for_terminal(&msg)),
            },
            Err(Fail(_, msg)) => eprintln!("{}", crate::progress::for_terminal(msg)),
        }
        eprintln!("watching {} paths (Ctrl-C to stop)", paths.len());
        if !crate::watch::wait_for_change(
            &rx,
            &paths,
            &ignore,
            std::time::Duration::from_millis(debounce_ms),
        ) {
            return Ok(0);
        }
        eprintln!("change detected: rerunning");
    }
}

/// Runs the command line `args` (the program's name first, as `std::env::args_os` gives it) and
/// returns its exit code; messages go to stderr, results to stdout, as the binary's.
pub fn main<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    // A second call in one process (Python) keeps the first's subscriber.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_env("KODAMA_DAG_LOG"))
        .with_writer(std::io::stderr)
        .try_init();
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        // Help and --version print and exit 0; a usage error prints and exits 2, as clap's own.
        Err(e) => {
            let _ = e.print();
            return e.exit_code().clamp(0, 255) as u8;
        }
    };
    let remote = cli.remote_cache.or_else(|| {
        std::env::var("KODAMA_DAG_REMOTE_CACHE")
            .ok()
            .filter(|u| !u.is_empty())
    });
    if let Ok(mut url) = REMOTE_CACHE.write() {
        *url = remote;
    }
    let code = match dispatch(cli.command) {
        Ok(code) => code,
        Err(Fail(code, msg)) => {
            eprintln!("{}", crate::progress::for_terminal(&msg));
            code
        }
    };
    use std::io::Write;
    let _ = std::io::stdout().flush();
    code
}

/// Runs the command the user gave; its exit code.
fn dispatch(cmd: Command) -> Result<u8, Fail> {
    match cmd {
        Command::Trace(a) => rf_commands::trace(a).map_err(|(c, m)| Fail(c, m)),
        Command::Radiomap(a) => rf_commands::radiomap(a).map_err(|(c, m)| Fail(c, m)),
        Command::Run {
            graph,
            cache,
            out,
            mut targets,
            tile,
            phase,
            radio,
            jobs,
            json,
            quiet,
        } => {
            let g = load_graph(&graph)?;
            if let Some(i) = radio {
                let node = g.radio_job(i).map_err(|m| Fail(2, format!("error: {m}")))?;
                targets.push(g.nodes[node].id.clone());
            }
            if tile.is_some() || phase.is_some() {
                let job = g
                    .tile_job(tile, phase)
                    .map_err(|m| Fail(2, format!("error: {m}")))?;
                if job.is_empty() {
                    if !quiet {
                        eprintln!("nothing to make for this tile job");
                    }
                    return Ok(0);
                }
                targets.extend(job.into_iter().map(|i| g.nodes[i].id.clone()));
            }
            let mut cache = open_cache(cache)?;
            let out_dir = out.unwrap_or_else(|| Path::new("out").join(&g.name));
            cache.writes_outputs_to(&out_dir);
            run_once(&g, &cache, out_dir, targets, jobs, json, quiet)
        }
        Command::Watch {
            graph,
            cache,
            out,
            jobs,
            json,
            quiet,
            debounce_ms,
        } => watch_loop(graph, cache, out, jobs, json, quiet, debounce_ms),
        Command::Sweep(a) => sweep_command(a),
        Command::Submit(a) => submit_command(a),
        Command::Explain {
            graph,
            cache,
            out,
            targets,
            json,
        } => explain_command(&graph, cache, out, &targets, json),
        Command::Gc(a) => gc_command(a),
        Command::Graph { graph, format } => {
            let g = load_graph(&graph)?;
            print!(
                "{}",
                match format {
                    Format::Dot => to_dot(&g),
                    Format::Mermaid => to_mermaid(&g),
                }
            );
            Ok(0)
        }
        Command::Serve { dir, port } => {
            crate::serve::serve(&dir, port).map_err(|m| Fail(2, format!("error: {m}")))?;
            Ok(0)
        }
        Command::Kinds { kind: None } => {
            kinds::print_kinds();
            Ok(0)
        }
        Command::Kinds { kind: Some(name) } => {
            kinds::print_kind(&name)?;
            Ok(0)
        }
    }
}

/// `sweep`: every variant run in order through one cache, then the metrics table; with
/// `--dry-run`, every variant's graph checked and the variants listed instead.
fn sweep_command(a: SweepArgs) -> Result<u8, Fail> {
    let SweepArgs {
        sweep,
        data,
        sets,
        cache,
        out,
        jobs,
        quiet,
        dry_run,
        allow_outside,
        variant,
        prefix,
    } = a;
    let sw = crate::sweep::load_sweep(&sweep, allow_outside)
        .map_err(|e| Fail(2, format!("error: {e}")))?;
    if dry_run {
        let opts = crate::sweep::SweepOptions {
            data_dir: data,
            sets,
            allow_outside,
            ..Default::default()
        };
        let variants =
            crate::sweep::check_variants(&sw, &opts).map_err(|e| Fail(2, format!("error: {e}")))?;
        for v in variants {
            println!("{}", v.name());
        }
        return Ok(0);
    }
    let mut cache = open_cache(cache)?;
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(&sw.name));
    cache.writes_outputs_to(&out_dir);
    let opts = crate::sweep::SweepOptions {
        data_dir: data,
        sets,
        out_dir: out_dir.clone(),
        jobs,
        allow_outside,
    };
    let reporter = Reporter::new(Mode::detect(quiet), 0);
    if let Some(i) = variant {
        let r =
            crate::sweep::run_one_variant(&sw, &cache, &opts, &reporter, i).map_err(sweep_fail)?;
        let ran = r
            .record
            .nodes
            .iter()
            .filter(|n| n.status == Status::Ran)
            .count();
        eprintln!("variant {i}: {}: {ran} node runs", r.variant.name());
        return Ok(0);
    }
    if prefix {
        let ids = crate::sweep::run_prefix(&sw, &cache, &opts, &reporter).map_err(sweep_fail)?;
        if ids.is_empty() {
            eprintln!("no node is shared by every variant: nothing to run");
        } else {
            eprintln!("the shared prefix ran, up to {}", ids.join(", "));
        }
        return Ok(0);
    }
    let results = crate::sweep::run_sweep(&sw, &cache, &opts, &reporter, |i, n, v| {
        if !quiet {
            eprintln!("variant {}/{n}: {}", i + 1, v.name());
        }
    })
    .map_err(sweep_fail)?;
    let ran: usize = results
        .iter()
        .map(|r| {
            r.record
                .nodes
                .iter()
                .filter(|n| n.status == Status::Ran)
                .count()
        })
        .sum();
    eprintln!(
        "{} variants, {ran} node runs in all; table in {}",
        results.len(),
        out_dir.join("table.md").display()
    );
    print!(
        "{}",
        std::fs::read_to_string(out_dir.join("table.md")).unwrap_or_default()
    );
    Ok(0)
}

/// A sweep's failure as the CLI reports it.
fn sweep_fail(e: crate::sweep::SweepError) -> Fail {
    match e {
        crate::sweep::SweepError::Graph(m) => Fail(2, format!("error: {m}")),
        crate::sweep::SweepError::Failed(m) => Fail(1, format!("error: {m}")),
        crate::sweep::SweepError::Run(e) => Fail::from(e),
    }
}

/// `submit`: the graph or sweep checked here (bad input exits 2 before anything is queued), its
/// job scripts written to `<out>/slurm/<n>/`, then submitted with sbatch unless `--dry-run`;
/// with `--wait`, squeue polled until the jobs end, exiting as a local run would.
fn submit_command(a: SubmitArgs) -> Result<u8, Fail> {
    use crate::slurm;
    let Engine::Slurm = a.engine;
    let usage = |m: String| Fail(2, format!("error: {m}"));
    let user_sbatch = match &a.sbatch {
        None => Vec::new(),
        Some(text) => shlex::split(text).ok_or_else(|| {
            usage(format!(
                "--sbatch {text:?}: unbalanced quotes; expected options as a shell writes them"
            ))
        })?,
    };
    if let Some(d) = &a.data
        && !d.is_dir()
    {
        return Err(usage(format!("--data {}: not a directory", d.display())));
    }
    let cache = open_cache(a.cache.clone())?;
    let cpus = a.jobs.unwrap_or(1);
    // Every job's shared arguments, each a quoted shell word.
    let mut common = vec![
        "--cache".to_string(),
        slurm::quote_path(cache.root()).map_err(usage)?,
    ];
    if let Some(d) = &a.data {
        common.push("--data".into());
        common.push(slurm::quote_path(d).map_err(usage)?);
    }
    for s in &a.sets {
        common.push("--set".into());
        common.push(slurm::quote(s).map_err(usage)?);
    }
    if a.allow_outside {
        common.push("--allow-outside".into());
    }
    if let Some(url) = remote_cache_url() {
        common.push("--remote-cache".into());
        common.push(slurm::quote(&url).map_err(usage)?);
    }
    let is_sweep = crate::sweep::is_sweep_file(&a.file).map_err(usage)?;
    let mut graph_tiles = None;
    let (plan, out_dir) = if is_sweep {
        if !a.targets.is_empty() {
            return Err(usage(
                "--target is for graphs; a sweep runs what its metrics and outputs need".into(),
            ));
        }
        let sw = crate::sweep::load_sweep(&a.file, a.allow_outside).map_err(usage)?;
        let out_dir = a
            .out
            .clone()
            .unwrap_or_else(|| Path::new("out").join(&sw.name));
        let opts = crate::sweep::SweepOptions {
            data_dir: a.data.clone(),
            sets: a.sets.clone(),
            out_dir: out_dir.clone(),
            jobs: Some(cpus),
            allow_outside: a.allow_outside,
        };
        common.push("--out".into());
        common.push(slurm::quote_path(&out_dir).map_err(usage)?);
        common.push("--quiet".into());
        (
            slurm::plan_sweep(&sw, &opts, &cache, &common).map_err(usage)?,
            out_dir,
        )
    } else {
        let g = load_graph(&GraphArgs {
            graph: a.file.clone(),
            data: a.data.clone(),
            sets: a.sets.clone(),
            allow_outside: a.allow_outside,
            tile_m: a.tile_m,
            halo_m: a.halo_m,
        })?;
        crate::exec::target_indices(&g, &a.targets)?;
        let out_dir = a
            .out
            .clone()
            .unwrap_or_else(|| Path::new("out").join(&g.name));
        common.push("--out".into());
        common.push(slurm::quote_path(&out_dir).map_err(usage)?);
        for t in &a.targets {
            common.push("--target".into());
            common.push(slurm::quote(t).map_err(usage)?);
        }
        if let Some(m) = a.tile_m {
            common.extend(["--tile-m".to_string(), m.to_string()]);
        }
        if let Some(m) = a.halo_m {
            common.extend(["--halo-m".to_string(), m.to_string()]);
        }
        common.extend(["--json".to_string(), "--quiet".to_string()]);
        graph_tiles = g.tiling.as_ref().map(|t| t.tiles.len());
        let plan = if g.tiling.is_some() {
            if !a.targets.is_empty() {
                return Err(usage(
                    "--target with a tiled graph: its jobs are the tiles and the merges; submit the targets untiled or run them after".into(),
                ));
            }
            slurm::plan_tiled(&g, &cache, &common)
        } else {
            slurm::plan_graph(&g, &common)
        };
        (plan.map_err(usage)?, out_dir)
    };
    for n in &plan.notes {
        eprintln!("{n}");
    }
    // A tiled graph's records are mostly its tile tasks': enough of them to reach its prefix and
    // merge jobs' too.
    let tiles = graph_tiles.unwrap_or(0);
    let sizing = RECORDS_SIZING
        .max(2 * tiles + RECORDS_SIZING)
        .min(MAX_RECORDS_SIZING);
    let records = crate::record::load_records(&cache.runs_dir(&plan.runs_key), sizing);
    let res = slurm::resources(&records, cpus);
    let mut plan = plan;
    if graph_tiles.is_some() {
        slurm::size_tile_jobs(&mut plan, &records, cpus);
    }
    let exe = std::env::current_exe()
        .map_err(|e| Fail(1, format!("error: cannot find kodama-dag's own path: {e}")))?;
    let cwd = std::env::current_dir()
        .map_err(|e| Fail(1, format!("error: cannot read the working folder: {e}")))?;
    let dir = slurm::submission_dir(&out_dir.join("slurm"))
        .map_err(|m| Fail(1, format!("error: {m}")))?;
    let dir = std::path::absolute(&dir).unwrap_or(dir);
    slurm::write_scripts(&plan, &dir, &exe, &cwd, &res, a.array_limit, &user_sbatch)
        .map_err(|m| Fail(1, format!("error: {m}")))?;
    if a.dry_run {
        eprintln!(
            "job scripts in {}; nothing submitted (--dry-run)",
            dir.display()
        );
        print!(
            "{}",
            std::fs::read_to_string(dir.join("submit.sh")).unwrap_or_default()
        );
        return Ok(0);
    }
    let ids = slurm::submit(&plan, &dir, a.array_limit, &user_sbatch).map_err(usage)?;
    let listed: Vec<String> = plan
        .jobs
        .iter()
        .zip(&ids)
        .map(|(j, id)| format!("{}={id}", j.name))
        .collect();
    std::fs::write(dir.join("jobs.txt"), listed.join("\n") + "\n").ok();
    eprintln!(
        "submitted {}; scripts and logs in {}",
        listed.join(" "),
        dir.display()
    );
    println!("{}", listed.join(" "));
    if !a.wait {
        return Ok(0);
    }
    let ended = slurm::wait(
        &plan,
        &ids,
        std::time::Duration::from_secs(a.poll_s),
        |line| eprintln!("{line}"),
    )
    .map_err(|m| Fail(1, format!("error: {m}")))?;
    for (job, task, e) in &ended.failed {
        let id = plan
            .jobs
            .iter()
            .position(|j| &j.name == job)
            .map(|k| ids[k].clone())
            .unwrap_or_default();
        let log = slurm::log_path(&dir, job, &id, *task);
        let task = task.map(|t| format!(" task {t}")).unwrap_or_default();
        if e.reason == "DependencyNeverSatisfied" {
            eprintln!("error: {job}{task} (job {id}): cancelled: a job it waits for failed");
            continue;
        }
        let why = match e.exit_code {
            Some(c) => format!("{}, exit {c} ({})", e.state, e.reason),
            None => format!("{} ({})", e.state, e.reason),
        };
        eprintln!(
            "error: {job}{task} (job {id}): {why}; log: {}",
            log.display()
        );
        if let Ok(text) = std::fs::read_to_string(&log) {
            for line in text
                .lines()
                .rev()
                .take(5)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
            {
                eprintln!("    {line}");
            }
        }
    }
    let code = ended.code();
    if code == 0 && is_sweep {
        print!(
            "{}",
            std::fs::read_to_string(out_dir.join("table.md")).unwrap_or_default()
        );
    }
    Ok(code)
}

/// How many of a graph's latest run records size a job's memory and time.
const RECORDS_SIZING: usize = 20;
/// The most records read to size a tiled graph's jobs.
const MAX_RECORDS_SIZING: usize = 2000;

/// `explain`: what `run` would do for each node of the graph (or of `targets` and what they
/// need) and why, as lines or as JSON.
fn explain_command(
    graph: &GraphArgs,
    cache: Option<PathBuf>,
    out: Option<PathBuf>,
    targets: &[String],
    json: bool,
) -> Result<u8, Fail> {
    let g = load_graph(graph)?;
    let mut cache = open_cache(cache)?;
    // The folder `run` would write, left out of folder inputs as `run` leaves it out.
    cache.writes_outputs_to(&out.unwrap_or_else(|| Path::new("out").join(&g.name)));
    let plan = explain(&g, &cache, targets)?;
    let tiles = g.tiling.as_ref().map(|t| {
        serde_json::json!({
            "tile_m": t.tile_m,
            "halo_m": t.halo_m,
            "halo_from": t.halo_from,
            "phases": t.phases,
            "tiles": t.tiles.iter().map(|tile| serde_json::json!({
                "name": tile.name,
                "core": [tile.core.min, tile.core.max],
                "window": [tile.window.min, tile.window.max],
            })).collect::<Vec<_>>(),
        })
    });
    if json {
        println!(
            "{}",
            serde_json::json!({ "graph": g.path.display().to_string(), "tiling": tiles, "nodes": plan })
        );
    } else {
        if let Some(t) = &g.tiling {
            println!(
                "tiled: {} tiles of {} m (tile I = x<column>y<row> from the south-west, row by row), halo {} m ({}), {} tile phase(s)",
                t.tiles.len(),
                t.tile_m,
                t.halo_m,
                t.halo_from,
                t.phases
            );
        }
        for e in &plan {
            let word = match e.plan {
                Plan::Cached => "cached",
                Plan::Run => "run",
                Plan::Maybe => "maybe",
            };
            println!("{word:<7} {} ({}): {}", e.id, e.kind, e.reason);
        }
    }
    Ok(0)
}

/// `gc`: least recently used artifacts evicted down to `--max-bytes`, never what a kept
/// graph's last run produced. gc deletes: it opens only a folder that is a cache, and creates
/// none.
fn gc_command(a: GcArgs) -> Result<u8, Fail> {
    let GcArgs {
        cache,
        max_bytes,
        keep,
        data,
        allow_outside,
    } = a;
    let dir = cache_dir(cache);
    let cache = Cache::open_existing(&dir).map_err(|e| cache_fail(&dir, e))?;
    let mut pinned = BTreeSet::new();
    for g in keep {
        let graph = load_graph(&GraphArgs {
            graph: g,
            data: data.clone(),
            sets: Vec::new(),
            allow_outside,
            tile_m: None,
            halo_m: None,
        })?;
        pinned.extend(crate::exec::last_run_digests(&graph, &cache));
    }
    let report = gc(&cache, max_bytes, &pinned, || {
        eprintln!("waiting for running jobs to release the cache...")
    })
    .map_err(|e| {
        Fail(
            1,
            format!("error: gc of {} failed: {e}", cache.root().display()),
        )
    })?;
    println!(
        "{} -> {} bytes; removed {} artifacts and {} stale action entries; kept {} pinned",
        report.bytes_before,
        report.bytes_after,
        report.blobs_removed,
        report.actions_removed,
        report.blobs_pinned
    );
    if let Some(first) = report.foreign.first() {
        eprintln!(
            "warning: left alone {} entries under cas/, ac/ and tmp/ that kodama-dag did \
             not name (first: {}); gc never deletes them",
            report.foreign.len(),
            first.display()
        );
    }
    Ok(0)
}
