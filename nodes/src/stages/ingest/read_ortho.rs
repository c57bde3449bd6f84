//! Ingest of orthophotos: RGB GeoTIFF, or JPEG/PNG with a world file (paper Sec. 4: "a
//! georeferenced orthophoto"), into the site frame.

use std::path::Path;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{Ortho, PodVec};
use crate::io::crs::source_crs;
use crate::io::crs::{Crs, ToSite};
use crate::io::geotiff::{PixelGrid, read_geotiff};
use crate::io::warp::{Resample, SourceMap, check_upsampling, covering_grid, sample, windowed};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadOrtho`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadOrthoParams {
    /// An RGB GeoTIFF, or a JPEG/PNG with a world file.
    pub path: String,
    /// The world file of a JPEG/PNG. Default: the image's path with the extension `.wld`.
    #[serde(default)]
    pub world_file: Option<String>,
    /// The image's CRS: required for JPEG/PNG (world files carry none); overrides a GeoTIFF's.
    #[serde(default)]
    pub crs: Option<String>,
    /// Resample onto the site-aligned grid of this cell size. Default: keep the image's grid when
    /// it is in the site CRS with square pixels, else the site's cell size.
    #[serde(default)]
    pub cell_m: Option<f64>,
    /// Read only the pixels whose centres fall in this box, (x_min, y_min, x_max, y_max) in site
    /// metres: an orthophoto tile reaches far beyond the site. Default: the whole image.
    #[serde(default)]
    pub window: Option<(f64, f64, f64, f64)>,
}

fn is_tiff(path: &str) -> bool {
    let p = path.to_ascii_lowercase();
    p.ends_with(".tif") || p.ends_with(".tiff")
}

fn world_file_of(p: &ReadOrthoParams) -> Option<String> {
    if is_tiff(&p.path) {
        return None;
    }
    Some(p.world_file.clone().unwrap_or_else(|| {
        Path::new(&p.path)
            .with_extension("wld")
            .to_string_lossy()
            .into_owned()
    }))
}

/// Reads an orthophoto into the site frame as 8-bit RGB.
pub struct ReadOrtho;

impl Stage for ReadOrtho {
    const KIND: &'static str = "ReadOrtho";
    const VERSION: u32 = 2;
    const DOC: &'static str =
        "orthophoto (RGB GeoTIFF, or JPEG/PNG + world file) into the site frame, Sec. 4";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadOrthoParams;
    type Output = Ortho;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        match &p.crs {
            Some(c) => {
                Crs::from_user(c).map_err(|m| ParamError::new("crs", m))?;
            }
            None if !is_tiff(&p.path) => {
                return Err(ParamError::new(
                    "crs",
                    "a JPEG/PNG with a world file needs its CRS in the graph, e.g. crs: \"EPSG:2994\"",
                ));
            }
            None => {}
        }
        crate::params::check_cell(p.cell_m)?;
        crate::params::check_window(p.window)?;
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        let mut f = vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }];
        if let Some(w) = world_file_of(p) {
            f.push(FileRef {
                field: "world_file",
                path: w,
            });
        }
        f
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Ortho, StageError> {
        let path = ctx.file(0)?;
        let (pixels, rgb, recorded_crs) = if is_tiff(&p.path) {
            read_tiff_rgb(path)?
        } else {
            read_image_with_world_file(path, ctx.file(1)?)?
        };
        let crs = source_crs(p.crs.as_deref(), recorded_crs, path)?;
        let to_site =
            ToSite::new(&crs, ctx.site).map_err(|m| StageError::bad_input(path, "CRS", m))?;
        if let (true, None, Some(grid)) = (
            to_site.is_identity(),
            p.cell_m,
            pixels.as_site_grid(ctx.site.origin),
        ) {
            let full_width = grid.width as usize;
            let (grid, col0, row0) =
                windowed(grid, p.window).map_err(|m| StageError::bad_input(path, "window", m))?;
            let width = grid.width as usize;
            let rgb = (0..grid.len())
                .map(|i| rgb[(row0 as usize + i / width) * full_width + col0 as usize + i % width])
                .collect();
            let n = grid.len();
            return Ok(Ortho {
                grid,
                rgb: PodVec(rgb),
                valid: PodVec(vec![1; n]),
            });
        }
        let grid = covering_grid(&pixels, &to_site, p.cell_m.unwrap_or(ctx.site.cell_m))
            .map_err(|m| StageError::bad_input(path, "reprojection", m))?;
        let (grid, _, _) =
            windowed(grid, p.window).map_err(|m| StageError::bad_input(path, "window", m))?;
        check_upsampling(&pixels, &grid)
            .map_err(|m| StageError::bad_input(path, "georeferencing", m))?;
        let map = SourceMap::new(&grid, &pixels, &to_site);
        ctx.progress.set_total(grid.height as u64);
        let w = grid.width as usize;
        let mut out = vec![[0u8; 3]; grid.len()];
        let mut valid = vec![0u8; grid.len()];
        out.par_chunks_mut(w)
            .zip(valid.par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (o, ok))| {
                for col in 0..w {
                    let Some((u, v)) = map.at(col as u32, row as u32) else {
                        continue;
                    };
                    let idx = sample(
                        u,
                        v,
                        pixels.width,
                        pixels.height,
                        Resample::Nearest,
                        |c, r| (r as usize * pixels.width as usize + c as usize) as f64,
                    );
                    if idx.is_finite() {
                        o[col] = rgb[idx as usize];
                        ok[col] = 1;
                    }
                }
                ctx.progress.advance(1);
            });
        Ok(Ortho {
            grid,
            rgb: PodVec(out),
            valid: PodVec(valid),
        })
    }
}

type Decoded = (PixelGrid, Vec<[u8; 3]>, Option<Crs>);

fn read_tiff_rgb(path: &Path) -> Result<Decoded, StageError> {
    let tif = read_geotiff(path)?;
    if tif.bands < 3 {
        return Err(StageError::bad_input(
            path,
            "bands",
            format!("expected an RGB image, found {} band(s)", tif.bands),
        ));
    }
    let n = tif.pixels.width as usize * tif.pixels.height as usize;
    let max = match &tif.samples {
        tiff::decoder::DecodingResult::U8(_) => 255.0,
        tiff::decoder::DecodingResult::U16(_) => 65535.0,
        _ => {
            return Err(StageError::bad_input(
                path,
                "sample format",
                "expected 8- or 16-bit unsigned RGB",
            ));
        }
    };
    let to8 = |v: f64| (v / max * 255.0).round() as u8;
    let rgb = (0..n)
        .map(|i| {
            [
                to8(tif.sample(i, 0)),
                to8(tif.sample(i, 1)),
                to8(tif.sample(i, 2)),
            ]
        })
        .collect();
    Ok((tif.pixels, rgb, tif.crs))
}

/// Reads a JPEG/PNG and its world file (six lines: A, D, B, E, C, F; C and F are the centre of the
/// upper-left pixel).
fn read_image_with_world_file(path: &Path, world: &Path) -> Result<Decoded, StageError> {
    let text = crate::io::open::read_regular_to_string(world)
        .map_err(|e| StageError::bad_input(world, "open", e.to_string()))?;
    let v: Vec<f64> = text
        .split_whitespace()
        .enumerate()
        .map(|(i, t)| {
            t.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    StageError::bad_input(
                        world,
                        format!("value {}", i + 1),
                        format!("expected a finite number, found {t:?}"),
                    )
                })
        })
        .collect::<Result<_, _>>()?;
    let [a, d, b, e, c, f] = v[..] else {
        return Err(StageError::bad_input(
            world,
            "contents",
            format!("expected 6 numbers (A D B E C F), found {}", v.len()),
        ));
    };
    if d != 0.0 || b != 0.0 {
        return Err(StageError::bad_input(
            world,
            "rotation terms",
            "rotated images are not supported; warp it north-up first (gdalwarp)",
        ));
    }
    if !(a > 0.0 && e < 0.0) {
        return Err(StageError::bad_input(
            world,
            "pixel size",
            format!("expected A > 0 and E < 0 (north-up), found A = {a}, E = {e}"),
        ));
    }
    let img = image::open(path)
        .map_err(|err| {
            StageError::bad_input(
                path,
                "image",
                format!("expected a readable JPEG/PNG: {err}"),
            )
        })?
        .into_rgb8();
    let (width, height) = img.dimensions();
    let pixels = PixelGrid {
        west: c - a / 2.0,
        north: f - e / 2.0,
        dx: a,
        dy: -e,
        width,
        height,
    };
    pixels
        .check()
        .map_err(|m| StageError::bad_input(world, "georeferencing", format!("expected {m}")))?;
    let rgb = img.pixels().map(|p| p.0).collect();
    Ok((pixels, rgb, None))
}
