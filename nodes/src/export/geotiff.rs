//! Float32 GeoTIFF with the georeferencing GDAL, QGIS and rasterio read.

use std::io::{Seek, Write};

use tiff::encoder::{TiffEncoder, colortype};
use tiff::tags::Tag;

use crate::artifact::Raster;
use crate::site::Site;

const MODEL_PIXEL_SCALE: u16 = 33550;
const MODEL_TIEPOINT: u16 = 33922;
const GEO_KEY_DIRECTORY: u16 = 34735;
const GDAL_NODATA: u16 = 42113;

/// Writes `r` as a single-band float32 GeoTIFF in the site CRS (absolute coordinates), NaN as
/// no-data. GeoKeys: projected model, pixel-is-area, `ProjectedCSTypeGeoKey` = the site's EPSG code.
pub fn write_geotiff<W: Write + Seek>(r: &Raster, site: &Site, w: &mut W) -> Result<(), String> {
    let epsg = site.epsg()?;
    let g = r.grid;
    let err = |e: tiff::TiffError| format!("GeoTIFF encoding failed: {e}");
    let mut enc = TiffEncoder::new(w).map_err(err)?;
    let mut img = enc
        .new_image::<colortype::Gray32Float>(g.width, g.height)
        .map_err(err)?;
    let x_west = site.origin.0 + g.x0;
    let y_north = site.origin.1 + g.y0;
    let e = img.encoder();
    e.write_tag(
        Tag::Unknown(MODEL_PIXEL_SCALE),
        &[g.cell_m, g.cell_m, 0.0][..],
    )
    .map_err(err)?;
    e.write_tag(
        Tag::Unknown(MODEL_TIEPOINT),
        &[0.0, 0.0, 0.0, x_west, y_north, 0.0][..],
    )
    .map_err(err)?;
    // GeoKeyDirectory: header (version 1.1.0, 3 keys), then (key, location, count, value).
    let keys: [u16; 16] = [
        1, 1, 0, 3, //
        1024, 0, 1, 1, // GTModelTypeGeoKey = ModelTypeProjected
        1025, 0, 1, 1, // GTRasterTypeGeoKey = RasterPixelIsArea
        3072, 0, 1, epsg, // ProjectedCSTypeGeoKey
    ];
    e.write_tag(Tag::Unknown(GEO_KEY_DIRECTORY), &keys[..])
        .map_err(err)?;
    e.write_tag(Tag::Unknown(GDAL_NODATA), "nan").map_err(err)?;
    img.write_data(&r.data).map_err(err)?;
    Ok(())
}
