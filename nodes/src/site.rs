//! The site frame every artifact lives in.

use serde::{Deserialize, Serialize};

/// A projected CRS and an origin in it. Geometry is in metres relative to `origin`, z up; rasters
/// snap to a grid of `cell_m` anchored at the origin.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Site {
    /// The projected CRS, as `EPSG:<code>`.
    pub crs: String,
    /// Site origin in the CRS (easting, northing), metres.
    pub origin: (f64, f64),
    /// Default raster cell size, metres.
    pub cell_m: f64,
}

impl Site {
    /// The EPSG code of [`Site::crs`], or a message saying what was expected.
    pub fn epsg(&self) -> Result<u16, String> {
        let code = self.crs.strip_prefix("EPSG:").ok_or_else(|| {
            format!(
                "expected a CRS of the form \"EPSG:<code>\", found {:?}",
                self.crs
            )
        })?;
        code.parse::<u16>()
            .map_err(|_| format!("expected a numeric EPSG code, found {code:?}"))
    }

    /// Checks the values a user wrote, but for the projection itself (`io::crs::check_site` checks
    /// both); the message names the offending field.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        self.epsg().map_err(|m| ("crs", m))?;
        if !(self.cell_m.is_finite() && self.cell_m > 0.0) {
            return Err((
                "cell_m",
                format!(
                    "expected a positive cell size in metres, found {}",
                    self.cell_m
                ),
            ));
        }
        if !(self.origin.0.is_finite() && self.origin.1.is_finite()) {
            return Err(("origin", "expected finite coordinates".into()));
        }
        Ok(())
    }
}
