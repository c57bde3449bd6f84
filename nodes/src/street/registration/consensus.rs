//! The second pass's evidence: the façade labels of the views already placed, pooled in cells
//! on the twin's walls, and read by each view without its own.

use std::cell::RefCell;
use std::collections::HashMap;

use crate::rng::MixState;

use super::labels::Facade;

/// The façade labels of the views already placed, pooled in cells on the twin's walls: the
/// second pass places a view whose silhouettes could not (a street front seen whole, one wall
/// from edge to edge) by the windows and doors the placed views agree on.
pub(super) struct Consensus {
    pub(super) cell_m: f64,
    /// Cell -> (feature, wall) sample counts over every placed view.
    pub(super) cells: Cells,
}

/// Cell -> (feature, wall) sample counts.
pub(super) type Cells = HashMap<[i64; 3], [u32; 2], MixState>;

/// One view's façade samples pooled in cells.
pub(super) type Pool = Cells;

impl Consensus {
    pub(super) fn key(cell_m: f64, at: [f64; 3]) -> [i64; 3] {
        at.map(|v| floor_div(v, cell_m))
    }

    pub(super) fn add(&mut self, pool: &Pool) {
        for (k, v) in pool {
            let c = self.cells.entry(*k).or_default();
            c[0] += v[0];
            c[1] += v[1];
        }
    }
}

/// floor(v / d) as an integer, for every cell a site can hold; without the libm call the
/// baseline x86-64 target makes of `f64::floor` (a twentieth of the second pass).
fn floor_div(v: f64, d: f64) -> i64 {
    let q = v / d;
    let i = q as i64;
    if (i as f64) > q { i - 1 } else { i }
}

/// The consensus as one view may use it: without what that view itself put in.
pub(super) struct OthersSay<'a> {
    all: &'a Consensus,
    own: Option<&'a Pool>,
    /// What `label_at` found per cell: one view's candidate poses look up the same few thousand
    /// cells again and again, and a table that small answers from the processor's cache where
    /// the consensus of every view (tens of MB) and the view's own pool took two lookups, the
    /// first mostly a miss in memory (13 % of the registration's time on the demo).
    seen: RefCell<HashMap<[i64; 3], Option<Facade>, MixState>>,
}

impl<'a> OthersSay<'a> {
    /// The consensus less `own`, a view's own pool.
    pub(super) fn new(all: &'a Consensus, own: Option<&'a Pool>) -> OthersSay<'a> {
        OthersSay {
            all,
            own,
            seen: RefCell::default(),
        }
    }

    /// The cell at `at`.
    pub(super) fn cell(&self, at: [f64; 3]) -> [i64; 3] {
        Consensus::key(self.all.cell_m, at)
    }

    /// The majority label of the other views in cell `key`, if any saw it and they did not tie.
    pub(super) fn label(&self, key: [i64; 3]) -> Option<Facade> {
        if let Some(&label) = self.seen.borrow().get(&key) {
            return label;
        }
        let label = self.count(&key);
        self.seen.borrow_mut().insert(key, label);
        label
    }

    /// The majority label of the other views in cell `key`.
    fn count(&self, key: &[i64; 3]) -> Option<Facade> {
        let [mut f, mut w] = *self.all.cells.get(key)?;
        if let Some(own) = self.own.and_then(|o| o.get(key)) {
            f -= own[0];
            w -= own[1];
        }
        match f.cmp(&w) {
            std::cmp::Ordering::Greater => Some(Facade::Feature),
            std::cmp::Ordering::Less => Some(Facade::Wall),
            std::cmp::Ordering::Equal => None,
        }
    }
}
