//! Raster mechanisms shared by the stages: gap filling, Gaussian blur, connected-component
//! labelling, morphology and surface normals. Never imports a stage.

pub mod blur;
pub mod gap_fill;
pub mod label;
pub mod morph;
pub mod normal;

/// The box (x0, x1, y0, y1), inclusive, of the cells of a row-major `w` x `h` grid that `set`
/// says are set; `None` where none is. The morphology and the fusion's blur visit only the part
/// of a large chart the views reached.
pub fn set_box<T>(cells: &[T], w: usize, h: usize, set: impl Fn(&T) -> bool) -> Option<[usize; 4]> {
    let mut b: Option<[usize; 4]> = None;
    for (y, row) in cells.chunks_exact(w.max(1)).take(h).enumerate() {
        let (Some(a), Some(z)) = (row.iter().position(&set), row.iter().rposition(&set)) else {
            continue;
        };
        b = Some(match b {
            None => [a, z, y, y],
            Some([x0, x1, y0, _]) => [x0.min(a), x1.max(z), y0, y],
        });
    }
    b
}
