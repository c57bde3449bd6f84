//! Rasters on grids in the site frame.

use serde::{Deserialize, Serialize};

use super::PodVec;

/// A north-up grid in the site frame. Row 0 is the northern edge, as in GeoTIFF.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Site-frame x of the western edge, metres.
    pub x0: f64,
    /// Site-frame y of the northern edge, metres.
    pub y0: f64,
    /// Cell size, metres (square cells).
    pub cell_m: f64,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

impl Grid {
    /// A grid of `cols` x `rows` cells computed from data (an extent over a cell size), checked
    /// against the cell and memory limits ([`crate::params::check_cells`], as f32 cells) before
    /// the counts are cast: a far-flung extent is an error, never a width that wraps.
    pub fn sized(x0: f64, y0: f64, cell_m: f64, cols: f64, rows: f64) -> Result<Grid, String> {
        let (cols, rows) = (cols.ceil(), rows.ceil());
        crate::params::check_cells(cols, rows, 4)?;
        Ok(Grid {
            x0,
            y0,
            cell_m,
            width: cols as u32,
            height: rows as u32,
        })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }
    /// True when the grid has no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Site-frame centre of cell (`col`, `row`).
    pub fn center(&self, col: u32, row: u32) -> (f64, f64) {
        (
            self.x0 + (col as f64 + 0.5) * self.cell_m,
            self.y0 - (row as f64 + 0.5) * self.cell_m,
        )
    }
    /// The cell containing site-frame point (`x`, `y`), if inside the grid.
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(u32, u32)> {
        // Truncation is the floor on [0, width): no call to libm's `floor` (the default x86-64
        // target has no rounding instruction), and the radio map asks once per crossing.
        let c = (x - self.x0) / self.cell_m;
        let r = (self.y0 - y) / self.cell_m;
        (c >= 0.0 && r >= 0.0 && c < self.width as f64 && r < self.height as f64)
            .then_some((c as u32, r as u32))
    }
    /// [`Grid::covering`], refused when the box or the cell size is not finite or the grid would
    /// have more than [`crate::params::MAX_CELLS`] cells: user extents and cell sizes are checked
    /// here, before a buffer of that size is asked for.
    pub fn covering_checked(lo: (f64, f64), hi: (f64, f64), cell_m: f64) -> Result<Grid, String> {
        if !(cell_m > 0.0 && cell_m.is_finite()) {
            return Err(format!(
                "expected a positive, finite cell size, found {cell_m}"
            ));
        }
        if ![lo.0, lo.1, hi.0, hi.1].iter().all(|v| v.is_finite()) {
            return Err(format!(
                "expected a finite extent, found ({}, {}) to ({}, {})",
                lo.0, lo.1, hi.0, hi.1
            ));
        }
        let x0 = (lo.0 / cell_m).floor() * cell_m;
        let y0 = (hi.1 / cell_m).floor() * cell_m + cell_m;
        let width = (((hi.0 - x0) / cell_m).floor() + 1.0).max(1.0);
        let height = (((y0 - lo.1) / cell_m).floor() + 1.0).max(1.0);
        crate::params::check_cells(width, height, 4)
            .map_err(|m| format!("{m} (cells of {cell_m} m)"))?;
        Ok(Grid::covering(lo, hi, cell_m))
    }
    /// Refuses a grid past [`crate::params::MAX_CELLS`], for grids sized from data (a scene's
    /// extent) before rasters of them are allocated.
    pub fn check_size(&self) -> Result<(), String> {
        crate::params::check_cells(self.width as f64, self.height as f64, 4)
            .map_err(|m| format!("{m} (cells of {} m)", self.cell_m))
    }
    /// The part of the grid whose cell centres lie in `window` (x_min, y_min, x_max, y_max, site
    /// metres), with the column and row of its first cell in this grid; None when no cell does.
    pub fn crop(&self, window: (f64, f64, f64, f64)) -> Option<(Grid, u32, u32)> {
        let (wx0, wy0, wx1, wy1) = window;
        let c = self.cell_m;
        let first = |v: f64| v.ceil().max(0.0);
        let last = |v: f64, n: u32| v.floor().min(n as f64 - 1.0);
        let (c0, c1) = (
            first((wx0 - self.x0) / c - 0.5),
            last((wx1 - self.x0) / c - 0.5, self.width),
        );
        let (r0, r1) = (
            first((self.y0 - wy1) / c - 0.5),
            last((self.y0 - wy0) / c - 0.5, self.height),
        );
        if !(c0 <= c1 && r0 <= r1) {
            return None;
        }
        let (col0, row0) = (c0 as u32, r0 as u32);
        let grid = Grid {
            x0: self.x0 + col0 as f64 * c,
            y0: self.y0 - row0 as f64 * c,
            cell_m: c,
            width: (c1 - c0) as u32 + 1,
            height: (r1 - r0) as u32 + 1,
        };
        Some((grid, col0, row0))
    }
    /// The smallest grid with cells of `cell_m`, aligned to multiples of `cell_m` from the site
    /// origin, that covers the box `[lo, hi]`.
    pub fn covering(lo: (f64, f64), hi: (f64, f64), cell_m: f64) -> Grid {
        let x0 = (lo.0 / cell_m).floor() * cell_m;
        let y0 = (hi.1 / cell_m).floor() * cell_m + cell_m;
        let width = (((hi.0 - x0) / cell_m).floor() as u32 + 1).max(1);
        let height = ((y0 - lo.1) / cell_m).floor() as u32 + 1;
        Grid {
            x0,
            y0,
            cell_m,
            width,
            height,
        }
    }
}

/// One f32 band on a [`Grid`], row-major from the north-west corner. NaN marks no-data
/// (the paper's ⊥: nothing observed there).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Raster {
    /// Where the cells are.
    pub grid: Grid,
    /// `grid.width * grid.height` values.
    pub data: PodVec<f32>,
}

impl Raster {
    /// A raster of `grid` filled with `v`.
    pub fn filled(grid: Grid, v: f32) -> Raster {
        Raster {
            grid,
            data: PodVec::filled(v, grid.len()),
        }
    }
    /// The value at (`col`, `row`).
    pub fn at(&self, col: u32, row: u32) -> f32 {
        self.data[row as usize * self.grid.width as usize + col as usize]
    }
    /// Bilinear interpolation between cell centres; `None` where a neighbour is no-data or outside.
    pub fn bilinear(&self, x: f64, y: f64) -> Option<f64> {
        let g = self.grid;
        if g.is_empty() {
            return None;
        }
        let fc = ((x - g.x0) / g.cell_m - 0.5).clamp(0.0, (g.width - 1) as f64);
        let fr = ((g.y0 - y) / g.cell_m - 0.5).clamp(0.0, (g.height - 1) as f64);
        let (c0, r0) = (fc.floor() as u32, fr.floor() as u32);
        let (c1, r1) = ((c0 + 1).min(g.width - 1), (r0 + 1).min(g.height - 1));
        let (tx, ty) = (fc - c0 as f64, fr - r0 as f64);
        let z00 = self.at(c0, r0) as f64;
        let z10 = self.at(c1, r0) as f64;
        let z01 = self.at(c0, r1) as f64;
        let z11 = self.at(c1, r1) as f64;
        let z = (z00 * (1.0 - tx) + z10 * tx) * (1.0 - ty) + (z01 * (1.0 - tx) + z11 * tx) * ty;
        z.is_finite().then_some(z)
    }

    /// The cells whose centres lie in `window` (x0, y0, x1, y1), on this raster's lattice; None
    /// when there are none.
    pub fn cropped(&self, window: (f64, f64, f64, f64)) -> Option<Raster> {
        let (grid, col0, row0) = self.grid.crop(window)?;
        let mut data = Vec::with_capacity(grid.len());
        for row in row0..row0 + grid.height {
            let start = row as usize * self.grid.width as usize + col0 as usize;
            data.extend_from_slice(&self.data[start..start + grid.width as usize]);
        }
        Some(Raster {
            grid,
            data: PodVec(data),
        })
    }

    /// Rows as slices.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, f32> {
        self.data.chunks_exact(self.grid.width.max(1) as usize)
    }
}
