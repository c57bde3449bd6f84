//! Content digests of input files, behind a stat cache so unchanged files are not re-read.

use std::fs;
use std::io;
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use super::{Cache, Digest, write_atomic};

#[derive(Serialize, Deserialize)]
struct StatEntry {
    path: String,
    size: u64,
    mtime_ns: i128,
    inode: u64,
    checked_ns: i128,
    digest: String,
}

/// A file modified this close to when it was hashed may have changed again within the
/// filesystem's timestamp granularity without its mtime moving ("racy git"); such entries are
/// not trusted.
const RACY_NS: i128 = 2_000_000_000;

fn now_ns() -> i128 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as i128)
        .unwrap_or(0)
}

/// blake3 of a file's bytes, memory-mapped and hashed on all threads when large.
pub fn hash_file(path: &Path) -> io::Result<Digest> {
    let mut h = blake3::Hasher::new();
    h.update_mmap_rayon(path)?;
    Ok(h.finalize())
}

impl Cache {
    /// The content digest of the file at `path`, read only if its size, mtime or inode changed
    /// since it was last digested. A folder's digest covers the relative paths and digests of
    /// every file below it, in sorted order.
    pub fn file_digest(&self, path: &Path) -> io::Result<Digest> {
        if path.is_dir() {
            let mut files = folder_files(path, false)?;
            files.sort();
            let mut h = blake3::Hasher::new();
            h.update(b"kodama-dag folder 1\0");
            for (rel, full) in files {
                h.update(&(rel.len() as u64).to_le_bytes());
                h.update(rel.as_bytes());
                h.update(self.regular_file_digest(&full)?.as_bytes());
            }
            return Ok(h.finalize());
        }
        self.regular_file_digest(path)
    }

    fn regular_file_digest(&self, path: &Path) -> io::Result<Digest> {
        let abs = fs::canonicalize(path)?;
        let meta = fs::metadata(&abs)?;
        if !meta.is_file() {
            // Checked when the graph loaded, but it may have been replaced since: never read a
            // FIFO or device, which could block the run forever.
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "{} is {}, not a regular file",
                    path.display(),
                    describe_file_type(&meta.file_type())
                ),
            ));
        }
        let mtime_ns = meta.mtime() as i128 * 1_000_000_000 + meta.mtime_nsec() as i128;
        let name = blake3::hash(abs.as_os_str().as_encoded_bytes()).to_hex();
        let entry_path = self.root.join("stat").join(name.as_str());
        if let Ok(bytes) = fs::read(&entry_path)
            && let Ok(e) = serde_json::from_slice::<StatEntry>(&bytes)
        {
            let same = e.size == meta.len() && e.mtime_ns == mtime_ns && e.inode == meta.ino();
            if same
                && e.checked_ns - e.mtime_ns > RACY_NS
                && let Ok(d) = Digest::from_hex(&e.digest)
            {
                return Ok(d);
            }
        }
        let checked_ns = now_ns();
        let digest = hash_file(&abs)?;
        let entry = StatEntry {
            path: abs.to_string_lossy().into_owned(),
            size: meta.len(),
            mtime_ns,
            inode: meta.ino(),
            checked_ns,
            digest: digest.to_hex().to_string(),
        };
        // The stat cache is an optimisation: failing to record it must not fail the run.
        let _ = write_atomic(
            &self.tmp(),
            &entry_path,
            &serde_json::to_vec(&entry).expect("stat entry serializes"),
        );
        Ok(digest)
    }
}

/// What a file that is neither a regular file nor a folder is, for messages.
pub fn describe_file_type(t: &fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_symlink() {
        "a symlink"
    } else {
        "a special file"
    }
}

/// Checks that every entry below folder `root` is a regular file or a folder (symlinks followed),
/// reached once: no FIFO, socket or device, no symlink loop. With `contained`, no symlink may
/// lead out of `root`. Nothing is opened, so a FIFO cannot block.
pub fn check_folder(root: &Path, contained: bool) -> io::Result<()> {
    folder_files(root, contained).map(|_| ())
}

/// Every regular file below `root`, as (relative path with `/`, full path), after the checks of
/// [`check_folder`].
pub fn folder_files(root: &Path, contained: bool) -> io::Result<Vec<(String, std::path::PathBuf)>> {
    let canonical_root = fs::canonicalize(root)?;
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    let refuse = |p: &Path, what: String| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{}: {what}", p.display()),
        )
    };
    while let Some(dir) = stack.pop() {
        let meta = fs::metadata(&dir)?;
        // Each folder once, whatever symlinks lead to it: a loop cannot make the walk endless.
        if !seen.insert((meta.dev(), meta.ino())) {
            return Err(refuse(
                &dir,
                "a folder reached twice through symlinks (a loop?)".into(),
            ));
        }
        for entry in fs::read_dir(&dir)? {
            let entry = entry?;
            let p = entry.path();
            let mut t = entry.file_type()?;
            if t.is_symlink() {
                if contained && !fs::canonicalize(&p).is_ok_and(|c| c.starts_with(&canonical_root))
                {
                    return Err(refuse(
                        &p,
                        format!(
                            "a symlink leading outside {}; pass --allow-outside to follow it",
                            root.display()
                        ),
                    ));
                }
                t = fs::metadata(&p)
                    .map_err(|e| refuse(&p, format!("a broken symlink ({e})")))?
                    .file_type();
            }
            if t.is_dir() {
                stack.push(p);
            } else if t.is_file() {
                let rel = p
                    .strip_prefix(root)
                    .unwrap_or(&p)
                    .to_string_lossy()
                    .replace('\\', "/");
                out.push((rel, p));
            } else {
                return Err(refuse(
                    &p,
                    format!(
                        "{}, not a regular file; refused so that reading it cannot block",
                        describe_file_type(&t)
                    ),
                ));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn set_mtime(path: &Path, t: SystemTime) {
        fs::File::options()
            .write(true)
            .open(path)
            .unwrap()
            .set_modified(t)
            .unwrap();
    }

    #[test]
    fn changed_files_are_rehashed_and_settled_ones_trusted() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(&dir.path().join("cache")).unwrap();
        let f = dir.path().join("data.bin");
        let old = SystemTime::now() - Duration::from_secs(3600);
        fs::write(&f, b"first").unwrap();
        set_mtime(&f, old);
        let d1 = cache.file_digest(&f).unwrap();
        assert_eq!(d1, blake3::hash(b"first"));

        // Same size, different content, new mtime: seen.
        fs::write(&f, b"other").unwrap();
        let d2 = cache.file_digest(&f).unwrap();
        assert_eq!(d2, blake3::hash(b"other"));

        // Settle it (old mtime), record it, then change the bytes but restore size and mtime: the
        // stat cache answers without reading, which is exactly what it is for.
        set_mtime(&f, old);
        assert_eq!(cache.file_digest(&f).unwrap(), blake3::hash(b"other"));
        fs::write(&f, b"third").unwrap();
        set_mtime(&f, old);
        assert_eq!(
            cache.file_digest(&f).unwrap(),
            blake3::hash(b"other"),
            "trusted by stat"
        );
    }

    #[test]
    fn folders_digest_their_files_and_names() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(&dir.path().join("cache")).unwrap();
        let t = dir.path().join("tiles");
        fs::create_dir_all(t.join("sub")).unwrap();
        fs::write(t.join("tileset.json"), b"{}").unwrap();
        fs::write(t.join("sub/a.glb"), b"aaaa").unwrap();
        let d1 = cache.file_digest(&t).unwrap();
        assert_eq!(d1, cache.file_digest(&t).unwrap());
        fs::write(t.join("sub/a.glb"), b"aaab").unwrap();
        let d2 = cache.file_digest(&t).unwrap();
        assert_ne!(d1, d2, "content change");
        fs::rename(t.join("sub/a.glb"), t.join("sub/b.glb")).unwrap();
        assert_ne!(d2, cache.file_digest(&t).unwrap(), "rename");
    }

    #[test]
    fn a_file_modified_just_before_hashing_is_not_trusted() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(&dir.path().join("cache")).unwrap();
        let f = dir.path().join("data.bin");
        fs::write(&f, b"first").unwrap();
        cache.file_digest(&f).unwrap();
        // Rewritten within the same timestamp, same size: only the racy-window rule catches it.
        let m = fs::metadata(&f).unwrap().modified().unwrap();
        fs::write(&f, b"secnd").unwrap();
        set_mtime(&f, m);
        assert_eq!(cache.file_digest(&f).unwrap(), blake3::hash(b"secnd"));
    }
}
