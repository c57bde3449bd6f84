//! Parts: what an artifact keeps apart from itself, content-addressed (a view set's pixels, one
//! part per view), and the stores that hold them.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

/// Why a part could not be stored or read: the store, the part and what went wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct PartError(pub String);

impl std::fmt::Display for PartError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for PartError {}

/// A content-addressed part of an artifact stored apart from it: the artifact holds only this
/// reference (the blake3 digest and size of the part's bytes), so what it names is covered by the
/// artifact's own digest, and the artifact loads without the part (a view set's pixels: a view is
/// read when a stage comes to it, never every view at once).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct PartRef {
    /// blake3 of the part's bytes.
    pub digest: [u8; 32],
    /// The part's length in bytes.
    pub size: u64,
}

impl PartRef {
    /// The reference of `bytes`.
    pub fn of(bytes: &[u8]) -> PartRef {
        PartRef {
            digest: *blake3::hash(bytes).as_bytes(),
            size: bytes.len() as u64,
        }
    }
}

/// Where a stage puts the parts of its output and finds the parts of its inputs. The engine's is
/// the cache (each part a blob, recorded with the action that made it, so gc and the remote tier
/// treat the artifact and its parts as one); [`MemParts`] keeps them in memory for tests and
/// library callers.
pub trait PartStore: Sync {
    /// Stores `bytes` (a part already stored is not written again) and returns their reference.
    fn put(&self, bytes: &[u8]) -> Result<PartRef, PartError>;
    /// The bytes stored as `part`, checked against its digest.
    fn get(&self, part: &PartRef) -> Result<Vec<u8>, PartError>;
}

/// Parts held in memory, for as long as the store lives.
#[derive(Default)]
pub struct MemParts {
    parts: std::sync::Mutex<std::collections::HashMap<PartRef, Arc<[u8]>>>,
}

impl MemParts {
    /// An empty store.
    pub fn new() -> MemParts {
        MemParts::default()
    }
}

impl PartStore for MemParts {
    fn put(&self, bytes: &[u8]) -> Result<PartRef, PartError> {
        let part = PartRef::of(bytes);
        self.parts
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .entry(part)
            .or_insert_with(|| bytes.into());
        Ok(part)
    }

    fn get(&self, part: &PartRef) -> Result<Vec<u8>, PartError> {
        self.parts
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(part)
            .map(|b| b.to_vec())
            .ok_or_else(|| {
                PartError(format!(
                    "part {} is not in this store (an artifact read with another store than the one it was made with)",
                    blake3::Hash::from(part.digest).to_hex()
                ))
            })
    }
}

/// The store [`Ctx::new`] hands to stages: in memory, for the life of the process.
pub fn process_parts() -> &'static MemParts {
    static PARTS: std::sync::OnceLock<MemParts> = std::sync::OnceLock::new();
    PARTS.get_or_init(MemParts::new)
}
