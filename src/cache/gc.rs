//! Bounding the cache: evict least recently used artifacts down to a size.
//!
//! **Invariant:** gc deletes only files the engine names (`cas/<2 hex>/<64 hex>`,
//! `ac/<2 hex>/<64 hex>`, `tmp/.kodama-<pid>-<...>.tmp`), only in a folder that is a cache
//! ([`Cache::open_existing`]). Anything else found there is left alone and reported.

use std::collections::BTreeSet;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use super::{Cache, Digest, is_entry_name, is_shard_name, is_temp_name, parse_action};

/// What a gc did.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct GcReport {
    /// Bytes in the store before.
    pub bytes_before: u64,
    /// Bytes in the store after.
    pub bytes_after: u64,
    /// Blobs removed.
    pub blobs_removed: usize,
    /// Blobs kept because a kept graph needs them.
    pub blobs_pinned: usize,
    /// Action entries removed because their blob is gone.
    pub actions_removed: usize,
    /// Entries under `cas/`, `ac/` or `tmp/` that the engine did not name: left alone.
    pub foreign: Vec<PathBuf>,
}

/// The files under the sharded folder `dir` that the engine named; anything else goes to
/// `foreign`. Symlinks are neither followed nor removed.
fn list(dir: &Path, foreign: &mut Vec<PathBuf>) -> io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for shard in fs::read_dir(dir)? {
        let shard = shard?;
        let shard_name = shard.file_name();
        let shard_name = shard_name.to_str().unwrap_or_default();
        if !shard.file_type()?.is_dir() || !is_shard_name(shard_name) {
            foreign.push(shard.path());
            continue;
        }
        for f in fs::read_dir(shard.path())? {
            let f = f?;
            let named = f.file_type()?.is_file()
                && f.file_name()
                    .to_str()
                    .is_some_and(|n| is_entry_name(shard_name, n));
            if named {
                out.push(f.path());
            } else {
                foreign.push(f.path());
            }
        }
    }
    Ok(out)
}

/// Evicts least recently used blobs until the store holds at most `max_bytes`, never one in
/// `keep`. Takes the cache's exclusive lock first, so it waits for running jobs and never removes
/// what a live run needs. Then drops action entries whose blob is gone and stale temp files.
/// Open the cache with [`Cache::open_existing`]: gc must not adopt a folder that is not one.
pub fn gc(
    cache: &Cache,
    max_bytes: u64,
    keep: &BTreeSet<[u8; 32]>,
    on_wait: impl FnOnce(),
) -> io::Result<GcReport> {
    let lock = cache.lock_file()?;
    if lock.try_lock().is_err() {
        on_wait();
        lock.lock()?;
    }
    let mut report = GcReport::default();
    // A kept output keeps the parts it names (a view set's pixels) and its reports.
    let actions = list(&cache.root.join("ac"), &mut report.foreign)?;
    let mut keep = keep.clone();
    for p in &actions {
        if let Some(a) = fs::read_to_string(p).ok().and_then(|t| parse_action(&t))
            && keep.contains(a.output.0.as_bytes())
        {
            keep.extend(a.blobs().map(|(d, _)| *d.as_bytes()));
        }
    }
    let mut blobs: Vec<(SystemTime, u64, PathBuf, bool)> = Vec::new();
    for p in list(&cache.root.join("cas"), &mut report.foreign)? {
        let Ok(m) = fs::symlink_metadata(&p) else {
            continue;
        };
        let pinned = p
            .file_name()
            .and_then(|n| Digest::from_hex(n.to_string_lossy().as_ref()).ok())
            .is_some_and(|d| keep.contains(d.as_bytes()));
        blobs.push((
            m.modified().unwrap_or(SystemTime::UNIX_EPOCH),
            m.len(),
            p,
            pinned,
        ));
    }
    blobs.sort();
    report.bytes_before = blobs.iter().map(|b| b.1).sum();
    report.blobs_pinned = blobs.iter().filter(|b| b.3).count();
    let mut total = report.bytes_before;
    for (_, size, path, pinned) in &blobs {
        if total <= max_bytes {
            break;
        }
        if *pinned {
            continue;
        }
        fs::remove_file(path)?;
        total -= size;
        report.blobs_removed += 1;
    }
    report.bytes_after = total;
    for p in actions {
        let present = |(d, size): (Digest, u64)| {
            fs::metadata(cache.blob_path(&d)).is_ok_and(|m| m.len() == size)
        };
        let stale = match fs::read_to_string(&p).ok().and_then(|t| parse_action(&t)) {
            Some(a) => !a.blobs().all(present),
            None => true,
        };
        if stale {
            fs::remove_file(&p)?;
            report.actions_removed += 1;
        }
    }
    // With the exclusive lock held no writer is active, so every temp file is a leftover.
    for f in fs::read_dir(cache.tmp())? {
        let f = f?;
        let named = f.file_type()?.is_file() && f.file_name().to_str().is_some_and(is_temp_name);
        if named {
            let _ = fs::remove_file(f.path());
        } else {
            report.foreign.push(f.path());
        }
    }
    drop(lock);
    Ok(report)
}
