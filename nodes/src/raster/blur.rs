//! Gaussian smoothing of rasters with no-data.

use rayon::prelude::*;

use crate::artifact::{PodVec, Raster};
use crate::stage::Progress;

/// Smooths `r` with a Gaussian of `sigma_m` metres, truncated at 3 sigma. Each output cell is the
/// kernel-weighted mean of the valid cells around it (weights renormalised), so no-data does not
/// drag values down and edges are not darkened. No-data cells stay no-data unless `fill`.
pub fn gaussian_blur(r: &Raster, sigma_m: f64, fill: bool) -> Raster {
    gaussian_blur_with_progress(r, sigma_m, fill, &crate::stage::NoProgress)
}

/// [`gaussian_blur`], reporting one unit of progress per row of each of the two passes.
pub fn gaussian_blur_with_progress(
    r: &Raster,
    sigma_m: f64,
    fill: bool,
    progress: &dyn Progress,
) -> Raster {
    let g = r.grid;
    let sigma = sigma_m / g.cell_m;
    if sigma < 1e-6 || g.is_empty() {
        return r.clone();
    }
    // A kernel reaching past the raster's longer side weighs nothing more, so it stops there:
    // the output is the same, and a huge sigma (or a tiny cell) sizes no huge kernel.
    let radius = ((3.0 * sigma).ceil()).min(g.width.max(g.height) as f64) as i64;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp())
        .collect();
    let (w, h) = (g.width as usize, g.height as usize);
    progress.set_total(2 * h as u64);
    // Horizontal pass: weighted sums and weights, kept apart so the vertical pass can renormalise.
    let mut sum = vec![0f64; w * h];
    let mut wsum = vec![0f64; w * h];
    sum.par_chunks_mut(w)
        .zip(wsum.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, (s, ws))| {
            let src = &r.data[row * w..(row + 1) * w];
            for (c, (s, ws)) in s.iter_mut().zip(ws.iter_mut()).enumerate() {
                let lo = (c as i64 - radius).max(0) as usize;
                let hi = ((c as i64 + radius) as usize).min(w - 1);
                let (mut a, mut b) = (0.0, 0.0);
                for (cc, &v) in src.iter().enumerate().take(hi + 1).skip(lo) {
                    if v.is_finite() {
                        let kw = kernel[(cc as i64 - c as i64 + radius) as usize];
                        a += kw * v as f64;
                        b += kw;
                    }
                }
                *s = a;
                *ws = b;
            }
            progress.advance(1);
        });
    // Vertical pass: whole rows at a time, so memory is read contiguously.
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(row, o)| {
        let mut a = vec![0f64; w];
        let mut b = vec![0f64; w];
        for (k, kw) in kernel.iter().enumerate() {
            let rr = row as i64 + k as i64 - radius;
            if rr < 0 || rr >= h as i64 {
                continue;
            }
            let base = rr as usize * w;
            for (c, (a, b)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
                *a += kw * sum[base + c];
                *b += kw * wsum[base + c];
            }
        }
        for (c, out_cell) in o.iter_mut().enumerate() {
            let keep = fill || r.data[row * w + c].is_finite();
            *out_cell = if keep && b[c] > 0.0 {
                (a[c] / b[c]) as f32
            } else {
                f32::NAN
            };
        }
        progress.advance(1);
    });
    Raster {
        grid: g,
        data: PodVec(out),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Grid;

    fn grid(w: u32, h: u32) -> Grid {
        Grid {
            x0: 0.0,
            y0: 0.0,
            cell_m: 1.0,
            width: w,
            height: h,
        }
    }

    #[test]
    fn preserves_planes_and_constants() {
        // A plane is an eigenfunction of a symmetric, normalised kernel away from the border.
        let g = grid(40, 30);
        let data = (0..g.len())
            .map(|i| (0.5 * (i % 40) as f64 - 0.25 * (i / 40) as f64) as f32)
            .collect();
        let r = Raster {
            grid: g,
            data: PodVec(data),
        };
        let s = gaussian_blur(&r, 2.0, false);
        for row in 8..22 {
            for col in 8..32 {
                assert!((s.at(col, row) - r.at(col, row)).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn spreads_an_impulse_as_a_normalised_gaussian() {
        let g = grid(41, 41);
        let mut r = Raster::filled(g, 0.0);
        r.data[20 * 41 + 20] = 1.0;
        let s = gaussian_blur(&r, 3.0, false);
        let total: f64 = s.data.iter().map(|&v| v as f64).sum();
        assert!((total - 1.0).abs() < 1e-3, "mass {total}");
        let expected_peak = 1.0 / (2.0 * std::f64::consts::PI * 9.0);
        assert!(((s.at(20, 20) as f64) - expected_peak).abs() / expected_peak < 0.02);
    }

    #[test]
    fn no_data_is_ignored_not_averaged_as_zero() {
        let g = grid(5, 1);
        let r = Raster {
            grid: g,
            data: PodVec(vec![2.0, f32::NAN, 2.0, 2.0, 2.0]),
        };
        let s = gaussian_blur(&r, 1.0, false);
        assert!(s.data[1].is_nan());
        assert!(
            s.data
                .iter()
                .filter(|v| v.is_finite())
                .all(|&v| (v - 2.0).abs() < 1e-6)
        );
        let filled = gaussian_blur(&r, 1.0, true);
        assert!((filled.data[1] - 2.0).abs() < 1e-6);
    }
}
