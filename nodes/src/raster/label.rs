//! Connected-component labelling on row-major grids (4-connected), and reading label rasters back.

use crate::artifact::Raster;

/// 4-connected components of at least `min_cells`, labelled 1, 2, ... in raster order of their
/// first cell; 0 elsewhere.
pub fn label_components(mask: &[bool], w: u32, h: u32, min_cells: usize) -> Vec<u32> {
    let key: Vec<u32> = mask.iter().map(|&m| m as u32).collect();
    label_regions(&key, w, h, min_cells)
}

/// 4-connected regions of equal non-zero `key` of at least `min_cells`, labelled 1, 2, ... in
/// raster order of their first cell; 0 elsewhere.
pub fn label_regions(key: &[u32], w: u32, h: u32, min_cells: usize) -> Vec<u32> {
    flood_regions(w, h, min_cells, |i| key[i] != 0, |i, j| key[i] == key[j])
}

/// 4-connected regions of `active` cells, neighbours joined where `connect(cell, neighbour)`,
/// of at least `min_cells`, labelled 1, 2, ... in raster order of their first cell; 0 elsewhere.
pub fn flood_regions(
    w: u32,
    h: u32,
    min_cells: usize,
    active: impl Fn(usize) -> bool,
    connect: impl Fn(usize, usize) -> bool,
) -> Vec<u32> {
    let (w, h) = (w as usize, h as usize);
    let mut labels = vec![0u32; w * h];
    let mut seen = vec![false; w * h];
    let mut next = 1u32;
    let (mut stack, mut members) = (Vec::new(), Vec::new());
    for start in 0..w * h {
        if !active(start) || seen[start] {
            continue;
        }
        members.clear();
        stack.push(start);
        seen[start] = true;
        while let Some(i) = stack.pop() {
            members.push(i);
            let (c, r) = (i % w, i / w);
            let neighbours = [
                (c > 0).then(|| i - 1),
                (c + 1 < w).then(|| i + 1),
                (r > 0).then(|| i - w),
                (r + 1 < h).then(|| i + w),
            ];
            for j in neighbours.into_iter().flatten() {
                if !seen[j] && active(j) && connect(i, j) {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        if members.len() >= min_cells {
            for &i in &members {
                labels[i] = next;
            }
            next += 1;
        }
    }
    labels
}

/// The label of every cell, 0 for none (or no data).
pub fn label_ids(labels: &Raster) -> Vec<u32> {
    labels
        .data
        .iter()
        .map(|&v| {
            if v.is_finite() && v > 0.0 {
                v as u32
            } else {
                0
            }
        })
        .collect()
}
