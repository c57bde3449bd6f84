//! Path-loss lines fitted to data: the floating-intercept power-distance model and the close-in
//! free-space reference model (paper Sec. 5; the close-in model of Sun, Rappaport et al., IEEE
//! Trans. Veh. Technol. 65(5), 2016, with d0 = 1 m).

use crate::rf::em::fspl_db;

/// Floating-intercept fit PL = α + 10 β log10 d by least squares: (α, β).
pub fn fit_power_distance(d: &[f64], pl: &[f64]) -> (f64, f64) {
    let x: Vec<f64> = d.iter().map(|d| 10.0 * d.log10()).collect();
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, pl.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(pl).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = x.iter().map(|x| (x - mx) * (x - mx)).sum();
    let beta = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - beta * mx, beta)
}

/// Close-in fit PL = FSPL(f, 1 m) + 10 n log10 d by least squares: n.
pub fn fit_close_in(d: &[f64], pl: &[f64], freq_hz: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for i in 0..d.len() {
        let a = pl[i] - fspl_db(1.0, freq_hz[i]);
        let dd = 10.0 * d[i].log10();
        num += a * dd;
        den += dd * dd;
    }
    if den > 0.0 { num / den } else { 0.0 }
}
