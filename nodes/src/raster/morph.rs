//! Binary morphology on row-major masks: dilation and erosion by a disk, and dilation by a
//! square in linear time.

use rayon::prelude::*;

/// Cells a parallel task of [`morph`] takes at least.
const MIN_CELLS_PER_TASK: usize = 1 << 16;

fn morph(mask: &[bool], w: u32, h: u32, radius: i64, dilate: bool) -> Vec<bool> {
    if radius <= 0 {
        return mask.to_vec();
    }
    let (w, h) = (w as usize, h as usize);
    // A disk is, row by row, a horizontal run: the row `dr` away is searched `span[dr]` cells
    // either side (a square, separably, would grow corners diagonally). Each output row is then
    // the OR (dilation) or AND (erosion) of sliding-window tests on the rows within the radius:
    // linear in the grid for a fixed radius, with no per-cell closure over the disk.
    let spans: Vec<(i64, usize)> = (-radius..=radius)
        .map(|dr| {
            let s = ((radius * radius - dr * dr) as f64).sqrt().floor() as i64;
            // Exact integer floor of the root: the disk is dc² + dr² <= radius².
            let s = (s - 1..=s + 1)
                .rev()
                .find(|&c| c >= 0 && c * c + dr * dr <= radius * radius)
                .unwrap_or(0);
            (dr, s as usize)
        })
        .collect();
    let mut out = vec![!dilate; w * h];
    if w == 0 {
        return out;
    }
    // Bands of rows big enough to be worth a task: a façade chart's few thousand cells are one
    // (the relief closes thousands of them, each already on a thread of its own).
    let band = MIN_CELLS_PER_TASK.div_ceil(w).max(1);
    out.par_chunks_mut(w * band)
        .enumerate()
        .for_each(|(b, rows)| {
            let mut window = vec![false; w];
            for (k, row) in rows.chunks_mut(w).enumerate() {
                let r = b * band + k;
                for &(dr, span) in &spans {
                    let rr = r as i64 + dr;
                    if rr < 0 || rr >= h as i64 {
                        // Outside the grid counts as empty for dilation and as full for
                        // erosion, so buildings cut by the survey's edge are not eaten away:
                        // no effect either way.
                        continue;
                    }
                    let src = &mask[rr as usize * w..(rr as usize + 1) * w];
                    sliding_any(src, span, dilate, &mut window);
                    for (o, &x) in row.iter_mut().zip(&window) {
                        if dilate {
                            *o |= x;
                        } else {
                            *o &= !x;
                        }
                    }
                }
            }
        });
    out
}

/// `out[x]` = whether any cell of `src` within `span` of x equals `value`: cells beyond the row's
/// ends never do (for an erosion they count as full, so as not `false`).
fn sliding_any(src: &[bool], span: usize, value: bool, out: &mut [bool]) {
    let w = src.len();
    let mut count = src[..span.min(w)].iter().filter(|&&m| m == value).count();
    for x in 0..w {
        if x + span < w && src[x + span] == value {
            count += 1;
        }
        out[x] = count > 0;
        if x >= span && src[x - span] == value {
            count -= 1;
        }
    }
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

/// `op` applied to the part of `mask` around its set cells only: their bounding box grown by
/// `margin` cells and clipped to the grid, every cell outside it unset in the result. Equal to
/// `op` on the whole mask when `op` reads and sets nothing farther than `margin` cells from a
/// set cell: [`erode`], [`dilate`], [`close_within`] and their sequences, by disks of radius up
/// to `margin` (an erosion's full outside is only ever met by unset cells). A wall chart's
/// relief mask is a few windows on a chart of a million texels.
pub fn on_support(
    mask: &[bool],
    w: u32,
    h: u32,
    margin: u32,
    op: impl FnOnce(&[bool], u32, u32) -> Vec<bool>,
) -> Vec<bool> {
    let (wu, hu) = (w as usize, h as usize);
    let Some([sx0, sx1, sy0, sy1]) = super::set_box(mask, wu, hu, |&m| m) else {
        return op(mask, w, h);
    };
    let m = margin as usize;
    let (x0, x1) = (sx0.saturating_sub(m), (sx1 + m).min(wu - 1));
    let (y0, y1) = (sy0.saturating_sub(m), (sy1 + m).min(hu - 1));
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    if cw == wu && ch == hu {
        return op(mask, w, h);
    }
    let crop: Vec<bool> = (y0..=y1)
        .flat_map(|y| mask[y * wu + x0..=y * wu + x1].iter().copied())
        .collect();
    let done = op(&crop, cw as u32, ch as u32);
    let mut out = vec![false; mask.len()];
    for (cy, row) in done.chunks_exact(cw).enumerate() {
        let at = (y0 + cy) * wu + x0;
        out[at..at + cw].copy_from_slice(row);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dilation and erosion by the definition: a disk of `radius`, outside empty for the one
    /// and full for the other.
    fn by_definition(mask: &[bool], w: u32, h: u32, r: i64, dilate: bool) -> Vec<bool> {
        let (w, h) = (w as i64, h as i64);
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let mut disk = (-r..=r)
                    .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
                    .filter(|(dx, dy)| dx * dx + dy * dy <= r * r)
                    .map(|(dx, dy)| {
                        let (xx, yy) = (x + dx, y + dy);
                        if xx < 0 || yy < 0 || xx >= w || yy >= h {
                            !dilate
                        } else {
                            mask[(yy * w + xx) as usize]
                        }
                    });
                if dilate {
                    disk.any(|m| m)
                } else {
                    disk.all(|m| m)
                }
            })
            .collect()
    }

    #[test]
    fn disk_dilation_and_erosion_match_the_definition() {
        let mut state = 0x9E37_79B9u64;
        for (w, h, density) in [(23u32, 17u32, 5u64), (1, 9, 2), (9, 1, 2), (31, 12, 2)] {
            let mask: Vec<bool> = (0..w * h)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state.is_multiple_of(density)
                })
                .collect();
            for r in [0i64, 1, 2, 3, 5, 40] {
                assert_eq!(
                    dilate(&mask, w, h, r),
                    by_definition(&mask, w, h, r, true),
                    "dilate {w}x{h} r {r}"
                );
                assert_eq!(
                    erode(&mask, w, h, r),
                    by_definition(&mask, w, h, r, false),
                    "erode {w}x{h} r {r}"
                );
            }
        }
    }

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

    #[test]
    fn morphology_on_the_support_equals_it_on_the_whole_grid() {
        // Opening then closing, as the relief does, on sparse random masks of every shape,
        // whole grid against the set cells' box: equal cell for cell.
        let mut seed = 12345u64;
        let mut rnd = move || {
            seed = crate::rng::mix(seed);
            (seed >> 33) as u32
        };
        for case in 0..200 {
            let (w, h) = (3 + rnd() % 40, 3 + rnd() % 40);
            let n = (w * h) as usize;
            let mut mask = vec![false; n];
            let blobs = rnd() % 4;
            for _ in 0..blobs {
                let (cx, cy) = (rnd() % w, rnd() % h);
                let (bw, bh) = (1 + rnd() % 6, 1 + rnd() % 6);
                for y in cy..(cy + bh).min(h) {
                    for x in cx..(cx + bw).min(w) {
                        mask[(y * w + x) as usize] = rnd() % 5 != 0;
                    }
                }
            }
            let (open, close) = ((rnd() % 3) as i64, (rnd() % 4) as i64);
            let op = |m: &[bool], w: u32, h: u32| {
                let opened = dilate(&erode(m, w, h, open), w, h, open);
                close_within(&opened, w, h, close)
            };
            let whole = op(&mask, w, h);
            let margin = open.max(close) as u32;
            assert_eq!(on_support(&mask, w, h, margin, op), whole, "case {case}");
        }
    }
}
