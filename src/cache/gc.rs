//! Bounding the cache: evict least recently used artifacts down to a size.

use std::collections::BTreeSet;
use std::fs;
use std::io;
use std::path::PathBuf;
use std::time::SystemTime;

use super::{Cache, Digest, parse_action};

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
}

fn list(dir: &std::path::Path) -> io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for shard in fs::read_dir(dir)? {
        let shard = shard?.path();
        if shard.is_dir() {
            for f in fs::read_dir(&shard)? {
                out.push(f?.path());
            }
        }
    }
    Ok(out)
}

/// Evicts least recently used blobs until the store holds at most `max_bytes`, never one in
/// `keep`. Takes the cache's exclusive lock first, so it waits for running jobs and never removes
/// what a live run needs. Then drops action entries whose blob is gone and stale temp files.
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
    let mut blobs: Vec<(SystemTime, u64, PathBuf, bool)> = Vec::new();
    for p in list(&cache.root.join("cas"))? {
        let Ok(m) = fs::metadata(&p) else { continue };
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
    let mut report = GcReport {
        bytes_before: blobs.iter().map(|b| b.1).sum(),
        ..Default::default()
    };
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
    for p in list(&cache.root.join("ac"))? {
        let stale = match fs::read_to_string(&p).ok().and_then(|t| parse_action(&t)) {
            Some((d, size)) => !fs::metadata(cache.blob_path(&d)).is_ok_and(|m| m.len() == size),
            None => true,
        };
        if stale {
            fs::remove_file(&p)?;
            report.actions_removed += 1;
        }
    }
    // With the exclusive lock held no writer is active, so every temp file is a leftover.
    for f in fs::read_dir(cache.tmp())? {
        let _ = fs::remove_file(f?.path());
    }
    drop(lock);
    Ok(report)
}
