//! Node kinds by name: the generic [`Stage`]s of the `nodes` crate, erased into entries the engine
//! can look up, type-check and run.

use std::collections::BTreeMap;
use std::marker::PhantomData;
use std::sync::LazyLock;

use kodama_nodes::artifact::Typed;
use kodama_nodes::stage::{FileRef, InputSpec, Inputs, ParamError, ReportSpec, Unit};
use kodama_nodes::{Artifact, ArtifactType, Ctx, Stage, StageError};

use crate::syntax::{Ast, DeError, from_ast};

/// Parameters of one node, typed inside, erased outside.
pub trait Params: Send + Sync {
    /// The canonical encoding that enters the action key (MessagePack of the typed struct, with
    /// defaults filled in, so `2` and `2.0` or an omitted default give the same key).
    fn canonical(&self) -> Vec<u8>;
    /// Field name -> value as JSON text, for run records and "what changed" reasons.
    fn fields(&self) -> BTreeMap<String, String>;
    /// The stage's own value checks.
    fn validate(&self) -> Result<(), ParamError>;
    /// The files the node reads.
    fn files(&self) -> Vec<FileRef>;
    /// Runs the stage: its output and its reports, by name.
    fn run(&self, inputs: &Inputs, ctx: &Ctx) -> Result<Ran, StageError>;
    /// How far the output reaches into input away from it (`Stage::reach_m`), metres.
    fn reach_m(&self) -> f64;
    /// What a raster output's values measure (`Stage::unit`).
    fn unit(&self) -> Unit;
    /// The same params, for a copy of the node (one per tile of a tiled run).
    fn clone_box(&self) -> Box<dyn Params>;
}

/// What one run of a stage made: its output and each of its reports.
pub struct Ran {
    /// The main artifact.
    pub output: Artifact,
    /// The reports, by name, in the order the kind declares them.
    pub reports: Vec<(&'static str, Artifact)>,
}

struct Erased<S: Stage>(S::Params, PhantomData<fn() -> S>);

impl<S: Stage> Params for Erased<S> {
    fn canonical(&self) -> Vec<u8> {
        rmp_serde::to_vec_named(&self.0).expect("params serialize to MessagePack")
    }
    fn fields(&self) -> BTreeMap<String, String> {
        match serde_json::to_value(&self.0) {
            Ok(serde_json::Value::Object(m)) => {
                m.into_iter().map(|(k, v)| (k, v.to_string())).collect()
            }
            Ok(other) => BTreeMap::from([(String::new(), other.to_string())]),
            Err(_) => BTreeMap::new(),
        }
    }
    fn validate(&self) -> Result<(), ParamError> {
        S::validate(&self.0)
    }
    fn files(&self) -> Vec<FileRef> {
        S::files(&self.0)
    }
    fn run(&self, inputs: &Inputs, ctx: &Ctx) -> Result<Ran, StageError> {
        let r = S::run_reported(&self.0, inputs, ctx)?;
        let mut output = r.output.into_artifact();
        if let Artifact::Scene(scene) = &mut output {
            sound_scene(scene, ctx)?;
        }
        Ok(Ran {
            output,
            reports: r.reports,
        })
    }
    fn reach_m(&self) -> f64 {
        S::reach_m(&self.0)
    }
    fn unit(&self) -> Unit {
        S::unit(&self.0)
    }
    fn clone_box(&self) -> Box<dyn Params> {
        Box::new(Erased::<S>(self.0.clone(), PhantomData))
    }
}

/// Every scene a stage builds is checked before anything downstream sees it: objects whose
/// meshes are not sound (non-finite or far-off vertices, indices past the vertices) are left out
/// and named in a warning; a scene that had objects and kept none is an error.
fn sound_scene(scene: &mut kodama_nodes::artifact::Scene, ctx: &Ctx) -> Result<(), StageError> {
    let had = scene.objects.len();
    let dropped = scene.drop_unsound();
    if dropped.is_empty() {
        return Ok(());
    }
    let shown: Vec<&str> = dropped.iter().map(String::as_str).collect();
    let named = kodama_nodes::stage::named_few(&shown);
    if scene.objects.is_empty() {
        return Err(StageError::bad_input(
            std::path::Path::new("the node's inputs"),
            "the scene built from them",
            format!("objects with sound meshes; every one of the {had} failed: {named}"),
        ));
    }
    ctx.progress.warn(&format!(
        "{} of the scene's {had} objects left out, their meshes unsound: {named}",
        dropped.len()
    ));
    Ok(())
}

/// The params of a report node (`"carved.outcomes"`): it has none, and runs nothing.
struct ReportOf;

impl Params for ReportOf {
    fn canonical(&self) -> Vec<u8> {
        Vec::new()
    }
    fn fields(&self) -> BTreeMap<String, String> {
        BTreeMap::new()
    }
    fn validate(&self) -> Result<(), ParamError> {
        Ok(())
    }
    fn files(&self) -> Vec<FileRef> {
        Vec::new()
    }
    fn run(&self, _: &Inputs, _: &Ctx) -> Result<Ran, StageError> {
        Err(StageError::Failed(
            "a report is made by its node's run, never run alone".into(),
        ))
    }
    fn reach_m(&self) -> f64 {
        0.0
    }
    fn unit(&self) -> Unit {
        Unit::None
    }
    fn clone_box(&self) -> Box<dyn Params> {
        Box::new(ReportOf)
    }
}

fn parse_report_of(ast: &Ast) -> Result<Box<dyn Params>, DeError> {
    let _: kodama_nodes::params::NoParams = from_ast(ast)?;
    Ok(Box::new(ReportOf))
}

/// One node kind.
pub struct Kind {
    /// Name in graph files.
    pub name: &'static str,
    /// The stage's VERSION.
    pub version: u32,
    /// One-line description.
    pub doc: &'static str,
    /// Named inputs in key order.
    pub inputs: &'static [InputSpec],
    /// Output type.
    pub output: ArtifactType,
    /// Reads this kind's params from a struct value (inputs already removed).
    pub parse: fn(&Ast) -> Result<Box<dyn Params>, DeError>,
    /// The full path of its params type (`std::any::type_name`), the key of its entry in the
    /// params reference (`kodama_nodes::params::reference`); empty for a report node's kind.
    pub params_type: fn() -> &'static str,
    /// The reports the kind makes beside its output (`Stage::REPORTS`).
    pub reports: &'static [ReportSpec],
    /// For the kind of a report node (`"carved.outcomes"`, made by the loader, never written in a
    /// graph): the report's name. Its one input, `of`, is the node that makes it.
    pub report: Option<&'static str>,
    /// Whether the stage reads only its tile's window in a tiled run (`Stage::WINDOWED`).
    pub windowed: bool,
}

impl Kind {
    /// The input of a report node that names the node making the report.
    pub const REPORT_OF: &'static str = "of";
}

fn parse_params<S: Stage>(ast: &Ast) -> Result<Box<dyn Params>, DeError> {
    let p: S::Params = from_ast(ast)?;
    Ok(Box::new(Erased::<S>(p, PhantomData)))
}

macro_rules! kinds {
    ($($s:ty),* $(,)?) => {
        vec![$(Kind {
            name: <$s as Stage>::KIND,
            version: <$s as Stage>::VERSION,
            doc: <$s as Stage>::DOC,
            inputs: <$s as Stage>::INPUTS,
            output: <<$s as Stage>::Output as Typed>::TYPE,
            parse: parse_params::<$s>,
            params_type: std::any::type_name::<<$s as Stage>::Params>,
            reports: <$s as Stage>::REPORTS,
            report: None,
            windowed: <$s as Stage>::WINDOWED,
        }),*]
    };
}

static KINDS: LazyLock<Vec<Kind>> = LazyLock::new(|| kodama_nodes::for_each_stage!(kinds));

/// The kinds of report nodes, one per (stage kind, report), named `Kind.report`. Made once; their
/// names and input lists live for the program, as the stages' own do.
static REPORT_KINDS: LazyLock<Vec<Kind>> = LazyLock::new(|| {
    KINDS
        .iter()
        .flat_map(|k| k.reports.iter().map(move |r| (k, r)))
        .map(|(k, r)| Kind {
            name: Box::leak(format!("{}.{}", k.name, r.name).into_boxed_str()),
            version: k.version,
            doc: r.doc,
            inputs: Box::leak(Box::new([InputSpec::one(
                Kind::REPORT_OF,
                k.output,
                "the node whose report this is",
            )])),
            output: r.ty,
            parse: parse_report_of,
            params_type: || "",
            reports: &[],
            report: Some(r.name),
            windowed: false,
        })
        .collect()
});

/// Every node kind a graph may name, in registration order.
pub fn kinds() -> &'static [Kind] {
    &KINDS
}

/// The kind called `name`: a stage's, or a report node's (`CarveRelief.outcomes`).
pub fn kind(name: &str) -> Option<&'static Kind> {
    KINDS
        .iter()
        .chain(REPORT_KINDS.iter())
        .find(|k| k.name == name)
}

/// The kind of the node that reads report `report` of a node of kind `of`.
pub fn report_kind(of: &Kind, report: &str) -> Option<&'static Kind> {
    kind(&format!("{}.{report}", of.name))
}
