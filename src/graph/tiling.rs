//! Tiled runs (city scale): a graph's `tiling:` block, or `--tile-m`, splits an area of the site
//! into square tiles and makes every node downstream of a windowed stage (`Stage::WINDOWED`: a
//! reader that crops, a sensor that flies only over its tile) once per tile, reading the tile's
//! core grown by a halo. The nodes `tiling.merge` names are merged (one node of the merge kind
//! of their type, under their own id), and what reads them, or anything made once, sees the
//! merge. A building is owned by the tile holding its centroid, so it comes whole from one tile.
//!
//! The expansion is plain graph rewriting: copies of nodes with a window in their key, and merge
//! nodes with the tiles as params. The engine runs the result as any graph; `--tile I` and
//! `--phase K` pick one tile job's nodes for a cluster's job array.

use kodama_nodes::site::{MergeTilesParams, TileCore};
use kodama_nodes::stages::tiles::{MERGED_TYPES, merge_kind};
use kodama_nodes::{Site, Window};
use serde::Deserialize;

use super::{Graph, Node};
use crate::diag::Diagnostic;
use crate::registry::{self, Kind};
use crate::syntax::{self, Ast, Span, did_you_mean};

/// The most tiles a run may have: a 100 km x 100 km area in 1 km tiles.
pub const MAX_TILES: usize = 10_000;

/// The most nodes a tiled graph may expand to.
pub const MAX_TILED_NODES: usize = 1_000_000;

/// `tiling: Tiling(...)` as a graph writes it.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, rename = "Tiling")]
pub struct TilingSpec {
    /// The part of the site to tile, site-frame metres (`(min: (x, y), max: (x, y))`), corners
    /// on the site's cell lattice.
    pub area: Window,
    /// Tile side, metres, a whole number of site cells. None runs the graph untiled unless
    /// `--tile-m` gives one.
    #[serde(default)]
    pub tile_m: Option<f64>,
    /// Halo around each tile's core, metres. None: the stages' reach plus half of `building_m`.
    #[serde(default)]
    pub halo_m: Option<f64>,
    /// The largest building across, metres (default 100): a building owned by a tile lies whole
    /// in its window when the halo covers half of it.
    #[serde(default = "default_building_m")]
    pub building_m: f64,
    /// The nodes whose tiles' outputs are merged into one, under their own id.
    pub merge: Vec<String>,
}

fn default_building_m() -> f64 {
    100.0
}

/// The tiles of a tiled graph.
#[derive(Clone, Debug)]
pub struct Tiling {
    /// Tile side, metres.
    pub tile_m: f64,
    /// Halo, metres.
    pub halo_m: f64,
    /// How the halo was chosen, for `explain` and the docs.
    pub halo_from: String,
    /// The tiled area.
    pub area: Window,
    /// Row-major from the south-west corner: tile `I` is column `I % columns`, row `I / columns`.
    pub tiles: Vec<Tile>,
    /// Tile phases: 1 when no tile node reads a merge, more when some do (see `Node::phase`).
    pub phases: u32,
}

/// One tile.
#[derive(Clone, Debug)]
pub struct Tile {
    /// `x<column>y<row>`, from the south-west.
    pub name: String,
    /// What the tile owns.
    pub core: Window,
    /// What its windowed stages read: the core grown by the halo.
    pub window: Window,
}

/// Overrides of a graph's tiling from the command line.
#[derive(Clone, Copy, Debug, Default)]
pub struct TileOverrides {
    /// `--tile-m`.
    pub tile_m: Option<f64>,
    /// `--halo-m`.
    pub halo_m: Option<f64>,
}

/// The graph's `tiling` field parsed; None, with a diagnostic, when it is wrong.
pub(super) fn tiling_spec(a: &Ast, diags: &mut Vec<Diagnostic>) -> Option<TilingSpec> {
    match syntax::from_ast::<TilingSpec>(a) {
        Ok(s) => Some(s),
        Err(e) => {
            diags.push(Diagnostic::at(e.span.unwrap_or(a.span), None, e.message));
            None
        }
    }
}

/// `graph` expanded into tiles per `spec` (and the command line's `over`); the graph as it is when
/// neither gives a tile size. Problems go to `diags` at `span` (the `tiling` field).
pub(super) fn expand(
    graph: Graph,
    spec: Option<&TilingSpec>,
    over: TileOverrides,
    span: Option<Span>,
    diags: &mut Vec<Diagnostic>,
) -> Option<Graph> {
    expand_or_say(graph, spec, over)
        .map_err(|m| {
            diags.push(match span {
                Some(s) => Diagnostic::at(s, None, m),
                None => Diagnostic::general(None, m),
            })
        })
        .ok()
}

fn expand_or_say(
    graph: Graph,
    spec: Option<&TilingSpec>,
    over: TileOverrides,
) -> Result<Graph, String> {
    let Some(spec) = spec else {
        if over.tile_m.is_some() || over.halo_m.is_some() {
            return Err("--tile-m and --halo-m need the graph's `tiling: Tiling(area: (min: (x, y), max: (x, y)), merge: [\"node\", ...])`: which part of the site to tile and which nodes to merge".into());
        }
        return Ok(graph);
    };
    let Some(tile_m) = over.tile_m.or(spec.tile_m) else {
        return Ok(graph);
    };
    check_spec(spec, tile_m, &graph.site)?;
    let (w, h) = spec.area.size();
    let (cols, rows) = ((w / tile_m).ceil(), (h / tile_m).ceil());
    if cols * rows > MAX_TILES as f64 {
        return Err(format!(
            "{cols} x {rows} tiles of {tile_m} m over the area: more than the {MAX_TILES} a run may have"
        ));
    }
    let merged = merge_points(&graph, spec)?;
    let per_tile = per_tile(&graph, &merged);
    check_per_tile(&graph, &merged, &per_tile)?;
    let (halo_m, halo_from) = match over.halo_m.or(spec.halo_m) {
        Some(h) if h.is_finite() && h >= 0.0 && h <= 10.0 * tile_m => (h, "given".to_owned()),
        Some(h) => {
            return Err(format!(
                "expected a finite halo from 0 to 10 tiles ({} m), found {h}",
                10.0 * tile_m
            ));
        }
        None => default_halo(&graph, &per_tile, spec.building_m, graph.site.cell_m),
    };
    let tiles = tiles_of(spec.area, tile_m, halo_m);
    let per_tile_nodes = per_tile.iter().filter(|p| **p).count();
    if graph.nodes.len() + per_tile_nodes * tiles.len() > MAX_TILED_NODES {
        return Err(format!(
            "{} tiles of {per_tile_nodes} tile nodes: more than the {MAX_TILED_NODES} nodes a run may have",
            tiles.len()
        ));
    }
    let phases = phases(&graph, &per_tile);
    let tiling = Tiling {
        tile_m,
        halo_m,
        halo_from,
        area: spec.area,
        tiles,
        phases: 1,
    };
    rewrite(graph, &merged, &per_tile, &phases, tiling)
}

/// Checks what the spec and the command line say, beside the graph.
fn check_spec(spec: &TilingSpec, tile_m: f64, site: &Site) -> Result<(), String> {
    spec.area
        .validate()
        .map_err(|m| format!("invalid `area`: {m}"))?;
    let cell = site.cell_m;
    let on_lattice = |v: f64| ((v / cell) - (v / cell).round()).abs() < 1e-6;
    if !(tile_m.is_finite() && tile_m > 0.0 && on_lattice(tile_m) && tile_m >= 8.0 * cell) {
        return Err(format!(
            "expected a tile size of at least 8 site cells and a whole number of them ({cell} m), found {tile_m}"
        ));
    }
    let corners = [
        spec.area.min.0,
        spec.area.min.1,
        spec.area.max.0,
        spec.area.max.1,
    ];
    if !corners.iter().all(|v| on_lattice(*v)) {
        return Err(format!(
            "expected the area's corners on the site's cell lattice (multiples of {cell} m), found min {:?} and max {:?}",
            spec.area.min, spec.area.max
        ));
    }
    if !(spec.building_m.is_finite() && spec.building_m >= 0.0 && spec.building_m <= 10_000.0) {
        return Err(format!(
            "expected `building_m` from 0 to 10000 m, found {}",
            spec.building_m
        ));
    }
    Ok(())
}

/// The nodes `tiling.merge` names, as a flag per node.
fn merge_points(graph: &Graph, spec: &TilingSpec) -> Result<Vec<bool>, String> {
    let mut merged = vec![false; graph.nodes.len()];
    for id in &spec.merge {
        let Some(i) = graph.index(id) else {
            let hint = did_you_mean(id, graph.nodes.iter().map(|n| n.id.as_str()))
                .map(|s| format!(" (did you mean `{s}`?)"))
                .unwrap_or_default();
            return Err(format!("`merge` names `{id}`, which is not a node{hint}"));
        };
        if merge_kind(graph.nodes[i].kind.output).is_none() {
            return Err(format!(
                "`merge` names `{id}`, a {:?}: only {MERGED_TYPES} are merged",
                graph.nodes[i].kind.output
            ));
        }
        merged[i] = true;
    }
    if let Some(n) = graph.nodes.iter().find(|n| n.id.contains('@')) {
        return Err(format!(
            "node `{}` has an `@` in its id, which a tiled run uses for its tile copies",
            n.id
        ));
    }
    Ok(merged)
}

/// Which nodes are made per tile: the windowed ones and what they feed, up to the merges.
fn per_tile(graph: &Graph, merged: &[bool]) -> Vec<bool> {
    let mut per = vec![false; graph.nodes.len()];
    for (i, n) in graph.nodes.iter().enumerate() {
        per[i] = n.kind.windowed || n.deps.iter().any(|&d| per[d] && !merged[d]);
    }
    per
}

/// A tiled graph must read a window, merge only tile nodes, and export only what is made once.
fn check_per_tile(graph: &Graph, merged: &[bool], per: &[bool]) -> Result<(), String> {
    if !per.iter().any(|p| *p) {
        let windowed: Vec<&str> = registry::kinds()
            .iter()
            .filter(|k| k.windowed)
            .map(|k| k.name)
            .collect();
        return Err(format!(
            "no node reads a tile: a tiled graph needs a windowed stage ({})",
            windowed.join(", ")
        ));
    }
    if let Some(n) = (0..per.len()).find(|&i| merged[i] && !per[i]) {
        return Err(format!(
            "`merge` names `{}`, which is made once: nothing windowed is upstream of it",
            graph.nodes[n].id
        ));
    }
    for (name, i) in &graph.outputs {
        if per[*i] && !merged[*i] {
            return Err(format!(
                "output {name:?} is node `{}`, which is made per tile: add it to `merge`",
                graph.nodes[*i].id
            ));
        }
    }
    Ok(())
}

/// The default halo: the largest sum of the stages' reaches along a chain of tile nodes, plus
/// half of `building_m`, rounded up to the cell lattice; and the sentence saying so.
fn default_halo(graph: &Graph, per: &[bool], building_m: f64, cell: f64) -> (f64, String) {
    let mut reach = vec![0.0f64; graph.nodes.len()];
    for (i, n) in graph.nodes.iter().enumerate() {
        if per[i] {
            let upstream = n.deps.iter().filter(|&&d| per[d]).map(|&d| reach[d]);
            reach[i] = n.params.reach_m() + upstream.fold(0.0, f64::max);
        }
    }
    let chain = reach.iter().copied().fold(0.0, f64::max);
    let halo = ((chain + building_m / 2.0) / cell).ceil() * cell;
    let from = format!(
        "the stages' largest reach along a chain of tile nodes ({chain} m) plus half of building_m ({} m)",
        building_m / 2.0
    );
    (halo, from)
}

/// Each node's phase (`Node::phase`): a tile node reads tile nodes in its own tile (same phase)
/// and nodes made once, which must be done before its phase starts; a node made once reads tile
/// nodes merged, after their phase.
fn phases(graph: &Graph, per: &[bool]) -> Vec<u32> {
    let mut phase = vec![0u32; graph.nodes.len()];
    for (i, n) in graph.nodes.iter().enumerate() {
        phase[i] = if per[i] {
            n.deps
                .iter()
                .map(|&d| if per[d] { phase[d] } else { phase[d] + 1 })
                .fold(1, u32::max)
        } else {
            n.deps.iter().map(|&d| phase[d]).fold(0, u32::max)
        };
    }
    phase
}

/// The tiles over `area`: cores of `tile_m` (the last row and column cut at the area's edge),
/// windows grown by `halo_m`.
fn tiles_of(area: Window, tile_m: f64, halo_m: f64) -> Vec<Tile> {
    let (w, h) = area.size();
    let cols = (w / tile_m - 1e-9).ceil().max(1.0) as usize;
    let rows = (h / tile_m - 1e-9).ceil().max(1.0) as usize;
    let mut tiles = Vec::with_capacity(cols * rows);
    for row in 0..rows {
        for col in 0..cols {
            let min = (
                area.min.0 + col as f64 * tile_m,
                area.min.1 + row as f64 * tile_m,
            );
            let max = (
                (min.0 + tile_m).min(area.max.0),
                (min.1 + tile_m).min(area.max.1),
            );
            let core = Window { min, max };
            tiles.push(Tile {
                name: format!("x{col}y{row}"),
                core,
                window: core.grown(halo_m),
            });
        }
    }
    tiles
}

/// The tiled graph: tile nodes copied per tile (`id@x1y0`), each merge point followed by its
/// merge under the point's own id, everything else once.
fn rewrite(
    graph: Graph,
    merged: &[bool],
    per: &[bool],
    phase: &[u32],
    mut tiling: Tiling,
) -> Result<Graph, String> {
    let tiles = &tiling.tiles;
    let n_tiles = tiles.len();
    let mut nodes: Vec<Node> = Vec::new();
    // Where each old node went: its one copy (or merge), and its per-tile copies.
    let mut once = vec![usize::MAX; graph.nodes.len()];
    let mut copies: Vec<Vec<usize>> = vec![Vec::new(); graph.nodes.len()];
    for (i, n) in graph.nodes.iter().enumerate() {
        if per[i] {
            for (t, tile) in tiles.iter().enumerate() {
                let inputs = n
                    .inputs
                    .iter()
                    .map(|list| {
                        list.iter()
                            .map(|&d| if per[d] { copies[d][t] } else { once[d] })
                            .collect()
                    })
                    .collect();
                copies[i].push(nodes.len());
                nodes.push(Node {
                    id: format!("{}@{}", n.id, tile.name),
                    kind: n.kind,
                    inputs,
                    deps: Vec::new(),
                    params: n.params.clone_box(),
                    files: n.files.clone(),
                    tile: Some(t),
                    window: Some(tile.window),
                    phase: phase[i],
                });
            }
            if merged[i] {
                once[i] = nodes.len();
                nodes.push(merge_node(n, &copies[i], tiles, phase[i])?);
            }
        } else {
            let inputs = n
                .inputs
                .iter()
                .map(|list| list.iter().map(|&d| once[d]).collect())
                .collect();
            once[i] = nodes.len();
            nodes.push(Node {
                id: n.id.clone(),
                kind: n.kind,
                inputs,
                deps: Vec::new(),
                params: n.params.clone_box(),
                files: n.files.clone(),
                tile: None,
                window: None,
                phase: phase[i],
            });
        }
    }
    debug_assert!(copies.iter().all(|c| c.is_empty() || c.len() == n_tiles));
    for n in &mut nodes {
        n.set_deps();
    }
    let outputs = graph
        .outputs
        .iter()
        .map(|(name, i)| (name.clone(), once[*i]))
        .collect();
    tiling.phases = phase
        .iter()
        .zip(per)
        .filter(|(_, p)| **p)
        .map(|(k, _)| *k)
        .max()
        .unwrap_or(1);
    Ok(Graph {
        path: graph.path,
        name: graph.name,
        site: graph.site,
        nodes,
        outputs,
        tiling: Some(tiling),
    })
}

/// The merge of node `n`'s tile copies `inputs`.
fn merge_node(n: &Node, inputs: &[usize], tiles: &[Tile], phase: u32) -> Result<Node, String> {
    let kind_name = merge_kind(n.kind.output).expect("merge points were checked");
    let kind: &'static Kind = registry::kind(kind_name).expect("merge kinds are registered");
    let p = MergeTilesParams {
        tiles: tiles
            .iter()
            .map(|t| TileCore {
                name: t.name.clone(),
                core: t.core,
            })
            .collect(),
    };
    let params = parse_params(kind, &p)?;
    Ok(Node {
        id: n.id.clone(),
        kind,
        inputs: vec![inputs.to_vec()],
        deps: Vec::new(),
        params,
        files: Vec::new(),
        tile: None,
        window: None,
        phase,
    })
}

/// The params of a merge node, through the kind's own parser (so they are erased as any
/// node's): written as the RON a graph would hold.
fn parse_params(
    kind: &'static Kind,
    p: &MergeTilesParams,
) -> Result<Box<dyn registry::Params>, String> {
    let window = |w: &Window| {
        format!(
            "(min: ({:?}, {:?}), max: ({:?}, {:?}))",
            w.min.0, w.min.1, w.max.0, w.max.1
        )
    };
    let tiles: Vec<String> = p
        .tiles
        .iter()
        .map(|t| format!("(name: {:?}, core: {})", t.name, window(&t.core)))
        .collect();
    let text = format!("(tiles: [{}])", tiles.join(", "));
    let ast = syntax::parse(&text, 0, 1, 1).map_err(|e| format!("merge params: {}", e.message))?;
    let params = (kind.parse)(&ast).map_err(|e| format!("merge params: {}", e.message))?;
    params
        .validate()
        .map_err(|e| format!("merge params: {}: {}", e.field, e.message))?;
    Ok(params)
}

/// The kinds whose nodes are radio work: one transmitter's map, or a trace of links.
pub const RADIO_KINDS: &[&str] = &["RadioMap", "Trace"];

impl Graph {
    /// The radio nodes made once (kinds [`RADIO_KINDS`]), in graph order: in a tiled run each
    /// is one task of the radio job array (`--radio I`), its work bounded by its transmitter's
    /// reach, not by the tiles.
    pub fn radio_nodes(&self) -> Vec<usize> {
        (0..self.nodes.len())
            .filter(|&i| {
                let n = &self.nodes[i];
                n.tile.is_none() && RADIO_KINDS.contains(&n.kind.name)
            })
            .collect()
    }

    /// The node `--radio I` makes: the `i`-th of [`Graph::radio_nodes`].
    pub fn radio_job(&self, i: usize) -> Result<usize, String> {
        let radio = self.radio_nodes();
        match radio.get(i) {
            Some(&n) => Ok(n),
            None if radio.is_empty() => Err(format!(
                "--radio {i}: the graph has no radio node (RadioMap or Trace)"
            )),
            None => Err(format!(
                "--radio: expected a radio node from 0 to {}, found {i}",
                radio.len() - 1
            )),
        }
    }

    /// The nodes one job of a tiled run makes: with `tile`, that tile's nodes (of `phase` only,
    /// when given); without, the nodes made once that tile jobs of the next phase wait for (those
    /// of `phase`, 0 by default: the shared upstream). What they need comes along as with
    /// `--target`. Errors name what was wrong with the request.
    pub fn tile_job(&self, tile: Option<usize>, phase: Option<u32>) -> Result<Vec<usize>, String> {
        let Some(tiling) = &self.tiling else {
            return Err("--tile and --phase need a tiled graph (its `tiling` with a tile size, or --tile-m)".into());
        };
        if let Some(t) = tile
            && t >= tiling.tiles.len()
        {
            return Err(format!(
                "expected a tile from 0 to {}, found {t}",
                tiling.tiles.len() - 1
            ));
        }
        if let Some(k) = phase
            && k > tiling.phases
        {
            return Err(format!(
                "expected a phase from 0 to {}, found {k}",
                tiling.phases
            ));
        }
        // Only a job of nodes made once asks who reads them.
        let consumers = std::cell::OnceCell::new();
        let feeds_tiles = |i: usize, k: u32| {
            consumers.get_or_init(|| self.consumers())[i]
                .iter()
                .any(|&c: &usize| self.nodes[c].tile.is_some() && self.nodes[c].phase == k + 1)
        };
        let picked: Vec<usize> = (0..self.nodes.len())
            .filter(|&i| {
                let n = &self.nodes[i];
                match tile {
                    Some(t) => n.tile == Some(t) && phase.is_none_or(|k| n.phase == k),
                    None => {
                        let k = phase.unwrap_or(0);
                        n.tile.is_none() && n.phase == k && feeds_tiles(i, k)
                    }
                }
            })
            .collect();
        Ok(picked)
    }
}
