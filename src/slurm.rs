//! Runs on a Slurm cluster (`kodama-dag submit --engine slurm`): a graph or a sweep becomes a
//! short chain of batch jobs, each one ordinary `kodama-dag` process over the cache on the
//! cluster's shared filesystem. Results come back through the cache, so a job is idempotent and
//! a resubmission reruns only what the cache lacks.
//!
//! A sweep is a prefix job (the nodes every variant shares, so the variants' tasks find them
//! cached instead of racing to compute them), one job array over the variants the cache lacks,
//! and a table job (the whole sweep again, all hits, writing the table a local sweep writes).
//! A graph is one job. Jobs wait on each other with `--dependency=afterok` and
//! `--kill-on-invalid-dep=yes`, so a failed job cancels what waits on it rather than leaving it
//! pending forever. Slurm decides placement; kodama-dag only writes the chain, as scripts a user
//! can read, edit and submit by hand.
//!
//! State is read from `squeue --json -t all` (no `sacct`: it needs the accounting database, which
//! many clusters and every one-node test cluster lack), in Slurm 22.05's shape and in the shape
//! later releases give (`job_state` as a list, numbers as `{set, number}` objects).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::record::RunRecord;

/// The most tasks one job array holds: Slurm's default `MaxArraySize` is 1001 (indices 0-1000),
/// so larger sweeps are split into several arrays.
pub const ARRAY_CHUNK: usize = 1000;

/// One batch job of a plan.
#[derive(Clone, Debug)]
pub struct Job {
    /// Its name in the plan and its script's stem: `prefix`, `variants`, `table`, `run`.
    pub name: String,
    /// What it does, one line for the script's header.
    pub what: String,
    /// kodama-dag's arguments, each a shell word (quoted where it needs to be).
    pub args: Vec<String>,
    /// The array's task indices, for a job array.
    pub array: Option<Vec<usize>>,
    /// Jobs of the plan (indices) that must succeed before this one starts.
    pub after: Vec<usize>,
    /// What this job asks for, where it differs from the plan's (a tile job against the merge).
    pub resources: Option<Resources>,
}

/// A chain of jobs to submit.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The graph or sweep file (absolute), for the scripts' headers.
    pub file: PathBuf,
    /// Short name for job names: the file's stem.
    pub name: String,
    /// The jobs, each after the ones it depends on.
    pub jobs: Vec<Job>,
    /// What the plan left out and why (variants already cached, no shared prefix).
    pub notes: Vec<String>,
    /// The graph's folder under the cache's `runs/`, whose records size the jobs.
    pub runs_key: String,
}

/// What each job asks Slurm for.
#[derive(Clone, Debug, PartialEq)]
pub struct Resources {
    /// `--cpus-per-task`, also kodama-dag's `-j`.
    pub cpus: usize,
    /// `--mem`, MB; None leaves the cluster's default.
    pub mem_mb: Option<u64>,
    /// `--time`, minutes; None leaves the partition's default.
    pub time_min: Option<u64>,
    /// Where the figures came from, for the scripts' headers.
    pub basis: String,
}

/// Memory asked for above the largest peak measured: room for a run on other data.
pub const MEM_FACTOR: f64 = 1.5;
/// Time asked for above the longest run measured: a busy shared filesystem, a slower node.
pub const TIME_FACTOR: f64 = 3.0;
/// The least memory asked for, MB.
pub const MIN_MEM_MB: u64 = 1024;
/// The least time asked for, minutes: below it Slurm's own start-up dominates.
pub const MIN_TIME_MIN: u64 = 10;

/// The resources a job asks for, from measured runs of the same graph in the same cache: memory
/// `MEM_FACTOR` x the largest peak RSS and time `TIME_FACTOR` x the longest wall time among
/// `records` (at least `MIN_MEM_MB` and `MIN_TIME_MIN`). With no measured run it asks for
/// neither, leaving the cluster's defaults, and says so.
pub fn resources(records: &[RunRecord], cpus: usize) -> Resources {
    let peak = records
        .iter()
        .filter_map(|r| r.peak_rss_mb)
        .fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))));
    let wall = records
        .iter()
        .map(|r| r.wall_s)
        .filter(|w| *w > 0.0)
        .fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))));
    let mem_mb = peak.map(|p| ((p * MEM_FACTOR).ceil() as u64).max(MIN_MEM_MB));
    let time_min = wall.map(|w| ((w * TIME_FACTOR / 60.0).ceil() as u64).max(MIN_TIME_MIN));
    let basis = match (peak, wall) {
        (None, None) => "no run of this graph in this cache measured its time and memory: \
                         the cluster's defaults apply (pass --sbatch \"--mem=... --time=...\")"
            .to_string(),
        _ => format!(
            "from the last {} runs of this graph in this cache: peak RSS {}, longest wall {} \
             (asked: {MEM_FACTOR} x the peak, at least {MIN_MEM_MB} MB; {TIME_FACTOR} x the \
             wall, at least {MIN_TIME_MIN} min)",
            records.len(),
            peak.map_or("unknown".into(), |p| format!("{p:.0} MB")),
            wall.map_or("unknown".into(), |w| format!("{w:.1} s")),
        ),
    };
    Resources {
        cpus,
        mem_mb,
        time_min,
        basis,
    }
}

/// Sizes a tiled plan's jobs apart: the tile jobs (`--tile`) from the runs that made only tile
/// nodes, the others (prefix, gathers, merge) from the runs that made nodes made once. A class
/// with no measured run keeps the plan's request.
pub fn size_tile_jobs(plan: &mut Plan, records: &[RunRecord], cpus: usize) {
    let tile_run = |r: &RunRecord| {
        let mut ran = r
            .nodes
            .iter()
            .filter(|n| n.status == crate::record::Status::Ran)
            .peekable();
        ran.peek().is_some() && ran.all(|n| n.id.contains('@'))
    };
    let (tiles, once): (Vec<RunRecord>, Vec<RunRecord>) =
        records.iter().cloned().partition(|r| tile_run(r));
    for job in &mut plan.jobs {
        let class = if job.args.iter().any(|a| a == "--tile") {
            &tiles
        } else {
            &once
        };
        if !class.is_empty() {
            job.resources = Some(resources(class, cpus));
        }
    }
}

/// A word for a POSIX shell: single-quoted where it has to be (not `--mem=2G` or a plain path).
pub fn quote(word: &str) -> Result<String, String> {
    let plain = |c: char| c.is_ascii_alphanumeric() || "_@%+=:,./-".contains(c);
    if !word.is_empty() && word.chars().all(plain) {
        return Ok(word.to_string());
    }
    shlex::try_quote(word)
        .map(|w| w.into_owned())
        .map_err(|_| format!("{word:?} cannot be passed to a shell (it holds a NUL byte)"))
}

/// A path for a script: absolute and quoted.
pub fn quote_path(p: &Path) -> Result<String, String> {
    let abs = std::path::absolute(p).map_err(|e| format!("{}: {e}", p.display()))?;
    let text = abs.to_str().ok_or_else(|| {
        format!(
            "{}: not UTF-8, cannot be written in a job script",
            p.display()
        )
    })?;
    quote(text)
}

/// Task indices as Slurm's `--array` list: runs of consecutive indices as ranges (`0-3,7,9-10`).
pub fn array_spec(indices: &[usize]) -> String {
    let mut out = String::new();
    let mut i = 0;
    while i < indices.len() {
        let start = indices[i];
        let mut end = start;
        while i + 1 < indices.len() && indices[i + 1] == end + 1 {
            i += 1;
            end += 1;
        }
        if !out.is_empty() {
            out.push(',');
        }
        if end == start {
            let _ = write!(out, "{start}");
        } else {
            let _ = write!(out, "{start}-{end}");
        }
        i += 1;
    }
    out
}

/// The log file Slurm writes for a job (`%A_%a` for array tasks, `%j` otherwise).
fn log_pattern(job: &Job) -> String {
    if job.array.is_some() {
        format!("{}-%A_%a.out", job.name)
    } else {
        format!("{}-%j.out", job.name)
    }
}

/// The batch script of `job`: `#SBATCH` lines for its name, log, folder and resources, then
/// `exec` of kodama-dag, so the job's exit code is kodama-dag's (2 stays a user error).
pub fn script(
    plan: &Plan,
    job: &Job,
    exe: &Path,
    dir: &Path,
    cwd: &Path,
    res: &Resources,
) -> Result<String, String> {
    let mut s = String::from("#!/bin/bash\n");
    let _ = writeln!(s, "# kodama-dag submit: {}", job.what);
    let _ = writeln!(s, "# for {}", plan.file.display());
    let res = job.resources.as_ref().unwrap_or(res);
    let _ = writeln!(s, "# resources {}", res.basis);
    let _ = writeln!(s, "#SBATCH --job-name=kodama-{}-{}", plan.name, job.name);
    let _ = writeln!(
        s,
        "#SBATCH --output={}",
        dir.join(log_pattern(job)).display()
    );
    let _ = writeln!(s, "#SBATCH --chdir={}", cwd.display());
    let _ = writeln!(s, "#SBATCH --cpus-per-task={}", res.cpus);
    if let Some(m) = res.mem_mb {
        let _ = writeln!(s, "#SBATCH --mem={m}M");
    }
    if let Some(t) = res.time_min {
        let _ = writeln!(s, "#SBATCH --time={t}");
    }
    let _ = writeln!(
        s,
        "exec {} {} -j \"${{SLURM_CPUS_PER_TASK:-{}}}\"",
        quote_path(exe)?,
        job.args.join(" "),
        res.cpus
    );
    Ok(s)
}

/// sbatch's arguments for `job`, given the ids of the jobs submitted before it.
fn sbatch_args(
    job: &Job,
    ids: &[String],
    array_limit: Option<usize>,
    user: &[String],
) -> Vec<String> {
    let mut a = vec!["--parsable".to_string()];
    if !job.after.is_empty() {
        let deps: Vec<&str> = job.after.iter().map(|&j| ids[j].as_str()).collect();
        a.push(format!("--dependency=afterok:{}", deps.join(":")));
        a.push("--kill-on-invalid-dep=yes".into());
    }
    if let Some(tasks) = &job.array {
        let limit = array_limit.map(|k| format!("%{k}")).unwrap_or_default();
        a.push(format!("--array={}{limit}", array_spec(tasks)));
    }
    a.extend(user.iter().cloned());
    a
}

/// `submit.sh`: the sbatch commands of the plan as a script, for reading and for submitting the
/// same chain again by hand.
pub fn submit_script(
    plan: &Plan,
    array_limit: Option<usize>,
    user: &[String],
) -> Result<String, String> {
    let mut s = String::from(
        "#!/bin/sh\n# The jobs `kodama-dag submit` sent to Slurm; run this to send them again.\n\
         set -eu\ncd \"$(dirname \"$0\")\"\n",
    );
    let vars: Vec<String> = plan.jobs.iter().map(|j| j.name.replace('-', "_")).collect();
    let refs: Vec<String> = vars.iter().map(|v| format!("${{{v}%%;*}}")).collect();
    for (job, var) in plan.jobs.iter().zip(&vars) {
        let args = sbatch_args(job, &refs, array_limit, user)
            .iter()
            .map(|a| {
                if a.starts_with("--dependency=") {
                    Ok(a.clone())
                } else {
                    quote(a)
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let _ = writeln!(s, "{var}=$(sbatch {} {}.sh)", args.join(" "), job.name);
    }
    let all: Vec<String> = vars.iter().map(|v| format!("{v}=${v}")).collect();
    let _ = writeln!(s, "echo \"{}\"", all.join(" "));
    Ok(s)
}

/// Writes the plan's scripts into `dir`: one `NAME.sh` per job and `submit.sh`.
pub fn write_scripts(
    plan: &Plan,
    dir: &Path,
    exe: &Path,
    cwd: &Path,
    res: &Resources,
    array_limit: Option<usize>,
    user: &[String],
) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut files = Vec::new();
    for job in &plan.jobs {
        files.push((
            format!("{}.sh", job.name),
            script(plan, job, exe, dir, cwd, res)?,
        ));
    }
    files.push((
        "submit.sh".to_string(),
        submit_script(plan, array_limit, user)?,
    ));
    for (name, text) in files {
        let path = dir.join(&name);
        std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
        make_executable(&path);
    }
    Ok(())
}

#[cfg(unix)]
fn make_executable(path: &Path) {
    use std::os::unix::fs::PermissionsExt;
    let _ = std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755));
}

#[cfg(not(unix))]
fn make_executable(_: &Path) {}

/// A fresh folder for one submission's scripts and logs: `<base>/1`, `<base>/2`, ...
pub fn submission_dir(base: &Path) -> Result<PathBuf, String> {
    std::fs::create_dir_all(base).map_err(|e| format!("{}: {e}", base.display()))?;
    for n in 1..=100_000u32 {
        let dir = base.join(n.to_string());
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(format!("{}: {e}", dir.display())),
        }
    }
    Err(format!(
        "{}: 100000 submissions' folders already; remove old ones",
        base.display()
    ))
}

/// Submits the plan's jobs in order; their ids. A job sbatch refuses cancels the ones already
/// submitted, so no partial chain is left queued; the error is sbatch's own words.
pub fn submit(
    plan: &Plan,
    dir: &Path,
    array_limit: Option<usize>,
    user: &[String],
) -> Result<Vec<String>, String> {
    let mut ids: Vec<String> = Vec::new();
    for job in &plan.jobs {
        let args = sbatch_args(job, &ids, array_limit, user);
        let out = Command::new("sbatch")
            .args(&args)
            .arg(dir.join(format!("{}.sh", job.name)))
            .current_dir(dir)
            .output();
        let refused = match out {
            Err(e) => Some(format!(
                "cannot run sbatch ({e}): `submit --engine slurm` needs Slurm's client \
                 commands on PATH"
            )),
            Ok(o) if !o.status.success() => Some(format!(
                "sbatch refused {}.sh: {}",
                job.name,
                String::from_utf8_lossy(&o.stderr).trim()
            )),
            Ok(o) => {
                let text = String::from_utf8_lossy(&o.stdout);
                let id = text.trim().split(';').next().unwrap_or("").to_string();
                if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
                    Some(format!(
                        "sbatch gave no job id for {}.sh (it printed {:?})",
                        job.name,
                        text.trim()
                    ))
                } else {
                    ids.push(id);
                    None
                }
            }
        };
        if let Some(msg) = refused {
            cancel(&ids);
            return Err(msg);
        }
    }
    Ok(ids)
}

/// Cancels submitted jobs (best effort: they are what a failed submission leaves behind).
pub fn cancel(ids: &[String]) {
    if !ids.is_empty() {
        let _ = Command::new("scancel").args(ids).output();
    }
}

/// One entry of `squeue --json`: a job, an array task, or an array's not yet started remainder.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The job's own id.
    pub job_id: u64,
    /// The array's id for an array task (0 otherwise).
    pub array_job_id: u64,
    /// The task index, for a started array task.
    pub array_task_id: Option<u64>,
    /// COMPLETED, FAILED, PENDING, ...
    pub state: String,
    /// Why it is in that state (DependencyNeverSatisfied, NonZeroExitCode, ...).
    pub reason: String,
    /// The exit code of its script, when it ended by exiting.
    pub exit_code: Option<i32>,
}

/// A number as Slurm prints it: plain (22.05), or `{"set": true, "number": N}` (23.02 on).
fn number(v: &serde_json::Value) -> Option<u64> {
    match v {
        serde_json::Value::Number(n) => n.as_u64(),
        serde_json::Value::Object(o) => {
            if o.get("set").and_then(|s| s.as_bool()) == Some(false) {
                return None;
            }
            o.get("number").and_then(|n| n.as_u64())
        }
        _ => None,
    }
}

/// The entries of `squeue --json` output.
pub fn parse_squeue(text: &str) -> Result<Vec<Entry>, String> {
    let v: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("squeue --json gave no JSON: {e}"))?;
    let jobs = v
        .get("jobs")
        .and_then(|j| j.as_array())
        .ok_or("squeue --json gave no `jobs` list")?;
    let mut out = Vec::with_capacity(jobs.len());
    for j in jobs {
        let state = match j.get("job_state") {
            Some(serde_json::Value::String(s)) => s.clone(),
            Some(serde_json::Value::Array(a)) => a
                .iter()
                .filter_map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join(","),
            _ => String::new(),
        };
        // 22.05 gives the raw wait status (exit code x 256); later releases an object whose
        // `return_code` is the exit code itself.
        let exit_code = match j.get("exit_code") {
            Some(serde_json::Value::Number(n)) => n.as_i64().map(|w| {
                let w = w as i32;
                if w & 0x7f == 0 {
                    (w >> 8) & 0xff
                } else {
                    128 + (w & 0x7f)
                }
            }),
            Some(o @ serde_json::Value::Object(_)) => {
                o.get("return_code").and_then(number).map(|c| c as i32)
            }
            _ => None,
        };
        out.push(Entry {
            job_id: j.get("job_id").and_then(number).unwrap_or(0),
            array_job_id: j.get("array_job_id").and_then(number).unwrap_or(0),
            array_task_id: j.get("array_task_id").and_then(number),
            state,
            reason: j
                .get("state_reason")
                .and_then(|s| s.as_str())
                .unwrap_or("")
                .to_string(),
            exit_code,
        });
    }
    Ok(out)
}

/// States a job does not leave.
fn terminal(state: &str) -> bool {
    [
        "COMPLETED",
        "FAILED",
        "CANCELLED",
        "TIMEOUT",
        "OUT_OF_MEMORY",
        "NODE_FAIL",
        "PREEMPTED",
        "BOOT_FAIL",
        "DEADLINE",
    ]
    .iter()
    .any(|t| state.split(',').any(|s| s == *t))
}

/// How a submission ended.
#[derive(Clone, Debug, PartialEq)]
pub struct Ended {
    /// Every job and task that did not complete: (plan job name, task, entry).
    pub failed: Vec<(String, Option<u64>, Entry)>,
}

impl Ended {
    /// The exit code `submit --wait` gives: 0 when all completed, 2 when a job failed on the
    /// user's input (kodama-dag's exit 2 inside it), 1 otherwise.
    pub fn code(&self) -> u8 {
        if self.failed.is_empty() {
            0
        } else if self.failed.iter().any(|(_, _, e)| e.exit_code == Some(2)) {
            2
        } else {
            1
        }
    }
}

/// The entries of the plan's jobs, grouped by job (an array's tasks under it).
fn group<'a>(ids: &[String], entries: &'a [Entry]) -> Vec<Vec<&'a Entry>> {
    ids.iter()
        .map(|id| {
            let id: u64 = id.parse().unwrap_or(0);
            entries
                .iter()
                .filter(|e| e.job_id == id || (e.array_job_id == id && id != 0))
                .collect()
        })
        .collect()
}

/// Polls `squeue --json -t all --jobs=...` every `poll` until every job of the plan has ended,
/// telling `on_change` of each job whose states changed; how they ended.
pub fn wait(
    plan: &Plan,
    ids: &[String],
    poll: Duration,
    mut on_change: impl FnMut(&str),
) -> Result<Ended, String> {
    let mut last: BTreeMap<String, String> = BTreeMap::new();
    let mut unseen_polls = 0u32;
    loop {
        let out = Command::new("squeue")
            .args(["--json", "-t", "all"])
            .arg(format!("--jobs={}", ids.join(",")))
            .output()
            .map_err(|e| format!("cannot run squeue: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "squeue failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        let entries = parse_squeue(&String::from_utf8_lossy(&out.stdout))?;
        let groups = group(ids, &entries);
        for ((job, id), g) in plan.jobs.iter().zip(ids).zip(&groups) {
            let mut states: BTreeMap<&str, usize> = BTreeMap::new();
            for e in g {
                *states.entry(e.state.as_str()).or_default() += 1;
            }
            let text = states
                .iter()
                .map(|(s, n)| {
                    if *n > 1 {
                        format!("{n} {s}")
                    } else {
                        s.to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join(", ");
            if last.get(&job.name) != Some(&text) {
                on_change(&format!("{} (job {id}): {text}", job.name));
                last.insert(job.name.clone(), text);
            }
        }
        if groups.iter().any(|g| g.is_empty()) {
            // Slurm forgets finished jobs after MinJobAge; a job never listed at all is gone.
            unseen_polls += 1;
            if unseen_polls > 30 {
                return Err(
                    "a submitted job is no longer listed by squeue (finished longer ago than the \
                     cluster's MinJobAge?): see its log in the submission folder"
                        .into(),
                );
            }
        } else if groups.iter().flatten().all(|e| terminal(&e.state)) {
            let mut failed = Vec::new();
            for (job, g) in plan.jobs.iter().zip(&groups) {
                for e in g {
                    if e.state != "COMPLETED" {
                        failed.push((job.name.clone(), e.array_task_id, (*e).clone()));
                    }
                }
            }
            return Ok(Ended { failed });
        }
        std::thread::sleep(poll);
    }
}

/// The log Slurm wrote for a job of the plan (an array task's when `task` is given).
pub fn log_path(dir: &Path, job: &str, id: &str, task: Option<u64>) -> PathBuf {
    match task {
        Some(t) => dir.join(format!("{job}-{id}_{t}.out")),
        None => dir.join(format!("{job}-{id}.out")),
    }
}

/// The plan of a sweep: a prefix job over the nodes every variant shares (when some of them
/// are not cached), one job array per `ARRAY_CHUNK` variants over the variants whose nodes the
/// cache does not all hold, and the table job. `common` is kodama-dag's arguments every job
/// shares after `sweep SWEEP` (cache, output folder, data, overrides), already quoted.
pub fn plan_sweep(
    sweep: &crate::sweep::Sweep,
    opts: &crate::sweep::SweepOptions,
    cache: &crate::cache::Cache,
    common: &[String],
) -> Result<Plan, String> {
    use crate::explain::{Plan as Step, explain};
    use crate::sweep::{checked_graphs, shared_prefix, variant_targets};
    let variants = sweep.variants();
    let graphs = checked_graphs(sweep, opts, &variants).map_err(|e| e.to_string())?;
    let all_cached = |g: &crate::graph::Graph, targets: &[String]| -> Result<bool, String> {
        Ok(explain(g, cache, targets)
            .map_err(|e| e.to_string())?
            .iter()
            .all(|e| e.plan == Step::Cached))
    };
    let targets = variant_targets(sweep);
    let mut pending = Vec::new();
    for (i, g) in graphs.iter().enumerate() {
        if !all_cached(g, &targets)? {
            pending.push(i);
        }
    }
    let sweep_file = quote_path(&sweep.path)?;
    let base = |extra: &[&str]| -> Vec<String> {
        let mut a = vec!["sweep".to_string(), sweep_file.clone()];
        a.extend(common.iter().cloned());
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let mut plan = Plan {
        file: std::path::absolute(&sweep.path).unwrap_or_else(|_| sweep.path.clone()),
        name: sweep.name.clone(),
        jobs: Vec::new(),
        notes: Vec::new(),
        // Every variant is the one base graph file, so its runs are kept under one key.
        runs_key: crate::exec::graph_key(&graphs[0]),
    };
    let prefix = shared_prefix(sweep, &graphs);
    if prefix.is_empty() {
        plan.notes
            .push("no node is shared by every variant: no prefix job".into());
    } else if pending.is_empty() || all_cached(&graphs[0], &prefix)? {
        plan.notes.push(format!(
            "the {} nodes every variant shares are cached: no prefix job",
            prefix.len()
        ));
    } else {
        plan.jobs.push(Job {
            name: "prefix".into(),
            what: format!("the nodes every variant shares, up to {}", list(&prefix)),
            args: base(&["--prefix"]),
            array: None,
            after: vec![],
            resources: None,
        });
    }
    let cached = variants.len() - pending.len();
    if cached > 0 {
        plan.notes.push(format!(
            "{cached} of {} variants are in the cache already: not submitted",
            variants.len()
        ));
    }
    let prefix_job: Vec<usize> = (!plan.jobs.is_empty()).then_some(0).into_iter().collect();
    push_arrays(
        &mut plan,
        "variants",
        "one variant per array task (variant",
        &pending,
        &prefix_job,
        |task| base(&["--variant", task]),
    );
    plan.jobs.push(Job {
        name: "table".into(),
        what: "the sweep's table, every variant a cache hit by now".into(),
        args: base(&[]),
        array: None,
        after: (0..plan.jobs.len()).collect(),
        resources: None,
    });
    Ok(plan)
}

/// A tiled graph's radio work, partitioned by transmitter, not by tile: when it has two radio
/// nodes or more (`Graph::radio_nodes`: each RadioMap bounded by its transmitter's `reach_m`),
/// a gather job makes what they read (the merged scene and terrain, once), then a job array
/// makes one radio node per task (`--radio I`); the merge job after them finds them cached.
fn push_radio(
    plan: &mut Plan,
    graph: &crate::graph::Graph,
    held: &std::collections::HashSet<String>,
    last: &mut Vec<usize>,
    base: &dyn Fn(&[&str]) -> Vec<String>,
) -> Result<(), String> {
    let radio = graph.radio_nodes();
    if radio.len() < 2 {
        return Ok(());
    }
    let pending: Vec<usize> = (0..radio.len())
        .filter(|&k| !held.contains(&graph.nodes[radio[k]].id))
        .collect();
    if pending.is_empty() {
        plan.notes.push(format!(
            "radio: all {} radio nodes are in the cache already: not submitted",
            radio.len()
        ));
        return Ok(());
    }
    let mut inputs: Vec<usize> = pending
        .iter()
        .flat_map(|&k| graph.nodes[radio[k]].deps.iter().copied())
        .filter(|&d| !held.contains(&graph.nodes[d].id))
        .collect();
    inputs.sort_unstable();
    inputs.dedup();
    if !inputs.is_empty() {
        let ids: Vec<String> = inputs.iter().map(|&i| graph.nodes[i].id.clone()).collect();
        let words: Vec<String> = ids.iter().map(|id| quote(id)).collect::<Result<_, _>>()?;
        let targets: Vec<&str> = words
            .iter()
            .flat_map(|w| ["--target", w.as_str()])
            .collect();
        plan.jobs.push(Job {
            name: "gather-radio".into(),
            what: format!("what the radio tasks read, made once: {}", list(&ids)),
            args: base(&targets),
            array: None,
            after: last.clone(),
            resources: None,
        });
        *last = vec![plan.jobs.len() - 1];
    }
    let before = plan.jobs.len();
    push_arrays(
        plan,
        "radio",
        "one radio node per array task (radio node",
        &pending,
        last,
        |task| base(&["--radio", task]),
    );
    *last = (before..plan.jobs.len()).collect();
    Ok(())
}

/// Job arrays over `pending` task indices, [`ARRAY_CHUNK`] at most per array (`NAME`, or
/// `NAME-0`, `NAME-1`, ... when there are several), each after the jobs `after`; `args` makes a
/// task's kodama-dag arguments from the shell word of its index.
fn push_arrays(
    plan: &mut Plan,
    name: &str,
    what: &str,
    pending: &[usize],
    after: &[usize],
    args: impl Fn(&str) -> Vec<String>,
) {
    let chunks: Vec<Vec<usize>> = pending
        .chunk_by(|a, b| a / ARRAY_CHUNK == b / ARRAY_CHUNK)
        .map(<[usize]>::to_vec)
        .collect();
    for chunk in &chunks {
        let offset = chunk[0] / ARRAY_CHUNK * ARRAY_CHUNK;
        let (job_name, task) = if chunks.len() == 1 {
            (name.to_string(), "\"$SLURM_ARRAY_TASK_ID\"".to_string())
        } else {
            (
                format!("{name}-{}", offset / ARRAY_CHUNK),
                format!("\"$((SLURM_ARRAY_TASK_ID + {offset}))\""),
            )
        };
        let plus = if offset > 0 {
            format!(" + {offset}")
        } else {
            String::new()
        };
        plan.jobs.push(Job {
            name: job_name,
            what: format!("{what} = task index{plus})"),
            args: args(&task),
            array: Some(chunk.iter().map(|i| i - offset).collect()),
            after: after.to_vec(),
            resources: None,
        });
    }
}

/// Node ids for a script's header: the first eight, then how many more.
fn list(ids: &[String]) -> String {
    const SHOWN: usize = 8;
    let mut text = ids[..ids.len().min(SHOWN)].join(", ");
    if ids.len() > SHOWN {
        let _ = write!(text, " and {} more", ids.len() - SHOWN);
    }
    text
}

/// The plan of a graph: one job running it. `args` is kodama-dag's arguments after `run GRAPH`,
/// already quoted.
pub fn plan_graph(graph: &crate::graph::Graph, args: &[String]) -> Result<Plan, String> {
    if graph.tiling.is_some() {
        return Err("a tiled graph is planned by plan_tiled".into());
    }
    let mut a = vec!["run".to_string(), quote_path(&graph.path)?];
    a.extend(args.iter().cloned());
    Ok(Plan {
        file: std::path::absolute(&graph.path).unwrap_or_else(|_| graph.path.clone()),
        name: graph.name.clone(),
        jobs: vec![Job {
            name: "run".into(),
            what: "the graph, every node the cache lacks".into(),
            args: a,
            array: None,
            after: vec![],
            resources: None,
        }],
        notes: vec![],
        runs_key: crate::exec::graph_key(graph),
    })
}

/// A tiled graph's chain: a prefix job for the nodes made once that the tiles read (when the
/// cache lacks them), then per tile phase a job array with one tile per task (tiles the cache
/// holds whole are left out) and, between phases, a gather job for the merges the next phase
/// reads; last, one `run` of the whole graph: merges, what reads them, and the outputs. Every job
/// passes `args` (with the same `--tile-m`/`--halo-m`, so each expands the same tiles).
pub fn plan_tiled(
    graph: &crate::graph::Graph,
    cache: &crate::cache::Cache,
    args: &[String],
) -> Result<Plan, String> {
    use crate::explain::{Plan as Step, explain};
    let tiling = graph.tiling.as_ref().ok_or("the graph is not tiled")?;
    let graph_file = quote_path(&graph.path)?;
    let base = |extra: &[&str]| -> Vec<String> {
        let mut a = vec!["run".to_string(), graph_file.clone()];
        a.extend(args.iter().cloned());
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let ids = |nodes: &[usize]| -> Vec<String> {
        nodes.iter().map(|&i| graph.nodes[i].id.clone()).collect()
    };
    // One look at the cache for the whole graph: a node is cached only when all it needs is.
    let held: std::collections::HashSet<String> = explain(graph, cache, &[])
        .map_err(|e| e.to_string())?
        .into_iter()
        .filter(|e| e.plan == Step::Cached)
        .map(|e| e.id)
        .collect();
    let cached = |nodes: &[usize]| nodes.iter().all(|&i| held.contains(&graph.nodes[i].id));
    let mut plan = Plan {
        file: std::path::absolute(&graph.path).unwrap_or_else(|_| graph.path.clone()),
        name: graph.name.clone(),
        jobs: Vec::new(),
        notes: vec![format!(
            "{} tiles of {} m, halo {} m ({}), {} tile phase(s)",
            tiling.tiles.len(),
            tiling.tile_m,
            tiling.halo_m,
            tiling.halo_from,
            tiling.phases
        )],
        runs_key: crate::exec::graph_key(graph),
    };
    let mut last: Vec<usize> = Vec::new();
    for k in 0..=tiling.phases {
        // The nodes made once that phase k + 1's tiles read: the shared upstream (k = 0), or
        // the merges of phase k.
        let once = graph.tile_job(None, Some(k))?;
        if k < tiling.phases && !once.is_empty() && !cached(&once) {
            let (name, what) = if k == 0 {
                (
                    "prefix".to_string(),
                    format!(
                        "the nodes made once that the tiles read, up to {}",
                        list(&ids(&once))
                    ),
                )
            } else {
                (
                    format!("gather-{k}"),
                    format!(
                        "what phase {} reads of phase {k}'s merges, up to {}",
                        k + 1,
                        list(&ids(&once))
                    ),
                )
            };
            let phase = k.to_string();
            plan.jobs.push(Job {
                name,
                what,
                args: base(&["--phase", &phase]),
                array: None,
                after: last.clone(),
                resources: None,
            });
            last = vec![plan.jobs.len() - 1];
        }
        if k == tiling.phases {
            break;
        }
        let phase = (k + 1).to_string();
        let mut pending = Vec::new();
        for t in 0..tiling.tiles.len() {
            let nodes = graph.tile_job(Some(t), Some(k + 1))?;
            if !nodes.is_empty() && !cached(&nodes) {
                pending.push(t);
            }
        }
        let held = tiling.tiles.len() - pending.len();
        if held > 0 {
            plan.notes.push(format!(
                "phase {}: {held} of {} tiles are in the cache already: not submitted",
                k + 1,
                tiling.tiles.len()
            ));
        }
        let before = plan.jobs.len();
        let name = if tiling.phases == 1 {
            "tiles".to_string()
        } else {
            format!("tiles-{}", k + 1)
        };
        push_arrays(
            &mut plan,
            &name,
            "one tile per array task (tile",
            &pending,
            &last,
            |task| base(&["--tile", task, "--phase", &phase]),
        );
        if plan.jobs.len() > before {
            last = (before..plan.jobs.len()).collect();
        }
    }
    push_radio(&mut plan, graph, &held, &mut last, &base)?;
    plan.jobs.push(Job {
        name: "merge".into(),
        what: "the merges, what reads them and the outputs, every tile a cache hit by now".into(),
        args: base(&[]),
        array: None,
        after: last,
        resources: None,
    });
    Ok(plan)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_lists_are_ranges() {
        assert_eq!(array_spec(&[0, 1, 2, 3, 7, 9, 10]), "0-3,7,9-10");
        assert_eq!(array_spec(&[5]), "5");
        assert_eq!(array_spec(&[]), "");
    }

    #[test]
    fn squeue_of_both_releases_parses() {
        // Slurm 22.05: plain numbers, the raw wait status.
        let old = r#"{"jobs": [{"job_id": 4, "array_job_id": 1, "array_task_id": 1,
            "job_state": "FAILED", "state_reason": "NonZeroExitCode", "exit_code": 512}]}"#;
        let e = &parse_squeue(old).unwrap()[0];
        assert_eq!((e.job_id, e.array_job_id, e.array_task_id), (4, 1, Some(1)));
        assert_eq!((e.state.as_str(), e.exit_code), ("FAILED", Some(2)));
        // 23.02 on: states as lists, numbers as objects, the exit code itself.
        let new = r#"{"jobs": [{"job_id": 9, "array_job_id": {"set": true, "number": 0},
            "array_task_id": {"set": false, "number": 0}, "job_state": ["CANCELLED"],
            "state_reason": "DependencyNeverSatisfied",
            "exit_code": {"status": ["SUCCESS"], "return_code": {"set": true, "number": 0}}}]}"#;
        let e = &parse_squeue(new).unwrap()[0];
        assert_eq!((e.job_id, e.array_task_id), (9, None));
        assert_eq!((e.state.as_str(), e.exit_code), ("CANCELLED", Some(0)));
        assert!(parse_squeue("not json").is_err());
    }

    #[test]
    fn requests_follow_the_measured_runs() {
        let rec = |wall_s, peak| RunRecord {
            graph: "g.ron".into(),
            nodes: vec![],
            outputs: Default::default(),
            output_errors: Default::default(),
            wall_s,
            peak_rss_mb: peak,
        };
        let r = resources(&[rec(100.0, Some(3000.0)), rec(500.0, Some(1000.0))], 4);
        assert_eq!(r.mem_mb, Some(4500));
        assert_eq!(r.time_min, Some(25));
        let small = resources(&[rec(1.0, Some(10.0))], 1);
        assert_eq!(
            (small.mem_mb, small.time_min),
            (Some(MIN_MEM_MB), Some(MIN_TIME_MIN))
        );
        let none = resources(&[], 2);
        assert_eq!((none.mem_mb, none.time_min), (None, None));
        assert!(none.basis.contains("default"), "{}", none.basis);
    }

    #[test]
    fn tile_jobs_are_sized_from_tile_runs() {
        use crate::record::{NodeRecord, Status};
        let ran = |id: &str| NodeRecord {
            id: id.into(),
            kind: "K".into(),
            status: Status::Ran,
            reason: String::new(),
            ms: 1.0,
            digest: None,
            error: None,
            user_error: false,
            unit: None,
        };
        let rec = |ids: &[&str], wall_s, peak| RunRecord {
            graph: "g.ron".into(),
            nodes: ids.iter().map(|id| ran(id)).collect(),
            outputs: Default::default(),
            output_errors: Default::default(),
            wall_s,
            peak_rss_mb: Some(peak),
        };
        let records = [
            rec(&["city", "truth"], 1200.0, 2000.0),
            rec(&["lidar@x0y0", "solids@x0y0"], 20.0, 4000.0),
            rec(&["terrain2", "scene"], 30.0, 1000.0),
        ];
        let job = |name: &str, args: &[&str]| Job {
            name: name.into(),
            what: String::new(),
            args: args.iter().map(|a| a.to_string()).collect(),
            array: None,
            after: vec![],
            resources: None,
        };
        let mut plan = Plan {
            file: "g.ron".into(),
            name: "g".into(),
            jobs: vec![
                job("prefix", &["run", "g.ron", "--phase", "0"]),
                job(
                    "tiles",
                    &["run", "g.ron", "--tile", "\"$SLURM_ARRAY_TASK_ID\""],
                ),
                job("merge", &["run", "g.ron"]),
            ],
            notes: vec![],
            runs_key: String::new(),
        };
        size_tile_jobs(&mut plan, &records, 1);
        let asked: Vec<(Option<u64>, Option<u64>)> = plan
            .jobs
            .iter()
            .map(|j| {
                let r = j.resources.as_ref().unwrap();
                (r.mem_mb, r.time_min)
            })
            .collect();
        // Tiles: 1.5 x 4000 MB, at least 10 min; the others: 1.5 x 2000 MB, 3 x 1200 s.
        assert_eq!(asked[1], (Some(6000), Some(10)));
        assert_eq!(asked[0], (Some(3000), Some(60)));
        assert_eq!(asked[2], asked[0]);
    }
}
