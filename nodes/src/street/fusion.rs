//! Exposure-weighted multi-view fusion (paper Sec. 4.2.2, eq. (2)-(3)): rays from street-view
//! pixels hit building charts, and each hit splats a Gaussian kernel into the chart's texel grid,
//! weighted by the projection Jacobian. Relief (eq. (4)) and materials (eq. (5)) call the same
//! operator with their own per-pixel votes and exponent.

use rayon::prelude::*;

use crate::artifact::{
    Chart, ChartLayers, ChartSet, FusionStats, PodVec, Scene, TexelLayers, View, Views,
};
use crate::geom::raycast::SceneRays;
use crate::stage::{Progress, StageError};

/// What one pixel says about the surface its ray hits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Vote {
    /// A class (an index into the fusion's class table): adds to W_exp and to that class's votes.
    Class(u16),
    /// Seen, but no class (the ignore label): adds to W_exp only.
    Seen,
    /// Not a view of the surface (the pixel belongs to a clutter instance in front of it): adds
    /// nothing, so foreground objects neither vote nor count as exposure (occlusion masking).
    Masked,
}

/// The fusion's knobs, named as in the paper.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusionParams {
    /// Stage exponent gamma_a on the Jacobian: high for relief, low for materials.
    pub gamma: f64,
    /// Views more oblique than theta_max (degrees from the surface normal) are gated out.
    pub theta_max_deg: f64,
    /// Kernel standard deviation sigma, texels; 0 deposits at the hit only (bilinearly).
    pub sigma_texels: f64,
    /// One ray every `stride` pixels each way; each stands for stride² pixels.
    pub stride: u32,
}

impl FusionParams {
    /// The knobs' ranges, as `(field, expected)` for the stage's `ParamError`.
    pub fn check(&self) -> Result<(), (&'static str, &'static str)> {
        if !(self.gamma >= 0.0 && self.gamma <= 8.0) {
            return Err(("gamma", "expected an exponent in [0, 8]"));
        }
        if !(self.theta_max_deg > 0.0 && self.theta_max_deg <= 90.0) {
            return Err(("theta_max_deg", "expected an angle in (0, 90] degrees"));
        }
        if !(self.sigma_texels >= 0.0 && self.sigma_texels <= 16.0) {
            return Err(("sigma_texels", "expected a kernel width in [0, 16] texels"));
        }
        if !(1..=64).contains(&self.stride) {
            return Err(("stride", "expected a stride of 1 to 64 pixels"));
        }
        Ok(())
    }
}

/// The projection Jacobian of eq. (2): J = cos(theta) (f / t)², proportional to how many pixels
/// of a view fall on a unit of surface area at the hit (`f` focal length in pixels, `t` hit
/// distance in metres). Zero for views more oblique than `theta_max` (`cos_theta_max` its cosine)
/// and for back faces.
pub fn projection_jacobian(cos_theta: f64, f: f64, t: f64, cos_theta_max: f64) -> f64 {
    if cos_theta <= 0.0 || cos_theta < cos_theta_max {
        0.0
    } else {
        cos_theta * (f / t) * (f / t)
    }
}

/// A normalised, truncated (3 sigma) Gaussian: the discrete K_sigma. Sums to 1.
pub fn gaussian_kernel(sigma: f64) -> Vec<f64> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (3.0 * sigma).ceil() as i64;
    let k: Vec<f64> = (-r..=r)
        .map(|x| (-(x * x) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.into_iter().map(|v| v / s).collect()
}

/// Eq. (2)-(3), exposure-weighted projection: for every pixel p of every view i (every
/// `stride`-th each way) a ray from the camera finds its closest hit in `scene`; hits on a chart
/// within the angle gate contribute
///
/// ω_ipq = J_ip^γ K_σ(q − u_ip),  W_exp(q) = Σ_ip ω_ipq,
///
/// and votes E_c(q) = Σ_ip ω_ipq 1[vote(i, p) = c] per class c (`vote` takes what `prepare` made of
/// view i, the view and the pixel's row-major index). The kernel is applied as one
/// separable convolution of the per-texel deposits after all views, which equals splatting each
/// hit's kernel at its texel-centre-bilinear position (exact in mass: a splat sums to its weight
/// away from the chart's border; texels off the surface are zeroed). `hits` counts the rays
/// whose hit lands in each texel.
///
/// Deterministic at any thread count: each view is reduced in pixel order on its own, and views
/// are merged in order.
///
/// # Units
/// Weights are in pixels² per m² raised to γ (times stride², so strides compare).
#[allow(clippy::too_many_arguments)]
pub fn fuse_views<P: Send>(
    scene: &Scene,
    rays: &SceneRays,
    charts: &ChartSet,
    views: Views,
    classes: Vec<String>,
    prepare: &(dyn Fn(usize, &View) -> P + Sync),
    vote: &(dyn Fn(&P, &View, usize) -> Vote + Sync),
    p: &FusionParams,
    progress: &dyn Progress,
) -> Result<TexelLayers, StageError> {
    let (layers, stats) = fuse_views_each(
        scene,
        rays,
        charts,
        views,
        prepare,
        vote,
        &|_, _| 0.0,
        p,
        progress,
        // A chart no pixel reached is stored as layers of zeros (no votes).
        |_, c, l| l.unwrap_or_else(|| ChartDeposits::new(c).into_layers(c, &[1.0])),
    )?;
    Ok(TexelLayers {
        classes,
        charts: layers,
        frames: charts.charts.iter().map(Chart::frame).collect(),
        stats,
    })
}

/// [`fuse_views`] with each pixel's hit moved onto the chart's plane offset by `displace(what
/// prepare made of the view, pixel)` metres along its outward normal (0: the chart itself): a
/// pixel that sees a protrusion standing `h` in front of the wall is deposited where the ray
/// crosses the plane at `h`, then projected along the normal onto the chart, so the feature
/// lands where it stands rather than where its parallax throws it (façade relief, eq. (4)). The
/// weight J is the one at the wall hit. Each chart's layers are handed to `finish` (its index,
/// the chart, the layers) as soon as they are blurred, charts in parallel: a caller that reduces
/// the layers to something smaller never holds every chart's layers at once (on a 1 km² site
/// they are 1.5 GB). A chart no pixel reached gets `None` rather than layers of zeros (most of
/// the charts of a street-level site: roofs, backs, courtyards). Returns what `finish` made, in
/// chart order, and the counts.
///
/// Views are read a batch at a time, and `prepare` runs once per view as it is read (a view's
/// refined labels, say): memory holds two batches' views, preparations and deposits, whatever
/// the number of views.
#[allow(clippy::too_many_arguments)]
pub fn fuse_views_each<P: Send, R: Send>(
    scene: &Scene,
    rays: &SceneRays,
    charts: &ChartSet,
    views: Views,
    prepare: &(dyn Fn(usize, &View) -> P + Sync),
    vote: &(dyn Fn(&P, &View, usize) -> Vote + Sync),
    displace: &(dyn Fn(&P, usize) -> f64 + Sync),
    p: &FusionParams,
    progress: &dyn Progress,
    finish: impl Fn(usize, &Chart, Option<ChartLayers>) -> R + Sync,
) -> Result<(Vec<R>, FusionStats), StageError> {
    let lookup = ChartLookup::new(scene, charts);
    let mut per_chart: Vec<ChartDeposits> = charts.charts.iter().map(ChartDeposits::new).collect();
    let mut stats = FusionStats::default();
    progress.set_total(views.len() as u64);
    // Views are read a batch at a time: memory holds two batches' views and deposits, whatever
    // the number of views.
    let chunk = (rayon::current_num_threads() * 2).max(1);
    let compute = |batch: std::ops::Range<usize>| -> Result<Vec<ViewDeposits>, StageError> {
        batch
            .into_par_iter()
            .map(|k| {
                let v = views.load(k)?;
                let pre = prepare(k, &v);
                let d = view_deposits(
                    &v,
                    rays,
                    charts,
                    &lookup,
                    &|px| vote(&pre, &v, px),
                    &|px| displace(&pre, px),
                    p,
                );
                progress.advance(1);
                Ok(d)
            })
            .collect()
    };
    // Each batch is merged in view order while the next is computed: the merge is serial, and
    // would otherwise leave every other thread idle.
    let mut pending: Vec<ViewDeposits> = Vec::new();
    for start in (0..views.len()).step_by(chunk) {
        let ((), next) = rayon::join(
            || {
                for d in pending.drain(..) {
                    d.merge_into(&mut per_chart, &mut stats);
                }
            },
            || compute(start..(start + chunk).min(views.len())),
        );
        pending = next?;
    }
    for d in pending {
        d.merge_into(&mut per_chart, &mut stats);
    }
    let kernel = gaussian_kernel(p.sigma_texels);
    let out = charts
        .charts
        .par_iter()
        .with_max_len(1)
        .zip(per_chart)
        .enumerate()
        .map(|(ci, (c, d))| {
            let layers = (!d.untouched()).then(|| d.into_layers(c, &kernel));
            finish(ci, c, layers)
        })
        .collect();
    Ok((out, stats))
}

/// Object and triangle -> chart index.
pub(crate) struct ChartLookup {
    of: Vec<Vec<u32>>,
}

impl ChartLookup {
    pub(crate) fn new(scene: &Scene, charts: &ChartSet) -> ChartLookup {
        let mut of: Vec<Vec<u32>> = scene
            .objects
            .iter()
            .map(|o| vec![u32::MAX; o.mesh.triangles.len()])
            .collect();
        for (k, c) in charts.charts.iter().enumerate() {
            if let Some(tris) = of.get_mut(c.object as usize) {
                for &t in c.triangles.iter() {
                    if let Some(slot) = tris.get_mut(t as usize) {
                        *slot = k as u32;
                    }
                }
            }
        }
        ChartLookup { of }
    }

    pub(crate) fn chart(&self, object: usize, triangle: usize) -> Option<u32> {
        let c = *self.of.get(object)?.get(triangle)?;
        (c != u32::MAX).then_some(c)
    }
}

/// What the views left on one chart: per slot the raw, unblurred weight of every texel, and the
/// pixel hits per texel. Sums run in view order, pixel order within a view, so they are the
/// same at any thread count. A slot's grid is allocated when it first gets a weight, so a
/// chart no view saw costs nothing.
struct ChartDeposits {
    len: usize,
    slots: Vec<TiledGrid>,
    hits: Vec<u16>,
    width: u32,
    height: u32,
}

/// A chart's texel grid of sums, allocated a tile of `TILE` x `TILE` texels at a time where a
/// weight lands: the views see the street side of a wall, not its back, its gable's corners or
/// what the next building hides, and the grids of every chart live until the last view is
/// merged (dense, they were most of the 1 km² relief's memory). Read back dense, a chart at a
/// time; the sums are the dense grid's, texel by texel.
struct TiledGrid {
    width: u32,
    tiles: Vec<Option<Box<[f64]>>>,
}

/// A tile's side, texels.
const TILE: u32 = 16;

impl TiledGrid {
    /// A grid with no tile allocated (no weight yet).
    fn empty() -> TiledGrid {
        TiledGrid {
            width: 0,
            tiles: Vec::new(),
        }
    }

    fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    fn add(&mut self, width: u32, height: u32, texel: u32, w: f64) {
        let across = width.div_ceil(TILE);
        if self.tiles.is_empty() {
            self.width = width;
            self.tiles = (0..across * height.div_ceil(TILE)).map(|_| None).collect();
        }
        let (x, y) = (texel % width, texel / width);
        let tile = self.tiles[((y / TILE) * across + x / TILE) as usize]
            .get_or_insert_with(|| vec![0.0; (TILE * TILE) as usize].into_boxed_slice());
        tile[((y % TILE) * TILE + x % TILE) as usize] += w;
    }

    /// The sums as a dense row-major grid of `len` texels.
    fn to_dense(&self, len: usize) -> Vec<f64> {
        let mut out = vec![0.0; len];
        let across = self.width.div_ceil(TILE);
        for (k, tile) in self.tiles.iter().enumerate() {
            let Some(tile) = tile else { continue };
            let (tx, ty) = (k as u32 % across * TILE, k as u32 / across * TILE);
            for (i, &v) in tile.iter().enumerate() {
                let (x, y) = (tx + i as u32 % TILE, ty + i as u32 / TILE);
                if x < self.width && ((y * self.width + x) as usize) < len {
                    out[(y * self.width + x) as usize] = v;
                }
            }
        }
        out
    }
}

impl ChartDeposits {
    fn new(c: &Chart) -> ChartDeposits {
        ChartDeposits {
            len: c.len(),
            slots: Vec::new(),
            hits: Vec::new(),
            width: c.width,
            height: c.height,
        }
    }

    fn add(&mut self, texel: u32, slot: u32, w: f64) {
        let s = slot as usize;
        if self.slots.len() <= s {
            self.slots.resize_with(s + 1, TiledGrid::empty);
        }
        self.slots[s].add(self.width, self.height, texel, w);
    }

    /// Whether no pixel deposited a weight or hit a texel here.
    fn untouched(&self) -> bool {
        self.hits.is_empty() && self.slots.iter().all(TiledGrid::is_empty)
    }

    fn hit(&mut self, texel: u32) {
        if self.hits.is_empty() {
            self.hits = vec![0; self.len];
        }
        let h = &mut self.hits[texel as usize];
        *h = h.saturating_add(1);
    }

    /// The chart's blurred layers: exposure from every slot (summed in slot order), votes from
    /// every slot but 0.
    fn into_layers(self, c: &Chart, kernel: &[f64]) -> ChartLayers {
        let n = c.len();
        let (w, h) = (c.width as usize, c.height as usize);
        let blur = |raw: &[f64]| -> PodVec<f32> {
            let out = convolve(raw, w, h, kernel);
            PodVec(
                out.iter()
                    .zip(c.triangle_at.iter())
                    .map(|(&v, &t)| if t != u32::MAX { v as f32 } else { 0.0 })
                    .collect(),
            )
        };
        let hits = if self.hits.is_empty() {
            vec![0u16; n]
        } else {
            self.hits
        };
        let used: Vec<(usize, Vec<f64>)> = self
            .slots
            .iter()
            .enumerate()
            .filter(|(_, g)| !g.is_empty())
            .map(|(slot, g)| (slot, g.to_dense(n)))
            .collect();
        if used.is_empty() {
            return ChartLayers {
                width: c.width,
                height: c.height,
                w_exp: PodVec(vec![0.0; n]),
                hits: PodVec(hits),
                votes: Vec::new(),
            };
        }
        let mut total = vec![0.0; n];
        for (_, g) in &used {
            for (t, x) in total.iter_mut().zip(g.iter()) {
                *t += x;
            }
        }
        let w_exp = blur(&total);
        drop(total);
        let votes = used
            .iter()
            .filter(|(slot, _)| *slot != 0)
            .map(|(slot, g)| ((slot - 1) as u16, blur(g)))
            .collect();
        ChartLayers {
            width: c.width,
            height: c.height,
            w_exp,
            hits: PodVec(hits),
            votes,
        }
    }
}

/// One pixel's weight at texel-centre coordinates (u, v) of a chart, spread bilinearly when
/// merged: `slot` 0 is exposure only, `c + 1` a vote for class c. Kept per pixel rather than as
/// its four texel deposits, a third of the bytes a view's deposits write and the merge reads.
#[derive(Clone, Copy)]
struct Splat {
    chart: u32,
    slot: u32,
    u: f64,
    v: f64,
    w: f64,
}

/// One view's contributions in pixel order.
struct ViewDeposits {
    splats: Vec<Splat>,
    hits: Vec<(u32, u32)>,
    stats: FusionStats,
}

impl ViewDeposits {
    fn merge_into(self, per_chart: &mut [ChartDeposits], stats: &mut FusionStats) {
        for s in self.splats {
            let c = &mut per_chart[s.chart as usize];
            bilinear(c.width, c.height, s.u, s.v, |texel, f| {
                c.add(texel, s.slot, s.w * f)
            });
        }
        for (c, t) in self.hits {
            per_chart[c as usize].hit(t);
        }
        stats.views += self.stats.views;
        stats.rays += self.stats.rays;
        stats.chart_hits += self.stats.chart_hits;
        stats.accepted += self.stats.accepted;
        stats.masked += self.stats.masked;
    }
}

#[allow(clippy::too_many_arguments)]
fn view_deposits(
    view: &View,
    rays: &SceneRays,
    charts: &ChartSet,
    lookup: &ChartLookup,
    vote: &dyn Fn(usize) -> Vote,
    displace: &dyn Fn(usize) -> f64,
    p: &FusionParams,
) -> ViewDeposits {
    let mut out = ViewDeposits {
        splats: Vec::new(),
        hits: Vec::new(),
        stats: FusionStats {
            views: 1,
            ..Default::default()
        },
    };
    let k = view.intrinsics;
    let s = p.stride.max(1);
    let cos_max = p.theta_max_deg.to_radians().cos();
    let pixel_weight = (s * s) as f64;
    let origin = view.pose.position.map(|c| c as f32);
    // The pixels the stride keeps, as a grid cast in tiles.
    let (gw, gh) = (
        (view.width.saturating_sub(s / 2)).div_ceil(s),
        (view.height.saturating_sub(s / 2)).div_ceil(s),
    );
    let pixel = |gx: u32, gy: u32| (s / 2 + gx * s, s / 2 + gy * s);
    let dirs: Vec<[f64; 3]> = (0..gh)
        .flat_map(|gy| (0..gw).map(move |gx| (gx, gy)))
        .map(|(gx, gy)| {
            let (x, y) = pixel(gx, gy);
            view.pixel_ray(x as f64 + 0.5, y as f64 + 0.5).0
        })
        .collect();
    // One splat and one hit per pixel at most: reserved once rather than grown by doubling
    // (each doubling copies, and faults in fresh pages).
    let pixels = (gw * gh) as usize;
    out.splats.reserve_exact(pixels);
    out.hits.reserve_exact(pixels);
    let hits = rays.cast_grid(
        gw,
        gh,
        |gx, gy| (origin, dirs[(gy * gw + gx) as usize].map(|c| c as f32)),
        1e-3,
        5000.0,
    );
    for gy in 0..gh {
        for gx in 0..gw {
            let (x, y) = pixel(gx, gy);
            out.stats.rays += 1;
            let d = dirs[(gy * gw + gx) as usize];
            let Some(hit) = hits[(gy * gw + gx) as usize] else {
                continue;
            };
            let Some(ci) = lookup.chart(hit.object, hit.triangle) else {
                continue;
            };
            out.stats.chart_hits += 1;
            let c = &charts.charts[ci as usize];
            let cos_theta = -(c.normal[0] * d[0] + c.normal[1] * d[1] + c.normal[2] * d[2]);
            let j = projection_jacobian(cos_theta, k.fx, hit.t as f64, cos_max);
            if j == 0.0 {
                continue;
            }
            let v = vote((y * view.width + x) as usize);
            let slot = match v {
                Vote::Masked => {
                    out.stats.masked += 1;
                    continue;
                }
                Vote::Seen => 0,
                Vote::Class(c) => c as u32 + 1,
            };
            out.stats.accepted += 1;
            // On the plane `h` in front of the chart the ray arrives h / cos(theta) earlier.
            let h = displace((y * view.width + x) as usize);
            let t = hit.t as f64 - if h.is_finite() { h / cos_theta } else { 0.0 };
            let at = std::array::from_fn(|a| view.pose.position[a] + d[a] * t);
            let (u, vv) = c.uv_of(at);
            if let Some((i, jj)) = c.texel_of(at) {
                out.hits.push((ci, jj * c.width + i));
            }
            out.splats.push(Splat {
                chart: ci,
                slot,
                u: u - 0.5,
                v: vv - 0.5,
                w: j.powf(p.gamma) * pixel_weight,
            });
        }
    }
    out
}

/// The four texel centres nearest texel-centre coordinates (u, v), each with its bilinear share
/// of a unit weight, handed to `each` as (texel index, share); shares that fall outside the
/// grid, or are zero, are dropped.
fn bilinear(width: u32, height: u32, u: f64, v: f64, mut each: impl FnMut(u32, f64)) {
    let (i0, j0) = (u.floor(), v.floor());
    let (a, b) = (u - i0, v - j0);
    for (di, dj, f) in [
        (0, 0, (1.0 - a) * (1.0 - b)),
        (1, 0, a * (1.0 - b)),
        (0, 1, (1.0 - a) * b),
        (1, 1, a * b),
    ] {
        let (i, j) = (i0 as i64 + di, j0 as i64 + dj);
        if f > 0.0 && i >= 0 && j >= 0 && i < width as i64 && j < height as i64 {
            each((j * width as i64 + i) as u32, f);
        }
    }
}

/// Separable convolution of a row-major `w` x `h` grid with a symmetric kernel; outside the grid
/// counts as zero. Only the box of the nonzero cells, grown by the kernel's reach, is visited:
/// the views see a part of most charts.
fn convolve(raw: &[f64], w: usize, h: usize, kernel: &[f64]) -> Vec<f64> {
    if kernel.len() == 1 {
        return raw.to_vec();
    }
    let r = kernel.len() / 2;
    let mut out = vec![0.0; raw.len()];
    let Some([x0, x1, y0, y1]) = crate::raster::set_box(raw, w, h, |&v| v != 0.0) else {
        return out;
    };
    // The row pass's output: the nonzero rows, the nonzero columns and r either side.
    let (rx0, rx1) = (x0.saturating_sub(r), (x1 + r).min(w - 1));
    let rw = rx1 - rx0 + 1;
    let mut rows = vec![0.0; (y1 - y0 + 1) * rw];
    for y in y0..=y1 {
        let dst = &mut rows[(y - y0) * rw..(y - y0 + 1) * rw];
        for x in x0..=x1 {
            let v = raw[y * w + x];
            if v == 0.0 {
                continue;
            }
            for (k, kv) in kernel.iter().enumerate() {
                let xx = (x + k).wrapping_sub(r);
                if xx < w {
                    dst[xx - rx0] += v * kv;
                }
            }
        }
    }
    for y in y0..=y1 {
        for rx in 0..rw {
            let v = rows[(y - y0) * rw + rx];
            if v == 0.0 {
                continue;
            }
            for (k, kv) in kernel.iter().enumerate() {
                let yy = (y + k).wrapping_sub(r);
                if yy < h {
                    out[yy * w + rx0 + rx] += v * kv;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_head_on_and_at_sixty_degrees() {
        // Head-on at 10 m with f = 500 px: (500 / 10)² = 2500 pixels per m².
        assert!((projection_jacobian(1.0, 500.0, 10.0, 0.0) - 2500.0).abs() < 1e-9);
        // At 60 degrees the same surface shows half as many pixels.
        let c60 = 60f64.to_radians().cos();
        assert!((projection_jacobian(c60, 500.0, 10.0, 0.0) - 1250.0).abs() < 1e-9);
        // Twice as far, a quarter.
        assert!((projection_jacobian(1.0, 500.0, 20.0, 0.0) - 625.0).abs() < 1e-9);
    }

    #[test]
    fn the_gate_drops_views_beyond_theta_max_and_back_faces() {
        let gate = 70f64.to_radians().cos();
        assert!(projection_jacobian(65f64.to_radians().cos(), 500.0, 10.0, gate) > 0.0);
        assert_eq!(
            projection_jacobian(75f64.to_radians().cos(), 500.0, 10.0, gate),
            0.0
        );
        assert_eq!(projection_jacobian(-0.5, 500.0, 10.0, 0.0), 0.0);
    }

    #[test]
    fn a_splat_sums_to_its_weight() {
        for sigma in [0.0, 0.7, 1.0, 2.5] {
            let k = gaussian_kernel(sigma);
            assert!((k.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            let (w, h) = (41, 37);
            let mut raw = vec![0.0; (w * h) as usize];
            bilinear(w, h, 17.3, 20.8, |texel, f| raw[texel as usize] += 3.5 * f);
            let out = convolve(&raw, w as usize, h as usize, &k);
            let total: f64 = out.iter().sum();
            assert!((total - 3.5).abs() < 1e-9, "sigma {sigma}: {total}");
            // The kernel's centre of mass stays at the hit.
            let cx: f64 = out
                .iter()
                .enumerate()
                .map(|(i, v)| (i % w as usize) as f64 * v)
                .sum::<f64>()
                / total;
            assert!((cx - 17.3).abs() < 1e-9, "{cx}");
        }
    }

    #[test]
    fn the_convolution_is_the_double_sum_near_edges_and_in_the_middle() {
        // Deposits in a corner, on an edge and inside, on grids narrower than the kernel too:
        // out(x, y) = sum over deposits of raw(x', y') k(x - x' + r) k(y - y' + r).
        let k = gaussian_kernel(1.5);
        let r = (k.len() / 2) as i64;
        for (w, h, cells) in [
            (
                20usize,
                15usize,
                vec![(0usize, 0usize, 1.0), (19, 7, 2.0), (9, 14, 0.5)],
            ),
            (3, 30, vec![(1, 10, 1.0), (2, 11, 4.0)]),
            (12, 12, vec![(5, 6, 1.0)]),
            (8, 5, vec![]),
        ] {
            let mut raw = vec![0.0; w * h];
            for &(x, y, v) in &cells {
                raw[y * w + x] = v;
            }
            let out = convolve(&raw, w, h, &k);
            for y in 0..h as i64 {
                for x in 0..w as i64 {
                    let want: f64 = cells
                        .iter()
                        .map(|&(cx, cy, v)| {
                            let (dx, dy) = (x - cx as i64 + r, y - cy as i64 + r);
                            let kk = |d: i64| k.get(d as usize).copied().filter(|_| d >= 0);
                            v * kk(dx).unwrap_or(0.0) * kk(dy).unwrap_or(0.0)
                        })
                        .sum();
                    let got = out[y as usize * w + x as usize];
                    assert!(
                        (got - want).abs() < 1e-12,
                        "{w}x{h} at ({x}, {y}): {got} {want}"
                    );
                }
            }
        }
    }
}
