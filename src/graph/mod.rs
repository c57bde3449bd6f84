//! A loaded, checked graph: nodes in topological order with resolved edges, params and files.

mod data_source;
mod load;
mod render;
mod tiling;

use std::path::PathBuf;

use kodama_nodes::stage::Unit;
use kodama_nodes::{Site, Window};

use crate::registry::{Kind, Params};

pub use load::{LoadOptions, MAX_GRAPH_BYTES, folder_name, load, read_graph_text};
pub use render::{to_dot, to_mermaid};
pub use tiling::{MAX_TILES, Tile, TileOverrides, Tiling};

/// A graph that passed every check: every edge exists and has the right type, there is no cycle,
/// every param is valid and every declared file exists.
pub struct Graph {
    /// The graph file as given.
    pub path: PathBuf,
    /// The file stem, used for the default output folder and in run records.
    pub name: String,
    /// The site frame.
    pub site: Site,
    /// Nodes in a topological order (file order where free).
    pub nodes: Vec<Node>,
    /// Declared outputs: name and node index.
    pub outputs: Vec<(String, usize)>,
    /// The tiles of a tiled run, None when the graph runs untiled.
    pub tiling: Option<Tiling>,
}

/// One node of a [`Graph`].
pub struct Node {
    /// The id in the graph file.
    pub id: String,
    /// Its kind.
    pub kind: &'static Kind,
    /// Upstream node indices for each of `kind.inputs`, in list order.
    pub inputs: Vec<Vec<usize>>,
    /// Distinct upstream node indices, ascending.
    pub deps: Vec<usize>,
    /// Typed params.
    pub params: Box<dyn Params>,
    /// Declared files, resolved.
    pub files: Vec<InputFile>,
    /// In a tiled run, the tile (an index into `Graph::tiling`) this copy of a node is made for;
    /// None for a node made once.
    pub tile: Option<usize>,
    /// What a windowed stage of this tile reads (the tile's core grown by the halo); it enters
    /// the node's key with the site. None untiled, and for nodes made once.
    pub window: Option<Window>,
    /// In a tiled run, the phase: for a tile's node, the tile job that makes it (1 for nodes that
    /// need no merge, k + 1 for those reading what a merge of phase k made); for a node made once,
    /// the phase of the tile nodes it waits for (0: none, it can run before any tile).
    pub phase: u32,
}

/// A file a node reads.
#[derive(Clone, Debug)]
pub struct InputFile {
    /// The params field naming it.
    pub field: &'static str,
    /// The path as written in the graph.
    pub written: String,
    /// The resolved path.
    pub path: PathBuf,
}

impl Node {
    /// Sets `deps` from `inputs`: the distinct upstream nodes, ascending.
    pub(crate) fn set_deps(&mut self) {
        self.deps = self
            .inputs
            .iter()
            .flatten()
            .copied()
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
    }
}

impl Graph {
    /// Index of the node called `id`.
    pub fn index(&self, id: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.id == id)
    }

    /// What node `i`'s raster values measure: its stage's unit, followed up the inputs a stage
    /// takes it from (a blur of a terrain is in metres). None for labels, counts and the unknown.
    pub fn raster_unit(&self, i: usize) -> Option<&'static str> {
        let mut at = i;
        // Each step goes upstream; a graph has no cycles, so the nodes bound the walk.
        for _ in 0..=self.nodes.len() {
            let node = self.nodes.get(at)?;
            match node.params.unit() {
                Unit::None => return None,
                Unit::Is(u) => return Some(u),
                Unit::SameAs(input) => {
                    let k = node.kind.inputs.iter().position(|s| s.name == input)?;
                    at = *node.inputs.get(k)?.first()?;
                }
            }
        }
        None
    }

    /// The nodes needed for `targets` (themselves and their ancestors), or all nodes if empty.
    pub fn needed(&self, targets: &[usize]) -> Vec<bool> {
        if targets.is_empty() {
            return vec![true; self.nodes.len()];
        }
        let mut need = vec![false; self.nodes.len()];
        let mut stack = targets.to_vec();
        while let Some(i) = stack.pop() {
            if !std::mem::replace(&mut need[i], true) {
                stack.extend(&self.nodes[i].deps);
            }
        }
        need
    }

    /// Direct consumers of every node.
    pub fn consumers(&self) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); self.nodes.len()];
        for (i, n) in self.nodes.iter().enumerate() {
            for &d in &n.deps {
                out[d].push(i);
            }
        }
        out
    }
}
