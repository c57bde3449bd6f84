//! Filling no-data cells from their valid neighbours.

use crate::artifact::Raster;

/// Bounded gap filling: `steps` times, every no-data cell with valid 8-neighbours takes their mean,
/// so holes shrink by one cell per step from their rim and nothing is invented further than
/// `steps` cells from an observation. Double-buffered, so the result does not depend on order.
pub fn fill_gaps(r: &mut Raster, steps: u32) {
    let (w, h) = (r.grid.width as i64, r.grid.height as i64);
    for _ in 0..steps {
        let src = r.data.clone();
        let mut changed = false;
        for row in 0..h {
            for col in 0..w {
                let i = (row * w + col) as usize;
                if src[i].is_finite() {
                    continue;
                }
                let (mut sum, mut n) = (0.0f64, 0u32);
                for (dr, dc) in [
                    (-1, -1),
                    (-1, 0),
                    (-1, 1),
                    (0, -1),
                    (0, 1),
                    (1, -1),
                    (1, 0),
                    (1, 1),
                ] {
                    let (rr, cc) = (row + dr, col + dc);
                    if rr >= 0 && rr < h && cc >= 0 && cc < w {
                        let v = src[(rr * w + cc) as usize];
                        if v.is_finite() {
                            sum += v as f64;
                            n += 1;
                        }
                    }
                }
                if n > 0 {
                    r.data[i] = (sum / n as f64) as f32;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
}
