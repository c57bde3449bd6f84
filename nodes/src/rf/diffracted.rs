//! Diffracted paths of a link: first order, over the convex edges a transmitter sees (rf.md
//! §3.1). Which wedges are candidates, and the path over each one whose diffraction point lies on
//! the edge and sees both ends; the wedges themselves and the UTD field over them are
//! `diffraction`'s.

use std::collections::HashSet;

use glam::DVec3;
use rayon::prelude::*;

use super::diffraction::{Wedge, diffracted_field, diffraction_point};
use super::fibonacci::fibonacci_sphere;
use super::field;
use super::foliage::{FoliageDepth, foliage_length, loss_amplitude};
use super::paths::{Interaction, InteractionKind, Path, TraceOptions, Tracer};
use super::scene::{EPS, RfScene};

/// The wedges of `all` that can diffract the wave of a transmitter at `tx`
/// ([`Wedge::diffracts_from`]). The first surfaces of its ray-found `sequences` are exactly the
/// ones it sees (as in Sionna, which samples wedges from the first hits); without reflection,
/// rays are shot to find them.
pub fn visible_wedges(
    scene: &RfScene,
    all: &[Wedge],
    tx: DVec3,
    sequences: &[Vec<u32>],
    opt: &TraceOptions,
) -> Vec<Wedge> {
    if all.is_empty() {
        return Vec::new();
    }
    let seen: HashSet<u32> = if opt.reflection {
        sequences
            .iter()
            .filter_map(|s| s.first().copied())
            .collect()
    } else {
        first_hits(scene, tx, opt.rays)
    };
    all.iter()
        .filter(|w| w.diffracts_from(tx, |t| seen.contains(&t)))
        .copied()
        .collect()
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

/// First-order diffracted paths from `tx` (at foliage depth `at_tx`) to `rx`: over every wedge
/// whose diffraction point lies on the edge and whose two legs are clear of surfaces (foliage
/// attenuates them, rf.md §5.1), with the UTD field of rf.md §3.1.
pub(super) fn diffracted_paths(
    t: &Tracer,
    wedges: &[Wedge],
    tx: DVec3,
    rx: DVec3,
    at_tx: FoliageDepth,
) -> Vec<Path> {
    const EDGE_EPS: f64 = 1e-2;
    let scene = t.scene;
    let mut out = Vec::new();
    for w in wedges {
        let Some(u) = diffraction_point(w, tx, rx) else {
            continue;
        };
        let q = w.a + w.e * u;
        let ki = (q - tx).normalize();
        let e_tx = field::real(DVec3::from(t.tx_antenna.field(ki.to_array())));
        let Some(e) = diffracted_field(scene, w, q, tx, rx, &e_tx) else {
            continue;
        };
        let (mut foliage_m, mut foliage) = (0.0, at_tx);
        let clear = [(tx, q), (q, rx)].into_iter().all(|(a, b)| {
            let hits = scene.hits_between(a, b, EDGE_EPS);
            if hits.iter().any(|h| !scene.is_foliage(h.triangle)) {
                return false;
            }
            let (inside, at_b) = foliage_length(scene, a, b, &hits, foliage);
            foliage_m += inside;
            foliage = at_b;
            true
        });
        if !clear {
            continue;
        }
        let ko = (rx - q).normalize();
        let rx_pattern = DVec3::from(t.rx_antenna.field((-ko).to_array()));
        let a = field::dot(&e, rx_pattern)
            * (scene.wavelength / (4.0 * std::f64::consts::PI))
            * loss_amplitude(t.foliage_db_per_m, foliage_m);
        let length = (q - tx).length() + (rx - q).length();
        let interactions = vec![Interaction {
            kind: InteractionKind::Diffraction,
            point: q.to_array(),
            triangle: w.tri0,
        }];
        out.push(Path::new(interactions, length, a, foliage_m));
    }
    out
}
