//! What a view says each pixel shows, as the registration reads it: building, sky or ground,
//! the wall instance, the façade feature; the lattices of pixels the search scores, and the
//! edges between labels near which a small move changes the score.

use crate::artifact::View;
use crate::geom::raycast::tiles_of;

use super::RegistrationParams;

/// What a view's segmentation says a pixel shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Seen {
    Building,
    Sky,
    Ground,
    /// No depth to tell sky from ground: anything but a building.
    NotBuilding,
}

/// What the twin shows along a ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Rendered {
    Building,
    Sky,
    Ground,
    /// Clutter or vegetation in the scene: says nothing about the pose.
    Other,
}

/// +1 agreement, -1 disagreement, 0 when the pair says nothing (sky against the ground beyond
/// the terrain's edge, anything against clutter).
pub(super) fn agreement(seen: Seen, rendered: Rendered) -> i32 {
    use Rendered as R;
    match (seen, rendered) {
        (_, R::Other) => 0,
        (Seen::Building, R::Building) => 1,
        (Seen::Building, _) => -1,
        (Seen::Sky, R::Sky) => 1,
        (Seen::Sky, R::Building) => -1,
        (Seen::Sky, R::Ground) => 0,
        (Seen::Ground, R::Ground) => 1,
        (Seen::Ground, R::Building) => -1,
        (Seen::Ground, R::Sky) => 0,
        (Seen::NotBuilding, R::Building) => -1,
        (Seen::NotBuilding, _) => 1,
    }
}

/// A sampled pixel: its camera-frame unit direction turned into the site frame by the reported
/// rotation, what the view says is there, the wall instance it shows (0 if not a wall), the
/// next sample right of it and below it on the lattice (`u32::MAX`: none), and its tile.
pub(super) struct Sample {
    pub(super) dir: [f64; 3],
    pub(super) seen: Seen,
    pub(super) wall: u16,
    pub(super) facade: Facade,
    pub(super) right: u32,
    pub(super) down: u32,
    /// The tile of the lattice it lies in (about 8 pixels across), numbered row by row.
    pub(super) tile: u32,
}

/// What a building pixel shows of its façade.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Facade {
    /// Plain wall.
    Wall,
    /// A window, door, balcony or any other architectural instance on the wall.
    Feature,
    /// Not a façade (roof, not a building, unlabelled).
    None,
}

/// The lattice strides for `view`: the coarse one giving about `p.samples` pixels, the fine one
/// a quarter of it.
pub(super) fn strides(view: &View, p: &RegistrationParams) -> (u32, u32) {
    let area = view.width as f64 * view.height as f64;
    let coarse = (area / p.samples as f64).sqrt().round().max(1.0) as u32;
    (coarse, (coarse / 4).max(1))
}

/// What the view says a pixel shows, or `None` where it says nothing the twin can be held to
/// (clutter in front, a feature standing off the wall, no depth where depth is given).
pub(super) fn label(view: &View, px: usize, p: &RegistrationParams) -> Option<(Seen, u16, Facade)> {
    let arch = view.arch.as_ref()?;
    if view
        .clutter
        .as_ref()
        .is_some_and(|c| c.ids.get(px).is_some_and(|&id| id != 0))
    {
        return None;
    }
    let id = *arch.ids.get(px)?;
    let seen = if id != 0 {
        Seen::Building
    } else {
        match view.depth.as_ref().map(|d| d[px]) {
            Some(d) if d.is_infinite() && d > 0.0 => Seen::Sky,
            // Something near, unlabelled: the ground if the ray points down; above the horizon
            // it is a wall the segmentation missed, or a tree, and says nothing sure.
            Some(d) if d.is_finite() => {
                let w = view.width as usize;
                let (x, y) = ((px % w) as f64 + 0.5, (px / w) as f64 + 0.5);
                if view.pixel_ray(x, y).0[2] < -0.02 {
                    Seen::Ground
                } else {
                    return None;
                }
            }
            Some(_) => return None,
            None => Seen::NotBuilding,
        }
    };
    let class = (id != 0).then(|| arch.classes.get(&id)).flatten();
    if class.is_some_and(|k| p.off_wall_classes.contains(k)) {
        return None;
    }
    let facade = match class {
        Some(k) if *k == p.wall_class => Facade::Wall,
        Some(k) if *k == p.roof_class => Facade::None,
        Some(_) => Facade::Feature,
        None => Facade::None,
    };
    let wall = if facade == Facade::Wall { id } else { 0 };
    Some((seen, wall, facade))
}

/// Pixels where the label changes (building, sky, ground, wall instance, and with `facades` the
/// edges of windows and doors): near them, and only there, a small move changes the agreement.
pub(super) fn edges(view: &View, facades: bool, p: &RegistrationParams) -> Vec<bool> {
    let (w, h) = (view.width as usize, view.height as usize);
    let labels: Vec<Option<(Seen, u16, Facade)>> =
        (0..w * h).map(|px| label(view, px, p)).collect();
    let differ = |a: &Option<(Seen, u16, Facade)>, b: &Option<(Seen, u16, Facade)>| match (a, b) {
        (Some(a), Some(b)) => {
            a.0 != b.0 || (a.1 != 0 && b.1 != 0 && a.1 != b.1) || (facades && a.2 != b.2)
        }
        (None, None) => false,
        _ => true,
    };
    let mut edge = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            if (x + 1 < w && differ(&labels[k], &labels[k + 1]))
                || (y + 1 < h && differ(&labels[k], &labels[k + w]))
            {
                edge[k] = true;
            }
        }
    }
    edge
}

/// The labelled pixels on a lattice of `stride` (those in `keep` only, when given), with their
/// lattice neighbours.
pub(super) fn samples(
    view: &View,
    stride: u32,
    keep: Option<&[bool]>,
    p: &RegistrationParams,
) -> Vec<Sample> {
    let n = (view.width * view.height) as usize;
    if view.arch.as_ref().is_none_or(|a| a.ids.len() != n)
        || view.depth.as_ref().is_some_and(|d| d.len() != n)
        || view.clutter.as_ref().is_some_and(|c| c.ids.len() != n)
    {
        return Vec::new();
    }
    let xs: Vec<u32> = (stride / 2..view.width).step_by(stride as usize).collect();
    let ys: Vec<u32> = (stride / 2..view.height).step_by(stride as usize).collect();
    let cols = xs.len();
    let mut at = vec![u32::MAX; cols * ys.len()];
    let mut out: Vec<Sample> = Vec::new();
    // In tiles about 8 pixels across (a packet's worth, 2.25 degrees in a 320-pixel view of 90),
    // each tile's samples a run: their rays run side by side and are cast as one packet. A
    // score sums over the samples: their order does not change it.
    let side = (8 / stride).max(1) as usize;
    let across = cols.div_ceil(side);
    for cell in tiles_of(cols as u32, ys.len() as u32, side as u32) {
        let (r, c) = (cell as usize / cols, cell as usize % cols);
        let (x, y) = (xs[c], ys[r]);
        let px = (y * view.width + x) as usize;
        if keep.is_some_and(|k| !k[px]) {
            continue;
        }
        let Some((seen, wall, facade)) = label(view, px, p) else {
            continue;
        };
        let (dir, _) = view.pixel_ray(x as f64 + 0.5, y as f64 + 0.5);
        at[r * cols + c] = out.len() as u32;
        out.push(Sample {
            dir,
            seen,
            wall,
            facade,
            right: u32::MAX,
            down: u32::MAX,
            tile: ((r / side) * across + c / side) as u32,
        });
    }
    for r in 0..ys.len() {
        for c in 0..cols {
            let k = at[r * cols + c];
            if k == u32::MAX {
                continue;
            }
            if c + 1 < cols {
                out[k as usize].right = at[r * cols + c + 1];
            }
            if r + 1 < ys.len() {
                out[k as usize].down = at[(r + 1) * cols + c];
            }
        }
    }
    out
}
