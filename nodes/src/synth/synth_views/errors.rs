//! The errors of the model outputs [`super::SynthViews`] hands on: what a monocular
//! depth model, a normal estimator and an instance segmenter get wrong on real street views,
//! applied to the buffers rendered from the truth. Every draw is a hash of the view's seed and
//! what it draws for (a pixel, a lattice node, an instance), so a view's errors are the same at
//! any thread count. The sources of the models and their default parameters are listed in the
//! README ("The synthetic sensors").

use std::collections::{BTreeMap, HashMap};

use crate::rng::{gaussian, mix, unit};

/// A smooth random field over a `w` x `h` image: standard normal values on a lattice of nodes
/// `cell` pixels apart, bilinearly interpolated (value noise). Its standard deviation is about
/// 0.6-1 between nodes and 1 on them; its correlation length is about `cell`.
pub struct ValueNoise {
    nx: usize,
    cell: f64,
    nodes: Vec<f64>,
}

impl ValueNoise {
    /// The field of `seed` over a `w` x `h` image, nodes every `cell` pixels.
    pub fn new(seed: u64, w: u32, h: u32, cell: f64) -> ValueNoise {
        let nx = (w as f64 / cell).ceil() as usize + 2;
        let ny = (h as f64 / cell).ceil() as usize + 2;
        let nodes = (0..nx * ny)
            .map(|k| gaussian(mix(seed ^ mix(k as u64 ^ 0x7A1E))))
            .collect();
        ValueNoise { nx, cell, nodes }
    }

    /// The field at pixel centre (u, v).
    pub fn at(&self, u: f64, v: f64) -> f64 {
        let (x, y) = (u / self.cell, v / self.cell);
        let (i, j) = (x.floor().max(0.0) as usize, y.floor().max(0.0) as usize);
        let (fx, fy) = (x - i as f64, y - j as f64);
        let n = |a: usize, b: usize| self.nodes[(b * self.nx + a).min(self.nodes.len() - 1)];
        let top = n(i, j) * (1.0 - fx) + n(i + 1, j) * fx;
        let bottom = n(i, j + 1) * (1.0 - fx) + n(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// A smooth, low-frequency field over the image: the 2D cosine terms of orders (a, b) with
/// 1 <= a + b <= 2, each with a standard normal weight, scaled so its RMS over the image is
/// about 1. The warp of a monocular depth model's output is of this kind: a few percent, bending
/// the whole image (a ground plane that tilts, a far side that is compressed).
pub struct LowOrderWarp {
    terms: Vec<(f64, f64, f64)>,
    w: f64,
    h: f64,
    /// Per pixel column, then per term, the term's cosine along the image's width at the
    /// column's centre; `rows` likewise down its height. A view's depth asks the warp of every
    /// pixel: ten cosines a pixel were a sixth of the views' time.
    columns: Vec<f64>,
    rows: Vec<f64>,
}

impl LowOrderWarp {
    /// The warp of `seed` over a `w` x `h` image.
    pub fn new(seed: u64, w: u32, h: u32) -> LowOrderWarp {
        let orders = [(1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (2.0, 0.0), (0.0, 2.0)];
        // Each term's mean square over the image: 1/2 per non-zero order.
        let power: f64 = orders
            .iter()
            .map(|&(a, b)| {
                let f = |o: f64| if o > 0.0 { 0.5 } else { 1.0 };
                f(a) * f(b)
            })
            .sum();
        let norm = 1.0 / power.sqrt();
        let terms: Vec<(f64, f64, f64)> = orders
            .iter()
            .enumerate()
            .map(|(k, &(a, b))| (a, b, norm * gaussian(mix(seed ^ mix(k as u64 ^ 0xC05)))))
            .collect();
        let (wf, hf) = (w as f64, h as f64);
        let pi = std::f64::consts::PI;
        let table = |n: u32, size: f64, order: fn(&(f64, f64, f64)) -> f64| -> Vec<f64> {
            (0..n)
                .flat_map(|i| {
                    let x = i as f64 + 0.5;
                    terms
                        .iter()
                        .map(move |t| (pi * order(t) * x / size).cos())
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let columns = table(w, wf, |t| t.0);
        let rows = table(h, hf, |t| t.1);
        LowOrderWarp {
            terms,
            w: wf,
            h: hf,
            columns,
            rows,
        }
    }

    /// [`LowOrderWarp::at`] the centre of pixel (`col`, `row`), the same number from the
    /// tables.
    pub fn at_pixel(&self, col: u32, row: u32) -> f64 {
        let n = self.terms.len();
        let (cu, cv) = (
            &self.columns[col as usize * n..][..n],
            &self.rows[row as usize * n..][..n],
        );
        self.terms
            .iter()
            .zip(cu.iter().zip(cv))
            .map(|(&(_, _, c), (&x, &y))| c * x * y)
            .sum()
    }

    /// The warp at pixel centre (u, v).
    pub fn at(&self, u: f64, v: f64) -> f64 {
        let pi = std::f64::consts::PI;
        self.terms
            .iter()
            .map(|&(a, b, c)| c * (pi * a * u / self.w).cos() * (pi * b * v / self.h).cos())
            .sum()
    }
}

/// The pixels within `r` pixels (square window) of a pixel where `edge(i, j)` holds between
/// 4-neighbours `i` and `j`.
fn near_edges(w: usize, h: usize, r: usize, edge: &dyn Fn(usize, usize) -> bool) -> Vec<bool> {
    let mut at_edge = vec![false; w * h];
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            if (u + 1 < w && edge(i, i + 1)) || (v + 1 < h && edge(i, i + w)) {
                at_edge[i] = true;
                if u + 1 < w {
                    at_edge[i + 1] = true;
                }
                if v + 1 < h {
                    at_edge[i + w] = true;
                }
            }
        }
    }
    if r == 0 {
        return at_edge;
    }
    let mut out = vec![false; w * h];
    for v in 0..h {
        for u in 0..w {
            if !at_edge[v * w + u] {
                continue;
            }
            for y in v.saturating_sub(r)..(v + r + 1).min(h) {
                for x in u.saturating_sub(r)..(u + r + 1).min(w) {
                    out[y * w + x] = true;
                }
            }
        }
    }
    out
}

/// Whether two depths are on either side of a discontinuity: one of them sky, or more than 10 %
/// apart.
fn depth_step(a: f32, b: f32) -> bool {
    if a.is_finite() != b.is_finite() {
        return a.is_finite() || b.is_finite();
    }
    a.is_finite() && (a - b).abs() > 0.1 * a.min(b)
}

/// The monocular depth model's errors (see [`DepthErrors`]).
#[derive(Clone, Copy, Debug)]
pub struct DepthErrors {
    /// Relative per-pixel noise at near range.
    pub noise: f64,
    /// The image's affine bias: reported = scale x depth + offset.
    pub scale: f64,
    /// See `scale`, metres.
    pub offset_m: f64,
    /// RMS of the smooth relative warp at near range.
    pub warp: f64,
    /// Relative errors (noise and warp) grow as 1 + depth / `far_m`; 0 turns the growth off.
    pub far_m: f64,
    /// Radius in pixels over which depths mix across a discontinuity.
    pub edge_px: u32,
}

/// `depth` (true z-depth, infinite for sky) as the depth model reports it: depths mixed across
/// discontinuities within `edge_px`, a smooth warp and per-pixel noise, both growing with depth,
/// then the image's affine bias. Sky stays infinite.
pub fn degrade_depth(depth: &[f32], w: u32, h: u32, e: &DepthErrors, seed: u64) -> Vec<f32> {
    let (wu, hu) = (w as usize, h as usize);
    let r = e.edge_px as usize;
    let bleed = near_edges(wu, hu, r, &|i, j| depth_step(depth[i], depth[j]));
    let warp = LowOrderWarp::new(mix(seed ^ 0xDE97), w, h);
    let mut out = vec![f32::INFINITY; depth.len()];
    for v in 0..hu {
        for u in 0..wu {
            let i = v * wu + u;
            if !depth[i].is_finite() {
                continue;
            }
            // Edge bleeding: the window's mean of the finite depths (the model's receptive field
            // straddles the edge, so it reports depths in between: "flying pixels").
            let d = if r > 0 && bleed[i] {
                let (mut s, mut n) = (0.0f64, 0.0f64);
                for y in v.saturating_sub(r)..(v + r + 1).min(hu) {
                    for x in u.saturating_sub(r)..(u + r + 1).min(wu) {
                        let q = depth[y * wu + x];
                        if q.is_finite() {
                            s += q as f64;
                            n += 1.0;
                        }
                    }
                }
                s / n
            } else {
                depth[i] as f64
            };
            let grow = if e.far_m > 0.0 {
                1.0 + d / e.far_m
            } else {
                1.0
            };
            let rel = grow
                * (e.warp * warp.at_pixel(u as u32, v as u32)
                    + e.noise * gaussian(mix(seed ^ (i as u64).wrapping_mul(0x9E37))));
            let reported = d * (1.0 + rel).max(0.05) * e.scale + e.offset_m;
            out[i] = reported.max(0.01) as f32;
        }
    }
    out
}

/// The normal estimator's errors: normals averaged across edges within `edge_px` (a network's
/// output is smooth where the truth steps), then turned by an angle whose median is
/// `median_deg`, half of its variance smooth over the image (a model errs on whole regions) and
/// half per pixel. Zero normals (sky) stay zero. `depth` marks the depth edges, which are normal
/// edges too.
pub fn degrade_normals(
    normal: &[[f32; 3]],
    depth: &[f32],
    w: u32,
    h: u32,
    median_deg: f64,
    edge_px: u32,
    seed: u64,
) -> Vec<[f32; 3]> {
    let (wu, hu) = (w as usize, h as usize);
    let r = edge_px as usize;
    let is_set = |n: [f32; 3]| n != [0.0; 3];
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let blur = near_edges(wu, hu, r, &|i, j| {
        (is_set(normal[i]) && is_set(normal[j]) && dot(normal[i], normal[j]) < 0.866)
            || depth_step(depth[i], depth[j])
    });
    // A tangent offset of standard deviation s per axis turns the normal by a Rayleigh angle,
    // whose median is s sqrt(2 ln 2).
    let s = median_deg.to_radians() / (2.0 * std::f64::consts::LN_2).sqrt();
    let smooth = [
        ValueNoise::new(mix(seed ^ 0xA0), w, h, 24.0),
        ValueNoise::new(mix(seed ^ 0xA1), w, h, 24.0),
    ];
    let half = std::f64::consts::FRAC_1_SQRT_2;
    let mut out = vec![[0f32; 3]; normal.len()];
    for v in 0..hu {
        for u in 0..wu {
            let i = v * wu + u;
            if !is_set(normal[i]) {
                continue;
            }
            let mut n = normal[i].map(|c| c as f64);
            if r > 0 && blur[i] {
                let mut acc = [0.0f64; 3];
                for y in v.saturating_sub(r)..(v + r + 1).min(hu) {
                    for x in u.saturating_sub(r)..(u + r + 1).min(wu) {
                        let q = normal[y * wu + x];
                        if is_set(q) {
                            for k in 0..3 {
                                acc[k] += q[k] as f64;
                            }
                        }
                    }
                }
                let len = (acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]).sqrt();
                if len > 1e-6 {
                    n = acc.map(|c| c / len);
                }
            }
            if s > 0.0 {
                // Two tangent directions of n.
                let a = if n[0].abs() < 0.9 {
                    [1.0, 0.0, 0.0]
                } else {
                    [0.0, 1.0, 0.0]
                };
                let t1 = normalize(cross(n, a));
                let t2 = cross(n, t1);
                let (uc, vc) = (u as f64 + 0.5, v as f64 + 0.5);
                let hp = mix(seed ^ (i as u64).wrapping_mul(0xB5AD_4ECE_DA1C_E2A9));
                let o1 = s * (half * smooth[0].at(uc, vc) + half * gaussian(hp));
                let o2 = s * (half * smooth[1].at(uc, vc) + half * gaussian(mix(hp ^ 1)));
                let angle = o1.hypot(o2);
                if angle > 1e-9 {
                    let dir: [f64; 3] = std::array::from_fn(|k| (o1 * t1[k] + o2 * t2[k]) / angle);
                    let (sn, cs) = angle.min(std::f64::consts::FRAC_PI_2).sin_cos();
                    n = std::array::from_fn(|k| cs * n[k] + sn * dir[k]);
                }
            }
            out[i] = n.map(|c| c as f32);
        }
    }
    out
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt().max(1e-12);
    a.map(|c| c / n)
}

/// The instance segmenter's errors beyond missed instances (which the renderer applies).
#[derive(Clone, Copy, Debug)]
pub struct MaskErrors {
    /// Standard deviation of the smooth displacement of every contour, pixels.
    pub boundary_px: f64,
    /// Spurious instances per true instance of a feature class.
    pub spurious: f64,
    /// Probability that two adjacent instances of one class on one object come out as one.
    pub merge: f64,
    /// Probability that an instance is reported as a confusable class.
    pub confusion: f64,
}

/// The class an instance of `class` is confused with (the commonest confusions of façade
/// parsers: windows and doors with each other, a balcony's glazing or a drainpipe taken for a
/// window; poles and signs, cars and shelters). None for a class with no confusable other.
fn confused_with(class: &str) -> Option<&'static str> {
    Some(match class {
        "window" => "door",
        "door" => "window",
        "balcony" | "drainpipe" => "window",
        "pole" => "sign",
        "sign" => "pole",
        "car" => "shelter",
        "shelter" => "car",
        _ => return None,
    })
}

/// Classes an instance model treats as things (countable features) on a façade, as opposed to
/// the stuff they sit on (wall, roof).
fn is_thing(class: &str) -> bool {
    !matches!(class, "wall" | "roof")
}

/// One instance map's errors, in place: merged neighbours, class confusion, spurious instances
/// and the contours displaced. `object_of` gives each instance's object (merges are within one
/// object) and `host_of` the instance a merged pair's gap is taken from (its wall); spurious
/// instances are painted over pixels where `host(id)` holds, with class `spurious_class`.
#[allow(clippy::too_many_arguments)]
pub fn degrade_instances(
    ids: &mut [u16],
    classes: &mut BTreeMap<u16, String>,
    w: u32,
    h: u32,
    object_of: &HashMap<u16, usize>,
    host_of: &HashMap<usize, u16>,
    host: &dyn Fn(u16) -> bool,
    spurious_class: &str,
    e: &MaskErrors,
    seed: u64,
) {
    let (wu, hu) = (w as usize, h as usize);
    // Bounding boxes of the instances present.
    let mut bbox: BTreeMap<u16, [usize; 4]> = BTreeMap::new();
    for v in 0..hu {
        for u in 0..wu {
            let id = ids[v * wu + u];
            if id == 0 {
                continue;
            }
            let b = bbox.entry(id).or_insert([u, v, u, v]);
            *b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
        }
    }
    // Merged neighbours: pairs of one class on one object whose boxes overlap along one axis and
    // are at most GAP pixels apart along the other.
    const GAP: usize = 4;
    if e.merge > 0.0 {
        let things: Vec<(u16, [usize; 4])> = bbox
            .iter()
            .filter(|(id, _)| classes.get(id).is_some_and(|c| is_thing(c)))
            .map(|(&id, &b)| (id, b))
            .collect();
        let mut into: BTreeMap<u16, u16> = BTreeMap::new();
        let root = |into: &BTreeMap<u16, u16>, mut id: u16| {
            while let Some(&n) = into.get(&id) {
                id = n;
            }
            id
        };
        let mut fills: Vec<([usize; 4], u16, u16)> = Vec::new();
        for (k, &(a, ba)) in things.iter().enumerate() {
            for &(b, bb) in &things[k + 1..] {
                if classes.get(&a) != classes.get(&b) || object_of.get(&a) != object_of.get(&b) {
                    continue;
                }
                let overlap_x = ba[0] <= bb[2] && bb[0] <= ba[2];
                let overlap_y = ba[1] <= bb[3] && bb[1] <= ba[3];
                let gap_x = bb[0].saturating_sub(ba[2]).max(ba[0].saturating_sub(bb[2]));
                let gap_y = bb[1].saturating_sub(ba[3]).max(ba[1].saturating_sub(bb[3]));
                let adjacent = (overlap_y && gap_x <= GAP) || (overlap_x && gap_y <= GAP);
                if !adjacent
                    || unit(mix(seed ^ mix(((a as u64) << 16 | b as u64) ^ 0x3E7))) >= e.merge
                {
                    continue;
                }
                let (ra, rb) = (root(&into, a), root(&into, b));
                if ra == rb {
                    continue;
                }
                into.insert(rb, ra);
                // The gap between them, taken from the wall they sit on.
                let gap = if overlap_y {
                    [
                        ba[2].min(bb[2]) + 1,
                        ba[1].max(bb[1]),
                        ba[0].max(bb[0]),
                        ba[3].min(bb[3]),
                    ]
                } else {
                    [
                        ba[0].max(bb[0]),
                        ba[3].min(bb[3]) + 1,
                        ba[2].min(bb[2]),
                        ba[1].max(bb[1]),
                    ]
                };
                let wall = object_of
                    .get(&a)
                    .and_then(|o| host_of.get(o))
                    .copied()
                    .unwrap_or(0);
                fills.push((gap, a, wall));
            }
        }
        if !into.is_empty() {
            for id in ids.iter_mut() {
                if *id != 0 && into.contains_key(id) {
                    *id = root(&into, *id);
                }
            }
            for (g, a, wall) in fills {
                let ra = root(&into, a);
                for v in g[1]..=g[3].min(hu - 1) {
                    for u in g[0]..=g[2].min(wu - 1) {
                        let i = v * wu + u;
                        if wall != 0 && ids[i] == wall {
                            ids[i] = ra;
                        }
                    }
                }
            }
            for gone in into.keys() {
                classes.remove(gone);
            }
        }
    }
    // Class confusion, per instance.
    if e.confusion > 0.0 {
        for (id, class) in classes.iter_mut() {
            if unit(mix(seed ^ mix(*id as u64 ^ 0xC1A5))) < e.confusion {
                if let Some(other) = confused_with(class) {
                    *class = other.to_owned();
                }
            }
        }
    }
    // Spurious instances: a box of a feature's size on a host pixel, painted over the host.
    if e.spurious > 0.0 {
        let n_things = classes.values().filter(|c| is_thing(c)).count();
        let expected = e.spurious * n_things.max(1) as f64;
        let mut n = expected.floor() as usize;
        if unit(mix(seed ^ 0x5B0)) < expected - expected.floor() {
            n += 1;
        }
        let mut next = classes.keys().max().copied().unwrap_or(0);
        for k in 0..n as u64 {
            let hk = mix(seed ^ mix(k ^ 0x5B1));
            // Up to 16 tries for a host pixel.
            let at = (0..16u64).find_map(|t| {
                let ht = mix(hk ^ t);
                let i = (unit(ht) * (wu * hu) as f64) as usize;
                (ids[i] != 0 && host(ids[i])).then_some(i)
            });
            let Some(i) = at else { continue };
            if next == u16::MAX {
                break;
            }
            next += 1;
            let (u0, v0) = (i % wu, i / wu);
            let bw = 4 + (unit(mix(hk ^ 2)) * 10.0) as usize;
            let bh = 6 + (unit(mix(hk ^ 3)) * 12.0) as usize;
            let mut painted = false;
            for v in v0.saturating_sub(bh / 2)..(v0 + bh / 2 + 1).min(hu) {
                for u in u0.saturating_sub(bw / 2)..(u0 + bw / 2 + 1).min(wu) {
                    let j = v * wu + u;
                    if ids[j] != 0 && host(ids[j]) {
                        ids[j] = next;
                        painted = true;
                    }
                }
            }
            if painted {
                classes.insert(next, spurious_class.to_owned());
            }
        }
    }
    // Contours displaced: each pixel takes the label a smooth random displacement away.
    if e.boundary_px > 0.0 {
        let dx = ValueNoise::new(mix(seed ^ 0xB0D), w, h, 8.0);
        let dy = ValueNoise::new(mix(seed ^ 0xB0E), w, h, 8.0);
        let src = ids.to_vec();
        for v in 0..hu {
            for u in 0..wu {
                let (uc, vc) = (u as f64 + 0.5, v as f64 + 0.5);
                let x = (u as f64 + e.boundary_px * dx.at(uc, vc)).round();
                let y = (v as f64 + e.boundary_px * dy.at(uc, vc)).round();
                let x = x.clamp(0.0, (wu - 1) as f64) as usize;
                let y = y.clamp(0.0, (hu - 1) as f64) as usize;
                ids[v * wu + u] = src[y * wu + x];
            }
        }
    }
    // Classes of instances left with no pixel go.
    let present: std::collections::BTreeSet<u16> = ids.iter().copied().collect();
    classes.retain(|id, _| present.contains(id));
}

#[cfg(test)]
mod tests {
    /// The warp from its tables is the warp from its formula, bit for bit, at every pixel.
    #[test]
    fn the_warp_tables_give_the_formulas_numbers() {
        let warp = super::LowOrderWarp::new(17, 37, 23);
        for row in 0..23 {
            for col in 0..37 {
                let want = warp.at(col as f64 + 0.5, row as f64 + 0.5);
                assert_eq!(
                    warp.at_pixel(col, row).to_bits(),
                    want.to_bits(),
                    "({col}, {row})"
                );
            }
        }
    }

    use super::*;

    #[test]
    fn depth_errors_are_seeded_and_bounded() {
        let (w, h) = (64u32, 48u32);
        // A wall at 10 m with a window recessed to 10.3 and sky above row 10.
        let depth: Vec<f32> = (0..w * h)
            .map(|i| if i / w < 10 { f32::INFINITY } else { 10.0 })
            .collect();
        let e = DepthErrors {
            noise: 0.02,
            scale: 1.0,
            offset_m: 0.0,
            warp: 0.04,
            far_m: 40.0,
            edge_px: 2,
        };
        let a = degrade_depth(&depth, w, h, &e, 7);
        let b = degrade_depth(&depth, w, h, &e, 7);
        assert_eq!(a, b);
        assert!(a[..(10 * w) as usize].iter().all(|d| d.is_infinite()));
        let finite: Vec<f64> = a
            .iter()
            .filter(|d| d.is_finite())
            .map(|&d| d as f64)
            .collect();
        let rel = (finite.iter().map(|d| (d / 10.0 - 1.0).powi(2)).sum::<f64>()
            / finite.len() as f64)
            .sqrt();
        // Noise and warp each grow by 1.25 at 10 m: RMS about 1.25 sqrt(0.02² + 0.04²) = 0.056.
        assert!(rel > 0.02 && rel < 0.12, "{rel}");
    }

    #[test]
    fn depth_bleeds_across_a_step() {
        let (w, h) = (20u32, 4u32);
        let depth: Vec<f32> = (0..w * h)
            .map(|i| if i % w < 10 { 5.0 } else { 20.0 })
            .collect();
        let e = DepthErrors {
            noise: 0.0,
            scale: 1.0,
            offset_m: 0.0,
            warp: 0.0,
            far_m: 0.0,
            edge_px: 2,
        };
        let out = degrade_depth(&depth, w, h, &e, 1);
        // Next to the step the depth lies between the two sides; far from it, it is exact.
        assert!(out[9] > 5.5 && out[9] < 19.5, "{}", out[9]);
        assert!(out[10] > 5.5 && out[10] < 19.5, "{}", out[10]);
        assert_eq!(out[0], 5.0);
        assert_eq!(out[19], 20.0);
    }

    #[test]
    fn normal_noise_has_the_median_asked() {
        let (w, h) = (120u32, 90u32);
        let normal = vec![[0.0f32, 0.0, -1.0]; (w * h) as usize];
        let depth = vec![10.0f32; (w * h) as usize];
        let out = degrade_normals(&normal, &depth, w, h, 12.0, 2, 3);
        let mut angles: Vec<f64> = out
            .iter()
            .map(|n| (-(n[2] as f64)).clamp(-1.0, 1.0).acos().to_degrees())
            .collect();
        angles.sort_by(f64::total_cmp);
        let median = angles[angles.len() / 2];
        assert!(median > 8.0 && median < 16.0, "{median}");
    }

    #[test]
    fn adjacent_windows_merge_and_contours_move() {
        let (w, h) = (40u32, 20u32);
        // A wall (id 1) with two windows (ids 2, 3) two pixels apart.
        let mut ids: Vec<u16> = (0..w * h)
            .map(|i| {
                let (u, v) = (i % w, i / w);
                if (5..15).contains(&v) && (10..18).contains(&u) {
                    2
                } else if (5..15).contains(&v) && (20..28).contains(&u) {
                    3
                } else {
                    1
                }
            })
            .collect();
        let mut classes: BTreeMap<u16, String> = [(1, "wall"), (2, "window"), (3, "window")]
            .into_iter()
            .map(|(k, c)| (k, c.to_owned()))
            .collect();
        let object_of: HashMap<u16, usize> = [(1, 0), (2, 0), (3, 0)].into_iter().collect();
        let host_of: HashMap<usize, u16> = [(0, 1)].into_iter().collect();
        let e = MaskErrors {
            boundary_px: 0.0,
            spurious: 0.0,
            merge: 1.0,
            confusion: 0.0,
        };
        degrade_instances(
            &mut ids,
            &mut classes,
            w,
            h,
            &object_of,
            &host_of,
            &|id| id == 1,
            "window",
            &e,
            5,
        );
        assert_eq!(classes.len(), 2, "{classes:?}");
        // The pier between them is part of the merged window.
        assert_eq!(ids[(10 * w + 19) as usize], 2);
        let before = ids.clone();
        let e = MaskErrors {
            boundary_px: 1.5,
            spurious: 0.0,
            merge: 0.0,
            confusion: 0.0,
        };
        degrade_instances(
            &mut ids,
            &mut classes,
            w,
            h,
            &object_of,
            &host_of,
            &|id| id == 1,
            "window",
            &e,
            5,
        );
        let changed = ids.iter().zip(&before).filter(|(a, b)| a != b).count();
        assert!(changed > 0 && changed < 200, "{changed}");
    }
}
