//! Resampling a georeferenced image from its own CRS onto a grid in the site frame.
//!
//! Every target cell centre is mapped back into source pixel coordinates. Reprojecting each cell
//! exactly is costly (a proj4rs call per cell), and over a few metres every map projection is
//! linear to far below a pixel, so, like GDAL's approximate transformer, the mapping is computed
//! exactly on a lattice every [`LATTICE`] cells and interpolated bilinearly in between.

use crate::artifact::Grid;
use crate::io::crs::ToSite;
use crate::io::geotiff::PixelGrid;

/// Lattice spacing, in target cells, of the exact reprojection.
pub const LATTICE: u32 = 16;

/// The site-aligned grid of `cell_m` covering the source image once reprojected.
pub fn covering_grid(src: &PixelGrid, to_site: &ToSite, cell_m: f64) -> Result<Grid, String> {
    let (mut lo, mut hi) = (
        (f64::INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    const EDGE_SAMPLES: u32 = 32;
    for k in 0..=EDGE_SAMPLES {
        let t = k as f64 / EDGE_SAMPLES as f64;
        let (w, h) = (src.width as f64, src.height as f64);
        for (px, py) in [(t * w, 0.0), (t * w, h), (0.0, t * h), (w, t * h)] {
            let (x, y, _) = to_site.apply(src.west + px * src.dx, src.north - py * src.dy, 0.0)?;
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
        }
    }
    Grid::covering_checked(lo, hi, cell_m).map_err(|m| format!("{m}; use a coarser cell"))
}

/// Most target cells per source pixel a resampling may fill, beyond [`MIN_BOUNDED_CELLS`]: a 90 m
/// DEM on a 0.25 m grid is 129,600 per pixel. Past it the georeferencing, not the data, sizes the
/// work: a 533-byte TIFF whose 12 pixels claim 2,228 km each filled 107 million cells.
pub const MAX_CELLS_PER_PIXEL: u64 = 1 << 20;

/// Target grids up to this many cells are never refused for their ratio to the source.
pub const MIN_BOUNDED_CELLS: u64 = 1 << 24;

/// Refuses resampling `src` onto `target` when the target holds more than
/// [`MAX_CELLS_PER_PIXEL`] cells per source pixel (and more than [`MIN_BOUNDED_CELLS`]).
pub fn check_upsampling(src: &PixelGrid, target: &Grid) -> Result<(), String> {
    let pixels = src.width as u64 * src.height as u64;
    let cells = target.len() as u64;
    if cells > MIN_BOUNDED_CELLS && cells / pixels.max(1) > MAX_CELLS_PER_PIXEL {
        return Err(format!(
            "its {} x {} pixels of {} x {} CRS units would fill {cells} cells of {} m, more than \
             {MAX_CELLS_PER_PIXEL} per pixel: check its pixel size (ModelPixelScale or the \
             geotransform), or give a window",
            src.width, src.height, src.dx, src.dy, target.cell_m
        ));
    }
    Ok(())
}

/// `grid` cut to the cells whose centres lie in `window` (site metres), when one is given: a
/// file far larger than the site (a DEM tile, an SRTM degree) is resampled only where it is used.
/// The column and row of the cut's first cell in `grid` come with it.
pub fn windowed(
    grid: Grid,
    window: Option<(f64, f64, f64, f64)>,
) -> Result<(Grid, u32, u32), String> {
    let Some(w) = window else {
        return Ok((grid, 0, 0));
    };
    grid.crop(w).ok_or_else(|| {
        let x1 = grid.x0 + grid.width as f64 * grid.cell_m;
        let y1 = grid.y0 - grid.height as f64 * grid.cell_m;
        format!(
            "the window ({}, {}, {}, {}) does not overlap the file, which covers x {:.1} to {x1:.1}, \
             y {y1:.1} to {:.1} (site metres)",
            w.0, w.1, w.2, w.3, grid.x0, grid.y0
        )
    })
}

/// Fractional source pixel coordinates (column, row; pixel centres at +0.5) of every target cell
/// centre, row by row.
pub struct SourceMap {
    nx: usize,
    lattice: Vec<Option<(f64, f64)>>,
}

impl SourceMap {
    /// Computes the exact mapping on the lattice.
    pub fn new(target: &Grid, src: &PixelGrid, to_site: &ToSite) -> SourceMap {
        let nx = target.width.div_ceil(LATTICE) as usize + 1;
        let ny = target.height.div_ceil(LATTICE) as usize + 1;
        let mut lattice = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let x = target.x0 + ((i as u32 * LATTICE) as f64 + 0.5) * target.cell_m;
                let y = target.y0 - ((j as u32 * LATTICE) as f64 + 0.5) * target.cell_m;
                lattice.push(
                    to_site
                        .inverse(x, y)
                        .ok()
                        .map(|(sx, sy)| ((sx - src.west) / src.dx, (src.north - sy) / src.dy)),
                );
            }
        }
        SourceMap { nx, lattice }
    }

    /// Source pixel coordinates of target cell (`col`, `row`), if its lattice corners projected.
    pub fn at(&self, col: u32, row: u32) -> Option<(f64, f64)> {
        let (i, j) = ((col / LATTICE) as usize, (row / LATTICE) as usize);
        let (tx, ty) = (
            (col % LATTICE) as f64 / LATTICE as f64,
            (row % LATTICE) as f64 / LATTICE as f64,
        );
        let p00 = self.lattice[j * self.nx + i]?;
        let p10 = self.lattice[j * self.nx + i + 1]?;
        let p01 = self.lattice[(j + 1) * self.nx + i]?;
        let p11 = self.lattice[(j + 1) * self.nx + i + 1]?;
        let lerp = |a: f64, b: f64, c: f64, d: f64| {
            (a * (1.0 - tx) + b * tx) * (1.0 - ty) + (c * (1.0 - tx) + d * tx) * ty
        };
        Some((
            lerp(p00.0, p10.0, p01.0, p11.0),
            lerp(p00.1, p10.1, p01.1, p11.1),
        ))
    }
}

/// How a value is read between source pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Resample {
    /// The pixel containing the point.
    Nearest,
    /// Bilinear between the four nearest pixel centres; no-data if any of them is.
    Bilinear,
}

/// Samples `value(col, row)` (NaN = no-data) at fractional pixel coordinates `(u, v)`.
pub fn sample(
    u: f64,
    v: f64,
    width: u32,
    height: u32,
    how: Resample,
    value: impl Fn(u32, u32) -> f64,
) -> f64 {
    if !(u >= 0.0 && v >= 0.0 && u < width as f64 && v < height as f64) {
        return f64::NAN;
    }
    match how {
        Resample::Nearest => value(u as u32, v as u32),
        Resample::Bilinear => {
            let (fu, fv) = (
                (u - 0.5).clamp(0.0, (width - 1) as f64),
                (v - 0.5).clamp(0.0, (height - 1) as f64),
            );
            let (c0, r0) = (fu.floor() as u32, fv.floor() as u32);
            let (c1, r1) = ((c0 + 1).min(width - 1), (r0 + 1).min(height - 1));
            let (tx, ty) = (fu - c0 as f64, fv - r0 as f64);
            (value(c0, r0) * (1.0 - tx) + value(c1, r0) * tx) * (1.0 - ty)
                + (value(c0, r1) * (1.0 - tx) + value(c1, r1) * tx) * ty
        }
    }
}
