//! Diffuse power of links: the effective-roughness model (Degli-Esposti, as in Sionna RT) at the
//! last bounce. Rays from the transmitter follow every specular and transmitted branch; wherever
//! one lands on a surface, the patch its tube covers scatters towards every receiver it sees, and
//! the powers add up incoherently. Foliage on either leg attenuates (ITU-R P.833); it never blocks.

use glam::DVec3;
use rayon::prelude::*;

use super::antenna::spherical_basis;
use super::fibonacci::fibonacci_sphere;
use super::field;
use super::foliage::{FoliageDepth, foliage_length};
use super::path::Tracer;
use super::scattering::pattern;
use super::scene::EPS;

/// Diffusely scattered power at each receiver (linear), last bounce only: rays from `tx` (at
/// foliage depth `at_tx`) follow specular reflections and transmissions (every branch) to
/// depth − 1; at each surface they hit, the ray tube of solid angle Ω scatters towards every
/// receiver it sees a field of amplitude S Γ √(f_s Ω) |E| / r (Degli-Esposti; the tube's footprint
/// cos θ_i dA = Ω L² cancels its 1/L spreading), times the foliage loss of both legs (ITU-R
/// P.833), summed incoherently: each receiver's total, and the same power split by how many
/// specular reflections came before the scattering surface (each of which kept √(1 − S²) of
/// the field), so a calibration can move S.
pub(super) fn diffuse_power(
    t: &Tracer,
    tx: DVec3,
    at_tx: FoliageDepth,
    rxs: &[DVec3],
) -> (Vec<f64>, Vec<Vec<f64>>) {
    let (scene, opt) = (t.scene, t.opt);
    let omega = 4.0 * std::f64::consts::PI / opt.rays.max(1) as f64;
    let s = opt.scattering_coefficient;
    let specular_factor = (1.0 - s * s).max(0.0).sqrt();
    let amp = scene.wavelength / (4.0 * std::f64::consts::PI);
    let depths = opt.max_depth.max(1) as usize;
    let chunks: Vec<(Vec<f64>, Vec<f64>)> = fibonacci_sphere(opt.rays)
        .chunks(4096)
        .map(|dirs| {
            let mut acc = vec![0.0; rxs.len()];
            let mut split = vec![0.0; rxs.len() * depths];
            for d0 in dirs {
                let e0 = field::real(DVec3::from(t.tx_antenna.field(d0.to_array())));
                // Each branch: where it starts, its field, depth, specular reflections, foliage
                // depth and the metres of foliage it has run through (P.833's law saturates on
                // the whole path's).
                let mut stack = vec![(tx, d0, e0, 0u32, 0usize, at_tx, 0.0f64)];
                while let Some((o, d, mut e, depth, reflections, mut foliage, mut in_foliage)) =
                    stack.pop()
                {
                    let Some(h) = scene.cast(o, d, EPS, f64::INFINITY) else {
                        continue;
                    };
                    if foliage.inside() {
                        let a = t.foliage.step_amplitude(in_foliage, h.t);
                        e = e.map(|c| c * a);
                        in_foliage += h.t;
                    }
                    let q = o + d * h.t;
                    if foliage.cross(scene, h.triangle, d) {
                        stack.push((q, d, e, depth, reflections, foliage, in_foliage));
                        continue;
                    }
                    if depth + 1 > opt.max_depth {
                        continue;
                    }
                    let n_raw = scene.normals[h.triangle as usize];
                    let n = if d.dot(n_raw) < 0.0 { n_raw } else { -n_raw };
                    let (r, tr) = scene.slab(h.triangle, d.dot(n));
                    let (e_spec, k_spec) = field::reflect(&e, d, n, r);
                    let gamma = (field::norm_sqr(&e_spec) / field::norm_sqr(&e).max(1e-300)).sqrt();
                    let (th_i, ph_i) = spherical_basis(d.to_array());
                    let (e_th, e_ph) = (
                        field::dot(&e, DVec3::from(th_i)),
                        field::dot(&e, DVec3::from(ph_i)),
                    );
                    for (k, rx) in rxs.iter().enumerate() {
                        let to = *rx - q;
                        let r_s = to.length();
                        let ks = to / r_s;
                        let f = pattern(opt.scattering_pattern, d, ks, n);
                        if f <= 0.0 {
                            continue;
                        }
                        let hits = scene.hits_between_until(q, *rx, EPS, 0);
                        if hits.iter().any(|h| !scene.is_foliage(h.triangle)) {
                            continue;
                        }
                        let (foliage_m, _) = foliage_length(scene, q, *rx, &hits, foliage);
                        let (th_o, ph_o) = spherical_basis(ks.to_array());
                        let scale = s * gamma * (f * omega).sqrt() / r_s
                            * amp
                            * t.foliage.step_amplitude(in_foliage, foliage_m);
                        let rx_pattern = DVec3::from(t.rx_antenna.field((-ks).to_array()));
                        let a = (e_th * DVec3::from(th_o).dot(rx_pattern)
                            + e_ph * DVec3::from(ph_o).dot(rx_pattern))
                            * scale;
                        acc[k] += a.norm_sqr();
                        split[k * depths + reflections] += a.norm_sqr();
                    }
                    if opt.reflection {
                        let e_r = e_spec.map(|c| c * specular_factor);
                        stack.push((
                            q,
                            k_spec,
                            e_r,
                            depth + 1,
                            reflections + 1,
                            foliage,
                            in_foliage,
                        ));
                    }
                    if opt.transmission {
                        let e_t = field::transmit(&e, d, n, tr);
                        stack.push((q, d, e_t, depth + 1, reflections, foliage, in_foliage));
                    }
                }
            }
            (acc, split)
        })
        .collect();
    let mut total = vec![0.0; rxs.len()];
    let mut by_reflections = vec![vec![0.0; depths]; rxs.len()];
    for (c, split) in chunks {
        for (t, v) in total.iter_mut().zip(c) {
            *t += v;
        }
        for (b, v) in by_reflections.iter_mut().zip(split.chunks(depths)) {
            for (x, y) in b.iter_mut().zip(v) {
                *x += y;
            }
        }
    }
    (total, by_reflections)
}
