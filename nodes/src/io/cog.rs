//! Cloud-Optimized GeoTIFF for float32 rasters: what every raster `.tif` output is written as.
//!
//! The layout GDAL's COG driver writes and its validator checks
//! (<https://gdal.org/drivers/raster/cog.html>): one band in 512 x 512 tiles, deflate-compressed,
//! with overviews halved (the mean of each 2 x 2 block's valid cells, as GDAL's AVERAGE) until
//! one fits a tile; every image file directory (IFD) at the front, the full resolution's first;
//! then the tiles, the smallest overview's first and the full resolution's last, each level row
//! by row. A reader fetches the directories with one request and any window or zoom level with
//! few more. No-data is NaN (`GDAL_NODATA`); the GeoKeys are `geokeys::geo_keys`; the band's unit
//! and description, when known, are GDAL's metadata items (`GDAL_METADATA`: what `gdalinfo`
//! prints and rasterio reads as `units` and `descriptions`).
//! Written by hand: the `tiff` crate's encoder writes strips, data before directories.

use std::io::Write;

use crate::artifact::Raster;
use crate::io::geokeys::{
    GDAL_METADATA, GDAL_NODATA, GEO_KEY_DIRECTORY, MODEL_PIXEL_SCALE, MODEL_TIEPOINT, geo_keys,
    scale_and_tiepoint,
};
use crate::site::Site;

/// What a raster's one band holds, for its GeoTIFF: the unit of its values as GDAL names units
/// ("m", "dB", "dBm"; none for labels and counts) and a description (the node that made it).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Band {
    /// The values' unit.
    pub unit: Option<String>,
    /// What the band is.
    pub description: Option<String>,
}

impl Band {
    /// GDAL's metadata XML for the band's items, or none when there is nothing to say.
    fn gdal_metadata(&self) -> Option<String> {
        let escape = |s: &str| {
            s.replace('&', "&amp;")
                .replace('<', "&lt;")
                .replace('>', "&gt;")
                .replace('"', "&quot;")
        };
        let mut items = String::new();
        if let Some(d) = &self.description {
            items.push_str(&format!(
                "<Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">{}</Item>",
                escape(d)
            ));
        }
        if let Some(u) = &self.unit {
            items.push_str(&format!(
                "<Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">{}</Item>",
                escape(u)
            ));
        }
        (!items.is_empty()).then(|| format!("<GDALMetadata>{items}</GDALMetadata>"))
    }
}

/// Tile side, pixels (GDAL's COG default).
pub const TILE: u32 = 512;

/// TIFF field types.
const SHORT: u16 = 3;
const LONG: u16 = 4;
const DOUBLE: u16 = 12;
const ASCII: u16 = 2;

/// One resolution level: its size and cells, row-major from the north-west corner.
struct Level {
    width: u32,
    height: u32,
    cells: Vec<f32>,
}

/// The next overview: each 2 x 2 block's mean over its finite cells (NaN where none), the last
/// row or column alone where the size is odd.
fn halve(l: &Level) -> Level {
    let (w, h) = (l.width.div_ceil(2), l.height.div_ceil(2));
    let mut cells = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h {
        for x in 0..w {
            let (mut sum, mut n) = (0.0f64, 0u32);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (sx, sy) = (2 * x + dx, 2 * y + dy);
                if sx < l.width && sy < l.height {
                    let v = l.cells[sy as usize * l.width as usize + sx as usize];
                    if v.is_finite() {
                        sum += v as f64;
                        n += 1;
                    }
                }
            }
            cells.push(if n == 0 {
                f32::NAN
            } else {
                (sum / n as f64) as f32
            });
        }
    }
    Level {
        width: w,
        height: h,
        cells,
    }
}

/// `level`'s tiles, row by row, each deflate-compressed (TIFF compression 8: a zlib stream),
/// padded with NaN past the image's edge.
fn tiles(level: &Level) -> Result<Vec<Vec<u8>>, String> {
    let (tx, ty) = (level.width.div_ceil(TILE), level.height.div_ceil(TILE));
    let t = TILE as usize;
    let mut out = Vec::with_capacity((tx * ty) as usize);
    let mut tile = vec![f32::NAN; t * t];
    for j in 0..ty {
        for i in 0..tx {
            tile.fill(f32::NAN);
            for r in 0..t {
                let y = j as usize * t + r;
                if y >= level.height as usize {
                    break;
                }
                let x0 = i as usize * t;
                let n = t.min(level.width as usize - x0);
                let row = y * level.width as usize + x0;
                tile[r * t..r * t + n].copy_from_slice(&level.cells[row..row + n]);
            }
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
            let bytes: Vec<u8> = tile.iter().flat_map(|v| v.to_le_bytes()).collect();
            z.write_all(&bytes).map_err(|e| e.to_string())?;
            out.push(z.finish().map_err(|e| e.to_string())?);
        }
    }
    Ok(out)
}

/// A directory entry's value: its type, count and little-endian bytes.
struct Value {
    ty: u16,
    count: u32,
    bytes: Vec<u8>,
}

fn shorts(v: &[u16]) -> Value {
    Value {
        ty: SHORT,
        count: v.len() as u32,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn longs(v: &[u32]) -> Value {
    Value {
        ty: LONG,
        count: v.len() as u32,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn doubles(v: &[f64]) -> Value {
    Value {
        ty: DOUBLE,
        count: v.len() as u32,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn ascii(s: &str) -> Value {
    let mut bytes = s.as_bytes().to_vec();
    bytes.push(0);
    Value {
        ty: ASCII,
        count: bytes.len() as u32,
        bytes,
    }
}

/// A directory: its entries, by tag.
struct Ifd {
    entries: Vec<(u16, Value)>,
}

impl Ifd {
    /// Bytes of the directory itself (count, entries, next offset) and of its values too long
    /// to sit in an entry, each value word-aligned.
    fn size(&self) -> u64 {
        let outside: u64 = self
            .entries
            .iter()
            .map(|(_, v)| {
                if v.bytes.len() > 4 {
                    (v.bytes.len() as u64 + 1) & !1
                } else {
                    0
                }
            })
            .sum();
        2 + 12 * self.entries.len() as u64 + 4 + outside
    }

    /// The directory at `at`, its next directory at `next` (0: the last), appended to `out`.
    fn write(&self, at: u64, next: u32, out: &mut Vec<u8>) {
        debug_assert_eq!(out.len() as u64, at);
        let mut values = at + 2 + 12 * self.entries.len() as u64 + 4;
        let mut tail = Vec::new();
        out.extend((self.entries.len() as u16).to_le_bytes());
        for (tag, v) in &self.entries {
            out.extend(tag.to_le_bytes());
            out.extend(v.ty.to_le_bytes());
            out.extend(v.count.to_le_bytes());
            if v.bytes.len() <= 4 {
                let mut inline = v.bytes.clone();
                inline.resize(4, 0);
                out.extend(inline);
            } else {
                out.extend((values as u32).to_le_bytes());
                tail.extend(&v.bytes);
                if v.bytes.len() % 2 == 1 {
                    tail.push(0);
                }
                values = at + 2 + 12 * self.entries.len() as u64 + 4 + tail.len() as u64;
            }
        }
        out.extend(next.to_le_bytes());
        out.extend(tail);
    }
}

/// The directory of a level of `width` x `height` with `tiles` tiles at `offsets`/`counts`;
/// the full resolution's carries the georeferencing.
fn ifd(
    (width, height): (u32, u32),
    overview: bool,
    (offsets, counts): (&[u32], &[u32]),
    georef: Option<[Value; 3]>,
    metadata: Option<&str>,
) -> Ifd {
    let mut e: Vec<(u16, Value)> = vec![
        (254, longs(&[overview as u32])),
        (256, longs(&[width])),
        (257, longs(&[height])),
        (258, shorts(&[32])),
        (259, shorts(&[8])),
        (262, shorts(&[1])),
        (277, shorts(&[1])),
        (284, shorts(&[1])),
        (322, shorts(&[TILE as u16])),
        (323, shorts(&[TILE as u16])),
        (324, longs(offsets)),
        (325, longs(counts)),
        (339, shorts(&[3])),
    ];
    if let Some([scale, tie, keys]) = georef {
        e.push((MODEL_PIXEL_SCALE, scale));
        e.push((MODEL_TIEPOINT, tie));
        e.push((GEO_KEY_DIRECTORY, keys));
    }
    if let Some(m) = metadata {
        e.push((GDAL_METADATA, ascii(m)));
    }
    e.push((GDAL_NODATA, ascii("nan")));
    e.sort_by_key(|(t, _)| *t);
    Ifd { entries: e }
}

/// `r` as a Cloud-Optimized GeoTIFF in the site CRS (module docs), saying nothing of its band.
pub fn write_cog(r: &Raster, site: &Site) -> Result<Vec<u8>, String> {
    write_cog_band(r, site, &Band::default())
}

/// `r` as a Cloud-Optimized GeoTIFF in the site CRS (module docs), its band described by `band`
/// (in the full resolution's directory, where GDAL reads it). Classic TIFF: an error past 4 GiB
/// of compressed tiles.
pub fn write_cog_band(r: &Raster, site: &Site, band: &Band) -> Result<Vec<u8>, String> {
    let metadata = band.gdal_metadata();
    let g = r.grid;
    if g.width == 0 || g.height == 0 {
        return Err("an empty raster has no GeoTIFF".into());
    }
    let epsg = if site.crs.is_empty() {
        None
    } else {
        Some(site.epsg()?)
    };
    let mut levels = vec![Level {
        width: g.width,
        height: g.height,
        cells: r.data.to_vec(),
    }];
    while let Some(last) = levels.last()
        && (last.width > TILE || last.height > TILE)
    {
        let next = halve(last);
        levels.push(next);
    }
    let tiled: Vec<Vec<Vec<u8>>> = levels.iter().map(tiles).collect::<Result<_, _>>()?;
    let (scale, tiepoint) = scale_and_tiepoint(&g, site);
    let georef = || [doubles(&scale), doubles(&tiepoint), shorts(&geo_keys(epsg))];
    // The directories' sizes do not depend on the offsets' values: lay them out with zeros,
    // then place the tiles after them, the smallest level's first.
    let dirs = |offsets: &[Vec<u32>]| -> Vec<Ifd> {
        levels
            .iter()
            .zip(offsets)
            .enumerate()
            .map(|(k, (l, off))| {
                let counts: Vec<u32> = tiled[k].iter().map(|t| t.len() as u32).collect();
                ifd(
                    (l.width, l.height),
                    k > 0,
                    (off, &counts),
                    (k == 0).then(georef),
                    metadata.as_deref().filter(|_| k == 0),
                )
            })
            .collect()
    };
    let zeros: Vec<Vec<u32>> = tiled.iter().map(|t| vec![0; t.len()]).collect();
    let header = 8u64;
    let dir_bytes: u64 = dirs(&zeros).iter().map(Ifd::size).sum();
    let mut at = header + dir_bytes;
    let mut offsets = zeros;
    for k in (0..levels.len()).rev() {
        for (i, t) in tiled[k].iter().enumerate() {
            offsets[k][i] = u32::try_from(at).map_err(|_| too_large())?;
            at += t.len() as u64;
        }
    }
    u32::try_from(at).map_err(|_| too_large())?;
    let mut out = Vec::with_capacity(at as usize);
    out.extend(b"II");
    out.extend(42u16.to_le_bytes());
    out.extend((header as u32).to_le_bytes());
    let dirs = dirs(&offsets);
    let mut pos = header;
    for (k, d) in dirs.iter().enumerate() {
        let next = if k + 1 < dirs.len() {
            (pos + d.size()) as u32
        } else {
            0
        };
        d.write(pos, next, &mut out);
        pos += d.size();
    }
    for t in tiled.iter().rev() {
        for tile in t {
            out.extend(tile);
        }
    }
    debug_assert_eq!(out.len() as u64, at);
    Ok(out)
}

fn too_large() -> String {
    "the raster's compressed tiles pass 4 GiB, more than a classic TIFF holds; use a coarser cell"
        .into()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Grid, PodVec};
    use crate::io::geotiff::read_geotiff;

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    /// (tag -> (type, count, value or offset)) of the directory at `at`, and the next one's.
    fn directory(b: &[u8], at: usize) -> (Vec<(u16, u16, u32, u32)>, u32) {
        let n = u16::from_le_bytes([b[at], b[at + 1]]) as usize;
        let e = (0..n)
            .map(|k| {
                let p = at + 2 + 12 * k;
                (
                    u16::from_le_bytes([b[p], b[p + 1]]),
                    u16::from_le_bytes([b[p + 2], b[p + 3]]),
                    u32_at(b, p + 4),
                    u32_at(b, p + 8),
                )
            })
            .collect();
        (e, u32_at(b, at + 2 + 12 * n))
    }

    #[test]
    fn a_cog_reads_back_and_is_laid_out_as_gdal_checks() {
        let (w, h) = (1300u32, 700u32);
        let data: Vec<f32> = (0..w * h)
            .map(|k| {
                let (x, y) = (k % w, k / w);
                if (x + y) % 97 == 0 {
                    f32::NAN
                } else {
                    x as f32 * 0.25 - y as f32 * 0.5
                }
            })
            .collect();
        let grid = Grid {
            x0: -100.0,
            y0: 250.0,
            cell_m: 0.5,
            width: w,
            height: h,
        };
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (583_200.0, 4_506_600.0),
            cell_m: 0.5,
        };
        let bytes = write_cog(
            &Raster {
                grid,
                data: PodVec(data.clone()),
            },
            &site,
        )
        .unwrap();
        // Read back by the tiff crate's decoder, through the GeoTIFF reader.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.tif");
        std::fs::write(&path, &bytes).unwrap();
        let back = read_geotiff(&path).unwrap();
        let cells: Vec<f32> = (0..(w * h) as usize)
            .map(|i| back.sample(i, 0) as f32)
            .collect();
        assert!(
            cells
                .iter()
                .zip(&data)
                .all(|(a, b)| a == b || (a.is_nan() && b.is_nan()))
        );
        let g = back.pixels.as_site_grid(site.origin).unwrap();
        assert_eq!(
            (g.x0, g.y0, g.cell_m, g.width, g.height),
            (-100.0, 250.0, 0.5, w, h)
        );
        assert_eq!(
            back.crs,
            Some(crate::io::crs::Crs::from_epsg(32618).unwrap())
        );
        assert!(back.nodata.is_some_and(f64::is_nan));
        // The layout: the first directory at 8, the directories in a row before any tile, levels
        // 1300 x 700 -> 650 x 350 -> 325 x 175 (the first to fit a tile), and the tiles of the
        // smallest level first, the full resolution's last.
        assert_eq!(&bytes[..4], b"II*\0");
        assert_eq!(u32_at(&bytes, 4), 8);
        let (main, next1) = directory(&bytes, 8);
        let (ovr1, next2) = directory(&bytes, next1 as usize);
        let (ovr2, last) = directory(&bytes, next2 as usize);
        assert!(8 < next1 && next1 < next2 && last == 0);
        let get = |d: &[(u16, u16, u32, u32)], tag| d.iter().find(|e| e.0 == tag).copied().unwrap();
        let size = |d: &[(u16, u16, u32, u32)]| (get(d, 256).3, get(d, 257).3, get(d, 254).3);
        assert_eq!(size(&main), (w, h, 0));
        assert_eq!(size(&ovr1), (650, 350, 1));
        assert_eq!(size(&ovr2), (325, 175, 1));
        assert_eq!(get(&main, 322).3, 512);
        // Tile counts 6, 2, 1; a single offset sits in its entry, longer lists elsewhere.
        let offsets = |d: &[(u16, u16, u32, u32)]| -> Vec<u32> {
            let (_, _, n, at) = get(d, 324);
            if n == 1 {
                vec![at]
            } else {
                (0..n)
                    .map(|k| u32_at(&bytes, (at + 4 * k) as usize))
                    .collect()
            }
        };
        let (o_main, o1, o2) = (offsets(&main), offsets(&ovr1), offsets(&ovr2));
        assert_eq!((o_main.len(), o1.len(), o2.len()), (6, 2, 1));
        assert!(o2[0] > next2, "tiles after every directory");
        assert!(
            o2[0] < o1[0] && o1[1] < o_main[0],
            "{o2:?} {o1:?} {o_main:?}"
        );
        assert!(o_main.windows(2).all(|p| p[0] < p[1]), "row by row");
        let tags: Vec<u16> = main.iter().map(|e| e.0).collect();
        assert!(
            tags.windows(2).all(|p| p[0] < p[1]),
            "tags in order: {tags:?}"
        );
        // The overview is the mean of each 2 x 2 block's valid cells.
        let full = |x: u32, y: u32| data[(y * w + x) as usize];
        let want = [full(10, 20), full(11, 20), full(10, 21), full(11, 21)]
            .iter()
            .filter(|v| v.is_finite())
            .map(|&v| v as f64)
            .sum::<f64>()
            / 4.0;
        let l0 = Level {
            width: w,
            height: h,
            cells: data.clone(),
        };
        let half = halve(&l0);
        assert!((half.cells[(10 * half.width + 5) as usize] as f64 - want).abs() < 1e-3);
    }
}
