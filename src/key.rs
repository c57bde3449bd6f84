//! Action keys: blake3 over everything that determines a node's output.

use kodama_nodes::stage::Arity;

use crate::cache::Digest;
use crate::graph::Node;
use crate::record::Snapshot;

/// Bumped if the key layout below changes, so old cache entries are not mistaken for new ones.
const KEY_LAYOUT: &[u8] = b"kodama-dag action key 1\0";

/// Hashes `bytes` behind their length, so that adjacent fields cannot run into each other.
pub(crate) fn put(h: &mut blake3::Hasher, bytes: &[u8]) {
    h.update(&(bytes.len() as u64).to_le_bytes());
    h.update(bytes);
}

/// The action key of `node` given its inputs' digests (one list per input, in declared order) and
/// its files' digests, plus the snapshot of what went into it.
///
/// key = blake3(layout, kind, VERSION, site, canonical params, for each input: name, arity and the
/// digests of its upstream outputs in list order, for each file: its content digest). Node ids and
/// file paths are not in the key: renaming a node or moving the data does not invalidate anything.
pub fn action_key(
    node: &Node,
    site: &Digest,
    inputs: &[Vec<Digest>],
    files: &[Digest],
) -> (Digest, Snapshot) {
    let mut h = blake3::Hasher::new();
    h.update(KEY_LAYOUT);
    put(&mut h, node.kind.name.as_bytes());
    h.update(&node.kind.version.to_le_bytes());
    h.update(site.as_bytes());
    put(&mut h, &node.params.canonical());
    for (spec, digests) in node.kind.inputs.iter().zip(inputs) {
        put(&mut h, spec.name.as_bytes());
        h.update(&[match spec.arity {
            Arity::One => 1,
            Arity::Optional => 2,
            Arity::Many => 3,
        }]);
        h.update(&(digests.len() as u64).to_le_bytes());
        for d in digests {
            h.update(d.as_bytes());
        }
    }
    for d in files {
        h.update(d.as_bytes());
    }
    let key = h.finalize();
    let snapshot = Snapshot {
        kind: node.kind.name.to_owned(),
        version: node.kind.version,
        site: site.to_hex().to_string(),
        params: node.params.fields(),
        inputs: node
            .kind
            .inputs
            .iter()
            .zip(inputs)
            .map(|(s, ds)| {
                (
                    s.name.to_owned(),
                    ds.iter().map(|d| d.to_hex().to_string()).collect(),
                )
            })
            .collect(),
        files: node
            .files
            .iter()
            .zip(files)
            .map(|(f, d)| {
                (
                    f.field.to_owned(),
                    f.written.clone(),
                    d.to_hex().to_string(),
                )
            })
            .collect(),
        key: key.to_hex().to_string(),
        digest: None,
    };
    (key, snapshot)
}

/// Digest of the site block (canonical MessagePack).
pub fn site_digest(site: &kodama_nodes::Site) -> Digest {
    blake3::hash(&rmp_serde::to_vec_named(site).expect("site serializes"))
}

/// The site digest a node's key takes: the graph's, or for a tile's node in a tiled run the graph's
/// with the window its tile reads, so each tile's copy of a node has a key of its own.
pub fn node_site(site: &Digest, node: &Node) -> Digest {
    match &node.window {
        None => *site,
        Some(w) => {
            let mut h = blake3::Hasher::new();
            h.update(site.as_bytes());
            put(&mut h, b"window");
            put(
                &mut h,
                &rmp_serde::to_vec_named(w).expect("a window serializes"),
            );
            h.finalize()
        }
    }
}
