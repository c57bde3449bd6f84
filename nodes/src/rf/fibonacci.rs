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
