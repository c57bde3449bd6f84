//! Polygon operations (a ring's area and point test are the artifact's own): convex hull, outlines traced from label
//! rasters, and Douglas-Peucker simplification of closed rings.

use std::collections::BTreeMap;

use crate::artifact::{Polygon, Raster, point_in_ring, ring_area};

/// A cell corner on the raster's integer lattice (column, row).
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

/// Indices of the vertices Douglas-Peucker keeps on a closed ring, in ring order (at least three
/// when the ring has them).
pub fn douglas_peucker(r: &[[f64; 2]], tol: f64) -> Vec<usize> {
    let n = r.len();
    if n <= 3 || tol <= 0.0 {
        return (0..n).collect();
    }
    let closed: Vec<[f64; 2]> = r.iter().copied().chain(std::iter::once(r[0])).collect();
    // A closed ring's chord from its first point to itself has no direction: start from the point
    // furthest from the first.
    let far = (1..n)
        .max_by(|&i, &j| {
            let d = |k: usize| (r[k][0] - r[0][0]).hypot(r[k][1] - r[0][1]);
            d(i).total_cmp(&d(j)).then(j.cmp(&i))
        })
        .expect("more than three points");
    let mut keep = vec![false; n + 1];
    keep[0] = true;
    keep[far] = true;
    let mut stack = vec![(0usize, far), (far, n)];
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
    let out: Vec<usize> = (0..n).filter(|&k| keep[k]).collect();
    if out.len() >= 3 {
        out
    } else {
        (0..n).collect()
    }
}

/// Distance from `p` to the segment `a`-`b`.
pub fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// Douglas-Peucker on each ring (closed), keeping at least a triangle.
pub fn simplify_polygon(p: Polygon, tol: f64) -> Polygon {
    if tol <= 0.0 {
        return p;
    }
    let simplify = |r: Vec<[f64; 2]>| {
        if r.len() <= 4 {
            return r;
        }
        douglas_peucker(&r, tol).into_iter().map(|k| r[k]).collect()
    };
    Polygon {
        exterior: simplify(p.exterior),
        holes: p.holes.into_iter().map(simplify).collect(),
    }
}

/// Convex hull (monotone chain), counter-clockwise.
pub fn convex_hull(mut p: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}
