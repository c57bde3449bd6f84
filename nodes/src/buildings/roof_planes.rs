//! Planar roof faces from a building's roof heights: sequential RANSAC over its cells (the
//! planes of gables, hips, sheds and flat roofs), and the lines where two planes whose cells
//! touch meet (ridges, hips and valleys). A roof surface read cell by cell from LiDAR keeps the
//! returns' noise: its ridge is a zigzag of short edges at random small angles, where a radio
//! ray diffracting over the roof finds no straight edge to turn on. Snapped to its planes, with
//! their meeting lines as edges, it has the one sharp ridge the building has.

use crate::rng::{mix, unit};

/// z = a x + b y + c.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoofPlane {
    /// Rise per metre along x.
    pub a: f64,
    /// Rise per metre along y.
    pub b: f64,
    /// Height at the origin, metres.
    pub c: f64,
}

impl RoofPlane {
    /// The plane's height at (x, y).
    pub fn z(&self, x: f64, y: f64) -> f64 {
        self.a * x + self.b * y + self.c
    }

    /// Least squares over `points`; None when they do not span a plane.
    fn fit(points: impl Iterator<Item = [f64; 3]>) -> Option<RoofPlane> {
        // Centred sums, so the site's large coordinates do not swamp the normal equations.
        let pts: Vec<[f64; 3]> = points.collect();
        let n = pts.len() as f64;
        if pts.len() < 3 {
            return None;
        }
        let m = [0, 1, 2].map(|k| pts.iter().map(|p| p[k]).sum::<f64>() / n);
        let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for p in &pts {
            let (x, y, z) = (p[0] - m[0], p[1] - m[1], p[2] - m[2]);
            sxx += x * x;
            sxy += x * y;
            syy += y * y;
            sxz += x * z;
            syz += y * z;
        }
        let det = sxx * syy - sxy * sxy;
        if det.abs() <= 1e-9 * (sxx * syy).max(1e-12) {
            return None;
        }
        let a = (sxz * syy - syz * sxy) / det;
        let b = (syz * sxx - sxz * sxy) / det;
        Some(RoofPlane {
            a,
            b,
            c: m[2] - a * m[0] - b * m[1],
        })
    }
}

/// The fit's knobs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneConfig {
    /// A cell within this of a plane lies on it, metres.
    pub tolerance_m: f64,
    /// Fewest cells a plane must hold.
    pub min_cells: usize,
    /// Most planes per building.
    pub max_planes: usize,
    /// Plane hypotheses tried per plane.
    pub trials: usize,
    /// Steepest plane, as its rise per metre (a wall's returns are not a roof).
    pub max_slope: f64,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        PlaneConfig {
            tolerance_m: 0.15,
            min_cells: 24,
            max_planes: 8,
            trials: 200,
            max_slope: 1.5,
        }
    }
}

/// Planes found among the cells, and each cell's plane (None: on none, e.g. an HVAC unit).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlaneFit {
    /// The planes, in the order found (most cells first).
    pub planes: Vec<RoofPlane>,
    /// Each cell's plane, an index into `planes`.
    pub of_cell: Vec<Option<u32>>,
}

/// Sequential RANSAC over cells at `xyz` (cell centres and roof heights): the plane holding
/// the most cells within the tolerance among those left (hypotheses through three cells drawn
/// with `seed`), refitted by least squares to them, its cells taken out; until a plane would
/// hold fewer than `min_cells`. Deterministic for a seed.
pub fn fit_planes(xyz: &[[f64; 3]], cfg: &PlaneConfig, seed: u64) -> PlaneFit {
    let mut fit = PlaneFit {
        planes: Vec::new(),
        of_cell: vec![None; xyz.len()],
    };
    let mut left: Vec<usize> = (0..xyz.len()).filter(|&k| xyz[k][2].is_finite()).collect();
    let near = |pl: &RoofPlane, k: usize| {
        (xyz[k][2] - pl.z(xyz[k][0], xyz[k][1])).abs() <= cfg.tolerance_m
    };
    let mut draw = 0u64;
    while left.len() >= cfg.min_cells.max(3) && fit.planes.len() < cfg.max_planes {
        let mut best: Option<(usize, RoofPlane)> = None;
        for _ in 0..cfg.trials {
            let mut pick = || {
                draw += 1;
                left[(unit(mix(seed ^ mix(draw))) * left.len() as f64) as usize % left.len()]
            };
            let (i, j, k) = (pick(), pick(), pick());
            let [p, q, r] = [xyz[i], xyz[j], xyz[k]];
            // Three cells spread over a triangle of a square metre or more.
            let area = 0.5 * ((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])).abs();
            if area < 1.0 {
                continue;
            }
            let Some(pl) = RoofPlane::fit([p, q, r].into_iter()) else {
                continue;
            };
            if pl.a.hypot(pl.b) > cfg.max_slope {
                continue;
            }
            let n = left.iter().filter(|&&k| near(&pl, k)).count();
            if best.is_none_or(|(m, _)| n > m) {
                best = Some((n, pl));
            }
        }
        let Some((n, pl)) = best else { break };
        if n < cfg.min_cells {
            break;
        }
        let inliers: Vec<usize> = left.iter().copied().filter(|&k| near(&pl, k)).collect();
        let Some(refit) = RoofPlane::fit(inliers.iter().map(|&k| xyz[k])) else {
            break;
        };
        let kept: Vec<usize> = left.iter().copied().filter(|&k| near(&refit, k)).collect();
        if kept.len() < cfg.min_cells || refit.a.hypot(refit.b) > cfg.max_slope {
            break;
        }
        let id = fit.planes.len() as u32;
        for &k in &kept {
            fit.of_cell[k] = Some(id);
        }
        fit.planes.push(refit);
        left.retain(|&k| fit.of_cell[k].is_none());
    }
    fit
}

/// Where two planes meet, a segment of their intersection line: along the stretch where their
/// cells touch (`touching`: pairs of cell indices into the fit's cells that are neighbours),
/// each pair's midpoint projected on the line. Pairs of planes that touch along a step (their
/// line more than `max_off_m` from the touching midpoints, or planes within `min_angle_deg`
/// of parallel) meet at no edge. Returns (plane, plane, from, to), in plane order.
pub fn meeting_lines(
    fit: &PlaneFit,
    xy: &[[f64; 2]],
    touching: &[(usize, usize)],
    max_off_m: f64,
    min_angle_deg: f64,
) -> Vec<(u32, u32, [f64; 2], [f64; 2])> {
    let mut by_pair: std::collections::BTreeMap<(u32, u32), Vec<[f64; 2]>> = Default::default();
    for &(i, j) in touching {
        if let (Some(p), Some(q)) = (fit.of_cell[i], fit.of_cell[j])
            && p != q
        {
            let mid = [(xy[i][0] + xy[j][0]) / 2.0, (xy[i][1] + xy[j][1]) / 2.0];
            by_pair.entry((p.min(q), p.max(q))).or_default().push(mid);
        }
    }
    let cos_min = min_angle_deg.to_radians().cos();
    let mut out = Vec::new();
    for ((p, q), mids) in by_pair {
        if mids.len() < 3 {
            continue;
        }
        let (s, t) = (fit.planes[p as usize], fit.planes[q as usize]);
        // Normals (-a, -b, 1), and the line (a_s - a_t) x + (b_s - b_t) y + (c_s - c_t) = 0.
        let (ns, nt) = ([-s.a, -s.b, 1.0], [-t.a, -t.b, 1.0]);
        let dot = ns[0] * nt[0] + ns[1] * nt[1] + 1.0;
        let len = |n: [f64; 3]| (n[0] * n[0] + n[1] * n[1] + 1.0).sqrt();
        if dot / (len(ns) * len(nt)) > cos_min {
            continue;
        }
        let (da, db, dc) = (s.a - t.a, s.b - t.b, s.c - t.c);
        let g = da.hypot(db);
        if g < 1e-9 {
            continue;
        }
        let normal = [da / g, db / g];
        let off = dc / g;
        let dir = [-normal[1], normal[0]];
        let mut lo = f64::MAX;
        let mut hi = f64::MIN;
        let mut dist = 0.0;
        for m in &mids {
            dist += (normal[0] * m[0] + normal[1] * m[1] + off).abs();
            let along = dir[0] * m[0] + dir[1] * m[1];
            lo = lo.min(along);
            hi = hi.max(along);
        }
        if dist / mids.len() as f64 > max_off_m || hi - lo < 1.0 {
            continue;
        }
        // The foot of the line nearest the origin, then along it.
        let foot = [-off * normal[0], -off * normal[1]];
        let at = |s: f64| [foot[0] + dir[0] * s, foot[1] + dir[1] * s];
        out.push((p, q, at(lo), at(hi)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hipped roof on a 0.5 m grid: 20 m x 12 m, eaves at 10 m, ridge at 14 m along x.
    fn hipped(noise: f64) -> (Vec<[f64; 3]>, usize, usize) {
        let (w, h) = (40usize, 24usize);
        let mut out = Vec::new();
        for r in 0..h {
            for c in 0..w {
                let (x, y) = (0.25 + 0.5 * c as f64, 0.25 + 0.5 * r as f64);
                let to_eave = y.min(12.0 - y).min(x).min(20.0 - x);
                let z = 10.0 + 4.0 / 6.0 * to_eave;
                let e = noise * (unit(mix((r * w + c) as u64)) - 0.5) * 2.0;
                out.push([x + 1000.0, y + 5000.0, z + e]);
            }
        }
        (out, w, h)
    }

    fn neighbours(w: usize, h: usize) -> Vec<(usize, usize)> {
        let mut v = Vec::new();
        for r in 0..h {
            for c in 0..w {
                if c + 1 < w {
                    v.push((r * w + c, r * w + c + 1));
                }
                if r + 1 < h {
                    v.push((r * w + c, (r + 1) * w + c));
                }
            }
        }
        v
    }

    #[test]
    fn a_hipped_roof_is_four_planes_meeting_at_a_ridge_and_four_hips() {
        let (xyz, w, h) = hipped(0.08);
        let fit = fit_planes(&xyz, &PlaneConfig::default(), 7);
        assert_eq!(fit.planes.len(), 4, "{:?}", fit.planes);
        // Each plane's slope is the roof's 4 m over 6 m.
        for pl in &fit.planes {
            assert!((pl.a.hypot(pl.b) - 4.0 / 6.0).abs() < 0.01, "{pl:?}");
        }
        let on = fit.of_cell.iter().filter(|c| c.is_some()).count();
        assert!(
            on as f64 >= 0.95 * xyz.len() as f64,
            "{on} of {}",
            xyz.len()
        );
        let xy: Vec<[f64; 2]> = xyz.iter().map(|p| [p[0], p[1]]).collect();
        let lines = meeting_lines(&fit, &xy, &neighbours(w, h), 0.75, 5.0);
        // The ridge: along x at y = 6 (+5000), from x = 6 to 14 (+1000), at 14 m.
        let ridge = lines
            .iter()
            .find(|l| (l.2[1] - l.3[1]).abs() < 0.05)
            .expect("a ridge along x");
        for e in [ridge.2, ridge.3] {
            assert!((e[1] - 5006.0).abs() < 0.05, "{ridge:?}");
            let z = fit.planes[ridge.0 as usize].z(e[0], e[1]);
            assert!((z - 14.0).abs() < 0.05, "{z}");
        }
        let xs = (ridge.2[0].min(ridge.3[0]), ridge.2[0].max(ridge.3[0]));
        assert!(
            xs.0 > 1005.5 && xs.0 < 1006.8 && xs.1 > 1013.2 && xs.1 < 1014.5,
            "{xs:?}"
        );
        // And four hips.
        assert_eq!(lines.len(), 5, "{lines:?}");
    }

    #[test]
    fn a_flat_roof_with_a_unit_on_it_is_one_plane_and_the_unit_none() {
        let mut xyz = Vec::new();
        for r in 0..20 {
            for c in 0..20 {
                let unit_here = (5..9).contains(&r) && (5..9).contains(&c);
                let z = if unit_here { 21.6 } else { 20.0 };
                xyz.push([0.25 + 0.5 * c as f64, 0.25 + 0.5 * r as f64, z]);
            }
        }
        let fit = fit_planes(&xyz, &PlaneConfig::default(), 1);
        assert_eq!(fit.planes.len(), 1);
        assert!(fit.planes[0].a.abs() < 1e-9 && (fit.planes[0].c - 20.0).abs() < 1e-9);
        assert_eq!(fit.of_cell.iter().filter(|c| c.is_none()).count(), 16);
        // The same at any seed: the one plane holds every flat cell.
        assert_eq!(
            fit_planes(&xyz, &PlaneConfig::default(), 99).of_cell,
            fit.of_cell
        );
    }
}
