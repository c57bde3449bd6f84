//! Roof cleaning (paper Sec. 4.1): the roof surface of each building in situ, Z_b = A on F_b, with
//! the geometry that is not roof removed and the gaps filled, giving the cleaned field Z̃_b.
//!
//! What is not roof is told by the building class where the LiDAR has one (a cell without
//! building returns is a tree, a car or a gap over the roof), and otherwise by how many surfaces
//! are stacked at a cell (a crown over a roof leaves returns at two heights, or one layer much
//! thicker than a roof). Roof parts left too small to be trusted are dropped; the gaps are filled
//! from the rest of the same building's roof, never from a neighbour's.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, PointSet, Raster};
use crate::raster::label::label_ids;
use crate::raster::label::label_regions;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// ASPRS class of building returns.
const BUILDING_CLASS: u8 = 6;

/// Params of [`RoofClean`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RoofCleanParams {
    /// Use the points' building class (6) when they have it. Default true.
    pub use_classes: bool,
    /// Without classes: the returns of a cell split into stacked surfaces at vertical gaps wider
    /// than this, metres. Default 1.5.
    pub layer_gap_m: f64,
    /// Without classes: a roof is thinner than this within one cell; a thicker top layer is
    /// foliage the pulses went into. Default 1.0 m (a 0.5 m cell of a 45° roof spans 0.5 m).
    pub max_layer_m: f64,
    /// Roof parts smaller than this once non-roof cells are removed are dropped and filled, m².
    /// Default 4.
    pub min_part_m2: f64,
    /// Radius of the median filter over each roof, cells (0 = none): it takes out the scanner's
    /// noise without rounding off steps. Default 1 (3 x 3).
    pub median_cells: u32,
}

impl Default for RoofCleanParams {
    fn default() -> Self {
        RoofCleanParams {
            use_classes: true,
            layer_gap_m: 1.5,
            max_layer_m: 1.0,
            min_part_m2: 4.0,
            median_cells: 1,
        }
    }
}

/// Z̃_b: each building's cleaned roof height above the terrain on its cells, NaN elsewhere.
pub struct RoofClean;

impl Stage for RoofClean {
    const KIND: &'static str = "RoofClean";
    const VERSION: u32 = 1;
    const DOC: &'static str = "cleaned roof heights Z̃_b = A on F_b without trees, stacked surfaces and small parts, gaps filled, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "labels",
            ArtifactType::Raster,
            "building labels F_b (1, 2, ...; 0 = none)",
        ),
        InputSpec::one(
            "above",
            ArtifactType::Raster,
            "the above-ground field A, on the labels' grid",
        ),
        InputSpec::optional(
            "points",
            ArtifactType::Points,
            "the LiDAR points, for classes and stacked surfaces",
        ),
        InputSpec::optional(
            "terrain",
            ArtifactType::Raster,
            "the terrain T (needed with points)",
        ),
    ];
    type Params = RoofCleanParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("m")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v) in [
            ("layer_gap_m", p.layer_gap_m),
            ("max_layer_m", p.max_layer_m),
            ("min_part_m2", p.min_part_m2),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ParamError::new(name, "expected a non-negative number"));
            }
        }
        if p.median_cells > 8 {
            return Err(ParamError::new(
                "median_cells",
                "expected a radius of at most 8 cells",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let labels: &Raster = inputs.one("labels")?;
        let above: &Raster = inputs.one("above")?;
        let points: Option<&PointSet> = inputs.optional("points")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        if labels.grid != above.grid {
            return Err(StageError::Failed(
                "labels and above must share one grid (make both from the same surface)".into(),
            ));
        }
        ctx.progress.set_total(4);
        let label = label_ids(labels);
        let mut roof: Vec<f32> = (0..label.len())
            .map(|i| {
                if label[i] > 0 {
                    above.data[i]
                } else {
                    f32::NAN
                }
            })
            .collect();
        if let Some(points) = points {
            let terrain = terrain.ok_or_else(|| {
                StageError::Failed(
                    "with points, RoofClean needs the terrain to put returns above ground".into(),
                )
            })?;
            let classes = p.use_classes && points.class.contains(&BUILDING_CLASS);
            let evidence = roof_from_returns(labels, &label, points, terrain, classes, p);
            for (r, e) in roof.iter_mut().zip(evidence) {
                if r.is_finite() {
                    *r = e;
                }
            }
        }
        ctx.progress.advance(1);
        let w = labels.grid.width;
        if p.median_cells > 0 {
            roof = median_within(&roof, &label, w, p.median_cells as i64);
        }
        ctx.progress.advance(1);
        let min_cells = (p.min_part_m2 / (labels.grid.cell_m * labels.grid.cell_m)).ceil() as usize;
        drop_small_parts(&mut roof, &label, w, labels.grid.height, min_cells);
        ctx.progress.advance(1);
        fill_within(&mut roof, &label, w);
        ctx.progress.advance(1);
        Ok(Raster {
            grid: labels.grid,
            data: PodVec(roof),
        })
    }
}

/// The roof height each building cell's returns support, or NaN where they show no roof: with
/// classes, the highest building return; without, the top of a single thin surface.
fn roof_from_returns(
    labels: &Raster,
    label: &[u32],
    points: &PointSet,
    terrain: &Raster,
    classes: bool,
    p: &RoofCleanParams,
) -> Vec<f32> {
    let g = labels.grid;
    // Bucket the returns of building cells by cell (counting sort keeps the file order).
    let cell_of: Vec<u32> = points
        .xyz
        .iter()
        .enumerate()
        .map(|(k, xyz)| {
            let keep = !classes || points.class.get(k) == Some(&BUILDING_CLASS);
            match g.cell_of(xyz[0] as f64, xyz[1] as f64) {
                Some((c, r)) if keep && label[(r * g.width + c) as usize] > 0 => r * g.width + c,
                _ => u32::MAX,
            }
        })
        .collect();
    let mut start = vec![0u32; g.len() + 1];
    for &c in cell_of.iter().filter(|&&c| c != u32::MAX) {
        start[c as usize + 1] += 1;
    }
    for i in 0..g.len() {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut z = vec![0f32; start[g.len()] as usize];
    for (k, &c) in cell_of.iter().enumerate() {
        if c != u32::MAX {
            z[fill[c as usize] as usize] = points.xyz[k][2];
            fill[c as usize] += 1;
        }
    }
    (0..g.len())
        .into_par_iter()
        .map(|i| {
            let zs = &z[start[i] as usize..start[i + 1] as usize];
            if label[i] == 0 || zs.is_empty() {
                return f32::NAN;
            }
            let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
            let Some(t) = terrain.bilinear(x, y) else {
                return f32::NAN;
            };
            let top = if classes {
                zs.iter().copied().fold(f32::NEG_INFINITY, f32::max) as f64
            } else {
                match single_thin_surface(zs, t, p) {
                    Some(top) => top,
                    None => return f32::NAN,
                }
            };
            (top - t).max(0.0) as f32
        })
        .collect()
}

/// The top of the one surface above ground at a cell, if there is exactly one and it is thin:
/// two stacked surfaces (a crown over a roof, an overhang) or a thick layer (foliage) are not roof.
/// Returns near the ground (walls' feet, the street seen past an edge) do not count as a surface.
fn single_thin_surface(zs: &[f32], terrain: f64, p: &RoofCleanParams) -> Option<f64> {
    let mut zs: Vec<f64> = zs
        .iter()
        .map(|&z| z as f64)
        .filter(|&z| z > terrain + p.layer_gap_m)
        .collect();
    zs.sort_by(f64::total_cmp);
    let (&lo, &hi) = (zs.first()?, zs.last()?);
    let stacked = zs.windows(2).any(|w| w[1] - w[0] > p.layer_gap_m);
    (!stacked && hi - lo <= p.max_layer_m).then_some(hi)
}

/// Median of the known cells of the same building within `radius` cells; unknown cells stay
/// unknown.
fn median_within(roof: &[f32], label: &[u32], w: u32, radius: i64) -> Vec<f32> {
    let (w, h) = (w as i64, (roof.len() as i64) / w as i64);
    (0..roof.len())
        .into_par_iter()
        .map(|i| {
            if !roof[i].is_finite() {
                return roof[i];
            }
            let (c, r) = (i as i64 % w, i as i64 / w);
            let mut v: Vec<f32> =
                Vec::with_capacity(((2 * radius + 1) * (2 * radius + 1)) as usize);
            for rr in (r - radius).max(0)..=(r + radius).min(h - 1) {
                for cc in (c - radius).max(0)..=(c + radius).min(w - 1) {
                    let j = (rr * w + cc) as usize;
                    if label[j] == label[i] && roof[j].is_finite() {
                        v.push(roof[j]);
                    }
                }
            }
            v.sort_by(f32::total_cmp);
            v[v.len() / 2]
        })
        .collect()
}

/// Removes roof parts (4-connected known cells of one building) smaller than `min_cells`, unless
/// the part is all the building has.
fn drop_small_parts(roof: &mut [f32], label: &[u32], w: u32, h: u32, min_cells: usize) {
    let known: Vec<u32> = (0..roof.len())
        .map(|i| if roof[i].is_finite() { label[i] } else { 0 })
        .collect();
    let parts = label_regions(&known, w, h, 1);
    let mut size = vec![0usize; parts.iter().copied().max().unwrap_or(0) as usize + 1];
    let mut largest_of_building = std::collections::HashMap::<u32, usize>::new();
    for &part in parts.iter().filter(|&&part| part > 0) {
        size[part as usize] += 1;
    }
    for (i, &part) in parts.iter().enumerate() {
        if part > 0 {
            let e = largest_of_building.entry(label[i]).or_default();
            *e = (*e).max(size[part as usize]);
        }
    }
    for (i, &part) in parts.iter().enumerate() {
        if part > 0 {
            let s = size[part as usize];
            if s < min_cells && s < largest_of_building[&label[i]] {
                roof[i] = f32::NAN;
            }
        }
    }
}

/// Fills the unknown cells of each building from its known cells, rim inwards: each step, an
/// unknown cell with known 8-neighbours of the same building takes their mean. Double-buffered, so
/// the result does not depend on the order; a building with no known cell stays unknown (it had
/// no roof: it is dropped downstream).
fn fill_within(roof: &mut [f32], label: &[u32], w: u32) {
    let (w, h) = (w as i64, roof.len() as i64 / w as i64);
    let mut todo: Vec<usize> = (0..roof.len())
        .filter(|&i| label[i] > 0 && !roof[i].is_finite())
        .collect();
    while !todo.is_empty() {
        let updates: Vec<(usize, f32)> = todo
            .iter()
            .filter_map(|&i| {
                let (c, r) = (i as i64 % w, i as i64 / w);
                let (mut sum, mut n) = (0.0f64, 0u32);
                for dr in -1..=1 {
                    for dc in -1..=1 {
                        let (cc, rr) = (c + dc, r + dr);
                        if (dr, dc) == (0, 0) || cc < 0 || rr < 0 || cc >= w || rr >= h {
                            continue;
                        }
                        let j = (rr * w + cc) as usize;
                        if label[j] == label[i] && roof[j].is_finite() {
                            sum += roof[j] as f64;
                            n += 1;
                        }
                    }
                }
                (n > 0).then(|| (i, (sum / n as f64) as f32))
            })
            .collect();
        if updates.is_empty() {
            break;
        }
        for &(i, v) in &updates {
            roof[i] = v;
        }
        todo.retain(|&i| !roof[i].is_finite());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stacked_or_thick_returns_are_not_roof() {
        let p = RoofCleanParams::default();
        assert_eq!(
            single_thin_surface(&[100.1, 109.9, 110.0, 110.05], 100.0, &p),
            Some(110.05f32 as f64),
            "ground returns past the edge do not count"
        );
        assert_eq!(
            single_thin_surface(&[110.0, 110.1, 114.0, 116.0], 100.0, &p),
            None,
            "a crown over the roof"
        );
        assert_eq!(
            single_thin_surface(&[104.0, 104.8, 105.5, 106.1, 107.0], 100.0, &p),
            None,
            "returns all through a crown"
        );
    }

    #[test]
    fn gaps_fill_from_the_same_building_only() {
        // Two buildings side by side; building 1 has a hole its neighbour must not leak into.
        let label = vec![1, 1, 1, 2, 1, 1, 1, 2, 1, 1, 1, 2];
        let nan = f32::NAN;
        let mut roof = vec![
            5.0, 5.0, 5.0, 20.0, 5.0, nan, nan, 20.0, 5.0, 5.0, 5.0, 20.0,
        ];
        fill_within(&mut roof, &label, 4);
        assert_eq!(roof[5], 5.0);
        assert_eq!(roof[6], 5.0);
    }

    #[test]
    fn small_parts_go_unless_they_are_the_whole_roof() {
        // Building 1: a 4-cell part and a 1-cell part touching building 2, a single cell.
        let label = vec![1, 1, 0, 0, 1, 1, 0, 1, 0, 0, 0, 2];
        let mut roof: Vec<f32> = label
            .iter()
            .map(|&l| if l > 0 { 7.0 } else { f32::NAN })
            .collect();
        drop_small_parts(&mut roof, &label, 4, 3, 4);
        let dropped: Vec<usize> = (0..12)
            .filter(|&i| label[i] > 0 && !roof[i].is_finite())
            .collect();
        assert_eq!(dropped, vec![7], "the lone cell of building 1 only");
    }
}
