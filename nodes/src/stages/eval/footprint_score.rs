//! Footprints scored against reference footprints (an official cadastre such as the Dutch BGT, or
//! the synthetic site's truth): the overall footprint IoU and each reference building's IoU with
//! the derived footprint that overlaps it most.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Footprints, Grid, Metrics, Raster};
use crate::geom::union_find::UnionFind;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`FootprintScore`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FootprintScoreParams {
    /// Evaluation cell, metres. Default 0.25.
    pub cell_m: f64,
    /// A reference building is scored when at least this fraction of its area lies in the
    /// evaluated region (references cut by the edge of a tile are not the method's fault).
    /// Default 0.9.
    pub min_inside: f64,
}

impl Default for FootprintScoreParams {
    fn default() -> Self {
        FootprintScoreParams {
            cell_m: 0.25,
            min_inside: 0.9,
        }
    }
}

/// Metrics: per reference building, `building_iou/<id>` with the prediction overlapping it most,
/// summarised as `building_iou_mean`, `building_iou_median`, `buildings_scored`,
/// `buildings_found` (IoU >= 0.5) and `buildings_cut_by_region`; merge-tolerant, over blocks of
/// overlapping references and predictions, `block_iou_mean`, `blocks_scored` and `iou` (all cells of
/// the scored blocks); `iou_all` (every cell of the region); `predicted_footprints`. Given the
/// building returns, `iou_returns`: the same blocks scored with the cells the returns reach in
/// place of the predicted footprints. It is what an outline that follows the returns exactly
/// would score, so it tells the method's share of the error from the data's: a reference drawn
/// along the walls misses the eaves and the annexes the returns show.
pub struct FootprintScore;

impl Stage for FootprintScore {
    const KIND: &'static str = "FootprintScore";
    // 3: `iou_returns` when the building returns are given.
    const VERSION: u32 = 3;
    const DOC: &'static str =
        "footprint IoU against reference footprints, overall and per building";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "predicted",
            ArtifactType::Footprints,
            "the derived footprints",
        ),
        InputSpec::one(
            "reference",
            ArtifactType::Footprints,
            "the reference footprints",
        ),
        InputSpec::optional(
            "region",
            ArtifactType::Raster,
            "where the data reaches (cells with data); default: everywhere",
        ),
        InputSpec::optional(
            "returns",
            ArtifactType::Raster,
            "cells the building returns reach (finite values), scored over the same blocks",
        ),
    ];
    type Params = FootprintScoreParams;
    type Output = Metrics;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::params::check_cell(Some(p.cell_m))?;
        if !(0.0..=1.0).contains(&p.min_inside) {
            return Err(ParamError::new(
                "min_inside",
                "expected a fraction in [0, 1]",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Metrics, StageError> {
        let predicted: &Footprints = inputs.one("predicted")?;
        let reference: &Footprints = inputs.one("reference")?;
        let region: Option<&Raster> = inputs.optional("region")?;
        let returns: Option<&Raster> = inputs.optional("returns")?;
        let scale = |n: u32, g: &Grid| n as f64 * g.cell_m / p.cell_m;
        let grid = match region {
            Some(r) => Grid::sized(
                r.grid.x0,
                r.grid.y0,
                p.cell_m,
                scale(r.grid.width, &r.grid),
                scale(r.grid.height, &r.grid),
            ),
            None => extent(&[predicted, reference], p.cell_m)
                .ok_or_else(|| StageError::Failed("neither footprint set has a polygon".into()))?,
        }
        .map_err(|m| {
            StageError::Param(ParamError::new(
                "cell_m",
                format!(
                    "{m} (the footprints' extent over cell_m; a larger cell_m or a `region` \
                     input bounds it)"
                ),
            ))
        })?;
        let finite_at = |r: &Raster, i: usize| {
            let (x, y) = grid.center(i as u32 % grid.width, i as u32 / grid.width);
            r.grid
                .cell_of(x, y)
                .is_some_and(|(c, row)| r.at(c, row).is_finite())
        };
        let in_region: Vec<bool> = (0..grid.len())
            .map(|i| region.is_none_or(|r| finite_at(r, i)))
            .collect();
        let returns: Option<Vec<bool>> =
            returns.map(|r| (0..grid.len()).map(|i| finite_at(r, i)).collect());
        Ok(score(
            predicted,
            reference,
            &grid,
            &in_region,
            returns.as_deref(),
            p.min_inside,
        ))
    }
}

/// A grid covering every polygon of `sets` (none without a polygon; an error past the cell
/// limits).
fn extent(sets: &[&Footprints], cell_m: f64) -> Option<Result<Grid, String>> {
    let pts = sets
        .iter()
        .flat_map(|s| &s.items)
        .flat_map(|f| &f.polygons)
        .flat_map(|p| &p.exterior);
    let (lo, hi) = pts.fold(None, |acc: Option<([f64; 2], [f64; 2])>, p| {
        Some(match acc {
            None => (*p, *p),
            Some((lo, hi)) => (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            ),
        })
    })?;
    Some(Grid::sized(
        lo[0] - cell_m,
        hi[1] + cell_m,
        cell_m,
        ((hi[0] - lo[0]) / cell_m).ceil() + 2.0,
        ((hi[1] - lo[1]) / cell_m).ceil() + 2.0,
    ))
}

/// The scores on `grid`, counting only cells `in_region`; `returns`, if given, marks the cells
/// the building returns reach.
pub fn score(
    predicted: &Footprints,
    reference: &Footprints,
    grid: &Grid,
    in_region: &[bool],
    returns: Option<&[bool]>,
    min_inside: f64,
) -> Metrics {
    let pred = predicted.rasterize(grid);
    let refs = reference.rasterize(grid);
    let cell_area = grid.cell_m * grid.cell_m;
    let (mut inter, mut union) = (0usize, 0usize);
    let mut pred_cells = vec![0usize; predicted.items.len() + 1];
    // overlap[(r, p)]: cells of reference r covered by prediction p.
    let mut overlap = std::collections::BTreeMap::<(u32, u32), usize>::new();
    let mut ref_cells = vec![0usize; reference.items.len() + 1];
    for i in (0..grid.len()).filter(|&i| in_region[i]) {
        let (r, p) = (refs[i], pred[i]);
        inter += (r > 0 && p > 0) as usize;
        union += (r > 0 || p > 0) as usize;
        pred_cells[p as usize] += 1;
        ref_cells[r as usize] += 1;
        if r > 0 && p > 0 {
            *overlap.entry((r, p)).or_default() += 1;
        }
    }
    let mut m = Metrics::default();
    m.set(
        "iou_all",
        if union > 0 {
            inter as f64 / union as f64
        } else {
            0.0
        },
    );
    m.set("predicted_footprints", predicted.items.len() as f64);
    let mut ious = Vec::new();
    let mut cut = 0usize;
    let mut scored = vec![false; reference.items.len() + 1];
    for (k, f) in reference.items.iter().enumerate() {
        let r = k as u32 + 1;
        let area: f64 = f.polygons.iter().map(|p| p.area()).sum();
        if area <= 0.0 || (ref_cells[r as usize] as f64 * cell_area) < min_inside * area {
            cut += 1;
            continue;
        }
        scored[r as usize] = true;
        // The prediction that covers most of it (the lowest index on ties).
        let best = overlap
            .range((r, 0)..=(r, u32::MAX))
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.1.cmp(&a.0.1)))
            .map(|(&(_, p), &n)| (p, n));
        let iou = best.map_or(0.0, |(p, n)| {
            n as f64 / (ref_cells[r as usize] + pred_cells[p as usize] - n) as f64
        });
        m.set(format!("building_iou/{}", f.id), iou);
        ious.push(iou);
    }
    block_scores(&mut m, &refs, &pred, in_region, returns, &overlap, &scored);
    m.set("buildings_scored", ious.len() as f64);
    m.set("buildings_cut_by_region", cut as f64);
    m.set(
        "buildings_found",
        ious.iter().filter(|&&v| v >= 0.5).count() as f64,
    );
    if !ious.is_empty() {
        m.set(
            "building_iou_mean",
            ious.iter().sum::<f64>() / ious.len() as f64,
        );
        let mut s = ious.clone();
        s.sort_by(f64::total_cmp);
        m.set("building_iou_median", s[s.len() / 2]);
    }
    m
}

/// Merge-tolerant scores: references and predictions that overlap form blocks (connected
/// components of the overlap graph, e.g. a terrace of cadastral houses and the one LiDAR footprint
/// covering it), and each block is scored by the IoU of its references' union with its
/// predictions' union. Party walls are invisible from the air and do not change how radio sees the
/// building mass; a missing, extra or misshapen building still costs. Blocks holding a reference
/// cut by the region are left out, as are predictions overlapping no reference (the reference may
/// not cover the whole region): `iou` is over the scored blocks. `iou_returns` scores the cells
/// of `returns` against the references over the same cells: those of the scored blocks.
fn block_scores(
    m: &mut Metrics,
    refs: &[u32],
    pred: &[u32],
    in_region: &[bool],
    returns: Option<&[bool]>,
    overlap: &std::collections::BTreeMap<(u32, u32), usize>,
    scored: &[bool],
) {
    let n_ref = scored.len() - 1;
    let n_pred = pred.iter().copied().max().unwrap_or(0) as usize;
    // Union-find over references 1..=n_ref and predictions n_ref+1..
    let mut sets = UnionFind::new(n_ref + n_pred + 1);
    for &(r, p) in overlap.keys() {
        sets.join(r, (n_ref + p as usize) as u32);
    }
    let mut valid = vec![None::<bool>; n_ref + n_pred + 1];
    for (r, &ok) in scored.iter().enumerate().skip(1) {
        let c = sets.root(r as u32) as usize;
        valid[c] = Some(valid[c].unwrap_or(true) && ok);
    }
    let mut acc = std::collections::BTreeMap::<usize, (usize, usize)>::new();
    let (mut inter_returns, mut union_returns) = (0usize, 0usize);
    for i in (0..refs.len()).filter(|&i| in_region[i]) {
        let cr = (refs[i] > 0).then(|| sets.root(refs[i]) as usize);
        let cp = (pred[i] > 0).then(|| sets.root((n_ref + pred[i] as usize) as u32) as usize);
        let in_block = |c: Option<usize>| c.is_some_and(|c| valid[c] == Some(true));
        if let Some(returns) = returns
            && (in_block(cr) || in_block(cp))
        {
            inter_returns += (returns[i] && in_block(cr)) as usize;
            union_returns += (returns[i] || in_block(cr)) as usize;
        }
        let mut blocks = [cr, cp];
        if cr == cp {
            blocks[1] = None;
        }
        for c in blocks.into_iter().flatten() {
            if valid[c] == Some(true) {
                let e = acc.entry(c).or_default();
                e.1 += 1;
                e.0 += (cr == Some(c) && cp == Some(c)) as usize;
            }
        }
    }
    let (inter, union) = acc.values().fold((0, 0), |a, v| (a.0 + v.0, a.1 + v.1));
    m.set(
        "iou",
        if union > 0 {
            inter as f64 / union as f64
        } else {
            0.0
        },
    );
    m.set("blocks_scored", acc.len() as f64);
    if returns.is_some() {
        m.set(
            "iou_returns",
            if union_returns > 0 {
                inter_returns as f64 / union_returns as f64
            } else {
                0.0
            },
        );
    }
    if !acc.is_empty() {
        let ious: Vec<f64> = acc.values().map(|&(i, u)| i as f64 / u as f64).collect();
        m.set(
            "block_iou_mean",
            ious.iter().sum::<f64>() / ious.len() as f64,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Footprint, Polygon};

    fn square(id: &str, x: f64, y: f64, s: f64) -> Footprint {
        Footprint {
            id: id.into(),
            polygons: vec![Polygon {
                exterior: vec![[x, y], [x + s, y], [x + s, y + s], [x, y + s]],
                holes: vec![],
            }],
            height_m: None,
            min_height_m: None,
            levels: None,
            min_level: None,
        }
    }

    #[test]
    fn ious_of_known_overlaps() {
        // Reference a: 10 x 10 at the origin, predicted shifted 2 m: IoU 80 / 120. Reference b
        // has no prediction; c's predicted square merges it with its neighbour d.
        let reference = Footprints {
            items: vec![
                square("a", 0.0, 0.0, 10.0),
                square("b", 20.0, 0.0, 4.0),
                square("c", 0.0, 20.0, 5.0),
                square("d", 5.0, 20.0, 5.0),
            ],
        };
        let predicted = Footprints {
            items: vec![
                square("p", 2.0, 0.0, 10.0),
                Footprint {
                    polygons: vec![Polygon {
                        exterior: vec![[0.0, 20.0], [10.0, 20.0], [10.0, 25.0], [0.0, 25.0]],
                        holes: vec![],
                    }],
                    ..square("q", 0.0, 0.0, 1.0)
                },
            ],
        };
        let grid = extent(&[&predicted, &reference], 0.25).unwrap().unwrap();
        let all = vec![true; grid.len()];
        let m = score(&predicted, &reference, &grid, &all, None, 0.9);
        let close = |k: &str, v: f64| assert!((m.get(k).unwrap() - v).abs() < 1e-9, "{k}: {m:?}");
        close("building_iou/a", 80.0 / 120.0);
        close("building_iou/b", 0.0);
        close("building_iou/c", 0.5);
        close("building_iou/d", 0.5);
        close("buildings_scored", 4.0);
        close("buildings_found", 3.0);
        close("iou_all", (80.0 + 50.0) / (120.0 + 16.0 + 50.0));
        // Blocks: {a, p}, {b}, {c, d, q}.
        close("blocks_scored", 3.0);
        close("block_iou_mean", (80.0 / 120.0 + 0.0 + 1.0) / 3.0);
        close("iou", (80.0 + 50.0) / (120.0 + 16.0 + 50.0));
        assert!(m.get("iou_returns").is_none(), "no returns, no iou_returns");

        // Returns over a with a 1 m eave strip (inside the block {a, p}), and a shed far from
        // any block, which no block counts.
        let returns: Vec<bool> = (0..grid.len())
            .map(|i| {
                let (x, y) = grid.center(i as u32 % grid.width, i as u32 / grid.width);
                ((0.0..11.0).contains(&x) && (0.0..10.0).contains(&y))
                    || ((40.0..42.0).contains(&x) && (0.0..2.0).contains(&y))
            })
            .collect();
        let m = score(&predicted, &reference, &grid, &all, Some(&returns), 0.9);
        let close = |k: &str, v: f64| assert!((m.get(k).unwrap() - v).abs() < 1e-9, "{k}: {m:?}");
        close("iou_returns", 100.0 / (110.0 + 16.0 + 50.0));
        close("iou", (80.0 + 50.0) / (120.0 + 16.0 + 50.0));
    }
}
