//! The directions every ray shooter launches along: a Fibonacci lattice on the unit sphere, as
//! Sionna RT's `fibonacci_lattice`, so that N rays each stand for the solid angle 4π/N.

use glam::DVec3;
use rayon::prelude::*;

/// Points on the unit sphere on a Fibonacci lattice (Sionna's `fibonacci_lattice`, mapped with
/// z = 1 - 2 y).
pub fn fibonacci_sphere(n: u32) -> impl IndexedParallelIterator<Item = DVec3> {
    let golden = (1.0 + 5f64.sqrt()) / 2.0;
    (0..n).into_par_iter().map(move |i| {
        let x = (i as f64 / golden).fract();
        let y = if n > 1 {
            i as f64 / (n - 1) as f64
        } else {
            0.5
        };
        let phi = 2.0 * std::f64::consts::PI * x;
        let z = 1.0 - 2.0 * y;
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    })
}

/// Points `start..start + len` of [`fibonacci_sphere`]`(n)`, in order, for a loop that walks a
/// run of them: the azimuth advances by the same angle 2π / φ from one point to the next, so
/// each point costs a 2 x 2 rotation instead of a sine and a cosine, the rotation restarting from
/// the closed form at every multiple of [`RESTART`]. A point is thus the same to the bit in any
/// run that holds it. The rotation's rounding grows by about 1e-16 a step (1e-12 over a restart's
/// span), well inside the closed form's own rounding of the fraction of i / φ, about 1e-9 at 10^7
/// points; the two agree within 1e-8 (test below).
pub fn fibonacci_run(n: u32, start: u32, len: u32) -> impl Iterator<Item = DVec3> {
    let golden = (1.0 + 5f64.sqrt()) / 2.0;
    let azimuth =
        move |i: u32| (2.0 * std::f64::consts::PI * (i as f64 / golden).fract()).sin_cos();
    let (ds, dc) = (2.0 * std::f64::consts::PI / golden).sin_cos();
    // Walked up from the last restart, as a run starting there would.
    let (mut s, mut c) = azimuth(start - start % RESTART);
    for _ in 0..start % RESTART {
        (c, s) = (c * dc - s * ds, s * dc + c * ds);
    }
    let end = start.saturating_add(len).min(n);
    (start..end).map(move |i| {
        if i % RESTART == 0 {
            (s, c) = azimuth(i);
        }
        let y = if n > 1 {
            i as f64 / (n - 1) as f64
        } else {
            0.5
        };
        let z = 1.0 - 2.0 * y;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let d = DVec3::new(r * c, r * s, z);
        (c, s) = (c * dc - s * ds, s * dc + c * ds);
        d
    })
}

/// Points between two restarts of [`fibonacci_run`]'s rotation.
pub const RESTART: u32 = 8192;

/// Rays per patch of [`patch_order`]: a ray packet of the wide BVH.
pub const PATCH: u32 = 64;

/// The points `start..start + len` of [`fibonacci_sphere`]`(n)` reordered (as offsets from
/// `start`) so that every [`PATCH`] consecutive ones lie close together: what a packet of rays
/// needs to traverse the BVH as one.
///
/// The lattice's z falls linearly with the index, so a run is a band of latitude; its azimuth is
/// 2π frac(i / φ), spread evenly over the band. The band is cut by index into rows about as high
/// as a square patch of [`PATCH`] points is wide there (side 8 √(4π / n)), and each row is
/// ordered by azimuth with a counting sort (about four points a bin). Costs a few nanoseconds a
/// point, no trigonometry. Near a pole the rows are thin rings and their patches short arcs.
pub fn patch_order(n: u32, start: u32, len: u32) -> Vec<u32> {
    let len = len.min(n.saturating_sub(start));
    if n <= 1 || len <= PATCH {
        return (0..len).collect();
    }
    let golden = (1.0 + 5f64.sqrt()) / 2.0;
    // A row of m points at polar angle θ is 2 m / (n sin θ) radians high; a patch of PATCH of
    // them is 2π sin θ PATCH / m wide. The two are equal when m = 8 sin θ √(π n).
    let square_row = |k: f64| {
        let z = 1.0 - 2.0 * (start as f64 + k) / (n - 1) as f64;
        8.0 * (1.0 - z * z).max(0.0).sqrt() * (std::f64::consts::PI * n as f64).sqrt()
    };
    let mut rows = Vec::new();
    let mut row = 0;
    while row < len {
        // Sized at the row's middle, found from a first guess sized at its start.
        let guess = square_row(row as f64).max(PATCH as f64);
        let m = square_row(row as f64 + guess / 2.0);
        let mut m = (((m / PATCH as f64).round() as u32).max(1) * PATCH).min(len - row);
        if len - row - m < m / 2 {
            m = len - row;
        }
        rows.push((row, m));
        row += m;
    }
    let mut order = Vec::with_capacity(len as usize);
    let mut bin = Vec::new();
    let mut count = Vec::new();
    for (row, m) in rows {
        let bins = (m / 4).max(1);
        bin.clear();
        bin.extend((row..row + m).map(|k| {
            let x = ((start + k) as f64 / golden).fract();
            ((x * bins as f64) as u32).min(bins - 1)
        }));
        count.clear();
        count.resize(bins as usize + 1, 0u32);
        for &b in &bin {
            count[b as usize + 1] += 1;
        }
        for b in 1..count.len() {
            count[b] += count[b - 1];
        }
        let base = order.len();
        order.resize(base + m as usize, 0);
        for (k, &b) in bin.iter().enumerate() {
            order[base + count[b as usize] as usize] = row + k as u32;
            count[b as usize] += 1;
        }
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run by rotation is the closed form, point for point, at the far end of a long run and
    /// across the lattice, including a run that goes past `n`.
    #[test]
    fn a_run_is_the_closed_form() {
        let n = 10_000_000;
        let closed: Vec<DVec3> = fibonacci_sphere(n).collect();
        for start in [0u32, 1, 8192, 4_999_999, n - 10_000] {
            let run: Vec<DVec3> = fibonacci_run(n, start, 10_000).collect();
            assert_eq!(run.len(), 10_000);
            for (k, d) in run.iter().enumerate() {
                let e = (*d - closed[start as usize + k]).length();
                assert!(e < 1e-8, "point {}: {e}", start as usize + k);
            }
        }
        assert_eq!(fibonacci_run(n, n - 5, 10).count(), 5);
        let long: Vec<DVec3> = fibonacci_run(n, 3 * RESTART - 100, 3 * RESTART).collect();
        let short: Vec<DVec3> = fibonacci_run(n, 4 * RESTART + 7, 50).collect();
        assert_eq!(long[RESTART as usize + 107..][..50], short[..]);
        assert_eq!(
            fibonacci_run(1, 0, 4).collect::<Vec<_>>(),
            vec![closed_one()]
        );
    }

    /// Every point once, and each patch about a square of [`PATCH`] points away from the poles,
    /// at the lattice sizes a map uses.
    #[test]
    fn patches_cover_the_run_once_and_stay_small() {
        for (n, len) in [
            (1_000_000u32, 14_208u32),
            (10_000_000, 44_864),
            (100_000, 8192),
        ] {
            let points: Vec<DVec3> = fibonacci_sphere(n).collect();
            let side = 8.0 * (4.0 * std::f64::consts::PI / n as f64).sqrt();
            for start in [0, n / 3, n / 2 - len / 2, n - len] {
                let order = patch_order(n, start, len);
                let mut seen = order.clone();
                seen.sort_unstable();
                assert_eq!(seen, (0..len).collect::<Vec<_>>(), "n {n} start {start}");
                let z = points[(start + len / 2) as usize].z;
                let mut worst = 0.0f64;
                for patch in order.chunks(PATCH as usize) {
                    let c = patch
                        .iter()
                        .map(|&k| points[(start + k) as usize])
                        .sum::<DVec3>()
                        .normalize();
                    for &k in patch {
                        worst = worst.max(points[(start + k) as usize].angle_between(c));
                    }
                }
                // A square's corners lie 0.71 of its side from its centre (0.73-0.74 measured);
                // the thin rings near a pole make arcs (0.8-1.34).
                let bound = if z.abs() < 0.9 { 0.9 } else { 1.5 };
                assert!(
                    worst < bound * side,
                    "n {n} start {start}: {worst} against side {side}"
                );
            }
        }
        assert_eq!(patch_order(10, 0, 4), vec![0, 1, 2, 3]);
        assert_eq!(patch_order(100, 90, 64).len(), 10);
    }

    fn closed_one() -> DVec3 {
        fibonacci_sphere(1).collect::<Vec<_>>()[0]
    }
}
