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

/// Which half of a block split a receiver falls in (Evaluate's `split`, recorded in its metrics
/// as `split/block_m` and `split/guard_m` so Report can label each link the same way).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Half {
    /// Offsets are fitted on it.
    Train,
    /// Every reported score is computed on it.
    HeldOut,
    /// Within the guard band of its block's edge: in neither half.
    Guard,
}

impl Half {
    /// The name links.csv writes.
    pub fn name(self) -> &'static str {
        match self {
            Half::Train => "train",
            Half::HeldOut => "held_out",
            Half::Guard => "guard",
        }
    }
}

/// The checkerboard of `block_m` squares at (x, y) in the site's CRS (site frame plus origin, so
/// the blocks do not move with the origin): bx = floor(x / block_m), by = floor(y / block_m);
/// held out when bx + by is odd (Euclidean remainder, so negative indices alternate too),
/// training when even; within `guard_m` of the block's edge (strictly closer than `guard_m`),
/// neither. The guard keeps every training receiver at least 2 `guard_m` from every held-out one.
/// The same rule as `scripts/duke_split.py`.
pub fn block_half(x: f64, y: f64, block_m: f64, guard_m: f64) -> Half {
    let (bx, by) = ((x / block_m).floor(), (y / block_m).floor());
    let (fx, fy) = (x - bx * block_m, y - by * block_m);
    if fx < guard_m || fx > block_m - guard_m || fy < guard_m || fy > block_m - guard_m {
        return Half::Guard;
    }
    if (bx + by).rem_euclid(2.0) == 1.0 {
        Half::HeldOut
    } else {
        Half::Train
    }
}
