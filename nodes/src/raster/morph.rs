//! Binary morphology on row-major masks: dilation and erosion by a disk, and dilation by a
//! square in linear time.

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

/// Morphological dilation with a (2 `radius` + 1)² square, separably with running counts: time
/// linear in the mask whatever the radius, for wide bands around sparse edges.
pub fn dilate_square(mask: &[bool], w: u32, h: u32, radius: i64) -> Vec<bool> {
    if radius <= 0 {
        return mask.to_vec();
    }
    let (w, h) = (w as usize, h as usize);
    let r = radius as usize;
    // One pass along lines of `len` cells `stride` apart, starting at each of `starts`.
    let pass = |src: &[bool], len: usize, starts: Vec<(usize, usize)>| -> Vec<bool> {
        let mut out = vec![false; src.len()];
        for (first, stride) in starts {
            let mut prefix = vec![0u32; len + 1];
            for k in 0..len {
                prefix[k + 1] = prefix[k] + src[first + k * stride] as u32;
            }
            for k in 0..len {
                let (lo, hi) = (k.saturating_sub(r), (k + r + 1).min(len));
                out[first + k * stride] = prefix[hi] > prefix[lo];
            }
        }
        out
    };
    let rows = pass(mask, w, (0..h).map(|y| (y * w, 1)).collect());
    pass(&rows, h, (0..w).map(|x| (x, w)).collect())
}

/// Morphological erosion with a disk of `radius` cells.
pub fn erode(mask: &[bool], w: u32, h: u32, radius: i64) -> Vec<bool> {
    morph(mask, w, h, radius, false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_square_dilation_matches_the_definition() {
        let (w, h) = (23u32, 17u32);
        let mut state = 0x2545_F491u64;
        let mask: Vec<bool> = (0..w * h)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state.is_multiple_of(29)
            })
            .collect();
        assert!(mask.iter().any(|&m| m));
        for r in [0i64, 1, 2, 5, 40] {
            let fast = dilate_square(&mask, w, h, r);
            for y in 0..h as i64 {
                for x in 0..w as i64 {
                    let want = (-r..=r).any(|dy| {
                        (-r..=r).any(|dx| {
                            let (xx, yy) = (x + dx, y + dy);
                            xx >= 0
                                && yy >= 0
                                && xx < w as i64
                                && yy < h as i64
                                && mask[(yy * w as i64 + xx) as usize]
                        })
                    });
                    assert_eq!(
                        fast[(y * w as i64 + x) as usize],
                        want,
                        "r {r} at ({x}, {y})"
                    );
                }
            }
        }
    }
}
