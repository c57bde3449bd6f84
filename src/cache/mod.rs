//! The on-disk cache: a content-addressed store of artifacts and an action cache mapping action
//! keys to artifact digests.
//!
//! Layout under the cache root (kept simple so a shared filesystem or a Remote Execution API
//! content store can stand in for it; blake3 is one of REAPI's digest functions):
//!
//! ```text
//! FORMAT                 layout version; the marker that makes a folder a cache (gc opens
//!                        nothing else, see `Cache::open_existing`)
//! lock                   runs hold it shared, gc exclusive
//! cas/<2 hex>/<64 hex>   artifact bytes, named by their blake3 digest
//! ac/<2 hex>/<64 hex>    "blake3:<digest hex> <size>\n" for an action key
//! stat/<64 hex>          stat cache of input files, by blake3 of the absolute path
//! runs/<graph>/...       last-run snapshots and run records
//! tmp/                   temp files; renamed into place when complete
//! ```
//!
//! With a remote tier (`--remote-cache s3://...`, `remote.rs`) the same `cas/` and `ac/` entries
//! are shared through an object store: a local miss asks it, and what is stored locally goes up
//! to it, each blob before the action entry naming it.
//!
//! **Invariant:** a file under `cas/`, `ac/` or `stat/` is only ever created by renaming a complete,
//! fsynced temp file, so a reader sees either nothing or the whole file, whatever was killed when.
//! A blob is verified against its name on every read; a bad one is a miss that rebuilds.

mod atomic;
mod files;
mod gc;
pub mod remote;

use std::fs::{self, File};
use std::io;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use kodama_nodes::artifact::{PartError, PartRef, PartStore};

pub use atomic::write_atomic;
pub use files::{InputStamp, check_folder, describe_file_type, folder_files, hash_file};
pub use gc::{GcReport, gc};
pub use remote::Remote;

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
    /// The remote tier, when the cache is shared through an object store.
    remote: Option<std::sync::Arc<Remote>>,
    /// Folders runs through this cache write (their output folders, canonical), left out of
    /// folder inputs' digests as the cache itself is ([`Cache::writes_outputs_to`]).
    own_folders: Vec<PathBuf>,
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

/// A folder that is not a kodama-dag cache, where one was expected: commands that delete from a
/// cache refuse it (exit 2), and no command marks it as a cache. Carried inside an
/// [`io::Error`] (kind `InvalidData`); [`NotACache::of`] finds it.
#[derive(Debug)]
pub struct NotACache {
    /// The folder.
    pub root: PathBuf,
    /// Why it is not one.
    pub why: String,
}

impl std::fmt::Display for NotACache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} is not a kodama-dag cache: {}; expected a folder made by `kodama-dag run --cache` \
             (a FORMAT file reading \"{}\", and cas/ and ac/ holding only files named by their \
             blake3 digest)",
            self.root.display(),
            self.why,
            FORMAT.trim()
        )
    }
}

impl std::error::Error for NotACache {}

impl NotACache {
    fn error(root: &Path, why: String) -> io::Error {
        io::Error::new(
            io::ErrorKind::InvalidData,
            NotACache {
                root: root.to_path_buf(),
                why,
            },
        )
    }

    /// The [`NotACache`] inside `e`, if that is what it is.
    pub fn of(e: &io::Error) -> Option<&NotACache> {
        e.get_ref()?.downcast_ref::<NotACache>()
    }
}

/// Whether `name` is `n` lowercase hex digits, as [`Digest::to_hex`] writes them.
fn is_hex(name: &str, n: usize) -> bool {
    name.len() == n && name.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// Whether `name` is a shard folder's name: two hex digits.
pub(crate) fn is_shard_name(name: &str) -> bool {
    is_hex(name, 2)
}

/// Whether `name` (in a shard folder called `shard`) is the name the engine gives a blob or an
/// action entry: its 64 hex digits, the first two of which name the shard.
pub(crate) fn is_entry_name(shard: &str, name: &str) -> bool {
    is_shard_name(shard) && is_hex(name, 64) && name.starts_with(shard)
}

/// Whether `name` is a temp file name the engine gives (`.kodama-<pid>-<...>.tmp`).
pub(crate) fn is_temp_name(name: &str) -> bool {
    name.strip_prefix(".kodama-")
        .and_then(|n| n.strip_suffix(".tmp"))
        .and_then(|n| n.split_once('-'))
        .is_some_and(|(pid, _)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// What a folder holds where the engine keeps the files it deletes (`cas/`, `ac/`, `tmp/`).
#[derive(Debug, PartialEq, Eq)]
enum Layout {
    /// `cas/` and `ac/` exist, and they and `tmp/` hold only names the engine gives.
    Engine,
    /// Nothing foreign there, but not both `cas/` and `ac/` (a new or empty folder).
    Incomplete,
    /// Something the engine would never have written there.
    Foreign(String),
}

/// Reads (without following symlinks or opening any file) what `root` holds under `cas/`,
/// `ac/` and `tmp/`.
fn layout(root: &Path) -> io::Result<Layout> {
    let foreign = |what: String| Ok(Layout::Foreign(what));
    let mut both = true;
    for dir in ["cas", "ac", "tmp"] {
        let path = root.join(dir);
        let meta = match fs::symlink_metadata(&path) {
            Ok(m) => m,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                both &= dir == "tmp";
                continue;
            }
            Err(e) => return Err(e),
        };
        if !meta.is_dir() {
            return foreign(format!("{dir} is not a folder"));
        }
        for entry in fs::read_dir(&path)? {
            let entry = entry?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else {
                return foreign(format!("{dir}/{} is not a name it gives", name.display()));
            };
            let t = entry.file_type()?;
            if dir == "tmp" {
                if !(t.is_file() && is_temp_name(name)) {
                    return foreign(format!("{dir}/{name} is not a temp file it names"));
                }
                continue;
            }
            if !(t.is_dir() && is_shard_name(name)) {
                return foreign(format!("{dir}/{name} is not a shard folder it names"));
            }
            for f in fs::read_dir(entry.path())? {
                let f = f?;
                let fname = f.file_name();
                let ok = f.file_type()?.is_file()
                    && fname.to_str().is_some_and(|n| is_entry_name(name, n));
                if !ok {
                    return foreign(format!(
                        "{dir}/{name}/{} is not a file it names",
                        fname.display()
                    ));
                }
            }
        }
    }
    Ok(if both {
        Layout::Engine
    } else {
        Layout::Incomplete
    })
}

impl Cache {
    /// Opens (creating if needed) the cache at `root`. A folder without the FORMAT marker becomes
    /// a cache only if nothing under its `cas/`, `ac/` and `tmp/` is foreign to the engine
    /// (else [`NotACache`]): the marker is never written over someone else's files.
    pub fn open(root: &Path) -> io::Result<Cache> {
        let marked = Self::marked(root)?;
        if !marked && let Layout::Foreign(why) = layout(root)? {
            return Err(NotACache::error(
                root,
                format!("it has no FORMAT file and {why}"),
            ));
        }
        Self::create_dirs(root)?;
        if !marked {
            write_atomic(&root.join("tmp"), &root.join("FORMAT"), FORMAT.as_bytes())?;
        }
        Ok(Cache {
            root: root.to_path_buf(),
            remote: None,
            own_folders: Vec::new(),
        })
    }

    /// Opens the existing cache at `root` for a command that deletes from it (`gc`), creating
    /// nothing: `root` must carry the FORMAT marker, or be a cache made without one (`cas/` and
    /// `ac/` present, and nothing under them or `tmp/` that the engine does not name), which is
    /// then marked. Anything else is [`NotACache`].
    pub fn open_existing(root: &Path) -> io::Result<Cache> {
        match fs::metadata(root) {
            Ok(m) if m.is_dir() => {}
            Ok(_) => return Err(NotACache::error(root, "it is not a folder".into())),
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Err(NotACache::error(root, "it does not exist".into()));
            }
            Err(e) => return Err(e),
        }
        if !Self::marked(root)? {
            match layout(root)? {
                Layout::Engine => {
                    Self::create_dirs(root)?;
                    write_atomic(&root.join("tmp"), &root.join("FORMAT"), FORMAT.as_bytes())?;
                }
                Layout::Incomplete => {
                    return Err(NotACache::error(
                        root,
                        "it has no FORMAT file and no cas/ and ac/ folders".into(),
                    ));
                }
                Layout::Foreign(why) => {
                    return Err(NotACache::error(
                        root,
                        format!("it has no FORMAT file and {why}"),
                    ));
                }
            }
        }
        Self::create_dirs(root)?;
        Ok(Cache {
            root: root.to_path_buf(),
            remote: None,
            own_folders: Vec::new(),
        })
    }

    /// Whether `root` carries this engine's FORMAT marker; an error if it carries another's.
    /// Whether `dir` is a folder carrying this engine's cache marker (errors read as no).
    pub fn is_cache_folder(dir: &Path) -> bool {
        Self::marked(dir).unwrap_or(false)
    }

    fn marked(root: &Path) -> io::Result<bool> {
        let fmt = root.join("FORMAT");
        match fs::symlink_metadata(&fmt) {
            Ok(m) if m.is_file() => {}
            Ok(_) => {
                return Err(NotACache::error(
                    root,
                    "its FORMAT is not a regular file".into(),
                ));
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
            Err(e) => return Err(e),
        }
        // A marker is a few bytes; a large file there is not one (and is not read whole).
        let mut text = String::new();
        io::Read::read_to_string(&mut io::Read::take(File::open(&fmt)?, 64), &mut text)
            .map_err(|_| NotACache::error(root, "its FORMAT file is not text".into()))?;
        if text == FORMAT {
            return Ok(true);
        }
        if !text.starts_with("kodama-dag cache ") {
            return Err(NotACache::error(
                root,
                format!("its FORMAT file reads {:?}", text.trim()),
            ));
        }
        Err(io::Error::other(format!(
            "{} is a cache of another format ({:?}); use another --cache or delete it",
            root.display(),
            text.trim()
        )))
    }

    fn create_dirs(root: &Path) -> io::Result<()> {
        for d in ["cas", "ac", "stat", "runs", "tmp"] {
            fs::create_dir_all(root.join(d))?;
        }
        Ok(())
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

    /// Shares this cache through `remote`: local misses ask it, and what is stored goes up to it.
    pub fn with_remote(mut self, remote: Remote) -> Cache {
        self.remote = Some(std::sync::Arc::new(remote));
        self
    }

    /// The remote tier, if any.
    pub fn remote(&self) -> Option<&Remote> {
        self.remote.as_deref()
    }

    /// Stores what `write` writes as a blob, hashed as it is written (the encoding is never held
    /// in memory whole), and returns its digest and size; with a remote tier, the blob goes up to
    /// it too. The temp file is fsynced and renamed into place, or removed if a blob of that
    /// digest is already stored or anything failed.
    pub fn put_blob_with(
        &self,
        write: impl FnOnce(&mut dyn io::Write) -> io::Result<()>,
    ) -> io::Result<(Digest, u64)> {
        let (digest, size) = self.store_local(write)?;
        if let Some(remote) = &self.remote {
            self.upload(remote, &digest, size);
        }
        Ok((digest, size))
    }

    /// Stores a blob in the local folder only.
    fn store_local(
        &self,
        write: impl FnOnce(&mut dyn io::Write) -> io::Result<()>,
    ) -> io::Result<(Digest, u64)> {
        let (tmp, file) = atomic::create_temp(&self.tmp())?;
        let result = (|| {
            let mut w = atomic::HashingWriter::new(file);
            write(&mut w)?;
            let (file, digest, size) = w.finish()?;
            drop(file);
            if self.has_local_blob(&digest, size) {
                fs::remove_file(&tmp)?;
                return Ok((digest, size));
            }
            let path = self.blob_path(&digest);
            fs::create_dir_all(path.parent().expect("sharded path has a parent"))?;
            self.displace_non_file(&path);
            fs::rename(&tmp, &path)?;
            Ok((digest, size))
        })();
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        result
    }

    /// Puts the local blob `digest` on the remote unless it is there already; true when the
    /// remote holds it afterwards. Failures are reported, never fatal.
    fn upload(&self, remote: &Remote, digest: &Digest, size: u64) -> bool {
        let hex = digest.to_hex();
        match remote.blob_size(&hex) {
            Ok(Some(s)) if s == size => return true,
            Ok(_) => {}
            Err(e) => {
                remote.warn("looking up a blob", e);
                return false;
            }
        }
        let bytes = match self.get_local_blob(digest) {
            Ok(b) => b,
            Err(_) => return false,
        };
        match remote.put_blob(&hex, &bytes) {
            Ok(()) => true,
            Err(e) => {
                remote.warn("uploading a blob", e);
                false
            }
        }
    }

    /// Fetches blob `digest` from the remote into the local folder, verified as it streams in;
    /// true when it is stored locally afterwards.
    fn fetch(&self, digest: &Digest) -> bool {
        let Some(remote) = &self.remote else {
            return false;
        };
        let hex = digest.to_hex();
        let got = self.store_local(|w| {
            if remote.read_blob(&hex, w)? {
                Ok(())
            } else {
                Err(io::Error::new(io::ErrorKind::NotFound, "not on the remote"))
            }
        });
        match got {
            Ok((d, _)) if d == *digest => true,
            Ok(_) => {
                // Stored under the digest of what it holds, harmless to keep; never used for
                // this one.
                remote.warn(
                    &format!("blob {hex}"),
                    "its bytes do not hash to its name; not used",
                );
                false
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => false,
            Err(e) => {
                remote.warn("fetching a blob", e);
                false
            }
        }
    }

    /// True if a blob of `size` bytes is stored under `digest` (by stat, not by hashing), fetched
    /// from the remote tier if only it has the blob; marks it recently used for gc.
    pub fn has_blob(&self, digest: &Digest, size: u64) -> bool {
        self.has_local_blob(digest, size)
            || (self.fetch(digest) && self.has_local_blob(digest, size))
    }

    /// Like [`Cache::has_blob`], but asks the remote without fetching: what `explain` and
    /// `submit` use to plan, moving no bytes.
    pub fn can_get_blob(&self, digest: &Digest, size: u64) -> bool {
        self.has_local_blob(digest, size)
            || self
                .remote
                .as_ref()
                .is_some_and(|r| matches!(r.blob_size(&digest.to_hex()), Ok(Some(s)) if s == size))
    }

    fn has_local_blob(&self, digest: &Digest, size: u64) -> bool {
        let path = self.blob_path(digest);
        match fs::symlink_metadata(&path) {
            Ok(m) if m.is_file() && m.len() == size => {
                touch(&path);
                true
            }
            _ => false,
        }
    }

    /// Moves whatever stands at a blob's or an action entry's path, if it is not a regular file
    /// (a folder, a symlink, a FIFO someone put there), into `tmp/` under a name that says so:
    /// the entry is then missing and is made again, where a folder there once failed every run
    /// that needed it. Nothing is deleted (gc lists it as foreign). True if something moved.
    fn displace_non_file(&self, path: &Path) -> bool {
        match fs::symlink_metadata(path) {
            Ok(m) if !m.is_file() => {
                let name = path.file_name().map(|n| n.to_string_lossy().to_string());
                let nanos = SystemTime::now()
                    .duration_since(SystemTime::UNIX_EPOCH)
                    .map_or(0, |d| d.as_nanos());
                let to = self.tmp().join(format!(
                    "displaced-{}-{}-{nanos}",
                    name.unwrap_or_default(),
                    std::process::id()
                ));
                fs::rename(path, to).is_ok()
            }
            _ => false,
        }
    }

    /// Maps and verifies the blob `digest`: its bytes are the page cache's, never copied into
    /// this process, so a large artifact is held once (decoded), not twice.
    pub fn get_blob(&self, digest: &Digest) -> Result<Blob, BlobError> {
        match self.get_local_blob(digest) {
            Err(BlobError::Missing) if self.fetch(digest) => self.get_local_blob(digest),
            other => other,
        }
    }

    fn get_local_blob(&self, digest: &Digest) -> Result<Blob, BlobError> {
        let path = self.blob_path(digest);
        if self.displace_non_file(&path) {
            return Err(BlobError::Missing);
        }
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

    /// What action `key` produced, if recorded here or on the remote tier (whose entry is then
    /// kept locally): its output blob and its reports'.
    pub fn get_action(&self, key: &Digest) -> Option<Action> {
        let path = shard(&self.root.join("ac"), &key.to_hex());
        if let Some(a) = fs::read_to_string(&path)
            .ok()
            .and_then(|t| parse_action(&t))
        {
            return Some(a);
        }
        let remote = self.remote.as_ref()?;
        match remote.get_action(&key.to_hex()) {
            Ok(Some(text)) => {
                let action = parse_action(&text)?;
                let _ = fs::create_dir_all(path.parent().expect("sharded path has a parent"));
                let _ = write_atomic(&self.tmp(), &path, text.as_bytes());
                Some(action)
            }
            Ok(None) => None,
            Err(e) => {
                remote.warn("reading an action entry", e);
                None
            }
        }
    }

    /// Records that action `key` produced `action`'s blobs; on the remote tier too, once every
    /// blob it names is there.
    pub fn put_action(&self, key: &Digest, action: &Action) -> io::Result<()> {
        let path = shard(&self.root.join("ac"), &key.to_hex());
        fs::create_dir_all(path.parent().expect("sharded path has a parent"))?;
        let (d, size) = action.output;
        let mut text = format!("blake3:{} {size}\n", d.to_hex());
        for (name, d, size) in &action.reports {
            text.push_str(&format!("report {name} blake3:{} {size}\n", d.to_hex()));
        }
        for (d, size) in &action.parts {
            text.push_str(&format!("part blake3:{} {size}\n", d.to_hex()));
        }
        self.displace_non_file(&path);
        write_atomic(&self.tmp(), &path, text.as_bytes())?;
        if let Some(remote) = &self.remote {
            // Every blob first: a remote entry never names a blob that did not arrive.
            if action
                .blobs()
                .collect::<Vec<_>>()
                .iter()
                .all(|(d, s)| self.upload(remote, d, *s))
                && let Err(e) = remote.put_action(&key.to_hex(), &text)
            {
                remote.warn("uploading an action entry", e);
            }
        }
        Ok(())
    }

    /// The folder for run records and last-run snapshots of one graph.
    pub fn runs_dir(&self, graph_key: &str) -> PathBuf {
        self.root.join("runs").join(graph_key)
    }
}

/// What one action produced: the output blob (digest, size), each report's, by name, and the
/// parts the output names (a view set's pixels).
#[derive(Clone, Debug, PartialEq)]
pub struct Action {
    /// The output's blob.
    pub output: (Digest, u64),
    /// (report name, digest, size) of each report, in the kind's order.
    pub reports: Vec<(String, Digest, u64)>,
    /// (digest, size) of each part the output names, in its order.
    pub parts: Vec<(Digest, u64)>,
}

impl Action {
    /// An action that made `output` and nothing else.
    pub fn of(output: (Digest, u64)) -> Action {
        Action {
            output,
            reports: Vec::new(),
            parts: Vec::new(),
        }
    }

    /// Every blob the action needs: the output, the reports, the parts.
    pub fn blobs(&self) -> impl Iterator<Item = (Digest, u64)> + '_ {
        std::iter::once(self.output)
            .chain(self.reports.iter().map(|(_, d, s)| (*d, *s)))
            .chain(self.parts.iter().copied())
    }

    /// The blob of report `name`, if recorded.
    pub fn report(&self, name: &str) -> Option<(Digest, u64)> {
        self.reports
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|(_, d, s)| (*d, *s))
    }
}

/// Parses an action entry: `blake3:<hex> <size>`, then a line `report <name> blake3:<hex> <size>`
/// per report and `part blake3:<hex> <size>` per part (entries written before reports or parts
/// existed have none).
pub(crate) fn parse_action(text: &str) -> Option<Action> {
    let blob = |t: &str| -> Option<(Digest, u64)> {
        let (d, size) = t.trim().strip_prefix("blake3:")?.split_once(' ')?;
        Some((Digest::from_hex(d).ok()?, size.parse().ok()?))
    };
    let mut lines = text.lines();
    let output = blob(lines.next()?)?;
    let mut action = Action::of(output);
    for line in lines {
        if let Some(rest) = line.strip_prefix("part ") {
            action.parts.push(blob(rest)?);
            continue;
        }
        let (name, rest) = line.strip_prefix("report ")?.split_once(' ')?;
        let (d, size) = blob(rest)?;
        action.reports.push((name.to_string(), d, size));
    }
    Some(action)
}

/// Action entries name a part by digest and size; stages by [`PartRef`].
pub fn part_ref((d, size): (Digest, u64)) -> PartRef {
    PartRef {
        digest: *d.as_bytes(),
        size,
    }
}

/// The cache as the store of the parts stages make and read: each part a blob, so it is written
/// whole or not at all, verified on every read, fetched from and sent to the remote tier like
/// any other.
impl PartStore for Cache {
    fn put(&self, bytes: &[u8]) -> Result<PartRef, PartError> {
        let (d, size) = self
            .put_blob_with(|w| io::Write::write_all(w, bytes))
            .map_err(|e| {
                PartError(format!(
                    "cannot store a part in {}: {e}",
                    self.root.display()
                ))
            })?;
        Ok(part_ref((d, size)))
    }

    fn get(&self, part: &PartRef) -> Result<Vec<u8>, PartError> {
        let d = Digest::from(part.digest);
        self.get_blob(&d).map(|b| b.to_vec()).map_err(|e| {
            PartError(format!(
                "part blake3:{} in {} is {e}; run again to rebuild it",
                d.to_hex(),
                self.root.display()
            ))
        })
    }
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

    /// A real cache: one blob, its action entry, a stale temp file.
    fn filled_cache(root: &Path) -> Digest {
        let cache = Cache::open(root).unwrap();
        let (d, size) = cache.put_blob_with(|w| w.write_all(b"artifact")).unwrap();
        cache
            .put_action(&blake3::hash(b"key"), &Action::of((d, size)))
            .unwrap();
        fs::write(root.join("tmp/.kodama-999999999-0-0.tmp"), b"left").unwrap();
        d
    }

    /// Only a folder that is a cache opens for deleting: marked, or laid out exactly as the
    /// engine lays one out (then it is marked). Nothing is created in one that is refused.
    #[test]
    fn only_a_cache_opens_for_deleting() {
        let dir = tempfile::tempdir().unwrap();
        let not = |root: &Path| -> String {
            let e = Cache::open_existing(root).err().expect("refused");
            NotACache::of(&e).expect("a NotACache").why.clone()
        };
        assert!(not(&dir.path().join("missing")).contains("does not exist"));
        assert!(!dir.path().join("missing").exists());

        let user = dir.path().join("user");
        fs::create_dir_all(user.join("cas")).unwrap();
        fs::create_dir_all(user.join("ac")).unwrap();
        fs::create_dir_all(user.join("tmp")).unwrap();
        fs::write(user.join("tmp/draft.txt"), b"mine").unwrap();
        assert!(not(&user).contains("tmp/draft.txt"), "{}", not(&user));
        fs::remove_file(user.join("tmp/draft.txt")).unwrap();
        fs::create_dir_all(user.join("cas/ab")).unwrap();
        fs::write(user.join("cas/ab/photo.jpg"), b"mine").unwrap();
        assert!(not(&user).contains("cas/ab/photo.jpg"));
        // A digest-like name in the wrong shard is not the engine's either.
        fs::remove_file(user.join("cas/ab/photo.jpg")).unwrap();
        fs::write(user.join("cas/ab").join("cd".repeat(32)), b"x").unwrap();
        assert!(not(&user).contains("is not a file it names"));
        assert!(!user.join("FORMAT").exists() && !user.join("lock").exists());
        // Nor may a run mark such a folder as a cache.
        assert!(NotACache::of(&Cache::open(&user).err().unwrap()).is_some());
        assert!(!user.join("FORMAT").exists());

        let empty = dir.path().join("empty");
        fs::create_dir_all(&empty).unwrap();
        assert!(not(&empty).contains("no cas/ and ac/"));

        let other = dir.path().join("other");
        fs::create_dir_all(&other).unwrap();
        fs::write(other.join("FORMAT"), b"my own format notes").unwrap();
        assert!(not(&other).contains("FORMAT file reads"));

        // A cache made without the marker: recognised by its layout and names, then marked.
        let legacy = dir.path().join("legacy");
        let d = filled_cache(&legacy);
        fs::remove_file(legacy.join("FORMAT")).unwrap();
        let cache = Cache::open_existing(&legacy).unwrap();
        assert_eq!(fs::read_to_string(legacy.join("FORMAT")).unwrap(), FORMAT);
        assert!(cache.get_blob(&d).is_ok());
    }

    /// gc deletes only what the engine named, even inside a marked cache.
    #[test]
    fn gc_never_deletes_a_file_the_engine_did_not_name() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("cache");
        filled_cache(&root);
        let planted = [
            root.join("cas/ab/notes.txt"),
            root.join("cas/notes.txt"),
            root.join("ac/zz/x"),
            root.join("tmp/keep.txt"),
        ];
        for p in &planted {
            fs::create_dir_all(p.parent().unwrap()).unwrap();
            fs::write(p, b"mine").unwrap();
        }
        let cache = Cache::open_existing(&root).unwrap();
        let report = gc(&cache, 0, &Default::default(), || {}).unwrap();
        assert_eq!((report.blobs_removed, report.actions_removed), (1, 1));
        assert_eq!(report.bytes_after, 0);
        for p in &planted {
            assert_eq!(fs::read(p).unwrap(), b"mine", "{}", p.display());
        }
        assert_eq!(report.foreign.len(), planted.len(), "{:?}", report.foreign);
        assert!(!root.join("tmp/.kodama-999999999-0-0.tmp").exists());
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
