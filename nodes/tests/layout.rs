//! The crate's layout, checked by reading the sources (ARCHITECTURE.md, "Code map"):
//!
//! - the crate's rooms stand in one order, from the bottom up ([`LAYERS`]): a file may use its own
//!   room and the rooms below it, never one above (so no circle between rooms can form);
//! - the stages (`stages/**`, `synth/**`) stand on top, and no stage imports another stage;
//! - inside a folder, its files and subfolders import each other without circles, except the
//!   circles named in [`KNOWN_CIRCLES`], each with its reason;
//! - only the crate's root files sit at `nodes/src/` top level.
//!
//! A path counts wherever it is written in code or in a doc comment: `use` lines (grouped ones
//! too), qualified calls, doc links, tests. Plain `//` comments do not count.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The rooms of `nodes/src`, from the bottom up: each may use only itself and those before it.
/// Root files are rooms of their own; `stages` and `synth` share the top, and `lib.rs` (which
/// lists the stages for the registry) stands above everything.
const LAYERS: &[&[&str]] = &[
    &["rng"],
    &["params"],
    &["artifact"],
    &["site"],
    &["stage"],
    &["raster"],
    &["geom"],
    &["rf"],
    &["io"],
    &["buildings"],
    &["street"],
    &["stages", "synth"],
    &["lib"],
];

/// Circles between the files of one folder that are kept on purpose, as (folder, the circle's
/// members sorted, the reason). A circle not listed here fails the test; so does a listed one that
/// no longer exists, so the list cannot go stale.
const KNOWN_CIRCLES: &[(&str, &[&str], &str)] = &[];

/// The files allowed at `nodes/src/` top level.
const ROOT_FILES: &[&str] = &["lib.rs", "stage.rs", "params.rs", "site.rs", "rng.rs"];

/// The room of a crate-level name (`geom`, `params`), as its index in [`LAYERS`].
fn layer(name: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&name))
}

/// A file's module path from the crate root: `geom/wide_bvh/packet.rs` -> `[geom, wide_bvh,
/// packet]`, `street/relief/mod.rs` -> `[street, relief]`.
fn module_of(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().map(String::as_str) == Some("mod") {
        parts.pop();
    }
    parts
}

/// The text a reader of paths should see: code and doc comments, with plain `//` comments and
/// string contents blanked (kept as spaces, so offsets still give line numbers).
fn scannable(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.split_inclusive('\n') {
        let t = line.trim_start();
        if t.starts_with("///") || t.starts_with("//!") {
            out.push_str(line);
            continue;
        }
        let mut in_str = false;
        let mut prev = ' ';
        let mut cut = false;
        for c in line.chars() {
            if cut {
                out.push(if c == '\n' { '\n' } else { ' ' });
                continue;
            }
            if !in_str && c == '/' && prev == '/' {
                out.pop();
                out.push(' ');
                out.push(' ');
                cut = true;
                continue;
            }
            if c == '"' && prev != '\\' {
                in_str = !in_str;
            }
            out.push(if in_str && c != '"' { ' ' } else { c });
            prev = c;
        }
    }
    out
}

/// Expands one written path after a root (`geom::{raycast::X, mesh_check}`) into full paths.
fn expand(rest: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut head = Vec::new();
    let mut word = String::new();
    let mut chars = rest.char_indices().peekable();
    while let Some((i, c)) = chars.next() {
        if c.is_alphanumeric() || c == '_' {
            word.push(c);
        } else if c == ':' && chars.peek().map(|p| p.1) == Some(':') {
            chars.next();
            head.push(std::mem::take(&mut word));
        } else if c == '{' && word.is_empty() {
            // A group: split its top-level items and expand each under the head.
            let mut depth = 1;
            let mut j = i + 1;
            let bytes = rest.as_bytes();
            let mut start = j;
            while j < rest.len() && depth > 0 {
                match bytes[j] {
                    b'{' => depth += 1,
                    b'}' => depth -= 1,
                    b',' if depth == 1 => {
                        for tail in expand(&rest[start..j]) {
                            out.push(head.iter().cloned().chain(tail).collect());
                        }
                        start = j + 1;
                    }
                    _ => {}
                }
                j += 1;
            }
            let end = j.saturating_sub(1).max(start);
            for tail in expand(&rest[start..end]) {
                out.push(head.iter().cloned().chain(tail).collect());
            }
            return out;
        } else if c.is_whitespace() && word.is_empty() && head.is_empty() {
            continue;
        } else {
            break;
        }
    }
    if !word.is_empty() {
        head.push(word);
    }
    if !head.is_empty() {
        out.push(head);
    }
    out
}

/// Where a path is written: what the file runs, what its docs link to, or its tests.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Code,
    Doc,
    Test,
}

/// Every crate path a file names, with its line: `crate::`, `$crate::`, `kodama_nodes::`, and
/// `super::` resolved against the file's module (inside a file's `mod tests`, `super::` is the
/// file itself; a name that is no module of the crate is dropped later).
fn paths_in(text: &str, module: &[String]) -> Vec<(usize, Vec<String>, Kind)> {
    let text = scannable(text);
    let line_at = |off: usize| text[..off].matches('\n').count() + 1;
    let tests_from = text.find("#[cfg(test)]").unwrap_or(text.len());
    let mut found = Vec::new();
    for root in ["crate::", "kodama_nodes::", "super::"] {
        let mut from = 0;
        while let Some(i) = text[from..].find(root) {
            let at = from + i;
            from = at + root.len();
            let before = text[..at].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            for mut p in expand(&text[from..]) {
                if root == "super::" {
                    let mut base: Vec<String> = if at > tests_from {
                        module.to_vec()
                    } else {
                        module[..module.len().saturating_sub(1)].to_vec()
                    };
                    // `super::super::x`
                    while p.first().map(String::as_str) == Some("super") {
                        p.remove(0);
                        base.pop();
                    }
                    if p.first().is_none_or(|s| s == "*") {
                        continue;
                    }
                    base.extend(p);
                    p = base;
                }
                let line = line_at(at);
                let kind = if at > tests_from {
                    Kind::Test
                } else if text.lines().nth(line - 1).is_some_and(|l| {
                    let t = l.trim_start();
                    t.starts_with("///") || t.starts_with("//!")
                }) {
                    Kind::Doc
                } else {
                    Kind::Code
                };
                found.push((line, p, kind));
            }
        }
    }
    found
}

/// The crate's module tree, as the set of module paths that are files.
fn modules(files: &[(PathBuf, String)]) -> BTreeSet<Vec<String>> {
    files.iter().map(|(rel, _)| module_of(rel)).collect()
}

/// The longest prefix of `path` that is a module of the crate.
fn resolve(path: &[String], known: &BTreeSet<Vec<String>>) -> Option<Vec<String>> {
    (1..=path.len())
        .rev()
        .map(|n| path[..n].to_vec())
        .find(|p| known.contains(p))
}

/// The stage module a module path lies in (`stages::buildings::roof_clean`, `synth::synth_city`).
fn stage_module(m: &[String]) -> Option<String> {
    match m.first().map(String::as_str) {
        Some("stages") if m.len() >= 3 => Some(m[..3].join("::")),
        Some("synth") if m.len() >= 2 => Some(m[..2].join("::")),
        _ => None,
    }
}

/// One resolved reference from a file to a module of the crate.
struct Use {
    file: PathBuf,
    line: usize,
    from: Vec<String>,
    to: Vec<String>,
    kind: Kind,
}

fn uses(files: &[(PathBuf, String)]) -> Vec<Use> {
    let known = modules(files);
    let mut out = Vec::new();
    for (rel, text) in files {
        let from = module_of(rel);
        for (line, p, kind) in paths_in(text, &from) {
            if let Some(to) = resolve(&p, &known) {
                if to != from {
                    out.push(Use {
                        file: rel.clone(),
                        line,
                        from: from.clone(),
                        to,
                        kind,
                    });
                }
            }
        }
    }
    out
}

/// Breaches of the order between rooms and of the stages' independence, one message each.
fn order_violations(files: &[(PathBuf, String)]) -> Vec<String> {
    let mut out = Vec::new();
    for (rel, _) in files {
        if rel.components().count() == 1 && !ROOT_FILES.contains(&rel.to_string_lossy().as_ref()) {
            out.push(format!(
                "nodes/src/{}: only the crate's root files ({}) sit at nodes/src/ top level; put this module in the room of its step",
                rel.display(),
                ROOT_FILES.join(", ")
            ));
        }
    }
    for u in uses(files) {
        let shown = Path::new("nodes/src").join(&u.file);
        let (a, b) = (&u.from[0], &u.to[0]);
        let (Some(la), Some(lb)) = (layer(a), layer(b)) else {
            out.push(format!(
                "{}:{}: `{a}` or `{b}` is in no layer of nodes/tests/layout.rs's LAYERS: add the new room where it stands in the order (and to ARCHITECTURE.md)",
                shown.display(),
                u.line
            ));
            continue;
        };
        if lb > la {
            let what = |r: &str| {
                if ROOT_FILES.contains(&format!("{r}.rs").as_str()) {
                    format!("the root file {r}.rs")
                } else {
                    format!("{r}/")
                }
            };
            out.push(format!(
                "{}:{}: uses `{}`, but {} stands below {} in the layers (ARCHITECTURE.md, \"Code map\"): a room never imports a room above it; move what both need down into {} or below",
                shown.display(),
                u.line,
                u.to.join("::"),
                what(a),
                what(b),
                what(a),
            ));
        }
        if let (Some(sa), Some(sb)) = (stage_module(&u.from), stage_module(&u.to)) {
            if sa != sb {
                out.push(format!(
                    "{}:{}: the stage `{sa}` uses the stage `{sb}`: no stage imports another stage; move what they share into a room below the stages",
                    shown.display(),
                    u.line
                ));
            }
        }
    }
    out
}

/// The circles (strongly connected sets of two or more) of a directed graph, each sorted.
fn circles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    let nodes: BTreeSet<&String> = edges
        .iter()
        .flat_map(|(a, bs)| std::iter::once(a).chain(bs))
        .collect();
    let reach = |from: &String| {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(n) = stack.pop() {
            for m in edges.get(&n).into_iter().flatten() {
                if seen.insert(m.clone()) {
                    stack.push(m.clone());
                }
            }
        }
        seen
    };
    let reached: BTreeMap<&String, BTreeSet<String>> =
        nodes.iter().map(|n| (*n, reach(n))).collect();
    let mut out: Vec<Vec<String>> = Vec::new();
    for n in &nodes {
        if !reached[n].contains(*n) {
            continue;
        }
        let mut set: Vec<String> = nodes
            .iter()
            .filter(|m| reached[n].contains(**m) && reached[*m].contains(*n))
            .map(|m| (*m).clone())
            .collect();
        set.sort();
        if set.len() > 1 && !out.contains(&set) {
            out.push(set);
        }
    }
    out
}

/// Circles between the parts of each folder (its files and subfolders, its own `mod.rs` aside),
/// as (folder, members). Only what the code runs counts: a doc link or a test helper from a
/// sibling makes no circle a reader must untangle. Between the crate's rooms (the top level) the
/// order of [`LAYERS`] already rules circles out.
fn folder_circles(files: &[(PathBuf, String)]) -> Vec<(String, Vec<String>)> {
    let mut graphs: BTreeMap<Vec<String>, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for u in uses(files) {
        let common = u.from.iter().zip(&u.to).take_while(|(a, b)| a == b).count();
        // Parts of the same folder below the top, neither of them the folder's own module.
        if u.kind == Kind::Code && common > 0 && common < u.from.len() && common < u.to.len() {
            graphs
                .entry(u.from[..common].to_vec())
                .or_default()
                .entry(u.from[common].clone())
                .or_default()
                .insert(u.to[common].clone());
        }
    }
    let mut out = Vec::new();
    for (folder, g) in &graphs {
        let name = if folder.is_empty() {
            "nodes/src".to_string()
        } else {
            folder.join("/")
        };
        for c in circles(g) {
            out.push((name.clone(), c));
        }
    }
    out
}

fn circle_violations(files: &[(PathBuf, String)]) -> Vec<String> {
    let found = folder_circles(files);
    let mut out = Vec::new();
    for (folder, members) in &found {
        let known = KNOWN_CIRCLES.iter().any(|(f, m, _)| {
            f == folder && m.iter().copied().eq(members.iter().map(String::as_str))
        });
        if !known {
            out.push(format!(
                "nodes/src/{folder}: its parts {} import each other in a circle; move what they share into one part (or a new file) that the others use, or, if the circle is meant, name it with its reason in KNOWN_CIRCLES",
                members.join(" <-> ")
            ));
        }
    }
    for (folder, members, _) in KNOWN_CIRCLES {
        if !found
            .iter()
            .any(|(f, m)| f == folder && m.iter().map(String::as_str).eq(members.iter().copied()))
        {
            out.push(format!(
                "KNOWN_CIRCLES names {folder}: {members:?}, which is no longer a circle: remove the entry"
            ));
        }
    }
    out
}

fn sources(dir: &Path, base: &Path, out: &mut Vec<(PathBuf, String)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            sources(&p, base, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&p).unwrap();
            out.push((p.strip_prefix(base).unwrap().to_path_buf(), text));
        }
    }
}

fn crate_sources() -> Vec<(PathBuf, String)> {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&base, &base, &mut files);
    files
}

#[test]
fn the_rooms_stand_in_their_order() {
    let files = crate_sources();
    assert!(files.len() > 50, "read {} source files", files.len());
    let v = order_violations(&files);
    assert!(v.is_empty(), "the layout rule is broken:\n{}", v.join("\n"));
}

#[test]
fn no_folder_s_files_import_each_other_in_a_circle() {
    let v = circle_violations(&crate_sources());
    assert!(v.is_empty(), "{}", v.join("\n"));
}

#[test]
fn every_room_at_the_top_is_in_the_layers() {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut stray = Vec::new();
    for e in std::fs::read_dir(&base).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let ok = if p.is_dir() {
            layer(&name).is_some()
        } else {
            ROOT_FILES.contains(&name.as_str()) && layer(name.trim_end_matches(".rs")).is_some()
        };
        if !ok {
            stray.push(name);
        }
    }
    stray.sort();
    assert!(
        stray.is_empty(),
        "at nodes/src/ top level but in no layer of LAYERS: {stray:?}"
    );
}

fn f(p: &str, t: &str) -> (PathBuf, String) {
    (PathBuf::from(p), t.to_string())
}

/// A small tree for the checker's own tests: the modules every case below may name.
fn tree() -> Vec<(PathBuf, String)> {
    [
        "lib.rs",
        "params.rs",
        "artifact/mod.rs",
        "geom/mod.rs",
        "geom/raycast.rs",
        "geom/wide_bvh.rs",
        "geom/wide_bvh/packet.rs",
        "rf/mod.rs",
        "rf/paths.rs",
        "rf/scene.rs",
        "raster/label.rs",
        "street/mod.rs",
        "street/relief/mod.rs",
        "stages/buildings/roof_clean.rs",
        "stages/buildings/building_mask.rs",
        "stages/buildings/unassigned.rs",
        "stages/buildings/assemble_scene.rs",
        "stages/ingest/read_las.rs",
        "synth/synth_city.rs",
        "synth/truth_scene.rs",
    ]
    .iter()
    .map(|p| f(p, ""))
    .collect()
}

/// `tree()` with `case` in place of its file of the same path.
fn with(case: &(PathBuf, String)) -> Vec<(PathBuf, String)> {
    let mut t: Vec<_> = tree().into_iter().filter(|(p, _)| *p != case.0).collect();
    t.push(case.clone());
    t
}

/// The checker itself: each kind of breach, written the ways Rust allows, is caught.
#[test]
fn the_checker_catches_each_kind_of_breach() {
    let bad = [
        f(
            "rf/paths.rs",
            "use crate::stages::buildings::assemble_scene::terrain_mesh;\n",
        ),
        f(
            "geom/raycast.rs",
            "fn f() { crate::synth::synth_city::generate(); }\n",
        ),
        f(
            "artifact/mod.rs",
            "/// See [`crate::geom::raycast::cast`].\npub struct X;\n",
        ),
        f(
            "params.rs",
            "use crate::{\n    rng::mix,\n    stages::ingest::read_las,\n};\n",
        ),
        f(
            "stages/buildings/roof_clean.rs",
            "use crate::stages::buildings::building_mask::label_regions;\n",
        ),
        f(
            "stages/buildings/unassigned.rs",
            "use super::roof_clean::label_ids;\n",
        ),
        f(
            "synth/truth_scene.rs",
            "use kodama_nodes::synth::synth_city::RECESS_M;\n",
        ),
        f("geom/raycast.rs", "use crate::street::relief::Instance;\n"),
        f("stray.rs", "\n"),
    ];
    for case in &bad {
        let v = order_violations(&with(case));
        assert_eq!(v.len(), 1, "{}: {v:?}", case.0.display());
    }
    let good = [
        f(
            "stages/buildings/roof_clean.rs",
            "use crate::raster::label::label_regions;\nuse crate::stages::buildings::roof_clean::RoofClean;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
        ),
        f(
            "lib.rs",
            "$crate::stages::buildings::roof_clean::RoofClean,\n",
        ),
        f(
            "rf/paths.rs",
            "use super::scene::RfScene; // crate::stages::x::y in a comment\nconst S: &str = \"crate::street::relief\";\n",
        ),
        f(
            "street/relief/mod.rs",
            "use crate::geom::{raycast::cast, wide_bvh::packet::P};\n",
        ),
    ];
    for case in &good {
        let v = order_violations(&with(case));
        assert!(v.is_empty(), "{}: {v:?}", case.0.display());
    }
    let msg = &order_violations(&with(&bad[7]))[0];
    assert_eq!(
        msg,
        "nodes/src/geom/raycast.rs:1: uses `street::relief`, but geom/ stands below street/ in the layers (ARCHITECTURE.md, \"Code map\"): a room never imports a room above it; move what both need down into geom/ or below"
    );
}

/// A circle between two files of a folder is caught, through `super::` and `crate::` alike, and
/// one between a folder's `mod.rs` and its parts is not a circle.
#[test]
fn the_checker_catches_a_circle_inside_a_folder() {
    let mut t = tree();
    t.retain(|(p, _)| !p.starts_with("rf") && !p.starts_with("geom"));
    t.push(f("rf/mod.rs", "pub mod paths;\npub use paths::Path;\n"));
    t.push(f(
        "rf/paths.rs",
        "use super::scene::RfScene;\nuse crate::rf::Thing;\n",
    ));
    t.push(f("rf/scene.rs", "fn f() { crate::rf::paths::trace(); }\n"));
    t.push(f("geom/wide_bvh.rs", "mod packet;\nuse packet::P;\n"));
    t.push(f("geom/wide_bvh/packet.rs", "use super::Node;\n"));
    let c = folder_circles(&t);
    assert_eq!(
        c,
        vec![(
            "rf".to_string(),
            vec!["paths".to_string(), "scene".to_string()]
        )]
    );
    let v = circle_violations(&t);
    assert_eq!(
        v,
        vec![
            "nodes/src/rf: its parts paths <-> scene import each other in a circle; move what they share into one part (or a new file) that the others use, or, if the circle is meant, name it with its reason in KNOWN_CIRCLES"
                .to_string()
        ]
    );
}
