//! A protruding region past the twin's silhouette (a feature by a corner seen from the street
//! round it): the wall end it stands by.

use glam::DVec3;

use crate::artifact::{ChartKind, ChartSet, View};

use crate::geom::theil_sen::median;

/// How far (as a share of the range its pixels' depth gives) a region's centre ray may run past
/// that range before the region counts as standing past the twin's silhouette, and how far from
/// it the wall end it stands by may lie: the calibrated depth of a thin feature errs by 5-10 %.
const SILHOUETTE_DEPTH_SLACK: f64 = 0.25;

/// Where a region that may stand past the twin's silhouette stands (see [`silhouette_edge`]):
/// `seen` its pixels, its first and last pixel columns and centre row, and its centre ray;
/// `hit` how far that ray meets the twin; `point` a pixel's calibrated point; `reach` its
/// class's deepest protrusion. None where its pixels' depth gives no range, or where the ray
/// meets the twin about where that depth puts the region.
pub(super) fn past_silhouette(
    view: &View,
    (pixels, (x0, x1, cy), dir): (&[u32], (u32, u32, f64), DVec3),
    hit: Option<f64>,
    point: impl Fn(usize) -> Option<DVec3>,
    charts: &ChartSet,
    reach: f64,
) -> Option<(u32, DVec3)> {
    let eye = DVec3::from(view.pose.position);
    let mut range: Vec<f64> = pixels
        .iter()
        .filter_map(|&q| point(q as usize))
        .map(|x| x.distance(eye))
        .collect();
    if range.len() < 5 {
        return None;
    }
    let range = median(&mut range).unwrap_or(f64::NAN);
    let slack = (SILHOUETTE_DEPTH_SLACK * range).max(1.0);
    if hit.is_some_and(|t| t <= range + slack) {
        return None;
    }
    let l = DVec3::from(view.pixel_ray(x0 as f64, cy).0);
    let r = DVec3::from(view.pixel_ray(x1 as f64 + 1.0, cy).0);
    let cos = l.dot(r) / (l.dot(l) * r.dot(r)).sqrt();
    let half_width = 0.5 * cos.clamp(-1.0, 1.0).acos() * range;
    silhouette_edge(
        charts,
        eye,
        dir,
        reach + half_width,
        (range - slack, range + slack),
    )
}

/// The wall end a ray from `eye` along unit `dir` passes within `reach` of, on the wall's outer
/// side, at a distance along the ray within `range`, for a wall whose face `eye` lies behind
/// (a view sees a feature past a corner only on the wall round it): the chart and the nearest
/// point of that end. The closest such end if several.
fn silhouette_edge(
    charts: &ChartSet,
    eye: DVec3,
    dir: DVec3,
    reach: f64,
    range: (f64, f64),
) -> Option<(u32, DVec3)> {
    let mut best: Option<(f64, u32, DVec3)> = None;
    for (ci, c) in charts.charts.iter().enumerate() {
        if c.kind != ChartKind::Wall || c.width == 0 || c.height == 0 {
            continue;
        }
        let (n, origin) = (DVec3::from(c.normal), DVec3::from(c.origin));
        if (eye - origin).dot(n) >= 0.0 {
            continue;
        }
        let up = DVec3::from(c.v_axis) * c.height as f64 * c.texel_m;
        for end in [0.0, c.width as f64 * c.texel_m] {
            let a = origin + DVec3::from(c.u_axis) * end;
            // Closest approach of the ray and the segment a + s up, s in [0, 1].
            let w0 = eye - a;
            let (b, cc, d, e) = (dir.dot(up), up.dot(up), dir.dot(w0), up.dot(w0));
            let denom = cc - b * b;
            if denom <= 1e-9 * cc {
                continue;
            }
            let s = ((e - b * d) / denom).clamp(0.0, 1.0);
            let t = s * b - d;
            if t < range.0 || t > range.1 {
                continue;
            }
            let on_ray = eye + dir * t;
            let on_end = a + up * s;
            let gap = on_ray.distance(on_end);
            if gap > reach || (on_ray - origin).dot(n) < 0.0 {
                continue;
            }
            if best.is_none_or(|(g, _, _)| gap < g) {
                best = Some((gap, ci as u32, on_end));
            }
        }
    }
    best.map(|(_, ci, at)| (ci, at))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_feature_past_a_corner_stands_on_the_wall_seen_from_behind() {
        let charts = ChartSet {
            charts: vec![crate::artifact::Chart::flat_wall(100, 100)],
        };
        let ray = |eye: DVec3, to: [f64; 3]| {
            let d = DVec3::from(to) - eye;
            (d / d.length(), d.length())
        };
        let eye = DVec3::new(12.0, 10.0, 1.5);
        let (dir, dist) = ray(eye, [10.05, -0.08, 5.0]);
        let around = (dist - 2.0, dist + 2.0);
        let (ci, at) = silhouette_edge(&charts, eye, dir, 0.3, around).unwrap();
        let (u, v) = charts.charts[ci as usize].uv_of(at.to_array());
        assert_eq!(u, 100.0);
        assert!((v - 50.0).abs() < 2.0, "{v}");
        // Not where its depth puts it farther off, nor beyond the reach of the wall's end.
        assert!(silhouette_edge(&charts, eye, dir, 0.3, (dist + 5.0, dist + 9.0)).is_none());
        assert!(silhouette_edge(&charts, eye, dir, 0.01, around).is_none());
        // A view the wall faces sees a feature there on the wall, not past it.
        let front = DVec3::new(12.0, -10.0, 1.5);
        let (dir, dist) = ray(front, [10.05, -0.08, 5.0]);
        assert!(silhouette_edge(&charts, front, dir, 0.3, (dist - 2.0, dist + 2.0)).is_none());
        // Nor on a ray that crosses the wall's plane inside its end (into the building).
        let (dir, dist) = ray(eye, [10.05, 1.0, 5.0]);
        assert!(silhouette_edge(&charts, eye, dir, 0.3, (dist - 2.0, dist + 2.0)).is_none());
    }
}
