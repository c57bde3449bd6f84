//! Named numbers: statistics, scores, counts.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// Named scalar values, sorted by name so the encoding is deterministic.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Name -> value. Counts are stored exactly (they are below 2^53).
    pub values: BTreeMap<String, f64>,
}

impl Metrics {
    /// Sets `name` to `v`.
    pub fn set(&mut self, name: impl Into<String>, v: f64) {
        self.values.insert(name.into(), v);
    }
    /// The value of `name`, if present.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.values.get(name).copied()
    }
}
