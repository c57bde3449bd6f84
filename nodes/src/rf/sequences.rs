//! The sequence search: rays shot from a transmitter record which surfaces they reflect off (and,
//! with transmission, which walls they pass), and every distinct sequence of reflecting surfaces
//! becomes a candidate path for the image method to solve exactly, as Sionna RT finds its
//! specular candidates. Foliage volumes are passed through.

use std::collections::HashSet;

use glam::DVec3;
use rayon::prelude::*;

use super::fibonacci::fibonacci_sphere;
use super::field;
use super::path::TraceOptions;
use super::scene::{EPS, RfScene};
use crate::rng::MixState;

/// The distinct sequences of triangles that rays from `tx` reflect off, up to the depth, sorted.
pub fn reflection_sequences(scene: &RfScene, tx: DVec3, opt: &TraceOptions) -> Vec<Vec<u32>> {
    if !opt.reflection || opt.max_depth == 0 {
        return Vec::new();
    }
    // Each chunk's set merged into the larger as they finish: the sorted result does not depend
    // on the merges' order, and a sequence many chunks find is held once per set, not once per
    // chunk until the end.
    let found = fibonacci_sphere(opt.rays)
        .chunks(4096)
        .map(|dirs| chunk_sequences(scene, tx, opt, &dirs))
        .reduce(Sequences::default, |a, b| {
            let (mut big, small) = if a.len() >= b.len() { (a, b) } else { (b, a) };
            big.extend(small);
            big
        });
    let mut all: Vec<Vec<u32>> = found.into_iter().collect();
    all.sort_unstable();
    all
}

/// [`reflection_sequences`] from each of `txs`, in turn.
pub fn reflection_sequences_from(
    scene: &RfScene,
    txs: &[DVec3],
    opt: &TraceOptions,
) -> Vec<Vec<Vec<u32>>> {
    txs.iter()
        .map(|&tx| reflection_sequences(scene, tx, opt))
        .collect()
}

/// A set of sequences (hashed with [`MixHasher`](crate::rng::MixHasher): sorted before use).
type Sequences = HashSet<Vec<u32>, MixState>;

/// The sequences the rays `dirs` from `tx` reflect off.
fn chunk_sequences(scene: &RfScene, tx: DVec3, opt: &TraceOptions, dirs: &[DVec3]) -> Sequences {
    let mut found = Sequences::default();
    for d in dirs {
        // (origin, direction, reflections so far, interactions so far)
        let mut stack = vec![(tx, *d, Vec::new(), 0u32)];
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
            // Most rays find what their neighbours found: copy only what is new.
            if !found.contains(&next) {
                found.insert(next.clone());
            }
            stack.push((p, field::mirror(d, n), next, depth + 1));
            if opt.transmission {
                stack.push((p, d, seq, depth + 1));
            }
        }
    }
    found
}
