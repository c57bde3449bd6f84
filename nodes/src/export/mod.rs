//! Artifacts as ordinary files that other tools open: GeoTIFF, JSON, text.

use crate::artifact::Artifact;
use crate::site::Site;

use crate::geotiff::{write_geotiff, write_geotiff_rgb};

/// Encodes `a` in the standard format for its type; returns the file extension and the bytes.
pub fn encode(a: &Artifact, site: &Site) -> Result<(&'static str, Vec<u8>), String> {
    match a {
        Artifact::Raster(r) => {
            let mut buf = std::io::Cursor::new(Vec::new());
            write_geotiff(r, site, &mut buf)?;
            Ok(("tif", buf.into_inner()))
        }
        Artifact::Ortho(o) => {
            let mut buf = std::io::Cursor::new(Vec::new());
            write_geotiff_rgb(&o.rgb, &o.grid, site, &mut buf)?;
            Ok(("tif", buf.into_inner()))
        }
        Artifact::Metrics(m) => {
            let mut s = serde_json::to_string_pretty(&m.values).map_err(|e| e.to_string())?;
            s.push('\n');
            Ok(("json", s.into_bytes()))
        }
        Artifact::Points(p) => {
            // ASCII XYZ in absolute CRS coordinates: what PDAL's text writer and CloudCompare read.
            use std::fmt::Write;
            let mut s = String::with_capacity(p.len() * 40);
            s.push_str("x y z class\n");
            let (ox, oy) = site.origin;
            for (i, q) in p.xyz.iter().enumerate() {
                let class = p.class.get(i).copied().unwrap_or(0);
                let _ = writeln!(
                    s,
                    "{:.3} {:.3} {:.3} {class}",
                    ox + q[0] as f64,
                    oy + q[1] as f64,
                    q[2]
                );
            }
            Ok(("xyz", s.into_bytes()))
        }
    }
}
