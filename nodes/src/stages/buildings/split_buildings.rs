//! Splitting building masks at roof steps: a LiDAR mask joins buildings that touch (a terrace of
//! houses, a block of party walls) into one component, while the cadastre and the radio scene
//! want one solid per building. Neighbouring houses rarely share one roof height; where the cleaned
//! roof jumps by more than a step the mask is cut, and the pieces too small to be buildings
//! (dormers, chimneys, roof units) are merged back into the neighbour they share most boundary
//! with.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, Raster};
use crate::raster::label::flood_regions;
use crate::raster::label::label_ids;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`SplitBuildings`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SplitBuildingsParams {
    /// Neighbouring cells whose roofs differ by more than this belong to different parts, metres.
    /// Must exceed the height change of the steepest roof over one cell (0.5 m for a 45° roof on
    /// 0.5 m cells). Default 1.0.
    pub step_m: f64,
    /// Parts smaller than this are merged into a neighbouring part of the same building, m².
    /// Default 20.
    pub min_part_m2: f64,
}

impl Default for SplitBuildingsParams {
    fn default() -> Self {
        SplitBuildingsParams {
            step_m: 1.0,
            min_part_m2: 20.0,
        }
    }
}

/// Building labels re-cut at roof steps, 1, 2, ... in raster order, 0 elsewhere.
pub struct SplitBuildings;

impl Stage for SplitBuildings {
    const KIND: &'static str = "SplitBuildings";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "building labels split where the cleaned roof steps, small parts merged back, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("labels", ArtifactType::Raster, "building labels F_b"),
        InputSpec::one(
            "roofs",
            ArtifactType::Raster,
            "cleaned roof heights Z̃_b on the labels' grid",
        ),
    ];
    type Params = SplitBuildingsParams;
    type Output = Raster;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.step_m > 0.0 && p.step_m.is_finite()) {
            return Err(ParamError::new(
                "step_m",
                "expected a positive height in metres",
            ));
        }
        if !(p.min_part_m2 >= 0.0 && p.min_part_m2.is_finite()) {
            return Err(ParamError::new(
                "min_part_m2",
                "expected a non-negative area in m²",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        let labels: &Raster = inputs.one("labels")?;
        let roofs: &Raster = inputs.one("roofs")?;
        if labels.grid != roofs.grid {
            return Err(StageError::Failed(
                "labels and roofs must share one grid (RoofClean keeps the labels' grid)".into(),
            ));
        }
        let g = labels.grid;
        let building = label_ids(labels);
        let roof = &roofs.data;
        let parts = flood_regions(
            g.width,
            g.height,
            1,
            |i| building[i] > 0 && roof[i].is_finite(),
            |i, j| building[i] == building[j] && (roof[i] - roof[j]).abs() as f64 <= p.step_m,
        );
        let min_cells = (p.min_part_m2 / (g.cell_m * g.cell_m)).ceil() as usize;
        let merged = merge_small_parts(&parts, &building, g.width, min_cells);
        Ok(Raster {
            grid: g,
            data: PodVec(merged.iter().map(|&l| l as f32).collect()),
        })
    }
}

/// Merges parts of fewer than `min_cells` into the neighbouring part of the same building they
/// share the longest boundary with, smallest first (ties: lowest id), until every part is large
/// enough or has no neighbour; then numbers the parts 1, 2, ... in raster order.
fn merge_small_parts(parts: &[u32], building: &[u32], w: u32, min_cells: usize) -> Vec<u32> {
    let w = w as usize;
    let n = parts.iter().copied().max().unwrap_or(0) as usize;
    let mut size = vec![0usize; n + 1];
    // shared[a][b]: cell edges between parts a and b of one building.
    let mut shared: Vec<BTreeMap<u32, usize>> = vec![BTreeMap::new(); n + 1];
    for i in 0..parts.len() {
        let a = parts[i];
        if a == 0 {
            continue;
        }
        size[a as usize] += 1;
        let right = (i % w + 1 < w).then(|| i + 1);
        let below = (i + w < parts.len()).then(|| i + w);
        for j in [right, below].into_iter().flatten() {
            let b = parts[j];
            if b != 0 && b != a && building[i] == building[j] {
                *shared[a as usize].entry(b).or_default() += 1;
                *shared[b as usize].entry(a).or_default() += 1;
            }
        }
    }
    let mut into: Vec<u32> = (0..=n as u32).collect();
    let mut alive: std::collections::BTreeSet<(usize, u32)> = (1..=n as u32)
        .filter(|&a| size[a as usize] < min_cells)
        .map(|a| (size[a as usize], a))
        .collect();
    while let Some((s, a)) = alive.pop_first() {
        let Some((&b, _)) = shared[a as usize]
            .iter()
            .max_by(|x, y| x.1.cmp(y.1).then(y.0.cmp(x.0)))
        else {
            continue;
        };
        into[a as usize] = b;
        let edges = std::mem::take(&mut shared[a as usize]);
        for (c, k) in edges {
            shared[c as usize].remove(&a);
            if c != b {
                *shared[b as usize].entry(c).or_default() += k;
                *shared[c as usize].entry(b).or_default() += k;
            }
        }
        let old = size[b as usize];
        size[b as usize] += s;
        if alive.remove(&(old, b)) && size[b as usize] < min_cells {
            alive.insert((size[b as usize], b));
        }
    }
    let root = |mut a: u32| {
        while into[a as usize] != a {
            a = into[a as usize];
        }
        a
    };
    let mut renumber = BTreeMap::new();
    parts
        .iter()
        .map(|&a| {
            if a == 0 {
                return 0;
            }
            let r = root(a);
            let next = renumber.len() as u32 + 1;
            *renumber.entry(r).or_insert(next)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Grid;
    use crate::stage::Slot;
    use crate::{Artifact, Site};
    use std::sync::Arc;

    #[test]
    fn a_terrace_splits_at_roof_steps_and_keeps_its_chimneys() {
        // Three 6 x 10 m houses in one mask, roofs at 9, 11 and 9 m; a 1 x 1 m chimney on the
        // first stands 1.5 m proud.
        let (w, h) = (36u32, 20u32);
        let roof = |c: u32, r: u32| -> f32 {
            let base = [9.0, 11.0, 9.0][(c / 12) as usize];
            if (4..6).contains(&c) && (4..6).contains(&r) {
                base + 1.5
            } else {
                base
            }
        };
        let grid = Grid {
            x0: 0.0,
            y0: 10.0,
            cell_m: 0.5,
            width: w,
            height: h,
        };
        let labels = Raster {
            grid,
            data: PodVec(vec![1.0; (w * h) as usize]),
        };
        let roofs = Raster {
            grid,
            data: PodVec((0..w * h).map(|i| roof(i % w, i / w)).collect()),
        };
        let inputs = Inputs::new()
            .with("labels", Slot::One(Arc::new(Artifact::Raster(labels))))
            .with("roofs", Slot::One(Arc::new(Artifact::Raster(roofs))));
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 0.5,
        };
        let out = SplitBuildings::run(&Default::default(), &inputs, &Ctx::new(&site, &[])).unwrap();
        let at = |c: u32, r: u32| out.data[(r * w + c) as usize];
        assert_eq!((at(0, 0), at(12, 0), at(24, 0)), (1.0, 2.0, 3.0));
        assert_eq!(at(4, 4), 1.0, "the chimney stays with its house");
        assert!(out.data.iter().all(|&l| (1.0..=3.0).contains(&l)));
    }
}
