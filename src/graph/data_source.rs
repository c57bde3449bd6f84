//! A graph's `data: Data(recipe: ..., docs: ...)`: where the files it reads come from, so that a
//! run without them says what fills them instead of only what is absent.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::diag::Diagnostic;
use crate::syntax::{self, Ast};

/// Where a graph's data comes from.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename = "Data")]
pub struct DataSource {
    /// The command that downloads what is public into the layout the graph reads, as a user types
    /// it, with `DATA` for the folder passed to `--data`.
    pub recipe: String,
    /// The page (a path in the repository, with an anchor) that lists every input, its source and
    /// what is not public.
    pub docs: String,
}

/// Longest `recipe` or `docs` text accepted: one command line or one path, not a document.
const MAX_TEXT: usize = 1000;

/// The graph's data source from its `data` field; None, and a diagnostic, when it is malformed.
pub fn data_source_of(a: &Ast, diags: &mut Vec<Diagnostic>) -> Option<DataSource> {
    match syntax::from_ast::<DataSource>(a) {
        Err(e) => {
            diags.push(Diagnostic::at(e.span.unwrap_or(a.span), None, e.message));
            None
        }
        Ok(d) => {
            for (field, text) in [("recipe", &d.recipe), ("docs", &d.docs)] {
                if text.trim().is_empty() || text.len() > MAX_TEXT || text.contains('\n') {
                    diags.push(Diagnostic::at(
                        a.span,
                        None,
                        format!(
                            "invalid `data.{field}`: expected one line of 1 to {MAX_TEXT} characters"
                        ),
                    ));
                    return None;
                }
            }
            Some(d)
        }
    }
}

/// The outermost missing folders or files of `paths` under `base` (each path's first component
/// below `base` that does not exist; paths that exist are skipped), without repeats, in
/// first-seen order: a site folder never downloaded is named once, not once per file in it.
pub fn missing_roots(base: &Path, paths: &[PathBuf]) -> Vec<PathBuf> {
    let mut roots: Vec<PathBuf> = Vec::new();
    for p in paths {
        let rel = p.strip_prefix(base).unwrap_or(p);
        let mut at = base.to_path_buf();
        let mut absent = false;
        for c in rel.components() {
            at.push(c);
            if std::fs::symlink_metadata(&at).is_err() {
                absent = true;
                break;
            }
        }
        if absent && !roots.contains(&at) {
            roots.push(at);
        }
    }
    roots
}

/// The note added after the per-file errors when a graph with a data source misses some of it.
pub fn missing_data_note(source: &DataSource, base: &Path, missing: &[PathBuf]) -> String {
    let list = missing_roots(base, missing)
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    format!(
        "this graph's data is missing: {list}. `{}` downloads what is public into the layout the \
         graph reads (DATA: the folder you pass as --data); {} says what each input is, where it \
         comes from and who holds what is not public",
        source.recipe, source.docs
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_site_folder_is_named_once() {
        let dir = tempfile::tempdir().unwrap();
        let base = dir.path();
        std::fs::create_dir(base.join("site")).unwrap();
        std::fs::write(base.join("site/here.csv"), "x").unwrap();
        let paths = [
            base.join("other/a.laz"),
            base.join("other/b/c.tif"),
            base.join("site/missing.csv"),
            base.join("site/here.csv"),
        ];
        let roots = missing_roots(base, &paths);
        assert_eq!(roots, [base.join("other"), base.join("site/missing.csv")]);
    }
}
