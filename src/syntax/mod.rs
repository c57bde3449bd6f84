//! RON as a tree of spanned values, and a serde deserializer over that tree.
//!
//! The `ron` crate deserializes straight into types and reports positions only for syntax errors;
//! the graph loader also needs positions for errors it finds later (an unknown node kind, an edge of
//! the wrong type, a value a stage rejects). So graph files are parsed here into [`Ast`] values that
//! remember where they came from, and params are deserialized from those values with errors that
//! carry the span of the offending value.

mod de;
mod parse;

pub use de::{DeError, from_ast};
pub use parse::{MAX_DEPTH, ParseError, parse};

/// A position in one of the sources a graph is built from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Span {
    /// Which source (0 = the graph file; others are `--set` arguments).
    pub src: u16,
    /// 1-based line.
    pub line: u32,
    /// 1-based column, in characters.
    pub col: u32,
}

/// A RON value with its position.
#[derive(Clone, Debug, PartialEq)]
pub struct Ast {
    /// The value.
    pub v: Value,
    /// Where it starts.
    pub span: Span,
}

/// A struct field or map entry name with its position.
#[derive(Clone, Debug, PartialEq)]
pub struct Name {
    /// The identifier.
    pub name: String,
    /// Where it starts.
    pub span: Span,
}

/// RON values.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `true` / `false`.
    Bool(bool),
    /// An integer literal.
    Int(i128),
    /// A float literal (also `inf`, `NaN`).
    Float(f64),
    /// A string literal.
    Str(String),
    /// A char literal.
    Char(char),
    /// `()`.
    Unit,
    /// A bare identifier: a unit enum variant, or `None`.
    Ident(String),
    /// `[a, b]`.
    List(Vec<Ast>),
    /// `(a, b)`.
    Tuple(Vec<Ast>),
    /// `{k: v}`.
    Map(Vec<(Ast, Ast)>),
    /// `Name(field: v, ...)` or `(field: v, ...)`.
    Struct {
        /// The struct name, if written.
        name: Option<Name>,
        /// Fields in source order.
        fields: Vec<(Name, Ast)>,
    },
    /// `Name(a, b)`: a tuple struct, tuple variant, or `Some(x)`.
    Call {
        /// The name.
        name: Name,
        /// Arguments in order.
        args: Vec<Ast>,
    },
}

impl Ast {
    /// The value as RON text (what a `--set` takes).
    pub fn to_ron(&self) -> String {
        let list = |items: &[Ast]| items.iter().map(Ast::to_ron).collect::<Vec<_>>().join(", ");
        let fields = |f: &[(Name, Ast)]| {
            f.iter()
                .map(|(n, v)| format!("{}: {}", n.name, v.to_ron()))
                .collect::<Vec<_>>()
                .join(", ")
        };
        match &self.v {
            Value::Bool(b) => b.to_string(),
            Value::Int(i) => i.to_string(),
            Value::Float(f) if f.is_finite() && f.fract() == 0.0 && f.abs() < 1e15 => {
                format!("{f:.1}")
            }
            Value::Float(f) if f.is_nan() => "NaN".into(),
            Value::Float(f) if f.is_infinite() => {
                if *f > 0.0 {
                    "inf".into()
                } else {
                    "-inf".into()
                }
            }
            Value::Float(f) => format!("{f}"),
            Value::Str(s) => format!("{s:?}"),
            Value::Char(c) => format!("{c:?}"),
            Value::Unit => "()".into(),
            Value::Ident(i) => i.clone(),
            Value::List(v) => format!("[{}]", list(v)),
            Value::Tuple(v) => format!("({})", list(v)),
            Value::Map(m) => format!(
                "{{{}}}",
                m.iter()
                    .map(|(k, v)| format!("{}: {}", k.to_ron(), v.to_ron()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            Value::Struct { name, fields: f } => format!(
                "{}({})",
                name.as_ref().map_or("", |n| n.name.as_str()),
                fields(f)
            ),
            Value::Call { name, args } => format!("{}({})", name.name, list(args)),
        }
    }
}

impl Value {
    /// A short description for "expected X, found Y" messages.
    pub fn describe(&self) -> String {
        match self {
            Value::Bool(b) => format!("boolean `{b}`"),
            Value::Int(i) => format!("integer `{i}`"),
            Value::Float(f) => format!("float `{f}`"),
            Value::Str(s) => format!("string {s:?}"),
            Value::Char(c) => format!("char {c:?}"),
            Value::Unit => "`()`".into(),
            Value::Ident(i) => format!("identifier `{i}`"),
            Value::List(_) => "a list".into(),
            Value::Tuple(_) => "a tuple".into(),
            Value::Map(_) => "a map".into(),
            Value::Struct { name: Some(n), .. } => format!("`{}(...)`", n.name),
            Value::Struct { name: None, .. } => "a struct".into(),
            Value::Call { name, .. } => format!("`{}(...)`", name.name),
        }
    }
}

/// The candidate closest to `word`, if it is close enough to be a plausible typo.
pub fn did_you_mean<'a>(
    word: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    candidates
        .into_iter()
        .map(|c| {
            (
                strsim::damerau_levenshtein(&word.to_lowercase(), &c.to_lowercase()),
                c,
            )
        })
        .filter(|(d, c)| *d <= (c.len().max(word.len()) / 3).max(1))
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}
