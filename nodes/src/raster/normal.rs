//! Surface normals of a height raster.

use rayon::prelude::*;

use crate::artifact::Raster;

/// Vertical component of the surface normal at each cell, from central differences; NaN where a
/// neighbour is missing.
pub fn normal_z(h: &Raster) -> Vec<f32> {
    let g = h.grid;
    let (w, ht) = (g.width as i64, g.height as i64);
    let at = |c: i64, r: i64| {
        if c < 0 || r < 0 || c >= w || r >= ht {
            f32::NAN
        } else {
            h.at(c as u32, r as u32)
        }
    };
    (0..g.len())
        .into_par_iter()
        .map(|i| {
            let (c, r) = ((i as i64) % w, (i as i64) / w);
            let dx = (at(c + 1, r) - at(c - 1, r)) as f64 / (2.0 * g.cell_m);
            let dy = (at(c, r - 1) - at(c, r + 1)) as f64 / (2.0 * g.cell_m);
            (1.0 / (1.0 + dx * dx + dy * dy).sqrt()) as f32
        })
        .collect()
}
