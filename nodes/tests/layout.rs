//! The crate's dependency rule, checked by reading the sources (ARCHITECTURE.md, "Code map"):
//!
//! - stages (`stages/**`, `synth/**`) may use `io`, `geom`, `raster`, `rf`, `artifact` and the
//!   crate's root files;
//! - `io`, `geom`, `raster`, `rf` and `artifact` (and the root files other than `lib.rs`, which
//!   lists the stages) never use a stage;
//! - no stage imports another stage;
//! - only the crate's root files sit at `nodes/src/` top level.
//!
//! A path counts wherever it is written: `use` lines, qualified calls, doc links, tests.

use std::path::{Path, PathBuf};

/// The files allowed at `nodes/src/` top level, and the folders.
const ROOT_FILES: &[&str] = &["lib.rs", "stage.rs", "params.rs", "site.rs", "rng.rs"];
const FOLDERS: &[&str] = &["artifact", "geom", "io", "raster", "rf", "stages", "synth"];
/// Folders of shared mechanisms: they never import a stage.
const MECHANISMS: &[&str] = &["artifact", "geom", "io", "raster", "rf"];

/// Where a source file sits in the layout.
#[derive(Debug, PartialEq)]
enum Room {
    /// `lib.rs`: lists every stage for the registry.
    Lib,
    /// Another root file, or a file of a mechanism folder.
    Below,
    /// A stage module, by its path from the crate root (`stages::buildings::roof_clean`).
    Stage(String),
    /// A folder's `mod.rs` under `stages/` or `synth/`: declares its stage modules.
    StageFolder,
}

fn room(rel: &Path) -> Room {
    let parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    match parts[0].as_str() {
        "lib" if parts.len() == 1 => Room::Lib,
        "stages" | "synth" if parts.last().map(String::as_str) == Some("mod") => Room::StageFolder,
        "stages" | "synth" => Room::Stage(parts.join("::")),
        _ => Room::Below,
    }
}

/// Every stage module a source text names: `crate::stages::a::b`, `crate::synth::b`,
/// `kodama_nodes::…`, `$crate::…`, and `super::` paths out of a stage file, with the line.
fn stage_paths(text: &str, own: Option<&str>) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let code = line.split("//").next().unwrap_or("");
        let doc = line.trim_start().starts_with("///") || line.trim_start().starts_with("//!");
        let scan = if doc { line } else { code };
        for root in ["crate::", "kodama_nodes::"] {
            let mut rest = scan;
            while let Some(i) = rest.find(root) {
                rest = &rest[i + root.len()..];
                let path: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':' || *c == '{')
                    .collect();
                let segs: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
                let module = match segs.first().copied() {
                    Some("stages") if segs.len() >= 3 => Some(segs[..3].join("::")),
                    Some("synth") if segs.len() >= 2 => Some(segs[..2].join("::")),
                    Some(s)
                        if s.starts_with('{')
                            && (path.contains("stages") || path.contains("synth")) =>
                    {
                        Some(path.clone())
                    }
                    _ => None,
                };
                if let Some(m) = module {
                    let m = m.trim_end_matches(|c| c == '{' || c == ':').to_string();
                    if own != Some(m.as_str()) {
                        found.push((n + 1, m));
                    }
                }
            }
        }
        // From a stage file, `super::x` is a sibling stage (inside `mod tests`, `super::*` is the
        // file itself, and is fine).
        if own.is_some() {
            let mut rest = code;
            while let Some(i) = rest.find("super::") {
                rest = &rest[i + "super::".len()..];
                let next: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == '*')
                    .collect();
                if next != "*" && !next.is_empty() && next.chars().next().unwrap().is_lowercase() {
                    found.push((n + 1, format!("super::{next}")));
                }
            }
        }
    }
    found
}

/// The rule's violations in a set of (path relative to `nodes/src`, text) pairs, one message each.
fn violations(files: &[(PathBuf, String)]) -> Vec<String> {
    let mut out = Vec::new();
    for (rel, text) in files {
        let shown = Path::new("nodes/src").join(rel);
        if rel.components().count() == 1 {
            let name = rel.to_string_lossy();
            if !ROOT_FILES.contains(&name.as_ref()) {
                out.push(format!(
                    "{}: only the crate's root files ({}) sit at nodes/src/ top level; put this module in the folder of its phase",
                    shown.display(),
                    ROOT_FILES.join(", ")
                ));
            }
        }
        match room(rel) {
            Room::Lib | Room::StageFolder => {}
            Room::Below => {
                for (line, m) in stage_paths(text, None) {
                    let folder = rel.iter().next().unwrap().to_string_lossy();
                    let what = if MECHANISMS.contains(&folder.as_ref()) {
                        format!("{folder}/ is below the stages")
                    } else {
                        "a root file is below the stages".to_string()
                    };
                    out.push(format!(
                        "{}:{line}: uses the stage `{m}`, but {what}: {} never import a stage; move what they share down into one of them",
                        shown.display(),
                        MECHANISMS.iter().map(|m| format!("{m}/")).collect::<Vec<_>>().join(", ")
                    ));
                }
            }
            Room::Stage(own) => {
                for (line, m) in stage_paths(text, Some(&own)) {
                    out.push(format!(
                        "{}:{line}: the stage `{own}` uses the stage `{m}`: no stage imports another stage; move what they share into io/, geom/, raster/, rf/ or artifact/",
                        shown.display()
                    ));
                }
            }
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
fn the_crate_keeps_its_dependency_rule() {
    let files = crate_sources();
    assert!(files.len() > 50, "read {} source files", files.len());
    let v = violations(&files);
    assert!(v.is_empty(), "the layout rule is broken:\n{}", v.join("\n"));
}

#[test]
fn only_root_files_and_phase_folders_at_the_top() {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut stray = Vec::new();
    for e in std::fs::read_dir(&base).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let ok = if p.is_dir() {
            FOLDERS.contains(&name.as_str())
        } else {
            ROOT_FILES.contains(&name.as_str())
        };
        if !ok {
            stray.push(name);
        }
    }
    stray.sort();
    assert!(
        stray.is_empty(),
        "unexpected at nodes/src/ top level: {stray:?}"
    );
}

/// The checker itself: each kind of breach, written the ways Rust allows, is caught.
#[test]
fn the_checker_catches_each_kind_of_breach() {
    let f = |p: &str, t: &str| (PathBuf::from(p), t.to_string());
    let bad = [
        f(
            "rf/radiomap.rs",
            "use crate::stages::buildings::assemble_scene::terrain_mesh;\n",
        ),
        f(
            "io/x.rs",
            "fn f() { crate::synth::synth_city::generate(); }\n",
        ),
        f(
            "artifact/x.rs",
            "/// See [`crate::stages::eval::evaluate::p2p`].\npub struct X;\n",
        ),
        f(
            "params.rs",
            "use crate::{stages::ingest::read_las, artifact::Raster};\n",
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
            "use crate::synth::synth_city::RECESS_M;\n",
        ),
        f("stray.rs", "\n"),
    ];
    for case in &bad {
        let v = violations(std::slice::from_ref(case));
        assert_eq!(v.len(), 1, "{}: {v:?}", case.0.display());
    }
    let good = [
        f(
            "stages/buildings/roof_clean.rs",
            "use crate::raster::label::label_regions;\nuse crate::stages::buildings::roof_clean::RoofClean;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
        ),
        f("stages/mod.rs", "pub mod buildings;\n"),
        f(
            "lib.rs",
            "$crate::stages::buildings::roof_clean::RoofClean,\n",
        ),
        f(
            "rf/paths.rs",
            "use super::scene::RfScene; // crate::stages::x::y in a comment\n",
        ),
    ];
    for case in &good {
        let v = violations(std::slice::from_ref(case));
        assert!(v.is_empty(), "{}: {v:?}", case.0.display());
    }
    let msg = &violations(&bad[..1])[0];
    assert!(
        msg.starts_with(
            "nodes/src/rf/radiomap.rs:1: uses the stage `stages::buildings::assemble_scene`"
        ),
        "{msg}"
    );
}
