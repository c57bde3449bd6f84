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
use super::scattering::{ScatteringPattern, pattern};
use super::scene::RfScene;
use crate::stage::ParamError;

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
    /// Diffuse reflection (effective roughness): a fraction `scattering_coefficient`² of the
    /// reflected power scattered by `scattering_pattern`, last bounce only for links. Default
    /// false, as in Sionna RT.
    pub diffuse: bool,
    /// S in [0, 1] for every surface; specular reflection keeps √(1 − S²) of the field whether
    /// or not diffuse paths are traced. Default 0 (Sionna's default).
    pub scattering_coefficient: f64,
    /// The diffuse pattern. Default Lambertian.
    pub scattering_pattern: ScatteringPattern,
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
            diffuse: false,
            scattering_coefficient: 0.0,
            scattering_pattern: ScatteringPattern::Lambertian,
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
    /// |Σ a e^{-j2πfτ}|², dB (diffuse power added incoherently).
    pub coherent_gain_db: f64,
    /// The diffusely scattered power alone, dB (-inf without it); included in both gains, not
    /// listed as paths.
    pub diffuse_gain_db: f64,
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
    let tx_of = |l: &LinkEnds| {
        txs.binary_search(&l.0.map(f64::to_bits))
            .expect("every tx was listed")
    };
    let all_wedges = if opt.diffraction && opt.max_depth > 0 {
        super::diffraction::wedges(scene)
    } else {
        Vec::new()
    };
    let sequences: Vec<Vec<(Vec<u32>, Vec<DVec3>)>> = txs
        .iter()
        .map(|t| {
            let tx = DVec3::from(t.map(f64::from_bits));
            reflection_sequences(scene, tx, opt)
                .into_iter()
                .map(|seq| {
                    let images = images_of(scene, tx, &seq);
                    (seq, images)
                })
                .collect()
        })
        .collect();
    // A wedge can diffract a transmitter's wave only if the transmitter sees one of its faces:
    // the first surfaces of the ray-found sequences are exactly the ones it sees (as in Sionna,
    // which samples wedges from the first hits).
    let wedges: Vec<Vec<super::diffraction::Wedge>> = sequences
        .iter()
        .zip(&txs)
        .map(|(seqs, t)| {
            if all_wedges.is_empty() {
                return Vec::new();
            }
            let seen: HashSet<u32> = if opt.reflection {
                seqs.iter()
                    .filter_map(|(s, _)| s.first().copied())
                    .collect()
            } else {
                first_hits(scene, DVec3::from(t.map(f64::from_bits)), opt.rays)
            };
            all_wedges
                .iter()
                .filter(|w| seen.contains(&w.tri0) || seen.contains(&w.trin))
                .copied()
                .collect()
        })
        .collect();
    // Diffuse power per link, computed per transmitter for all its receivers.
    let mut diffuse = vec![0.0; links.len()];
    if opt.diffuse && opt.scattering_coefficient > 0.0 && opt.max_depth > 0 {
        for (k, t) in txs.iter().enumerate() {
            let idx: Vec<usize> = (0..links.len())
                .filter(|&i| tx_of(&links[i]) == k)
                .collect();
            let rxs: Vec<DVec3> = idx.iter().map(|&i| DVec3::from(links[i].1)).collect();
            let tx = DVec3::from(t.map(f64::from_bits));
            let p = diffuse_power(scene, tx, &rxs, tx_antenna, rx_antenna, opt);
            for (&i, v) in idx.iter().zip(p) {
                diffuse[i] = v;
            }
        }
    }
    links
        .par_iter()
        .zip(diffuse.par_iter())
        .map(|(link, &diffuse_power)| {
            let k = tx_of(link);
            let (tx, rx) = (DVec3::from(link.0), DVec3::from(link.1));
            let mut paths = link_paths(
                scene,
                tx,
                rx,
                &sequences[k],
                tx_antenna,
                rx_antenna,
                opt,
                freq_hz,
            );
            if !wedges[k].is_empty() {
                paths.extend(diffracted_paths(
                    scene, &wedges[k], tx, rx, tx_antenna, rx_antenna, opt, freq_hz,
                ));
            }
            summarize(paths, freq_hz, diffuse_power)
        })
        .collect()
}

/// Diffusely scattered power at each receiver (linear), last bounce only: rays from `tx` follow
/// specular reflections and transmissions (every branch) to depth − 1; at each surface they hit,
/// the ray tube of solid angle Ω scatters towards every receiver it sees a field of amplitude
/// S Γ √(f_s Ω) |E| / r (the tube's footprint cos θ_i dA = Ω L² cancels its 1/L spreading),
/// summed incoherently (rf.md §1.3).
fn diffuse_power(
    scene: &RfScene,
    tx: DVec3,
    rxs: &[DVec3],
    tx_antenna: &Antenna,
    rx_antenna: &Antenna,
    opt: &TraceOptions,
) -> Vec<f64> {
    let omega = 4.0 * std::f64::consts::PI / opt.rays.max(1) as f64;
    let s = opt.scattering_coefficient;
    let specular_factor = (1.0 - s * s).max(0.0).sqrt();
    let amp = scene.wavelength / (4.0 * std::f64::consts::PI);
    let chunks: Vec<Vec<f64>> = fibonacci_sphere(opt.rays)
        .chunks(4096)
        .map(|dirs| {
            let mut acc = vec![0.0; rxs.len()];
            for d0 in dirs {
                let e0 = field::real(DVec3::from(tx_antenna.field(d0.to_array())));
                let mut stack = vec![(tx, d0, e0, 0u32)];
                while let Some((o, d, e, depth)) = stack.pop() {
                    let Some(h) = scene.cast(o, d, EPS, f64::INFINITY) else {
                        continue;
                    };
                    let q = o + d * h.t;
                    if scene.is_foliage(h.triangle) {
                        stack.push((q, d, e, depth));
                        continue;
                    }
                    if depth + 1 > opt.max_depth {
                        continue;
                    }
                    let n_raw = scene.normals[h.triangle as usize];
                    let n = if d.dot(n_raw) < 0.0 { n_raw } else { -n_raw };
                    let (r, t) = scene.slab(h.triangle, d.dot(n));
                    let (e_spec, k_spec) = field::reflect(&e, d, n, r);
                    let gamma = (field::norm_sqr(&e_spec) / field::norm_sqr(&e).max(1e-300)).sqrt();
                    let (th_i, ph_i) = super::antenna::spherical_basis(d.to_array());
                    let (e_th, e_ph) = (
                        field::dot(&e, DVec3::from(th_i)),
                        field::dot(&e, DVec3::from(ph_i)),
                    );
                    for (k, rx) in rxs.iter().enumerate() {
                        let to = *rx - q;
                        let r_s = to.length();
                        let ks = to / r_s;
                        let f = pattern(opt.scattering_pattern, d, ks, n);
                        if f <= 0.0 || !scene.hits_between(q, *rx, EPS).is_empty() {
                            continue;
                        }
                        let (th_o, ph_o) = super::antenna::spherical_basis(ks.to_array());
                        let scale = s * gamma * (f * omega).sqrt() / r_s * amp;
                        let rx_pattern = DVec3::from(rx_antenna.field((-ks).to_array()));
                        let a = (e_th * DVec3::from(th_o).dot(rx_pattern)
                            + e_ph * DVec3::from(ph_o).dot(rx_pattern))
                            * scale;
                        acc[k] += a.norm_sqr();
                    }
                    if opt.reflection {
                        stack.push((q, k_spec, e_spec.map(|c| c * specular_factor), depth + 1));
                    }
                    if opt.transmission {
                        stack.push((q, d, field::transmit(&e, d, n, t), depth + 1));
                    }
                }
            }
            acc
        })
        .collect();
    let mut total = vec![0.0; rxs.len()];
    for c in chunks {
        for (t, v) in total.iter_mut().zip(c) {
            *t += v;
        }
    }
    total
}

/// The surfaces a transmitter sees: where its rays first land (through foliage).
fn first_hits(scene: &RfScene, tx: DVec3, rays: u32) -> HashSet<u32> {
    fibonacci_sphere(rays)
        .filter_map(|d| {
            let mut o = tx;
            loop {
                let h = scene.cast(o, d, EPS, f64::INFINITY)?;
                if !scene.is_foliage(h.triangle) {
                    return Some(h.triangle);
                }
                o += d * h.t;
            }
        })
        .collect::<Vec<u32>>()
        .into_iter()
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

/// Every path of one receiver: the direct one and each sequence solved.
#[allow(clippy::too_many_arguments)]
fn link_paths(
    scene: &RfScene,
    tx: DVec3,
    rx: DVec3,
    sequences: &[(Vec<u32>, Vec<DVec3>)],
    tx_antenna: &Antenna,
    rx_antenna: &Antenna,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Vec<Path> {
    let mut paths = Vec::new();
    if opt.los
        && let Some(p) = evaluate(scene, &[tx, rx], &[], tx_antenna, rx_antenna, opt, freq_hz)
    {
        paths.push(p);
    }
    for (seq, images) in sequences {
        if let Some(points) = image_points(scene, tx, rx, seq, images)
            && let Some(p) = evaluate(scene, &points, seq, tx_antenna, rx_antenna, opt, freq_hz)
        {
            paths.push(p);
        }
    }
    paths
}

/// Paths by delay, with the gains they add up to.
fn summarize(mut paths: Vec<Path>, freq_hz: f64, diffuse_power: f64) -> LinkPaths {
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
        gain_db: 10.0 * (incoherent + diffuse_power).log10(),
        coherent_gain_db: 10.0 * (coherent.norm_sqr() + diffuse_power).log10(),
        diffuse_gain_db: 10.0 * diffuse_power.log10(),
    }
}

/// The transmitter mirrored in each surface of `seq` in turn: the images of the image method.
fn images_of(scene: &RfScene, tx: DVec3, seq: &[u32]) -> Vec<DVec3> {
    let mut images = Vec::with_capacity(seq.len());
    let mut img = tx;
    for &t in seq {
        let n = scene.normals[t as usize];
        let q = scene.tris[t as usize][0];
        img -= 2.0 * (img - q).dot(n) * n;
        images.push(img);
    }
    images
}

/// The image method: with the transmitter's `images` in the surfaces of `seq`, walk back from
/// the receiver, intersecting each surface's plane. `None` when a point misses its triangle or falls
/// outside its segment.
fn image_points(
    scene: &RfScene,
    tx: DVec3,
    rx: DVec3,
    seq: &[u32],
    images: &[DVec3],
) -> Option<Vec<DVec3>> {
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
    let specular_factor = (1.0 - opt.scattering_coefficient.powi(2)).max(0.0).sqrt();
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
            e = e2.map(|c| c * specular_factor);
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
    if a.norm_sqr() == 0.0 {
        return None; // e.g. specular reflection with S = 1: nothing travels this way
    }
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

/// Checks the options a user can set: what Trace and RadioMap validate.
pub fn check_options(o: &TraceOptions) -> Result<(), ParamError> {
    if !(0.0..=1.0).contains(&o.scattering_coefficient) {
        return Err(ParamError::new(
            "options",
            "expected a scattering_coefficient in [0, 1]",
        ));
    }
    if o.rays == 0 {
        return Err(ParamError::new("options", "expected at least one ray"));
    }
    if o.foliage_db_per_m
        .is_some_and(|v| !(v >= 0.0 && v.is_finite()))
    {
        return Err(ParamError::new(
            "options",
            "expected a non-negative foliage loss in dB/m",
        ));
    }
    Ok(())
}
