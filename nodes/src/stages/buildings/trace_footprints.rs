//! Footprint polygons from a building label raster (paper Sec. 4.1: "building masks F_b with
//! coherent boundaries"), output as GeoJSON in the site CRS.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Footprint, Footprints, Polygon, Raster, ring_area};
use crate::stages::ingest::read_osm::point_in_ring;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`TraceFootprints`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TraceFootprintsParams {
    /// Douglas-Peucker tolerance for the traced outlines, metres; 0 keeps the exact cell
    /// boundaries (collinear vertices are always merged). Default 0.
    pub simplify_m: f64,
    /// The percentile of A within a building reported as its height. Default 90.
    pub height_percentile: f64,
}

impl Default for TraceFootprintsParams {
    fn default() -> Self {
        TraceFootprintsParams {
            simplify_m: 0.0,
            height_percentile: 90.0,
        }
    }
}

/// One footprint per label: the outline and courtyards traced along cell boundaries.
pub struct TraceFootprints;

impl Stage for TraceFootprints {
    const KIND: &'static str = "TraceFootprints";
    const VERSION: u32 = 2;
    const DOC: &'static str = "footprint polygons (outlines and courtyards) traced from a building label raster, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "labels",
            ArtifactType::Raster,
            "building labels (1, 2, ...; 0 = none)",
        ),
        InputSpec::optional(
            "above",
            ArtifactType::Raster,
            "the above-ground field A, for heights",
        ),
    ];
    type Params = TraceFootprintsParams;
    type Output = Footprints;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.simplify_m >= 0.0) {
            return Err(ParamError::new(
                "simplify_m",
                "expected a non-negative tolerance in metres",
            ));
        }
        if !(0.0..=100.0).contains(&p.height_percentile) {
            return Err(ParamError::new(
                "height_percentile",
                "expected a percentile in [0, 100]",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Footprints, StageError> {
        let labels: &Raster = inputs.one("labels")?;
        let above: Option<&Raster> = inputs.optional("above")?;
        let heights = above.map(|a| label_heights(labels, a));
        let mut items = Vec::new();
        for (label, polygons) in trace(labels) {
            let polygons: Vec<Polygon> = polygons
                .into_iter()
                .map(|poly| simplify_polygon(poly, p.simplify_m))
                .collect();
            let height_m = heights
                .as_ref()
                .and_then(|h| h.get(&label))
                .map(|v| percentile(v, p.height_percentile));
            items.push(Footprint {
                id: format!("building-{label}"),
                polygons,
                height_m,
                min_height_m: None,
                levels: None,
                min_level: None,
            });
        }
        Ok(Footprints { items })
    }
}

type Vertex = (i64, i64);

/// Polygons per label, from the boundary edges of each label's cells with the label on the left.
pub fn trace(labels: &Raster) -> BTreeMap<u32, Vec<Polygon>> {
    let g = labels.grid;
    let (w, h) = (g.width as i64, g.height as i64);
    let label_at = |c: i64, r: i64| -> u32 {
        if c < 0 || r < 0 || c >= w || r >= h {
            return 0;
        }
        let v = labels.data[(r * w + c) as usize];
        if v.is_finite() && v > 0.0 {
            v as u32
        } else {
            0
        }
    };
    // Directed boundary edges per label, in vertex (column, row) space; rows grow southwards, so
    // going counter-clockwise in the site frame means SW -> SE -> NE -> NW.
    let mut edges: BTreeMap<u32, BTreeMap<Vertex, Vec<Vertex>>> = BTreeMap::new();
    for r in 0..h {
        for c in 0..w {
            let l = label_at(c, r);
            if l == 0 {
                continue;
            }
            let e = edges.entry(l).or_default();
            let mut add = |a: Vertex, b: Vertex| e.entry(a).or_default().push(b);
            if label_at(c, r + 1) != l {
                add((c, r + 1), (c + 1, r + 1));
            }
            if label_at(c + 1, r) != l {
                add((c + 1, r + 1), (c + 1, r));
            }
            if label_at(c, r - 1) != l {
                add((c + 1, r), (c, r));
            }
            if label_at(c - 1, r) != l {
                add((c, r), (c, r + 1));
            }
        }
    }
    let to_site = |v: Vertex| [g.x0 + v.0 as f64 * g.cell_m, g.y0 - v.1 as f64 * g.cell_m];
    let mut out = BTreeMap::new();
    for (label, mut adj) in edges {
        let mut rings: Vec<Vec<[f64; 2]>> = Vec::new();
        while let Some((&start, _)) = adj.iter().find(|(_, v)| !v.is_empty()) {
            let mut ring = vec![start];
            let mut prev = start;
            let mut cur = adj
                .get_mut(&start)
                .and_then(|v| v.pop())
                .expect("a start with an edge");
            while cur != start {
                ring.push(cur);
                let d_in = (cur.0 - prev.0, cur.1 - prev.1);
                let Some(nexts) = adj.get_mut(&cur).filter(|v| !v.is_empty()) else {
                    break;
                };
                // At a pinch (two ways out), take the left-most turn: rings touching at a corner
                // stay separate. Left of d_in in site frame = (d.y, -d.x) in (col, row) space.
                let score = |n: &Vertex| {
                    let d = (n.0 - cur.0, n.1 - cur.1);
                    let cross = d_in.0 * d.1 - d_in.1 * d.0; // > 0: right turn in row-down space
                    let dot = d_in.0 * d.0 + d_in.1 * d.1;
                    if cross < 0 {
                        0
                    } else if dot > 0 {
                        1
                    } else {
                        2
                    }
                };
                let k = (0..nexts.len())
                    .min_by_key(|&k| score(&nexts[k]))
                    .expect("non-empty");
                let next = nexts.swap_remove(k);
                prev = cur;
                cur = next;
            }
            rings.push(merge_collinear(ring.into_iter().map(to_site).collect()));
        }
        let (exteriors, holes): (Vec<_>, Vec<_>) = rings
            .into_iter()
            .filter(|r| r.len() >= 3)
            .partition(|r| ring_area(r) > 0.0);
        let mut polygons: Vec<Polygon> = exteriors
            .into_iter()
            .map(|e| Polygon {
                exterior: e,
                holes: vec![],
            })
            .collect();
        for hole in holes {
            // A point just inside the hole: the midpoint of its first edge, nudged to its right
            // (holes run clockwise, so their inside is on the right).
            let (a, b) = (hole[0], hole[1]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len = dx.hypot(dy);
            let probe = [
                (a[0] + b[0]) / 2.0 + dy / len * 1e-3,
                (a[1] + b[1]) / 2.0 - dx / len * 1e-3,
            ];
            if let Some(p) = polygons
                .iter_mut()
                .find(|p| point_in_ring(probe, &p.exterior))
            {
                p.holes.push(hole);
            }
        }
        out.insert(label, polygons);
    }
    out
}

/// Drops vertices on a straight line between their neighbours.
fn merge_collinear(ring: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    let n = ring.len();
    (0..n)
        .filter(|&i| {
            let (a, b, c) = (ring[(i + n - 1) % n], ring[i], ring[(i + 1) % n]);
            ((b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])).abs() > 1e-9
        })
        .map(|i| ring[i])
        .collect()
}

/// Douglas-Peucker on each ring (closed), keeping at least a triangle.
pub(crate) fn simplify_polygon(p: Polygon, tol: f64) -> Polygon {
    if tol <= 0.0 {
        return p;
    }
    let simplify = |r: Vec<[f64; 2]>| {
        if r.len() <= 4 {
            return r;
        }
        let mut keep = vec![false; r.len() + 1];
        let closed: Vec<[f64; 2]> = r.iter().copied().chain(std::iter::once(r[0])).collect();
        // The chord of a closed ring from its first point to itself has no direction: start from
        // the point furthest from the first.
        let far = (1..r.len())
            .max_by(|&i, &j| {
                let d = |k: usize| (r[k][0] - r[0][0]).hypot(r[k][1] - r[0][1]);
                d(i).total_cmp(&d(j)).then(j.cmp(&i))
            })
            .expect("more than four points");
        keep[0] = true;
        keep[far] = true;
        keep[r.len()] = true;
        let mut stack = vec![(0usize, far), (far, r.len())];
        while let Some((i, j)) = stack.pop() {
            let (a, b) = (closed[i], closed[j]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len = dx.hypot(dy).max(1e-12);
            let (k, d) = (i + 1..j)
                .map(|k| {
                    (
                        k,
                        ((closed[k][0] - a[0]) * dy - (closed[k][1] - a[1]) * dx).abs() / len,
                    )
                })
                .fold((0, -1.0), |m, x| if x.1 > m.1 { x } else { m });
            if d > tol {
                keep[k] = true;
                stack.push((i, k));
                stack.push((k, j));
            }
        }
        let out: Vec<[f64; 2]> = (0..r.len()).filter(|&k| keep[k]).map(|k| r[k]).collect();
        if out.len() >= 3 { out } else { r }
    };
    Polygon {
        exterior: simplify(p.exterior),
        holes: p.holes.into_iter().map(simplify).collect(),
    }
}

/// The finite values of `above` at the centre of each labelled cell, sorted, per label.
fn label_heights(labels: &Raster, above: &Raster) -> BTreeMap<u32, Vec<f32>> {
    let g = labels.grid;
    let mut out: BTreeMap<u32, Vec<f32>> = BTreeMap::new();
    for (i, &l) in labels.data.iter().enumerate() {
        if !(l.is_finite() && l > 0.0) {
            continue;
        }
        let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
        if let Some(a) = above
            .grid
            .cell_of(x, y)
            .map(|(c, r)| above.at(c, r))
            .filter(|a| a.is_finite())
        {
            out.entry(l as u32).or_default().push(a);
        }
    }
    for v in out.values_mut() {
        v.sort_by(f32::total_cmp);
    }
    out
}

/// The `q`-th percentile of sorted, non-empty `v`.
fn percentile(v: &[f32], q: f64) -> f64 {
    v[((v.len() - 1) as f64 * q / 100.0).round() as usize] as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Grid, PodVec};

    fn grid_of(rows: &[&str]) -> Raster {
        let (w, h) = (rows[0].len() as u32, rows.len() as u32);
        let data = rows
            .iter()
            .flat_map(|r| r.chars().map(|c| c.to_digit(10).unwrap() as f32))
            .collect();
        Raster {
            grid: Grid {
                x0: 0.0,
                y0: h as f64,
                cell_m: 1.0,
                width: w,
                height: h,
            },
            data: PodVec(data),
        }
    }

    #[test]
    fn a_courtyard_building_traces_to_an_outline_with_a_hole() {
        let r = grid_of(&["00000", "01110", "01010", "01110", "00000"]);
        let t = trace(&r);
        let p = &t[&1];
        assert_eq!(p.len(), 1);
        assert_eq!(
            p[0].exterior.len(),
            4,
            "collinear vertices merged: {:?}",
            p[0].exterior
        );
        assert_eq!(p[0].holes.len(), 1);
        assert!(
            (p[0].area() - 8.0).abs() < 1e-12,
            "9 cells minus the courtyard"
        );
    }

    #[test]
    fn simplifying_straightens_the_stairs_of_a_diagonal_outline() {
        // A band one cell wide running diagonally: stairs along both long sides.
        let rows: Vec<String> = (0..12)
            .map(|r| {
                (0..14)
                    .map(|c| if c == r || c == r + 1 { '1' } else { '0' })
                    .collect()
            })
            .collect();
        let r = grid_of(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        let exact = trace(&r)[&1][0].clone();
        assert!(exact.exterior.len() > 40, "{}", exact.exterior.len());
        let simple = simplify_polygon(exact.clone(), 1.0);
        assert!(simple.exterior.len() <= 6, "{:?}", simple.exterior);
        assert!((simple.area() - exact.area()).abs() < 0.2 * exact.area());
        assert_eq!(simplify_polygon(exact.clone(), 0.0), exact);
    }

    #[test]
    fn diagonal_touches_stay_separate_rings() {
        let r = grid_of(&["110", "110", "001"]);
        let t = trace(&r);
        let areas: Vec<f64> = t[&1].iter().map(Polygon::area).collect();
        assert_eq!(areas, vec![4.0, 1.0]);
    }
}
