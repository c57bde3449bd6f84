//! Theil-Sen line fit: the median of pairwise slopes and the median residual intercept, robust to
//! up to about 29 % of arbitrary outliers (its breakdown point). What calibrates a monocular depth
//! map's affine bias against depths cast into the twin (paper Sec. 4.2.4); any other robust
//! affine fit (relief's plane offsets, for one) could share it.

use crate::rng::mix;

/// A fitted line y = slope x + intercept.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineFit {
    /// a.
    pub slope: f64,
    /// b.
    pub intercept: f64,
    /// Pairs whose slopes were taken.
    pub pairs: usize,
}

impl LineFit {
    /// slope x + intercept.
    pub fn eval(&self, x: f64) -> f64 {
        self.slope * x + self.intercept
    }
}

/// The median of `v` (the mean of the two middle values for an even length); `None` when empty.
/// Reorders `v`.
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let n = v.len();
    let (_, &mut hi, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        return Some(hi);
    }
    let lo = v[..n / 2].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some((lo + hi) / 2.0)
}

/// The weighted median of (value, weight) pairs: the first value, in increasing order, at which
/// the running weight reaches half the total; `None` when empty. Sorts `v` by value.
pub fn weighted_median(v: &mut [(f64, f64)]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|x| x.1).sum();
    let mut acc = 0.0;
    for x in v.iter() {
        acc += x.1;
        if acc >= total / 2.0 {
            return Some(x.0);
        }
    }
    v.last().map(|x| x.0)
}

/// The median of the shortest half of `v`: the values in the narrowest window holding
/// floor(n/2) + 1 of them (Rousseeuw's shorth), whose median is a location estimate that, unlike
/// the plain median, one-sided contamination below 50 % barely moves. Sorts `v`; `None` when
/// empty.
pub fn shorth_median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let k = n / 2 + 1;
    let start = (0..=n - k)
        .min_by(|&i, &j| (v[i + k - 1] - v[i]).total_cmp(&(v[j + k - 1] - v[j])))
        .unwrap_or(0);
    median(&mut v[start..start + k])
}

/// Theil-Sen fit of y = a x + b over the finite pairs of `xs` and `ys`: a is the median of the
/// slopes (y_j - y_i) / (x_j - x_i) over pairs with |x_j - x_i| > `min_dx`, b the median of the
/// residuals y - a x within their shortest half ([`shorth_median`]): the plain median of the
/// residuals, Theil's choice, is dragged by one-sided outliers (an occluder is always in front of
/// the surface the twin sees), the shortest half sits on the inliers. With more than `max_pairs` pairs, `max_pairs` of them are drawn by a hash of
/// (`seed`, draw index), so the result does not depend on thread count or call order.
/// `None` with fewer than two usable points or no pair spread in x.
pub fn theil_sen(
    xs: &[f64],
    ys: &[f64],
    min_dx: f64,
    max_pairs: usize,
    seed: u64,
) -> Option<LineFit> {
    let pts: Vec<(f64, f64)> = xs
        .iter()
        .zip(ys)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(&x, &y)| (x, y))
        .collect();
    let n = pts.len();
    if n < 2 {
        return None;
    }
    let total = n * (n - 1) / 2;
    let mut slopes = Vec::with_capacity(total.min(max_pairs.max(1)));
    let mut push = |i: usize, j: usize| {
        let (dx, dy) = (pts[j].0 - pts[i].0, pts[j].1 - pts[i].1);
        if dx.abs() > min_dx {
            slopes.push(dy / dx);
        }
    };
    if total <= max_pairs {
        for i in 0..n {
            for j in i + 1..n {
                push(i, j);
            }
        }
    } else {
        for k in 0..max_pairs as u64 {
            let h = mix(seed ^ mix(k));
            let i = (h % n as u64) as usize;
            let j = (mix(h) % (n as u64 - 1)) as usize;
            let j = if j >= i { j + 1 } else { j };
            push(i.min(j), i.max(j));
        }
    }
    let pairs = slopes.len();
    let slope = median(&mut slopes)?;
    let mut res: Vec<f64> = pts.iter().map(|(x, y)| y - slope * x).collect();
    let intercept = shorth_median(&mut res)?;
    Some(LineFit {
        slope,
        intercept,
        pairs,
    })
}

/// Ordinary least squares y = a x + b over the finite pairs (the fit Theil-Sen is compared with);
/// `None` without spread in x.
pub fn least_squares(xs: &[f64], ys: &[f64]) -> Option<LineFit> {
    let pts: Vec<(f64, f64)> = xs
        .iter()
        .zip(ys)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(&x, &y)| (x, y))
        .collect();
    let n = pts.len() as f64;
    if pts.len() < 2 {
        return None;
    }
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if !(sxx > 0.0) {
        return None;
    }
    let slope = sxy / sxx;
    Some(LineFit {
        slope,
        intercept: my - slope * mx,
        pairs: pts.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_line_and_median() {
        let xs: Vec<f64> = (0..20).map(|i| i as f64).collect();
        let ys: Vec<f64> = xs.iter().map(|x| 1.25 * x - 1.5).collect();
        let f = theil_sen(&xs, &ys, 1e-9, 1000, 1).unwrap();
        assert!((f.slope - 1.25).abs() < 1e-12 && (f.intercept + 1.5).abs() < 1e-12);
        assert_eq!(median(&mut [3.0, 1.0, 2.0, 10.0]), Some(2.5));
        assert_eq!(median(&mut []), None);
        // Shortest half of 1..=5 plus two far values: {1, 2, 3, 4} -> 2.5; the median would be 4.
        assert_eq!(
            shorth_median(&mut [5.0, 1.0, 3.0, 2.0, 4.0, 90.0, 80.0]),
            Some(2.5)
        );
        assert!(theil_sen(&[1.0, 1.0], &[0.0, 5.0], 1e-9, 10, 0).is_none());
    }

    #[test]
    fn subsampled_fit_is_deterministic() {
        let xs: Vec<f64> = (0..3000).map(|i| (i % 97) as f64 * 0.3).collect();
        let ys: Vec<f64> = xs.iter().map(|x| 2.0 * x + 0.5).collect();
        let a = theil_sen(&xs, &ys, 1e-9, 5000, 9).unwrap();
        let b = theil_sen(&xs, &ys, 1e-9, 5000, 9).unwrap();
        assert_eq!(a, b);
        assert!((a.slope - 2.0).abs() < 1e-9, "{a:?}");
    }

    #[test]
    fn weighted_median_follows_the_weights() {
        let mut v = vec![(0.25, 10.0), (0.1, 1.0), (0.3, 2.0)];
        assert_eq!(weighted_median(&mut v), Some(0.25));
        let mut v = vec![(0.25, 1.0), (0.1, 10.0)];
        assert_eq!(weighted_median(&mut v), Some(0.1));
    }
}
