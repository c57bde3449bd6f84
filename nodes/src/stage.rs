//! The contract between a stage and whoever runs it.
//!
//! The rules a stage keeps (the engine relies on every one):
//! 1. `run` is a deterministic function of `Params`, the input artifacts, the files that `files`
//!    declares and the [`Site`]: the same values give byte-identical output at any thread count.
//!    Randomness is seeded from params (or [`Ctx::seed`]); no `HashMap` order reaches an output;
//!    parallel reductions are ordered.
//! 2. A stage reads no file its `files` function did not declare, and writes none.
//! 3. `VERSION` is bumped whenever the output for the same inputs would change.
//! 4. Bad user data is a [`StageError::BadInput`] naming the file, the place and what was expected;
//!    a stage never panics on user input.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::artifact::{Artifact, ArtifactType, Typed};
pub use crate::artifact::{MemParts, PartError, PartRef, PartStore, process_parts};
pub use crate::params::ParamError;
use crate::site::{Site, Window};

/// How many upstream nodes an input takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arity {
    /// Exactly one node id.
    One,
    /// Zero or one node id.
    Optional,
    /// A list of node ids, possibly empty.
    Many,
}

/// One named, typed input of a node kind.
#[derive(Clone, Copy, Debug)]
pub struct InputSpec {
    /// The field name in the graph file.
    pub name: &'static str,
    /// The artifact type the upstream node must produce.
    pub ty: ArtifactType,
    /// How many upstream nodes it takes.
    pub arity: Arity,
    /// What the input is for, for `explain` and error messages.
    pub doc: &'static str,
}

impl InputSpec {
    /// An input taking exactly one node.
    pub const fn one(name: &'static str, ty: ArtifactType, doc: &'static str) -> Self {
        InputSpec {
            name,
            ty,
            arity: Arity::One,
            doc,
        }
    }
    /// An input that may be left out.
    pub const fn optional(name: &'static str, ty: ArtifactType, doc: &'static str) -> Self {
        InputSpec {
            name,
            ty,
            arity: Arity::Optional,
            doc,
        }
    }
    /// An input taking a list of nodes.
    pub const fn many(name: &'static str, ty: ArtifactType, doc: &'static str) -> Self {
        InputSpec {
            name,
            ty,
            arity: Arity::Many,
            doc,
        }
    }
}

/// A file a node reads, named by the params field that holds its path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileRef {
    /// The params field holding the path, for error messages.
    pub field: &'static str,
    /// The path as written in the graph (relative to the data folder or the graph file).
    pub path: String,
}

/// Why a stage did not produce its output.
#[derive(Debug, Clone, PartialEq)]
pub enum StageError {
    /// The user's data is not what it should be: the file, the place in it, what was expected.
    BadInput {
        /// The file at fault.
        file: PathBuf,
        /// Where in it (a line, a record, a tag).
        place: String,
        /// What was expected and what was found.
        expected: String,
    },
    /// A parameter turned out to be unusable with these inputs.
    Param(ParamError),
    /// The stage failed for a reason that is not the user's input.
    Failed(String),
}

impl StageError {
    /// A `BadInput` error.
    pub fn bad_input(file: &Path, place: impl Into<String>, expected: impl Into<String>) -> Self {
        StageError::BadInput {
            file: file.to_path_buf(),
            place: place.into(),
            expected: expected.into(),
        }
    }
    /// Runs `f`, a third-party decoder step that panics on some corrupt files (gltf-json, laz):
    /// such a panic is the file's fault, reported as bad input at `place`, `expected` followed by
    /// the panic's message.
    pub fn catch_decoder_panic<T>(
        file: &Path,
        place: &str,
        expected: &str,
        f: impl FnOnce() -> T,
    ) -> Result<T, StageError> {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|p| {
            let why = p
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| p.downcast_ref::<&str>().copied())
                .unwrap_or("a panic");
            StageError::bad_input(file, place, format!("{expected}: {why})"))
        })
    }
    /// True when the user's input (data or params) is at fault, which the CLI reports as exit 2.
    pub fn is_user_error(&self) -> bool {
        !matches!(self, StageError::Failed(_))
    }
}

impl std::fmt::Display for StageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StageError::BadInput {
                file,
                place,
                expected,
            } => {
                write!(f, "{}: {place}: {expected}", file.display())
            }
            StageError::Param(e) => write!(f, "param `{}`: {}", e.field, e.message),
            StageError::Failed(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for StageError {}

/// Where a long stage reports how far it got. The engine turns it into progress bars or log lines.
pub trait Progress: Sync {
    /// Sets the amount of work (in the stage's own units).
    fn set_total(&self, total: u64);
    /// Marks `n` more units done.
    fn advance(&self, n: u64);
    /// Something the user should know that does not stop the stage (input records skipped, a
    /// fallback taken). Shown once, when the stage runs.
    fn warn(&self, message: &str) {
        let _ = message;
    }
}

/// The first few of `ids`, for a warning: "a, b, c, d, e and 12 more".
pub fn named_few(ids: &[&str]) -> String {
    const FEW: usize = 5;
    let shown = ids[..ids.len().min(FEW)].join(", ");
    match ids.len().saturating_sub(FEW) {
        0 => shown,
        more => format!("{shown} and {more} more"),
    }
}

/// A `Progress` that reports nowhere, for tests and library callers.
pub struct NoProgress;
impl Progress for NoProgress {
    fn set_total(&self, _: u64) {}
    fn advance(&self, _: u64) {}
}

impl From<PartError> for StageError {
    fn from(e: PartError) -> StageError {
        StageError::Failed(e.0)
    }
}

/// What a stage may know of the world besides its inputs.
pub struct Ctx<'a> {
    /// The site frame.
    pub site: &'a Site,
    /// The resolved paths of the files `Stage::files` declared, in the same order.
    pub files: &'a [PathBuf],
    /// Where progress goes.
    pub progress: &'a dyn Progress,
    /// 32 bytes derived from the node's action key, for stages that need randomness but have no
    /// seed parameter.
    pub seed: [u8; 32],
    /// Where the parts of artifacts live (a view set's pixels): the output's are put here, the
    /// inputs' read from here.
    pub parts: &'a dyn PartStore,
    /// In a tiled run, the part of the site a windowed stage ([`Stage::WINDOWED`]) reads: its
    /// tile's core grown by the halo. `None` reads everything. Other stages never see one.
    pub window: Option<Window>,
}

impl<'a> Ctx<'a> {
    /// A context for calling a stage directly (tests, benchmarks, other programs). Parts go to
    /// [`process_parts`], held in memory until the process ends: a caller making many views
    /// gives a store of its own with [`Ctx::with_parts`].
    pub fn new(site: &'a Site, files: &'a [PathBuf]) -> Self {
        Ctx {
            site,
            files,
            progress: &NoProgress,
            seed: [0; 32],
            parts: process_parts(),
            window: None,
        }
    }
    /// The same context reading only `window` (a tile of a tiled run).
    pub fn with_window(self, window: Window) -> Self {
        Ctx {
            window: Some(window),
            ..self
        }
    }
    /// The same context with parts in `parts`.
    pub fn with_parts(self, parts: &'a dyn PartStore) -> Self {
        Ctx { parts, ..self }
    }
    /// The resolved path of the `i`-th declared file.
    pub fn file(&self, i: usize) -> Result<&Path, StageError> {
        self.files
            .get(i)
            .map(PathBuf::as_path)
            .ok_or_else(|| StageError::Failed(format!("declared file #{i} was not provided")))
    }
    /// The seed as a `u64`.
    pub fn seed_u64(&self) -> u64 {
        u64::from_le_bytes(self.seed[..8].try_into().expect("8 bytes"))
    }
}

/// One input slot as handed to `run`.
#[derive(Clone, Debug)]
pub enum Slot {
    /// An `Arity::One` input.
    One(Arc<Artifact>),
    /// An `Arity::Optional` input.
    Optional(Option<Arc<Artifact>>),
    /// An `Arity::Many` input.
    Many(Vec<Arc<Artifact>>),
}

/// The input artifacts of one node run, by input name, in declared order.
#[derive(Clone, Debug, Default)]
pub struct Inputs {
    slots: Vec<(&'static str, Slot)>,
}

impl Inputs {
    /// Empty inputs.
    pub fn new() -> Self {
        Inputs::default()
    }
    /// Adds a slot (builder style).
    pub fn with(mut self, name: &'static str, slot: Slot) -> Self {
        self.slots.push((name, slot));
        self
    }
    /// Adds a slot.
    pub fn push(&mut self, name: &'static str, slot: Slot) {
        self.slots.push((name, slot));
    }

    fn slot(&self, name: &str) -> Result<&Slot, StageError> {
        self.slots
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, s)| s)
            .ok_or_else(|| StageError::Failed(format!("input `{name}` was not provided")))
    }

    fn cast<'s, T: Typed>(name: &str, a: &'s Artifact) -> Result<&'s T, StageError> {
        T::from_artifact(a).ok_or_else(|| {
            StageError::Failed(format!(
                "input `{name}`: expected {}, got {}",
                T::TYPE,
                a.ty()
            ))
        })
    }

    /// The artifact of an `Arity::One` input.
    pub fn one<T: Typed>(&self, name: &str) -> Result<&T, StageError> {
        match self.slot(name)? {
            Slot::One(a) => Self::cast(name, a),
            _ => Err(StageError::Failed(format!(
                "input `{name}` is not a single input"
            ))),
        }
    }
    /// The artifact of an `Arity::Optional` input, if given. Library callers may leave an
    /// optional input out altogether (the engine always fills every declared slot).
    pub fn optional<T: Typed>(&self, name: &str) -> Result<Option<&T>, StageError> {
        if !self.slots.iter().any(|(n, _)| *n == name) {
            return Ok(None);
        }
        match self.slot(name)? {
            Slot::Optional(a) => a.as_deref().map(|a| Self::cast(name, a)).transpose(),
            _ => Err(StageError::Failed(format!(
                "input `{name}` is not an optional input"
            ))),
        }
    }
    /// The artifacts of an `Arity::Many` input, in the order the graph lists them.
    pub fn many<T: Typed>(&self, name: &str) -> Result<Vec<&T>, StageError> {
        match self.slot(name)? {
            Slot::Many(v) => v.iter().map(|a| Self::cast(name, a)).collect(),
            _ => Err(StageError::Failed(format!(
                "input `{name}` is not a list input"
            ))),
        }
    }
}

/// One named side output of a node kind: a report the stage makes beside its artifact (the
/// carve's outcomes, the clutter's counts), cached under the node's key and named in graphs as
/// `"node.name"`.
#[derive(Clone, Copy, Debug)]
pub struct ReportSpec {
    /// The name after the node id's dot.
    pub name: &'static str,
    /// The report's artifact type.
    pub ty: ArtifactType,
    /// What it says, for `kinds` and `explain`.
    pub doc: &'static str,
}

/// A stage's output with its reports, in the order of its `Stage::REPORTS`.
#[derive(Debug)]
pub struct Reported<T> {
    /// The main artifact.
    pub output: T,
    /// Each declared report, by name.
    pub reports: Vec<(&'static str, Artifact)>,
}

/// What the values of a raster output measure, for its GeoTIFF band (GDAL's unit type).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// Labels, counts, flags, or not known: no unit.
    None,
    /// A unit as GDAL writes it: `"m"`, `"dB"`, `"dBm"`.
    Is(&'static str),
    /// The unit of the raster on the input of this name (a blur's, a mosaic's).
    SameAs(&'static str),
}

/// A node kind: what a graph file names, what it takes and what it makes.
pub trait Stage: 'static {
    /// The kind name as written in graph files, e.g. `"GaussianBlur"`.
    const KIND: &'static str;
    /// Bumped whenever the output for the same inputs and params would change.
    const VERSION: u32;
    /// One line saying what the stage does, with the paper reference.
    const DOC: &'static str;
    /// The named inputs, in the order they enter the action key.
    const INPUTS: &'static [InputSpec];
    /// The parameters as read from the graph file (`deny_unknown_fields`; defaults documented).
    /// Maps inside must be `BTreeMap` so the canonical encoding is order-free.
    type Params: Serialize + DeserializeOwned + Clone + Send + Sync + 'static;
    /// The output artifact.
    type Output: Typed;

    /// Rejects values that are well-formed but unusable (a negative sigma, an empty range).
    fn validate(_params: &Self::Params) -> Result<(), ParamError> {
        Ok(())
    }
    /// The files this node reads; their contents enter the action key.
    fn files(_params: &Self::Params) -> Vec<FileRef> {
        Vec::new()
    }
    /// Computes the output.
    fn run(params: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Self::Output, StageError>;

    /// Whether the stage reads only the part of its source that lies in `Ctx::window` when a
    /// tiled run gives one (a reader cropping its file, a sensor flying only over the tile). Its
    /// output, and everything made from it up to a merge, is then made once per tile.
    const WINDOWED: bool = false;

    /// How far, in metres, a value of the output may depend on input that lies away from it
    /// (a blur's 3 sigma, a terrain pass's coarse windows); 0 for stages that work point by
    /// point or object by object. A tiled run's default halo sums these along its chains.
    fn reach_m(_params: &Self::Params) -> f64 {
        0.0
    }

    /// What the values of a raster output measure (none by default; not asked of other types).
    fn unit(_params: &Self::Params) -> Unit {
        Unit::None
    }

    /// The reports the stage makes beside its output, each made by the same run (none by
    /// default).
    const REPORTS: &'static [ReportSpec] = &[];

    /// Computes the output and every report of [`Stage::REPORTS`]; what the engine calls. A
    /// stage with reports overrides it, and its `run` keeps only the output.
    fn run_reported(
        params: &Self::Params,
        inputs: &Inputs,
        ctx: &Ctx,
    ) -> Result<Reported<Self::Output>, StageError> {
        Ok(Reported {
            output: Self::run(params, inputs, ctx)?,
            reports: Vec::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::named_few;

    #[test]
    fn a_warning_names_five_and_counts_the_rest() {
        assert_eq!(named_few(&["a", "b"]), "a, b");
        let ids = ["a", "b", "c", "d", "e", "f", "g"];
        assert_eq!(named_few(&ids), "a, b, c, d, e and 2 more");
        assert_eq!(named_few(&[]), "");
    }
}
