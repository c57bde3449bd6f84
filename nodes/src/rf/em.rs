//! Electromagnetic interactions at surfaces (ITU-R P.2040): complex relative permittivity from the
//! P.2040 laws, Fresnel coefficients of a half-space and of a single-layer slab, free-space loss.

use num_complex::Complex64 as C64;

use crate::artifact::Material;

/// Vacuum permittivity, F/m.
const EPS0: f64 = 8.854_187_812_8e-12;

/// Complex relative permittivity η = ε_r' − j σ / (ε0 ω) of `material` at `freq_hz` (P.2040 eq.
/// (9b) with the Table 3 laws; time convention e^{+jωt}, as in Sionna).
pub fn permittivity(material: Material, freq_hz: f64, extrapolate: bool) -> Result<C64, String> {
    let (eps, sigma) = material.eps_sigma(freq_hz, extrapolate)?;
    Ok(complex_permittivity(eps, sigma, freq_hz))
}

/// η = ε' − j σ / (ε0 ω) (P.2040 eq. (9b), e^{+jωt}).
pub fn complex_permittivity(eps: f64, sigma: f64, freq_hz: f64) -> C64 {
    C64::new(eps, -sigma / (EPS0 * 2.0 * std::f64::consts::PI * freq_hz))
}

/// (ε', σ) of η at `freq_hz`: [`complex_permittivity`] undone.
pub fn eps_sigma_of(eta: C64, freq_hz: f64) -> (f64, f64) {
    (
        eta.re,
        -eta.im * (2.0 * std::f64::consts::PI * freq_hz * EPS0),
    )
}

/// Fresnel reflection coefficients (r_TE, r_TM) of a half-space of permittivity `eta` for a wave
/// from vacuum at incidence cosine `cos_theta` (ITU-R P.2040 eqs (37a), (37b)).
pub fn fresnel(cos_theta: f64, eta: C64) -> (C64, C64) {
    let sin2 = 1.0 - cos_theta * cos_theta;
    fresnel_with_root(cos_theta, eta, csqrt(eta - sin2))
}

/// [`fresnel`] given `a` = √(η − sin²θ).
fn fresnel_with_root(cos_theta: f64, eta: C64, a: C64) -> (C64, C64) {
    let c = C64::from(cos_theta);
    ((c - a) / (c + a), (eta * c - a) / (eta * c + a))
}

/// The principal square root, algebraically: `Complex::sqrt` goes through polar form (atan2,
/// hypot, sin and cos), which cost a fifth of a radio map's time. Each branch avoids the
/// cancellation of |z| ± Re z.
fn csqrt(z: C64) -> C64 {
    let m = (z.re * z.re + z.im * z.im).sqrt();
    if m == 0.0 {
        return C64::new(0.0, z.im);
    }
    if z.re >= 0.0 {
        let r = ((m + z.re) / 2.0).sqrt();
        C64::new(r, z.im / (2.0 * r))
    } else {
        let i = ((m - z.re) / 2.0).sqrt().copysign(z.im);
        C64::new(z.im / (2.0 * i), i)
    }
}

/// Reflection and transmission coefficients of a slab of thickness `d` (metres) in vacuum, per
/// polarisation: `((R_TE, R_TM), (T_TE, T_TM))` (ITU-R P.2040 eqs (43a), (43b), (44)).
pub fn slab(cos_theta: f64, eta: C64, d: f64, wavelength: f64) -> ((C64, C64), (C64, C64)) {
    let sin2 = 1.0 - cos_theta * cos_theta;
    let root = csqrt(eta - sin2);
    let q = 2.0 * std::f64::consts::PI * d / wavelength * root;
    let (r_te, r_tm) = fresnel_with_root(cos_theta, eta, root);
    let e1 = (-C64::i() * q).exp();
    let e2 = e1 * e1;
    let refl = |r: C64| r * (1.0 - e2) / (1.0 - r * r * e2);
    let trans = |r: C64| (1.0 - r * r) * e1 / (1.0 - r * r * e2);
    ((refl(r_te), refl(r_tm)), (trans(r_te), trans(r_tm)))
}

/// The derivatives d/dη of [`slab`]'s coefficients `((R_TE, R_TM), (T_TE, T_TM))`: each is a
/// holomorphic function of the permittivity η at fixed incidence, thickness and wavelength, and
/// this is the chain rule through P.2040 eqs (37), (43a), (43b), (44) (with a = √(η − sin²θ),
/// da/dη = 1 / 2a). What calibration fits materials with (`rf::calibration`). Zero where a = 0
/// (a lossless slab at the critical angle), where the derivative does not exist.
pub fn slab_derivative(
    cos_theta: f64,
    eta: C64,
    d: f64,
    wavelength: f64,
) -> ((C64, C64), (C64, C64)) {
    let zero = C64::new(0.0, 0.0);
    let sin2 = 1.0 - cos_theta * cos_theta;
    let a = csqrt(eta - sin2);
    if a.norm_sqr() == 0.0 {
        return ((zero, zero), (zero, zero));
    }
    let da = 0.5 / a;
    let c = C64::from(cos_theta);
    let (r_te, r_tm) = fresnel_with_root(cos_theta, eta, a);
    let dr_te = -2.0 * c * da / ((c + a) * (c + a));
    let (num, den) = (eta * c - a, eta * c + a);
    let dr_tm = ((c - da) * den - num * (c + da)) / (den * den);
    let k = 2.0 * std::f64::consts::PI * d / wavelength;
    let e1 = (-C64::i() * k * a).exp();
    let de1 = -C64::i() * k * da * e1;
    let (e2, de2) = (e1 * e1, 2.0 * e1 * de1);
    let quotient = |(u, du): (C64, C64), (v, dv): (C64, C64)| (du * v - u * dv) / (v * v);
    let denominator = |r: C64, dr: C64| (1.0 - r * r * e2, -(2.0 * r * dr * e2 + r * r * de2));
    let refl = |r: C64, dr: C64| {
        let u = (r * (1.0 - e2), dr * (1.0 - e2) - r * de2);
        quotient(u, denominator(r, dr))
    };
    let trans = |r: C64, dr: C64| {
        let u = ((1.0 - r * r) * e1, -2.0 * r * dr * e1 + (1.0 - r * r) * de1);
        quotient(u, denominator(r, dr))
    };
    (
        (refl(r_te, dr_te), refl(r_tm, dr_tm)),
        (trans(r_te, dr_te), trans(r_tm, dr_tm)),
    )
}

/// Free-space path loss 20 log10(4π d f / c), dB.
pub fn fspl_db(distance_m: f64, freq_hz: f64) -> f64 {
    20.0 * (4.0 * std::f64::consts::PI * distance_m * freq_hz / super::SPEED_OF_LIGHT).log10()
}

/// 20 log10 |z|.
pub fn db(z: C64) -> f64 {
    20.0 * z.norm().log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64, what: &str) {
        assert!((a - b).abs() <= tol, "{what}: {a} vs {b}");
    }

    /// The slab's derivatives in η against central differences of [`slab`] itself, for lossy
    /// and nearly lossless materials, thin and thick slabs, at normal to grazing incidence.
    #[test]
    fn slab_derivatives_match_central_differences() {
        for eta in [
            C64::new(5.24, -0.632),
            C64::new(6.31, -0.02),
            C64::new(18.3, -3.93),
        ] {
            for d in [0.01, 0.2, 2.0] {
                for cos in [1.0, 0.7, 0.3, 0.05] {
                    let got = slab_derivative(cos, eta, d, 0.0857);
                    let h = 1e-6 * eta.norm();
                    for (dir, along) in
                        [(C64::new(h, 0.0), "real"), (C64::new(0.0, h), "imaginary")]
                    {
                        let (p, m) = (
                            slab(cos, eta + dir, d, 0.0857),
                            slab(cos, eta - dir, d, 0.0857),
                        );
                        let fd = |a: C64, b: C64| (a - b) / (2.0 * dir);
                        let want = [
                            fd(p.0.0, m.0.0),
                            fd(p.0.1, m.0.1),
                            fd(p.1.0, m.1.0),
                            fd(p.1.1, m.1.1),
                        ];
                        let got = [got.0.0, got.0.1, got.1.0, got.1.1];
                        for (g, w) in got.iter().zip(want) {
                            assert!(
                                (g - w).norm() <= 1e-5 * (1.0 + w.norm()),
                                "η {eta}, d {d}, cos {cos}, {along} step: {g} vs {w}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// Reference values computed apart from ITU-R P.2040 eqs (37), (43), (44): concrete at
    /// 3.5 GHz, half-space and 0.1 m slab.
    #[test]
    fn fresnel_and_slab_test_vectors() {
        let eta = permittivity(Material::Concrete, 3.5e9, false).unwrap();
        close(eta.re, 5.240, 5e-4, "eta re");
        close(eta.im, -0.632, 5e-4, "eta im");
        let (te, tm) = fresnel(1.0, eta);
        close(te.re, -0.3938, 5e-4, "r_TE re");
        close(te.im, 0.0254, 5e-4, "r_TE im");
        close(tm.re, 0.3938, 5e-4, "r_TM re");
        close(db(te), -8.08, 0.01, "|r| dB");
        for (deg, te_db, tm_db) in [
            (45.0, -5.81, -11.62),
            (60.0, -4.14, -19.19),
            (80.0, -1.45, -8.21),
        ] {
            let (te, tm) = fresnel(f64::to_radians(deg).cos(), eta);
            close(db(te), te_db, 0.01, "r_TE dB");
            close(db(tm), tm_db, 0.01, "r_TM dB");
        }
        let lam = crate::rf::wavelength(3.5e9);
        let ((r, _), (t, _)) = slab(1.0, eta, 0.1, lam);
        close(db(r), -7.49, 0.01, "slab R");
        close(db(t), -10.36, 0.01, "slab T");
        let ((r_te, r_tm), (t_te, t_tm)) = slab(f64::to_radians(45.0).cos(), eta, 0.1, lam);
        close(db(r_te), -6.48, 0.01, "R_TE 45");
        close(db(t_te), -11.64, 0.01, "T_TE 45");
        close(db(r_tm), -12.45, 0.01, "R_TM 45");
        close(db(t_tm), -9.79, 0.01, "T_TM 45");
        let eta28 = permittivity(Material::Concrete, 28e9, false).unwrap();
        let ((r, _), (t, _)) = slab(1.0, eta28, 0.1, crate::rf::wavelength(28e9));
        close(db(r), -8.11, 0.01, "slab R 28 GHz");
        close(db(t), -46.16, 0.01, "slab T 28 GHz");
    }

    /// FSPL at 1 m, 20 log10(4π f / c), is 43.33 dB at 3.5 GHz and 61.39 dB at 28 GHz; +20 dB per
    /// decade. The algebraic root is the library's polar one, on every quadrant and on the axes.
    #[test]
    fn complex_root_matches_the_polar_one() {
        for re in [-7.5, -1.0, -1e-9, 0.0, 1e-9, 0.3, 5.0, 80.0] {
            for im in [-60.0, -0.2, -1e-12, -0.0, 0.0, 1e-12, 0.7, 33.0] {
                let z = C64::new(re, im);
                let (got, want) = (csqrt(z), z.sqrt());
                assert!(
                    (got - want).norm() <= 1e-15 * want.norm().max(1e-300),
                    "sqrt({z}) = {got}, want {want}"
                );
                assert_eq!(got.im.is_sign_negative(), want.im.is_sign_negative(), "{z}");
            }
        }
    }

    #[test]
    fn free_space_loss() {
        close(fspl_db(1.0, 3.5e9), 43.33, 0.01, "3.5 GHz");
        close(fspl_db(1.0, 28e9), 61.39, 0.01, "28 GHz");
        close(
            fspl_db(1000.0, 3.5e9) - fspl_db(100.0, 3.5e9),
            20.0,
            1e-9,
            "decade",
        );
    }
}
