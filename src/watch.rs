//! Watch mode: which paths a graph depends on, and waiting for one of them to change.
//!
//! The watcher follows the graph file and every file or folder its nodes declare, never the cache
//! or output folders (which a run itself writes). Events are debounced: an editor's save is often
//! several writes, and a batch of edits should cause one rerun.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::Duration;

use notify::{Event, EventKind, RecommendedWatcher, RecursiveMode, Watcher};

use crate::graph::Graph;

/// The graph file and every input it declares, absolute.
pub fn watched_paths(graph_file: &Path, graph: Option<&Graph>) -> Vec<PathBuf> {
    let mut out = vec![absolute(graph_file)];
    if let Some(g) = graph {
        for n in &g.nodes {
            for f in &n.files {
                out.push(absolute(&f.path));
            }
        }
    }
    out.sort();
    out.dedup();
    out
}

fn absolute(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| {
        std::env::current_dir()
            .map(|d| d.join(p))
            .unwrap_or_else(|_| p.to_path_buf())
    })
}

/// A notify watcher on the folders holding `paths` (files are watched through their folder, so
/// editors that replace a file by renaming still count), with the events it sends. A folder input
/// is watched inside and through its parent, so deleting and recreating it is seen; a path that
/// does not exist (an input deleted since) is watched through its nearest existing ancestor.
pub fn watcher(
    paths: &[PathBuf],
) -> notify::Result<(RecommendedWatcher, Receiver<notify::Result<Event>>)> {
    let (tx, rx) = std::sync::mpsc::channel();
    let mut w = notify::recommended_watcher(tx)?;
    let mut dirs: Vec<(PathBuf, RecursiveMode)> = Vec::new();
    for p in paths {
        if p.is_dir() {
            dirs.push((p.clone(), RecursiveMode::Recursive));
        }
        let mut parent = p.parent().map(Path::to_path_buf);
        while let Some(d) = parent.clone().filter(|d| !d.is_dir()) {
            parent = d.parent().map(Path::to_path_buf);
        }
        dirs.push((
            parent.unwrap_or_else(|| PathBuf::from(".")),
            RecursiveMode::NonRecursive,
        ));
    }
    dirs.sort();
    dirs.dedup();
    for (d, mode) in dirs {
        if d.exists() {
            w.watch(&d, mode)?;
        }
    }
    Ok((w, rx))
}

/// Whether `event` touches one of `paths` (or something inside a watched folder, or a folder on
/// the way to one, created or removed) and none of the `ignore` folders.
pub fn relevant(event: &Event, paths: &[PathBuf], ignore: &[PathBuf]) -> bool {
    if matches!(event.kind, EventKind::Access(_)) {
        return false;
    }
    let structural = matches!(event.kind, EventKind::Create(_) | EventKind::Remove(_))
        || matches!(
            event.kind,
            EventKind::Modify(notify::event::ModifyKind::Name(_))
        );
    event.paths.iter().any(|p| {
        !ignore.iter().any(|i| p.starts_with(i))
            && paths
                .iter()
                .any(|w| p == w || p.starts_with(w) || (structural && w.starts_with(p)))
    })
}

/// Blocks until a relevant change, then waits until `debounce` passes without another one.
/// Returns false when the watcher is gone.
pub fn wait_for_change(
    rx: &Receiver<notify::Result<Event>>,
    paths: &[PathBuf],
    ignore: &[PathBuf],
    debounce: Duration,
) -> bool {
    loop {
        match rx.recv() {
            Ok(Ok(e)) if relevant(&e, paths, ignore) => break,
            Ok(_) => continue,
            Err(_) => return false,
        }
    }
    loop {
        match rx.recv_timeout(debounce) {
            Ok(_) => continue,
            Err(RecvTimeoutError::Timeout) => return true,
            Err(RecvTimeoutError::Disconnected) => return false,
        }
    }
}
