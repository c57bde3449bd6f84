//! Artifacts as ordinary files that other tools open: GeoTIFF, JSON, text.

mod glb;
mod las;

use crate::artifact::Artifact;

use crate::site::Site;
pub use glb::{material_color, write_glb};
pub use las::write_las;

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
        Artifact::City(c) => Ok((
            "json",
            serde_json::to_vec_pretty(c).map_err(|e| e.to_string())?,
        )),
        Artifact::Scene(s) => Ok(("glb", write_glb(s)?)),
        Artifact::Footprints(f) => Ok((
            "geojson",
            crate::geojson::write_footprints(f, site)?.into_bytes(),
        )),
        Artifact::Measurements(m) => Ok(("csv", measurements_csv(m).into_bytes())),
        Artifact::Metrics(m) => {
            let mut s = serde_json::to_string_pretty(&m.values).map_err(|e| e.to_string())?;
            s.push('\n');
            Ok(("json", s.into_bytes()))
        }
        Artifact::Points(p) => Ok(("las", write_las(p, site)?)),
    }
}

/// Measurements in the project's CSV layout, site-frame coordinates.
fn measurements_csv(m: &crate::artifact::Measurements) -> String {
    use crate::artifact::Height;
    use std::fmt::Write;
    let opt = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
    let z = |h: Height| match h {
        Height::Absolute(z) => (z.to_string(), String::new()),
        Height::AboveGround(h) => (String::new(), h.to_string()),
    };
    let mut s = String::from(
        "tx_id,tx_x,tx_y,tx_z,tx_height_m,tx_azimuth_deg,rx_id,rx_x,rx_y,rx_z,rx_height_m,freq_hz,path_loss_db,rx_power_dbm,tx_eirp_dbm,los\n",
    );
    for l in &m.links {
        let ((tz, th), (rz, rh)) = (z(l.tx.z), z(l.rx.z));
        let los = l.los.map(|b| if b { "1" } else { "0" }).unwrap_or("");
        let _ = writeln!(
            s,
            "{},{:.3},{:.3},{tz},{th},{},{},{:.3},{:.3},{rz},{rh},{},{},{},{},{los}",
            l.tx.id,
            l.tx.x,
            l.tx.y,
            opt(l.tx.azimuth_deg),
            l.rx.id,
            l.rx.x,
            l.rx.y,
            l.freq_hz,
            opt(l.path_loss_db),
            opt(l.rx_power_dbm),
            opt(l.tx_eirp_dbm)
        );
    }
    s
}
