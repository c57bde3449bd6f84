//! Instances from one chart's posteriors: thresholding with hysteresis, morphology, connected
//! components joined across unobserved gaps, features that run the wall's height, and each
//! instance's class, depth and rectangle.

use std::collections::{BTreeMap, BTreeSet};

use crate::artifact::{Chart, ReliefInstance};
use crate::geom::raycast::SceneRays;
use crate::geom::theil_sen::weighted_median;
use crate::geom::union_find::UnionFind;
use crate::raster::label::label_components;
use crate::raster::morph::{close_within, dilate, erode, on_support};

use super::extent::{extent, mean_finite, texel_box};
use super::layers::DenseLayers;
use super::lookup::Lookup;
use super::params::{ClassRule, ReliefParams};
use super::posterior::mesh_state_probabilities;
use super::votes::RegionVote;

/// Threshold, opening, closing and connected components of one chart's posteriors (pieces
/// joined across unobserved stretches), each component a rectangle (where its evidence falls to
/// half its peak) with a class, a depth and its evidence.
#[allow(clippy::too_many_arguments)]
pub(super) fn instances(
    ci: u32,
    c: &Chart,
    lay: &DenseLayers,
    regions: &[&RegionVote],
    with_mesh: bool,
    j_ref: f64,
    ground: &dyn Fn(f64) -> Option<f64>,
    p: &ReliefParams,
) -> Vec<ReliefInstance> {
    let mut out = Vec::new();
    for sign in [-1i8, 1] {
        let (mine, other, evidence) = if sign < 0 {
            (&lay.pr_recessed, &lay.pr_protruding, &lay.recessed)
        } else {
            (&lay.pr_protruding, &lay.pr_recessed, &lay.protruding)
        };
        let s = SignCtx {
            ci,
            c,
            lay,
            regions,
            sign,
            mine,
            other,
            evidence,
            // The evidence's blur: the kernel and the bilinear deposit (a triangle of variance
            // 1/6).
            spread: (p.sigma_texels * p.sigma_texels + 1.0 / 6.0).sqrt(),
            with_mesh,
            j_ref,
            ground,
            p,
        };
        s.instances(&mut out);
    }
    out
}

/// What making one chart's instances of one sign reads.
struct SignCtx<'a> {
    ci: u32,
    c: &'a Chart,
    lay: &'a DenseLayers,
    regions: &'a [&'a RegionVote],
    sign: i8,
    /// The posterior of this sign, of the other relief class, and this sign's evidence share.
    mine: &'a [f32],
    other: &'a [f32],
    evidence: &'a [f32],
    /// The evidence's blur, texels.
    spread: f64,
    with_mesh: bool,
    j_ref: f64,
    ground: &'a dyn Fn(f64) -> Option<f64>,
    p: &'a ReliefParams,
}

/// One chart's pieces of one sign: each one's texels and rectangle, the exposure that stops it
/// running the wall's height (None for a class that does not run it), and its rectangle after
/// that run.
struct Pieces {
    pieces: Vec<(Vec<usize>, [f64; 4])>,
    up: Vec<Option<f64>>,
    reached: Vec<[f64; 4]>,
}

impl SignCtx<'_> {
    /// Over `threshold`, ahead of the other relief class and of flat; or (grown) over
    /// `threshold` and ahead of the other relief class.
    fn over(&self, k: usize, threshold: f64, grown: bool) -> bool {
        let (a, b) = (self.mine[k] as f64, self.other[k] as f64);
        a.is_finite() && a >= threshold && a >= b && (grown || a >= 1.0 - a - b)
    }

    /// This sign's instances, pushed onto `out`.
    fn instances(&self, out: &mut Vec<ReliefInstance>) {
        let Some(mask) = self.core_mask() else {
            return;
        };
        let (comps, grown) = self.components(&mask);
        let pieces = self.pieces(comps, &grown);
        for members in self.join_runs(&pieces) {
            if let Some(inst) = self.instance(&pieces, &members, &grown) {
                out.push(inst);
            }
        }
    }

    /// The texels over the threshold after opening and closing; None where none is over it
    /// (nothing the morphology could make an instance of).
    fn core_mask(&self) -> Option<Vec<bool>> {
        let (c, p) = (self.c, self.p);
        let (w, h) = (c.width, c.height);
        let n = c.len();
        let mut mask: Vec<bool> = (0..n).map(|k| self.over(k, p.threshold, false)).collect();
        if !mask.contains(&true) {
            return None;
        }
        let open = if self.sign < 0 {
            p.open_texels.0
        } else {
            p.open_texels.1
        } as i64;
        let close = p.close_texels as i64;
        mask = on_support(&mask, w, h, open.max(close) as u32, |m, w, h| {
            let opened = if open > 0 {
                dilate(&erode(m, w, h, open), w, h, open)
            } else {
                m.to_vec()
            };
            if close > 0 {
                close_within(&opened, w, h, close)
            } else {
                opened
            }
        });
        if close > 0 {
            // Closing never reaches off the surface.
            for (k, m) in mask.iter_mut().enumerate() {
                *m &= c.triangle_at[k] != u32::MAX;
            }
        }
        Some(mask)
    }

    /// The core's components, grouped through the grown mask and joined across gaps, with the
    /// grown mask. Hysteresis: texels over the threshold (the core) are grouped through texels
    /// over the lower `grow_threshold`, so a thin feature whose evidence straddles two texel
    /// columns (a 0.12 m drainpipe on 0.1 m texels reads about half in each) stays one instance
    /// rather than breaking wherever both halves dip under the threshold. The rectangle and the
    /// evidence come from the core alone.
    fn components(&self, mask: &[bool]) -> (Vec<Vec<usize>>, Vec<bool>) {
        let (c, p, lay) = (self.c, self.p, self.lay);
        let (w, h) = (c.width, c.height);
        let n = c.len();
        let grown: Vec<bool> = (0..n)
            .map(|k| {
                mask[k] || (c.triangle_at[k] != u32::MAX && self.over(k, p.grow_threshold, true))
            })
            .collect();
        let labels = label_components(&grown, w, h, 1);
        let mut comps: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
        for (k, &l) in labels.iter().enumerate() {
            if l != 0 && mask[k] {
                comps.entry(l).or_default().push(k);
            }
        }
        let passable = |k: usize| {
            c.triangle_at[k] != u32::MAX
                && (!(lay.exposure[k] as f64 >= p.exposure_min) || grown[k])
        };
        let comps = bridge_gaps(comps.into_values().collect(), w, p.bridge_texels, &passable);
        (comps, grown)
    }

    /// The regions that voted inside a rectangle (with the deposit's slack).
    fn inside(&self, rect: [f64; 4]) -> Vec<&RegionVote> {
        let slack = 2.0;
        self.regions
            .iter()
            .copied()
            .filter(|r| {
                r.sign == self.sign
                    && r.uv.0 >= rect[0] - slack
                    && r.uv.0 <= rect[2] + slack
                    && r.uv.1 >= rect[1] - slack
                    && r.uv.1 <= rect[3] + slack
            })
            .collect()
    }

    /// A piece of a class that runs the wall's height (a downpipe, from its gutter to the
    /// ground) reaches up and down to where a storey of observed flat wall, the surface's end or
    /// the terrain stops it, and pieces that then overlap are one feature. Flat wall counts only
    /// where the views saw it well enough to have resolved the feature: an exposure over what
    /// one view resolving the class's widest (`width_m`) across gives, (1 / (w² J_ref))^(gamma
    /// + 1) in exposure units (a far view sees a 0.12 m pipe under a pixel wide and reads the
    /// wall flat). None for a class that does not run the wall's height.
    fn stop_exposure(&self, class: &str) -> Option<f64> {
        let p = self.p;
        let r = p
            .classes
            .iter()
            .find(|r| r.name == class && r.runs_full_height)?;
        let resolve = r.width_m.map_or(0.0, |(_, hi)| {
            (1.0 / (hi * hi * self.j_ref)).powf(p.gamma + 1.0)
        });
        Some(resolve.max(p.exposure_min))
    }

    /// `rect` run up and down the wall through its columns until an exposure of `stop` of flat
    /// wall, the surface's end or the ground stops it.
    fn reach(&self, rect: [f64; 4], stop: f64, grown: &[bool]) -> [f64; 4] {
        let (c, lay) = (self.c, self.lay);
        let stop_rows = ((self.p.run_stop_m / c.texel_m).ceil() as usize).max(1);
        let floor = (self.ground)(0.5 * (rect[0] + rect[2])).unwrap_or(0.0);
        run_full_height(rect, c.width, c.height, floor, stop_rows, |k| {
            if c.triangle_at[k] == u32::MAX {
                Row::Off
            } else if !(lay.exposure[k] as f64 >= stop) || grown[k] {
                Row::Passable
            } else {
                Row::Flat
            }
        })
    }

    /// The components big enough, their rectangles, and how far those of a running class run.
    fn pieces(&self, comps: Vec<Vec<usize>>, grown: &[bool]) -> Pieces {
        let (c, p) = (self.c, self.p);
        let pieces: Vec<(Vec<usize>, [f64; 4])> = comps
            .into_iter()
            .filter(|t| t.len() >= p.min_texels as usize)
            .map(|t| {
                let rect = extent(&t, self.evidence, c.width, c.height, self.spread);
                (t, rect)
            })
            .collect();
        let up: Vec<Option<f64>> = pieces
            .iter()
            .map(|(_, rect)| self.stop_exposure(&majority_class(&self.inside(*rect))))
            .collect();
        let reached: Vec<[f64; 4]> = pieces
            .iter()
            .zip(&up)
            .map(|((_, rect), u)| u.map_or(*rect, |stop| self.reach(*rect, stop, grown)))
            .collect();
        Pieces {
            pieces,
            up,
            reached,
        }
    }

    /// The pieces grouped: those that both run the wall's height and meet in one column are one
    /// feature. Groups in the order of their smallest member.
    fn join_runs(&self, pc: &Pieces) -> Vec<Vec<usize>> {
        let (up, reached) = (&pc.up, &pc.reached);
        let mut sets = UnionFind::new(pc.pieces.len());
        for x in 0..pc.pieces.len() {
            for y in x + 1..pc.pieces.len() {
                if up[x].is_some() && up[y].is_some() && one_column(&reached[x], &reached[y]) {
                    sets.join(x as u32, y as u32);
                }
            }
        }
        let mut groups: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
        for (x, name) in sets.names().into_iter().enumerate() {
            groups.entry(name).or_default().push(x);
        }
        groups.into_values().collect()
    }

    /// The instance a group of pieces makes, or None where it does not clear the threshold on
    /// average or is a protrusion no view measured standing out.
    fn instance(&self, pc: &Pieces, members: &[usize], grown: &[bool]) -> Option<ReliefInstance> {
        let (c, p, sign) = (self.c, self.p, self.sign);
        let (texels, rect) = if let [one] = members[..] {
            (pc.pieces[one].0.clone(), pc.reached[one])
        } else {
            let mut t: Vec<usize> = members
                .iter()
                .flat_map(|&x| pc.pieces[x].0.iter().copied())
                .collect();
            t.sort_unstable();
            // Pieces join only when both run up, so the group's first has a stop.
            let stop = pc.up[members[0]].unwrap_or(p.exposure_min);
            let rect = self.reach(
                extent(&t, self.evidence, c.width, c.height, self.spread),
                stop,
                grown,
            );
            (t, rect)
        };
        let m = texels.len() as f64;
        let mean = |l: &[f32]| {
            texels
                .iter()
                .map(|&k| l[k] as f64)
                .filter(|v| v.is_finite())
                .sum::<f64>()
                / m
        };
        let posterior = mean(self.mine);
        // Closing can join a few texels over the threshold with more under it: what comes out
        // must still clear the threshold on average, or it is noise the morphology grew.
        if posterior < p.threshold {
            return None;
        }
        let exposure = mean(&self.lay.exposure);
        let delta_agreement = self.with_mesh.then(|| self.delta_agreement(&texels));
        // The regions that voted for it: class by majority, depth by pixel-weighted median of
        // the measured steps.
        let inside = self.inside(rect);
        let class = majority_class(&inside);
        let mut steps: Vec<(f64, f64)> = inside
            .iter()
            .filter(|r| r.step_m.is_finite() && r.step_m * sign as f64 > 0.0)
            .map(|r| (r.step_m.abs(), r.pixels as f64))
            .collect();
        let measured = weighted_median(&mut steps);
        // A protrusion is deposited on the plane its measured step gives; with none, the class
        // alone put it on this wall.
        if sign > 0 && !measured.is_some_and(|d| d >= p.min_step_m) {
            return None;
        }
        let (lo, hi) = p.depth_range(&class, sign);
        let depth_m = measured.unwrap_or((lo + hi) / 2.0).clamp(lo, hi);
        let rect = match p.classes.iter().find(|r| r.name == class) {
            Some(ClassRule {
                width_m: Some(range),
                ..
            }) => within_width(rect, *range, c.texel_m, c.width, self.evidence),
            _ => rect,
        };
        let views: BTreeSet<u32> = inside.iter().map(|r| r.view).collect();
        let corners = [
            c.world_of(rect[0], rect[1]),
            c.world_of(rect[2], rect[1]),
            c.world_of(rect[2], rect[3]),
            c.world_of(rect[0], rect[3]),
        ];
        Some(ReliefInstance {
            chart: self.ci,
            building: c.building.clone(),
            sign,
            class,
            rect,
            corners,
            depth_m,
            measured_depth_m: measured,
            posterior,
            exposure,
            texels: texels.len() as u32,
            views: views.len() as u32,
            delta_agreement,
        })
    }

    /// The share of an instance's texels where the mesh agrees with its sign: Pr(d | Delta)
    /// again from the stored Delta (f32 both times: the same values the posterior used), rather
    /// than kept for every texel of every chart.
    fn delta_agreement(&self, texels: &[usize]) -> f64 {
        let d = if self.sign < 0 { 0 } else { 2 };
        texels
            .iter()
            .filter(|&&k| {
                let dq = self.lay.delta.get(k).map_or(f64::NAN, |&x| x as f64);
                mesh_state_probabilities(dq, &self.p.delta)[d] > 0.5
            })
            .count() as f64
            / texels.len() as f64
    }
}

/// Class by pixel-weighted majority of the regions inside (named classes first).
fn majority_class(inside: &[&RegionVote]) -> String {
    let mut by_class: BTreeMap<&str, u64> = BTreeMap::new();
    for r in inside {
        *by_class.entry(r.class.as_str()).or_default() += r.pixels as u64;
    }
    by_class
        .iter()
        .filter(|(c, _)| **c != "unknown")
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
        .map_or("unknown", |(c, _)| c)
        .to_owned()
}

/// `rect` narrowed or widened along `u` to a width within `range` (metres; the chart's texels
/// are `texel_m`) about the centroid of the mean `evidence` of its columns and
/// [`CENTROID_REACH`] more each side (a side the chart's end bounds leaves the rectangle's
/// middle off the feature's), kept on the chart's `w` texels.
fn within_width(
    rect: [f64; 4],
    range: (f64, f64),
    texel_m: f64,
    w: u32,
    evidence: &[f32],
) -> [f64; 4] {
    let width = (rect[2] - rect[0]).clamp(range.0 / texel_m, range.1 / texel_m);
    let rows = rect[1].floor() as usize..(rect[3].ceil() as usize).min(evidence.len() / w as usize);
    // The rectangle's own columns cut the blurred evidence's tails unevenly (a 1.2-texel pipe
    // read as [0.7, 1.7] has its centroid pulled 0.4 texel toward the cut side): the centroid
    // is taken over CENTROID_REACH more columns each side, above the window's lowest column
    // mean (the wall's own level, which would pull it toward the window's middle).
    let lo = (rect[0] - CENTROID_REACH).floor().max(0.0) as usize;
    let hi = ((rect[2] + CENTROID_REACH).ceil() as usize).min(w as usize);
    let means: Vec<(usize, f64)> = (lo..hi)
        .map(|i| {
            let m = mean_finite(evidence, &mut rows.clone().map(|j| j * w as usize + i));
            (i, m)
        })
        .filter(|m| m.1.is_finite())
        .collect();
    let floor = means.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
    let (mut sum, mut weight) = (0.0, 0.0);
    for (i, mean) in means {
        sum += (mean - floor) * (i as f64 + 0.5);
        weight += mean - floor;
    }
    let centre = if weight > 0.0 {
        sum / weight
    } else {
        0.5 * (rect[0] + rect[2])
    };
    let u0 = (centre - width / 2.0).clamp(0.0, (w as f64 - width).max(0.0));
    [u0, rect[1], (u0 + width).min(w as f64), rect[3]]
}

/// Columns beyond a thin feature's rectangle its evidence's centroid is taken over: three
/// times the spread of the fusion's blur (sigma 0.5 texel and the bilinear deposit, 0.65).
const CENTROID_REACH: f64 = 2.0;

/// What a row of a running feature's columns holds: a texel it may pass (unobserved, or with
/// some of its evidence), only observed flat wall, or only texels off the surface.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Row {
    Passable,
    Flat,
    Off,
}

/// `rect` run up to the surface's top and down to row `floor` (the terrain) through its columns:
/// through every row where one of its columns' texels `passes`, and through fewer than `stop`
/// rows in a row of observed flat wall; a row off the surface ends the run. A side stays at the
/// last passable row it reached.
fn run_full_height(
    rect: [f64; 4],
    w: u32,
    h: u32,
    floor: f64,
    stop: usize,
    passes: impl Fn(usize) -> Row,
) -> [f64; 4] {
    let (wu, hu) = (w as usize, h as usize);
    let i0 = (rect[0].floor().max(0.0) as usize).min(wu - 1);
    let i1 = (rect[2].ceil() as usize).clamp(i0 + 1, wu);
    let row = |j: usize| {
        let mut row = Row::Off;
        for i in i0..i1 {
            match passes(j * wu + i) {
                Row::Passable => return Row::Passable,
                Row::Flat => row = Row::Flat,
                Row::Off => {}
            }
        }
        row
    };
    // The last passable row reached along `rows`, or None.
    let run = |rows: &mut dyn Iterator<Item = usize>| {
        let (mut last, mut flat) = (None, 0);
        for j in rows {
            match row(j) {
                Row::Off => break,
                Row::Flat => {
                    flat += 1;
                    if flat >= stop {
                        break;
                    }
                }
                Row::Passable => {
                    flat = 0;
                    last = Some(j);
                }
            }
        }
        last
    };
    let top = run(&mut ((rect[3].ceil() as usize).min(hu)..hu)).map_or(rect[3], |j| (j + 1) as f64);
    let first_below = (rect[1].floor().max(0.0) as usize).min(hu);
    let bottom = run(&mut (0..first_below)
        .rev()
        .take_while(|&j| (j + 1) as f64 > floor))
    .map_or(rect[1], |j| (j as f64).max(floor).min(rect[1]));
    [rect[0], bottom, rect[2], top]
}

/// The chart row where the terrain meets a wall chart at column `u`: a ray cast straight down
/// from the chart's top, just outside the wall, that meets the terrain first. None where it
/// meets something else (a neighbour's roof) or nothing.
pub(super) fn ground_row(c: &Chart, rays: &SceneRays, lookup: &Lookup, u: f64) -> Option<f64> {
    const OUTSIDE_M: f64 = 0.3;
    let top = c.world_of(u, c.height as f64);
    let from: [f64; 3] = std::array::from_fn(|k| top[k] + c.normal[k] * OUTSIDE_M);
    let hit = rays.cast(from.map(|x| x as f32), [0.0, 0.0, -1.0], 1e-3, 1e5)?;
    lookup.terrain.get(hit.object).copied().filter(|&t| t)?;
    Some(c.uv_of([top[0], top[1], from[2] - hit.t as f64]).1)
}

/// Whether two rectangles are pieces of one upright feature: they overlap along `u` over half
/// the narrower one's width, and their `v` spans meet.
fn one_column(a: &[f64; 4], b: &[f64; 4]) -> bool {
    let overlap = a[2].min(b[2]) - a[0].max(b[0]);
    let narrower = (a[2] - a[0]).min(b[2] - b[0]);
    overlap > 0.0 && 2.0 * overlap >= narrower && a[1] <= b[3] && b[1] <= a[3]
}

/// Joins components that face each other across a stretch at most `gap` texels wide where every
/// line across has a `passable` texel (unobserved, or with some evidence) within their overlap:
/// one feature seen in pieces (a drainpipe whose storeys a balcony slab hides from the views)
/// rather than several. They must overlap across the gap over half the narrower one's span, and
/// a line of observed flat wall stops the join, so a row of windows stays a row of windows.
fn bridge_gaps(
    comps: Vec<Vec<usize>>,
    w: u32,
    gap: u32,
    passable: impl Fn(usize) -> bool,
) -> Vec<Vec<usize>> {
    if gap == 0 || comps.len() < 2 {
        return comps;
    }
    let boxes: Vec<[usize; 4]> = comps.iter().map(|t| texel_box(t, w)).collect();
    let wu = w as usize;
    // Along axis `a` (0: u, 1: v) box `y` follows box `x` across a passable gap.
    let faces = |x: &[usize; 4], y: &[usize; 4], a: usize| -> bool {
        let b = 1 - a;
        if y[a] <= x[a + 2] || y[a] - x[a + 2] - 1 > gap as usize {
            return false;
        }
        let (lo, hi) = (x[b].max(y[b]), x[b + 2].min(y[b + 2]));
        let narrower = (x[b + 2] - x[b]).min(y[b + 2] - y[b]) + 1;
        if hi < lo || 2 * (hi - lo + 1) < narrower {
            return false;
        }
        (x[a + 2] + 1..y[a]).all(|s| {
            (lo..=hi).any(|t| {
                let (i, j) = if a == 0 { (s, t) } else { (t, s) };
                passable(j * wu + i)
            })
        })
    };
    let mut sets = UnionFind::new(comps.len());
    for x in 0..boxes.len() {
        for y in 0..boxes.len() {
            if x != y && (faces(&boxes[x], &boxes[y], 0) || faces(&boxes[x], &boxes[y], 1)) {
                sets.join(x as u32, y as u32);
            }
        }
    }
    let mut joined: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (x, name) in sets.names().into_iter().enumerate() {
        joined.entry(name).or_default().extend_from_slice(&comps[x]);
    }
    joined
        .into_values()
        .map(|mut t| {
            t.sort_unstable();
            t
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{ChartKind, Scene};

    #[test]
    fn a_thin_protrusion_whose_evidence_dips_stays_one_instance() {
        // A pipe down column 3, one texel from the chart's edge: two rows in every six its
        // evidence dips to "some votes" (0.35), as when it straddles two texel columns.
        let (w, h) = (12u32, 64u32);
        let c = Chart::flat_wall(w, h);
        let n = c.len();
        let mut pr = vec![0.03f32; n];
        for j in 0..h {
            pr[(j * w + 3) as usize] = if j % 6 >= 4 { 0.35 } else { 0.85 };
        }
        let lay = seen_layers(w, h, pr, vec![0.0; n]);
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        // The views measured it standing out all along.
        let at: Vec<(f64, f64)> = (0..h).map(|j| (3.5, j as f64 + 0.5)).collect();
        let votes = measured_out("unknown", &at);
        let votes: Vec<&RegionVote> = votes.iter().collect();
        let one = instances(0, &c, &lay, &votes, false, 1e12, &|_| None, &p);
        assert_eq!(one.len(), 1, "{one:?}");
        // The extent is the core's: one column wide, never grown over the gap to the edge.
        let r = one[0].rect;
        assert!(
            r[0] > 2.9 && r[2] < 4.1 && r[1] < 0.5 && r[3] > 63.5,
            "{r:?}"
        );
        let without = ReliefParams {
            grow_threshold: p.threshold,
            ..p
        };
        // Without the hysteresis (closing bridges one row, not two): a piece per stretch.
        assert_eq!(
            instances(0, &c, &lay, &votes, false, 1e12, &|_| None, &without).len(),
            11
        );
    }

    /// Layers of a `w` x `h` chart seen everywhere (exposure 10) with protruding posterior and
    /// evidence `pr` and `e`.
    fn seen_layers(w: u32, h: u32, pr: Vec<f32>, e: Vec<f32>) -> DenseLayers {
        let n = (w * h) as usize;
        DenseLayers {
            exposure: vec![10.0; n],
            recessed: vec![0.0; n],
            protruding: e,
            delta: vec![f32::NAN; n],
            pr_recessed: vec![0.03; n],
            pr_protruding: pr,
        }
    }

    /// Protruding posterior and evidence of a pipe down column 3 of a `w`-wide chart of `n`
    /// texels, on `rows`; flat elsewhere.
    fn pipe_in_column_3(w: u32, n: usize, rows: impl Iterator<Item = u32>) -> (Vec<f32>, Vec<f32>) {
        let mut pr = vec![0.03f32; n];
        let mut e = vec![0.0f32; n];
        for j in rows {
            pr[(j * w + 3) as usize] = 0.85;
            e[(j * w + 3) as usize] = 0.9;
        }
        (pr, e)
    }

    /// Makes `rows` of `lay` unobserved (no exposure, no evidence, no posterior).
    fn unobserve(lay: &mut DenseLayers, w: u32, rows: std::ops::Range<u32>) {
        for j in rows {
            for i in 0..w {
                let k = (j * w + i) as usize;
                lay.exposure[k] = 0.0;
                lay.protruding[k] = f32::NAN;
                lay.pr_protruding[k] = f32::NAN;
                lay.pr_recessed[k] = f32::NAN;
            }
        }
    }

    /// Region votes that measured a protrusion standing 0.15 m out, one at each of `at` (texel
    /// coordinates), of class `class`.
    fn measured_out(class: &str, at: &[(f64, f64)]) -> Vec<RegionVote> {
        at.iter()
            .map(|&uv| RegionVote {
                view: 0,
                chart: 0,
                uv,
                class: class.into(),
                sign: 1,
                step_m: 0.15,
                pixels: 50,
            })
            .collect()
    }

    #[test]
    fn a_thin_feature_sits_where_its_evidence_splits_between_columns() {
        // Evidence all in column 3 (a pipe centred on it), then split evenly between columns 3
        // and 4 (a pipe on their common edge): the posterior clears the threshold in column 3
        // alone both times, the rectangle follows the evidence.
        let (w, h) = (10u32, 30u32);
        let c = Chart::flat_wall(w, h);
        let n = c.len();
        let mut pr = vec![0.03f32; n];
        for j in 0..h {
            pr[(j * w + 3) as usize] = 0.85;
        }
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let centre = |split: bool| {
            let mut e = vec![0.0f32; n];
            for j in 0..h {
                e[(j * w + 2) as usize] = 0.3;
                e[(j * w + 3) as usize] = 0.8;
                e[(j * w + 4) as usize] = if split { 0.8 } else { 0.3 };
                e[(j * w + 5) as usize] = if split { 0.3 } else { 0.0 };
            }
            let votes = measured_out("unknown", &[(3.5, 15.0)]);
            let votes: Vec<&RegionVote> = votes.iter().collect();
            let one = instances(
                0,
                &c,
                &seen_layers(w, h, pr.clone(), e),
                &votes,
                false,
                1e12,
                &|_| None,
                &p,
            );
            assert_eq!(one.len(), 1, "{one:?}");
            let r = one[0].rect;
            assert!(r[1] < 0.5 && r[3] > 29.5, "{r:?}");
            ((r[0] + r[2]) / 2.0, r[2] - r[0])
        };
        let (on_column, width) = centre(false);
        assert!(
            (on_column - 3.5).abs() < 1e-9 && width < 2.0,
            "{on_column} {width}"
        );
        let (on_edge, width) = centre(true);
        assert!(
            (on_edge - 4.0).abs() < 1e-9 && width < 3.0,
            "{on_edge} {width}"
        );
    }

    #[test]
    fn pieces_join_across_an_unobserved_stretch_not_across_observed_wall() {
        // A pipe down column 3, rows 0-19 and 24-43; rows 20-23 between them unobserved (a
        // balcony slab hid them), then observed and flat.
        let (w, h) = (10u32, 44u32);
        let c = Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), (0..20).chain(24..44));
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let mut hidden = seen_layers(w, h, pr.clone(), e.clone());
        unobserve(&mut hidden, w, 20..24);
        let votes = measured_out("unknown", &[(3.5, 10.0), (3.5, 34.0)]);
        let votes: Vec<&RegionVote> = votes.iter().collect();
        let one = instances(0, &c, &hidden, &votes, false, 1e12, &|_| None, &p);
        assert_eq!(one.len(), 1, "{one:?}");
        assert!(
            one[0].rect[1] < 0.5 && one[0].rect[3] > 43.5,
            "{:?}",
            one[0].rect
        );
        let narrow = ReliefParams {
            bridge_texels: 3,
            ..p.clone()
        };
        assert_eq!(
            instances(0, &c, &hidden, &votes, false, 1e12, &|_| None, &narrow).len(),
            2
        );
        let flat = seen_layers(w, h, pr, e);
        assert_eq!(
            instances(0, &c, &flat, &votes, false, 1e12, &|_| None, &p).len(),
            2
        );
    }

    #[test]
    fn a_protrusion_no_view_measured_standing_out_is_dropped() {
        // The pipe of `pieces_join_...`, seen whole: found when a view measured it 0.15 m out,
        // dropped with no step or a step under `min_step_m` (the class in the image alone).
        let (w, h) = (10u32, 30u32);
        let c = Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), 0..h);
        let lay = seen_layers(w, h, pr, e);
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let found = |step_m: f64| {
            let mut votes = measured_out("unknown", &[(3.5, 15.0)]);
            votes[0].step_m = step_m;
            let votes: Vec<&RegionVote> = votes.iter().collect();
            instances(0, &c, &lay, &votes, false, 1e12, &|_| None, &p).len()
        };
        assert_eq!(found(0.15), 1);
        assert_eq!(found(0.02), 0);
        assert_eq!(found(f64::NAN), 0);
        assert!(instances(0, &c, &lay, &[], false, 1e12, &|_| None, &p).is_empty());
    }

    #[test]
    fn a_drainpipe_runs_the_walls_height_unless_a_storey_of_flat_wall_stops_it() {
        // A pipe seen in column 3 on rows 0-9 and 30-34 of a 50-row wall (0.1 m texels); the
        // rows between and above are unobserved (`hidden`) or observed flat (`flat_between`).
        let (w, h) = (10u32, 50u32);
        let c = Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), (0..10).chain(30..35));
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let mut hidden = seen_layers(w, h, pr.clone(), e.clone());
        unobserve(&mut hidden, w, 10..30);
        unobserve(&mut hidden, w, 35..50);
        let run_with = |lay: &DenseLayers, class: &str, p: &ReliefParams, j_ref: f64| {
            let votes = measured_out(class, &[(3.5, 5.0), (3.5, 32.0)]);
            let votes: Vec<&RegionVote> = votes.iter().collect();
            let mut r: Vec<[f64; 4]> = instances(0, &c, lay, &votes, false, j_ref, &|_| None, p)
                .iter()
                .map(|i| i.rect)
                .collect();
            r.sort_by(|a, b| a[1].total_cmp(&b[1]));
            r
        };
        let run = |lay: &DenseLayers, class: &str| run_with(lay, class, &p, 1e12);
        // A drainpipe: the two pieces are one, up to the wall's top.
        let pipe = run(&hidden, "drainpipe");
        assert_eq!(pipe.len(), 1, "{pipe:?}");
        assert!(pipe[0][1] < 0.5 && pipe[0][3] == 50.0, "{pipe:?}");
        // A feature of no such class stays where it was seen: two pieces (20 rows apart, past
        // `bridge_texels`).
        let other = run(&hidden, "unknown");
        assert_eq!(other.len(), 2, "{other:?}");
        assert!(other[0][3] < 10.5 && other[1][3] < 35.5, "{other:?}");
        // 2 m of observed flat wall between the pieces, under the default storey (3 m): one
        // pipe. With `run_stop_m` at 1 m it stops both: the lower piece stays under it, the
        // upper runs up only.
        let mut flat_between = seen_layers(w, h, pr, e);
        unobserve(&mut flat_between, w, 35..50);
        let pipe = run(&flat_between, "drainpipe");
        assert_eq!(pipe.len(), 1, "{pipe:?}");
        assert!(pipe[0][1] < 0.5 && pipe[0][3] == 50.0, "{pipe:?}");
        let metre = ReliefParams {
            run_stop_m: 1.0,
            ..p.clone()
        };
        let pipe = run_with(&flat_between, "drainpipe", &metre, 1e12);
        assert_eq!(pipe.len(), 2, "{pipe:?}");
        assert!(pipe[0][3] < 10.5, "{pipe:?}");
        assert!(pipe[1][1] > 29.5 && pipe[1][3] == 50.0, "{pipe:?}");
        // Flat only to views too far to have resolved a pipe: it runs through, even a metre of
        // it. The reference view sees 28.4 pixels a square metre (f = 160 px at 30 m);
        // resolving 0.15 m across takes 44.4, (44.4 / 28.4)^3 = 3.8 reference exposures at
        // gamma 2.
        let j_ref = (160.0f64 / 30.0).powi(2);
        let far = |e: f32| {
            let mut lay = flat_between.clone();
            for j in 10..30 {
                for i in 0..w {
                    lay.exposure[(j * w + i) as usize] = e;
                }
            }
            run_with(&lay, "drainpipe", &metre, j_ref)
        };
        let through = far(3.0);
        assert_eq!(through.len(), 1, "{through:?}");
        assert!(through[0][1] < 0.5 && through[0][3] == 50.0);
        assert_eq!(far(4.5).len(), 2);
    }

    #[test]
    fn the_ground_under_a_wall_is_the_terrain_not_a_neighbours_roof() {
        use crate::artifact::Material;
        use crate::artifact::{ObjectClass, SceneObject};
        use crate::geom::charts::{ChartSpec, building_charts};
        use crate::geom::mesh_build::cuboid;
        // A 6 m box standing on its base at z = 0 in a terrain slab whose top is at 0.55 m,
        // and a 2 m shed against its south wall's west half.
        let object = |id: &str, class, mesh| SceneObject {
            id: id.into(),
            class,
            mesh,
        };
        let scene = Scene {
            objects: vec![
                object(
                    "building-0",
                    ObjectClass::Building,
                    cuboid([12.0, 21.5], [4.0, 3.0, 6.0], 0.0, 0.0, Material::Concrete),
                ),
                object(
                    "terrain",
                    ObjectClass::Terrain,
                    cuboid(
                        [12.0, 21.5],
                        [40.0, 40.0, 1.0],
                        0.0,
                        -0.45,
                        Material::Concrete,
                    ),
                ),
                object(
                    "shed",
                    ObjectClass::Building,
                    cuboid([11.0, 19.0], [2.0, 2.0, 2.0], 0.0, 0.0, Material::Concrete),
                ),
            ],
        };
        let charts = building_charts(&scene, &ChartSpec::default()).unwrap();
        let rays = SceneRays::new(&scene);
        let lookup = Lookup::new(&scene, &charts);
        let south = charts
            .charts
            .iter()
            .find(|c| c.building == "building-0" && c.kind == ChartKind::Wall && c.normal[1] < -0.9)
            .unwrap();
        let row = |x: f64| {
            let (u, _) = south.uv_of([x, 20.0, 3.0]);
            ground_row(south, &rays, &lookup, u)
        };
        // 0.55 m above the wall's foot (z = 0) on 0.1 m texels.
        let v = row(13.5).unwrap();
        assert!((v - 5.5).abs() < 1e-3, "{v}");
        // Over the shed's roof: no ground there.
        assert_eq!(row(10.5), None);
    }

    #[test]
    fn a_drainpipe_runs_down_to_the_ground_and_no_further() {
        // Seen on rows 30-34 only; the wall below runs on underground to row 0, unobserved.
        let (w, h) = (10u32, 50u32);
        let c = Chart::flat_wall(w, h);
        let (pr, e) = pipe_in_column_3(w, c.len(), 30..35);
        let mut lay = seen_layers(w, h, pr, e);
        unobserve(&mut lay, w, 0..30);
        unobserve(&mut lay, w, 35..50);
        let p = ReliefParams {
            min_texels: 3,
            ..Default::default()
        };
        let votes = measured_out("drainpipe", &[(3.5, 32.0)]);
        let votes: Vec<&RegionVote> = votes.iter().collect();
        let at = |ground: &dyn Fn(f64) -> Option<f64>| {
            let r = instances(0, &c, &lay, &votes, false, 1e12, ground, &p);
            assert_eq!(r.len(), 1, "{r:?}");
            r[0].rect
        };
        let r = at(&|u| (u > 3.0 && u < 4.0).then_some(12.4));
        assert!(r[1] == 12.4 && r[3] == 50.0, "{r:?}");
        // No terrain found under it: down to the wall's foot.
        let r = at(&|_| None);
        assert!(r[1] == 0.0 && r[3] == 50.0, "{r:?}");
    }

    #[test]
    fn a_drainpipe_takes_its_classs_width_about_the_evidence_centroid() {
        // Evidence over columns 0..3 centred on column 1.5 (texel centres k + 0.5), two rows.
        let w = 6;
        let rows = |row: [f32; 6]| -> Vec<f32> { row.iter().chain(row.iter()).copied().collect() };
        let evidence = rows([0.5, 1.0, 1.0, 0.5, 0.0, 0.0]);
        let r = within_width([0.0, 0.0, 4.0, 2.0], (0.05, 0.15), 0.1, w, &evidence);
        assert!((r[2] - r[0] - 1.5).abs() < 1e-9, "{r:?}");
        assert!((r[0] + r[2] - 4.0).abs() < 1e-9, "{r:?}");
        assert_eq!((r[1], r[3]), (0.0, 2.0));
        // A rectangle that cuts the evidence on one side (columns 1-2 of a peak on column 2):
        // the centroid is the whole peak's, not pulled toward the cut (2.27 within the cut).
        let peak = rows([0.0, 0.3, 1.0, 0.3, 0.0, 0.0]);
        let r = within_width([1.6, 0.0, 2.4, 2.0], (0.05, 0.15), 0.1, w, &peak);
        assert!(
            (r[0] - 2.1).abs() < 1e-9 && (r[2] - 2.9).abs() < 1e-9,
            "{r:?}"
        );
        // The wall's own level under the peak does not pull it toward the window's middle
        // (1.83 with it).
        let raised = rows([0.7, 1.2, 0.7, 0.2, 0.2, 0.2]);
        let r = within_width([0.0, 0.0, 3.0, 2.0], (0.05, 0.15), 0.1, w, &raised);
        assert!((r[0] + r[2] - 3.0).abs() < 1e-9, "{r:?}");
        // Narrower than the class: widened about the centroid, and kept on the chart where that
        // would reach past its end.
        let edge = rows([1.0, 0.3, 0.0, 0.0, 0.0, 0.0]);
        let centre = (0.5 + 0.3 * 1.5) / 1.3; // 0.3 as f32: to 1e-6
        let r = within_width([0.0, 0.0, 0.2, 2.0], (0.05, 0.15), 0.1, w, &edge);
        assert!(
            (r[0] - (centre - 0.25)).abs() < 1e-6 && (r[2] - (centre + 0.25)).abs() < 1e-6,
            "{r:?} {centre}"
        );
        let r = within_width([0.0, 0.0, 0.2, 2.0], (0.15, 0.3), 0.1, w, &edge);
        assert!(r[0] == 0.0 && (r[2] - 1.5).abs() < 1e-9, "{r:?}");
    }
}
