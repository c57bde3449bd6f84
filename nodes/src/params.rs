//! Checks and conventions shared by stages' parameters.

use std::path::Path;

use serde::{Deserialize, Serialize};

/// A parameter value that is well-formed but not acceptable.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamError {
    /// The params field at fault.
    pub field: &'static str,
    /// What was expected, and what was found.
    pub message: String,
}

impl ParamError {
    /// An error on `field`.
    pub fn new(field: &'static str, message: impl Into<String>) -> Self {
        ParamError {
            field,
            message: message.into(),
        }
    }
}

/// An optional cell size must be positive (rejects NaN too).
pub fn check_cell(cell_m: Option<f64>) -> Result<(), ParamError> {
    match cell_m {
        Some(c) if !(c > 0.0) => Err(ParamError::new(
            "cell_m",
            "expected a positive cell size in metres",
        )),
        _ => Ok(()),
    }
}

/// A reader's `window` (x_min, y_min, x_max, y_max in site metres): finite, each min below its
/// max.
pub fn check_window(window: Option<(f64, f64, f64, f64)>) -> Result<(), ParamError> {
    match window {
        Some((x0, y0, x1, y1))
            if !([x0, y0, x1, y1].iter().all(|v| v.is_finite()) && x0 < x1 && y0 < y1) =>
        {
            Err(ParamError::new(
                "window",
                format!(
                    "expected (x_min, y_min, x_max, y_max) in site metres, finite, each min \
                     below its max; found ({x0}, {y0}, {x1}, {y1})"
                ),
            ))
        }
        _ => Ok(()),
    }
}

/// The folder holding `path` (`.` for a bare file name): what a node whose data is a folder of
/// files (a tileset, a view set) declares as its input.
pub fn folder_of(path: &str) -> String {
    Path::new(path)
        .parent()
        .map(|f| f.to_string_lossy().into_owned())
        .filter(|f| !f.is_empty())
        .unwrap_or_else(|| ".".into())
}

/// The params of a stage that takes none.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoParams {}

/// The largest coordinate magnitude a scene may have, metres: a site frame spans kilometres, and
/// past this f32 keeps no useful precision (8 m at 10^8) while the areas a BVH computes overflow.
pub const MAX_COORD_M: f32 = 1e8;

/// The most cells one grid a node makes may have (rasters, orthophotos, radio maps, the synthetic
/// site): 2^31, 8 GiB as f32. Past it a run would more likely exhaust memory than finish, so it is
/// refused before anything is allocated; real data that large is tiled.
pub const MAX_CELLS: u64 = 1 << 31;

/// The most bytes one buffer sized by the user's values (a file's element counts, an image's
/// size, a kernel) may take: 16 GiB.
pub const MAX_BYTES: u64 = 16 << 30;

/// `width` x `height` cells of `bytes_each`, checked against [`MAX_CELLS`] and [`MAX_BYTES`].
/// The sizes are f64 so that an extent over a tiny cell size, or an infinite or NaN one, is caught
/// before any integer conversion saturates or overflows. The error says what it would have needed.
pub fn check_cells(width: f64, height: f64, bytes_each: usize) -> Result<(), String> {
    let cells = width * height;
    if !(width >= 0.0 && height >= 0.0 && cells.is_finite() && cells <= MAX_CELLS as f64) {
        return Err(format!(
            "a grid of {} x {} cells would need {} of memory; the limit is {} cells ({})",
            count(width),
            count(height),
            bytes(cells * bytes_each as f64),
            MAX_CELLS,
            bytes((MAX_CELLS * bytes_each as u64) as f64),
        ));
    }
    check_bytes("the grid", cells, bytes_each)
}

/// `n` items of `bytes_each` for `what`, checked against [`MAX_BYTES`]; the error says how much it
/// would have needed.
pub fn check_bytes(what: &str, n: f64, bytes_each: usize) -> Result<(), String> {
    let need = n * bytes_each as f64;
    if !(n >= 0.0 && need <= MAX_BYTES as f64) {
        return Err(format!(
            "{what} ({} items) would need {} of memory; the limit is {}",
            count(n),
            bytes(need),
            bytes(MAX_BYTES as f64)
        ));
    }
    Ok(())
}

/// A point in the site frame, metres: finite and within [`MAX_COORD_M`] of the
/// origin on every axis, as a scene's vertices must be. A transmitter at 1e308 m is finite, and
/// silently empties a radio map.
pub fn check_point(p: [f64; 3]) -> Result<(), String> {
    let most = MAX_COORD_M as f64;
    if p.iter().all(|c| c.abs() <= most) {
        Ok(())
    } else {
        Err(format!(
            "finite coordinates within {most:e} m of the site origin, found ({}, {}, {})",
            p[0], p[1], p[2]
        ))
    }
}

/// What one node reads in all through the files its inputs name (the meshes a scene file lists,
/// a tileset's content and buffers, external tilesets): the same file named a thousand times
/// counts a thousand times, so a few lines of references cannot make a run read or hold more than
/// [`MAX_BYTES`]. Each file is counted by its size before it is read.
pub struct ReadBudget {
    spent: std::cell::Cell<u64>,
    limit: u64,
}

impl Default for ReadBudget {
    fn default() -> Self {
        ReadBudget::new(MAX_BYTES)
    }
}

impl ReadBudget {
    /// A budget of `limit` bytes.
    pub fn new(limit: u64) -> Self {
        ReadBudget {
            spent: std::cell::Cell::new(0),
            limit,
        }
    }

    /// Counts regular file `path` against the budget before it is read; past it, the error says
    /// how much the references came to.
    pub fn take(&self, path: &Path) -> Result<(), String> {
        let len = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        let spent = self.spent.get().saturating_add(len);
        self.spent.set(spent);
        if spent > self.limit {
            return Err(format!(
                "the files named come to {} with {}, past the limit of {} a node may read in \
                 all (a file counts each time it is named)",
                bytes(spent as f64),
                path.display(),
                bytes(self.limit as f64)
            ));
        }
        Ok(())
    }
}

fn count(n: f64) -> String {
    if n.is_finite() && n.abs() < 1e12 {
        format!("{n:.0}")
    } else {
        format!("{n:.3e}")
    }
}

/// A byte count for people: `16.0 GiB`, `180.0 PiB`.
fn bytes(b: f64) -> String {
    if !b.is_finite() {
        return "unbounded memory".into();
    }
    let units = ["bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = b;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{v:.0} bytes")
    } else if v < 1e6 {
        format!("{v:.1} {}", units[u])
    } else {
        format!("{v:.3e} {}", units[u])
    }
}

#[cfg(test)]
mod limit_tests {
    use super::*;

    #[test]
    fn grids_past_the_budget_say_what_they_would_need() {
        assert!(check_cells(1000.0, 1000.0, 4).is_ok());
        let e = check_cells(1e9, 1e9, 4).unwrap_err();
        assert!(e.contains("3.5 EiB"), "{e}");
        assert!(check_cells(f64::INFINITY, 1.0, 4).is_err());
        assert!(check_cells(f64::NAN, 1.0, 4).is_err());
        assert!(check_bytes("faces", 1e12, 12).unwrap_err().contains("TiB"));
    }
}

/// A finite value within [`lo`, `hi`]: Ok, or (field, message) naming the range and the value.
pub fn check_in(
    name: &'static str,
    v: f64,
    lo: f64,
    hi: f64,
) -> Result<(), (&'static str, String)> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err((name, format!("expected a value in [{lo}, {hi}], got {v}")))
    }
}

/// The params reference: every type in this crate that a graph's params deserialize into (each
/// stage's params and the structs and enums inside them), with each field's type, whether it may
/// be left out, and its doc comment: read from the source by build.rs, so it is the code's own
/// documentation. `kodama-dag kinds KIND` prints it.
pub mod reference {
    /// A struct or an enum.
    pub struct TypeDoc {
        /// Its module, as `std::any::type_name` writes it.
        pub module: &'static str,
        /// Its name in the source.
        pub name: &'static str,
        /// Its doc comment.
        pub doc: &'static str,
        /// An enum's fields are its variants (with their payload as the type).
        pub is_enum: bool,
        /// Its fields, or its variants, in source order.
        pub fields: &'static [FieldDoc],
    }

    /// A struct's field or an enum's variant.
    pub struct FieldDoc {
        /// The name a graph writes.
        pub name: &'static str,
        /// The Rust type as written (a variant's payload; empty for a unit variant).
        pub ty: &'static str,
        /// Its doc comment.
        pub doc: &'static str,
        /// Whether a graph may leave it out (a default, or an `Option`).
        pub optional: bool,
    }

    /// Every documented type, in source order.
    pub static TYPES: &[TypeDoc] = include!(concat!(env!("OUT_DIR"), "/params_reference.rs"));

    /// The type whose full path (`std::any::type_name`) is `path`.
    pub fn of_path(path: &str) -> Option<&'static TypeDoc> {
        let (module, name) = path.rsplit_once("::")?;
        TYPES.iter().find(|t| t.name == name && t.module == module)
    }

    /// The documented types a Rust type's text names (`Option<Antenna>` names `Antenna`), each
    /// resolved to the one nearest `module` where two share a name.
    pub fn named_in(ty: &str, module: &str) -> Vec<&'static TypeDoc> {
        let mut out: Vec<&'static TypeDoc> = Vec::new();
        for word in ty.split(|c: char| !(c.is_alphanumeric() || c == '_')) {
            let nearest = TYPES
                .iter()
                .filter(|t| t.name == word)
                .max_by_key(|t| shared_prefix(t.module, module));
            if let Some(t) = nearest
                && !out.iter().any(|o| std::ptr::eq(*o, t))
            {
                out.push(t);
            }
        }
        out
    }

    fn shared_prefix(a: &str, b: &str) -> usize {
        a.split("::")
            .zip(b.split("::"))
            .take_while(|(x, y)| x == y)
            .count()
    }
}
