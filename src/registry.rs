//! Node kinds by name: the generic [`Stage`]s of the `nodes` crate, erased into entries the engine
//! can look up, type-check and run.

use std::collections::BTreeMap;
use std::marker::PhantomData;
use std::sync::LazyLock;

use kodama_nodes::artifact::Typed;
use kodama_nodes::stage::{FileRef, InputSpec, Inputs, ParamError};
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
    /// Runs the stage.
    fn run(&self, inputs: &Inputs, ctx: &Ctx) -> Result<Artifact, StageError>;
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
    fn run(&self, inputs: &Inputs, ctx: &Ctx) -> Result<Artifact, StageError> {
        S::run(&self.0, inputs, ctx).map(Typed::into_artifact)
    }
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
        }),*]
    };
}

static KINDS: LazyLock<Vec<Kind>> = LazyLock::new(|| kodama_nodes::for_each_stage!(kinds));

/// Every node kind, in registration order.
pub fn kinds() -> &'static [Kind] {
    &KINDS
}

/// The kind called `name`.
pub fn kind(name: &str) -> Option<&'static Kind> {
    KINDS.iter().find(|k| k.name == name)
}
