//! Run records (what happened to every node, and why) and last-run snapshots (what every node's
//! key was made of, so the next run can say which param or input changed).

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::cache::write_atomic;

/// What happened to a node in a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Its stage ran.
    Ran,
    /// Its output was in the cache and nothing upstream ran.
    Cached,
    /// Something upstream ran but reproduced its output, so this node's key was unchanged.
    Cutoff,
    /// Its stage failed.
    Failed,
    /// An input failed, so it was not run.
    Skipped,
}

/// One node's line in a run record.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct NodeRecord {
    /// Node id.
    pub id: String,
    /// Node kind.
    pub kind: String,
    /// What happened.
    pub status: Status,
    /// Why: which param or input changed, what failed, where the output came from.
    pub reason: String,
    /// Wall time spent on the node in this run, milliseconds.
    pub ms: f64,
    /// blake3 of the output artifact, if there is one.
    pub digest: Option<String>,
    /// The error, for failed nodes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// True when the failure is the user's input (data or params): the CLI exits 2, not 1.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub user_error: bool,
    /// What a raster output's values measure (`Graph::raster_unit`), for its GeoTIFF band.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}

/// The record of one run, as `--json` prints it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunRecord {
    /// The graph file as given.
    pub graph: String,
    /// Every node of the run, in topological order.
    pub nodes: Vec<NodeRecord>,
    /// Output name -> file written.
    pub outputs: BTreeMap<String, String>,
    /// Output name -> why it was not written; absent when every output was.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub output_errors: BTreeMap<String, crate::exec::OutputError>,
    /// Wall time of the whole run, seconds (0 in records written before it was kept).
    #[serde(default)]
    pub wall_s: f64,
    /// The process's peak resident memory when the run ended, MB (Linux's VmHWM): what `submit`
    /// sizes a Slurm job's `--mem` from. None where the OS does not say.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_rss_mb: Option<f64>,
}

/// The process's peak resident set so far, MB, from `/proc/self/status` (Linux); None elsewhere.
pub fn peak_rss_mb() -> Option<f64> {
    let status = fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// The run records of one graph kept in `dir` (a graph's folder under the cache's `runs/`),
/// newest first, at most `limit`; unreadable ones are passed over.
pub fn load_records(dir: &Path, limit: usize) -> Vec<RunRecord> {
    let mut names: Vec<_> = fs::read_dir(dir.join("records"))
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    names.sort();
    names
        .iter()
        .rev()
        .filter_map(|p| serde_json::from_slice(&fs::read(p).ok()?).ok())
        .take(limit)
        .collect()
}

/// What a node's action key was made of.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// Node kind.
    pub kind: String,
    /// Stage VERSION.
    pub version: u32,
    /// Digest of the site block.
    pub site: String,
    /// Param field -> JSON value.
    pub params: BTreeMap<String, String>,
    /// Input name -> digests of its upstream outputs.
    pub inputs: Vec<(String, Vec<String>)>,
    /// (params field, path as written, content digest) of each declared file.
    pub files: Vec<(String, String, String)>,
    /// The action key.
    pub key: String,
    /// The output digest, once known.
    pub digest: Option<String>,
}

/// Snapshots of every node of the last run of one graph.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct LastRun {
    /// Node id -> snapshot.
    pub nodes: BTreeMap<String, Snapshot>,
}

impl LastRun {
    /// Reads `dir/last.json`; a missing or unreadable one is an empty history.
    pub fn load(dir: &Path) -> LastRun {
        fs::read(dir.join("last.json"))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default()
    }

    /// Writes `dir/last.json` atomically.
    pub fn save(&self, dir: &Path, tmp: &Path) -> std::io::Result<()> {
        fs::create_dir_all(dir)?;
        write_atomic(
            tmp,
            &dir.join("last.json"),
            &serde_json::to_vec_pretty(self).expect("snapshots serialize"),
        )
    }
}

/// Keeps this many run records per graph.
const RECORDS_KEPT: usize = 50;

/// Saves `record` as `dir/records/<unix ms>-<pid>.json` and drops the oldest beyond the limit.
pub fn save_record(record: &RunRecord, dir: &Path, tmp: &Path) -> std::io::Result<()> {
    let records = dir.join("records");
    fs::create_dir_all(&records)?;
    let ms = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis())
        .unwrap_or(0);
    let name = format!("{ms:015}-{}.json", std::process::id());
    write_atomic(
        tmp,
        &records.join(name),
        &serde_json::to_vec_pretty(record).expect("records serialize"),
    )?;
    let mut names: Vec<_> = fs::read_dir(&records)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    names.sort();
    for old in names.iter().rev().skip(RECORDS_KEPT) {
        let _ = fs::remove_file(old);
    }
    Ok(())
}

/// Says what differs between this run's snapshot of a node and the last run's: the reason a node
/// that missed the cache had to run.
pub fn what_changed(now: &Snapshot, last: Option<&Snapshot>) -> String {
    let Some(last) = last else {
        return "new node (no earlier run of this graph with this cache)".into();
    };
    if now.kind != last.kind {
        return format!("kind changed from {}", last.kind);
    }
    let mut why = Vec::new();
    if now.version != last.version {
        why.push(format!(
            "{} VERSION {} -> {}",
            now.kind, last.version, now.version
        ));
    }
    if now.site != last.site {
        why.push("site changed".into());
    }
    let fields: std::collections::BTreeSet<&String> =
        now.params.keys().chain(last.params.keys()).collect();
    for f in fields {
        let (a, b) = (last.params.get(f), now.params.get(f));
        if a != b {
            let show = |v: Option<&String>| v.cloned().unwrap_or_else(|| "(none)".into());
            why.push(format!("param `{f}`: {} -> {}", show(a), show(b)));
        }
    }
    for (name, digests) in &now.inputs {
        match last.inputs.iter().find(|(n, _)| n == name) {
            Some((_, old)) if old == digests => {}
            Some(_) => why.push(format!("input `{name}` changed")),
            None => why.push(format!("input `{name}` is new")),
        }
    }
    for (field, path, digest) in &now.files {
        match last.files.iter().find(|(f, _, _)| f == field) {
            Some((_, p, _)) if p != path => why.push(format!("file `{field}` is now {path}")),
            Some((_, _, d)) if d != digest => why.push(format!("file `{field}` ({path}) changed")),
            _ => {}
        }
    }
    if why.is_empty() {
        return if now.key == last.key {
            "output not in the cache (first run with this cache, or evicted)".into()
        } else {
            "inputs changed".into()
        };
    }
    why.join("; ")
}
