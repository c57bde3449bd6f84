//! User-facing errors about graph files: file, line, column, node, what was expected, and the
//! source line with a caret.

use std::fmt;

use crate::syntax::Span;

/// One problem found in a graph or its inputs.
#[derive(Clone, Debug)]
pub struct Diagnostic {
    /// Where, when known.
    pub span: Option<Span>,
    /// The node it concerns, when there is one.
    pub node: Option<String>,
    /// What was expected and what was found.
    pub message: String,
}

impl Diagnostic {
    /// A diagnostic at `span`.
    pub fn at(span: Span, node: Option<&str>, message: impl Into<String>) -> Self {
        Diagnostic {
            span: Some(span),
            node: node.map(str::to_owned),
            message: message.into(),
        }
    }
    /// A diagnostic without a position.
    pub fn general(node: Option<&str>, message: impl Into<String>) -> Self {
        Diagnostic {
            span: None,
            node: node.map(str::to_owned),
            message: message.into(),
        }
    }
}

/// The texts diagnostics point into: the graph file (source 0) and each `--set` argument.
#[derive(Clone, Debug, Default)]
pub struct Sources {
    /// Display name and text of each source.
    pub items: Vec<(String, String)>,
}

/// Everything wrong with a graph, rendered against its sources. The CLI exits 2 on it.
#[derive(Clone, Debug)]
pub struct GraphError {
    /// The problems, in the order found.
    pub diagnostics: Vec<Diagnostic>,
    /// The texts they point into.
    pub sources: Sources,
}

impl GraphError {
    /// A single problem with no position in any source.
    pub fn general(file: &str, message: impl Into<String>) -> Self {
        GraphError {
            diagnostics: vec![Diagnostic::general(None, message)],
            sources: Sources {
                items: vec![(file.to_owned(), String::new())],
            },
        }
    }
}

impl fmt::Display for GraphError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.diagnostics.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            let node = d
                .node
                .as_ref()
                .map(|n| format!("node \"{n}\": "))
                .unwrap_or_default();
            let Some(span) = d.span else {
                let file = self
                    .sources
                    .items
                    .first()
                    .map(|s| s.0.as_str())
                    .unwrap_or("graph");
                write!(f, "error: {file}: {node}{}", d.message)?;
                continue;
            };
            let (name, text) = self
                .sources
                .items
                .get(span.src as usize)
                .map(|(n, t)| (n.as_str(), t.as_str()))
                .unwrap_or(("?", ""));
            if span.src == 0 {
                write!(
                    f,
                    "error: {name}:{}:{}: {node}{}",
                    span.line, span.col, d.message
                )?;
            } else {
                write!(
                    f,
                    "error: {name} (column {}): {node}{}",
                    span.col, d.message
                )?;
            }
            if let Some(line) = text.lines().nth(span.line as usize - 1) {
                let no = span.line.to_string();
                let pad = " ".repeat(no.len());
                let caret: String = line
                    .chars()
                    .take(span.col as usize - 1)
                    .map(|c| if c == '\t' { '\t' } else { ' ' })
                    .collect();
                write!(f, "\n{pad} |\n{no} | {line}\n{pad} | {caret}^")?;
            }
        }
        Ok(())
    }
}

impl std::error::Error for GraphError {}
