//! Ingest of single-band GeoTIFF rasters (DSM, DEM) and SRTM `.hgt` tiles into the site frame
//! (paper Sec. 4: each source becomes a height field H_s on the shared grid, ⊥ where it observed
//! nothing).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{PodVec, Raster};
use crate::io::crs::ToSite;
use crate::io::crs::source_crs;
use crate::io::geotiff::{GeoTiff, read_geotiff};
use crate::io::hgt::{is_hgt, read_hgt};
use crate::io::warp::{Resample, SourceMap, check_upsampling, covering_grid, sample, windowed};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadRaster`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadRasterParams {
    /// The GeoTIFF, or an SRTM `.hgt` tile (told by the extension; 1 or 3 arc-second, its
    /// south-west corner from its name as in `N40W074.hgt`, EPSG:4326, heights in metres above
    /// the EGM96 geoid as stored, voids as no-data).
    pub path: String,
    /// The raster's CRS when the file records none (or to override it).
    #[serde(default)]
    pub crs: Option<String>,
    /// Which band, from 1. Default 1.
    #[serde(default = "one")]
    pub band: u16,
    /// Resample onto the site-aligned grid of this cell size. Default: keep the file's grid when
    /// it is in the site CRS with square pixels, else the site's cell size.
    #[serde(default)]
    pub cell_m: Option<f64>,
    /// How values are read when resampling. Default Bilinear.
    #[serde(default = "bilinear")]
    pub resample: Resample,
    /// The no-data value, overriding the file's.
    #[serde(default)]
    pub nodata: Option<f64>,
    /// Read only the cells whose centres fall in this box, (x_min, y_min, x_max, y_max) in site
    /// metres: a DEM or an SRTM tile reaches far beyond the site. Default: the whole file.
    #[serde(default)]
    pub window: Option<(f64, f64, f64, f64)>,
}

fn one() -> u16 {
    1
}
fn bilinear() -> Resample {
    Resample::Bilinear
}

/// Reads one band of a GeoTIFF, or an SRTM `.hgt` tile, as a [`Raster`] in the site frame;
/// no-data (an SRTM void) becomes NaN.
pub struct ReadRaster;

impl Stage for ReadRaster {
    const KIND: &'static str = "ReadRaster";
    const VERSION: u32 = 3;
    const DOC: &'static str = "GeoTIFF band (DSM/DEM) or SRTM .hgt tile into the site frame as a height field H_s, Sec. 4";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadRasterParams;
    type Output = Raster;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::crs::check_crs_param(&p.crs)?;
        if p.band == 0 {
            return Err(ParamError::new("band", "bands count from 1"));
        }
        crate::params::check_cell(p.cell_m)?;
        crate::params::check_window(p.window)?;
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }]
    }

    // A tile of a tiled run reads the cells in its window (and in `window`, when both are given).
    const WINDOWED: bool = true;

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let path = ctx.file(0)?;
        let window = match (p.window, ctx.window) {
            (w, None) => w,
            (None, Some(t)) => Some((t.min.0, t.min.1, t.max.0, t.max.1)),
            (Some(w), Some(t)) => Some((
                w.0.max(t.min.0),
                w.1.max(t.min.1),
                w.2.min(t.max.0),
                w.3.min(t.max.1),
            )),
        };
        let tif = if is_hgt(path) {
            read_hgt(path)?
        } else {
            read_geotiff(path)?
        };
        if p.band > tif.bands {
            return Err(StageError::bad_input(
                path,
                "bands",
                format!("band {} requested, the file has {}", p.band, tif.bands),
            ));
        }
        let crs = source_crs(p.crs.as_deref(), tif.crs.clone(), path)?;
        let to_site =
            ToSite::new(&crs, ctx.site).map_err(|m| StageError::bad_input(path, "CRS", m))?;
        let nodata = p.nodata.or(tif.nodata);
        let band = (p.band - 1) as usize;
        let value = |i: usize| {
            let v = tif.sample(i, band);
            if nodata.is_some_and(|nd| v == nd || (nd.is_nan() && v.is_nan())) {
                f64::NAN
            } else {
                v * crs.z_to_m
            }
        };
        // Exact: the file's own grid, when it already is one in the site frame.
        if let (true, None, Some(grid)) = (
            to_site.is_identity(),
            p.cell_m,
            tif.pixels.as_site_grid(ctx.site.origin),
        ) {
            let full_width = grid.width as usize;
            let (grid, col0, row0) =
                windowed(grid, window).map_err(|m| StageError::bad_input(path, "window", m))?;
            let width = grid.width as usize;
            let data = (0..grid.len())
                .into_par_iter()
                .map(|i| {
                    let (r, c) = (row0 as usize + i / width, col0 as usize + i % width);
                    value(r * full_width + c) as f32
                })
                .collect();
            return Ok(Raster {
                grid,
                data: PodVec(data),
            });
        }
        warp_raster(
            &tif,
            &to_site,
            p.cell_m.unwrap_or(ctx.site.cell_m),
            window,
            p.resample,
            value,
            ctx,
        )
        .map_err(|m| StageError::bad_input(path, "reprojection", m))
    }
}

fn warp_raster(
    tif: &GeoTiff,
    to_site: &ToSite,
    cell_m: f64,
    window: Option<(f64, f64, f64, f64)>,
    how: Resample,
    value: impl Fn(usize) -> f64 + Sync,
    ctx: &Ctx,
) -> Result<Raster, String> {
    let px = tif.pixels;
    let (grid, _, _) = windowed(covering_grid(&px, to_site, cell_m)?, window)?;
    check_upsampling(&px, &grid)?;
    let map = SourceMap::new(&grid, &px, to_site);
    ctx.progress.set_total(grid.height as u64);
    let mut data = vec![f32::NAN; grid.len()];
    data.par_chunks_mut(grid.width as usize)
        .enumerate()
        .for_each(|(row, out)| {
            for (col, z) in out.iter_mut().enumerate() {
                if let Some((u, v)) = map.at(col as u32, row as u32) {
                    *z = sample(u, v, px.width, px.height, how, |c, r| {
                        value(r as usize * px.width as usize + c as usize)
                    }) as f32;
                }
            }
            ctx.progress.advance(1);
        });
    Ok(Raster {
        grid,
        data: PodVec(data),
    })
}
