//! Radio propagation physics: ITU-R P.2040 materials as complex permittivities, Fresnel and
//! thin-slab coefficients, UTD wedge diffraction and the P.526 knife edge, antenna patterns, and
//! the ray tracer built on them. Formulas and test vectors: `shared/reference/rf.md`.

pub mod antenna;
pub mod diffraction;
pub mod em;
pub mod field;
pub mod links_csv;
pub mod materials;
pub mod paths;
pub mod pathloss_fit;
pub mod radiomap;
pub mod scattering;
pub mod scene;
pub mod utd;

/// Speed of light in vacuum, m/s (Sionna's constant).
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// Wavelength at `freq_hz`, metres.
pub fn wavelength(freq_hz: f64) -> f64 {
    SPEED_OF_LIGHT / freq_hz
}
