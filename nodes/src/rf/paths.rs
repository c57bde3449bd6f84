//! Propagation paths between point pairs: line of sight, specular reflections to a depth and
//! straight-through slab transmissions, found the way Sionna RT finds them. Rays shot from the
//! transmitter on a Fibonacci sphere record which surfaces they bounce off; every distinct
//! sequence of surfaces is then solved exactly for each receiver by the image method, and kept
//! when its reflection points lie on their triangles and its segments are clear (or, with
//! transmission, cross walls that each count as one more interaction).

use std::collections::HashSet;

use glam::DVec3;
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::antenna::Antenna;
use super::field::{self, CVec};
use super::scene::RfScene;

/// A transmitter and a receiver position, site frame.
pub type LinkEnds = ([f64; 3], [f64; 3]);

/// Which interactions a trace follows, and how hard it looks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TraceOptions {
    /// Most interactions (reflections + transmissions) along one path. Default 3.
    pub max_depth: u32,
    /// Line-of-sight paths. Default true.
    pub los: bool,
    /// Specular reflection. Default true.
    pub reflection: bool,
    /// Transmission through surfaces as thin slabs (P.2040). Default true.
    pub transmission: bool,
    /// First-order UTD diffraction at convex edges, for links (radio maps do not model it yet).
    /// Default false, as in Sionna RT.
    pub diffraction: bool,
    /// Rays shot from each transmitter to find reflection sequences. Default 10^6 (Sionna's).
    pub rays: u32,
    /// Loss inside foliage volumes, dB per metre; default 0.2 dB/m x f in GHz (rf.md §5.1,
    /// P.833 Figure 2 read off at 1 and 30 GHz).
    pub foliage_db_per_m: Option<f64>,
}

impl Default for TraceOptions {
    fn default() -> Self {
        TraceOptions {
            max_depth: 3,
            los: true,
            reflection: true,
            transmission: true,
            diffraction: false,
            rays: 1_000_000,
            foliage_db_per_m: None,
        }
    }
}

/// What happened at a path vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum InteractionKind {
    /// Specular reflection.
    Reflection,
    /// Transmission through a slab.
    Transmission,
    /// Diffraction at an edge (UTD).
    Diffraction,
}

/// One interaction of a path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Interaction {
    /// What it was.
    pub kind: InteractionKind,
    /// Where, site frame.
    pub point: [f64; 3],
    /// The global triangle index.
    pub triangle: u32,
}

/// A propagation path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Path {
    /// Interactions in order from the transmitter.
    pub interactions: Vec<Interaction>,
    /// Unfolded length, metres.
    pub length_m: f64,
    /// Delay, seconds.
    pub delay_s: f64,
    /// Complex gain a = (λ/4π) C_R^H T C_T / length (Sionna's `a`, without the e^{-j2πfτ}).
    pub a: [f64; 2],
    /// Path length inside foliage, metres (its loss is in `a`).
    pub foliage_m: f64,
}

/// Every path of one link and the received power they add up to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkPaths {
    /// The paths, by delay.
    pub paths: Vec<Path>,
    /// Σ |a|², dB (-inf without paths).
    pub gain_db: f64,
    /// |Σ a e^{-j2πfτ}|², dB.
    pub coherent_gain_db: f64,
}

const EPS: f64 = 1e-3;

/// Points on the unit sphere on a Fibonacci lattice (Sionna's `fibonacci_lattice`, mapped with
/// z = 1 - 2 y).
pub fn fibonacci_sphere(n: u32) -> impl IndexedParallelIterator<Item = DVec3> {
    let golden = (1.0 + 5f64.sqrt()) / 2.0;
    (0..n).into_par_iter().map(move |i| {
        let x = (i as f64 / golden).fract();
        let y = if n > 1 {
            i as f64 / (n - 1) as f64
        } else {
            0.5
        };
        let phi = 2.0 * std::f64::consts::PI * x;
        let z = 1.0 - 2.0 * y;
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    })
}

/// Traces every link (`tx`, `rx` pairs). Links sharing a transmitter share its ray search.
pub fn trace_links(
    scene: &RfScene,
    links: &[LinkEnds],
    tx_antenna: &Antenna,
    rx_antenna: &Antenna,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Vec<LinkPaths> {
    let mut txs: Vec<[u64; 3]> = links.iter().map(|l| l.0.map(f64::to_bits)).collect();
    txs.sort_unstable();
    txs.dedup();
    let wedges = if opt.diffraction && opt.max_depth > 0 {
        super::diffraction::wedges(scene)
    } else {
        Vec::new()
    };
    let sequences: Vec<Vec<Vec<u32>>> = txs
        .iter()
        .map(|t| reflection_sequences(scene, DVec3::from(t.map(f64::from_bits)), opt))
        .collect();
    links
        .par_iter()
        .map(|(tx, rx)| {
            let k = txs
                .binary_search(&tx.map(f64::to_bits))
                .expect("every tx was listed");
            let (tx, rx) = (DVec3::from(*tx), DVec3::from(*rx));
            let found = link_paths(
                scene,
                tx,
                rx,
                &sequences[k],
                tx_antenna,
                rx_antenna,
                opt,
                freq_hz,
            );
            if wedges.is_empty() {
                return found;
            }
            let extra =
                diffracted_paths(scene, &wedges, tx, rx, tx_antenna, rx_antenna, opt, freq_hz);
            summarize(found.paths.into_iter().chain(extra).collect(), freq_hz)
        })
        .collect()
}

/// The distinct sequences of triangles that rays from `tx` reflect off, up to the depth, sorted.
fn reflection_sequences(scene: &RfScene, tx: DVec3, opt: &TraceOptions) -> Vec<Vec<u32>> {
    if !opt.reflection || opt.max_depth == 0 {
        return Vec::new();
    }
    let chunks: Vec<HashSet<Vec<u32>>> = fibonacci_sphere(opt.rays)
        .chunks(4096)
        .map(|dirs| {
            let mut found = HashSet::new();
            for d in dirs {
                // (origin, direction, reflections so far, interactions so far)
                let mut stack = vec![(tx, d, Vec::new(), 0u32)];
                while let Some((o, d, seq, depth)) = stack.pop() {
                    let Some(h) = scene.cast(o, d, EPS, f64::INFINITY) else {
                        continue;
                    };
                    let p = o + d * h.t;
                    if scene.is_foliage(h.triangle) {
                        stack.push((p, d, seq, depth));
                        continue;
                    }
                    if depth + 1 > opt.max_depth {
                        continue;
                    }
                    let n = scene.normals[h.triangle as usize];
                    let mut next = seq.clone();
                    next.push(h.triangle);
                    found.insert(next.clone());
                    stack.push((p, field::mirror(d, n), next, depth + 1));
                    if opt.transmission {
                        stack.push((p, d, seq, depth + 1));
                    }
                }
            }
            found
        })
        .collect();
    let mut all: Vec<Vec<u32>> = chunks
        .into_iter()
        .flatten()
        .collect::<HashSet<_>>()
        .into_iter()
        .collect();
    all.sort_unstable();
    all
}

/// Solves every sequence for one receiver, plus the direct path.
#[allow(clippy::too_many_arguments)]
fn link_paths(
    scene: &RfScene,
    tx: DVec3,
    rx: DVec3,
    sequences: &[Vec<u32>],
    tx_antenna: &Antenna,
    rx_antenna: &Antenna,
    opt: &TraceOptions,
    freq_hz: f64,
) -> LinkPaths {
    let mut paths = Vec::new();
    if opt.los
        && let Some(p) = evaluate(scene, &[tx, rx], &[], tx_antenna, rx_antenna, opt, freq_hz)
    {
        paths.push(p);
    }
    for seq in sequences {
        if let Some(points) = image_points(scene, tx, rx, seq)
            && let Some(p) = evaluate(scene, &points, seq, tx_antenna, rx_antenna, opt, freq_hz)
        {
            paths.push(p);
        }
    }
    summarize(paths, freq_hz)
}

/// Paths by delay, with the gains they add up to.
fn summarize(mut paths: Vec<Path>, freq_hz: f64) -> LinkPaths {
    paths.sort_by(|a, b| {
        a.delay_s
            .total_cmp(&b.delay_s)
            .then(a.interactions.len().cmp(&b.interactions.len()))
    });
    let incoherent: f64 = paths
        .iter()
        .map(|p| p.a[0] * p.a[0] + p.a[1] * p.a[1])
        .sum();
    let k = 2.0 * std::f64::consts::PI * freq_hz;
    let coherent: C64 = paths
        .iter()
        .map(|p| C64::new(p.a[0], p.a[1]) * C64::from_polar(1.0, -k * p.delay_s))
        .sum();
    LinkPaths {
        paths,
        gain_db: 10.0 * incoherent.log10(),
        coherent_gain_db: 10.0 * coherent.norm_sqr().log10(),
    }
}

/// The image method: mirror the transmitter in each surface of `seq`, then walk back from the
/// receiver, intersecting each surface's plane. `None` when a point misses its triangle or falls
/// outside its segment.
fn image_points(scene: &RfScene, tx: DVec3, rx: DVec3, seq: &[u32]) -> Option<Vec<DVec3>> {
    let mut images = Vec::with_capacity(seq.len());
    let mut img = tx;
    for &t in seq {
        let n = scene.normals[t as usize];
        let q = scene.tris[t as usize][0];
        img -= 2.0 * (img - q).dot(n) * n;
        images.push(img);
    }
    let mut points = vec![DVec3::ZERO; seq.len() + 2];
    points[0] = tx;
    points[seq.len() + 1] = rx;
    let mut target = rx;
    for j in (0..seq.len()).rev() {
        let t = seq[j] as usize;
        let (n, q) = (scene.normals[t], scene.tris[t][0]);
        let d = target - images[j];
        let denom = n.dot(d);
        if denom.abs() < 1e-12 {
            return None;
        }
        let s = n.dot(q - images[j]) / denom;
        if !(s > 1e-9 && s < 1.0 - 1e-9) {
            return None;
        }
        let p = images[j] + d * s;
        if !inside_triangle(&scene.tris[t], n, p) {
            return None;
        }
        points[j + 1] = p;
        target = p;
    }
    // Each reflection must send the path back to the side it came from.
    for j in 1..=seq.len() {
        let n = scene.normals[seq[j - 1] as usize];
        let (a, b) = (
            (points[j - 1] - points[j]).dot(n),
            (points[j + 1] - points[j]).dot(n),
        );
        if a * b <= 0.0 {
            return None;
        }
    }
    Some(points)
}

fn inside_triangle(t: &[DVec3; 3], n: DVec3, p: DVec3) -> bool {
    let tol = -1e-9;
    (0..3).all(|k| {
        (t[(k + 1) % 3] - t[k]).cross(p - t[k]).dot(n) >= tol * (t[(k + 1) % 3] - t[k]).length()
    })
}

/// The field along a polyline whose inner points are reflections off `seq`; walls crossed on the
/// way are transmissions (or block the path). `None` if blocked or over the depth.
#[allow(clippy::too_many_arguments)]
fn evaluate(
    scene: &RfScene,
    points: &[DVec3],
    seq: &[u32],
    tx_antenna: &Antenna,
    rx_antenna: &Antenna,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Option<Path> {
    let foliage_db_per_m = opt.foliage_db_per_m.unwrap_or(0.2 * freq_hz / 1e9);
    let k0 = (points[1] - points[0]).normalize();
    let mut e: CVec = field::real(DVec3::from(tx_antenna.field(k0.to_array())));
    let mut interactions = Vec::new();
    let (mut length, mut foliage_m) = (0.0, 0.0);
    let mut depth = seq.len() as u32;
    for s in 0..points.len() - 1 {
        let (a, b) = (points[s], points[s + 1]);
        let d = (b - a).normalize();
        length += (b - a).length();
        let mut inside_since: Option<f64> = None;
        for h in scene.hits_between(a, b, EPS) {
            let n = scene.normals[h.triangle as usize];
            if scene.is_foliage(h.triangle) {
                // Entering where the ray runs against the outward normal, leaving where along it.
                if d.dot(n) < 0.0 {
                    inside_since.get_or_insert(h.t);
                } else if let Some(t0) = inside_since.take() {
                    foliage_m += h.t - t0;
                } else {
                    foliage_m += h.t; // started inside
                }
                continue;
            }
            if !opt.transmission {
                return None;
            }
            depth += 1;
            if depth > opt.max_depth {
                return None;
            }
            let (_, t) = scene.slab(h.triangle, d.dot(n));
            e = field::transmit(&e, d, n, t);
            interactions.push(Interaction {
                kind: super::paths::InteractionKind::Transmission,
                point: (a + d * h.t).to_array(),
                triangle: h.triangle,
            });
        }
        if let Some(t0) = inside_since {
            foliage_m += (b - a).length() - t0;
        }
        if s + 1 < points.len() - 1 {
            let tri = seq[s];
            let n = scene.normals[tri as usize];
            let (r, _) = scene.slab(tri, d.dot(n));
            let (e2, _) = field::reflect(&e, d, n, r);
            e = e2;
            interactions.push(Interaction {
                kind: InteractionKind::Reflection,
                point: b.to_array(),
                triangle: tri,
            });
        }
    }
    let k_last = (points[points.len() - 1] - points[points.len() - 2]).normalize();
    let rx_pattern = DVec3::from(rx_antenna.field((-k_last).to_array()));
    let amplitude = scene.wavelength / (4.0 * std::f64::consts::PI * length)
        * 10f64.powf(-foliage_db_per_m * foliage_m / 20.0);
    let a = field::dot(&e, rx_pattern) * amplitude;
    Some(Path {
        interactions,
        length_m: length,
        delay_s: length / super::SPEED_OF_LIGHT,
        a: [a.re, a.im],
        foliage_m,
    })
}

/// First-order diffracted paths: over every convex edge whose diffraction point lies on the edge
/// and sees both ends (rf.md §3.1).
#[allow(clippy::too_many_arguments)]
fn diffracted_paths(
    scene: &RfScene,
    wedges: &[super::diffraction::Wedge],
    tx: DVec3,
    rx: DVec3,
    tx_antenna: &Antenna,
    rx_antenna: &Antenna,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Vec<Path> {
    const EDGE_EPS: f64 = 1e-2;
    let foliage_db_per_m = opt.foliage_db_per_m.unwrap_or(0.2 * freq_hz / 1e9);
    let mut out = Vec::new();
    for w in wedges {
        let Some(u) = super::diffraction::diffraction_point(w, tx, rx) else {
            continue;
        };
        let q = w.a + w.e * u;
        let ki = (q - tx).normalize();
        let e_tx = field::real(DVec3::from(tx_antenna.field(ki.to_array())));
        let Some(e) = super::diffraction::diffracted_field(scene, w, q, tx, rx, &e_tx) else {
            continue;
        };
        let mut foliage_m = 0.0;
        let mut clear = true;
        for (a, b) in [(tx, q), (q, rx)] {
            let d = (b - a).normalize();
            let mut inside_since: Option<f64> = None;
            for h in scene.hits_between(a, b, EDGE_EPS) {
                if !scene.is_foliage(h.triangle) {
                    clear = false;
                    break;
                }
                if d.dot(scene.normals[h.triangle as usize]) < 0.0 {
                    inside_since.get_or_insert(h.t);
                } else {
                    foliage_m += h.t - inside_since.take().unwrap_or(0.0);
                }
            }
            if let Some(t0) = inside_since {
                foliage_m += (b - a).length() - t0;
            }
            if !clear {
                break;
            }
        }
        if !clear {
            continue;
        }
        let ko = (rx - q).normalize();
        let rx_pattern = DVec3::from(rx_antenna.field((-ko).to_array()));
        let a = field::dot(&e, rx_pattern)
            * (scene.wavelength / (4.0 * std::f64::consts::PI))
            * 10f64.powf(-foliage_db_per_m * foliage_m / 20.0);
        let length = (q - tx).length() + (rx - q).length();
        out.push(Path {
            interactions: vec![Interaction {
                kind: InteractionKind::Diffraction,
                point: q.to_array(),
                triangle: w.tri0,
            }],
            length_m: length,
            delay_s: length / super::SPEED_OF_LIGHT,
            a: [a.re, a.im],
            foliage_m,
        });
    }
    out
}
