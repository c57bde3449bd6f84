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

/// Morphological closing (dilation, then erosion) by a disk of `radius` cells as if the grid
/// went on empty beyond its edge: [`erode`] counts outside as full, so a closing made of the two
/// would fill the gap between a mask and the grid's edge (a drainpipe one texel from a wall's
/// corner grown over that texel). Computed on a copy padded by `radius` empty cells.
pub fn close_within(mask: &[bool], w: u32, h: u32, radius: i64) -> Vec<bool> {
    if radius <= 0 {
        return mask.to_vec();
    }
    let r = radius as u32;
    let (pw, ph) = (w + 2 * r, h + 2 * r);
    let mut padded = vec![false; (pw * ph) as usize];
    for y in 0..h {
        let row = (y * w) as usize..((y + 1) * w) as usize;
        let at = ((y + r) * pw + r) as usize;
        padded[at..at + w as usize].copy_from_slice(&mask[row]);
    }
    let closed = erode(&dilate(&padded, pw, ph, radius), pw, ph, radius);
    (0..h)
        .flat_map(|y| {
            let at = ((y + r) * pw + r) as usize;
            closed[at..at + w as usize].to_vec()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closing_within_leaves_the_edge_gap_and_bridges_inner_ones() {
        // Columns: 0 empty (the gap to the edge), 1 full, 2 empty, 3 full, 4.. empty.
        let (w, h) = (8u32, 6u32);
        let mask: Vec<bool> = (0..w * h).map(|k| matches!(k % w, 1 | 3)).collect();
        let closed = close_within(&mask, w, h, 1);
        let col = |m: &[bool], x: u32, ys: std::ops::Range<u32>| {
            ys.into_iter().all(|y| m[(y * w + x) as usize])
        };
        assert!(
            !(0..h).any(|y| closed[(y * w) as usize]),
            "the edge gap stays open"
        );
        assert!(
            col(&closed, 1, 0..h) && col(&closed, 3, 0..h),
            "the mask stays"
        );
        // The bridge's ends on the first and last rows open onto the empty outside.
        assert!(col(&closed, 2, 1..h - 1), "the inner gap closes");
        assert!(!closed[2] && !closed[((h - 1) * w + 2) as usize]);
        assert!(!(0..h).any(|y| closed[(y * w + 5) as usize]));
        // What the plain pair does, and why this exists: outside counts as full.
        let plain = erode(&dilate(&mask, w, h, 1), w, h, 1);
        assert!((0..h).all(|y| plain[(y * w) as usize]));
    }

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
