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

/// A carrier's name in metric keys (`f/<label>/pd_rmse_db`, written by Evaluate and read by
/// Report): GHz to 10 MHz, without trailing zeros ("3.5GHz").
pub fn carrier_label(freq_hz: f64) -> String {
    let centi = (freq_hz / 1e7).round() as i64;
    let (whole, frac) = (centi / 100, centi % 100);
    match frac {
        0 => format!("{whole}GHz"),
        f if f % 10 == 0 => format!("{whole}.{}GHz", f / 10),
        f => format!("{whole}.{f:02}GHz"),
    }
}
