//! Building outline regularization: outlines traced along raster cells have stair steps on
//! oblique walls and corners cut by simplification. Buildings are mostly made of straight walls at
//! right angles to each other, so, as in the building-outline regularization literature
//! (dominant orientations, then constrained line fitting; e.g. Sampath and Shan 2007, Zhang et al.
//! 2006), each outline is:
//!
//! 1. simplified (Douglas-Peucker) into candidate edges, each owning the run of traced boundary it
//!    replaces;
//! 2. given a dominant orientation θ, the length-weighted circular mean of its edges' directions
//!    modulo 90° (the mean of 4α);
//! 3. each edge within `angle_tol_deg` of θ or θ + 90° turned to it, the others kept as they are;
//!    its line placed at the length-weighted mean of its run of traced boundary, the direction
//!    held fixed;
//! 4. consecutive edges on one line merged, consecutive parallel edges on different lines joined
//!    by a perpendicular step, and every other pair meeting where their lines cross.
//!
//! Where the caller can say where a wall really is (the edge of the roof returns: a traced cell
//! boundary lies up to a cell outside the wall, further where wall returns fall outside it), a
//! [`WallSnap`] moves each dominant-direction line there, within `max_shift_m`.
//!
//! The result is refused (the caller keeps its other outline) when it would not be a simple ring,
//! would move a vertex further than `max_shift_m` from the traced boundary, or change the area by
//! more than `max_area_change`.

use crate::artifact::Polygon;
use crate::artifact::ring_area;
use crate::geom::polygon::{douglas_peucker, segment_distance};

/// Knobs of [`regularize_polygon`].
#[derive(Clone, Copy, Debug)]
pub struct RegularizeConfig {
    /// Douglas-Peucker tolerance that makes the candidate edges, metres: about one and a half
    /// cells, so the chords of an oblique wall's stair steps run along the wall (at one cell
    /// they zigzag by up to 20° and the wall breaks into steps).
    pub simplify_m: f64,
    /// Edges within this angle of a dominant direction are turned to it, degrees.
    pub angle_tol_deg: f64,
    /// The furthest a regularized vertex may lie from the traced boundary, metres.
    pub max_shift_m: f64,
    /// The largest relative change of area accepted.
    pub max_area_change: f64,
}

impl Default for RegularizeConfig {
    fn default() -> Self {
        RegularizeConfig {
            simplify_m: 0.75,
            angle_tol_deg: 12.0,
            max_shift_m: 1.5,
            max_area_change: 0.1,
        }
    }
}

/// Where a wall is: given a line (unit direction `d`, the ring's interior on its left), its
/// offset `o` along the left normal (-d.y, d.x), and the extent `[s0, s1]` along `d` of the
/// boundary it stands for, the offset of the wall, or `None` to keep `o`.
pub type WallSnap<'a> = &'a dyn Fn([f64; 2], f64, [f64; 2]) -> Option<f64>;

/// The polygon with every ring regularized about the exterior's dominant orientation, or `None`
/// when a ring fails the checks (see the module docs).
pub fn regularize_polygon(
    p: &Polygon,
    cfg: &RegularizeConfig,
    snap: Option<WallSnap>,
) -> Option<Polygon> {
    let theta = dominant_orientation(&p.exterior, cfg.simplify_m, cfg.angle_tol_deg.to_radians())?;
    let exterior = regularize_ring(&p.exterior, theta, cfg, snap)?;
    let holes = p
        .holes
        .iter()
        .map(|h| regularize_ring(h, theta, cfg, snap))
        .collect::<Option<Vec<_>>>()?;
    Some(Polygon { exterior, holes })
}

/// The dominant wall direction of a ring in [0, π/2), radians: the direction modulo 90° of the
/// simplified ring's longest edge, refined by the circular mean of 4α over the edges within
/// `angle_tol` of it, weighted by length squared (a long wall says more about the orientation than
/// the short chords of stair steps and cut corners, which would otherwise tilt it).
pub fn dominant_orientation(ring: &[[f64; 2]], simplify_m: f64, angle_tol: f64) -> Option<f64> {
    let keep = douglas_peucker(ring, simplify_m);
    let edges: Vec<(f64, f64)> = (0..keep.len())
        .map(|k| {
            let (a, b) = (ring[keep[k]], ring[keep[(k + 1) % keep.len()]]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            (dx.hypot(dy), dy.atan2(dx))
        })
        .collect();
    let quarter = std::f64::consts::FRAC_PI_2;
    let &(_, longest) = edges.iter().max_by(|a, b| a.0.total_cmp(&b.0))?;
    let (mut s, mut c) = (0.0, 0.0);
    for &(len, alpha) in &edges {
        let off = (alpha - longest) / quarter;
        if ((off - off.round()) * quarter).abs() <= angle_tol {
            s += len * len * (4.0 * alpha).sin();
            c += len * len * (4.0 * alpha).cos();
        }
    }
    if s.hypot(c) < 1e-12 {
        return None;
    }
    Some((s.atan2(c) / 4.0).rem_euclid(quarter))
}

/// A line: unit direction `d` and offset `o` along the left normal (-d.y, d.x).
#[derive(Clone, Copy, Debug)]
struct Line {
    d: [f64; 2],
    o: f64,
    /// Traced boundary length behind the line (its weight when merged).
    w: f64,
    /// Whether `d` was turned to a dominant direction.
    snapped: bool,
    /// The traced ring's vertices the line stands for, first and last (it may wrap).
    span: (usize, usize),
}

impl Line {
    fn normal(&self) -> [f64; 2] {
        [-self.d[1], self.d[0]]
    }
    /// How far `p` lies from the line, to its left positive.
    fn offset_of(&self, p: [f64; 2]) -> f64 {
        let n = self.normal();
        n[0] * p[0] + n[1] * p[1] - self.o
    }
    /// The point of the line nearest to `p`.
    fn project(&self, p: [f64; 2]) -> [f64; 2] {
        let (n, off) = (self.normal(), self.offset_of(p));
        [p[0] - off * n[0], p[1] - off * n[1]]
    }
    fn parallel(&self, other: &Line) -> bool {
        (self.d[0] * other.d[1] - self.d[1] * other.d[0]).abs() < 1e-9
    }
    /// Parallel and running the same way.
    fn same_way(&self, other: &Line) -> bool {
        self.parallel(other) && self.d[0] * other.d[0] + self.d[1] * other.d[1] > 0.0
    }
}

/// The regularized ring of `ring` (dominant direction `theta`), walls moved onto `snap`'s where it
/// has one: None where a step leaves fewer than three lines or the result fails the checks.
fn regularize_ring(
    ring: &[[f64; 2]],
    theta: f64,
    cfg: &RegularizeConfig,
    snap: Option<WallSnap>,
) -> Option<Vec<[f64; 2]>> {
    let n = ring.len();
    if n < 3 {
        return None;
    }
    let keep = douglas_peucker(ring, cfg.simplify_m);
    let m = keep.len();
    if m < 3 {
        return None;
    }
    let tol = cfg.angle_tol_deg.to_radians();
    // One line per simplified edge, fitted to the traced run it replaces.
    let mut lines: Vec<Line> = Vec::with_capacity(m);
    for k in 0..m {
        let (i, j) = (keep[k], keep[(k + 1) % m]);
        lines.push(fit_line(ring, (i, j), theta, tol)?);
    }
    // Consecutive edges on (nearly) one line become one.
    let mut merged = lines;
    merge_collinear_lines(&mut merged, cfg.simplify_m);
    if merged.len() < 3 {
        return None;
    }
    remove_off_axis_cuts(&mut merged, ring, cfg.simplify_m);
    merge_collinear_lines(&mut merged, cfg.simplify_m);
    if merged.len() < 3 {
        return None;
    }
    if let Some(snap) = snap {
        snap_lines(&mut merged, ring, cfg, snap);
    }
    // Two walls of one step the returns put on one line are one wall.
    merge_collinear_lines(&mut merged, cfg.simplify_m);
    if merged.len() < 3 {
        return None;
    }
    let out = corners(&merged, ring)?;
    checked(out, ring, cfg)
}

/// The line of the simplified edge from ring vertex `i` to `j`: turned to the dominant direction
/// (`theta` + k pi/2) nearest it where within `tol` radians, at the length-weighted mean offset of
/// the traced run it replaces; None for a run of no length. A step: one line per edge.
fn fit_line(ring: &[[f64; 2]], (i, j): (usize, usize), theta: f64, tol: f64) -> Option<Line> {
    let n = ring.len();
    let (a, b) = (ring[i], ring[j]);
    let alpha = (b[1] - a[1]).atan2(b[0] - a[0]);
    // The dominant direction nearest alpha, among theta + k pi/2.
    let quarter = std::f64::consts::FRAC_PI_2;
    let turns = ((alpha - theta) / quarter).round();
    let snapped_alpha = theta + turns * quarter;
    let snapped = (alpha - snapped_alpha).abs() <= tol;
    let dir = if snapped { snapped_alpha } else { alpha };
    let d = [dir.cos(), dir.sin()];
    let nrm = [-d[1], d[0]];
    // Length-weighted mean offset of the run's segments (their midpoints).
    let (mut sum, mut w) = (0.0, 0.0);
    let mut idx = i;
    loop {
        let next = (idx + 1) % n;
        let (p, q) = (ring[idx], ring[next]);
        let len = (q[0] - p[0]).hypot(q[1] - p[1]);
        let mid = [(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0];
        sum += len * (nrm[0] * mid[0] + nrm[1] * mid[1]);
        w += len;
        idx = next;
        if idx == j {
            break;
        }
    }
    if w <= 0.0 {
        return None;
    }
    Some(Line {
        d,
        o: sum / w,
        w,
        snapped,
        span: (i, j),
    })
}

/// Removes the runs of lines `off_axis_cut` finds, one after the other, while more than three
/// lines are left. A step: the clean-up of what simplification made of corners and steps.
fn remove_off_axis_cuts(merged: &mut Vec<Line>, ring: &[[f64; 2]], simplify_m: f64) {
    // Cut corners, stair chords and spikes: short edges off the dominant directions are what
    // simplification makes of a square corner whose corner cell is missing, of a step, or of a
    // cell of returns standing off a wall; the dominant lines on either side meet instead.
    let chamfer = 2.0 * simplify_m.max(1.0);
    let corner = 2.0 * chamfer;
    while merged.len() > 3 {
        match off_axis_cut(merged, ring, chamfer, corner) {
            Some((start, len)) => {
                for _ in 0..len {
                    let at = start % merged.len();
                    merged.remove(at);
                }
            }
            None => break,
        }
    }
}

/// Moves each dominant-direction line onto the wall `snap` gives for its extent, where that is
/// finite and within `max_shift_m`. A step: the only one that reads outside the ring.
fn snap_lines(merged: &mut [Line], ring: &[[f64; 2]], cfg: &RegularizeConfig, snap: WallSnap) {
    // Each dominant-direction line's extent along itself: its run of the traced ring is gone
    // after merging, so take the ring's points within a cell of the line.
    for l in merged.iter_mut().filter(|l| l.snapped) {
        let (s0, s1) = ring
            .iter()
            .filter(|p| l.offset_of(**p).abs() <= cfg.simplify_m)
            .map(|p| l.d[0] * p[0] + l.d[1] * p[1])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        if s1 > s0
            && let Some(o) = snap(l.d, l.o, [s0, s1])
            && (o - l.o).abs() <= cfg.max_shift_m
            && o.is_finite()
        {
            l.o = o;
        }
    }
}

/// The ring's corners: where consecutive lines cross, and a step between parallel ones; None
/// where two lines do not meet. A step: lines back to vertices.
fn corners(merged: &[Line], ring: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
    // Corners: where consecutive lines cross; a step between parallel ones.
    let k = merged.len();
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(2 * k);
    for e in 0..k {
        let (a, b) = (merged[e], merged[(e + 1) % k]);
        if a.parallel(&b) {
            // A step: from a's line to b's, at the traced vertex between them.
            let shared = step_on_ring(ring, &a, &b);
            out.push(a.project(shared));
            out.push(b.project(shared));
        } else {
            out.push(intersect(&a, &b)?);
        }
    }
    Some(out)
}

/// `out` without repeated vertices, if it is a simple ring of at least three whose area keeps
/// the sign of `ring`'s and changes by at most `max_area_change`, and no vertex of it lies more
/// than `max_shift_m` from `ring`. A step: the acceptance checks.
fn checked(out: Vec<[f64; 2]>, ring: &[[f64; 2]], cfg: &RegularizeConfig) -> Option<Vec<[f64; 2]>> {
    let out = dedup_ring(out);
    if out.len() < 3 || !is_simple(&out) {
        return None;
    }
    let (a0, a1) = (ring_area(ring), ring_area(&out));
    if a0.signum() != a1.signum() || ((a1 - a0) / a0).abs() > cfg.max_area_change {
        return None;
    }
    if out
        .iter()
        .any(|&v| distance_to_ring(v, ring) > cfg.max_shift_m)
    {
        return None;
    }
    Some(out)
}

/// The next run of lines off the dominant directions to remove, as (first index, count; it may
/// wrap around the ring's end): a single one shorter than `chamfer`, else a run between two
/// dominant lines that is either square to them (a chamfer, a chamfer beside a one-cell bump)
/// and shorter than `corner` in all or with the square corner they would make within
/// `chamfer / 2` of the traced `ring` (a cut corner, not a wall of its own), or between two
/// parallel lines of one direction and shorter than `corner` (a spike on one wall, or the
/// slanted side of a bay the LiDAR sees: a square step replaces it).
fn off_axis_cut(
    lines: &[Line],
    ring: &[[f64; 2]],
    chamfer: f64,
    corner: f64,
) -> Option<(usize, usize)> {
    let k = lines.len();
    if let Some(e) = (0..k).position(|e| !lines[e].snapped && lines[e].w < chamfer) {
        return Some((e, 1));
    }
    (0..k).find_map(|e| {
        let prev = lines[(e + k - 1) % k];
        if lines[e].snapped || !prev.snapped {
            return None;
        }
        let len = (0..k).take_while(|&r| !lines[(e + r) % k].snapped).count();
        let next = lines[(e + len) % k];
        if len + 2 > k || !next.snapped {
            return None;
        }
        let w: f64 = (0..len).map(|r| lines[(e + r) % k].w).sum();
        let cut = if prev.parallel(&next) {
            w < corner && prev.same_way(&next)
        } else {
            w < corner
                || intersect(&prev, &next)
                    .is_some_and(|c| distance_to_ring(c, ring) <= chamfer / 2.0)
        };
        cut.then_some((e, len))
    })
}

/// Merges consecutive snapped lines of one direction whose offsets differ by `tol` or less
/// (around the ring's end too), each at their length-weighted mean offset.
fn merge_collinear_lines(lines: &mut Vec<Line>, tol: f64) {
    let same =
        |a: &Line, b: &Line| a.snapped && b.snapped && a.same_way(b) && (a.o - b.o).abs() <= tol;
    // `b` follows `a` along the ring.
    let join = |a: &mut Line, b: &Line| {
        let w = a.w + b.w;
        a.o = (a.o * a.w + b.o * b.w) / w;
        a.w = w;
        a.span.1 = b.span.1;
    };
    let mut out: Vec<Line> = Vec::with_capacity(lines.len());
    for l in lines.drain(..) {
        match out.last_mut() {
            Some(last) if same(last, &l) => join(last, &l),
            _ => out.push(l),
        }
    }
    while out.len() > 1 {
        let last = out[out.len() - 1];
        if !same(&out[0], &last) {
            break;
        }
        let first = out[0];
        out[0] = last;
        join(&mut out[0], &first);
        out.pop();
    }
    *lines = out;
}

/// Where a step from line `a` to the parallel line `b` after it stands: the traced vertex,
/// between the end of `a`'s run and the start of `b`'s, about equally far from both lines (the
/// middle of the transition the removed edges made, or the vertex the two runs share).
fn step_on_ring(ring: &[[f64; 2]], a: &Line, b: &Line) -> [f64; 2] {
    let dist = |l: &Line, p: [f64; 2]| l.offset_of(p).abs();
    let n = ring.len();
    let gap = (b.span.0 + n - a.span.1) % n;
    (0..=gap)
        .map(|k| ring[(a.span.1 + k) % n])
        .min_by(|p, q| {
            let (dp, dq) = (dist(a, *p) - dist(b, *p), dist(a, *q) - dist(b, *q));
            dp.abs().total_cmp(&dq.abs())
        })
        .expect("the range holds a.span.1")
}

fn intersect(a: &Line, b: &Line) -> Option<[f64; 2]> {
    let (na, nb) = (a.normal(), b.normal());
    let det = na[0] * nb[1] - na[1] * nb[0];
    if det.abs() < 1e-12 {
        return None;
    }
    Some([
        (a.o * nb[1] - b.o * na[1]) / det,
        (na[0] * b.o - nb[0] * a.o) / det,
    ])
}

fn dedup_ring(r: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(r.len());
    for p in r {
        if out
            .last()
            .is_none_or(|q| (p[0] - q[0]).hypot(p[1] - q[1]) > 1e-6)
        {
            out.push(p);
        }
    }
    while out.len() > 1 {
        let (f, l) = (out[0], out[out.len() - 1]);
        if (f[0] - l[0]).hypot(f[1] - l[1]) > 1e-6 {
            break;
        }
        out.pop();
    }
    out
}

/// No two non-adjacent edges touch and no adjacent ones fold back.
fn is_simple(r: &[[f64; 2]]) -> bool {
    let n = r.len();
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let touch = |p1: [f64; 2], p2: [f64; 2], q1: [f64; 2], q2: [f64; 2]| {
        let (d1, d2) = (cross(q1, q2, p1), cross(q1, q2, p2));
        let (d3, d4) = (cross(p1, p2, q1), cross(p1, p2, q2));
        let lo = |a: f64, b: f64| a.min(b) - 1e-9;
        let hi = |a: f64, b: f64| a.max(b) + 1e-9;
        let boxes = lo(p1[0], p2[0]) <= hi(q1[0], q2[0])
            && lo(q1[0], q2[0]) <= hi(p1[0], p2[0])
            && lo(p1[1], p2[1]) <= hi(q1[1], q2[1])
            && lo(q1[1], q2[1]) <= hi(p1[1], p2[1]);
        boxes && d1 * d2 <= 0.0 && d3 * d4 <= 0.0
    };
    for i in 0..n {
        let (a, b) = (r[i], r[(i + 1) % n]);
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            if touch(a, b, r[j], r[(j + 1) % n]) {
                return false;
            }
        }
    }
    // Adjacent edges folding back onto each other.
    (0..n).all(|i| {
        let (a, b, c) = (r[(i + n - 1) % n], r[i], r[(i + 1) % n]);
        let (u, v) = ([b[0] - a[0], b[1] - a[1]], [c[0] - b[0], c[1] - b[1]]);
        let crs = u[0] * v[1] - u[1] * v[0];
        let dot = u[0] * v[0] + u[1] * v[1];
        crs.abs() > 1e-9 || dot > 0.0
    })
}

fn distance_to_ring(p: [f64; 2], ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|k| segment_distance(p, ring[k], ring[(k + 1) % n]))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::point_in_ring;
    use crate::artifact::{Grid, PodVec, Raster};
    use crate::geom::polygon::trace;

    /// The cells of a 0.5 m raster whose centres fall in `ring`, traced.
    fn traced(ring: &[[f64; 2]]) -> Polygon {
        traced_cells(|x, y| point_in_ring([x, y], ring))
    }

    /// The cells of a 0.5 m raster whose centres `inside` takes, traced.
    fn traced_cells(inside: impl Fn(f64, f64) -> bool) -> Polygon {
        let grid = Grid {
            x0: 0.0,
            y0: 60.0,
            cell_m: 0.5,
            width: 120,
            height: 120,
        };
        let data = (0..grid.len())
            .map(|i| {
                let (x, y) = grid.center(i as u32 % grid.width, i as u32 / grid.width);
                if inside(x, y) { 1.0 } else { 0.0 }
            })
            .collect();
        trace(&Raster {
            grid,
            data: PodVec(data),
        })
        .remove(&1)
        .unwrap()
        .remove(0)
    }

    /// How far `p` is from the nearest of `points`.
    fn nearest(p: [f64; 2], points: &[[f64; 2]]) -> f64 {
        points
            .iter()
            .map(|q| (q[0] - p[0]).hypot(q[1] - p[1]))
            .fold(f64::INFINITY, f64::min)
    }

    fn rotated_rect(c: [f64; 2], half: [f64; 2], deg: f64) -> Vec<[f64; 2]> {
        let (s, co) = deg.to_radians().sin_cos();
        [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
            .iter()
            .map(|k| {
                let (u, v) = (k[0] * half[0], k[1] * half[1]);
                [c[0] + co * u - s * v, c[1] + s * u + co * v]
            })
            .collect()
    }

    /// A rectangle at 0°, 17° and 30° to the grid comes back as four corners at right angles,
    /// each within 0.5 m (a cell) of the true corner, where the traced outline has dozens of stair
    /// steps.
    #[test]
    fn a_rotated_rectangle_comes_back_square() {
        for deg in [0.0, 17.0, 30.0] {
            let truth = rotated_rect([30.0, 30.0], [12.0, 7.0], deg);
            let raw = traced(&truth);
            let out = regularize_polygon(&raw, &RegularizeConfig::default(), None)
                .unwrap_or_else(|| panic!("{deg}°: refused"));
            let r = &out.exterior;
            assert_eq!(
                r.len(),
                4,
                "{deg}°: {r:?} from {} traced",
                raw.exterior.len()
            );
            for k in 0..4 {
                let (a, b, c) = (r[(k + 3) % 4], r[k], r[(k + 1) % 4]);
                let dot = (b[0] - a[0]) * (c[0] - b[0]) + (b[1] - a[1]) * (c[1] - b[1]);
                assert!(dot.abs() < 1e-6, "{deg}°: corner {k} not square");
                let near = nearest(b, &truth);
                assert!(near < 0.5, "{deg}°: corner {b:?} is {near:.2} m off");
            }
        }
    }

    /// What a LiDAR mask makes of a square building's corner (traced from a real one of the
    /// demo's): the corner cell and its neighbour missing in a stair, a cell of returns standing
    /// off the wall beside it (a drainpipe) and a missing cell after that. It comes back a
    /// square corner: a chamfer left at a street corner mirrors a transmitter down the cross
    /// street, where the building's real corner only diffracts.
    #[test]
    fn a_stair_corner_beside_a_spike_comes_back_square() {
        let (x0, x1, y0, y1) = (14.5, 38.5, 14.0, 47.5);
        let raw = traced_cells(|x, y| {
            let rect = x > x0 && x < x1 && y > y0 && y < y1;
            let stair = (x < 15.0 && y < 15.0) || (x < 15.5 && y < 14.5);
            let notch = (17.5..18.0).contains(&x) && y < 14.5;
            let pipe = (16.0..16.5).contains(&x) && (13.5..14.0).contains(&y);
            (rect && !stair && !notch) || pipe
        });
        let out = regularize_polygon(&raw, &RegularizeConfig::default(), None)
            .unwrap_or_else(|| panic!("refused: {:?}", raw.exterior));
        let r = &out.exterior;
        assert_eq!(r.len(), 4, "{r:?}");
        for c in [[x0, y0], [x1, y0], [x1, y1], [x0, y1]] {
            let near = nearest(c, r);
            assert!(near < 0.5, "corner {c:?} is {near:.2} m from {r:?}");
        }
    }

    /// A bay the LiDAR sees in front of a wall, its sides slanted by the stair of cells,
    /// comes back with square sides: a slanted face mirrors the street into a cross street.
    #[test]
    fn a_bay_with_slanted_sides_comes_back_square() {
        let raw = traced_cells(|x, y| {
            let rect = x > 10.0 && x < 40.0 && y > 10.0 && y < 30.0;
            let bay = y > 8.5 && y <= 10.0 && x > 19.0 + (10.0 - y) && x < 24.0 - (10.0 - y);
            rect || bay
        });
        let out = regularize_polygon(&raw, &RegularizeConfig::default(), None)
            .unwrap_or_else(|| panic!("refused: {:?}", raw.exterior));
        let r = &out.exterior;
        assert_eq!(r.len(), 8, "{r:?}");
        for k in 0..r.len() {
            let (a, b) = (r[k], r[(k + 1) % r.len()]);
            let axis = (a[0] - b[0]).abs().min((a[1] - b[1]).abs());
            assert!(axis < 1e-6, "edge {a:?} -> {b:?} is slanted in {r:?}");
        }
    }

    /// A wall snap moves each wall to where it says, and the corners follow.
    #[test]
    fn walls_move_to_where_the_snap_puts_them() {
        let truth = rotated_rect([30.0, 30.0], [12.0, 7.0], 0.0);
        let raw = traced(&truth);
        // Every wall 0.3 m further in than the traced line.
        let snap = |_: [f64; 2], o: f64, _: [f64; 2]| Some(o + 0.3);
        let plain = regularize_polygon(&raw, &RegularizeConfig::default(), None).unwrap();
        let moved = regularize_polygon(&raw, &RegularizeConfig::default(), Some(&snap)).unwrap();
        let (a0, a1) = (plain.area(), moved.area());
        let expected = (24.0 - 0.6 + 0.0) * (14.0 - 0.6);
        assert!(a1 < a0, "{a1} !< {a0}");
        assert!(
            (a1 - expected).abs() < 0.25 * 38.0,
            "area {a1}, expected about {expected}"
        );
    }

    /// A ring that regularizing would turn into something else is refused, not returned.
    #[test]
    fn a_triangle_is_not_squared() {
        let truth = vec![[10.0, 10.0], [50.0, 12.0], [30.0, 45.0]];
        let raw = traced(&truth);
        if let Some(out) = regularize_polygon(&raw, &RegularizeConfig::default(), None) {
            let (a0, a1) = (raw.area(), out.area());
            assert!(((a1 - a0) / a0).abs() <= 0.1, "{a0} -> {a1}");
        }
    }
}
