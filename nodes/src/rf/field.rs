//! The electric field along a ray as a complex 3-vector across the direction of travel, and how
//! reflection and transmission change it (the bases of Sionna RT's EM primer: e_⊥ = k_i × n / |k_i
//! × n|, e_∥ = e_⊥ × k_i, reflected e_r∥ = e_⊥ × k_r; TE is ⊥, TM is ∥).

use glam::DVec3;
use num_complex::Complex64 as C64;

/// A complex field vector.
pub type CVec = [C64; 3];

/// `v` as a complex vector.
pub fn real(v: DVec3) -> CVec {
    [v.x, v.y, v.z].map(|c| C64::new(c, 0.0))
}

/// Σ e_i v_i.
pub fn dot(e: &CVec, v: DVec3) -> C64 {
    e[0] * v.x + e[1] * v.y + e[2] * v.z
}

/// |e|².
pub fn norm_sqr(e: &CVec) -> f64 {
    e.iter().map(|c| c.norm_sqr()).sum()
}

fn combine(a: C64, u: DVec3, b: C64, v: DVec3) -> CVec {
    [a * u.x + b * v.x, a * u.y + b * v.y, a * u.z + b * v.z]
}

/// The (⊥, ∥) basis of the plane of incidence of `k` on a surface of normal `n`; at normal
/// incidence any vector across `k` serves as ⊥.
fn basis(k: DVec3, n: DVec3) -> (DVec3, DVec3) {
    let c = k.cross(n);
    let perp = if c.length_squared() > 1e-20 {
        c.normalize()
    } else {
        k.any_orthonormal_vector()
    };
    (perp, perp.cross(k))
}

/// The specular direction of `k` off a surface of normal `n`.
pub fn mirror(k: DVec3, n: DVec3) -> DVec3 {
    k - 2.0 * k.dot(n) * n
}

/// The field after a reflection with coefficients (r_TE, r_TM): returns it and the new direction.
// Always inlined: left to the inliner, the radio map's bounce loop came to call it out as
// the crate grew, and the map took 15 % longer (docs/benchmarks-log.md, 2026-11-27, commit 34e95bb).
#[inline(always)]
pub fn reflect(e: &CVec, k: DVec3, n: DVec3, r: (C64, C64)) -> (CVec, DVec3) {
    let (perp, par_i) = basis(k, n);
    let kr = mirror(k, n);
    let par_r = perp.cross(kr);
    (
        combine(r.0 * dot(e, perp), perp, r.1 * dot(e, par_i), par_r),
        kr,
    )
}

/// The field after a straight-through transmission with coefficients (T_TE, T_TM).
#[inline(always)]
pub fn transmit(e: &CVec, k: DVec3, n: DVec3, t: (C64, C64)) -> CVec {
    let (perp, par) = basis(k, n);
    combine(t.0 * dot(e, perp), perp, t.1 * dot(e, par), par)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_perfect_mirror_keeps_the_power_and_flips_the_tangential_field() {
        let k = DVec3::new(1.0, 0.0, -1.0).normalize();
        let n = DVec3::Z;
        // Horizontal (TE) field, along y.
        let e = real(DVec3::Y);
        let one = C64::new(1.0, 0.0);
        let (out, kr) = reflect(&e, k, n, (-one, one));
        assert!((kr - DVec3::new(1.0, 0.0, 1.0).normalize()).length() < 1e-12);
        assert!((norm_sqr(&out) - 1.0).abs() < 1e-12);
        assert!(
            (out[1].re + 1.0).abs() < 1e-12,
            "PEC: tangential E reverses: {out:?}"
        );
        // A TM field stays across the new direction.
        let e = real(DVec3::new(1.0, 0.0, 1.0).normalize()); // TM, across k
        let (out, kr) = reflect(&e, k, n, (-one, one));
        assert!(dot(&out, kr).norm() < 1e-12);
        assert!((norm_sqr(&out) - 1.0).abs() < 1e-12);
    }
}
