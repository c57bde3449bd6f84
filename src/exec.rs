//! Running a graph: nodes whose inputs are ready run in parallel on a rayon pool; each one is a
//! cache hit (its action key maps to a stored artifact) or runs its stage and stores the result.
//!
//! **Invariants:**
//! - a node runs at most once per run, after all its inputs are done (rebuilding a corrupt
//!   blob re-executes the producing node once more, which is the point);
//! - a failure is never cached, and stops only the failed node's descendants;
//! - an output is stored under a key (and exported) only if the node's files are still what the
//!   key's digests say after its stage read them: a moved input drops the output and reruns the
//!   node once on fresh digests, then fails it;
//! - the state mutex is never held while a slot mutex is taken or a stage runs; slot mutexes are
//!   taken in ancestor-before-descendant order only, so there is no lock cycle.

use std::collections::BTreeMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use kodama_nodes::io::cog::Band;
use kodama_nodes::io::export::{Encoded, check_names, encode_with_band, output_file};
use kodama_nodes::stage::{Arity, Slot};
use kodama_nodes::{Artifact, Ctx, Inputs, StageError};
use rayon::prelude::*;

use crate::cache::{Action, Cache, Digest, InputStamp, write_atomic};
use crate::graph::Graph;
use crate::key::{action_key, node_site, site_digest};
use crate::progress::Reporter;
use crate::record::{LastRun, NodeRecord, RunRecord, Snapshot, Status, save_record, what_changed};
use crate::registry;

/// Options of one run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Worker threads; default: all cores.
    pub jobs: Option<usize>,
    /// Run only these nodes and their ancestors; all when empty.
    pub targets: Vec<String>,
    /// Where declared outputs are written; None writes none (a metrics-only sweep's variants).
    pub out_dir: Option<PathBuf>,
}

/// Why a run could not start or finish.
#[derive(Debug)]
pub enum RunError {
    /// Bad usage or input (exit 2): unknown target, unreadable input file.
    Usage(String),
    /// The cache or output folder failed (exit 1).
    Io(String),
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Usage(m) | RunError::Io(m) => f.write_str(m),
        }
    }
}

/// The folder name under `runs/` for this graph file: its stem and a hash of its absolute path.
pub fn graph_key(graph: &Graph) -> String {
    let abs = std::fs::canonicalize(&graph.path).unwrap_or_else(|_| graph.path.clone());
    let h = blake3::hash(abs.as_os_str().as_encoded_bytes()).to_hex();
    format!("{}-{}", graph.name, &h[..16])
}

/// The output digests of every node of `graph`'s last run in `cache` (what `gc --keep` pins).
pub fn last_run_digests(graph: &Graph, cache: &Cache) -> Vec<[u8; 32]> {
    LastRun::load(&cache.runs_dir(&graph_key(graph)))
        .nodes
        .values()
        .filter_map(|s| s.digest.as_deref())
        .filter_map(|d| crate::cache::Digest::from_hex(d).ok())
        .map(|d| *d.as_bytes())
        .collect()
}

/// Resolves `--target` ids to node indices.
pub fn target_indices(graph: &Graph, targets: &[String]) -> Result<Vec<usize>, RunError> {
    targets
        .iter()
        .map(|t| {
            graph.index(t).ok_or_else(|| {
                let hint =
                    crate::syntax::did_you_mean(t, graph.nodes.iter().map(|n| n.id.as_str()))
                        .map(|m| format!("; did you mean `{m}`?"))
                        .unwrap_or_default();
                RunError::Usage(format!(
                    "--target: no node `{t}` in {}{hint}",
                    graph.path.display()
                ))
            })
        })
        .collect()
}

/// Content digests of the files of every needed node, in parallel, through the stat cache.
pub fn file_digests(
    graph: &Graph,
    cache: &Cache,
    need: &[bool],
) -> Result<Vec<Vec<Digest>>, RunError> {
    Ok(stamped_file_digests(graph, cache, need)?
        .into_iter()
        .map(|f| f.digests)
        .collect())
}

/// The digests of one node's declared files, with how each looked when it was digested.
#[derive(Clone, Default)]
struct NodeFiles {
    digests: Vec<Digest>,
    stamps: Vec<InputStamp>,
}

/// [`file_digests`] with the stamps the post-run re-check compares against.
fn stamped_file_digests(
    graph: &Graph,
    cache: &Cache,
    need: &[bool],
) -> Result<Vec<NodeFiles>, RunError> {
    graph
        .nodes
        .par_iter()
        .zip(need)
        .map(|(n, &needed)| {
            if !needed {
                return Ok(NodeFiles::default());
            }
            node_files(n, cache).map_err(|(f, e)| {
                RunError::Usage(format!(
                    "node \"{}\": cannot read `{}` ({}): {e}",
                    n.id,
                    f.field,
                    f.path.display()
                ))
            })
        })
        .collect()
}

/// Digests and stamps of `node`'s files; on failure, the file and the error.
fn node_files<'n>(
    node: &'n crate::graph::Node,
    cache: &Cache,
) -> Result<NodeFiles, (&'n crate::graph::InputFile, std::io::Error)> {
    let mut files = NodeFiles::default();
    for f in &node.files {
        let (d, stamp) = cache.file_digest_stamped(&f.path).map_err(|e| (f, e))?;
        files.digests.push(d);
        files.stamps.push(stamp);
    }
    Ok(files)
}

/// Worker threads per available core at most: more only adds memory and contention, and an
/// absurd `--jobs` would otherwise try to start that many threads.
pub const MAX_JOBS_PER_CORE: usize = 4;

/// The worker threads for `jobs`, clamped to [`MAX_JOBS_PER_CORE`] per core, with a warning
/// when clamped.
pub fn worker_threads(jobs: Option<usize>) -> (Option<usize>, Option<String>) {
    let Some(j) = jobs else {
        return (None, None);
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let max = cores * MAX_JOBS_PER_CORE;
    if j > max {
        let warning = format!(
            "--jobs {j} is more than {MAX_JOBS_PER_CORE} per core ({cores} cores); using {max}"
        );
        return (Some(max), Some(warning));
    }
    (Some(j.max(1)), None)
}

fn pool(jobs: Option<usize>, reporter: &Reporter) -> Result<rayon::ThreadPool, RunError> {
    let mut b = rayon::ThreadPoolBuilder::new().thread_name(|i| format!("kodama-{i}"));
    let (jobs, warning) = worker_threads(jobs);
    if let Some(w) = warning {
        reporter.warn(&w);
    }
    if let Some(j) = jobs {
        b = b.num_threads(j);
    }
    b.build()
        .map_err(|e| RunError::Io(format!("cannot start worker threads: {e}")))
}

/// Runs `graph` against `cache`, writes its outputs, saves the run record, and returns it.
pub fn run(
    graph: &Graph,
    cache: &Cache,
    opts: &RunOptions,
    reporter: &Reporter,
) -> Result<RunRecord, RunError> {
    let io = |what: &str, e: std::io::Error| RunError::Io(format!("{what}: {e}"));
    let targets = target_indices(graph, &opts.targets)?;
    let need = graph.needed(&targets);
    let _lock = cache
        .lock_shared()
        .map_err(|e| io("cannot lock the cache", e))?;
    remove_stale_temps(&cache.tmp());
    let runs_dir = cache.runs_dir(&graph_key(graph));
    let last = LastRun::load(&runs_dir);
    let started = Instant::now();
    let pool = pool(opts.jobs, reporter)?;
    let (records, snapshots, outputs, output_errors) =
        pool.install(|| -> Result<_, RunError> {
            let files = stamped_file_digests(graph, cache, &need)?;
            let exec = Exec::new(graph, cache, &last, reporter, files, need.clone());
            rayon::scope(|s| {
                let exec = &exec;
                for i in 0..graph.nodes.len() {
                    if exec.need[i] && graph.nodes[i].deps.is_empty() {
                        s.spawn(move |s| exec.visit(s, i));
                    }
                }
            });
            let (outputs, output_errors) = match &opts.out_dir {
                Some(dir) => exec.export(dir),
                None => Default::default(),
            };
            let (records, snapshots) = exec.into_results();
            Ok((records, snapshots, outputs, output_errors))
        })?;
    reporter.finish(&records, started.elapsed().as_secs_f64());
    let record = RunRecord {
        graph: graph.path.display().to_string(),
        nodes: records,
        outputs,
        output_errors,
        wall_s: started.elapsed().as_secs_f64(),
        peak_rss_mb: crate::record::peak_rss_mb(),
    };
    let mut next = last;
    next.nodes.extend(snapshots);
    next.save(&runs_dir, &cache.tmp())
        .map_err(|e| io("cannot save the run state", e))?;
    save_record(&record, &runs_dir, &cache.tmp())
        .map_err(|e| io("cannot save the run record", e))?;
    Ok(record)
}

/// The result of one node.
struct Outcome {
    record: NodeRecord,
    digest: Option<Digest>,
    /// The digest of each report the node made, by name.
    reports: BTreeMap<&'static str, Digest>,
    /// This node or one of its ancestors ran in this run.
    ran_upstream: bool,
    snapshot: Option<Snapshot>,
}

impl Outcome {
    fn ok(&self) -> bool {
        self.digest.is_some()
    }
}

#[derive(Default)]
struct State {
    pending: Vec<usize>,
    consumers_left: Vec<usize>,
    outcomes: Vec<Option<Outcome>>,
}

struct Executed {
    artifact: Arc<Artifact>,
    digest: Digest,
    reports: BTreeMap<&'static str, Digest>,
    snapshot: Snapshot,
    /// Why the stage ran twice: an input moved while it ran the first time.
    rerun: Option<String>,
}

/// A stage run on files that held still while it ran: what it returned (or how it panicked),
/// the key and snapshot of the digests it ran on, and why it first ran again, if it did.
struct Settled {
    result: std::thread::Result<Result<registry::Ran, StageError>>,
    key: Digest,
    snapshot: Snapshot,
    moved_once: Option<String>,
}

/// What `node`'s stage made, as a failure when it failed, panicked (a bug, named so), returned
/// another type than its kind's output, or made other reports than its kind declares.
fn checked_run(
    node: &crate::graph::Node,
    result: std::thread::Result<Result<registry::Ran, StageError>>,
) -> Result<registry::Ran, StageError> {
    let ran = match result {
        Ok(r) => r?,
        Err(panic) => {
            let msg = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned());
            return Err(StageError::Failed(format!(
                "the stage panicked (a bug): {}",
                msg.unwrap_or_default()
            )));
        }
    };
    if ran.output.ty() != node.kind.output {
        return Err(StageError::Failed(format!(
            "the stage returned {} instead of {}",
            ran.output.ty(),
            node.kind.output
        )));
    }
    let declared: Vec<_> = node.kind.reports.iter().map(|r| (r.name, r.ty)).collect();
    let made: Vec<_> = ran.reports.iter().map(|(n, a)| (*n, a.ty())).collect();
    if made != declared {
        return Err(StageError::Failed(format!(
            "the stage made the reports {made:?}; its kind declares {declared:?} (a bug)"
        )));
    }
    Ok(ran)
}

struct Exec<'a> {
    graph: &'a Graph,
    cache: &'a Cache,
    last: &'a LastRun,
    reporter: &'a Reporter,
    site: Digest,
    /// Each node's files: digested before any node runs, refreshed when a stage saw one move.
    files: Vec<Mutex<NodeFiles>>,
    need: Vec<bool>,
    consumers: Vec<Vec<usize>>,
    is_output: Vec<bool>,
    state: Mutex<State>,
    /// Artifacts in memory: produced this run, or loaded for a consumer; dropped when the last
    /// consumer is done (outputs are kept for export).
    slots: Vec<Mutex<Option<Arc<Artifact>>>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panicking stage is caught before it can poison anything; recover the data regardless.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl<'a> Exec<'a> {
    fn new(
        graph: &'a Graph,
        cache: &'a Cache,
        last: &'a LastRun,
        reporter: &'a Reporter,
        files: Vec<NodeFiles>,
        need: Vec<bool>,
    ) -> Self {
        let n = graph.nodes.len();
        let consumers: Vec<Vec<usize>> = graph
            .consumers()
            .into_iter()
            .map(|c| c.into_iter().filter(|&c| need[c]).collect())
            .collect();
        let mut is_output = vec![false; n];
        for (_, i) in &graph.outputs {
            is_output[*i] = true;
        }
        let state = State {
            pending: graph.nodes.iter().map(|n| n.deps.len()).collect(),
            consumers_left: consumers.iter().map(Vec::len).collect(),
            outcomes: (0..n).map(|_| None).collect(),
        };
        Exec {
            graph,
            cache,
            last,
            reporter,
            site: site_digest(&graph.site),
            files: files.into_iter().map(Mutex::new).collect(),
            need,
            consumers,
            is_output,
            state: Mutex::new(state),
            slots: (0..n).map(|_| Mutex::new(None)).collect(),
        }
    }

    fn visit<'s>(&'s self, s: &rayon::Scope<'s>, i: usize) {
        let t0 = Instant::now();
        let mut outcome = self.process(i);
        outcome.record.ms = (t0.elapsed().as_secs_f64() * 1e6).round() / 1e3;
        self.reporter.finished(&outcome.record);
        let node = &self.graph.nodes[i];
        let (ready, release) = {
            let mut st = lock(&self.state);
            st.outcomes[i] = Some(outcome);
            let mut release = Vec::new();
            for &d in &node.deps {
                st.consumers_left[d] -= 1;
                if st.consumers_left[d] == 0 && !self.is_output[d] {
                    release.push(d);
                }
            }
            let mut ready = Vec::new();
            for &c in &self.consumers[i] {
                st.pending[c] -= 1;
                if st.pending[c] == 0 {
                    ready.push(c);
                }
            }
            (ready, release)
        };
        for d in release {
            *lock(&self.slots[d]) = None;
        }
        if self.consumers[i].is_empty() && !self.is_output[i] {
            *lock(&self.slots[i]) = None;
        }
        for c in ready {
            s.spawn(move |s| self.visit(s, c));
        }
    }

    fn record(
        &self,
        i: usize,
        status: Status,
        reason: String,
        digest: Option<Digest>,
    ) -> NodeRecord {
        let node = &self.graph.nodes[i];
        NodeRecord {
            id: node.id.clone(),
            kind: node.kind.name.to_owned(),
            status,
            reason,
            ms: 0.0,
            digest: digest.map(|d| d.to_hex().to_string()),
            error: None,
            user_error: false,
            unit: self.graph.raster_unit(i).map(str::to_owned),
        }
    }

    /// The digests of each input list of node `i`, once all its inputs are done.
    fn input_digests(&self, i: usize) -> Vec<Vec<Digest>> {
        let st = lock(&self.state);
        let node = &self.graph.nodes[i];
        node.inputs
            .iter()
            .map(|list| {
                list.iter()
                    .map(|&d| {
                        st.outcomes[d]
                            .as_ref()
                            .and_then(|o| o.digest)
                            .expect("input done")
                    })
                    .collect()
            })
            .collect()
    }

    fn process(&self, i: usize) -> Outcome {
        let node = &self.graph.nodes[i];
        let ran_upstream = {
            let st = lock(&self.state);
            let deps: Vec<&Outcome> = node
                .deps
                .iter()
                .map(|&d| st.outcomes[d].as_ref().expect("deps done"))
                .collect();
            if let Some((d, o)) = node.deps.iter().zip(&deps).find(|(_, o)| !o.ok()) {
                let why = if o.record.status == Status::Failed {
                    "failed"
                } else {
                    "was skipped"
                };
                let reason = format!("input \"{}\" {why}", self.graph.nodes[*d].id);
                return Outcome {
                    record: self.record(i, Status::Skipped, reason, None),
                    digest: None,
                    reports: BTreeMap::new(),
                    ran_upstream: false,
                    snapshot: None,
                };
            }
            deps.iter().any(|o| o.ran_upstream)
        };
        if let Some(report) = node.kind.report {
            return self.report_outcome(i, report);
        }
        let files = lock(&self.files[i]).digests.clone();
        let site = node_site(&self.site, node);
        let (key, snapshot) = action_key(node, &site, &self.input_digests(i), &files);
        let last = self.last.nodes.get(&node.id);
        let mut reason = None;
        if let Some(action) = self.cache.get_action(&key) {
            let (digest, size) = action.output;
            let reports = self.stored_reports(i, &action);
            let parts_stored = || action.parts.iter().all(|(d, s)| self.cache.has_blob(d, *s));
            if self.cache.has_blob(&digest, size) && reports.is_some() && parts_stored() {
                let unchanged = last.is_some_and(|l| l.key == snapshot.key);
                let (status, why) = match (ran_upstream, unchanged) {
                    (true, true) => (
                        Status::Cutoff,
                        "upstream reran and reproduced its output".to_owned(),
                    ),
                    (true, false) => (
                        Status::Cached,
                        format!("in the cache, though {}", what_changed(&snapshot, last)),
                    ),
                    (false, true) => (Status::Cached, "unchanged".to_owned()),
                    (false, false) => (
                        Status::Cached,
                        format!("in the cache, though {}", what_changed(&snapshot, last)),
                    ),
                };
                let snapshot = Snapshot {
                    digest: Some(digest.to_hex().to_string()),
                    ..snapshot
                };
                return Outcome {
                    record: self.record(i, status, why, Some(digest)),
                    digest: Some(digest),
                    reports: reports.unwrap_or_default(),
                    ran_upstream,
                    snapshot: Some(snapshot),
                };
            }
            self.reporter.warn(&format!(
                "node \"{}\": its cached output, a report or a part is missing from the store; rebuilding",
                node.id
            ));
            reason = Some(
                "cached output, a report or a part was missing from the store; rebuilt".to_owned(),
            );
        }
        let reason = reason.unwrap_or_else(|| what_changed(&snapshot, last));
        match self.execute(i) {
            Ok(ex) => {
                *lock(&self.slots[i]) = Some(ex.artifact);
                let reason = match ex.rerun {
                    Some(why) => format!("{reason}; {why}"),
                    None => reason,
                };
                Outcome {
                    record: self.record(i, Status::Ran, reason, Some(ex.digest)),
                    digest: Some(ex.digest),
                    reports: ex.reports,
                    ran_upstream: true,
                    snapshot: Some(ex.snapshot),
                }
            }
            Err(e) => {
                let mut record = self.record(i, Status::Failed, reason, None);
                record.user_error = e.is_user_error();
                record.error = Some(crate::progress::cut(
                    &e.to_string(),
                    crate::progress::MAX_RECORD_CHARS,
                ));
                Outcome {
                    record,
                    digest: None,
                    reports: BTreeMap::new(),
                    ran_upstream: true,
                    snapshot: None,
                }
            }
        }
    }

    /// Runs node `i`'s stage on its inputs and stores the output.
    fn execute(&self, i: usize) -> Result<Executed, StageError> {
        let node = &self.graph.nodes[i];
        let inputs = self.stage_inputs(i)?;
        let settled = self.run_on_settled_files(i, &inputs)?;
        let ran = checked_run(node, settled.result)?;
        let (digest, reports) = self.store_ran(&settled.key, &ran)?;
        let mut snapshot = settled.snapshot;
        snapshot.digest = Some(digest.to_hex().to_string());
        Ok(Executed {
            artifact: Arc::new(ran.output),
            digest,
            reports,
            snapshot,
            rerun: settled
                .moved_once
                .map(|why| format!("{why} while it ran, so it ran again")),
        })
    }

    /// Node `i`'s inputs as its stage takes them: each input slot's upstream artifacts, loaded
    /// (or rebuilt) as needed.
    fn stage_inputs(&self, i: usize) -> Result<Inputs, StageError> {
        let node = &self.graph.nodes[i];
        let mut inputs = Inputs::new();
        for (spec, list) in node.kind.inputs.iter().zip(&node.inputs) {
            let arts = list
                .iter()
                .map(|&d| self.artifact(d))
                .collect::<Result<Vec<_>, _>>()?;
            let slot = match spec.arity {
                Arity::One => Slot::One(arts.into_iter().next().expect("checked by the loader")),
                Arity::Optional => Slot::Optional(arts.into_iter().next()),
                Arity::Many => Slot::Many(arts),
            };
            inputs.push(spec.name, slot);
        }
        Ok(inputs)
    }

    /// Runs node `i`'s stage on `inputs` until its files held still while it ran. The stage reads
    /// its files while it runs, after they were digested: if one moved in between, its output
    /// belongs to other bytes than its key says. It is dropped and the node runs once more on
    /// fresh digests; if they move again, the node fails. Nothing of a moved input is ever stored
    /// under a key.
    fn run_on_settled_files(&self, i: usize, inputs: &Inputs) -> Result<Settled, StageError> {
        let node = &self.graph.nodes[i];
        let paths: Vec<PathBuf> = node.files.iter().map(|f| f.path.clone()).collect();
        let mut moved_once: Option<String> = None;
        loop {
            let files = lock(&self.files[i]).clone();
            // Inputs are loaded now; a rebuilt input may have changed its digest, so key afresh.
            let site = node_site(&self.site, node);
            let (key, snapshot) = action_key(node, &site, &self.input_digests(i), &files.digests);
            let progress = self.reporter.started(&node.id, node.kind.name);
            let ctx = Ctx {
                site: &self.graph.site,
                files: &paths,
                progress: &progress,
                seed: *key.as_bytes(),
                parts: self.cache,
                window: node.window,
            };
            let result = catch_unwind(AssertUnwindSafe(|| node.params.run(inputs, &ctx)));
            drop(progress);
            // A failure is re-checked too: a file caught half-saved fails a stage that the saved
            // file would not.
            let moved = node
                .files
                .iter()
                .zip(&files.stamps)
                .find_map(|(f, s)| s.moved().map(|why| format!("input `{}`: {why}", f.field)));
            let Some(why) = moved else {
                return Ok(Settled {
                    result,
                    key,
                    snapshot,
                    moved_once,
                });
            };
            if let Some(first) = moved_once {
                return Err(StageError::Failed(format!(
                    "{first} while the node ran, and {why} while it ran again; its output was \
                     not kept. Run again once the input is settled"
                )));
            }
            self.reporter.warn(&format!(
                "node \"{}\": {why} while it ran; its output was dropped and it runs again on \
                 the new content",
                node.id
            ));
            let fresh = node_files(node, self.cache).map_err(|(f, e)| {
                StageError::bad_input(
                    &f.path,
                    format!("`{}`", f.field),
                    format!("a readable input; it changed while the node ran and now: {e}"),
                )
            })?;
            *lock(&self.files[i]) = fresh;
            moved_once = Some(why);
        }
    }

    /// Stores what the stage made: its output and reports as blobs, the action entry listing
    /// them under `key`. Returns the output's digest and each report's.
    fn store_ran(
        &self,
        key: &Digest,
        ran: &registry::Ran,
    ) -> Result<(Digest, BTreeMap<&'static str, Digest>), StageError> {
        let store = |e: std::io::Error| {
            StageError::Failed(format!(
                "cannot store the output in {}: {e}",
                self.cache.root().display()
            ))
        };
        let (digest, size) = self.store(&ran.output).map_err(store)?;
        // The parts were stored by the stage as it made them; the entry names them, so gc and
        // the remote tier keep them with the output.
        let mut action = Action {
            output: (digest, size),
            reports: Vec::new(),
            parts: ran
                .output
                .parts()
                .iter()
                .map(|p| (Digest::from(p.digest), p.size))
                .collect(),
        };
        let mut reports = BTreeMap::new();
        for (name, report) in &ran.reports {
            let (d, size) = self.store(report).map_err(store)?;
            action.reports.push((name.to_string(), d, size));
            reports.insert(*name, d);
        }
        self.cache.put_action(key, &action).map_err(store)?;
        Ok((digest, reports))
    }

    /// Encodes `artifact` straight into the store (a large artifact's encoding is never held
    /// whole): its digest and size.
    fn store(&self, artifact: &Artifact) -> std::io::Result<(Digest, u64)> {
        self.cache.put_blob_with(|w| {
            rmp_serde::encode::write(w, artifact).map_err(|e| {
                // A failed write (a full disk) is told as itself, not as an encoding error.
                let mut cause = std::error::Error::source(&e);
                while let Some(c) = cause {
                    if let Some(io) = c.downcast_ref::<std::io::Error>() {
                        return std::io::Error::new(io.kind(), io.to_string());
                    }
                    cause = c.source();
                }
                std::io::Error::other(format!("cannot encode the output: {e}"))
            })
        })
    }

    /// The reports of node `i` a cached action recorded, if it recorded every report the kind
    /// declares and each is in the store (an entry from before the kind had reports has none:
    /// the node runs again to make them).
    fn stored_reports(&self, i: usize, action: &Action) -> Option<BTreeMap<&'static str, Digest>> {
        self.graph.nodes[i]
            .kind
            .reports
            .iter()
            .map(|r| {
                let (d, size) = action.report(r.name)?;
                self.cache.has_blob(&d, size).then_some((r.name, d))
            })
            .collect()
    }

    /// The outcome of report node `i` (`"carved.outcomes"`): what its node's run, done or
    /// cached, recorded for it. Nothing runs.
    fn report_outcome(&self, i: usize, report: &'static str) -> Outcome {
        let node = &self.graph.nodes[i];
        let of = node.inputs[0][0];
        let st = lock(&self.state);
        let parent = st.outcomes[of].as_ref().expect("deps done");
        let of_id = &self.graph.nodes[of].id;
        let Some(&digest) = parent.reports.get(report) else {
            let mut record = self.record(i, Status::Failed, String::new(), None);
            record.error = Some(format!("\"{of_id}\" made no report `{report}` (a bug)"));
            return Outcome {
                record,
                digest: None,
                reports: BTreeMap::new(),
                ran_upstream: parent.ran_upstream,
                snapshot: None,
            };
        };
        let status = match parent.record.status {
            Status::Ran => Status::Ran,
            _ => Status::Cached,
        };
        let key = parent.snapshot.as_ref().map(|p| {
            let mut h = blake3::Hasher::new();
            h.update(p.key.as_bytes());
            h.update(b"\0report\0");
            h.update(report.as_bytes());
            h.finalize().to_hex().to_string()
        });
        let snapshot = Snapshot {
            kind: node.kind.name.to_owned(),
            version: node.kind.version,
            site: node_site(&self.site, node).to_hex().to_string(),
            params: BTreeMap::new(),
            inputs: vec![(
                registry::Kind::REPORT_OF.to_owned(),
                vec![parent.digest.expect("deps ok").to_hex().to_string()],
            )],
            files: Vec::new(),
            key: key.unwrap_or_default(),
            digest: Some(digest.to_hex().to_string()),
        };
        Outcome {
            record: self.record(i, status, format!("report of \"{of_id}\""), Some(digest)),
            digest: Some(digest),
            reports: BTreeMap::new(),
            ran_upstream: parent.ran_upstream,
            snapshot: Some(snapshot),
        }
    }

    /// The artifact of finished node `d`: from memory, else from the store (verified). A missing or
    /// corrupt blob is rebuilt by running `d` again.
    fn artifact(&self, d: usize) -> Result<Arc<Artifact>, StageError> {
        let mut slot = lock(&self.slots[d]);
        if let Some(a) = slot.as_ref() {
            return Ok(a.clone());
        }
        let digest = lock(&self.state).outcomes[d]
            .as_ref()
            .and_then(|o| o.digest)
            .expect("input done");
        let problem = match self.cache.get_blob(&digest) {
            Ok(bytes) => match rmp_serde::from_slice::<Artifact>(&bytes) {
                Ok(a) => {
                    let a = Arc::new(a);
                    *slot = Some(a.clone());
                    return Ok(a);
                }
                Err(e) => format!("undecodable ({e})"),
            },
            Err(e) => e.to_string(),
        };
        let id = &self.graph.nodes[d].id;
        self.reporter.warn(&format!(
            "node \"{id}\": its stored output {} is {problem}; rebuilding",
            &digest.to_hex()[..12]
        ));
        let t0 = Instant::now();
        if let Some(report) = self.graph.nodes[d].kind.report {
            let a = self.rebuild_report(d, report, &digest, &problem)?;
            *slot = Some(a.clone());
            return Ok(a);
        }
        let ex = self.execute(d)?;
        if ex.digest != digest {
            self.reporter.warn(&format!("node \"{id}\": the rebuilt output differs from the recorded one; is its stage deterministic?"));
        }
        {
            let mut st = lock(&self.state);
            let o = st.outcomes[d].as_mut().expect("input done");
            o.digest = Some(ex.digest);
            o.reports = ex.reports;
            o.snapshot = Some(ex.snapshot);
            o.record.status = Status::Ran;
            o.record.reason = format!("stored output was {problem}; rebuilt");
            if let Some(why) = ex.rerun {
                o.record.reason = format!("{}; {why}", o.record.reason);
            }
            o.record.digest = Some(ex.digest.to_hex().to_string());
            o.record.ms += t0.elapsed().as_secs_f64() * 1e3;
        }
        *slot = Some(ex.artifact.clone());
        Ok(ex.artifact)
    }

    /// Report node `d`'s artifact, its stored blob being `problem`: its node runs again and the
    /// report it makes is read back.
    fn rebuild_report(
        &self,
        d: usize,
        report: &str,
        recorded: &Digest,
        problem: &str,
    ) -> Result<Arc<Artifact>, StageError> {
        let of = self.graph.nodes[d].inputs[0][0];
        let (id, of_id) = (&self.graph.nodes[d].id, &self.graph.nodes[of].id);
        let ex = self.execute(of)?;
        let digest = *ex.reports.get(report).ok_or_else(|| {
            StageError::Failed(format!("\"{of_id}\" made no report `{report}` (a bug)"))
        })?;
        if digest != *recorded {
            self.reporter.warn(&format!("node \"{id}\": the rebuilt report differs from the recorded one; is the stage of \"{of_id}\" deterministic?"));
        }
        let bytes = self.cache.get_blob(&digest).map_err(|e| {
            StageError::Failed(format!(
                "the rebuilt report of \"{of_id}\" cannot be read: {e}"
            ))
        })?;
        let a = rmp_serde::from_slice::<Artifact>(&bytes).map_err(|e| {
            StageError::Failed(format!(
                "the rebuilt report of \"{of_id}\" is undecodable: {e}"
            ))
        })?;
        let mut st = lock(&self.state);
        let o = st.outcomes[d].as_mut().expect("input done");
        o.digest = Some(digest);
        o.record.status = Status::Ran;
        o.record.reason = format!("stored report was {problem}; \"{of_id}\" ran again to make it");
        o.record.digest = Some(digest.to_hex().to_string());
        Ok(Arc::new(a))
    }

    /// Writes every declared output whose node succeeded into `dir`, each file atomically. An
    /// output whose files are still the ones written from the same digest (by the manifest in
    /// `dir`) is not written again, so a no-op rerun does not rewrite large exports. An output
    /// that cannot be written is reported by name and the others are still written.
    fn export(&self, dir: &Path) -> (BTreeMap<String, String>, BTreeMap<String, OutputError>) {
        let mut written = BTreeMap::new();
        let mut errors = BTreeMap::new();
        let wanted: Vec<(&String, usize)> = self
            .graph
            .outputs
            .iter()
            .filter(|(_, i)| self.need[*i])
            .map(|(n, i)| (n, *i))
            .collect();
        if wanted.is_empty() {
            return (written, errors);
        }
        if let Err(e) = std::fs::create_dir_all(dir) {
            for (name, _) in wanted {
                errors.insert(
                    name.clone(),
                    OutputError::io(format!("cannot create {}: {e}", dir.display())),
                );
            }
            return (written, errors);
        }
        remove_stale_temps(dir);
        let mut manifest = OutputManifest::load(dir);
        for (name, i) in wanted {
            let Some(digest) = lock(&self.state).outcomes[i]
                .as_ref()
                .and_then(|o| o.digest)
            else {
                continue;
            };
            if let Some(file) = manifest.unchanged(dir, name, &digest) {
                written.insert(name.clone(), dir.join(file).display().to_string());
                continue;
            }
            match self.export_one(dir, name, i, digest) {
                Ok((file_name, stamps, digest)) => {
                    manifest.record(name, &digest, &file_name, stamps);
                    written.insert(name.clone(), dir.join(&file_name).display().to_string());
                }
                Err(e) => {
                    manifest.outputs.remove(name);
                    errors.insert(name.clone(), e);
                }
            }
        }
        if let Err(e) = manifest.save(dir) {
            self.reporter.warn(&format!(
                "cannot write the output manifest in {}: {e}; the next run rewrites every output",
                dir.display()
            ));
        }
        (written, errors)
    }

    /// Encodes and writes output `name` of node `i`: its file name, the stamps of the files
    /// written, and the digest it was written from.
    fn export_one(
        &self,
        dir: &Path,
        name: &str,
        i: usize,
        digest: Digest,
    ) -> Result<(String, Vec<FileStamp>, Digest), OutputError> {
        let art = self
            .artifact(i)
            .map_err(|e| OutputError::io(e.to_string()))?;
        check_names(&art).map_err(OutputError::user)?;
        let (file_name, format) = output_file(name, art.ty()).map_err(OutputError::io)?;
        let node = &self.graph.nodes[i];
        let band = Band {
            unit: self.graph.raster_unit(i).map(str::to_owned),
            description: Some(format!("{} ({})", node.id, node.kind.name)),
        };
        let encoded = encode_with_band(&art, &self.graph.site, format, self.cache, &band)
            .map_err(OutputError::io)?;
        let path = dir.join(&file_name);
        let stamps = write_output(dir, &file_name, encoded)
            .map_err(|e| OutputError::io(format!("cannot write {}: {e}", path.display())))?;
        // The artifact may have been rebuilt while loading; record the digest it has now.
        let digest = lock(&self.state).outcomes[i]
            .as_ref()
            .and_then(|o| o.digest)
            .unwrap_or(digest);
        Ok((file_name, stamps, digest))
    }

    fn into_results(self) -> (Vec<NodeRecord>, Vec<(String, Snapshot)>) {
        let st = self.state.into_inner().unwrap_or_else(|p| p.into_inner());
        let mut records = Vec::new();
        let mut snapshots = Vec::new();
        for (i, o) in st.outcomes.into_iter().enumerate() {
            let Some(o) = o else { continue };
            if let Some(s) = o.snapshot {
                snapshots.push((self.graph.nodes[i].id.clone(), s));
            }
            records.push(o.record);
        }
        (records, snapshots)
    }
}

/// Why a declared output was not written.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct OutputError {
    /// What went wrong.
    pub error: String,
    /// True when the artifact's own content cannot be written (a view id that is not a file
    /// name): the CLI exits 2, not 1.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub user_error: bool,
}

impl OutputError {
    fn io(error: String) -> OutputError {
        OutputError {
            error,
            user_error: false,
        }
    }
    fn user(error: String) -> OutputError {
        OutputError {
            error,
            user_error: true,
        }
    }
}

/// `.kodama-outputs.json` in an output folder: which artifact digest each output was written
/// from, with every file it wrote (path relative to the folder, size, mtime and content digest
/// then). A file whose size and mtime still match is trusted; one whose mtime moved is hashed,
/// so a touched file is kept and a replaced or deleted one is written again.
#[derive(Default, serde::Serialize, serde::Deserialize)]
struct OutputManifest {
    version: u32,
    outputs: BTreeMap<String, ManifestEntry>,
}

const MANIFEST_VERSION: u32 = 2;

#[derive(serde::Serialize, serde::Deserialize)]
struct ManifestEntry {
    digest: String,
    /// The output as reported (a file, or a folder), relative to the output folder.
    file: String,
    /// Every file written for it.
    files: Vec<FileStamp>,
}

/// One file an output wrote, relative to the output folder.
#[derive(Clone, serde::Serialize, serde::Deserialize)]
struct FileStamp {
    path: String,
    size: u64,
    mtime_ns: u128,
    blake3: String,
}

const MANIFEST: &str = ".kodama-outputs.json";

fn size_and_mtime(path: &Path) -> Option<(u64, u128)> {
    let m = std::fs::symlink_metadata(path).ok()?;
    if !m.is_file() {
        return None;
    }
    let t = m
        .modified()
        .ok()?
        .duration_since(std::time::UNIX_EPOCH)
        .ok()?;
    Some((m.len(), t.as_nanos()))
}

impl FileStamp {
    /// Whether the file is still the one written; refreshes the mtime of a touched but
    /// unchanged file.
    fn verify(&mut self, dir: &Path) -> bool {
        // Only names the engine wrote are followed: a hand-edited manifest cannot point outside.
        if kodama_nodes::io::safe_name::check_relative_path(&self.path).is_err() {
            return false;
        }
        let path = dir.join(&self.path);
        let Some((size, mtime_ns)) = size_and_mtime(&path) else {
            return false;
        };
        if (size, mtime_ns) == (self.size, self.mtime_ns) {
            return true;
        }
        let same = size == self.size
            && crate::cache::hash_file(&path).is_ok_and(|d| d.to_hex().as_str() == self.blake3);
        if same {
            self.mtime_ns = mtime_ns;
        }
        same
    }
}

impl OutputManifest {
    fn load(dir: &Path) -> OutputManifest {
        std::fs::read(dir.join(MANIFEST))
            .ok()
            .and_then(|b| serde_json::from_slice::<OutputManifest>(&b).ok())
            .filter(|m| m.version == MANIFEST_VERSION)
            .unwrap_or_default()
    }
    /// The output's file name if every file it wrote from `digest` is still there unchanged.
    fn unchanged(&mut self, dir: &Path, name: &str, digest: &Digest) -> Option<String> {
        let e = self.outputs.get_mut(name)?;
        let same = e.digest == digest.to_hex().as_str()
            && !e.files.is_empty()
            && e.files.iter_mut().all(|f| f.verify(dir));
        same.then(|| e.file.clone())
    }
    fn record(&mut self, name: &str, digest: &Digest, file: &str, files: Vec<FileStamp>) {
        let entry = ManifestEntry {
            digest: digest.to_hex().to_string(),
            file: file.to_owned(),
            files,
        };
        self.outputs.insert(name.to_owned(), entry);
    }
    fn save(&mut self, dir: &Path) -> std::io::Result<()> {
        self.version = MANIFEST_VERSION;
        write_atomic(
            dir,
            &dir.join(MANIFEST),
            &serde_json::to_vec_pretty(self).expect("manifest serializes"),
        )
    }
}

/// Removes the temp files and folders (`.kodama-<pid>-...tmp`) that a killed process left in
/// `dir`. A temp of a process that still runs is left alone, as are temps younger than an hour
/// where there is no `/proc` to ask.
pub fn remove_stale_temps(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let have_proc = Path::new("/proc/self").exists();
    let me = std::process::id().to_string();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(rest) = name
            .to_str()
            .and_then(|n| n.strip_prefix(".kodama-"))
            .filter(|n| n.ends_with(".tmp"))
        else {
            continue;
        };
        let pid = rest.split('-').next().unwrap_or_default();
        if pid == me || pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        let dead = if have_proc {
            !Path::new("/proc").join(pid).exists()
        } else {
            entry
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age.as_secs() > 3600)
        };
        if dead {
            let p = entry.path();
            let _ = match entry.file_type() {
                Ok(t) if t.is_dir() => std::fs::remove_dir_all(&p),
                _ => std::fs::remove_file(&p),
            };
        }
    }
}

fn stamp(rel: String, path: &Path, bytes: &[u8]) -> std::io::Result<FileStamp> {
    let (size, mtime_ns) = size_and_mtime(path)
        .ok_or_else(|| std::io::Error::other(format!("{} vanished", path.display())))?;
    Ok(FileStamp {
        path: rel,
        size,
        mtime_ns,
        blake3: blake3::hash(bytes).to_hex().to_string(),
    })
}

/// Writes `encoded` as `file_name` in `dir` as a run writes its declared outputs (never half a
/// file or folder; an existing one of that name replaced); the paths written, relative to
/// `dir`. For writers outside a run: the Python package's `Run.export`.
pub fn write_encoded(
    dir: &Path,
    file_name: &str,
    encoded: Encoded,
) -> std::io::Result<Vec<String>> {
    Ok(write_output(dir, file_name, encoded)?
        .into_iter()
        .map(|s| s.path)
        .collect())
}

/// Puts the finished folder `tmp` at `path`, replacing whatever is there. Runs sharing an output
/// folder race here: each moves the old folder aside and renames its own in, and a rename that
/// finds another run's folder already back in place tries again, so every run ends with a whole
/// folder at `path`, its own or the other's (the same bytes: the same inputs give them).
fn replace_folder(tmp: &Path, path: &Path) -> std::io::Result<()> {
    use std::io::ErrorKind::{DirectoryNotEmpty, NotADirectory, NotFound};
    // A temp name too (`.kodama-<pid>-...tmp`), so a killed run's leftover is cleaned up.
    let old = tmp.with_extension("old.tmp");
    let mut last = None;
    for _ in 0..100 {
        let _ = std::fs::remove_dir_all(&old);
        let aside = match std::fs::symlink_metadata(path) {
            Ok(m) if m.is_dir() => std::fs::rename(path, &old),
            Ok(_) => std::fs::remove_file(path),
            Err(e) => Err(e),
        };
        match aside {
            Ok(()) => {}
            Err(e) if e.kind() == NotFound => {}
            Err(e) => return Err(e),
        }
        match std::fs::rename(tmp, path) {
            Ok(()) => {
                let _ = std::fs::remove_dir_all(&old);
                return Ok(());
            }
            Err(e) if matches!(e.kind(), DirectoryNotEmpty | NotADirectory) => last = Some(e),
            Err(e) => return Err(e),
        }
    }
    let _ = std::fs::remove_dir_all(tmp);
    Err(last.unwrap_or_else(|| std::io::Error::other("could not replace the folder")))
}

/// Writes an encoded output as `file_name` in `dir` so that it never exists half-written: a file
/// through a temp file and rename; a folder assembled under a hidden temp name, then renamed over
/// the old one. Returns the stamps of the files written.
fn write_output(dir: &Path, file_name: &str, encoded: Encoded) -> std::io::Result<Vec<FileStamp>> {
    let path = dir.join(file_name);
    match encoded {
        Encoded::File(bytes) => {
            write_atomic(dir, &path, &bytes)?;
            Ok(vec![stamp(file_name.to_owned(), &path, &bytes)?])
        }
        Encoded::Folder(files) => {
            // Named by pid first, as write_atomic's temps are, so a later run can tell whether
            // the process that left it is gone; then a number, for several writers in one.
            static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
            let n = WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let tmp = dir.join(format!(
                ".kodama-{}-{n}-{file_name}.tmp",
                std::process::id()
            ));
            let _ = std::fs::remove_dir_all(&tmp);
            for (rel, bytes) in &files {
                let f = tmp.join(rel);
                std::fs::create_dir_all(f.parent().unwrap_or(&tmp))?;
                std::fs::write(&f, bytes)?;
            }
            // Stamped before the rename (which keeps sizes and times): afterwards another run
            // may already have put its own copy there.
            let stamps = files
                .iter()
                .map(|(rel, bytes)| stamp(format!("{file_name}/{rel}"), &tmp.join(rel), bytes))
                .collect::<std::io::Result<Vec<_>>>()?;
            replace_folder(&tmp, &path)?;
            Ok(stamps)
        }
    }
}
