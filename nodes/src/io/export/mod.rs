//! Artifacts as ordinary files that other tools open: GeoTIFF, LAS, glTF, 3D Tiles, GeoJSON, CSV,
//! JSON.

mod atlas;
mod chart_glb;
mod cityjson;
pub mod colormap;
pub mod figures;
mod glb;
mod gpkg;
mod las;
mod material_atlas;
pub mod object_properties;
mod pixel_font;
mod relief_atlas;
mod relief_json;
pub mod report_html;
mod tiles;

use crate::artifact::{Artifact, ArtifactType, TexelLayers};
use crate::io::cog::Band;
use crate::io::geotiff::write_geotiff_rgb;
use crate::io::safe_name::{check_file_name, check_folder};
use crate::site::Site;

pub use chart_glb::write_chart_glb;
pub use glb::{material_color, write_glb, write_glb_objects};
pub use las::write_las;
pub use tiles::write_tileset;

/// An encoded output.
pub enum Encoded {
    /// One file.
    File(Vec<u8>),
    /// A folder of files, by relative path; the first is its entry point (e.g. `tileset.json`).
    Folder(Vec<(String, Vec<u8>)>),
}

/// The formats (file extensions) an artifact type can be written in; the first is the default.
pub fn formats(ty: ArtifactType) -> &'static [&'static str] {
    match ty {
        ArtifactType::Raster => &["tif", "exr", "png"],
        ArtifactType::Ortho => &["tif"],
        ArtifactType::City | ArtifactType::Metrics => &["json"],
        ArtifactType::Scene => &["glb", "3dtiles", "sionna", "city.json"],
        ArtifactType::Footprints => &["geojson", "gpkg"],
        ArtifactType::Measurements => &["csv"],
        ArtifactType::Points => &["las", "laz", "xyz"],
        ArtifactType::Views => &["views"],
        ArtifactType::Report => &["report"],
        ArtifactType::Charts => &["json"],
        ArtifactType::Texels => &["atlas", "glb"],
        ArtifactType::Relief => &["json", "geojson", "atlas"],
        ArtifactType::Materials => &["atlas"],
    }
}

/// The file name and format of output `name` of type `ty`: a name ending in one of the type's
/// formats (`truth.3dtiles`, `twin.city.json`) picks it; otherwise the default format's extension
/// is appended.
pub fn output_file(name: &str, ty: ArtifactType) -> Result<(String, &'static str), String> {
    let fmts = formats(ty);
    let ends_in = |f: &str| {
        name.len() > f.len() + 1
            && name.ends_with(f)
            && name.as_bytes()[name.len() - f.len() - 1] == b'.'
    };
    if let Some(f) = fmts.iter().find(|f| ends_in(f)) {
        return Ok((name.to_owned(), f));
    }
    match name.rsplit_once('.') {
        Some((_, ext)) => {
            let list = match fmts.split_last() {
                Some((last, rest)) if !rest.is_empty() => {
                    format!("{} or {last}", rest.join(", "))
                }
                _ => fmts.join(""),
            };
            Err(format!("{ty} outputs are written as {list}, not .{ext}"))
        }
        // A report is a folder named as the output.
        None if matches!(
            ty,
            ArtifactType::Report | ArtifactType::Texels | ArtifactType::Materials
        ) =>
        {
            Ok((name.to_owned(), fmts[0]))
        }
        None => Ok((format!("{name}.{}", fmts[0]), fmts[0])),
    }
}

/// Checks the names in `a` that become file names when it is exported (a view set's ids), so a
/// bad one is reported as the user's input, naming the element, before anything is written.
pub fn check_names(a: &Artifact) -> Result<(), String> {
    if let Artifact::Views(set) = a {
        for (k, v) in set.views.iter().enumerate() {
            check_file_name(&v.id)
                .map_err(|e| format!("view {k} (id {:?}): its id names its files: {e}", v.id))?;
        }
    }
    Ok(())
}

/// Encodes `a` in `format`, one of [`formats`] for its type. Every file of a folder output passes
/// [`check_folder`]: nothing lands outside the folder or replaces a sibling.
pub fn encode(a: &Artifact, site: &Site, format: &str) -> Result<Encoded, String> {
    encode_with_parts(a, site, format, crate::stage::process_parts())
}

/// [`encode`] for an artifact whose parts (a view set's pixels) are in `parts`.
pub fn encode_with_parts(
    a: &Artifact,
    site: &Site,
    format: &str,
    parts: &dyn crate::stage::PartStore,
) -> Result<Encoded, String> {
    encode_with_band(a, site, format, parts, &Band::default())
}

/// [`encode_with_parts`], a raster's band described by `band` (its unit and what made it) in the
/// formats that carry one (GeoTIFF).
pub fn encode_with_band(
    a: &Artifact,
    site: &Site,
    format: &str,
    parts: &dyn crate::stage::PartStore,
    band: &Band,
) -> Result<Encoded, String> {
    check_names(a)?;
    let encoded = encode_unchecked(a, site, format, parts, band)?;
    if let Encoded::Folder(files) = &encoded {
        check_folder(files.iter().map(|(rel, _)| rel.as_str()))
            .map_err(|e| format!("{} as {format}: {e}", a.ty()))?;
    }
    Ok(encoded)
}

fn encode_unchecked(
    a: &Artifact,
    site: &Site,
    format: &str,
    parts: &dyn crate::stage::PartStore,
    band: &Band,
) -> Result<Encoded, String> {
    let file = |bytes: Vec<u8>| Ok(Encoded::File(bytes));
    match (a, format) {
        (Artifact::Raster(r), "tif") => file(crate::io::cog::write_cog_band(r, site, band)?),
        (Artifact::Raster(r), "exr") => file(crate::io::exr_io::write_exr(
            r.grid.width as usize,
            r.grid.height as usize,
            vec![("Y", r.data.to_vec())],
        )?),
        (Artifact::Raster(r), "png") => file(colormap::raster_png(r)?),
        (Artifact::Ortho(o), "tif") => {
            let mut buf = std::io::Cursor::new(Vec::new());
            write_geotiff_rgb(&o.rgb, &o.grid, site, &mut buf)?;
            file(buf.into_inner())
        }
        (Artifact::City(c), "json") => {
            file(serde_json::to_vec_pretty(c).map_err(|e| e.to_string())?)
        }
        (Artifact::Scene(s), "glb") => file(write_glb(s)?),
        (Artifact::Scene(s), "city.json") => file(cityjson::write_cityjson(s, site)?),
        (Artifact::Scene(s), "3dtiles") => Ok(Encoded::Folder(write_tileset(s, site, 100.0)?)),
        (Artifact::Scene(s), "sionna") => {
            let mut files = crate::io::sionna_xml::write_scene(s)?;
            files.push(("site.json".into(), crate::io::sionna_xml::site_json(site)?));
            Ok(Encoded::Folder(files))
        }
        (Artifact::Footprints(f), "geojson") => {
            file(crate::io::geojson::write_footprints(f, site)?.into_bytes())
        }
        (Artifact::Footprints(f), "gpkg") => file(gpkg::write_gpkg(f, site)?),
        (Artifact::Measurements(m), "csv") => file(measurements_csv(m, site)?.into_bytes()),
        (Artifact::Metrics(m), "json") => {
            let mut s = serde_json::to_string_pretty(&m.values).map_err(|e| e.to_string())?;
            s.push('\n');
            file(s.into_bytes())
        }
        (Artifact::Points(p), "las") => file(write_las(p, site, false)?),
        (Artifact::Points(p), "laz") => file(write_las(p, site, true)?),
        (Artifact::Points(p), "xyz") => file(xyz_text(p, site).into_bytes()),
        (Artifact::Views(v), "views") => Ok(Encoded::Folder(crate::io::views_io::write_viewset(
            v, parts,
        )?)),
        (Artifact::Report(r), "report") => Ok(Encoded::Folder(r.files.clone())),
        (Artifact::Charts(c), "json") => file(charts_json(c)?),
        (Artifact::Materials(m), "atlas") => {
            Ok(Encoded::Folder(material_atlas::write_material_atlas(m)?))
        }
        (Artifact::Relief(r), "json") => file(relief_json::relief_json(r)?),
        (Artifact::Relief(r), "geojson") => file(relief_json::relief_geojson(r, site)?),
        (Artifact::Relief(r), "atlas") => Ok(Encoded::Folder(relief_atlas::write_relief_atlas(r)?)),
        (Artifact::Texels(t), "atlas") => Ok(Encoded::Folder(texel_atlas(t)?)),
        (Artifact::Texels(t), "glb") => file(chart_glb::write_chart_glb(t)?),
        (a, f) => Err(format!(
            "{} cannot be written as {f:?}; formats: {}",
            a.ty(),
            formats(a.ty()).join(", ")
        )),
    }
}

/// Chart frames and grids (not the per-texel triangle index): where each texel lies in the world.
fn charts_json(c: &crate::artifact::ChartSet) -> Result<Vec<u8>, String> {
    let charts: Vec<serde_json::Value> = c
        .charts
        .iter()
        .map(|ch| {
            serde_json::json!({
                "building": ch.building,
                "kind": format!("{:?}", ch.kind),
                "origin": ch.origin,
                "u_axis": ch.u_axis,
                "v_axis": ch.v_axis,
                "normal": ch.normal,
                "texel_m": ch.texel_m,
                "width": ch.width,
                "height": ch.height,
                "covered_texels": ch.covered(),
                "triangles": ch.triangles.len(),
            })
        })
        .collect();
    serde_json::to_vec_pretty(&serde_json::json!({ "charts": charts })).map_err(|e| e.to_string())
}

/// ASCII XYZ in absolute CRS coordinates: what PDAL's text writer and CloudCompare read.
fn xyz_text(p: &crate::artifact::PointSet, site: &Site) -> String {
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
    s
}

/// Measurements in the project's CSV layout, site-frame coordinates.
/// Links as the `Links` layout of `ReadMeasurements` reads them: site-frame x/y (which a reader
/// takes when a file has both) and, for a GIS, each end's WGS 84 longitude and latitude (degrees,
/// 8 decimals: about a millimetre).
fn measurements_csv(m: &crate::artifact::Measurements, site: &Site) -> Result<String, String> {
    use crate::artifact::Height;
    use crate::io::crs::{Crs, ToSite};
    use std::fmt::Write;
    let wgs84 = ToSite::new(&Crs::from_epsg(4326)?, site)?;
    let opt = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
    let z = |h: Height| match h {
        Height::Absolute(z) => (z.to_string(), String::new()),
        Height::AboveGround(h) => (String::new(), h.to_string()),
    };
    let mut s = String::from(
        "tx_id,tx_x,tx_y,tx_z,tx_height_m,tx_azimuth_deg,rx_id,rx_x,rx_y,rx_z,rx_height_m,freq_hz,path_loss_db,rx_power_dbm,tx_eirp_dbm,los,tx_lon,tx_lat,rx_lon,rx_lat\n",
    );
    for l in &m.links {
        let ((tz, th), (rz, rh)) = (z(l.tx.z), z(l.rx.z));
        let los = l.los.map(|b| if b { "1" } else { "0" }).unwrap_or("");
        let (tx_lon, tx_lat) = wgs84.inverse(l.tx.x, l.tx.y)?;
        let (rx_lon, rx_lat) = wgs84.inverse(l.rx.x, l.rx.y)?;
        let _ = writeln!(
            s,
            "{},{:.3},{:.3},{tz},{th},{},{},{:.3},{:.3},{rz},{rh},{},{},{},{},{los},{tx_lon:.8},{tx_lat:.8},{rx_lon:.8},{rx_lat:.8}",
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
    Ok(s)
}

/// The texel layers' atlas (`atlas`) and, when the layers carry their charts' frames,
/// `charts.glb`: every chart as a textured quad in its world position (`chart_glb`).
fn texel_atlas(t: &TexelLayers) -> Result<Vec<(String, Vec<u8>)>, String> {
    let mut files = atlas::write_atlas(t)?;
    if !t.frames.is_empty() {
        files.push(("charts.glb".into(), chart_glb::write_chart_glb(t)?));
    }
    Ok(files)
}
