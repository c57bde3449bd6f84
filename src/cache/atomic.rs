//! Atomic file creation: write a temp file, fsync it, rename it into place.

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `bytes` to `dest` so that `dest` never exists half-written: the bytes go to a uniquely
/// named file in `tmp_dir` (same filesystem), which is fsynced and renamed over `dest`.
///
/// For the kill-during-write test, `KODAMA_DAG_FAULT_SLOW_WRITE_MS` makes every write pause halfway
/// for that many milliseconds (fault injection; never set it otherwise).
pub fn write_atomic(tmp_dir: &Path, dest: &Path, bytes: &[u8]) -> io::Result<()> {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    // Hidden name: a temp file left by a killed process is not mistaken for an output.
    let tmp = tmp_dir.join(format!(
        ".kodama-{}-{n}-{nanos:08x}.tmp",
        std::process::id()
    ));
    let result = (|| {
        let mut f = File::create(&tmp)?;
        match slow_write_ms() {
            Some(ms) if bytes.len() > 1 => {
                let (a, b) = bytes.split_at(bytes.len() / 2);
                f.write_all(a)?;
                f.flush()?;
                std::thread::sleep(std::time::Duration::from_millis(ms));
                f.write_all(b)?;
            }
            _ => f.write_all(bytes)?,
        }
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, dest)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

fn slow_write_ms() -> Option<u64> {
    std::env::var("KODAMA_DAG_FAULT_SLOW_WRITE_MS")
        .ok()?
        .parse()
        .ok()
}
