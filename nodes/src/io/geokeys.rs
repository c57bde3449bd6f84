//! The GeoTIFF georeferencing both GeoTIFF writers and the reader share: the tags' numbers,
//! the GeoKeyDirectory of a projected site CRS, and a site grid's pixel scale and tiepoint.

use crate::artifact::Grid;
use crate::site::Site;

pub(crate) const MODEL_PIXEL_SCALE: u16 = 33550;
pub(crate) const MODEL_TIEPOINT: u16 = 33922;
pub(crate) const GEO_KEY_DIRECTORY: u16 = 34735;
pub(crate) const GDAL_METADATA: u16 = 42112;
pub(crate) const GDAL_NODATA: u16 = 42113;
pub(crate) const MODEL_TRANSFORMATION: u16 = 34264;
pub(crate) const GEO_DOUBLE_PARAMS: u16 = 34736;
pub(crate) const GEO_ASCII_PARAMS: u16 = 34737;

/// `ModelPixelScale` and `ModelTiepoint` of `g` (site frame) in the site CRS: square cells,
/// the north-west corner of pixel (0, 0) at its absolute coordinates.
pub(crate) fn scale_and_tiepoint(g: &Grid, site: &Site) -> ([f64; 3], [f64; 6]) {
    (
        [g.cell_m, g.cell_m, 0.0],
        [
            0.0,
            0.0,
            0.0,
            site.origin.0 + g.x0,
            site.origin.1 + g.y0,
            0.0,
        ],
    )
}

/// The GeoKeyDirectory: header (version 1.1.0, key count), then (key, location, count, value):
/// a projected model, pixel-is-area, and the EPSG code when there is one (without, a local
/// frame such as a Sionna scene's, the CRS is left unknown).
pub(crate) fn geo_keys(epsg: Option<u16>) -> Vec<u16> {
    let mut keys: Vec<u16> = vec![
        1, 1, 0, 2, //
        1024, 0, 1, 1, // GTModelTypeGeoKey = ModelTypeProjected
        1025, 0, 1, 1, // GTRasterTypeGeoKey = RasterPixelIsArea
    ];
    if let Some(code) = epsg {
        keys[3] = 3;
        keys.extend([3072, 0, 1, code]); // ProjectedCSTypeGeoKey
    }
    keys
}
