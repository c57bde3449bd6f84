//! SRTM `.hgt` elevation tiles (NASA/USGS SRTM, and the same layout from other DEMs): a square
//! of big-endian signed 16-bit heights in metres, 3601 x 3601 posts (1 arc-second) or
//! 1201 x 1201 (3 arc-second), rows from north to south, -32768 where the radar saw nothing.
//!
//! The file holds no georeferencing: the tile's south-west corner is in its name (`N40W074.hgt`
//! covers 40..41 N, 74..73 W). Posts are pixel-is-point, on whole degrees at the tile's edges, so
//! neighbouring tiles share their edge rows; as a grid of pixels the tile reaches half a post past
//! each whole degree. Coordinates are WGS84 (EPSG:4326); heights are metres above the EGM96
//! geoid, read as they are (no geoid-to-ellipsoid correction).
//!
//! # References
//! USGS, "Shuttle Radar Topography Mission (SRTM) 1 Arc-Second Global", and the SRTM
//! Topography documentation (`SRTM_Topo.pdf`, NASA JPL): file layout, byte order, void value.

use std::path::Path;

use tiff::decoder::DecodingResult;

use crate::io::crs::Crs;
use crate::io::geotiff::{GeoTiff, PixelGrid};
use crate::stage::StageError;

/// The value of a void post.
pub const VOID: i16 = -32768;

/// Posts per side of the two tile sizes: 1 and 3 arc-seconds.
pub const SIDES: [u32; 2] = [3601, 1201];

/// Whether `path` is named as an SRTM tile (`.hgt`, any case).
pub fn is_hgt(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("hgt"))
}

/// The south-west corner (latitude, longitude in whole degrees) from a tile name such as
/// `N40W074.hgt` or `s23e017.SRTMGL1.hgt`: N/S, two digits, E/W, three digits.
pub fn tile_corner(name: &str) -> Result<(i32, i32), String> {
    let expected = || {
        format!(
            "a tile name like N40W074.hgt (N or S, 2 digits of latitude, E or W, 3 digits of \
             longitude: the tile's south-west corner), found {name:?}"
        )
    };
    let b = name.as_bytes();
    if b.len() < 7 || !b[1..3].iter().chain(&b[4..7]).all(u8::is_ascii_digit) {
        return Err(expected());
    }
    let digits = |r: std::ops::Range<usize>| name[r].parse::<i32>().map_err(|_| expected());
    let lat = match b[0].to_ascii_uppercase() {
        b'N' => digits(1..3)?,
        b'S' => -digits(1..3)?,
        _ => return Err(expected()),
    };
    let lon = match b[3].to_ascii_uppercase() {
        b'E' => digits(4..7)?,
        b'W' => -digits(4..7)?,
        _ => return Err(expected()),
    };
    if !(-90..90).contains(&lat) || !(-180..180).contains(&lon) {
        return Err(format!(
            "a south-west corner within 90 S..89 N and 180 W..179 E, found {lat}, {lon} in {name:?}"
        ));
    }
    Ok((lat, lon))
}

/// Where the posts of a tile of `side` posts with south-west corner (`lat`, `lon`) are, as a
/// grid of pixels centred on them.
pub fn tile_grid(lat: i32, lon: i32, side: u32) -> PixelGrid {
    let step = 1.0 / (side - 1) as f64;
    PixelGrid {
        west: lon as f64 - step / 2.0,
        north: (lat + 1) as f64 + step / 2.0,
        dx: step,
        dy: step,
        width: side,
        height: side,
    }
}

/// Reads a tile: its heights as one band of i16 with [`VOID`] as no-data, in EPSG:4326.
pub fn read_hgt(path: &Path) -> Result<GeoTiff, StageError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let (lat, lon) = tile_corner(&name).map_err(|m| StageError::bad_input(path, "file name", m))?;
    let len = std::fs::metadata(path)
        .map_err(|e| StageError::bad_input(path, "open", e.to_string()))?
        .len();
    let Some(side) = SIDES.into_iter().find(|&s| len == 2 * s as u64 * s as u64) else {
        return Err(StageError::bad_input(
            path,
            "size",
            format!(
                "a 1 arc-second (3601 x 3601) or 3 arc-second (1201 x 1201) tile of 16-bit \
                 heights, {} or {} bytes, found {len} bytes",
                2 * 3601 * 3601,
                2 * 1201 * 1201
            ),
        ));
    };
    let bytes = crate::io::open::read_regular(path)
        .map_err(|e| StageError::bad_input(path, "read", e.to_string()))?;
    if bytes.len() as u64 != len {
        return Err(StageError::bad_input(
            path,
            "size",
            format!("{len} bytes, found {} when read", bytes.len()),
        ));
    }
    let heights = bytes
        .chunks_exact(2)
        .map(|c| i16::from_be_bytes([c[0], c[1]]))
        .collect();
    Ok(GeoTiff {
        pixels: tile_grid(lat, lon, side),
        bands: 1,
        samples: DecodingResult::I16(heights),
        crs: Some(Crs::from_epsg(4326).map_err(StageError::Failed)?),
        nodata: Some(VOID as f64),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_give_the_south_west_corner() {
        assert_eq!(tile_corner("N40W074.hgt"), Ok((40, -74)));
        assert_eq!(tile_corner("s23e017.SRTMGL1.hgt"), Ok((-23, 17)));
        assert_eq!(tile_corner("S01W180.hgt"), Ok((-1, -180)));
        for bad in [
            "40W074.hgt",
            "N4W074.hgt",
            "X40W074.hgt",
            "N40Q074.hgt",
            "N+4W074.hgt",
            "",
        ] {
            assert!(tile_corner(bad).is_err(), "{bad}");
        }
        assert!(tile_corner("N90E000.hgt").unwrap_err().contains("89 N"));
        assert!(tile_corner("N00E180.hgt").unwrap_err().contains("179 E"));
    }

    #[test]
    fn posts_sit_on_whole_degrees() {
        for side in SIDES {
            let g = tile_grid(40, -74, side);
            // The centre of the first post is the north-west corner, of the last the south-east.
            assert!((g.west + g.dx / 2.0 - -74.0).abs() < 1e-12);
            assert!((g.north - g.dy / 2.0 - 41.0).abs() < 1e-12);
            let last = (side - 1) as f64 + 0.5;
            assert!((g.west + last * g.dx - -73.0).abs() < 1e-12);
            assert!((g.north - last * g.dy - 40.0).abs() < 1e-12);
        }
    }
}
