//! A remote tier of the cache in an S3 bucket (AWS S3 or any S3-compatible store: SeaweedFS,
//! MinIO, Ceph RGW, Cloudflare R2), for machines that share no filesystem: what one computes,
//! every machine using the same bucket and prefix finds.
//!
//! The remote holds the same `cas/` and `ac/` entries as a local cache, under the URL's prefix,
//! beside a `FORMAT` object that marks it. The local cache stays in front of it (blobs are read by
//! mapping local files; locks, stat cache and run records are local): a local miss asks the
//! remote, and what the remote gives is verified and stored locally before use.
//!
//! **Invariants**, the local cache's carried over:
//! - an object is whole or absent: a single PUT is atomic in S3, and a large blob goes up as a
//!   multipart upload that is invisible until completed (a client or server killed mid-upload
//!   leaves no object);
//! - an action entry goes up only after every blob it names is there, so a remote entry never
//!   points at a blob that never arrived;
//! - a blob fetched from the remote is hashed as it streams in and kept only if it hashes to its
//!   name.
//!
//! A remote that fails (unreachable, refusing) never fails a run: the run goes on with its local
//! cache, says what it could not share, and asks the remote nothing more (each request would
//! otherwise wait out its retries).

use std::io::{self, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use futures_util::StreamExt;
use object_store::aws::AmazonS3Builder;
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, ObjectStoreExt, PutPayload};

/// What marks a prefix as a kodama-dag remote cache (the local cache's FORMAT, same layout).
const FORMAT: &str = "kodama-dag cache 1\n";

/// Blobs above this go up as multipart uploads of parts this size (S3's least part is 5 MiB).
const PART_BYTES: usize = 8 << 20;

/// A remote cache: a bucket and a prefix.
pub struct Remote {
    store: Arc<dyn ObjectStore>,
    prefix: String,
    url: String,
    rt: tokio::runtime::Runtime,
    warnings: AtomicUsize,
    /// Set by the first failure: the rest of the process uses the local cache only.
    down: AtomicBool,
}

impl std::fmt::Debug for Remote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.url)
    }
}

/// Splits `s3://bucket/prefix` into the bucket and the prefix (without slashes at its ends).
pub fn parse_url(url: &str) -> Result<(String, String), String> {
    let rest = url.strip_prefix("s3://").ok_or_else(|| {
        format!("remote cache {url:?}: expected s3://BUCKET/PREFIX (the only scheme served)")
    })?;
    let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
    let bucket_ok = (3..=63).contains(&bucket.len())
        && bucket
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'.');
    if !bucket_ok {
        return Err(format!(
            "remote cache {url:?}: bucket {bucket:?} is not an S3 bucket name (3-63 lowercase \
             letters, digits, '-' and '.')"
        ));
    }
    let prefix = prefix.trim_matches('/').to_string();
    if prefix.split('/').any(|p| p == "." || p == "..")
        || ObjectPath::parse(&prefix).is_err()
        || prefix.len() > 512
    {
        return Err(format!(
            "remote cache {url:?}: prefix {prefix:?} is not a plain object path (no empty, \
             '.' or '..' parts; at most 512 bytes)"
        ));
    }
    Ok((bucket.to_string(), prefix))
}

impl Remote {
    /// Connects to the remote cache at `url` (`s3://BUCKET/PREFIX`). Endpoint, region and
    /// credentials come from the usual AWS variables (`AWS_ENDPOINT`, `AWS_REGION`,
    /// `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_ALLOW_HTTP=true` for a plain-HTTP
    /// endpoint); with no access key, requests go unsigned (a public or test bucket). The prefix
    /// must be empty or marked as a kodama-dag cache of this format; an empty one is marked.
    pub fn open(url: &str) -> Result<Remote, String> {
        let (bucket, prefix) = parse_url(url)?;
        let mut builder = AmazonS3Builder::from_env().with_bucket_name(&bucket);
        if std::env::var_os("AWS_ACCESS_KEY_ID").is_none() {
            builder = builder.with_skip_signature(true);
        }
        if std::env::var_os("AWS_REGION").is_none()
            && std::env::var_os("AWS_DEFAULT_REGION").is_none()
        {
            builder = builder.with_region("us-east-1");
        }
        let retry = object_store::RetryConfig {
            max_retries: 3,
            retry_timeout: Duration::from_secs(20),
            ..Default::default()
        };
        let store = builder
            .with_retry(retry)
            .build()
            .map_err(|e| format!("remote cache {url}: {e}"))?;
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("kodama-s3")
            .enable_all()
            .build()
            .map_err(|e| format!("remote cache {url}: cannot start its I/O threads: {e}"))?;
        let remote = Remote {
            store: Arc::new(store),
            prefix,
            url: url.to_string(),
            rt,
            warnings: AtomicUsize::new(0),
            down: AtomicBool::new(false),
        };
        remote.check_format()?;
        Ok(remote)
    }

    /// The URL it was opened with.
    pub fn url(&self) -> &str {
        &self.url
    }

    fn path(&self, rel: &str) -> ObjectPath {
        if self.prefix.is_empty() {
            ObjectPath::from(rel)
        } else {
            ObjectPath::from(format!("{}/{rel}", self.prefix))
        }
    }

    /// The object of a `cas/` or `ac/` entry: `<prefix>/<dir>/<2 hex>/<64 hex>`.
    fn entry(&self, dir: &str, hex: &str) -> ObjectPath {
        self.path(&format!("{dir}/{}/{hex}", &hex[..2]))
    }

    fn check_format(&self) -> Result<(), String> {
        let at = self.path("FORMAT");
        let found = self.rt.block_on(async {
            match self.store.get(&at).await {
                Ok(r) => r.bytes().await.map(Some),
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(e),
            }
        });
        match found {
            Err(e) => Err(format!("remote cache {}: cannot reach it: {e}", self.url)),
            Ok(Some(b)) if b.as_ref() == FORMAT.as_bytes() => Ok(()),
            Ok(Some(b)) => Err(format!(
                "remote cache {}: its FORMAT reads {:?}, not this version's {:?}; use another \
                 prefix",
                self.url,
                String::from_utf8_lossy(&b[..b.len().min(64)]).trim(),
                FORMAT.trim()
            )),
            Ok(None) => {
                let listed = self.rt.block_on(async {
                    let prefix = (!self.prefix.is_empty()).then(|| self.path(""));
                    self.store.list(prefix.as_ref()).next().await.transpose()
                });
                match listed {
                    Err(e) => Err(format!("remote cache {}: cannot list it: {e}", self.url)),
                    Ok(Some(o)) => Err(format!(
                        "remote cache {}: the prefix holds other objects ({}) and no FORMAT: \
                         not a kodama-dag cache, and none is made over someone else's objects",
                        self.url, o.location
                    )),
                    Ok(None) => self
                        .rt
                        .block_on(
                            self.store
                                .put(&at, PutPayload::from(FORMAT.as_bytes().to_vec())),
                        )
                        .map(|_| ())
                        .map_err(|e| format!("remote cache {}: cannot mark it: {e}", self.url)),
                }
            }
        }
    }

    /// Says (on stderr, the first time) that the remote failed at `what`, and stops asking it;
    /// the run goes on with the local cache.
    pub fn warn(&self, what: &str, e: impl std::fmt::Display) {
        self.down.store(true, Ordering::Relaxed);
        if self.warnings.fetch_add(1, Ordering::Relaxed) == 0 {
            eprintln!(
                "warning: remote cache {}: {what}: {e}; the rest of this run uses the local \
                 cache only",
                self.url
            );
        }
    }

    /// An error for requests made after the remote failed once.
    fn check_up(&self) -> io::Result<()> {
        if self.down.load(Ordering::Relaxed) {
            Err(io::Error::other("not asked: it failed earlier in this run"))
        } else {
            Ok(())
        }
    }

    /// The action entry `hex`'s text, if the remote has it.
    pub fn get_action(&self, hex: &str) -> io::Result<Option<String>> {
        self.check_up()?;
        let at = self.entry("ac", hex);
        self.rt.block_on(async {
            match self.store.get(&at).await {
                Ok(r) => {
                    let b = r.bytes().await.map_err(io::Error::other)?;
                    Ok(Some(String::from_utf8_lossy(&b).into_owned()))
                }
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(io::Error::other(e)),
            }
        })
    }

    /// Puts the action entry `hex` (call only once its blobs are up).
    pub fn put_action(&self, hex: &str, text: &str) -> io::Result<()> {
        self.check_up()?;
        let at = self.entry("ac", hex);
        self.rt
            .block_on(
                self.store
                    .put(&at, PutPayload::from(text.as_bytes().to_vec())),
            )
            .map(|_| ())
            .map_err(io::Error::other)
    }

    /// The size of blob `hex` on the remote, if it is there.
    pub fn blob_size(&self, hex: &str) -> io::Result<Option<u64>> {
        self.check_up()?;
        let at = self.entry("cas", hex);
        match self.rt.block_on(self.store.head(&at)) {
            Ok(m) => Ok(Some(m.size)),
            Err(object_store::Error::NotFound { .. }) => Ok(None),
            Err(e) => Err(io::Error::other(e)),
        }
    }

    /// Streams blob `hex` into `w`; false if the remote has no such blob.
    pub fn read_blob(&self, hex: &str, w: &mut dyn Write) -> io::Result<bool> {
        self.check_up()?;
        let at = self.entry("cas", hex);
        self.rt.block_on(async {
            let mut stream = match self.store.get(&at).await {
                Ok(r) => r.into_stream(),
                Err(object_store::Error::NotFound { .. }) => return Ok(false),
                Err(e) => return Err(io::Error::other(e)),
            };
            while let Some(chunk) = stream.next().await {
                w.write_all(&chunk.map_err(io::Error::other)?)?;
            }
            Ok(true)
        })
    }

    /// Puts blob `hex`'s `bytes`: one PUT, or a multipart upload above `PART_BYTES`, completed
    /// only once every part is up (aborted on failure), so no reader sees part of it.
    pub fn put_blob(&self, hex: &str, bytes: &[u8]) -> io::Result<()> {
        self.check_up()?;
        let at = self.entry("cas", hex);
        if bytes.len() <= PART_BYTES {
            return self
                .rt
                .block_on(self.store.put(&at, PutPayload::from(bytes.to_vec())))
                .map(|_| ())
                .map_err(io::Error::other);
        }
        // Fault injection for the tests: a pause after the first part, the moment to kill the
        // client or the server mid-upload.
        let pause = std::env::var("KODAMA_DAG_FAULT_SLOW_UPLOAD_MS")
            .ok()
            .and_then(|v| v.parse::<u64>().ok())
            .map(Duration::from_millis);
        self.rt.block_on(async {
            let mut upload = self
                .store
                .put_multipart(&at)
                .await
                .map_err(io::Error::other)?;
            let parts = async {
                for (i, part) in bytes.chunks(PART_BYTES).enumerate() {
                    upload.put_part(PutPayload::from(part.to_vec())).await?;
                    if i == 0
                        && let Some(p) = pause
                    {
                        tokio::time::sleep(p).await;
                    }
                }
                upload.complete().await
            }
            .await;
            match parts {
                Ok(_) => Ok(()),
                Err(e) => {
                    let _ = upload.abort().await;
                    Err(io::Error::other(e))
                }
            }
        })
    }
}
