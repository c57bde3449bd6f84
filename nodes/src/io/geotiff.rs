//! GeoTIFF: reading rasters with their georeferencing (as GDAL writes them), and writing float32
//! rasters (Cloud-Optimized, `cog.rs`) and RGB ones that GDAL, QGIS and rasterio read.

use std::io::{Seek, Write};
use std::path::Path;

use tiff::ColorType;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::encoder::{TiffEncoder, colortype};
use tiff::tags::{PlanarConfiguration, Tag};

use crate::artifact::{Grid, Raster};
use crate::io::crs::{Crs, parse_geokeys};
use crate::io::geokeys::{
    GDAL_NODATA, GEO_ASCII_PARAMS, GEO_DOUBLE_PARAMS, GEO_KEY_DIRECTORY, MODEL_PIXEL_SCALE,
    MODEL_TIEPOINT, MODEL_TRANSFORMATION, geo_keys, scale_and_tiepoint,
};
use crate::site::Site;
use crate::stage::StageError;

/// Where the pixels of an image are: the CRS coordinates of its north-west corner and the pixel
/// size, north-up, without rotation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelGrid {
    /// CRS x of the western edge.
    pub west: f64,
    /// CRS y of the northern edge.
    pub north: f64,
    /// Pixel width in CRS units.
    pub dx: f64,
    /// Pixel height in CRS units (positive: rows go south).
    pub dy: f64,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

impl PixelGrid {
    /// Refuses georeferencing no grid can be made of: a corner or pixel size that is not finite,
    /// pixels that are not positive (north-up), an extent that overflows. The error says which.
    pub fn check(&self) -> Result<(), String> {
        if !(self.west.is_finite() && self.north.is_finite()) {
            return Err(format!(
                "a finite north-west corner, found ({}, {})",
                self.west, self.north
            ));
        }
        if !(self.dx > 0.0 && self.dy > 0.0 && self.dx.is_finite() && self.dy.is_finite()) {
            return Err(format!(
                "positive, finite pixel sizes and a north-up raster, found {} x {}",
                self.dx, self.dy
            ));
        }
        let (east, south) = (
            self.west + self.width as f64 * self.dx,
            self.north - self.height as f64 * self.dy,
        );
        if !(east.is_finite() && south.is_finite()) {
            return Err(format!(
                "an extent that fits in a double, found {} x {} pixels of {} x {}",
                self.width, self.height, self.dx, self.dy
            ));
        }
        Ok(())
    }

    /// The same grid in the site frame, if the pixels are square and the CRS is the site's.
    pub fn as_site_grid(&self, origin: (f64, f64)) -> Option<Grid> {
        ((self.dx - self.dy).abs() <= 1e-9 * self.dx.abs()).then_some(Grid {
            x0: self.west - origin.0,
            y0: self.north - origin.1,
            cell_m: self.dx,
            width: self.width,
            height: self.height,
        })
    }
}

/// A decoded GeoTIFF: samples, georeferencing, CRS (when recorded) and no-data value.
pub struct GeoTiff {
    /// Where the pixels are.
    pub pixels: PixelGrid,
    /// Samples per pixel.
    pub bands: u16,
    /// Interleaved samples, row-major from the north-west corner.
    pub samples: DecodingResult,
    /// The CRS from the GeoKeys, if any.
    pub crs: Option<Crs>,
    /// The GDAL no-data value, if any.
    pub nodata: Option<f64>,
}

impl GeoTiff {
    /// Sample `band` (0-based) of pixel `i` as f64.
    pub fn sample(&self, i: usize, band: usize) -> f64 {
        let k = i * self.bands as usize + band;
        match &self.samples {
            DecodingResult::U8(v) => v[k] as f64,
            DecodingResult::U16(v) => v[k] as f64,
            DecodingResult::U32(v) => v[k] as f64,
            DecodingResult::U64(v) => v[k] as f64,
            DecodingResult::F16(v) => f64::from(v[k]),
            DecodingResult::F32(v) => v[k] as f64,
            DecodingResult::F64(v) => v[k],
            DecodingResult::I8(v) => v[k] as f64,
            DecodingResult::I16(v) => v[k] as f64,
            DecodingResult::I32(v) => v[k] as f64,
            DecodingResult::I64(v) => v[k] as f64,
        }
    }
}

/// The decoder's limits while tags are read: a tag's values lie in the file, at least a byte
/// each, so a tag claiming more values than the file has bytes is refused before the decoder
/// allocates them (the tiff crate sizes a tag's vector from its count against
/// `decoding_buffer_size`; a 280-byte TIFF claiming 200 million doubles asked for 6.4 GB).
fn tag_limits(file_len: u64) -> Limits {
    let mut l = limits();
    let per_value = std::mem::size_of::<tiff::decoder::ifd::Value>() as u64;
    let most = file_len.saturating_add(64).saturating_mul(per_value);
    l.decoding_buffer_size = most.min(crate::params::MAX_BYTES) as usize;
    l.ifd_value_size = l.ifd_value_size.min(file_len.saturating_add(64) as usize);
    l
}

/// The decoder's buffers, bounded by the shared budget rather than left unlimited (a crafted
/// tag or strip length would otherwise be allocated as stated).
fn limits() -> Limits {
    let mut l = Limits::default();
    l.decoding_buffer_size = crate::params::MAX_BYTES as usize;
    l.intermediate_buffer_size = 1 << 30;
    l.ifd_value_size = 256 << 20;
    l
}

fn tiff_error(path: &Path, place: &str, e: tiff::TiffError) -> StageError {
    StageError::bad_input(path, place, format!("expected a readable TIFF: {e}"))
}

/// The decoder over a TIFF file, as every step of [`read_geotiff`] reads it.
type FileDecoder = Decoder<std::io::BufReader<std::fs::File>>;

/// Reads a GeoTIFF's first image with its georeferencing. A TIFF without tiepoint and pixel scale
/// (or a model transformation) is an error: we would not know where it is.
pub fn read_geotiff(path: &Path) -> Result<GeoTiff, StageError> {
    let file = crate::io::open::open_regular(path)
        .map_err(|e| StageError::bad_input(path, "open", e.to_string()))?;
    let file_len = file.metadata().map_or(0, |m| m.len());
    let mut d = Decoder::new(std::io::BufReader::new(file))
        .map_err(|e| tiff_error(path, "header", e))?
        .with_limits(tag_limits(file_len));
    let (width, height) = d
        .dimensions()
        .map_err(|e| tiff_error(path, "dimensions", e))?;
    let bands = interleaved_bands(path, &mut d)?;
    let pixels = pixel_grid(path, &mut d, width, height)?;
    let crs = geokeys_crs(path, &mut d)?;
    let nodata = gdal_nodata(&mut d);
    let samples = image_samples(path, d, width, height, bands)?;
    Ok(GeoTiff {
        pixels,
        bands,
        samples,
        crs,
        nodata,
    })
}

/// Samples per pixel, from the colour type; an error for a colour type we do not read or a
/// band-sequential (planar) multi-band layout, which [`GeoTiff::sample`] could not index.
fn interleaved_bands(path: &Path, d: &mut FileDecoder) -> Result<u16, StageError> {
    let bands = match d
        .colortype()
        .map_err(|e| tiff_error(path, "colour type", e))?
    {
        ColorType::Gray(_) => 1,
        ColorType::GrayA(_) => 2,
        ColorType::RGB(_) | ColorType::YCbCr(_) => 3,
        ColorType::RGBA(_) | ColorType::CMYK(_) => 4,
        ColorType::Multiband { num_samples, .. } => num_samples,
        other => {
            return Err(StageError::bad_input(
                path,
                "colour type",
                format!("unsupported colour type {other:?}"),
            ));
        }
    };
    let planar = d
        .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)
        .ok()
        .flatten();
    if bands > 1 && planar == Some(PlanarConfiguration::Planar.to_u16()) {
        return Err(StageError::bad_input(
            path,
            "PlanarConfiguration",
            "band-sequential (planar) multi-band TIFFs are not supported; write it pixel-interleaved (gdal_translate -co INTERLEAVE=PIXEL)",
        ));
    }
    Ok(bands)
}

/// The values of the doubles tag `tag`, if the file has it and they read as doubles.
fn f64_tag(d: &mut FileDecoder, tag: u16) -> Option<Vec<f64>> {
    d.find_tag(Tag::Unknown(tag))
        .ok()
        .flatten()
        .and_then(|v| v.into_f64_vec().ok())
}

/// Where the pixels are, from the tiepoint and pixel scale, else the model transformation
/// (north-up only), checked. An error when neither is there: we would not know where the raster
/// is.
fn pixel_grid(
    path: &Path,
    d: &mut FileDecoder,
    width: u32,
    height: u32,
) -> Result<PixelGrid, StageError> {
    let scale = f64_tag(d, MODEL_PIXEL_SCALE);
    let tie = f64_tag(d, MODEL_TIEPOINT);
    let matrix = f64_tag(d, MODEL_TRANSFORMATION);
    let no_georef = || {
        StageError::bad_input(
            path,
            "georeferencing",
            "no ModelTiepoint + ModelPixelScale or ModelTransformation tags: the raster's position is unknown (add a world file or georeference it)",
        )
    };
    let pixels = match (scale, tie, matrix) {
        (Some(s), Some(t), _) if s.len() >= 2 && t.len() >= 6 => PixelGrid {
            west: t[3] - t[0] * s[0],
            north: t[4] + t[1] * s[1],
            dx: s[0],
            dy: s[1],
            width,
            height,
        },
        (_, _, Some(m)) if m.len() >= 16 => {
            if m[1] != 0.0 || m[4] != 0.0 {
                return Err(StageError::bad_input(
                    path,
                    "ModelTransformation",
                    "rotated rasters are not supported; warp it north-up first (gdalwarp)",
                ));
            }
            PixelGrid {
                west: m[3],
                north: m[7],
                dx: m[0],
                dy: -m[5],
                width,
                height,
            }
        }
        _ => return Err(no_georef()),
    };
    pixels
        .check()
        .map_err(|m| StageError::bad_input(path, "georeferencing", format!("expected {m}")))?;
    Ok(pixels)
}

/// The CRS the GeoKey directory records, None without one; an error for keys we cannot read as
/// a CRS.
fn geokeys_crs(path: &Path, d: &mut FileDecoder) -> Result<Option<Crs>, StageError> {
    let Some(dir) = d
        .find_tag_unsigned_vec::<u16>(Tag::Unknown(GEO_KEY_DIRECTORY))
        .ok()
        .flatten()
    else {
        return Ok(None);
    };
    let doubles = f64_tag(d, GEO_DOUBLE_PARAMS).unwrap_or_default();
    let ascii = d
        .find_tag(Tag::Unknown(GEO_ASCII_PARAMS))
        .ok()
        .flatten()
        .and_then(|v| v.into_string().ok())
        .unwrap_or_default();
    let keys = parse_geokeys(&dir, &doubles, &ascii)
        .map_err(|m| StageError::bad_input(path, "GeoKeyDirectory", m))?;
    Ok(Some(Crs::from_geokeys(&keys).map_err(|m| {
        StageError::bad_input(path, "GeoKeyDirectory", m)
    })?))
}

/// The GDAL no-data value, if the file records one that reads as a number.
fn gdal_nodata(d: &mut FileDecoder) -> Option<f64> {
    d.find_tag(Tag::Unknown(GDAL_NODATA))
        .ok()
        .flatten()
        .and_then(|v| v.into_string().ok())
        .and_then(|s| s.trim_matches(['\0', ' ']).parse::<f64>().ok())
}

/// The image's samples, its size checked against the budget before the decoder allocates it (a
/// few bytes of TIFF can claim 10^10 x 10^10 pixels) and what it decoded checked to hold every
/// pixel's `bands` samples. `d` comes with [`tag_limits`] and leaves with [`limits`].
fn image_samples(
    path: &Path,
    mut d: FileDecoder,
    width: u32,
    height: u32,
    bands: u16,
) -> Result<DecodingResult, StageError> {
    let bits = d.colortype().map_or(8, |c| u64::from(c.bit_depth()));
    let sample_bytes = bits.div_ceil(8).max(1) as usize;
    crate::params::check_cells(width as f64, height as f64, sample_bytes * bands as usize)
        .map_err(|m| StageError::bad_input(path, "dimensions", m))?;
    // What the chunks hold uncompressed: rows of packed samples (a 1-bit mask stores an eighth
    // of the bytes it decodes to).
    let stored_rows = (width as u64 * bands as u64 * bits).div_ceil(8) * height as u64;
    check_stored_data(path, &mut d, stored_rows)?;
    // Tags read; the pixels, checked above, may take the whole budget.
    let samples = d
        .with_limits(limits())
        .read_image()
        .map_err(|e| tiff_error(path, "pixel data", e))?;
    // The decoder returns what the strips hold, which a file's tags can make fewer than the
    // pixels times the bands that `sample` indexes.
    let got = decoded_len(&samples);
    let want = width as usize * height as usize * bands as usize;
    if got < want {
        return Err(StageError::bad_input(
            path,
            "pixel data",
            format!("{want} samples ({width} x {height} x {bands} bands), found {got}"),
        ));
    }
    Ok(samples)
}

/// Whether the file can hold the `decoded` bytes of pixels its tags claim (packed, as the chunks
/// hold them uncompressed), checked before the decoder allocates them: a 64-byte TIFF can claim
/// 46,340 x 46,340 floats within the cell limit.
/// The strips' or tiles' stored bytes must lie inside the file, and expand to the pixels at most
/// by their compression's largest ratio (none 1, PackBits 64, Deflate 1,032, LZW and JPEG 4,096,
/// CCITT Group 4 65,536); a compression the decoder does not read is refused here, before it
/// allocates the image (found by AFL++: 4-12 GB from a few hundred bytes). Chunks stored as 0
/// bytes (GDAL's sparse files) hold none of the pixels and are not asked to.
fn check_stored_data(path: &Path, d: &mut FileDecoder, decoded: u64) -> Result<(), StageError> {
    let counts = d
        .get_tag_u64_vec(Tag::TileByteCounts)
        .or_else(|_| d.get_tag_u64_vec(Tag::StripByteCounts))
        .unwrap_or_default();
    if counts.is_empty() {
        return Ok(());
    }
    let file_len = std::fs::metadata(path).map_or(u64::MAX, |m| m.len());
    let stored = counts.iter().fold(0u64, |a, &c| a.saturating_add(c));
    if stored > file_len {
        return Err(StageError::bad_input(
            path,
            "strip or tile byte counts",
            format!(
                "image data inside the file ({file_len} bytes), found chunks of {stored} bytes in all"
            ),
        ));
    }
    let compression = d.get_tag_u32(Tag::Compression).unwrap_or(1);
    let ratio: u64 = match compression {
        1 => 1,
        32773 => 64,
        8 | 32946 => 1032,
        5 => 4096,
        // JPEG: a flat 8 x 8 block takes a few bits of its 192 bytes.
        7 => 4096,
        // CCITT Group 4: a blank row is a bit; bilevel images only.
        4 => 1 << 16,
        other => {
            // The decoder would refuse it too, but only after allocating the whole image.
            return Err(StageError::bad_input(
                path,
                "Compression",
                format!(
                    "none, LZW, Deflate, PackBits, JPEG or CCITT Group 4, found compression \
                     {other} (gdal_translate -co COMPRESS=DEFLATE rewrites it)"
                ),
            ));
        }
    };
    let chunks = counts.len() as u64;
    let held = counts.iter().filter(|&&c| c > 0).count() as u64;
    let needed = decoded / chunks * held;
    if needed > stored.saturating_mul(ratio) {
        return Err(StageError::bad_input(
            path,
            "strip or tile byte counts",
            format!(
                "{needed} bytes of pixels from {stored} stored bytes, more than their compression \
                 can expand to (at most {ratio} to 1)"
            ),
        ));
    }
    Ok(())
}

/// How many samples the decoder returned, whatever their type.
fn decoded_len(samples: &DecodingResult) -> usize {
    match samples {
        DecodingResult::U8(v) => v.len(),
        DecodingResult::U16(v) => v.len(),
        DecodingResult::U32(v) => v.len(),
        DecodingResult::U64(v) => v.len(),
        DecodingResult::F16(v) => v.len(),
        DecodingResult::F32(v) => v.len(),
        DecodingResult::F64(v) => v.len(),
        DecodingResult::I8(v) => v.len(),
        DecodingResult::I16(v) => v.len(),
        DecodingResult::I32(v) => v.len(),
        DecodingResult::I64(v) => v.len(),
    }
}

/// Writes `r` as a single-band float32 GeoTIFF in the site CRS (absolute coordinates), NaN as
/// no-data, Cloud-Optimized (tiled, deflate, overviews: [`crate::io::cog`]). GeoKeys: projected
/// model, pixel-is-area, `ProjectedCSTypeGeoKey` = the site's EPSG code.
pub fn write_geotiff<W: Write + Seek>(r: &Raster, site: &Site, w: &mut W) -> Result<(), String> {
    let bytes = crate::io::cog::write_cog(r, site)?;
    w.write_all(&bytes)
        .map_err(|e| format!("GeoTIFF writing failed: {e}"))
}

/// Writes the GeoTIFF georeferencing tags of `g` (site frame) in the site CRS.
fn write_georef<W: Write + Seek, K: tiff::encoder::TiffKind>(
    e: &mut tiff::encoder::DirectoryEncoder<'_, W, K>,
    g: &Grid,
    site: &Site,
    epsg: Option<u16>,
) -> Result<(), tiff::TiffError> {
    let (scale, tiepoint) = scale_and_tiepoint(g, site);
    e.write_tag(Tag::Unknown(MODEL_PIXEL_SCALE), &scale[..])?;
    e.write_tag(Tag::Unknown(MODEL_TIEPOINT), &tiepoint[..])?;
    e.write_tag(Tag::Unknown(GEO_KEY_DIRECTORY), &geo_keys(epsg)[..])
}

/// Writes an RGB u8 image on `g` as a GeoTIFF in the site CRS.
pub fn write_geotiff_rgb<W: Write + Seek>(
    rgb: &[[u8; 3]],
    g: &Grid,
    site: &Site,
    w: &mut W,
) -> Result<(), String> {
    let err = |e: tiff::TiffError| format!("GeoTIFF encoding failed: {e}");
    let mut enc = TiffEncoder::new(w).map_err(err)?;
    let mut img = enc
        .new_image::<colortype::RGB8>(g.width, g.height)
        .map_err(err)?;
    write_georef(img.encoder(), g, site, Some(site.epsg()?)).map_err(err)?;
    img.write_data(bytemuck::cast_slice(rgb)).map_err(err)?;
    Ok(())
}
