//! Binary morphology on row-major masks: dilation and erosion by a square structuring element.

use rayon::prelude::*;

fn morph(mask: &[bool], w: u32, h: u32, radius: i64, dilate: bool) -> Vec<bool> {
    if radius <= 0 {
        return mask.to_vec();
    }
    let (w, h) = (w as i64, h as i64);
    // A disk, separably would be a square; the disk keeps corners from growing diagonally.
    let offsets: Vec<(i64, i64)> = (-radius..=radius)
        .flat_map(|dr| (-radius..=radius).map(move |dc| (dc, dr)))
        .filter(|(dc, dr)| dc * dc + dr * dr <= radius * radius)
        .collect();
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (c, r) = (i % w, i / w);
            let hit = |(dc, dr): &(i64, i64)| {
                let (cc, rr) = (c + dc, r + dr);
                // Outside the grid counts as empty for dilation and as full for erosion, so
                // buildings cut by the survey's edge are not eaten away.
                if cc < 0 || rr < 0 || cc >= w || rr >= h {
                    !dilate
                } else {
                    mask[(rr * w + cc) as usize]
                }
            };
            if dilate {
                offsets.iter().any(hit)
            } else {
                offsets.iter().all(hit)
            }
        })
        .collect()
}

/// Morphological dilation with a disk of `radius` cells.
pub fn dilate(mask: &[bool], w: u32, h: u32, radius: i64) -> Vec<bool> {
    morph(mask, w, h, radius, true)
}

/// Morphological erosion with a disk of `radius` cells.
pub fn erode(mask: &[bool], w: u32, h: u32, radius: i64) -> Vec<bool> {
    morph(mask, w, h, radius, false)
}
