//! Radio (Sec. 5): link paths and radio maps traced through a scene.

pub mod calibrate;
pub mod coverage;
pub mod radio_map;
pub mod trace;

use crate::stage::ParamError;

/// The most a transmitter's `reach_m` may be, metres: a transmitter's reach, not a country.
pub const MAX_REACH_M: f64 = 100_000.0;

/// Checks a radio node's `reach_m`: none, or a distance above 0 and at most [`MAX_REACH_M`].
pub fn check_reach(reach_m: Option<f64>) -> Result<(), ParamError> {
    match reach_m {
        Some(r) if !(r > 0.0 && r <= MAX_REACH_M) => Err(ParamError::new(
            "reach_m",
            format!("expected a distance above 0 and at most {MAX_REACH_M} m, got {r}"),
        )),
        _ => Ok(()),
    }
}

pub use crate::rf::traced_links::within_reach;
