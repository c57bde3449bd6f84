//! First-order edge diffraction in radio maps, estimated as Sionna RT 2.2's radio maps estimate
//! it: a Monte Carlo integral over the edges the transmitter lights and the directions of each
//! edge's Keller cone. Each sample picks a wedge in proportion to its length, a point `q` on it
//! and an angle φ round the edge; the diffracted ray leaves `q` along the cone and adds, to the
//! cell it crosses, |E_d|² times the area of the map that a unit of (edge length, cone angle)
//! maps onto there (the Jacobian of `area_per_length_angle`). Averaged over the samples each
//! wedge drew, that is ∫ |E_d|² dA over every cell, the mean the shoot-and-bounce part of the
//! map also gives. The field over the edge is the links' UTD (`diffraction`).
//!
//! As in Sionna: the wedges are the edges of the triangles the transmitter's rays first land
//! on that it meets from outside; the transmitter must see `q` and a point 5 cm outside the corner (so a ray does not
//! slip into the solid between two triangles of the edge), and the diffracted ray must reach the
//! map from both; samples are as many as the map's rays.

use glam::DVec3;
use rayon::prelude::*;

use crate::rng::{mix, unit};

use super::antenna::Antenna;
use super::diffraction::{Wedge, Wedges, diffracted_field, keller_cone};
use super::field;
use super::foliage::{FoliageDepth, FoliageLoss, foliage_length};
use super::map_plane::{Crossing, MapPlane};
use super::scene::RfScene;

/// Sionna's offset of the visibility point outside the corner, metres.
const OUTSIDE_CORNER_M: f64 = 5e-2;
/// Sionna's shortest leg a diffracted contribution may have, metres.
const MIN_LEG_M: f64 = 1e-2;
/// How far a leg keeps clear of its ends when looking for surfaces across it, metres (as links).
const LEG_EPS: f64 = 1e-2;
/// Salts the sample hashes apart from the shoot-and-bounce draws.
const SALT: u64 = 0xD1FF_AC71_0000_0001;

/// What the diffracted samples of one map share.
pub(super) struct EdgeSampler<'a> {
    pub scene: &'a RfScene,
    pub tx: DVec3,
    pub antenna: &'a Antenna,
    pub plane: &'a MapPlane,
    /// Foliage depth at the transmitter, and the loss inside foliage.
    pub foliage: (FoliageDepth, FoliageLoss),
}

/// The wedges of `all` that can diffract the wave from `tx`, whose rays first land on the sorted
/// triangles `seen` ([`Wedge::diffracts_from`]).
pub(crate) fn lit_wedges(all: &Wedges, seen: &[u32], tx: DVec3) -> Vec<Wedge> {
    let mut lit: Vec<u32> = seen.iter().map(|&t| all.face[t as usize]).collect();
    lit.sort_unstable();
    lit.dedup();
    all.list
        .iter()
        .filter(|w| w.diffracts_from(tx, |f| lit.binary_search(&f).is_ok()))
        .copied()
        .collect()
}

impl EdgeSampler<'_> {
    /// `samples` diffracted samples over `wedges`: (cell, |E|² dA / A_patch) per contribution,
    /// to be scaled by (λ/4π)² like the rest of the map. Fixed chunks in order: the same
    /// contributions at any thread count.
    pub fn contributions(&self, wedges: &[Wedge], samples: u32) -> Vec<(u32, f64)> {
        if wedges.is_empty() || samples == 0 {
            return Vec::new();
        }
        let mut cdf = Vec::with_capacity(wedges.len());
        let mut total = 0.0;
        for w in wedges {
            total += w.length;
            cdf.push(total);
        }
        let pick = |i: u32| {
            let u = unit(mix(SALT ^ i as u64)) * total;
            cdf.partition_point(|&c| c <= u).min(wedges.len() - 1)
        };
        // How many samples each wedge drew: every one's estimate is the mean over its own.
        let mut drawn = vec![0u32; wedges.len()];
        for i in 0..samples {
            drawn[pick(i)] += 1;
        }
        const CHUNK: u32 = 8192;
        let chunks: Vec<Vec<(u32, f64)>> = (0..samples.div_ceil(CHUNK))
            .into_par_iter()
            .map(|k| {
                let mut out = Vec::new();
                let mut crossings = Vec::new();
                for i in k * CHUNK..(k * CHUNK).saturating_add(CHUNK).min(samples) {
                    let w = pick(i);
                    let h = mix(SALT ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                    let (u_edge, u_cone) = (unit(mix(h ^ 1)), unit(mix(h ^ 2)));
                    let weight = wedges[w].length / drawn[w] as f64;
                    self.sample(&wedges[w], u_edge, u_cone, weight, &mut crossings, &mut out);
                }
                out
            })
            .collect();
        chunks.into_iter().flatten().collect()
    }

    /// One sample: the point `u_edge` of the way along `w`, the cone angle `u_cone` of its
    /// exterior angle, each contribution weighted by `weight` (the wedge's length over the
    /// samples it drew).
    fn sample(
        &self,
        w: &Wedge,
        u_edge: f64,
        u_cone: f64,
        weight: f64,
        crossings: &mut Vec<Crossing>,
        out: &mut Vec<(u32, f64)>,
    ) {
        let EdgeSampler {
            scene,
            tx,
            antenna,
            plane,
            foliage: (at_tx, loss),
        } = *self;
        let ell = u_edge * w.length;
        let q = w.a + w.e * ell;
        let s_in = (q - tx).length();
        if s_in <= MIN_LEG_M {
            return;
        }
        let ki = (q - tx) / s_in;
        let angle = w.n * std::f64::consts::PI;
        let ko = keller_cone(w, ki, u_cone * angle);
        // Where the diffracted ray meets the map comes first: most cone directions miss it (up,
        // or off the grid), and that costs no ray through the scene on a plane.
        crossings.clear();
        plane.crossings(q, ko, f64::INFINITY, crossings);
        let Some(last) = crossings.last().map(|c| c.t) else {
            return;
        };
        // The transmitter must see the edge, and the point just outside the corner; the
        // diffracted ray runs until a surface stops it, seen from both alike.
        let q_out = q + (w.n0 + w.nn).normalize_or_zero() * OUTSIDE_CORNER_M;
        if scene.blocked(tx, q, LEG_EPS) || scene.blocked(tx, q_out, LEG_EPS) {
            return;
        }
        let t_end = first_wall(scene, q, ko, last).min(first_wall(scene, q_out, ko, last));
        let (foliage_in, at_q) = if scene.has_foliage() {
            let hits = scene.hits_between(tx, q, LEG_EPS);
            foliage_length(scene, tx, q, &hits, at_tx)
        } else {
            (0.0, at_tx)
        };
        let e_tx = field::real(DVec3::from(antenna.field(ki.to_array())));
        for c in crossings.iter() {
            if c.t <= MIN_LEG_M || c.t >= t_end {
                continue;
            }
            let p = q + ko * c.t;
            let Some(e) = diffracted_field(scene, w, q, tx, p, &e_tx) else {
                continue;
            };
            let foliage_m = foliage_in
                + if scene.has_foliage() {
                    foliage_length(scene, q, p, &scene.hits_between(q, p, LEG_EPS), at_q).0
                } else {
                    0.0
                };
            let a = loss.amplitude(foliage_m);
            let area = area_per_length_angle(w, tx, ell, ko, p, c.normal);
            out.push((
                c.cell,
                field::norm_sqr(&e) * a * a * area * angle * weight / plane.patch_area(c.normal),
            ));
        }
    }
}

/// Where the ray `o + t d` first meets a surface that is not foliage before `t_max` (infinity
/// if none).
fn first_wall(scene: &RfScene, o: DVec3, d: DVec3, t_max: f64) -> f64 {
    let mut tmin = LEG_EPS;
    for _ in 0..10_000 {
        let Some(h) = scene.cast(o, d, tmin, t_max + LEG_EPS) else {
            return f64::INFINITY;
        };
        if !scene.is_foliage(h.triangle) {
            return h.t;
        }
        tmin = h.t.max(tmin) + LEG_EPS;
    }
    f64::INFINITY
}

/// |∂p/∂φ × ∂p/∂ℓ|: the area of the surface through `p` (normal `n`) swept per metre of edge
/// and per radian of cone angle by the diffracted rays of a source at `src`, where the ray
/// leaving the edge `ell` metres along `w` in direction `ko` meets it at `p`. The change of
/// variables that turns Sionna's integral over the cell into one over (ℓ, φ)
/// (`RadioMap._diffraction_integration_weight`, there by automatic differentiation).
fn area_per_length_angle(w: &Wedge, src: DVec3, ell: f64, ko: DVec3, p: DVec3, n: DVec3) -> f64 {
    let (e, n0) = (w.e, w.n0);
    let t0 = n0.cross(e).normalize();
    let along = (src - w.a).dot(e);
    let r = (src - w.a - e * along).length();
    let z = ell - along;
    let rho2 = r * r + z * z;
    // On the cone, ko = sinθ (cosφ t0 + sinφ n0) + cosθ e with θ = atan2(r, ℓ − along).
    let (sin_t, cos_t) = (r / rho2.sqrt(), z / rho2.sqrt());
    let phi = ko.dot(n0).atan2(ko.dot(t0));
    let (sin_p, cos_p) = phi.sin_cos();
    let dk_dphi = (n0 * cos_p - t0 * sin_p) * sin_t;
    let dtheta_dell = -r / rho2;
    let dk_dell = ((t0 * cos_p + n0 * sin_p) * cos_t - e * sin_t) * dtheta_dell;
    // p = q + t ko with n · (p − p0) = 0: dp = (I − ko nᵀ / (n · ko)) (dq + t dko).
    let q = w.a + e * ell;
    let t = (p - q).dot(ko);
    let nk = n.dot(ko);
    if nk.abs() < 1e-12 {
        return 0.0;
    }
    let onto = |v: DVec3| v - ko * (n.dot(v) / nk);
    let dp_dphi = onto(dk_dphi * t);
    let dp_dell = onto(e + dk_dell * t);
    dp_dphi.cross(dp_dell).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn box_corner() -> Wedge {
        // The vertical corner x = 0, y = 0 of a solid in x > 0, y > 0... seen from outside: faces
        // y = 0 (normal −y) and x = 0 (normal −x).
        let (n0, nn) = (DVec3::NEG_Y, DVec3::NEG_X);
        Wedge {
            a: DVec3::ZERO,
            e: n0.cross(nn).normalize(),
            length: 30.0,
            n0,
            nn,
            n: 1.5,
            tri0: 0,
            trin: 1,
            face0: 0,
            facen: 1,
            size: None,
        }
    }

    /// The Jacobian against finite differences of the ray-plane intersection.
    #[test]
    fn the_swept_area_is_the_jacobian_of_the_landing_point() {
        let w = box_corner();
        let e = w.e;
        let src = DVec3::new(-20.0, -35.0, 10.0);
        let n = DVec3::new(0.1, -0.2, 1.0).normalize();
        let p0 = DVec3::new(0.0, 0.0, -40.0);
        // The landing point of (ℓ, φ) on the plane through p0.
        let land = |ell: f64, phi: f64| {
            let q = w.a + e * ell;
            let ki = (q - src).normalize();
            let k = keller_cone(&w, ki, phi);
            q + k * (n.dot(p0 - q) / n.dot(k))
        };
        for (ell, phi) in [(12.0, 3.5), (20.0, 4.2), (7.0, 2.0)] {
            let (h, g) = (1e-6, 1e-7);
            let dl = (land(ell + h, phi) - land(ell - h, phi)) / (2.0 * h);
            let dp = (land(ell, phi + g) - land(ell, phi - g)) / (2.0 * g);
            let want = dp.cross(dl).length();
            let q = w.a + e * ell;
            let ko = keller_cone(&w, (q - src).normalize(), phi);
            let p = land(ell, phi);
            let got = area_per_length_angle(&w, src, ell, ko, p, n);
            assert!(
                ((got - want) / want).abs() < 1e-5,
                "ℓ {ell}, φ {phi}: {got} against {want}"
            );
        }
    }

    /// The cone keeps the incident angle to the edge, goes on forward, and φ = 0 runs along the
    /// 0-face, φ = nπ along the n-face.
    #[test]
    fn the_keller_cone_spans_the_exterior_angle() {
        let w = box_corner();
        let ki = DVec3::new(0.6, 0.7, -0.3).normalize();
        let t0 = w.n0.cross(w.e);
        for phi in [0.0, 1.0, 2.5, 1.5 * std::f64::consts::PI] {
            let k = keller_cone(&w, ki, phi);
            assert!((k.dot(w.e) - ki.dot(w.e)).abs() < 1e-12);
            assert!((k.length() - 1.0).abs() < 1e-12);
            if phi == 0.0 {
                let across = (k - w.e * k.dot(w.e)).normalize();
                assert!((across - t0).length() < 1e-12);
            }
        }
        let last = keller_cone(&w, ki, 1.5 * std::f64::consts::PI);
        let across = (last - w.e * last.dot(w.e)).normalize();
        // Along the n-face, into it: perpendicular to its normal.
        assert!(across.dot(w.nn).abs() < 1e-12, "{across}");
    }
}
