//! Ingest of ASPRS LAS/LAZ point clouds (paper Sec. 4: airborne LiDAR) into the site frame.

use std::path::Path;

use las::Reader;
use serde::{Deserialize, Serialize};

use crate::artifact::PointSet;
use crate::io::crs::{Crs, ToSite, parse_geokeys};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadLas`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadLasParams {
    /// The `.las` or `.laz` file.
    pub path: String,
    /// The file's CRS (`"EPSG:<code>"` or a `+proj` string). Needed when the header carries none;
    /// when given, it overrides the header. Default: from the header.
    #[serde(default)]
    pub crs: Option<String>,
}

/// Reads a LAS/LAZ file: positions reprojected into the site frame, with class, intensity, return
/// numbers and RGB when the point format has them.
pub struct ReadLas;

impl Stage for ReadLas {
    const KIND: &'static str = "ReadLas";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "LAS/LAZ point cloud (CRS from header or graph) into the site frame, Sec. 4";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadLasParams;
    type Output = PointSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::params::check_crs(&p.crs)?;
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }]
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<PointSet, StageError> {
        let path = ctx.file(0)?;
        read_las(path, p.crs.as_deref(), ctx)
    }
}

fn las_error(path: &Path, place: &str, e: las::Error) -> StageError {
    StageError::bad_input(path, place, format!("expected a valid LAS/LAZ file: {e}"))
}

/// The CRS recorded in a LAS header: GeoTIFF keys first, then an OGC WKT record.
pub fn header_crs(path: &Path, header: &las::Header) -> Result<Option<Crs>, StageError> {
    let vlr = |id: u16| {
        header
            .all_vlrs()
            .find(|v| v.user_id.trim_end_matches('\0') == "LASF_Projection" && v.record_id == id)
    };
    if let Some(dir) = vlr(34735) {
        let dir: Vec<u16> = dir
            .data
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        let doubles: Vec<f64> = vlr(34736)
            .map(|v| {
                v.data
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect()
            })
            .unwrap_or_default();
        let ascii = vlr(34737)
            .map(|v| String::from_utf8_lossy(&v.data).into_owned())
            .unwrap_or_default();
        let keys = parse_geokeys(&dir, &doubles, &ascii)
            .map_err(|m| StageError::bad_input(path, "GeoKeyDirectory record", m))?;
        return Crs::from_geokeys(&keys)
            .map(Some)
            .map_err(|m| StageError::bad_input(path, "GeoKeyDirectory record", m));
    }
    if let Some(wkt) = header
        .get_wkt_crs_bytes()
        .or_else(|| vlr(2112).map(|v| v.data.as_slice()))
    {
        let wkt = String::from_utf8_lossy(wkt);
        return Crs::from_wkt(&wkt)
            .map(Some)
            .map_err(|m| StageError::bad_input(path, "WKT record", m));
    }
    Ok(None)
}

/// Reads `path` into the site frame of `ctx`, in batches so progress can be reported.
pub fn read_las(path: &Path, crs: Option<&str>, ctx: &Ctx) -> Result<PointSet, StageError> {
    let mut reader = Reader::from_path(path).map_err(|e| las_error(path, "header", e))?;
    let header = reader.header().clone();
    let crs = match crs {
        Some(c) => Crs::from_user(c).map_err(|m| StageError::Param(ParamError::new("crs", m)))?,
        None => header_crs(path, &header)?.ok_or_else(|| {
            StageError::bad_input(path, "header", "no CRS recorded (no GeoTIFF keys or WKT record); give it in the graph, e.g. crs: \"EPSG:28992\"")
        })?,
    };
    let to_site = ToSite::new(&crs, ctx.site).map_err(|m| StageError::bad_input(path, "CRS", m))?;
    let n = header.number_of_points();
    if n > 2_000_000_000 {
        return Err(StageError::bad_input(
            path,
            "header",
            format!("{n} points is more than one node can hold; tile the data"),
        ));
    }
    let format = header.point_format();
    let mut out = PointSet::default();
    out.xyz.reserve(n as usize);
    ctx.progress.set_total(n);
    const BATCH: u64 = 1 << 20;
    let mut done = 0u64;
    while done < n {
        let pd = reader
            .read_points(BATCH.min(n - done))
            .map_err(|e| las_error(path, &format!("point {}", done + 1), e))?;
        if pd.is_empty() {
            return Err(StageError::bad_input(
                path,
                format!("point {}", done + 1),
                format!("the header announces {n} points but the file ends after {done}"),
            ));
        }
        for ((x, y), z) in pd.x().zip(pd.y()).zip(pd.z()) {
            let (sx, sy, sz) = to_site
                .apply(x, y, z)
                .map_err(|m| StageError::bad_input(path, format!("point {}", done + 1), m))?;
            out.xyz.push([sx as f32, sy as f32, sz as f32]);
        }
        out.class.extend(pd.classification());
        out.intensity.extend(pd.intensity());
        out.return_number.extend(pd.return_number());
        out.number_of_returns.extend(pd.number_of_returns());
        if format.has_color
            && let Some(rgb) = pd.rgb()
        {
            out.rgb.extend(rgb.map(|(r, g, b)| [r, g, b]));
        }
        done += pd.len() as u64;
        ctx.progress.advance(pd.len() as u64);
    }
    normalize_rgb(&mut out.rgb);
    Ok(out)
}

/// LAS colours are 16-bit, but many writers store 8-bit values in them. When no channel of any
/// point exceeds 255 the file is taken to be 8-bit and scaled by 257, so every [`PointSet`] colour
/// spans 0..=65535.
fn normalize_rgb(rgb: &mut [[u16; 3]]) {
    if rgb.iter().all(|c| c.iter().all(|&v| v <= 255)) {
        for c in rgb.iter_mut() {
            for v in c.iter_mut() {
                *v *= 257;
            }
        }
    }
}
