//! Content digests of input files, behind a stat cache so unchanged files are not re-read.

use std::fs;
use std::io;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
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

/// What one `stat` says about a file: what the stat cache and the post-run re-check compare.
/// The stat cache keys on size, mtime and inode; the re-check also compares the device and the
/// ctime, which no tool can set back (an editor, `touch -d` or `rsync -t` can restore an mtime).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct FileStat {
    size: u64,
    mtime_ns: i128,
    inode: u64,
    dev: u64,
    ctime_ns: i128,
}

impl FileStat {
    fn of(meta: &fs::Metadata) -> FileStat {
        FileStat {
            size: meta.len(),
            mtime_ns: meta.mtime() as i128 * 1_000_000_000 + meta.mtime_nsec() as i128,
            inode: meta.ino(),
            dev: meta.dev(),
            ctime_ns: meta.ctime() as i128 * 1_000_000_000 + meta.ctime_nsec() as i128,
        }
    }
}

/// One regular file as it was when it was digested.
#[derive(Clone, Debug)]
struct FileSeen {
    /// Relative path with `/` inside a folder input; empty for a file input.
    rel: String,
    /// The canonical path that was read.
    abs: PathBuf,
    /// Its stat, taken before its bytes were hashed.
    stat: FileStat,
    /// When that stat was taken (or, for a stat-cache hit, when the entry was checked).
    checked_ns: i128,
    digest: Digest,
}

/// How a declared input (a file, or a folder: every file's relative path and content) looked
/// when it was digested, so that after a stage has read it the engine can tell whether it is
/// still what its digest says ([`InputStamp::moved`]).
#[derive(Clone, Debug)]
pub struct InputStamp {
    /// The path as declared.
    path: PathBuf,
    /// A folder input (else a file input).
    folder: bool,
    /// Its files, sorted by relative path.
    files: Vec<FileSeen>,
    /// The folders below it that were left out (kodama-dag's own: [`folder_files`]).
    skip: Vec<PathBuf>,
}

impl InputStamp {
    /// `None` if the input is still what was digested, else what moved. Every file is compared by
    /// stat (size, mtime, inode, device, ctime), and a folder's file list by relative path;
    /// where the stat is equal that is enough, except for a file whose mtime was within the
    /// racy window ([`RACY_NS`]) of its stat: it may have been rewritten within the filesystem's
    /// timestamp granularity, so it is hashed again.
    pub fn moved(&self) -> Option<String> {
        let shown = self.path.display();
        if self.folder {
            let mut now = match folder_files(&self.path, false, &self.skip) {
                Ok(f) => f,
                Err(e) => return Some(format!("{shown} can no longer be read ({e})")),
            };
            now.sort();
            let before: Vec<&str> = self.files.iter().map(|f| f.rel.as_str()).collect();
            let after: Vec<&str> = now.iter().map(|(rel, _)| rel.as_str()).collect();
            if before != after {
                let added = after.iter().find(|r| !before.contains(r));
                let removed = before.iter().find(|r| !after.contains(r));
                return Some(match (added, removed) {
                    (Some(a), _) => format!("{shown}: `{a}` appeared"),
                    (None, Some(r)) => format!("{shown}: `{r}` disappeared"),
                    (None, None) => format!("{shown}: its file list changed"),
                });
            }
            for (seen, (_, full)) in self.files.iter().zip(&now) {
                if let Some(why) = seen.moved(full) {
                    return Some(format!("{shown}: `{}` {why}", seen.rel));
                }
            }
            return None;
        }
        let seen = self.files.first()?;
        seen.moved(&self.path).map(|why| format!("{shown} {why}"))
    }
}

impl FileSeen {
    fn moved(&self, path: &Path) -> Option<String> {
        let (abs, meta) = match fs::canonicalize(path).and_then(|a| Ok((fs::metadata(&a)?, a))) {
            Ok((meta, abs)) => (abs, meta),
            Err(e) => return Some(format!("can no longer be read ({e})")),
        };
        if abs != self.abs {
            return Some(format!("now leads to {}", abs.display()));
        }
        let stat = FileStat::of(&meta);
        if stat != self.stat {
            return Some(if stat.size != self.stat.size {
                format!("changed size ({} -> {} bytes)", self.stat.size, stat.size)
            } else if stat.inode != self.stat.inode || stat.dev != self.stat.dev {
                "was replaced (another inode)".to_owned()
            } else {
                "was modified".to_owned()
            });
        }
        if self.checked_ns - self.stat.mtime_ns > RACY_NS {
            return None;
        }
        match hash_file(&abs) {
            Ok(d) if d == self.digest => None,
            Ok(_) => Some("was modified (same size and time, other bytes)".to_owned()),
            Err(e) => Some(format!("can no longer be read ({e})")),
        }
    }
}

impl Cache {
    /// Tells the cache that runs through it write their outputs to `dir`, which folder inputs'
    /// digests then leave out ([`folder_files`]), whether or not it exists yet.
    pub fn writes_outputs_to(&mut self, dir: &Path) {
        let c = canonical_to_be(dir);
        if !self.own_folders.contains(&c) {
            self.own_folders.push(c);
        }
    }

    /// The content digest of the file at `path`, read only if its size, mtime or inode changed
    /// since it was last digested. A folder's digest covers the relative paths and digests of
    /// every file below it, in sorted order.
    pub fn file_digest(&self, path: &Path) -> io::Result<Digest> {
        self.file_digest_stamped(path).map(|(d, _)| d)
    }

    /// [`Cache::file_digest`], with the stamp that tells later whether the input moved since.
    pub fn file_digest_stamped(&self, path: &Path) -> io::Result<(Digest, InputStamp)> {
        if path.is_dir() {
            let skip = self.own_folders.clone();
            let mut files = folder_files(path, false, &skip)?;
            files.sort();
            let mut h = blake3::Hasher::new();
            h.update(b"kodama-dag folder 1\0");
            let mut seen = Vec::with_capacity(files.len());
            for (rel, full) in files {
                h.update(&(rel.len() as u64).to_le_bytes());
                h.update(rel.as_bytes());
                let mut file = self.regular_file_digest(&full)?;
                h.update(file.digest.as_bytes());
                file.rel = rel;
                seen.push(file);
            }
            let stamp = InputStamp {
                path: path.to_path_buf(),
                folder: true,
                files: seen,
                skip,
            };
            return Ok((h.finalize(), stamp));
        }
        let file = self.regular_file_digest(path)?;
        let stamp = InputStamp {
            path: path.to_path_buf(),
            folder: false,
            files: vec![file],
            skip: Vec::new(),
        };
        Ok((stamp.files[0].digest, stamp))
    }

    fn regular_file_digest(&self, path: &Path) -> io::Result<FileSeen> {
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
        let stat = FileStat::of(&meta);
        let name = blake3::hash(abs.as_os_str().as_encoded_bytes()).to_hex();
        let entry_path = self.root.join("stat").join(name.as_str());
        if let Ok(bytes) = fs::read(&entry_path)
            && let Ok(e) = serde_json::from_slice::<StatEntry>(&bytes)
        {
            let same = e.size == stat.size && e.mtime_ns == stat.mtime_ns && e.inode == stat.inode;
            if same
                && e.checked_ns - e.mtime_ns > RACY_NS
                && let Ok(digest) = Digest::from_hex(&e.digest)
            {
                return Ok(FileSeen {
                    rel: String::new(),
                    abs,
                    stat,
                    checked_ns: e.checked_ns,
                    digest,
                });
            }
        }
        let checked_ns = now_ns();
        let digest = hash_file(&abs)?;
        let entry = StatEntry {
            path: abs.to_string_lossy().into_owned(),
            size: stat.size,
            mtime_ns: stat.mtime_ns,
            inode: stat.inode,
            checked_ns,
            digest: digest.to_hex().to_string(),
        };
        // The stat cache is an optimisation: failing to record it must not fail the run.
        let _ = write_atomic(
            &self.tmp(),
            &entry_path,
            &serde_json::to_vec(&entry).expect("stat entry serializes"),
        );
        Ok(FileSeen {
            rel: String::new(),
            abs,
            stat,
            checked_ns,
            digest,
        })
    }
}

pub use kodama_nodes::io::open::describe_file_type;

/// The canonical path `path` has, or will have once made: its nearest existing ancestor
/// canonicalized, the rest appended.
fn canonical_to_be(path: &Path) -> PathBuf {
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut rest = Vec::new();
    let mut at = abs.as_path();
    loop {
        if let Ok(c) = fs::canonicalize(at) {
            return rest.iter().rev().fold(c, |p, part| p.join(part));
        }
        match (at.parent(), at.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                at = parent;
            }
            _ => return abs,
        }
    }
}

/// Checks that every entry below folder `root` is a regular file or a folder (symlinks followed),
/// reached once: no FIFO, socket or device, no symlink loop. With `contained`, no symlink may
/// lead out of `root`. Nothing is opened, so a FIFO cannot block.
pub fn check_folder(root: &Path, contained: bool) -> io::Result<()> {
    folder_files(root, contained, &[]).map(|_| ())
}

/// Every regular file below `root`, as (relative path with `/`, full path), after the checks of
/// [`check_folder`]. Folders below `root` that kodama-dag itself writes are left out: a cache
/// (found by its FORMAT marker) and the folders in `skip` (canonical: a run's output folder).
/// A run writes into them while it reads the input, so counting them would give the input a
/// new digest at every run (`watch` would rerun itself forever, and concurrent runs would see
/// their input move); no stage reads its inputs from there.
pub fn folder_files(
    root: &Path,
    contained: bool,
    skip: &[PathBuf],
) -> io::Result<Vec<(String, std::path::PathBuf)>> {
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
                if Cache::is_cache_folder(&p)
                    || (!skip.is_empty() && fs::canonicalize(&p).is_ok_and(|c| skip.contains(&c)))
                {
                    continue;
                }
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

    /// The post-run re-check: a file input whose bytes were swapped after it was digested is
    /// seen as moved, even when the swap was undone (an edit, then an undo).
    #[test]
    fn a_file_input_that_moved_after_its_digest_is_seen() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(&dir.path().join("cache")).unwrap();
        let f = dir.path().join("points.xyz");
        fs::write(&f, b"1 2 3\n").unwrap();
        let (d, stamp) = cache.file_digest_stamped(&f).unwrap();
        assert_eq!(d, blake3::hash(b"1 2 3\n"));
        assert_eq!(stamp.moved(), None, "nothing happened");

        fs::write(&f, b"1 2 3\n4 5 6\n").unwrap();
        let why = stamp.moved().expect("an edit is seen");
        assert!(why.contains("changed size"), "{why}");
        // Undone: the same bytes again, but the file was written in between (a tick later than
        // the digest, as any edit by hand is).
        std::thread::sleep(Duration::from_millis(50));
        fs::write(&f, b"1 2 3\n").unwrap();
        assert!(stamp.moved().is_some(), "an edit then an undo is seen");

        // A fresh stamp of the settled file: an old mtime is trusted by stat.
        set_mtime(&f, SystemTime::now() - Duration::from_secs(3600));
        let (_, settled) = cache.file_digest_stamped(&f).unwrap();
        assert_eq!(settled.moved(), None);
        // Replaced by a rename (another inode), even with the same bytes and mtime.
        let g = dir.path().join("new.xyz");
        fs::write(&g, b"1 2 3\n").unwrap();
        set_mtime(&g, SystemTime::now() - Duration::from_secs(3600));
        fs::rename(&g, &f).unwrap();
        assert!(settled.moved().is_some_and(|w| w.contains("replaced")));
        fs::remove_file(&f).unwrap();
        assert!(
            settled
                .moved()
                .is_some_and(|w| w.contains("can no longer be read"))
        );
    }

    /// A folder input is every file's relative path and content: adding, removing, renaming or
    /// editing any file is a move.
    #[test]
    fn a_folder_input_that_moved_after_its_digest_is_seen() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::open(&dir.path().join("cache")).unwrap();
        let t = dir.path().join("tiles");
        fs::create_dir_all(t.join("sub")).unwrap();
        fs::write(t.join("tileset.json"), b"{}").unwrap();
        fs::write(t.join("sub/a.glb"), b"aaaa").unwrap();
        let stamp = || cache.file_digest_stamped(&t).unwrap().1;

        let s = stamp();
        assert_eq!(s.moved(), None);
        fs::write(t.join("sub/b.glb"), b"bbbb").unwrap();
        assert!(
            s.moved()
                .is_some_and(|w| w.contains("`sub/b.glb` appeared"))
        );

        let s = stamp();
        fs::remove_file(t.join("sub/b.glb")).unwrap();
        assert!(
            s.moved()
                .is_some_and(|w| w.contains("`sub/b.glb` disappeared"))
        );

        let s = stamp();
        fs::rename(t.join("sub/a.glb"), t.join("sub/c.glb")).unwrap();
        assert!(s.moved().is_some());

        let s = stamp();
        fs::write(t.join("sub/c.glb"), b"cccc").unwrap();
        assert!(
            s.moved()
                .is_some_and(|w| w.contains("`sub/c.glb` was modified")),
            "{:?}",
            s.moved()
        );
        assert_eq!(stamp().moved(), None);
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
