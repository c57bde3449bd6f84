//! The candidate diffracted paths of a transmitter: one edge, with specular reflections before
//! and after it up to the depth, found as Sionna RT 2.2 finds them (but with wedges lit by flat
//! face, not by triangle: `diffraction::wedges`) and solved exactly for each receiver
//! (`diffracted`), as the reflection sequences are.
//!
//! - First order: every wedge the transmitter sees ([`Wedge::diffracts_from`]).
//! - Chained: the transmitter's rays bounce as in the reflection search; where one lands on a
//!   flat face with wedges it diffracts with Sionna's probability (0.2) at one of them met from
//!   outside, at a point along the edge, and leaves on the Keller cone of its incidence at an
//!   angle round the wedge's outside, bouncing on to the depth. The surfaces before the edge,
//!   the edge and every prefix of those after it make a candidate. Every draw is a hash of the
//!   ray and the bounce, so the candidates are the same at any thread count.

use std::collections::{BTreeSet, HashMap, HashSet};

use glam::DVec3;
use rayon::prelude::*;

use crate::rng::{mix, unit};

use super::diffraction::{Wedge, Wedges, keller_cone};
use super::fibonacci::fibonacci_sphere;
use super::field;
use super::image_method::images_of;
use super::path::TraceOptions;
use super::scene::{EPS, RfScene};

/// A diffracted path to solve: the surfaces it reflects off before the edge, the wedge, and
/// those it reflects off after, with the transmitter's images in `pre`.
#[derive(Clone, Debug)]
pub struct DiffractionSequence {
    /// The surfaces reflected off before the edge, in order.
    pub pre: Vec<u32>,
    /// The transmitter mirrored in each surface of `pre` in turn (`image_method::images_of`).
    pub pre_images: Vec<DVec3>,
    /// The edge.
    pub wedge: Wedge,
    /// The surfaces reflected off after the edge, in order.
    pub post: Vec<u32>,
}

/// Sionna RT 2.2's chance that a ray landing on a face with a valid wedge diffracts there
/// (`DIFFRACTION_SAMPLING_PROBABILITY`).
const DIFFRACTION_PROBABILITY: f64 = 0.2;
/// Salts the diffraction draws apart from every other hash of a ray index.
const SALT: u64 = 0xD1FF_5EA7_C400_0002;

/// (pre, wedge index, post)
type Candidate = (Vec<u32>, u32, Vec<u32>);

/// The candidate diffracted paths from `tx` over the wedges `wedges`, given its ray-found
/// reflection `sequences` (their first surfaces are the ones it sees), sorted.
pub fn diffraction_sequences(
    scene: &RfScene,
    wedges: &Wedges,
    tx: DVec3,
    sequences: &[Vec<u32>],
    opt: &TraceOptions,
) -> Vec<DiffractionSequence> {
    let all = &wedges.list[..];
    if all.is_empty() || opt.max_depth == 0 {
        return Vec::new();
    }
    // The faces the transmitter lights: those its rays first land on.
    let seen_tris: HashSet<u32> = if opt.reflection {
        sequences
            .iter()
            .filter_map(|s| s.first().copied())
            .collect()
    } else {
        first_hits(scene, tx, opt.rays)
    };
    let seen: HashSet<u32> = seen_tris
        .into_iter()
        .map(|t| wedges.face[t as usize])
        .collect();
    let mut found: BTreeSet<Candidate> = (0..all.len() as u32)
        .filter(|&i| all[i as usize].diffracts_from(tx, |f| seen.contains(&f)))
        .map(|i| (Vec::new(), i, Vec::new()))
        .collect();
    if opt.reflection && opt.max_depth >= 2 {
        let mut by_face: HashMap<u32, Vec<u32>> = HashMap::new();
        for (i, w) in all.iter().enumerate() {
            by_face.entry(w.face0).or_default().push(i as u32);
            by_face.entry(w.facen).or_default().push(i as u32);
        }
        let walk = Walk {
            scene,
            all,
            face: &wedges.face,
            by_face: &by_face,
            depth: opt.max_depth,
        };
        const CHUNK: usize = 4096;
        let chunks: Vec<BTreeSet<Candidate>> = fibonacci_sphere(opt.rays)
            .enumerate()
            .chunks(CHUNK)
            .map(|rays| {
                let mut out = BTreeSet::new();
                for (i, d) in rays {
                    walk.ray(tx, d, i as u64, &mut out);
                }
                out
            })
            .collect();
        found.extend(chunks.into_iter().flatten());
    }
    found
        .into_iter()
        .map(|(pre, w, post)| DiffractionSequence {
            pre_images: images_of(scene, tx, &pre),
            pre,
            wedge: all[w as usize],
            post,
        })
        .collect()
}

/// What every ray of the chained search shares.
struct Walk<'a> {
    scene: &'a RfScene,
    all: &'a [Wedge],
    /// Each triangle's flat face (`Wedges::face`).
    face: &'a [u32],
    /// The wedges on each face (indices into `all`).
    by_face: &'a HashMap<u32, Vec<u32>>,
    depth: u32,
}

impl Walk<'_> {
    /// Ray `i` from `tx` along `d`: its diffractions, as candidates into `out`.
    fn ray(&self, tx: DVec3, mut d: DVec3, i: u64, out: &mut BTreeSet<Candidate>) {
        let scene = self.scene;
        let (mut o, mut pre) = (tx, Vec::new());
        for bounce in 0..self.depth {
            let Some((p, tri)) = first_surface(scene, o, d) else {
                return;
            };
            let h = mix(SALT ^ mix(i) ^ bounce as u64);
            if unit(h) < DIFFRACTION_PROBABILITY
                && let Some(faces) = self.by_face.get(&self.face[tri as usize])
            {
                // One of the face's wedges the ray meets from outside, as Sionna's silhouette
                // sampling picks one edge of the primitive it lands on.
                let lit: Vec<u32> = faces
                    .iter()
                    .copied()
                    .filter(|&w| self.all[w as usize].lit_from(o))
                    .collect();
                if !lit.is_empty() {
                    let w = lit[(mix(h ^ 1) % lit.len() as u64) as usize];
                    let after = self.depth - 1 - bounce;
                    let (u_edge, u_cone) = (unit(mix(h ^ 2)), unit(mix(h ^ 3)));
                    self.diffract(o, &pre, w, after, (u_edge, u_cone), out);
                }
            }
            if bounce + 1 == self.depth {
                return;
            }
            pre.push(tri);
            o = p;
            d = field::mirror(d, scene.normals[tri as usize]);
        }
    }

    /// A wave from `o` (after reflecting off `pre`) diffracting at wedge `w` at the point
    /// `u_edge` of the way along it, leaving at `u_cone` of the way round its outside: the
    /// candidates with every prefix of the up to `after` surfaces it reflects off next.
    fn diffract(
        &self,
        o: DVec3,
        pre: &[u32],
        w: u32,
        after: u32,
        (u_edge, u_cone): (f64, f64),
        out: &mut BTreeSet<Candidate>,
    ) {
        let scene = self.scene;
        let wedge = &self.all[w as usize];
        out.insert((pre.to_vec(), w, Vec::new()));
        let q = wedge.a + wedge.e * (u_edge * wedge.length);
        let ki = (q - o).normalize_or_zero();
        let mut d = keller_cone(wedge, ki, u_cone * wedge.n * std::f64::consts::PI);
        // Started a hair outside the corner, so that it does not land on its own faces.
        let mut from = q + (wedge.n0 + wedge.nn).normalize_or_zero() * EPS;
        let mut post = Vec::new();
        for _ in 0..after {
            let Some((p, tri)) = first_surface(scene, from, d) else {
                return;
            };
            post.push(tri);
            out.insert((pre.to_vec(), w, post.clone()));
            from = p;
            d = field::mirror(d, scene.normals[tri as usize]);
        }
    }
}

/// Where the ray `o + t d` first lands on a surface, through foliage: the point and the
/// triangle.
fn first_surface(scene: &RfScene, mut o: DVec3, d: DVec3) -> Option<(DVec3, u32)> {
    loop {
        let h = scene.cast(o, d, EPS, f64::INFINITY)?;
        o += d * h.t;
        if !scene.is_foliage(h.triangle) {
            return Some((o, h.triangle));
        }
    }
}

/// The surfaces a transmitter sees: where its rays first land (through foliage).
fn first_hits(scene: &RfScene, tx: DVec3, rays: u32) -> HashSet<u32> {
    fibonacci_sphere(rays)
        .filter_map(|d| first_surface(scene, tx, d).map(|(_, t)| t))
        .collect::<Vec<u32>>()
        .into_iter()
        .collect()
}
