//! The field along one path: from the transmit antenna's pattern through each reflection (thin
//! slab, ITU-R P.2040 §2.2.2.2, scaled by √(1 − S²) for rough surfaces, Degli-Esposti), each wall
//! crossed on the way (slab transmission, or a blocked path), the foliage it runs through (ITU-R
//! P.833) and the spreading over its unfolded length, into the receive antenna's pattern (Sionna
//! RT's EM primer).

use glam::DVec3;

use super::field::{self, CVec};
use super::foliage::{FoliageDepth, foliage_length};
use super::path::{Interaction, InteractionKind, Path, Tracer};
use super::scene::EPS;

/// The path along the polyline `points` whose inner points are reflections off `seq`, from a
/// transmitter at foliage depth `at_tx`: a = (λ/4π) C_R^H T C_T / length (Sionna RT's EM primer),
/// with T the reflections' and transmissions' coefficients (ITU-R P.2040) and 10^(−γ d/20) for d
/// metres in foliage (ITU-R P.833). `None` if a wall blocks it (without transmission), the walls
/// crossed take it over the depth, or no field arrives.
pub(super) fn evaluate(
    t: &Tracer,
    points: &[DVec3],
    seq: &[u32],
    at_tx: FoliageDepth,
) -> Option<Path> {
    let (scene, opt) = (t.scene, t.opt);
    let k0 = (points[1] - points[0]).normalize();
    let mut e: CVec = field::real(DVec3::from(t.tx_antenna.field(k0.to_array())));
    let mut interactions = Vec::new();
    let (mut length, mut foliage_m, mut foliage) = (0.0, 0.0, at_tx);
    let mut depth = seq.len() as u32;
    for s in 0..points.len() - 1 {
        let (a, b) = (points[s], points[s + 1]);
        let d = (b - a).normalize();
        length += (b - a).length();
        // The walls this segment may still cross: past them the path is given up below, so
        // the surfaces beyond are not looked for.
        let walls = if opt.transmission {
            opt.max_depth.saturating_sub(depth) as usize
        } else {
            0
        };
        let hits = scene.hits_between_until(a, b, EPS, walls);
        let (inside, at_b) = foliage_length(scene, a, b, &hits, foliage);
        foliage_m += inside;
        foliage = at_b;
        for h in hits.iter().filter(|h| !scene.is_foliage(h.triangle)) {
            if !opt.transmission {
                return None;
            }
            depth += 1;
            if depth > opt.max_depth {
                return None;
            }
            let n = scene.normals[h.triangle as usize];
            let (_, tr) = scene.slab(h.triangle, d.dot(n));
            e = field::transmit(&e, d, n, tr);
            interactions.push(Interaction {
                kind: InteractionKind::Transmission,
                point: (a + d * h.t).to_array(),
                triangle: h.triangle,
            });
        }
        if s + 1 < points.len() - 1 {
            let (e2, at) = specular(t, seq[s], d, b, &e);
            e = e2;
            interactions.push(at);
        }
    }
    let k_last = (points[points.len() - 1] - points[points.len() - 2]).normalize();
    let rx_pattern = DVec3::from(t.rx_antenna.field((-k_last).to_array()));
    let amplitude =
        scene.wavelength / (4.0 * std::f64::consts::PI * length) * t.foliage.amplitude(foliage_m);
    let a = field::dot(&e, rx_pattern) * amplitude;
    if a.norm_sqr() == 0.0 {
        return None; // e.g. specular reflection with S = 1: nothing travels this way
    }
    Some(Path::new(interactions, length, a, foliage_m))
}

/// The field `e` arriving along `d` after its specular reflection off surface `tri` at `point`:
/// the slab's coefficients at that incidence (ITU-R P.2040 §2.2.2.2), scaled by √(1 − S²) for
/// rough surfaces (Degli-Esposti's effective roughness); with the interaction to record.
pub(super) fn specular(
    t: &Tracer,
    tri: u32,
    d: DVec3,
    point: DVec3,
    e: &CVec,
) -> (CVec, Interaction) {
    let specular_factor = (1.0 - t.opt.scattering_coefficient.powi(2)).max(0.0).sqrt();
    let n = t.scene.normals[tri as usize];
    let (r, _) = t.scene.slab(tri, d.dot(n));
    let e = field::reflect(e, d, n, r).0.map(|c| c * specular_factor);
    let at = Interaction {
        kind: InteractionKind::Reflection,
        point: point.to_array(),
        triangle: tri,
    };
    (e, at)
}
