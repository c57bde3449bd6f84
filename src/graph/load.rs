//! Graph file -> [`Graph`]: parse, apply `--set`, look up kinds, split inputs from params, check
//! edges, types, cycles, values and files. Every problem found is reported, not just the first.

use std::collections::hash_map::Entry;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use kodama_nodes::Site;
use kodama_nodes::io::safe_name::check_file_name;
use kodama_nodes::stage::{Arity, InputSpec};
use petgraph::algo::tarjan_scc;
use petgraph::graph::DiGraph;

use super::data_source::{data_source_of, missing_data_note};
use super::tiling::{TileOverrides, expand, tiling_spec};
use super::{Graph, InputFile, Node};
use crate::diag::{Diagnostic, GraphError, Sources};
use crate::registry::{self, Kind};
use crate::syntax::{self, Ast, DeError, Name, Span, Value, did_you_mean};

/// How to load a graph.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Resolve data paths against this folder instead of the graph file's.
    pub data_dir: Option<PathBuf>,
    /// `NODE.PARAM=VALUE` overrides, in order.
    pub sets: Vec<String>,
    /// Let data paths reach outside the graph file's folder (or `--data`): `..`, absolute paths,
    /// symlinks that lead elsewhere.
    pub allow_outside: bool,
    /// `--tile-m` and `--halo-m`: a tiled run of a graph with a `tiling` block.
    pub tiles: TileOverrides,
}

/// The largest graph file read: far beyond any real graph, and a bound on memory when the path
/// names something endless.
pub const MAX_GRAPH_BYTES: u64 = 64 << 20;

/// Reads a graph or sweep file as text, refusing one larger than [`MAX_GRAPH_BYTES`].
pub fn read_graph_text(path: &Path) -> Result<String, String> {
    use std::io::Read;
    // Regular files only, opened without blocking: a FIFO given as the graph would wait forever.
    let f = kodama_nodes::io::open::open_regular(path).map_err(|e| e.to_string())?;
    let mut bytes = Vec::new();
    f.take(MAX_GRAPH_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > MAX_GRAPH_BYTES {
        return Err(format!(
            "larger than {} MiB; a graph file is text a person writes",
            MAX_GRAPH_BYTES >> 20
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        format!(
            "not UTF-8 text (invalid byte at offset {})",
            e.utf8_error().valid_up_to()
        )
    })
}

struct RawNode {
    id: String,
    kind: Name,
    fields: Vec<(Name, Ast)>,
}

/// Loads and checks the graph at `path`.
pub fn load(path: &Path, opts: &LoadOptions) -> Result<Graph, GraphError> {
    let display = path.display().to_string();
    let text = read_graph_text(path)
        .map_err(|e| GraphError::general(&display, format!("cannot read the graph file: {e}")))?;
    let mut sources = Sources {
        items: vec![(display, text)],
    };
    for s in &opts.sets {
        sources.items.push((format!("--set {s}"), s.clone()));
    }
    let mut diags = Vec::new();
    let graph = check(path, opts, &sources, &mut diags);
    match graph {
        Some(g) if diags.is_empty() => Ok(g),
        _ => Err(GraphError {
            diagnostics: diags,
            sources,
        }),
    }
}

fn de_diag(e: DeError, fallback: Span, node: Option<&str>) -> Diagnostic {
    Diagnostic::at(e.span.unwrap_or(fallback), node, e.message)
}

/// The graph of the file in `sources` (item 0), its `--set` overrides applied: parsed, its site
/// and nodes checked, its outputs resolved, its nodes in topological order. None when anything
/// is wrong, every problem in `diags`.
fn check(
    path: &Path,
    opts: &LoadOptions,
    sources: &Sources,
    diags: &mut Vec<Diagnostic>,
) -> Option<Graph> {
    let ast = match syntax::parse(&sources.items[0].1, 0, 1, 1) {
        Ok(a) => a,
        Err(e) => {
            diags.push(Diagnostic::at(e.span, None, e.message));
            return None;
        }
    };
    let top = top_fields(&ast, diags)?;
    let site = site_of(&ast, top.site, diags);
    let tiling = top.tiling.map(|a| (a.span, tiling_spec(a, diags)));
    let Some(nodes_ast) = top.nodes else {
        diags.push(Diagnostic::at(
            ast.span,
            None,
            "missing field `nodes`: expected `nodes: { \"id\": Kind(...), ... }`",
        ));
        return None;
    };
    let mut raw = raw_nodes(nodes_ast, diags);
    apply_sets(&mut raw, opts, diags);
    add_report_nodes(&mut raw, top.outputs);

    // Kinds, inputs and params.
    let ids: Vec<&str> = raw.iter().map(|r| r.id.as_str()).collect();
    let index: HashMap<&str, usize> = ids.iter().enumerate().map(|(i, id)| (*id, i)).collect();
    let mut nodes: Vec<Option<Node>> = Vec::with_capacity(raw.len());
    let roots = data_root(path, opts);
    for r in &raw {
        nodes.push(build_node(r, &raw, &index, &roots, diags));
    }
    if let Some(a) = top.data
        && let Some(source) = data_source_of(a, diags)
    {
        let missing = roots.missing.borrow();
        if !missing.is_empty() {
            let note = missing_data_note(&source, &roots.base, &missing);
            diags.push(Diagnostic::at(a.span, None, note));
        }
    }

    let outputs = top
        .outputs
        .map(|a| check_outputs(a, &index, &raw, diags))
        .unwrap_or_default();
    if !diags.is_empty() {
        return None;
    }
    let nodes: Vec<Node> = nodes
        .into_iter()
        .map(|n| n.expect("no diagnostics means every node built"))
        .collect();
    let order = topo_order(&nodes, &raw, diags)?;
    let site = site?;
    let (nodes, outputs) = in_topological_order(nodes, &order, outputs);
    let name = folder_name(path, "graph");
    let graph = Graph {
        path: path.to_path_buf(),
        name,
        site,
        nodes,
        outputs,
        tiling: None,
    };
    let (span, spec) = match tiling {
        Some((span, Some(spec))) => (Some(span), Some(spec)),
        Some((_, None)) => return None,
        None => (None, None),
    };
    expand(graph, spec.as_ref(), opts.tiles, span, diags)
}

/// The fields of a graph file's `Graph(...)`, each as written, if given.
struct TopFields<'a> {
    site: Option<&'a Ast>,
    nodes: Option<&'a Ast>,
    outputs: Option<&'a Ast>,
    data: Option<&'a Ast>,
    tiling: Option<&'a Ast>,
}

/// The fields of the graph file's top value `ast`, which must be a `Graph(...)` (None, and a
/// diagnostic, when it is not); a diagnostic for each field it does not know.
fn top_fields<'a>(ast: &'a Ast, diags: &mut Vec<Diagnostic>) -> Option<TopFields<'a>> {
    let top = match &ast.v {
        Value::Struct { name, fields } if name.as_ref().is_none_or(|n| n.name == "Graph") => fields,
        _ => {
            diags.push(Diagnostic::at(
                ast.span,
                None,
                format!(
                    "expected `Graph(site: ..., nodes: {{...}}, outputs: {{...}})`, found {}",
                    ast.v.describe()
                ),
            ));
            return None;
        }
    };
    const TOP: &[&str] = &["site", "nodes", "outputs", "data", "tiling"];
    let mut fields = TopFields {
        site: None,
        nodes: None,
        outputs: None,
        data: None,
        tiling: None,
    };
    for (name, v) in top {
        match name.name.as_str() {
            "site" => fields.site = Some(v),
            "nodes" => fields.nodes = Some(v),
            "outputs" => fields.outputs = Some(v),
            "data" => fields.data = Some(v),
            "tiling" => fields.tiling = Some(v),
            other => diags.push(Diagnostic::at(
                name.span,
                None,
                unknown("field", other, TOP.iter().copied()),
            )),
        }
    }
    Some(fields)
}

/// The graph's site, from its `site` field (`site_ast`; the graph `ast` is where a missing one
/// is reported), parsed and checked; None, and a diagnostic, when it is missing or wrong.
fn site_of(ast: &Ast, site_ast: Option<&Ast>, diags: &mut Vec<Diagnostic>) -> Option<Site> {
    match site_ast {
        None => {
            diags.push(Diagnostic::at(ast.span, None, "missing field `site`: expected `site: Site(crs: \"EPSG:<code>\", origin: (x, y), cell_m: 0.5)`"));
            None
        }
        Some(a) => match syntax::from_ast::<Site>(a) {
            Err(e) => {
                diags.push(de_diag(e, a.span, None));
                None
            }
            Ok(site) => match kodama_nodes::io::crs::check_site(&site)
                .and_then(|()| check_site_cell(&site))
            {
                Err((field, msg)) => {
                    diags.push(Diagnostic::at(
                        field_span(a, field).unwrap_or(a.span),
                        None,
                        format!("invalid `{field}`: {msg}"),
                    ));
                    None
                }
                Ok(()) => Some(site),
            },
        },
    }
}

/// Where the nodes' data paths resolve: `--data`, else the graph file's folder (`.` when the
/// path has none).
fn data_root(path: &Path, opts: &LoadOptions) -> DataRoot {
    let base = opts
        .data_dir
        .clone()
        .unwrap_or_else(|| path.parent().map(Path::to_path_buf).unwrap_or_default());
    let base = if base.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        base
    };
    DataRoot::new(base, opts)
}

/// The nodes renumbered into topological `order` (`order[new]` = old index), their inputs and
/// the outputs pointing at the new indices, each node's deps the distinct nodes it takes.
fn in_topological_order(
    nodes: Vec<Node>,
    order: &[usize],
    outputs: Vec<(String, usize)>,
) -> (Vec<Node>, Vec<(String, usize)>) {
    let mut new_index = vec![0; nodes.len()];
    for (new, &old) in order.iter().enumerate() {
        new_index[old] = new;
    }
    let mut slots: Vec<Option<Node>> = nodes.into_iter().map(Some).collect();
    let nodes = order
        .iter()
        .map(|&old| {
            let mut n = slots[old].take().expect("each node once");
            for list in &mut n.inputs {
                for i in list.iter_mut() {
                    *i = new_index[*i];
                }
            }
            n.set_deps();
            n
        })
        .collect();
    let outputs = outputs
        .into_iter()
        .map(|(name, old)| (name, new_index[old]))
        .collect();
    (nodes, outputs)
}

/// The finest site cell accepted. Every raster of a graph is on the site's grid, so a cell far
/// below this (`1e-300`) asks any stage for more cells than memory holds, over any extent.
pub const MIN_SITE_CELL_M: f64 = 1e-3;

fn check_site_cell(site: &Site) -> Result<(), (&'static str, String)> {
    if site.cell_m < MIN_SITE_CELL_M {
        return Err((
            "cell_m",
            format!(
                "a cell of {:e} m is finer than the {MIN_SITE_CELL_M} m a site can take",
                site.cell_m
            ),
        ));
    }
    Ok(())
}

fn unknown<'a>(
    what: &str,
    word: &str,
    candidates: impl IntoIterator<Item = &'a str> + Clone,
) -> String {
    match did_you_mean(word, candidates.clone()) {
        Some(m) => format!("unknown {what} `{word}`; did you mean `{m}`?"),
        None => {
            let list: Vec<&str> = candidates.into_iter().collect();
            if list.is_empty() {
                format!("unknown {what} `{word}`")
            } else {
                format!(
                    "unknown {what} `{word}`; expected one of: {}",
                    list.join(", ")
                )
            }
        }
    }
}

fn field_span(a: &Ast, field: &str) -> Option<Span> {
    match &a.v {
        Value::Struct { fields, .. } => fields
            .iter()
            .find(|(n, _)| n.name == field)
            .map(|(_, v)| v.span),
        _ => None,
    }
}

fn raw_nodes(nodes_ast: &Ast, diags: &mut Vec<Diagnostic>) -> Vec<RawNode> {
    let Value::Map(entries) = &nodes_ast.v else {
        diags.push(Diagnostic::at(
            nodes_ast.span,
            None,
            format!(
                "expected `{{ \"id\": Kind(...), ... }}`, found {}",
                nodes_ast.v.describe()
            ),
        ));
        return Vec::new();
    };
    let mut out = Vec::new();
    for (k, v) in entries {
        let Value::Str(id) = &k.v else {
            diags.push(Diagnostic::at(
                k.span,
                None,
                format!("expected a node id string, found {}", k.v.describe()),
            ));
            continue;
        };
        if id.is_empty() || id.contains(['.', '"', '\n']) || id.trim() != id {
            diags.push(Diagnostic::at(k.span, None, format!("invalid node id {id:?}: expected a non-empty name without dots, quotes or surrounding spaces")));
            continue;
        }
        let (kind, fields) = match &v.v {
            Value::Struct {
                name: Some(n),
                fields,
            } => (n.clone(), fields.clone()),
            Value::Ident(n) => (
                Name {
                    name: n.clone(),
                    span: v.span,
                },
                Vec::new(),
            ),
            Value::Call { name, .. } => {
                diags.push(Diagnostic::at(
                    v.span,
                    Some(id),
                    format!(
                        "expected `{}(field: value, ...)` with named fields",
                        name.name
                    ),
                ));
                continue;
            }
            other => {
                diags.push(Diagnostic::at(
                    v.span,
                    Some(id),
                    format!(
                        "expected a node `Kind(field: value, ...)`, found {}",
                        other.describe()
                    ),
                ));
                continue;
            }
        };
        out.push(RawNode {
            id: id.clone(),
            kind,
            fields,
        });
    }
    out
}

fn apply_sets(raw: &mut [RawNode], opts: &LoadOptions, diags: &mut Vec<Diagnostic>) {
    for (k, s) in opts.sets.iter().enumerate() {
        let src = (k + 1) as u16;
        let at = |col: usize| Span {
            src,
            line: 1,
            col: col as u32,
        };
        let Some((lhs, value)) = s.split_once('=') else {
            diags.push(Diagnostic::at(at(1), None, "expected NODE.PARAM=VALUE"));
            continue;
        };
        let Some((node, param)) = lhs.split_once('.') else {
            // NODE=Kind(...): the node replaced by another definition (an ablation swaps a stage).
            replace_node(raw, lhs, value, src, diags);
            continue;
        };
        let Some(r) = raw.iter_mut().find(|r| r.id == node) else {
            let ids: Vec<String> = raw.iter().map(|r| r.id.clone()).collect();
            diags.push(Diagnostic::at(
                at(1),
                None,
                unknown("node", node, ids.iter().map(String::as_str)),
            ));
            continue;
        };
        let value_col = lhs.chars().count() + 2;
        // Shells eat quotes, so a value that is not RON (a path, say) is taken as a string.
        let v = syntax::parse(value, src, 1, value_col as u32).unwrap_or_else(|_| Ast {
            v: Value::Str(value.to_owned()),
            span: at(value_col),
        });
        // NODE.PARAM.KEY...=VALUE sets one entry of a map or struct param, keeping the rest.
        let mut path = param.split('.');
        let top = path.next().unwrap_or_default();
        let name = Name {
            name: top.to_owned(),
            span: at(node.chars().count() + 2),
        };
        let rest: Vec<&str> = path.collect();
        if rest.len() >= syntax::MAX_DEPTH {
            diags.push(Diagnostic::at(
                at(1),
                Some(node),
                format!(
                    "`{param}` is nested more than {} levels deep",
                    syntax::MAX_DEPTH
                ),
            ));
            continue;
        }
        match r.fields.iter_mut().find(|(n, _)| n.name == top) {
            Some(f) => {
                f.0 = name;
                if let Err(m) = set_at(&mut f.1, &rest, v) {
                    diags.push(Diagnostic::at(at(1), Some(node), m));
                }
            }
            None => r.fields.push((name, nest(&rest, v))),
        }
    }
}

/// `v` under the struct fields `path`, innermost last: `a.b=1` on a param left at its default.
fn nest(path: &[&str], v: Ast) -> Ast {
    path.iter().rev().fold(v, |inner, key| Ast {
        span: inner.span,
        v: Value::Struct {
            name: None,
            fields: vec![(
                Name {
                    name: (*key).to_owned(),
                    span: inner.span,
                },
                inner,
            )],
        },
    })
}

/// Replaces the value at `path` inside `target` (map entries by string key, struct fields by
/// name), adding the entry or field when missing.
fn set_at(target: &mut Ast, path: &[&str], v: Ast) -> Result<(), String> {
    let Some((key, rest)) = path.split_first() else {
        *target = v;
        return Ok(());
    };
    match &mut target.v {
        Value::Map(entries) => {
            match entries
                .iter_mut()
                .find(|(k, _)| matches!(&k.v, Value::Str(s) if s == key))
            {
                Some((_, val)) => set_at(val, rest, v),
                None => {
                    let k = Ast {
                        v: Value::Str((*key).to_owned()),
                        span: v.span,
                    };
                    entries.push((k, nest(rest, v)));
                    Ok(())
                }
            }
        }
        Value::Struct { fields, .. } => match fields.iter_mut().find(|(n, _)| n.name == *key) {
            Some((_, val)) => set_at(val, rest, v),
            None => {
                let n = Name {
                    name: (*key).to_owned(),
                    span: v.span,
                };
                fields.push((n, nest(rest, v)));
                Ok(())
            }
        },
        other => Err(format!(
            "`{key}` names an entry, but the value it is in is {}, not a map or struct",
            other.describe()
        )),
    }
}

/// `--set NODE=Kind(field: value, ...)`: the node's kind and fields replaced.
fn replace_node(
    raw: &mut [RawNode],
    node: &str,
    value: &str,
    src: u16,
    diags: &mut Vec<Diagnostic>,
) {
    let at = |col: usize| Span {
        src,
        line: 1,
        col: col as u32,
    };
    let Some(r) = raw.iter_mut().find(|r| r.id == node) else {
        let ids: Vec<String> = raw.iter().map(|r| r.id.clone()).collect();
        diags.push(Diagnostic::at(
            at(1),
            None,
            format!(
                "{} (NODE=Kind(...) replaces a node; NODE.PARAM=VALUE sets a param)",
                unknown("node", node, ids.iter().map(String::as_str))
            ),
        ));
        return;
    };
    let value_col = node.chars().count() + 2;
    match syntax::parse(value, src, 1, value_col as u32) {
        Ok(Ast {
            v:
                Value::Struct {
                    name: Some(kind),
                    fields,
                },
            ..
        }) => {
            r.kind = kind;
            r.fields = fields;
        }
        Ok(Ast {
            v: Value::Ident(kind),
            span,
        }) => {
            r.kind = Name { name: kind, span };
            r.fields = Vec::new();
        }
        Ok(other) => diags.push(Diagnostic::at(
            other.span,
            Some(node),
            format!(
                "expected a node definition `Kind(field: value, ...)`, found {}",
                other.v.describe()
            ),
        )),
        Err(e) => diags.push(Diagnostic::at(e.span, Some(node), e.message)),
    }
}

/// Where a graph's data paths resolve, and whether they may leave it.
struct DataRoot {
    base: PathBuf,
    /// `base` with symlinks resolved, when it exists.
    canonical: Option<PathBuf>,
    /// What `base` is, for messages.
    what: &'static str,
    allow_outside: bool,
    /// The resolved paths found missing, for the graph's data-source note.
    missing: std::cell::RefCell<Vec<PathBuf>>,
}

impl DataRoot {
    fn new(base: PathBuf, opts: &LoadOptions) -> DataRoot {
        DataRoot {
            canonical: std::fs::canonicalize(&base).ok(),
            base,
            what: if opts.data_dir.is_some() {
                "--data"
            } else {
                "the graph file's folder"
            },
            allow_outside: opts.allow_outside,
            missing: Default::default(),
        }
    }

    /// Resolves `written` and checks it: inside the root (unless allowed out), existing, and a
    /// regular file or a folder of them. Never opens a file, so a FIFO cannot hang the load.
    fn resolve(&self, written: &str, field: &str) -> (PathBuf, Result<(), String>) {
        let w = Path::new(written);
        if w.is_absolute() && !self.allow_outside {
            let msg = format!(
                "`{field}` is the absolute path {written}; data paths are relative to {} ({}), \
                 or pass --allow-outside to read it",
                self.what,
                self.base.display()
            );
            return (w.to_path_buf(), Err(msg));
        }
        let path = if w.is_absolute() {
            w.to_path_buf()
        } else {
            self.base.join(w)
        };
        if std::fs::symlink_metadata(&path).is_err() {
            self.missing.borrow_mut().push(path.clone());
            let msg = format!(
                "file not found: {} (`{field}` resolves against {})",
                path.display(),
                self.what
            );
            return (path, Err(msg));
        }
        if !self.allow_outside {
            let canonical = std::fs::canonicalize(&path);
            let inside = match (&canonical, &self.canonical) {
                (Ok(c), Some(root)) => c.starts_with(root),
                _ => false,
            };
            if !inside {
                let target = canonical
                    .map(|c| c.display().to_string())
                    .unwrap_or_else(|e| format!("nowhere ({e})"));
                let msg = format!(
                    "`{field}` = {written:?} leads outside {} ({}) to {target}; pass \
                     --allow-outside to read it",
                    self.what,
                    self.base.display()
                );
                return (path, Err(msg));
            }
        }
        let checked = check_input_kind(&path, written, !self.allow_outside)
            .map_err(|e| format!("`{field}` ({}): {e}", path.display()));
        (path, checked)
    }
}

/// Extensions of formats that are always single files: a folder with one where a data file was
/// meant is refused when the graph loads, not when a stage trips over it.
const FILE_EXTENSIONS: &[&str] = &[
    "las", "laz", "csv", "tif", "tiff", "hgt", "xyz", "txt", "geojson", "pbf", "osm", "xml", "ply",
    "glb", "b3dm", "json", "jsonl", "png", "jpg", "jpeg", "exr",
];

/// A declared input must be a regular file, or a folder holding only regular files and folders.
/// FIFOs, sockets and devices are refused before anything reads them. With `contained`, a symlink
/// inside a folder must not lead out of it.
fn check_input_kind(path: &Path, written: &str, contained: bool) -> Result<(), String> {
    let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
    if meta.is_file() {
        return Ok(());
    }
    if meta.is_dir() {
        let ext = Path::new(written)
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        if let Some(ext) = ext.filter(|e| FILE_EXTENSIONS.contains(&e.as_str())) {
            return Err(format!("expected a .{ext} file, found a folder"));
        }
        return crate::cache::check_folder(path, contained).map_err(|e| e.to_string());
    }
    Err(format!(
        "expected a regular file or a folder, found {}",
        crate::cache::describe_file_type(&meta.file_type())
    ))
}

/// The node `r` as the engine runs it: its kind, its inputs resolved to node indices, its params
/// parsed and validated, its declared files resolved; None (with every problem in `diags`) when
/// any of these fails.
fn build_node(
    r: &RawNode,
    raw: &[RawNode],
    index: &HashMap<&str, usize>,
    roots: &DataRoot,
    diags: &mut Vec<Diagnostic>,
) -> Option<Node> {
    let Some(kind) = registry::kind(&r.kind.name) else {
        let names = registry::kinds().iter().map(|k| k.name);
        diags.push(Diagnostic::at(
            r.kind.span,
            Some(r.id.as_str()),
            unknown("node kind", &r.kind.name, names),
        ));
        return None;
    };
    let before = diags.len();
    let b = NodeBuild {
        r,
        raw,
        index,
        kind,
    };
    let (inputs, params) = b.inputs_and_params(diags);
    b.check_required_inputs(&inputs, diags);
    if !b.params_finite(&params, diags) {
        return None;
    }
    let parsed = b.parse_params(&params, diags)?;
    let files = b.declared_files(parsed.as_ref(), &params, roots, diags);
    if diags.len() > before {
        return None;
    }
    Some(Node {
        id: r.id.clone(),
        kind,
        inputs,
        deps: Vec::new(),
        params: parsed,
        files,
        tile: None,
        window: None,
        phase: 0,
    })
}

/// One raw node being built into a [`Node`] of its `kind`, with the graph's raw nodes and their
/// indices by id to resolve its inputs against.
struct NodeBuild<'a> {
    r: &'a RawNode,
    raw: &'a [RawNode],
    index: &'a HashMap<&'a str, usize>,
    kind: &'static Kind,
}

impl NodeBuild<'_> {
    /// The node id, as diagnostics name it.
    fn id(&self) -> Option<&str> {
        Some(self.r.id.as_str())
    }

    /// The node's fields sorted into inputs (per input slot, the indices of the nodes named) and
    /// params (every field that is not an input). A step of its own: the kind says which is
    /// which, and only inputs refer to other nodes.
    fn inputs_and_params(
        &self,
        diags: &mut Vec<Diagnostic>,
    ) -> (Vec<Vec<usize>>, Vec<(Name, Ast)>) {
        let kind = self.kind;
        let mut inputs = vec![Vec::new(); kind.inputs.len()];
        let mut params = Vec::new();
        for (name, v) in &self.r.fields {
            let Some(slot) = kind.inputs.iter().position(|s| s.name == name.name) else {
                params.push((name.clone(), v.clone()));
                continue;
            };
            let spec = kind.inputs[slot];
            let Some(refs) = self.input_refs(v, spec, diags) else {
                continue;
            };
            for a in refs {
                if let Some(t) = self.input_node(a, spec, diags) {
                    inputs[slot].push(t);
                }
            }
        }
        (inputs, params)
    }

    /// The references an input's value holds, by its arity: none for `None`, one for an id or
    /// `Some(id)`, each of a list; None (and a diagnostic) for any other shape.
    fn input_refs<'v>(
        &self,
        v: &'v Ast,
        spec: InputSpec,
        diags: &mut Vec<Diagnostic>,
    ) -> Option<Vec<&'v Ast>> {
        Some(match (&v.v, spec.arity) {
            (Value::Ident(n), Arity::Optional) if n == "None" => vec![],
            (Value::Str(_) | Value::Ident(_), _) => vec![v],
            (Value::Call { name: n, args }, Arity::Optional)
                if n.name == "Some" && args.len() == 1 =>
            {
                vec![&args[0]]
            }
            (Value::List(items), Arity::Many) => items.iter().collect(),
            _ => {
                let expected = match spec.arity {
                    Arity::Many => "a list of node ids",
                    _ => "a node id string",
                };
                diags.push(Diagnostic::at(
                    v.span,
                    self.id(),
                    format!(
                        "input `{}` expects {expected} ({} nodes), found {}",
                        spec.name,
                        spec.ty,
                        v.v.describe()
                    ),
                ));
                return None;
            }
        })
    }

    /// The index of the node reference `a` names for input `spec`; None (and a diagnostic) when
    /// it is not an id string, names no node, or names a node of another output type.
    fn input_node(&self, a: &Ast, spec: InputSpec, diags: &mut Vec<Diagnostic>) -> Option<usize> {
        let (raw, id) = (self.raw, self.id());
        let (Value::Str(target) | Value::Ident(target)) = &a.v else {
            diags.push(Diagnostic::at(
                a.span,
                id,
                format!(
                    "input `{}` expects a node id string, found {}",
                    spec.name,
                    a.v.describe()
                ),
            ));
            return None;
        };
        let Some(&t) = self.index.get(target.as_str()) else {
            let names = referable(raw);
            let names = names.iter().map(String::as_str);
            diags.push(Diagnostic::at(
                a.span,
                id,
                format!("input `{}`: {}", spec.name, unknown("node", target, names)),
            ));
            return None;
        };
        let produced = registry::kind(&raw[t].kind.name).map(|k| k.output);
        if let Some(out) = produced.filter(|o| *o != spec.ty) {
            diags.push(Diagnostic::at(
                a.span,
                id,
                format!(
                    "input `{}` expects a {} node, but \"{target}\" ({}) produces {out}",
                    spec.name, spec.ty, raw[t].kind.name
                ),
            ));
            return None;
        }
        Some(t)
    }

    /// A diagnostic for every input taking exactly one node that the node leaves out.
    fn check_required_inputs(&self, inputs: &[Vec<usize>], diags: &mut Vec<Diagnostic>) {
        let r = self.r;
        for (slot, spec) in self.kind.inputs.iter().enumerate() {
            if spec.arity == Arity::One
                && inputs[slot].is_empty()
                && !r.fields.iter().any(|(n, _)| n.name == spec.name)
            {
                diags.push(Diagnostic::at(
                    r.kind.span,
                    self.id(),
                    format!(
                        "missing input `{}`: expected the id of a {} node ({})",
                        spec.name, spec.ty, spec.doc
                    ),
                ));
            }
        }
    }

    /// Whether every number in the params is finite; a diagnostic for each that is not. A step
    /// of its own: a non-finite value stops the node before its params are parsed.
    fn params_finite(&self, params: &[(Name, Ast)], diags: &mut Vec<Diagnostic>) -> bool {
        let before_values = diags.len();
        for (name, v) in params {
            let mut bad = Vec::new();
            non_finite(v, &mut bad);
            for (span, x) in bad {
                diags.push(Diagnostic::at(
                    span,
                    self.id(),
                    format!(
                        "`{}`: {x} can never run; expected a finite number",
                        name.name
                    ),
                ));
            }
        }
        diags.len() <= before_values
    }

    /// The span of param `field` as written, else the node's kind.
    fn param_span(&self, params: &[(Name, Ast)], field: &str) -> Span {
        params
            .iter()
            .find(|(n, _)| n.name == field)
            .map(|(_, v)| v.span)
            .unwrap_or(self.r.kind.span)
    }

    /// The params parsed into the kind's typed struct (None, and a diagnostic, when they do not
    /// parse), and validated (a diagnostic at the offending field when they are not valid).
    fn parse_params(
        &self,
        params: &[(Name, Ast)],
        diags: &mut Vec<Diagnostic>,
    ) -> Option<Box<dyn registry::Params>> {
        let r = self.r;
        let params_ast = Ast {
            v: Value::Struct {
                name: None,
                fields: params.to_vec(),
            },
            span: r.kind.span,
        };
        let parsed = match (self.kind.parse)(&params_ast) {
            Ok(p) => p,
            Err(e) => {
                diags.push(de_diag(e, r.kind.span, self.id()));
                return None;
            }
        };
        if let Err(e) = parsed.validate() {
            diags.push(Diagnostic::at(
                self.param_span(params, e.field),
                self.id(),
                format!("invalid `{}`: {}", e.field, e.message),
            ));
        }
        Some(parsed)
    }

    /// The files the parsed params declare, resolved against the data root; a diagnostic at the
    /// naming field for each that is refused.
    fn declared_files(
        &self,
        parsed: &dyn registry::Params,
        params: &[(Name, Ast)],
        roots: &DataRoot,
        diags: &mut Vec<Diagnostic>,
    ) -> Vec<InputFile> {
        let mut files = Vec::new();
        for f in parsed.files() {
            let (path, checked) = roots.resolve(&f.path, f.field);
            if let Err(msg) = checked {
                diags.push(Diagnostic::at(
                    self.param_span(params, f.field),
                    self.id(),
                    msg,
                ));
            }
            files.push(InputFile {
                field: f.field,
                written: f.path,
                path,
            });
        }
        files
    }
}

/// A node for every report a graph names (`"carved.outcomes"`: the report `outcomes` of the node
/// `carved`), as an input or an output, unless a node of that id is written in the graph. Its one
/// input is the node making the report, so it is scheduled after it and takes its type checks.
fn add_report_nodes(raw: &mut Vec<RawNode>, outputs: Option<&Ast>) {
    let mut named: Vec<&Ast> = Vec::new();
    for r in raw.iter() {
        let Some(kind) = registry::kind(&r.kind.name) else {
            continue;
        };
        for (field, v) in &r.fields {
            if kind.inputs.iter().any(|s| s.name == field.name) {
                node_refs(v, &mut named);
            }
        }
    }
    if let Some(Ast {
        v: Value::Map(entries),
        ..
    }) = outputs
    {
        named.extend(entries.iter().map(|(_, v)| v));
    }
    let mut added: Vec<RawNode> = Vec::new();
    for a in named {
        let (Value::Str(target) | Value::Ident(target)) = &a.v else {
            continue;
        };
        if raw.iter().chain(&added).any(|r| r.id == *target) {
            continue;
        }
        let Some((of, report)) = target.rsplit_once('.') else {
            continue;
        };
        let Some(kind) = raw
            .iter()
            .find(|r| r.id == of)
            .and_then(|r| registry::kind(&r.kind.name))
            .and_then(|k| registry::report_kind(k, report))
        else {
            continue;
        };
        added.push(RawNode {
            id: target.clone(),
            kind: Name {
                name: kind.name.to_string(),
                span: a.span,
            },
            fields: vec![(
                Name {
                    name: Kind::REPORT_OF.to_string(),
                    span: a.span,
                },
                Ast {
                    v: Value::Str(of.to_string()),
                    span: a.span,
                },
            )],
        });
    }
    raw.extend(added);
}

/// What an input or an output may name: every node id, and every report of every node
/// (`"carved.outcomes"`).
fn referable(raw: &[RawNode]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in raw {
        if !out.contains(&r.id) {
            out.push(r.id.clone());
        }
        let reports = registry::kind(&r.kind.name).map_or(&[][..], |k| k.reports);
        for rep in reports {
            let name = format!("{}.{}", r.id, rep.name);
            if !out.contains(&name) {
                out.push(name);
            }
        }
    }
    out
}

/// The node references in an input's value: a string, a list of them, `Some(..)`.
fn node_refs<'a>(v: &'a Ast, out: &mut Vec<&'a Ast>) {
    match &v.v {
        Value::Str(_) | Value::Ident(_) => out.push(v),
        Value::List(items) => items.iter().for_each(|a| node_refs(a, out)),
        Value::Call { args, .. } => args.iter().for_each(|a| node_refs(a, out)),
        _ => {}
    }
}

/// Every non-finite number in `a` (`inf`, `NaN`, or a literal too large for an f64), with where
/// it is. No stage takes one: an infinite size or count would ask for unbounded memory or time,
/// and NaN fails every comparison a check would make.
fn non_finite(a: &Ast, out: &mut Vec<(Span, f64)>) {
    match &a.v {
        Value::Float(x) if !x.is_finite() => out.push((a.span, *x)),
        Value::List(items) | Value::Tuple(items) | Value::Call { args: items, .. } => {
            items.iter().for_each(|i| non_finite(i, out))
        }
        Value::Map(entries) => entries.iter().for_each(|(k, v)| {
            non_finite(k, out);
            non_finite(v, out);
        }),
        Value::Struct { fields, .. } => fields.iter().for_each(|(_, v)| non_finite(v, out)),
        _ => {}
    }
}

fn check_outputs(
    a: &Ast,
    index: &HashMap<&str, usize>,
    raw: &[RawNode],
    diags: &mut Vec<Diagnostic>,
) -> Vec<(String, usize)> {
    let Value::Map(entries) = &a.v else {
        diags.push(Diagnostic::at(
            a.span,
            None,
            format!(
                "expected `{{ \"name\": \"node id\", ... }}`, found {}",
                a.v.describe()
            ),
        ));
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut files: HashMap<String, String> = HashMap::new();
    for (k, v) in entries {
        let (Value::Str(name), Value::Str(node)) = (&k.v, &v.v) else {
            diags.push(Diagnostic::at(
                k.span,
                None,
                "expected `\"output name\": \"node id\"`",
            ));
            continue;
        };
        // A leading dot is refused too: hidden names are the engine's (manifest, temp files).
        let valid = check_file_name(name).and_then(|()| match name.starts_with('.') {
            true => Err(format!("{name:?} starts with a dot")),
            false => Ok(()),
        });
        if let Err(m) = valid {
            diags.push(Diagnostic::at(
                k.span,
                None,
                format!("invalid output name: {m}"),
            ));
            continue;
        }
        match index.get(node.as_str()) {
            Some(&i) => {
                let ty = registry::kind(&raw[i].kind.name).map(|k| k.output);
                match ty.map(|t| kodama_nodes::io::export::output_file(name, t)) {
                    Some(Err(m)) => diags.push(Diagnostic::at(
                        k.span,
                        None,
                        format!("output \"{name}\": {m}"),
                    )),
                    Some(Ok((file, _))) => {
                        // Compared without case: one file on macOS and Windows.
                        match files.entry(file.to_lowercase()) {
                            Entry::Occupied(first) => diags.push(Diagnostic::at(
                                k.span,
                                None,
                                format!(
                                    "output \"{name}\" writes {file}, as output \"{}\" does; \
                                     each output needs its own file",
                                    first.get()
                                ),
                            )),
                            Entry::Vacant(slot) => {
                                slot.insert(name.clone());
                                out.push((name.clone(), i));
                            }
                        }
                    }
                    None => out.push((name.clone(), i)),
                }
            }
            None => diags.push(Diagnostic::at(
                v.span,
                None,
                format!(
                    "output \"{name}\": {}",
                    unknown("node", node, referable(raw).iter().map(String::as_str))
                ),
            )),
        }
    }
    out
}

/// Kahn's algorithm, taking the earliest ready node in file order; on a cycle, reports one.
fn topo_order(nodes: &[Node], raw: &[RawNode], diags: &mut Vec<Diagnostic>) -> Option<Vec<usize>> {
    let n = nodes.len();
    let mut indegree = vec![0usize; n];
    let mut consumers = vec![Vec::new(); n];
    for (i, node) in nodes.iter().enumerate() {
        let deps: BTreeSet<usize> = node.inputs.iter().flatten().copied().collect();
        indegree[i] = deps.len();
        for d in deps {
            consumers[d].push(i);
        }
    }
    let mut ready: BTreeSet<usize> = (0..n).filter(|&i| indegree[i] == 0).collect();
    let mut order = Vec::with_capacity(n);
    while let Some(i) = ready.pop_first() {
        order.push(i);
        for &c in &consumers[i] {
            indegree[c] -= 1;
            if indegree[c] == 0 {
                ready.insert(c);
            }
        }
    }
    if order.len() == n {
        return Some(order);
    }
    let mut g = DiGraph::<usize, ()>::new();
    let idx: Vec<_> = (0..n).map(|i| g.add_node(i)).collect();
    for (i, node) in nodes.iter().enumerate() {
        for &d in node.inputs.iter().flatten() {
            g.add_edge(idx[d], idx[i], ());
        }
    }
    let scc = tarjan_scc(&g)
        .into_iter()
        .find(|c| c.len() > 1 || g.contains_edge(c[0], c[0]))
        .expect("a graph without a topological order has a cycle");
    let members: BTreeSet<usize> = scc.iter().map(|&x| g[x]).collect();
    // Walk the cycle from its first member (in file order), following edges inside the component.
    let start = *members.first().expect("non-empty component");
    let mut path = vec![start];
    let mut seen = BTreeMap::from([(start, 0usize)]);
    let mut cur = start;
    loop {
        let next = consumers[cur]
            .iter()
            .copied()
            .filter(|c| members.contains(c))
            .min()
            .expect("cycle member has a successor in the cycle");
        if let Some(&pos) = seen.get(&next) {
            path.push(next);
            path.drain(..pos);
            break;
        }
        seen.insert(next, path.len());
        path.push(next);
        cur = next;
    }
    let text: Vec<String> = path.iter().map(|&i| format!("\"{}\"", raw[i].id)).collect();
    diags.push(Diagnostic::at(
        raw[path[0]].kind.span,
        Some(&raw[path[0]].id),
        format!("cycle: {}", text.join(" -> ")),
    ));
    None
}

/// The name a file gives the folder its outputs go to by default (`out/<name>`): its stem, or
/// `fallback` where the stem names no file of its own (`...ron` has the stem `..`, which would
/// put the outputs in the working folder's parent).
pub fn folder_name(path: &std::path::Path, fallback: &str) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| kodama_nodes::io::safe_name::check_file_name(s).is_ok())
        .unwrap_or_else(|| fallback.into())
}
