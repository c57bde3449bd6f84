//! The synthetic site's terrain as a function: what the synthetic sensors sample as ground truth.

use serde::{Deserialize, Serialize};

/// The synthetic site's terrain: a sloped plane plus fractal value noise (the params of the
/// `SynthTerrain` stage, and part of the synthetic [`City`](super::City) truth).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerrainModel {
    /// Noise seed. Default 1.
    pub seed: u64,
    /// Extent (east, north) in metres, starting at the site origin. Default (400, 300).
    pub size_m: (f64, f64),
    /// Cell size in metres; default: the site's.
    pub cell_m: Option<f64>,
    /// Elevation at the origin, metres. Default 10.
    pub base_m: f64,
    /// Gradient (dz/dx, dz/dy), m/m. Default (0.02, 0.01).
    pub slope: (f64, f64),
    /// Peak-to-mean amplitude of the noise, metres. Default 2.
    pub relief_m: f64,
    /// Wavelength of the coarsest octave, metres. Default 120.
    pub wavelength_m: f64,
    /// Number of octaves, each half the wavelength and amplitude of the last. Default 4.
    pub octaves: u32,
}

impl Default for TerrainModel {
    fn default() -> Self {
        TerrainModel {
            seed: 1,
            size_m: (400.0, 300.0),
            cell_m: None,
            base_m: 10.0,
            slope: (0.02, 0.01),
            relief_m: 2.0,
            wavelength_m: 120.0,
            octaves: 4,
        }
    }
}

/// Terrain elevation at site-frame (x, y): also what synthetic sensors use as ground truth.
pub fn height_at(p: &TerrainModel, x: f64, y: f64) -> f64 {
    let mut z = p.base_m + p.slope.0 * x + p.slope.1 * y;
    let (mut wl, mut amp) = (p.wavelength_m, p.relief_m);
    for octave in 0..p.octaves {
        z += amp
            * value_noise(
                p.seed.wrapping_add(octave as u64 * 0x9E37_79B9),
                x / wl,
                y / wl,
            );
        wl *= 0.5;
        amp *= 0.5;
    }
    z
}

/// Smooth value noise in [-1, 1]: random values on the integer lattice, smoothstep-interpolated.
fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (ix, iy) = (xf as i64, yf as i64);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (tx, ty) = (s(x - xf), s(y - yf));
    let v = |i: i64, j: i64| lattice(seed, i, j);
    let a = v(ix, iy) + (v(ix + 1, iy) - v(ix, iy)) * tx;
    let b = v(ix, iy + 1) + (v(ix + 1, iy + 1) - v(ix, iy + 1)) * tx;
    a + (b - a) * ty
}

fn lattice(seed: u64, i: i64, j: i64) -> f64 {
    let h = crate::rng::mix(
        seed ^ (i as u64).wrapping_mul(0xA24B_AED4_963E_E407)
            ^ (j as u64).wrapping_mul(0x9FB2_1C65_1E98_DF25),
    );
    (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}
