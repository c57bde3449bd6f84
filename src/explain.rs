//! `explain`: what a run would do and why, without running anything or touching outputs.

use serde::Serialize;

use crate::cache::{Action, Cache, Digest};
use crate::exec::{RunError, file_digests, graph_key, target_indices};
use crate::graph::Graph;
use crate::key::{action_key, node_site, site_digest};
use crate::record::{LastRun, what_changed};

/// What would happen to one node.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Plan {
    /// Its output is in the cache for the current inputs.
    Cached,
    /// It would run.
    Run,
    /// It would run unless everything upstream that runs reproduces its output (early cutoff).
    Maybe,
}

/// One node's line.
#[derive(Clone, Debug, Serialize)]
pub struct PlanEntry {
    /// Node id.
    pub id: String,
    /// Kind.
    pub kind: String,
    /// What would happen.
    pub plan: Plan,
    /// Why.
    pub reason: String,
}

/// Plans a run of `graph` (restricted to `targets` and their ancestors when given).
pub fn explain(
    graph: &Graph,
    cache: &Cache,
    targets: &[String],
) -> Result<Vec<PlanEntry>, RunError> {
    let need = graph.needed(&target_indices(graph, targets)?);
    let files = file_digests(graph, cache, &need)?;
    let last = LastRun::load(&cache.runs_dir(&graph_key(graph)));
    let site = site_digest(&graph.site);
    let mut digests: Vec<Option<Digest>> = vec![None; graph.nodes.len()];
    let mut actions: Vec<Option<Action>> = vec![None; graph.nodes.len()];
    let mut out: Vec<PlanEntry> = Vec::new();
    for (i, node) in graph.nodes.iter().enumerate().filter(|(i, _)| need[*i]) {
        let entry = |plan, reason| PlanEntry {
            id: node.id.clone(),
            kind: node.kind.name.to_owned(),
            plan,
            reason,
        };
        if let Some(report) = node.kind.report {
            // A report node does what its node does: it is made by that node's run.
            let of = node.inputs[0][0];
            let of_id = &graph.nodes[of].id;
            let parent = out.iter().rfind(|e| e.id == *of_id).map(|e| e.plan.clone());
            match actions[of].as_ref().and_then(|a| a.report(report)) {
                Some((d, _)) => {
                    digests[i] = Some(d);
                    out.push(entry(
                        Plan::Cached,
                        format!("report of \"{of_id}\", in the cache"),
                    ));
                }
                None => out.push(entry(
                    parent.unwrap_or(Plan::Run),
                    format!("report of \"{of_id}\", made when it runs"),
                )),
            }
            continue;
        }
        let unknown: Vec<&str> = node
            .deps
            .iter()
            .filter(|&&d| digests[d].is_none())
            .map(|&d| graph.nodes[d].id.as_str())
            .collect();
        if !unknown.is_empty() {
            let list = unknown
                .iter()
                .map(|u| format!("\"{u}\""))
                .collect::<Vec<_>>()
                .join(", ");
            let verb = if unknown.len() == 1 {
                "reproduces its output"
            } else {
                "reproduce their outputs"
            };
            out.push(entry(Plan::Maybe, format!("runs unless {list} {verb}")));
            continue;
        }
        let inputs: Vec<Vec<Digest>> = node
            .inputs
            .iter()
            .map(|l| l.iter().map(|&d| digests[d].expect("known")).collect())
            .collect();
        let (key, snapshot) = action_key(node, &node_site(&site, node), &inputs, &files[i]);
        let hit = cache.get_action(&key).filter(|a| {
            let (d, size) = a.output;
            cache.can_get_blob(&d, size)
                && node.kind.reports.iter().all(|r| {
                    a.report(r.name)
                        .is_some_and(|(d, size)| cache.can_get_blob(&d, size))
                })
                && a.parts.iter().all(|(d, size)| cache.can_get_blob(d, *size))
        });
        match hit {
            Some(a) => {
                digests[i] = Some(a.output.0);
                actions[i] = Some(a);
                out.push(entry(Plan::Cached, "in the cache".into()));
            }
            None => out.push(entry(
                Plan::Run,
                what_changed(&snapshot, last.nodes.get(&node.id)),
            )),
        }
    }
    Ok(out)
}
