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

/// An axis-aligned rectangle of the site frame, metres: a tile's core, or the window (core plus
/// halo) a tiled run lets a node read. `min` is the south-west corner, `max` the north-east one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Window {
    /// South-west corner (x, y).
    pub min: (f64, f64),
    /// North-east corner (x, y).
    pub max: (f64, f64),
}

impl Window {
    /// Whether `(x, y)` lies in the window: the west and south edges in, the east and north
    /// edges out, so windows that tile the plane own every point once.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.min.0 && x < self.max.0 && y >= self.min.1 && y < self.max.1
    }

    /// Whether the box `lo..=hi` (x, y) meets the window.
    pub fn meets(&self, lo: (f64, f64), hi: (f64, f64)) -> bool {
        lo.0 < self.max.0 && hi.0 >= self.min.0 && lo.1 < self.max.1 && hi.1 >= self.min.1
    }

    /// The window grown by `m` metres on every side.
    pub fn grown(&self, m: f64) -> Window {
        Window {
            min: (self.min.0 - m, self.min.1 - m),
            max: (self.max.0 + m, self.max.1 + m),
        }
    }

    /// Width and height, metres.
    pub fn size(&self) -> (f64, f64) {
        (self.max.0 - self.min.0, self.max.1 - self.min.1)
    }

    /// Checks the corners: finite, `min` south-west of `max`.
    pub fn validate(&self) -> Result<(), String> {
        let all = [self.min.0, self.min.1, self.max.0, self.max.1];
        if !all.iter().all(|v| v.is_finite()) {
            return Err("expected finite corners".into());
        }
        if !(self.min.0 < self.max.0 && self.min.1 < self.max.1) {
            return Err(format!(
                "expected `min` south-west of `max`, found min {:?} and max {:?}",
                self.min, self.max
            ));
        }
        Ok(())
    }
}

/// One tile of a tiled run, as a merge sees it: its name and the core it owns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TileCore {
    /// The tile's name (`x2y0`: column 2, row 0 from the south-west), which prefixes the ids of
    /// the objects it gives a merged scene.
    pub name: String,
    /// The part of the site the tile owns: a point belongs to the one tile whose core contains
    /// it ([`Window::contains`]).
    pub core: Window,
}

/// The params of every merge of a tiled run: the tiles, in the order of the merged node's inputs.
/// The engine writes them; a graph never does.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MergeTilesParams {
    /// The tiles whose outputs are merged, one per input.
    pub tiles: Vec<TileCore>,
}

impl MergeTilesParams {
    /// The tile whose core holds `(x, y)`, if any.
    pub fn owner(&self, x: f64, y: f64) -> Option<usize> {
        self.tiles.iter().position(|t| t.core.contains(x, y))
    }

    /// Fails unless there is one input per tile.
    pub fn check_inputs(&self, inputs: usize) -> Result<(), String> {
        if inputs == self.tiles.len() {
            return Ok(());
        }
        Err(format!(
            "expected one input per tile ({}), found {inputs}",
            self.tiles.len()
        ))
    }

    /// Checks every core and that the names are distinct and plain.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let mut seen = std::collections::BTreeSet::new();
        for t in &self.tiles {
            t.core
                .validate()
                .map_err(|m| ("tiles", format!("tile {:?}: {m}", t.name)))?;
            let plain = !t.name.is_empty()
                && t.name.len() <= 32
                && t.name
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'_');
            if !plain || !seen.insert(t.name.as_str()) {
                return Err((
                    "tiles",
                    format!(
                        "expected distinct tile names of letters, digits and _, found {:?}",
                        t.name
                    ),
                ));
            }
        }
        Ok(())
    }
}
