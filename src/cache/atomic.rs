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
    let (tmp, mut f) = create_temp(tmp_dir)?;
    let result = (|| {
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

/// A temp file in `tmp_dir` that [`HashingWriter`] fills and the caller renames into place, or
/// removes on failure.
pub(crate) fn create_temp(tmp_dir: &Path) -> io::Result<(std::path::PathBuf, File)> {
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
    let f = File::create(&tmp)?;
    Ok((tmp, f))
}

/// Writes to a file and hashes what it writes (blake3), through a buffer of [`HashingWriter::BUF`]
/// bytes; larger writes (an artifact's dense arrays) go straight through. What it hashes is exactly
/// what the file receives, in order, so the digest is the file's.
pub(crate) struct HashingWriter {
    file: File,
    hasher: blake3::Hasher,
    buf: Vec<u8>,
    size: u64,
}

impl HashingWriter {
    pub(crate) const BUF: usize = 8 << 20;

    pub(crate) fn new(file: File) -> HashingWriter {
        HashingWriter {
            file,
            hasher: blake3::Hasher::new(),
            buf: Vec::with_capacity(Self::BUF),
            size: 0,
        }
    }

    fn pass(&mut self, bytes: &[u8]) -> io::Result<()> {
        super::hash_into(&mut self.hasher, bytes);
        self.size += bytes.len() as u64;
        self.file.write_all(bytes)
    }

    fn drain(&mut self) -> io::Result<()> {
        let buf = std::mem::take(&mut self.buf);
        let r = self.pass(&buf);
        self.buf = buf;
        self.buf.clear();
        r
    }

    /// Writes what is buffered, fsyncs, and returns the file, the digest and the size.
    /// `KODAMA_DAG_FAULT_SLOW_WRITE_MS` pauses halfway through the last write, as
    /// [`write_atomic`] does.
    pub(crate) fn finish(mut self) -> io::Result<(File, blake3::Hash, u64)> {
        if let Some(ms) = slow_write_ms() {
            let rest = std::mem::take(&mut self.buf);
            let (a, b) = rest.split_at(rest.len() / 2);
            self.pass(a)?;
            self.file.flush()?;
            std::thread::sleep(std::time::Duration::from_millis(ms));
            self.pass(b)?;
        } else {
            self.drain()?;
        }
        self.file.sync_all()?;
        Ok((self.file, self.hasher.finalize(), self.size))
    }
}

impl Write for HashingWriter {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        if self.buf.len() + bytes.len() > Self::BUF {
            self.drain()?;
        }
        if bytes.len() >= Self::BUF {
            self.pass(bytes)?;
        } else {
            self.buf.extend_from_slice(bytes);
        }
        Ok(bytes.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

fn slow_write_ms() -> Option<u64> {
    std::env::var("KODAMA_DAG_FAULT_SLOW_WRITE_MS")
        .ok()?
        .parse()
        .ok()
}
