//! `kinds` and `kinds KIND`: the node kinds a graph may name, and one kind's reference (its
//! inputs, output, reports and every param with its type, default and documentation, read from
//! the stage's own source by `kodama_nodes::params::reference`).

use std::collections::VecDeque;

use kodama_nodes::params::reference::{self, FieldDoc, TypeDoc};
use kodama_nodes::stage::{Arity, InputSpec};
use serde_json::{Map, Value};

use super::Fail;
use crate::registry::{self, Kind};
use crate::syntax;

/// One line per kind: inputs, output and its one-line description.
pub(super) fn print_kinds() {
    for k in registry::kinds() {
        let inputs: Vec<String> = k.inputs.iter().map(input_text).collect();
        println!(
            "{} v{} ({}) -> {}\n    {}",
            k.name,
            k.version,
            inputs.join(", "),
            k.output,
            k.doc
        );
        for r in k.reports {
            println!("    report \"<node>.{}\" -> {}: {}", r.name, r.ty, r.doc);
        }
    }
    println!("\n`kodama-dag kinds KIND` prints one kind's params with their defaults and units.");
}

fn input_text(i: &InputSpec) -> String {
    match i.arity {
        Arity::One => format!("{}: {}", i.name, i.ty),
        Arity::Optional => format!("{}: {}?", i.name, i.ty),
        Arity::Many => format!("{}: [{}]", i.name, i.ty),
    }
}

/// The reference of kind `name`; an unknown name is exit 2 with the nearest kind.
pub(super) fn print_kind(name: &str) -> Result<(), Fail> {
    let Some(kind) = registry::kind(name) else {
        let names = registry::kinds().iter().map(|k| k.name);
        let hint = syntax::did_you_mean(name, names)
            .map(|n| format!("; did you mean {n:?}?"))
            .unwrap_or_default();
        return Err(Fail(
            2,
            format!(
                "error: no node kind {:?}{hint} (`kodama-dag kinds` lists them)",
                crate::progress::for_terminal(name)
            ),
        ));
    };
    print!("{}", kind_reference(kind));
    Ok(())
}

/// The text `kinds KIND` prints.
pub fn kind_reference(kind: &Kind) -> String {
    let mut out = format!("{} (version {}): {}\n", kind.name, kind.version, kind.doc);
    if !kind.inputs.is_empty() {
        out.push_str("\nInputs (node ids):\n");
        for i in kind.inputs {
            out.push_str(&format!("  {}\n      {}\n", input_text(i), i.doc));
        }
    }
    out.push_str(&format!("\nOutput: {}\n", kind.output));
    for r in kind.reports {
        out.push_str(&format!(
            "  report \"<node>.{}\" -> {}: {}\n",
            r.name, r.ty, r.doc
        ));
    }
    let Some(params) = reference::of_path((kind.params_type)()) else {
        return out;
    };
    let defaults = defaults_of(kind, params);
    out.push_str(&format!(
        "\nParams ({}; `= value` is the default):\n",
        params.name
    ));
    let mut queue = VecDeque::new();
    write_fields(&mut out, params, defaults.as_ref(), &mut queue);
    let mut written = vec![params as *const TypeDoc];
    while let Some((ty, default)) = queue.pop_front() {
        if written.contains(&(ty as *const TypeDoc)) {
            continue;
        }
        written.push(ty);
        out.push_str(&format!(
            "\n{} {}:\n",
            if ty.is_enum { "enum" } else { "struct" },
            ty.name
        ));
        if !ty.doc.is_empty() {
            out.push_str(&indent(ty.doc, 2));
        }
        write_fields(
            &mut out,
            ty,
            default.as_ref().and_then(Value::as_object),
            &mut queue,
        );
    }
    out
}

/// A nested type to document, with its default value where the parent's default gives one.
type Pending = (&'static TypeDoc, Option<Value>);

fn write_fields(
    out: &mut String,
    ty: &'static TypeDoc,
    defaults: Option<&Map<String, Value>>,
    queue: &mut VecDeque<Pending>,
) {
    for f in ty.fields {
        let default = defaults.and_then(|d| d.get(f.name));
        out.push_str(&format!("  {}\n", field_line(ty, f, default)));
        if !f.doc.is_empty() {
            out.push_str(&indent(f.doc, 6));
        }
        for nested in reference::named_in(f.ty, ty.module) {
            queue.push_back((nested, default.cloned()));
        }
    }
}

fn field_line(ty: &TypeDoc, f: &FieldDoc, default: Option<&Value>) -> String {
    if ty.is_enum {
        return if f.ty.is_empty() {
            f.name.to_string()
        } else {
            format!("{}{}", f.name, f.ty)
        };
    }
    let value = match default {
        None if !f.optional => ", required".to_string(),
        Some(Value::Object(_)) => " = (below)".to_string(),
        Some(Value::Null) => " = none".to_string(),
        None if f.ty.starts_with("Option<") => " = none".to_string(),
        Some(v) => {
            let text = graph_syntax(v, f.ty);
            if text.chars().count() > 60 {
                " = (long; see the doc)".to_string()
            } else {
                format!(" = {text}")
            }
        }
        None => " (optional)".to_string(),
    };
    format!("{}: {}{value}", f.name, f.ty)
}

/// A default as a graph writes it: enum variants bare, tuples in parentheses.
fn graph_syntax(v: &Value, ty: &str) -> String {
    match v {
        Value::String(_) if ty.contains("String") || ty.contains("PathBuf") => v.to_string(),
        Value::String(s) => s.clone(),
        Value::Array(items) => {
            let inner: Vec<String> = items.iter().map(|i| graph_syntax(i, "")).collect();
            if ty.starts_with('(') {
                format!("({})", inner.join(", "))
            } else {
                format!("[{}]", inner.join(", "))
            }
        }
        other => other.to_string(),
    }
}

fn indent(text: &str, n: usize) -> String {
    text.lines().map(|l| format!("{:n$}{l}\n", "")).collect()
}

/// Every field's default, read from the kind's own params parser: the required fields filled
/// with placeholders of their type, the rest left to their defaults. None where a required
/// field's type has no placeholder (then only the docs are printed).
pub fn defaults_of(kind: &Kind, params: &TypeDoc) -> Option<Map<String, Value>> {
    let mut fields = Vec::new();
    for f in params.fields.iter().filter(|f| !f.optional) {
        fields.push(format!("{}: {}", f.name, placeholder(f.ty)?));
    }
    // The loader hands a kind's parser its fields as an unnamed struct, inputs removed.
    let text = format!("({})", fields.join(", "));
    let ast = syntax::parse(&text, 0, 1, 1).ok()?;
    let parsed = (kind.parse)(&ast).ok()?;
    let required: Vec<&str> = params
        .fields
        .iter()
        .filter(|f| !f.optional)
        .map(|f| f.name)
        .collect();
    Some(
        parsed
            .fields()
            .into_iter()
            .filter(|(k, _)| !required.contains(&k.as_str()))
            .filter_map(|(k, v)| Some((k, serde_json::from_str(&v).ok()?)))
            .collect(),
    )
}

/// A value of the Rust type `ty` in graph syntax, for the fields a default cannot be read
/// without; None for a type it cannot make.
fn placeholder(ty: &str) -> Option<String> {
    let ty = ty.trim();
    if let Some(inner) = ty.strip_prefix('(').and_then(|t| t.strip_suffix(')')) {
        let parts: Option<Vec<String>> = split_top(inner).iter().map(|p| placeholder(p)).collect();
        return Some(format!("({})", parts?.join(", ")));
    }
    if let Some(inner) = ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        let (elem, n) = inner.rsplit_once(';')?;
        let n: usize = n.trim().parse().ok().filter(|n| *n <= 16)?;
        let one = placeholder(elem)?;
        return Some(format!("[{}]", vec![one; n].join(", ")));
    }
    if ty.starts_with("Vec<") {
        return Some("[]".into());
    }
    Some(
        match ty {
            "f64" | "f32" => "1.0",
            "u8" | "u16" | "u32" | "u64" | "usize" | "i32" | "i64" => "1",
            "bool" => "false",
            "String" | "PathBuf" => "\"x\"",
            _ => return None,
        }
        .into(),
    )
}

/// `f64, (f64, f64), u32` -> its top-level parts.
fn split_top(s: &str) -> Vec<&str> {
    let (mut parts, mut depth, mut start) = (Vec::new(), 0i32, 0);
    for (i, c) in s.char_indices() {
        match c {
            '(' | '[' | '<' => depth += 1,
            ')' | ']' | '>' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&s[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    if !s[start..].trim().is_empty() {
        parts.push(&s[start..]);
    }
    parts
}
