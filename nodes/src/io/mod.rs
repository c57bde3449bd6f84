//! Files and frames: the formats artifacts are read from and written to (GeoTIFF, SRTM .hgt, GeoJSON, OSM XML, EXR,
//! the street-view folder layout, street imagery from Mapillary and Panoramax, Sionna's Mitsuba XML + PLY, and every `export` format), coordinate
//! reference systems, ECEF/ENU, and resampling into the site frame. Never imports a stage.

pub mod cog;
pub mod crs;
pub mod csv_text;
pub mod ecef;
pub mod export;
pub mod exr_io;
pub mod geojson;
pub mod geokeys;
pub mod geotiff;
pub mod hgt;
/// ONNX models run on view images (feature `onnx`): the runtime found through `ORT_DYLIB_PATH`.
#[cfg(feature = "onnx")]
pub mod onnx;
/// Opening user-named files: regular files only, never blocking on a FIFO or device.
pub mod open;
pub mod osm_xml;
pub mod safe_name;
pub mod sionna_xml;
pub mod street_imagery;
pub mod views_io;
pub mod warp;

/// The provider readers at the paths callers have always used.
pub use street_imagery::{mapillary, panoramax};
