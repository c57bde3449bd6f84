//! The graph as Graphviz dot or Mermaid text.

use super::Graph;

fn edges(g: &Graph) -> impl Iterator<Item = (usize, usize)> + '_ {
    g.nodes
        .iter()
        .enumerate()
        .flat_map(|(i, n)| n.deps.iter().map(move |&d| (d, i)))
}

/// Graphviz dot: one `"id" [label=...]` line per node, one `"a" -> "b";` line per edge.
pub fn to_dot(g: &Graph) -> String {
    let mut s = format!(
        "digraph \"{}\" {{\n  rankdir=LR;\n  node [shape=box];\n",
        g.name
    );
    for n in &g.nodes {
        s.push_str(&format!(
            "  \"{}\" [label=\"{}\\n{}\"];\n",
            n.id, n.id, n.kind.name
        ));
    }
    for (a, b) in edges(g) {
        s.push_str(&format!(
            "  \"{}\" -> \"{}\";\n",
            g.nodes[a].id, g.nodes[b].id
        ));
    }
    s.push_str("}\n");
    s
}

/// Mermaid flowchart. Node ids are replaced by `n<index>` because Mermaid ids cannot hold every
/// character a graph id can.
pub fn to_mermaid(g: &Graph) -> String {
    let mut s = String::from("flowchart LR\n");
    for (i, n) in g.nodes.iter().enumerate() {
        s.push_str(&format!(
            "  n{i}[\"{}<br/><small>{}</small>\"]\n",
            n.id.replace('"', "#quot;"),
            n.kind.name
        ));
    }
    for (a, b) in edges(g) {
        s.push_str(&format!("  n{a} --> n{b}\n"));
    }
    s
}
