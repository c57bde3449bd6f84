//! The on-disk cache: a content-addressed store of artifacts and an action cache mapping action
//! keys to artifact digests.
//!
//! Layout under the cache root (kept simple so a shared filesystem or a Remote Execution API
//! content store can stand in for it; blake3 is one of REAPI's digest functions):
//!
//! ```text
//! FORMAT                 layout version
//! lock                   runs hold it shared, gc exclusive
//! cas/<2 hex>/<64 hex>   artifact bytes, named by their blake3 digest
//! ac/<2 hex>/<64 hex>    "blake3:<digest hex> <size>\n" for an action key
//! stat/<64 hex>          stat cache of input files, by blake3 of the absolute path
//! runs/<graph>/...       last-run snapshots and run records
//! tmp/                   temp files; renamed into place when complete
//! ```
//!
//! **Invariant:** a file under `cas/`, `ac/` or `stat/` is only ever created by renaming a complete,
//! fsynced temp file, so a reader sees either nothing or the whole file, whatever was killed when.
//! A blob is verified against its name on every read; a bad one is a miss that rebuilds.

mod atomic;
mod files;
mod gc;

use std::fs::{self, File};
use std::io;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

pub use atomic::write_atomic;
pub use files::{InputStamp, check_folder, describe_file_type, folder_files, hash_file};
pub use gc::{GcReport, gc};

/// A blake3 digest (of artifact bytes, file contents, or an action).
pub type Digest = blake3::Hash;

const FORMAT: &str = "kodama-dag cache 1\n";

/// Why a blob could not be read.
#[derive(Debug)]
pub enum BlobError {
    /// Not in the store.
    Missing,
    /// Its bytes do not hash to its name.
    Corrupt,
    /// Reading failed.
    Io(io::Error),
}

impl std::fmt::Display for BlobError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BlobError::Missing => f.write_str("missing from the store"),
            BlobError::Corrupt => f.write_str("corrupt (its bytes do not match its digest)"),
            BlobError::Io(e) => write!(f, "unreadable: {e}"),
        }
    }
}

/// The bytes of a stored blob, mapped from its file.
pub enum Blob {
    /// A blob of no bytes (nothing to map).
    Empty,
    /// The file's pages.
    Mapped(memmap2::Mmap),
}

impl std::ops::Deref for Blob {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Blob::Empty => &[],
            Blob::Mapped(m) => m,
        }
    }
}

/// A cache directory.
pub struct Cache {
    root: PathBuf,
}

/// Digest of `bytes`, using all threads for large inputs.
pub fn digest_bytes(bytes: &[u8]) -> Digest {
    let mut h = blake3::Hasher::new();
    hash_into(&mut h, bytes);
    h.finalize()
}

/// Feeds `bytes` to `h`, on all threads from 1 MiB up (below, splitting costs more than it gains).
pub(crate) fn hash_into(h: &mut blake3::Hasher, bytes: &[u8]) {
    if bytes.len() >= 1 << 20 {
        h.update_rayon(bytes);
    } else {
        h.update(bytes);
    }
}

fn shard(dir: &Path, hex: &str) -> PathBuf {
    dir.join(&hex[..2]).join(hex)
}

impl Cache {
    /// Opens (creating if needed) the cache at `root`.
    pub fn open(root: &Path) -> io::Result<Cache> {
        for d in ["cas", "ac", "stat", "runs", "tmp"] {
            fs::create_dir_all(root.join(d))?;
        }
        let fmt = root.join("FORMAT");
        match fs::read_to_string(&fmt) {
            Ok(s) if s == FORMAT => {}
            Ok(s) => {
                return Err(io::Error::other(format!(
                    "{} is a cache of another format ({:?}); use another --cache or delete it",
                    root.display(),
                    s.trim()
                )));
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                write_atomic(&root.join("tmp"), &fmt, FORMAT.as_bytes())?;
            }
            Err(e) => return Err(e),
        }
        Ok(Cache {
            root: root.to_path_buf(),
        })
    }

    /// The cache root.
    pub fn root(&self) -> &Path {
        &self.root
    }

    pub(crate) fn tmp(&self) -> PathBuf {
        self.root.join("tmp")
    }

    /// A lock held for the duration of a run: any number of runs, but no gc, at a time.
    pub fn lock_shared(&self) -> io::Result<File> {
        let f = self.lock_file()?;
        f.lock_shared()?;
        Ok(f)
    }

    fn lock_file(&self) -> io::Result<File> {
        File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(self.root.join("lock"))
    }

    fn blob_path(&self, d: &Digest) -> PathBuf {
        shard(&self.root.join("cas"), &d.to_hex())
    }

    /// Stores what `write` writes as a blob, hashed as it is written (the encoding is never held
    /// in memory whole), and returns its digest and size. The temp file is fsynced and renamed
    /// into place, or removed if a blob of that digest is already stored or anything failed.
    pub fn put_blob_with(
        &self,
        write: impl FnOnce(&mut dyn io::Write) -> io::Result<()>,
    ) -> io::Result<(Digest, u64)> {
        let (tmp, file) = atomic::create_temp(&self.tmp())?;
        let result = (|| {
            let mut w = atomic::HashingWriter::new(file);
            write(&mut w)?;
            let (file, digest, size) = w.finish()?;
            drop(file);
            if self.has_blob(&digest, size) {
                fs::remove_file(&tmp)?;
                return Ok((digest, size));
            }
            let path = self.blob_path(&digest);
            fs::create_dir_all(path.parent().expect("sharded path has a parent"))?;
            fs::rename(&tmp, &path)?;
            Ok((digest, size))
        })();
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        result
    }

    /// True if a blob of `size` bytes is stored under `digest` (by stat, not by hashing); marks it
    /// recently used for gc.
    pub fn has_blob(&self, digest: &Digest, size: u64) -> bool {
        let path = self.blob_path(digest);
        match fs::metadata(&path) {
            Ok(m) if m.len() == size => {
                touch(&path);
                true
            }
            _ => false,
        }
    }

    /// Maps and verifies the blob `digest`: its bytes are the page cache's, never copied into
    /// this process, so a large artifact is held once (decoded), not twice.
    pub fn get_blob(&self, digest: &Digest) -> Result<Blob, BlobError> {
        let path = self.blob_path(digest);
        let file = match File::open(&path) {
            Ok(f) => f,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Err(BlobError::Missing),
            Err(e) => return Err(BlobError::Io(e)),
        };
        let len = file.metadata().map_err(BlobError::Io)?.len();
        let blob = if len == 0 {
            Blob::Empty
        } else {
            // SAFETY: a blob file is never written after it is renamed into place (writers rename
            // complete temp files; gc unlinks, which leaves a mapping intact), so the mapped bytes
            // cannot change under the reader. Only a process outside kodama-dag truncating a
            // file inside the cache could fault it.
            Blob::Mapped(unsafe { memmap2::Mmap::map(&file) }.map_err(BlobError::Io)?)
        };
        if digest_bytes(&blob) != *digest {
            // Remove it, or the rebuilt blob would be taken for already stored (same name, same
            // size) and the bad bytes would stay.
            drop(blob);
            let _ = fs::remove_file(&path);
            return Err(BlobError::Corrupt);
        }
        touch(&path);
        Ok(blob)
    }

    /// The artifact digest and size recorded for action `key`, if any.
    pub fn get_action(&self, key: &Digest) -> Option<(Digest, u64)> {
        parse_action(&fs::read_to_string(shard(&self.root.join("ac"), &key.to_hex())).ok()?)
    }

    /// Records that action `key` produced the blob `digest` of `size` bytes.
    pub fn put_action(&self, key: &Digest, digest: &Digest, size: u64) -> io::Result<()> {
        let path = shard(&self.root.join("ac"), &key.to_hex());
        fs::create_dir_all(path.parent().expect("sharded path has a parent"))?;
        write_atomic(
            &self.tmp(),
            &path,
            format!("blake3:{} {size}\n", digest.to_hex()).as_bytes(),
        )
    }

    /// The folder for run records and last-run snapshots of one graph.
    pub fn runs_dir(&self, graph_key: &str) -> PathBuf {
        self.root.join("runs").join(graph_key)
    }
}

/// Parses an action entry `blake3:<hex> <size>`.
fn parse_action(text: &str) -> Option<(Digest, u64)> {
    let (d, size) = text.trim().strip_prefix("blake3:")?.split_once(' ')?;
    Some((Digest::from_hex(d).ok()?, size.parse().ok()?))
}

/// Marks a file as recently used (its mtime is the LRU clock gc reads). Best effort: a read-only
/// cache still works, it just ages by write time.
fn touch(path: &Path) {
    if let Ok(f) = File::options().write(true).open(path) {
        let _ = f.set_modified(SystemTime::now());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes of every size (headers of a few bytes, arrays across the buffer's edge, arrays
    /// larger than the buffer) store exactly the bytes written, under the digest of the whole.
    #[test]
    fn a_streamed_blob_is_its_bytes_under_their_digest() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(dir.path()).unwrap();
        let big = atomic::HashingWriter::BUF;
        let pieces: Vec<Vec<u8>> = [3, 1 << 20, big - 5, 7, big + 11, 2 * big + 1, 0, 1]
            .iter()
            .enumerate()
            .map(|(k, &n)| (0..n).map(|i| (i * 31 + k * 7) as u8).collect())
            .collect();
        let whole: Vec<u8> = pieces.concat();
        let (digest, size) = cache
            .put_blob_with(|w| {
                for p in &pieces {
                    w.write_all(p)?;
                }
                Ok(())
            })
            .unwrap();
        assert_eq!(digest, blake3::hash(&whole));
        assert_eq!(size, whole.len() as u64);
        assert_eq!(&*cache.get_blob(&digest).unwrap(), &whole[..]);
        // The same bytes again: stored once, no temp file left behind.
        let again = cache.put_blob_with(|w| w.write_all(&whole)).unwrap();
        assert_eq!(again, (digest, size));
        assert_eq!(fs::read_dir(cache.tmp()).unwrap().count(), 0);
        // An empty blob maps to nothing and still verifies.
        let (empty, _) = cache.put_blob_with(|_| Ok(())).unwrap();
        assert!(cache.get_blob(&empty).unwrap().is_empty());
    }

    /// A failing writer leaves neither a blob nor a temp file.
    #[test]
    fn a_failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(dir.path()).unwrap();
        let r = cache.put_blob_with(|w| {
            w.write_all(&[1u8; 100])?;
            Err(io::Error::other("no space left"))
        });
        assert!(r.is_err());
        assert_eq!(fs::read_dir(cache.tmp()).unwrap().count(), 0);
        assert!(
            !dir.path().join("cas").exists()
                || fs::read_dir(dir.path().join("cas")).unwrap().count() == 0
        );
    }
}
