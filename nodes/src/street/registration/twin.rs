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
    let mut rays: Vec<([f32; 3], [f32; 3])> = Vec::with_capacity(samples.len() * m);
    for smp in samples {
        for (position, turn) in poses {
            rays.push((
                position.map(|v| v as f32),
                turn.apply(smp.dir).map(|v| v as f32),
            ));
        }
    }
    // A tile's samples under every pose are a run: near an edge a tile holds a fraction of a
    // packet, and a packet of several tiles spreads too wide to be cast as one.
    let runs: Vec<u32> = samples
        .chunk_by(|a, b| a.tile == b.tile)
        .map(|run| (run.len() * m) as u32)
        .collect();
    let hits = twin
        .rays
        .cast_runs_index(&rays, &runs, 1e-3, twin.max_range);
    // Per sample, the consensus cell its last candidate's ray met and what the others say
    // there: one pixel's rays under the candidates of a step land in one 25 cm cell mostly.
    let mut met = vec![None; samples.len()];
    (0..m)
        .map(|j| {
            let pose_hits = (0..samples.len()).map(|i| (rays[i * m + j].1, hits[i * m + j]));
            tally(samples, twin, consensus, poses[j].0, pose_hits, &mut met)
        })
        .collect()
}

/// One pose's agreement share from its rays' directions and hits, in sample order (NaN when
/// no sample counts).
fn tally(
    samples: &[Sample],
    twin: &Twin,
    consensus: Option<&OthersSay>,
    position: [f64; 3],
    hits: impl Iterator<Item = ([f32; 3], Option<(f32, u32)>)>,
    met: &mut [Option<([i64; 3], Option<Facade>)>],
) -> f64 {
    let (mut total, mut counted) = (0i64, 0i64);
    let shown: Vec<Shown> = samples
        .iter()
        .zip(hits)
        .zip(met.iter_mut())
        .map(|((smp, (dir, hit)), met)| {
            let sh = match hit {
                None => Shown {
                    rendered: Rendered::Sky,
                    object: u32::MAX,
                },
                Some((_, prim)) => twin.shown_by_triangle[prim as usize],
            };
            let a = agreement(smp.seen, sh.rendered);
            total += a as i64;
            counted += (a != 0) as i64;
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
                    total += if f == smp.facade { 1 } else { -1 };
                    counted += 1;
                }
            }
            sh
        })
        .collect();
    for (k, smp) in samples.iter().enumerate() {
        if smp.wall == 0 || shown[k].rendered != Rendered::Building {
            continue;
        }
        for nb in [smp.right, smp.down] {
            let Some(o) = samples.get(nb as usize) else {
                continue;
            };
            let other = shown[nb as usize];
            if o.wall == 0 || other.rendered != Rendered::Building {
                continue;
            }
            let seen_split = o.wall != smp.wall;
            let shown_split = other.object != shown[k].object;
            total += if seen_split == shown_split { 1 } else { -1 };
            counted += 1;
        }
    }
    if counted == 0 {
        f64::NAN
    } else {
        total as f64 / counted as f64
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
    pub(super) fn apply(&self, d: [f64; 3]) -> [f64; 3] {
        self.turn(self.zoomed(d))
    }

    /// Direction `d` with its camera-frame x and y scaled by `zoom`.
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
    pub(super) fn turn(&self, d: [f64; 3]) -> [f64; 3] {
        let d = rodrigues(d, self.forward, self.roll);
        let d = rodrigues(d, self.right, self.pitch);
        let (s, c) = self.yaw;
        [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]
    }
}
