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
/// after the run's first point each costs a 2 x 2 rotation instead of a sine and a cosine. The
/// rotation's rounding grows by about 1e-16 a step (1e-12 over a run of 10^4), well inside the
/// closed form's own rounding of the fraction of i / φ, about 1e-9 at 10^7 points; the two agree
/// within 1e-8 (test below).
pub fn fibonacci_run(n: u32, start: u32, len: u32) -> impl Iterator<Item = DVec3> {
    let golden = (1.0 + 5f64.sqrt()) / 2.0;
    let phi0 = 2.0 * std::f64::consts::PI * (start as f64 / golden).fract();
    let (mut s, mut c) = phi0.sin_cos();
    let (ds, dc) = (2.0 * std::f64::consts::PI / golden).sin_cos();
    let end = start.saturating_add(len).min(n);
    (start..end).map(move |i| {
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
        assert_eq!(
            fibonacci_run(1, 0, 4).collect::<Vec<_>>(),
            vec![closed_one()]
        );
    }

    fn closed_one() -> DVec3 {
        fibonacci_sphere(1).collect::<Vec<_>>()[0]
    }
}
