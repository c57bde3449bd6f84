//! The twin as the registration sees it: what each triangle is, and the agreement between a
//! view's labels and the twin rendered from a candidate pose.

use crate::artifact::{ObjectClass, Scene, View};
use crate::geom::raycast::SceneRays;

use super::RegistrationParams;
use super::consensus::{Consensus, OthersSay, Pool};
use super::labels::{Facade, Rendered, Sample, agreement, samples, strides};

/// What the twin shows along a ray: the class and, for a building, its object.
#[derive(Clone, Copy)]
pub(super) struct Shown {
    pub(super) rendered: Rendered,
    pub(super) object: u32,
}

/// The twin: its rays, what each triangle is (in the order [`SceneRays`] numbers them), and
/// how far a ray may go before it counts as sky.
pub(super) struct Twin<'a> {
    pub(super) rays: &'a SceneRays,
    pub(super) shown_by_triangle: &'a [Shown],
    pub(super) max_range: f32,
}

/// The agreement shares (-1 to 1) of the camera at each of `poses` (a position and a turn of
/// the reported camera): per pose, the silhouettes (building, sky, ground) per sample, plus,
/// for neighbouring samples that show a wall in the view and a building in the twin, whether
/// both say the same about the two being one building or two (a party wall between row houses
/// is where a flat street front tells where along it the camera stood).
///
/// The poses are cast together, sample by sample: one pixel's rays under the poses a pattern
/// search compares lie within centimetres and hundredths of a degree of each other, the most
/// coherent packet there is, so the BVH's inner nodes are tested once for all of them. Each
/// ray's hit is what it would be cast alone (`WideBvh::closest_packet`), so each pose's score
/// is too.
pub(super) fn scores(
    samples: &[Sample],
    twin: &Twin,
    consensus: Option<&OthersSay>,
    poses: &[([f64; 3], Turn)],
) -> Vec<f64> {
    let m = poses.len();
    let mut tally = Tally {
        total: vec![0; m],
        counted: vec![0; m],
        shown: Vec::with_capacity(samples.len() * m),
    };
    // Per sample, the consensus cell its last candidate's ray met and what the others say
    // there: one pixel's rays under the candidates of a step land in one 25 cm cell mostly.
    let mut met = vec![None; samples.len()];
    let mut rays: Vec<([f32; 3], [f32; 3])> = Vec::new();
    // Whole tiles at a time, about CHUNK samples: the rays and hits of one chunk stay in the
    // processor's cache, where a view's (14,600 samples x 20 poses) did not.
    let mut first = 0;
    for chunk in chunks_of_tiles(samples, CHUNK) {
        rays.clear();
        rays_of(chunk, poses, &mut rays);
        // A tile's samples under every pose are a run: near an edge a tile holds a fraction of
        // a packet, and a packet of several tiles spreads too wide to be cast as one.
        let runs: Vec<u32> = chunk
            .chunk_by(|a, b| a.tile == b.tile)
            .map(|run| (run.len() * m) as u32)
            .collect();
        let hits = twin
            .rays
            .cast_runs_index(&rays, &runs, 1e-3, twin.max_range);
        for (i, smp) in chunk.iter().enumerate() {
            for (j, (position, _)) in poses.iter().enumerate() {
                let (dir, hit) = (rays[i * m + j].1, hits[i * m + j]);
                tally.sample(
                    smp,
                    twin,
                    consensus,
                    *position,
                    (dir, hit),
                    j,
                    &mut met[first + i],
                );
            }
        }
        first += chunk.len();
    }
    tally.wall_pairs(samples, m);
    tally
        .total
        .iter()
        .zip(&tally.counted)
        .map(|(&t, &c)| {
            if c == 0 {
                f64::NAN
            } else {
                t as f64 / c as f64
            }
        })
        .collect()
}

/// Each sample's ray under each pose, sample-major, appended to `rays`.
pub(super) fn rays_of(
    samples: &[Sample],
    poses: &[([f64; 3], Turn)],
    rays: &mut Vec<([f32; 3], [f32; 3])>,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::geom::wide_bvh::simd_available() {
        // SAFETY: the CPU has AVX2.
        return unsafe { rays_of_avx2(samples, poses, rays) };
    }
    rays_of_any(samples, poses, rays)
}

/// [`rays_of`] compiled for AVX2: the same operations in the same order (Rust contracts no
/// multiply-add), so the same bits, in half the instructions; a sixth of the registration's
/// time was building these rays.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn rays_of_avx2(
    samples: &[Sample],
    poses: &[([f64; 3], Turn)],
    rays: &mut Vec<([f32; 3], [f32; 3])>,
) {
    rays_of_any(samples, poses, rays)
}

#[inline(always)]
pub(super) fn rays_of_any(
    samples: &[Sample],
    poses: &[([f64; 3], Turn)],
    rays: &mut Vec<([f32; 3], [f32; 3])>,
) {
    for smp in samples {
        for (position, turn) in poses {
            rays.push((
                position.map(|v| v as f32),
                turn.apply(smp.dir).map(|v| v as f32),
            ));
        }
    }
}

/// About how many samples [`scores`] casts at a time.
const CHUNK: usize = 256;

/// `samples` in runs of whole tiles, each about `size` samples (a tile larger than that alone).
fn chunks_of_tiles(samples: &[Sample], size: usize) -> impl Iterator<Item = &[Sample]> {
    let mut rest = samples;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let mut end = 0;
        for run in rest.chunk_by(|a, b| a.tile == b.tile) {
            if end > 0 && end + run.len() > size {
                break;
            }
            end += run.len();
        }
        let (chunk, after) = rest.split_at(end);
        rest = after;
        Some(chunk)
    })
}

/// Each pose's agreement, summed sample by sample: its total and the samples counted, and what
/// the twin showed each sample under each pose (sample-major) for the wall pairs at the end.
struct Tally {
    total: Vec<i64>,
    counted: Vec<i64>,
    shown: Vec<Shown>,
}

impl Tally {
    /// Sample `smp` under pose `j` (at `position`), its ray's direction and hit: the silhouette
    /// agreement, and the consensus's where the sample shows a façade the twin's building
    /// holds. `met` is the sample's last consensus cell and what the others say there.
    #[allow(clippy::too_many_arguments)]
    fn sample(
        &mut self,
        smp: &Sample,
        twin: &Twin,
        consensus: Option<&OthersSay>,
        position: [f64; 3],
        (dir, hit): ([f32; 3], Option<(f32, u32)>),
        j: usize,
        met: &mut Option<([i64; 3], Option<Facade>)>,
    ) {
        let sh = match hit {
            None => Shown {
                rendered: Rendered::Sky,
                object: u32::MAX,
            },
            Some((_, prim)) => twin.shown_by_triangle[prim as usize],
        };
        let a = agreement(smp.seen, sh.rendered);
        self.total[j] += a as i64;
        self.counted[j] += (a != 0) as i64;
        if let (Some(cons), Some((t, _))) = (consensus, hit)
            && sh.rendered == Rendered::Building
            && smp.facade != Facade::None
        {
            let at = std::array::from_fn(|k| position[k] + dir[k] as f64 * t as f64);
            let cell = cons.cell(at);
            let label = match *met {
                Some((c, label)) if c == cell => label,
                _ => {
                    let label = cons.label(cell);
                    *met = Some((cell, label));
                    label
                }
            };
            if let Some(f) = label {
                self.total[j] += if f == smp.facade { 1 } else { -1 };
                self.counted[j] += 1;
            }
        }
        self.shown.push(sh);
    }

    /// For neighbouring samples that both show a wall in the view and a building in the twin
    /// under pose j, +1 where both say the same about the two being one building or two, -1
    /// where not.
    fn wall_pairs(&mut self, samples: &[Sample], m: usize) {
        for (k, smp) in samples.iter().enumerate() {
            if smp.wall == 0 {
                continue;
            }
            for nb in [smp.right, smp.down] {
                let Some(o) = samples.get(nb as usize) else {
                    continue;
                };
                if o.wall == 0 {
                    continue;
                }
                let seen_split = o.wall != smp.wall;
                let (here, there) = (k * m, nb as usize * m);
                for j in 0..m {
                    let (a, b) = (self.shown[here + j], self.shown[there + j]);
                    if a.rendered != Rendered::Building || b.rendered != Rendered::Building {
                        continue;
                    }
                    let shown_split = a.object != b.object;
                    self.total[j] += if seen_split == shown_split { 1 } else { -1 };
                    self.counted[j] += 1;
                }
            }
        }
    }
}

/// What each of the scene's triangles is, in the order [`SceneRays`] numbers them.
pub(super) fn shown_by_triangle(scene: &Scene) -> Vec<Shown> {
    scene
        .objects
        .iter()
        .enumerate()
        .flat_map(|(k, o)| {
            let rendered = match o.class {
                ObjectClass::Building => Rendered::Building,
                ObjectClass::Terrain => Rendered::Ground,
                _ => Rendered::Other,
            };
            let shown = Shown {
                rendered,
                object: k as u32,
            };
            std::iter::repeat_n(shown, o.mesh.triangles.len())
        })
        .collect()
}

impl Twin<'_> {
    /// For the consensus: `view`'s façade samples as seen from `position`, turned by `turn`
    /// from its reported orientation, pooled in cells.
    pub(super) fn pool(
        &self,
        cell_m: f64,
        view: &View,
        position: [f64; 3],
        turn: Turn,
        p: &RegistrationParams,
    ) -> Pool {
        let origin = position.map(|v| v as f32);
        let mut cells = Pool::default();
        let (_, fine_stride) = strides(view, p);
        for smp in samples(view, fine_stride, None, p) {
            if smp.facade == Facade::None {
                continue;
            }
            let d = turn.apply(smp.dir);
            let dir = d.map(|c| c as f32);
            let Some((t, prim)) = self.rays.cast_index(origin, dir, 1e-3, self.max_range) else {
                continue;
            };
            if self.shown_by_triangle[prim as usize].rendered != Rendered::Building {
                continue;
            }
            let at = std::array::from_fn(|k| position[k] + d[k] * t as f64);
            let cell = cells.entry(Consensus::key(cell_m, at)).or_default();
            cell[(smp.facade == Facade::Wall) as usize] += 1;
        }
        cells
    }
}

/// A candidate's turn of the reported camera: rolled about its forward axis, pitched about its
/// right axis (both the reported camera's, in the site frame), then turned about the vertical.
#[derive(Clone, Copy)]
pub(super) struct Turn {
    /// (sine, cosine) of the yaw.
    yaw: (f64, f64),
    /// (sine, cosine) of the pitch.
    pitch: (f64, f64),
    /// (sine, cosine) of the roll.
    roll: (f64, f64),
    /// The reported camera's forward axis, site frame.
    forward: [f64; 3],
    /// The reported camera's right axis, site frame.
    right: [f64; 3],
    /// The reported camera's rotation (columns right, down, forward).
    rotation: [[f64; 3]; 3],
    /// 1 / (1 + the relative focal change): a ray's camera-frame x and y scale by it.
    zoom: f64,
}

/// `d` rotated about unit axis `k` by the angle of (sine, cosine) `(s, c)`, by Rodrigues'
/// formula: d cos + (k x d) sin + k (k . d)(1 - cos). `d` itself where the angle is 0.
#[inline(always)]
fn rodrigues(d: [f64; 3], k: [f64; 3], (s, c): (f64, f64)) -> [f64; 3] {
    if s == 0.0 && c == 1.0 {
        return d;
    }
    let kxd = [
        k[1] * d[2] - k[2] * d[1],
        k[2] * d[0] - k[0] * d[2],
        k[0] * d[1] - k[1] * d[0],
    ];
    let kd = k[0] * d[0] + k[1] * d[1] + k[2] * d[2];
    std::array::from_fn(|a| d[a] * c + kxd[a] * s + k[a] * kd * (1.0 - c))
}

impl Turn {
    /// The turn of candidate `c` (yaw `c[2]`, pitch `c[4]`, roll `c[6]`, radians; focal change
    /// `c[5]`) from `pose`.
    pub(super) fn of(pose: &crate::artifact::Pose, c: [f64; 7]) -> Turn {
        let r = pose.rotation;
        Turn {
            yaw: c[2].sin_cos(),
            pitch: c[4].sin_cos(),
            roll: c[6].sin_cos(),
            forward: [r[0][2], r[1][2], r[2][2]],
            right: [r[0][0], r[1][0], r[2][0]],
            rotation: r,
            zoom: 1.0 / (1.0 + c[5]),
        }
    }

    /// Direction `d` (site frame, a pixel's ray from the reported pose) as the candidate sees
    /// that pixel: its focal length applied about the image centre, then pitched and turned.
    #[inline(always)]
    pub(super) fn apply(&self, d: [f64; 3]) -> [f64; 3] {
        self.turn(self.zoomed(d))
    }

    /// Direction `d` with its camera-frame x and y scaled by `zoom`.
    #[inline(always)]
    fn zoomed(&self, d: [f64; 3]) -> [f64; 3] {
        if self.zoom == 1.0 {
            return d;
        }
        let r = self.rotation;
        let cam: [f64; 3] =
            std::array::from_fn(|c| r[0][c] * d[0] + r[1][c] * d[1] + r[2][c] * d[2]);
        let cam = [cam[0] * self.zoom, cam[1] * self.zoom, cam[2]];
        let n = (cam[0] * cam[0] + cam[1] * cam[1] + cam[2] * cam[2]).sqrt();
        std::array::from_fn(|a| (r[a][0] * cam[0] + r[a][1] * cam[1] + r[a][2] * cam[2]) / n)
    }

    /// Direction `d` (site frame) rolled, pitched and turned (the camera's axes turn so).
    #[inline(always)]
    pub(super) fn turn(&self, d: [f64; 3]) -> [f64; 3] {
        let d = rodrigues(d, self.forward, self.roll);
        let d = rodrigues(d, self.right, self.pitch);
        let (s, c) = self.yaw;
        [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]
    }
}
