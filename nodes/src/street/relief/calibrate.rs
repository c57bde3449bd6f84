//! A view's reported depth calibrated against the twin: a robust affine fit of reported depth
//! against ray-cast depth (monocular depth is affinely biased), and the median with its standard
//! error that the depth cue rests on.

use crate::artifact::{ChartSet, View};
use crate::geom::raycast::SceneRays;
use crate::geom::theil_sen::median;

use super::lookup::Lookup;

/// Median and its standard error (1.4826 MAD x 1.2533 / sqrt(n)).
pub(super) fn median_se(v: &mut [f64]) -> (f64, f64) {
    let m = median(v).unwrap_or(f64::NAN);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    let mad = median(&mut dev).unwrap_or(f64::NAN);
    (m, 1.4826 * mad * 1.2533 / (v.len() as f64).sqrt())
}

/// Robust affine fit y = a x + b: least squares, then refits on the points within three robust
/// standard deviations of the line, four times. `None` when too few points or too little spread
/// in x to separate scale from offset.
pub fn robust_affine(xs: &[f64], ys: &[f64]) -> Option<(f64, f64)> {
    let n = xs.len();
    if n < 30 {
        return None;
    }
    let mut keep = vec![true; n];
    let mut fit = None;
    for _ in 0..5 {
        let (mut sx, mut sy, mut c) = (0.0, 0.0, 0.0);
        for i in 0..n {
            if keep[i] {
                sx += xs[i];
                sy += ys[i];
                c += 1.0;
            }
        }
        if c < 30.0 {
            return None;
        }
        let (mx, my) = (sx / c, sy / c);
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for i in 0..n {
            if keep[i] {
                sxx += (xs[i] - mx) * (xs[i] - mx);
                sxy += (xs[i] - mx) * (ys[i] - my);
            }
        }
        // Depth must spread over at least 1 m (std) to tell scale from offset.
        if sxx / c < 1.0 {
            return None;
        }
        let a = sxy / sxx;
        let b = my - a * mx;
        fit = Some((a, b));
        let mut res: Vec<f64> = (0..n).map(|i| (ys[i] - a * xs[i] - b).abs()).collect();
        let mad = median(&mut res.clone()).unwrap_or(f64::NAN).max(1e-6);
        for i in 0..n {
            keep[i] = res[i] <= 3.0 * 1.4826 * mad;
        }
        res.clear();
    }
    fit.filter(|(a, b)| *a > 0.0 && a.is_finite() && b.is_finite())
}

/// Calibrates a view's reported depth against the twin: (a, b) with reported = a z + b, from
/// wall pixels whose ray hits a wall chart and unlabelled pixels whose ray hits the terrain
/// (every 4th pixel each way): the ground spreads the depths a head-on wall alone does not.
pub(super) fn calibrate(
    view: &View,
    rays: &SceneRays,
    charts: &ChartSet,
    lookup: &Lookup,
    is_wall: &dyn Fn(usize) -> bool,
    is_ground: &dyn Fn(usize) -> bool,
) -> Option<(f64, f64)> {
    let depth = view.depth.as_ref()?;
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    let origin = view.pose.position.map(|c| c as f32);
    for y in (2..view.height).step_by(4) {
        for x in (2..view.width).step_by(4) {
            let px = (y * view.width + x) as usize;
            let d = depth.get(px).copied().unwrap_or(f32::NAN) as f64;
            let (wall, ground) = (is_wall(px), is_ground(px));
            if !d.is_finite() || !(wall || ground) {
                continue;
            }
            let (dir, norm) = view.pixel_ray(x as f64 + 0.5, y as f64 + 0.5);
            let Some(hit) = rays.cast(origin, dir.map(|c| c as f32), 1e-3, 2000.0) else {
                continue;
            };
            let ok = if wall {
                lookup
                    .wall_chart(charts, hit.object, hit.triangle)
                    .is_some()
            } else {
                lookup.terrain.get(hit.object).copied().unwrap_or(false)
            };
            if !ok {
                continue;
            }
            xs.push(hit.t as f64 / norm);
            ys.push(d);
        }
    }
    robust_affine(&xs, &ys)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_affine_recovers_scale_and_offset_despite_outliers() {
        let xs: Vec<f64> = (0..200).map(|i| 5.0 + i as f64 * 0.1).collect();
        let mut ys: Vec<f64> = xs.iter().map(|x| 0.8 * x + 1.0).collect();
        for k in (0..200).step_by(10) {
            ys[k] -= 3.0; // balconies in front of the wall
        }
        let (a, b) = robust_affine(&xs, &ys).unwrap();
        assert!((a - 0.8).abs() < 1e-9 && (b - 1.0).abs() < 1e-9, "{a} {b}");
        // No spread, no fit.
        assert!(robust_affine(&vec![10.0; 100], &vec![9.0; 100]).is_none());
    }
}
