//! A view's reported depth calibrated against the twin: a Theil-Sen affine fit of reported depth
//! against ray-cast depth (monocular depth is affinely biased), and the median with its standard
//! error that the depth cue rests on.

use crate::artifact::{ChartSet, View};
use crate::geom::raycast::SceneRays;
use crate::geom::theil_sen::{median, theil_sen};

use super::lookup::Lookup;

/// Median and its standard error (1.4826 MAD x 1.2533 / sqrt(n)).
pub(super) fn median_se(v: &mut [f64]) -> (f64, f64) {
    let m = median(v).unwrap_or(f64::NAN);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    let mad = median(&mut dev).unwrap_or(f64::NAN);
    (m, 1.4826 * mad * 1.2533 / (v.len() as f64).sqrt())
}

/// Fewer points than this leave a view uncalibrated.
const MIN_POINTS: usize = 30;

/// The affine fit y = a x + b of reported depth on ray-cast depth: the Theil-Sen fit the clutter's
/// lifting uses too ([`theil_sen`]; its intercept from the residuals' shortest half, which
/// one-sided outliers such as balconies in front of a wall do not drag). `None` with fewer than
/// 30 points, too little spread in x to separate scale from offset (1 m standard deviation), or a
/// fit that does not rise.
pub fn depth_affine(xs: &[f64], ys: &[f64]) -> Option<(f64, f64)> {
    let n = xs.len();
    if n < MIN_POINTS {
        return None;
    }
    let mean = xs.iter().sum::<f64>() / n as f64;
    let variance = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64;
    if !(variance >= 1.0) {
        return None;
    }
    theil_sen(xs, ys, 0.5, 20_000, CALIBRATION_SEED)
        .filter(|f| f.slope > 0.0 && f.slope.is_finite() && f.intercept.is_finite())
        .map(|f| (f.slope, f.intercept))
}

/// The seed of the pairs Theil-Sen draws when a view has more than it takes: fixed, so a view's
/// calibration is the same in every run.
const CALIBRATION_SEED: u64 = 0x5EED;

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
    depth_affine(&xs, &ys)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_affine_recovers_scale_and_offset_despite_outliers() {
        let xs: Vec<f64> = (0..200).map(|i| 5.0 + i as f64 * 0.1).collect();
        let mut ys: Vec<f64> = xs.iter().map(|x| 0.8 * x + 1.0).collect();
        for k in (0..200).step_by(10) {
            ys[k] -= 3.0; // balconies in front of the wall
        }
        let (a, b) = depth_affine(&xs, &ys).unwrap();
        assert!((a - 0.8).abs() < 1e-9 && (b - 1.0).abs() < 1e-9, "{a} {b}");
        // No spread, no fit.
        assert!(depth_affine(&vec![10.0; 100], &vec![9.0; 100]).is_none());
    }
}
