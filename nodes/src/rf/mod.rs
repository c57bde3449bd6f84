//! Radio propagation physics: ITU-R P.2040 materials as complex permittivities (the grounds above
//! 10 GHz, where P.2040 ends, from the ITU-R P.527 soil model in `p527`), Fresnel and thin-slab
//! coefficients, UTD wedge diffraction and the P.526 knife edge, antenna patterns, foliage loss
//! (P.833), and the ray tracers built on them: links (`paths`, the entry point, and its parts
//! `sequences`, `image_method`, `path_field`, `diffraction_search`, `diffracted`, `diffuse`) and
//! radio maps (`radiomap`, with edge diffraction in `radiomap_diffraction`). Each module names the
//! sources of its formulas.

pub mod antenna;
pub mod calibration;
pub mod diffracted;
pub mod diffraction;
pub mod diffraction_search;
pub mod diffuse;
pub mod em;
pub mod fibonacci;
pub mod field;
pub mod foliage;
pub mod gpu;
pub mod image_method;
pub mod links_csv;
pub mod map_plane;
pub mod materials;
pub mod p527;
pub mod path;
pub mod path_field;
pub mod pathloss_fit;
pub mod paths;
pub mod radiomap;
pub mod radiomap_diffraction;
pub mod scattering;
pub mod scene;
pub mod sequences;
pub mod slab_table;
#[doc(hidden)]
pub mod test_scenes;
pub mod traced_links;
pub mod utd;

/// Speed of light in vacuum, m/s (Sionna's constant).
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// Wavelength at `freq_hz`, metres.
pub fn wavelength(freq_hz: f64) -> f64 {
    SPEED_OF_LIGHT / freq_hz
}
