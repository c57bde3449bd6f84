//! The one check every name that becomes a file name passes: output names, view ids, tile and
//! atlas entries; and the one check every path a data file gives for another file passes
//! ([`resolve_inside`]). Names come from graph files and from data (a view set's ids), so a hostile or
//! careless one must not reach outside the output folder, clobber a sibling, or produce a name
//! that only some systems can open.

use std::path::{Component, Path, PathBuf};

/// The longest file-name component most filesystems take (bytes).
pub const MAX_NAME_BYTES: usize = 255;

/// Names Windows reserves for devices, with or without an extension.
const RESERVED: &[&str] = &[
    "CON", "PRN", "AUX", "NUL", "COM1", "COM2", "COM3", "COM4", "COM5", "COM6", "COM7", "COM8",
    "COM9", "LPT1", "LPT2", "LPT3", "LPT4", "LPT5", "LPT6", "LPT7", "LPT8", "LPT9",
];

/// Checks that `name` is one plain file-name component: not empty, not `.` or `..`, no path
/// separator, no NUL or other control character, none of `< > : " | ? *`, no trailing dot or
/// space, not a Windows device name, at most [`MAX_NAME_BYTES`]. The error says what is wrong.
pub fn check_file_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("a file name cannot be empty".into());
    }
    if name == "." || name == ".." {
        return Err(format!("{name:?} is not a file name (it names a folder)"));
    }
    if let Some(c) = name.chars().find(|c| *c == '/' || *c == '\\') {
        return Err(format!(
            "{name:?} contains the path separator `{c}`; expected a plain file name"
        ));
    }
    if let Some(c) = name.chars().find(|c| c.is_control()) {
        return Err(format!(
            "{name:?} contains the control character U+{:04X}",
            c as u32
        ));
    }
    if let Some(c) = name.chars().find(|c| "<>:\"|?*".contains(*c)) {
        return Err(format!(
            "{name:?} contains `{c}`, which Windows forbids in file names"
        ));
    }
    if name.ends_with(['.', ' ']) {
        return Err(format!(
            "{name:?} ends in a dot or a space, which Windows drops"
        ));
    }
    let stem = name.split('.').next().unwrap_or(name);
    if RESERVED
        .iter()
        .any(|r| r.eq_ignore_ascii_case(stem.trim_end()))
    {
        return Err(format!("{name:?} is a device name on Windows"));
    }
    if name.len() > MAX_NAME_BYTES {
        return Err(format!(
            "a file name of {} bytes is longer than the {MAX_NAME_BYTES} filesystems take",
            name.len()
        ));
    }
    Ok(())
}

/// Checks a relative path inside an output folder: `/`-separated components, each a plain file
/// name ([`check_file_name`]); so never absolute, never `..`, never `a//b`.
pub fn check_relative_path(rel: &str) -> Result<(), String> {
    if rel.is_empty() {
        return Err("a file path cannot be empty".into());
    }
    for part in rel.split('/') {
        check_file_name(part).map_err(|e| format!("in {rel:?}: {e}"))?;
    }
    Ok(())
}

/// Checks every relative path of a folder output, and that no two of them name the same file
/// (compared without case, as on macOS and Windows), which would make one silently replace the
/// other.
pub fn check_folder<'a>(paths: impl IntoIterator<Item = &'a str>) -> Result<(), String> {
    let mut seen = std::collections::HashMap::new();
    for rel in paths {
        check_relative_path(rel)?;
        if let Some(first) = seen.insert(rel.to_lowercase(), rel) {
            return Err(format!("{first:?} and {rel:?} would be the same file"));
        }
    }
    Ok(())
}

/// Resolves `rel`, a path that a data file gives for another file (a scene's PLY, a view's image,
/// a tile's content), against `base`, the folder of the file that names it, and checks that the
/// result stays inside `root`, the folder the node declared (and the cache digests): an absolute
/// path, or one that climbs out with `..`, is refused, since reading it would read a file the node
/// never declared and the cache never digested. The error says which. The check is lexical:
/// symbolic links inside the folder are the engine's to police (it refuses one leading outside
/// unless the user passes `--allow-outside`, and then digests what it leads to).
pub fn resolve_inside(root: &Path, base: &Path, rel: &str) -> Result<PathBuf, String> {
    if rel.is_empty() {
        return Err("an empty path; expected a file inside the folder".into());
    }
    if rel.contains('\0') {
        return Err(format!("{rel:?} contains a NUL byte"));
    }
    let r = Path::new(rel);
    if r.has_root() || r.components().any(|c| matches!(c, Component::Prefix(_))) {
        return Err(format!(
            "{rel:?} is an absolute path; expected a path relative to {}, inside it",
            root.display()
        ));
    }
    let root_n = normalise(root);
    let joined = normalise(&base.join(r));
    if !joined.starts_with(&root_n) {
        return Err(format!(
            "{rel:?} leads outside {} (to {}); expected a file inside that folder",
            root.display(),
            joined.display()
        ));
    }
    Ok(joined)
}

/// `p` with `.` dropped and each `..` taking off the component before it, without touching the
/// filesystem. A `..` above the start is kept, so the result then fails any `starts_with` check.
fn normalise(p: &Path) -> PathBuf {
    let mut out: Vec<Component> = Vec::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => match out.last() {
                Some(Component::Normal(_)) => {
                    out.pop();
                }
                Some(Component::RootDir | Component::Prefix(_)) => {}
                _ => out.push(c),
            },
            c => out.push(c),
        }
    }
    out.iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_names_pass() {
        for n in [
            "dsm.tif",
            "v0001",
            "a b",
            "0_1.glb",
            "report",
            "ünïcode",
            ".hidden",
        ] {
            check_file_name(n).unwrap();
        }
        check_relative_path("img/v0001.png").unwrap();
    }

    #[test]
    fn names_that_escape_or_confuse_are_refused() {
        for n in [
            "", ".", "..", "../x", "a/b", "a\\b", "/etc", "a\0b", "a\nb", "x:y", "a?", "CON",
            "nul.txt", "x.", "x ",
        ] {
            assert!(check_file_name(n).is_err(), "{n:?}");
        }
        assert!(check_file_name(&"a".repeat(256)).is_err());
        for p in ["img/../../x.png", "/abs", "a//b", "a/", "img/.."] {
            assert!(check_relative_path(p).is_err(), "{p:?}");
        }
    }

    #[test]
    fn duplicate_entries_are_refused() {
        assert!(check_folder(["a.png", "b.png"]).is_ok());
        let e = check_folder(["img/A.png", "img/a.png"]).unwrap_err();
        assert!(e.contains("same file"), "{e}");
    }

    #[test]
    fn paths_in_data_files_stay_inside_the_declared_folder() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir_all(root.join("meshes/sub")).unwrap();
        std::fs::write(root.join("meshes/a.ply"), b"x").unwrap();
        assert_eq!(
            resolve_inside(root, root, "meshes/a.ply").unwrap(),
            normalise(&root.join("meshes/a.ply"))
        );
        // Climbing within the folder is fine.
        assert!(resolve_inside(root, &root.join("meshes/sub"), "../a.ply").is_ok());
        for bad in ["../x.ply", "meshes/../../x.ply", "/etc/passwd", ""] {
            let e = resolve_inside(root, root, bad).unwrap_err();
            assert!(
                e.contains("outside") || e.contains("absolute") || e.contains("empty"),
                "{bad:?}: {e}"
            );
        }
    }
}
