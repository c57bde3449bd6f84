//! LAS 1.2 (or LAZ) export of point sets: point format 1 (3 with colour), coordinates in the site CRS at
//! millimetre resolution, the CRS as a GeoTIFF GeoKeyDirectory record (as PDAL and LAStools write
//! it), so PDAL, CloudCompare, QGIS and our own reader place the points.

use std::io::Cursor;

use las::point::{Classification, Format};
use las::{Builder, Color, Point, Transform, Vector, Version, Vlr, Writer};

use crate::artifact::PointSet;
use crate::site::Site;

/// Encodes `p` as a LAS file, or LAZ (LASzip-compressed) when `compressed`.
pub fn write_las(p: &PointSet, site: &Site, compressed: bool) -> Result<Vec<u8>, String> {
    let err = |e: las::Error| format!("LAS encoding failed: {e}");
    let epsg = site.epsg()?;
    let mut b = Builder::from(Version::new(1, 2));
    b.point_format = Format::new(if p.rgb.is_empty() { 1 } else { 3 }).map_err(err)?;
    b.point_format.is_compressed = compressed;
    b.generating_software = concat!("kodama-dag ", env!("CARGO_PKG_VERSION")).into();
    let (ox, oy) = (site.origin.0.round(), site.origin.1.round());
    b.transforms = Vector {
        x: Transform {
            scale: 0.001,
            offset: ox,
        },
        y: Transform {
            scale: 0.001,
            offset: oy,
        },
        z: Transform {
            scale: 0.001,
            offset: 0.0,
        },
    };
    // GeoKeyDirectory: version 1.1.0 with 3 keys: projected model, pixel-is-area, the EPSG code.
    let keys: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, epsg];
    b.vlrs.push(Vlr {
        user_id: "LASF_Projection".into(),
        record_id: 34735,
        description: "GeoTiff GeoKeyDirectoryTag".into(),
        data: keys.iter().flat_map(|k| k.to_le_bytes()).collect(),
    });
    let header = b.into_header().map_err(err)?;
    let mut w = Writer::new(Cursor::new(Vec::new()), header).map_err(err)?;
    for (i, q) in p.xyz.iter().enumerate() {
        let class = p.class.get(i).copied().unwrap_or(0);
        let point = Point {
            x: site.origin.0 + q[0] as f64,
            y: site.origin.1 + q[1] as f64,
            z: q[2] as f64,
            intensity: p.intensity.get(i).copied().unwrap_or(0),
            return_number: p.return_number.get(i).copied().unwrap_or(1),
            number_of_returns: p.number_of_returns.get(i).copied().unwrap_or(1),
            classification: Classification::new(class.min(31)).map_err(err)?,
            color: p.rgb.get(i).map(|c| Color::new(c[0], c[1], c[2])),
            // Formats 1 and 3 carry a GPS time; we have no clock, so points are numbered instead.
            gps_time: Some(i as f64),
            ..Default::default()
        };
        w.write_point(point).map_err(err)?;
    }
    w.close().map_err(err)?;
    Ok(w.into_inner().map_err(err)?.into_inner())
}
