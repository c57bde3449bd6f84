//! An instance's rectangle from its evidence: where the evidence profile falls to half its peak,
//! with the fusion's blur taken off.

/// Texel box of a set of texels: (i0, j0, i1, j1), inclusive.
pub(super) fn texel_box(texels: &[usize], w: u32) -> [usize; 4] {
    let w = w as usize;
    texels.iter().fold([usize::MAX, usize::MAX, 0, 0], |b, &k| {
        let (i, j) = (k % w, k / w);
        [b[0].min(i), b[1].min(j), b[2].max(i), b[3].max(j)]
    })
}

/// How far the evidence reaches past an instance's texels: the fusion kernel's and the bilinear
/// deposit's spread.
const EXTENT_REACH: usize = 3;

/// An instance's rectangle (u0, v0, u1, v1) in texels: along each axis, where its evidence
/// profile (the layer's mean across the instance's span, per texel column or row) falls to half
/// its peak, interpolated between texel centres. A feature narrower than two texels (a drainpipe)
/// gets its width and place from how its evidence splits between the columns, not from the
/// whole texels that cleared the threshold.
pub(super) fn extent(texels: &[usize], evidence: &[f32], w: u32, h: u32, spread: f64) -> [f64; 4] {
    let b = texel_box(texels, w);
    let (wu, hu) = (w as usize, h as usize);
    let span = |lo: usize, hi: usize, len: usize| {
        (
            lo.saturating_sub(EXTENT_REACH),
            (hi + EXTENT_REACH).min(len - 1),
        )
    };
    let (ua, ub) = span(b[0], b[2], wu);
    let (va, vb) = span(b[1], b[3], hu);
    let cols: Vec<f64> = (ua..=ub)
        .map(|i| mean_finite(evidence, &mut (b[1]..=b[3]).map(|j| j * wu + i)))
        .collect();
    let rows: Vec<f64> = (va..=vb)
        .map(|j| mean_finite(evidence, &mut (b[0]..=b[2]).map(|i| j * wu + i)))
        .collect();
    let (u0, u1) = deblurred(half_peak_edges(&cols, b[0] - ua, b[2] - ua), spread);
    let (v0, v1) = deblurred(half_peak_edges(&rows, b[1] - va, b[3] - va), spread);
    [
        (ua as f64 + u0).max(0.0),
        (va as f64 + v0).max(0.0),
        (ua as f64 + u1).min(w as f64),
        (va as f64 + v1).min(h as f64),
    ]
}

/// Mean of the finite `evidence` at `cells`, NaN where none is.
pub(super) fn mean_finite(evidence: &[f32], cells: &mut dyn Iterator<Item = usize>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for k in cells {
        let e = evidence[k] as f64;
        if e.is_finite() {
            s += e;
            n += 1;
        }
    }
    if n == 0 { f64::NAN } else { s / n as f64 }
}

/// Narrowest rectangle the extent gives, texels: a feature whose evidence is no wider than the
/// fusion's own spread has a width the evidence cannot tell, and the rectangle must stay one to
/// carve.
const MIN_WIDTH_TEXELS: f64 = 0.5;

/// The half-peak interval narrowed to the box whose blur by a Gaussian of standard deviation
/// `spread` (texels) reads as wide, each side that is a half-peak crossing moved in by its share
/// of the blur; a side bounded by the chart's end or by unobserved texels, where the evidence
/// does not fall toward it, stays. The fusion
/// widens every feature by its kernel and its bilinear deposit: a 0.12 m drainpipe (1.2 texels)
/// reads about 1.75 texels wide at half its peak; a 1.4 m window is unchanged to a hundredth of
/// a texel.
fn deblurred(e: HalfPeak, spread: f64) -> (f64, f64) {
    let measured = e.hi - e.lo;
    let sides = e.lo_blurred as u8 + e.hi_blurred as u8;
    if spread <= 0.0 || measured <= 0.0 || sides == 0 {
        return (e.lo, e.hi);
    }
    // What a box of width `a` reads as with `sides` of its edges blurred.
    let reads = |a: f64| a + sides as f64 * (blurred_width(a, spread) - a) / 2.0;
    let floor = MIN_WIDTH_TEXELS.min(measured);
    let width = if reads(0.0) >= measured {
        floor
    } else {
        // `reads` grows with the width and exceeds it: bisect on [0, measured].
        let (mut lo, mut hi) = (0.0, measured);
        for _ in 0..48 {
            let mid = 0.5 * (lo + hi);
            if reads(mid) < measured {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (0.5 * (lo + hi)).max(floor)
    };
    match (e.lo_blurred, e.hi_blurred) {
        (true, true) => {
            let c = 0.5 * (e.lo + e.hi);
            (c - width / 2.0, c + width / 2.0)
        }
        (false, _) => (e.lo, e.lo + width),
        (true, false) => (e.hi - width, e.hi),
    }
}

/// Half-peak width of a box of width `a` convolved with a Gaussian of standard deviation `s`:
/// 2x where Phi((x + a/2) / s) - Phi((x - a/2) / s) is half its value at 0.
fn blurred_width(a: f64, s: f64) -> f64 {
    if a < 1e-6 * s {
        // The limit, a point: the Gaussian's own full width at half maximum.
        return 2.0 * (2.0 * std::f64::consts::LN_2).sqrt() * s;
    }
    let f = |x: f64| phi((x + a / 2.0) / s) - phi((x - a / 2.0) / s);
    let half = f(0.0) / 2.0;
    let (mut lo, mut hi) = (0.0, a / 2.0 + 6.0 * s);
    for _ in 0..48 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > half {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo + hi
}

/// The standard normal distribution function, by erf (Abramowitz and Stegun 7.1.26, absolute
/// error under 1.5e-7).
fn phi(x: f64) -> f64 {
    let z = x / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * z.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-z * z).exp();
    0.5 * (1.0 + erf.copysign(z))
}

/// Where a profile crosses half its peak on each side, and whether each side is such a crossing
/// (blurred by the fusion) rather than a bound (the profile's end, an unobserved texel).
#[derive(Clone, Copy, Debug)]
struct HalfPeak {
    lo: f64,
    hi: f64,
    lo_blurred: bool,
    hi_blurred: bool,
}

/// Where `profile` (values at texel centres k + 0.5, NaN unobserved) crosses half its peak over
/// the core span [lo, hi], one crossing each side, searched outward from the core's ends (inward
/// where an end is already under half); an unobserved texel or the profile's end bounds the
/// search at a texel edge.
fn half_peak_edges(profile: &[f64], lo: usize, hi: usize) -> HalfPeak {
    let peak = profile[lo..=hi]
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    if peak <= 0.0 {
        return HalfPeak {
            lo: lo as f64,
            hi: hi as f64 + 1.0,
            lo_blurred: false,
            hi_blurred: false,
        };
    }
    let level = peak / 2.0;
    let above = |k: usize| profile[k] >= level;
    // Past an unobserved texel or the profile's end there is no neighbour to cross to, but the
    // profile may still be seen falling toward it (a drainpipe 0.1 m from a corner reads
    // highest one texel in from the chart's end): the line through the last two texels gives
    // the crossing when it falls within the bound; where the profile does not fall, or falls
    // to half its peak only past the bound, the feature runs to the bound.
    let toward_bound = |inner: usize, further_in: Option<usize>, bound: f64| -> (f64, bool) {
        let (a, b) = match further_in {
            Some(j) if profile[j].is_finite() => (profile[inner], profile[j]),
            _ => return (bound, false),
        };
        if b <= a {
            return (bound, false);
        }
        let centre = inner as f64 + 0.5;
        let x = centre + (bound - centre).signum() * (a - level) / (b - a);
        if (x - bound) * (centre - bound) >= 0.0 {
            (x, true)
        } else {
            (bound, false)
        }
    };
    // The crossing between texel `inner` (at or over the level) and its neighbour `outer`.
    let cross = |inner: usize, outer: usize| -> (f64, bool) {
        let (a, b) = (profile[inner], profile[outer]);
        if !b.is_finite() {
            let (bound, further_in) = if outer < inner {
                (inner as f64, Some(inner + 1).filter(|&j| j < profile.len()))
            } else {
                (inner as f64 + 1.0, inner.checked_sub(1))
            };
            return toward_bound(inner, further_in, bound);
        }
        let f = (a - level) / (a - b);
        let (ci, co) = (inner as f64 + 0.5, outer as f64 + 0.5);
        (ci + (co - ci) * f, true)
    };
    // Innermost texel over the level from each end of the core.
    let first = (lo..=hi).find(|&k| above(k)).unwrap_or(lo);
    let last = (lo..=hi).rev().find(|&k| above(k)).unwrap_or(hi);
    let mut l = first;
    while l > 0 && profile[l - 1].is_finite() && above(l - 1) {
        l -= 1;
    }
    let mut r = last;
    while r + 1 < profile.len() && profile[r + 1].is_finite() && above(r + 1) {
        r += 1;
    }
    let (left, lo_blurred) = if l == 0 {
        toward_bound(0, (profile.len() > 1).then_some(1), 0.0)
    } else {
        cross(l, l - 1)
    };
    let (right, hi_blurred) = if r + 1 == profile.len() {
        toward_bound(r, r.checked_sub(1), profile.len() as f64)
    } else {
        cross(r, r + 1)
    };
    HalfPeak {
        lo: left,
        hi: right,
        lo_blurred,
        hi_blurred,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_blur_comes_off_a_thin_feature_and_not_off_a_wide_one() {
        // Known values: a point blurred by a Gaussian reads its FWHM, 2 sqrt(2 ln 2) sigma; a
        // wide box reads its own width; Phi(1.959964) = 0.975.
        let s = 0.645;
        assert!((blurred_width(0.0, s) - 2.354_820 * s).abs() < 1e-5);
        assert!((blurred_width(14.0, s) - 14.0).abs() < 1e-6);
        assert!((phi(1.959_964) - 0.975).abs() < 1e-6 && (phi(0.0) - 0.5).abs() < 1e-7);
        let both = |a: f64| {
            let b = blurred_width(a, s);
            HalfPeak {
                lo: 5.0 - b / 2.0,
                hi: 5.0 + b / 2.0,
                lo_blurred: true,
                hi_blurred: true,
            }
        };
        for a in [0.6, 1.2, 3.0, 14.0] {
            let (lo, hi) = deblurred(both(a), s);
            assert!(
                (hi - lo - a).abs() < 1e-6 && (lo + hi - 10.0).abs() < 1e-9,
                "{a}"
            );
        }
        // A side bounded by the chart's end stays; only the blurred side moves in.
        let b = both(1.2);
        let (lo, hi) = deblurred(
            HalfPeak {
                lo: 0.0,
                hi: b.hi - b.lo - (b.hi - b.lo - 1.2) / 2.0,
                lo_blurred: false,
                hi_blurred: true,
            },
            s,
        );
        assert!(lo == 0.0 && (hi - 1.2).abs() < 1e-6, "{lo} {hi}");
        // Narrower than the blur alone reads: the floor.
        let (lo, hi) = deblurred(
            HalfPeak {
                lo: 0.0,
                hi: 1.0,
                lo_blurred: true,
                hi_blurred: true,
            },
            s,
        );
        assert!((hi - lo - MIN_WIDTH_TEXELS).abs() < 1e-12);
    }

    #[test]
    fn a_side_at_the_charts_end_is_extrapolated_where_the_evidence_falls_toward_it() {
        // A drainpipe 0.1 m from a corner, as the demo city's views read it: highest one texel
        // in from the chart's end, falling toward the end and away from it.
        let e = half_peak_edges(&[0.535, 0.867, 0.516, 0.026, 0.0], 0, 2);
        let level = 0.867 / 2.0;
        let lo = 0.5 - (0.535 - level) / (0.867 - 0.535);
        let hi = 2.5 + (0.516 - level) / (0.516 - 0.026);
        assert!(e.lo_blurred && (e.lo - lo).abs() < 1e-12, "{e:?}");
        assert!(e.hi_blurred && (e.hi - hi).abs() < 1e-12, "{e:?}");
        // Level to the end: cut by the chart, the bound stays.
        let e = half_peak_edges(&[0.9, 0.9, 0.5, 0.0], 0, 2);
        assert!(!e.lo_blurred && e.lo == 0.0, "{e:?}");
        // Falling, but reaching half the peak only past the end: the bound stays.
        let e = half_peak_edges(&[0.8, 0.9, 0.2], 0, 1);
        assert!(!e.lo_blurred && e.lo == 0.0, "{e:?}");
        // An unobserved texel bounds as the end does: extrapolated toward it, mirrored.
        let e = half_peak_edges(&[0.0, 0.026, 0.516, 0.867, 0.535, f64::NAN], 2, 4);
        assert!(e.hi_blurred && (e.hi - (5.0 - lo)).abs() < 1e-12, "{e:?}");
    }
}
