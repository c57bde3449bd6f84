//! Diffraction (the UTD of Kouyoumjian-Pathak; ITU-R P.526): the Fresnel integrals, the UTD
//! transition function F(x), the Kouyoumjian-Pathak wedge coefficients D1..D4, and the ITU-R P.526
//! knife-edge loss J(v).

use std::f64::consts::PI;

use num_complex::Complex64 as C64;

/// The Fresnel integrals (S(x), C(x)) = ∫0^x (sin, cos)(π t² / 2) dt: power series below 1.5,
/// Lentz's continued fraction above (Numerical Recipes' `frenel`, to 1e-15).
pub fn fresnel_integrals(x: f64) -> (f64, f64) {
    const EPS: f64 = 1e-15;
    const FPMIN: f64 = 1e-300;
    const MAXIT: usize = 200;
    let ax = x.abs();
    let (s, c) = if ax < FPMIN.sqrt() {
        (0.0, ax)
    } else if ax <= 1.5 {
        let fact = PI / 2.0 * ax * ax;
        let (mut sum, mut sums, mut sumc) = (0.0, 0.0, ax);
        let (mut sign, mut term, mut n, mut odd) = (1.0, ax, 3.0, true);
        for k in 1..MAXIT {
            term *= fact / k as f64;
            sum += sign * term / n;
            let test = sum.abs() * EPS;
            if odd {
                sign = -sign;
                sums = sum;
                sum = sumc;
            } else {
                sumc = sum;
                sum = sums;
            }
            if term < test {
                break;
            }
            odd = !odd;
            n += 2.0;
        }
        (sums, sumc)
    } else {
        let pix2 = PI * ax * ax;
        let mut b = C64::new(1.0, -pix2);
        let mut cc = C64::new(1.0 / FPMIN, 0.0);
        let mut d = C64::new(1.0, 0.0) / b;
        let mut h = d;
        let mut n = -1.0;
        for _ in 2..MAXIT {
            n += 2.0;
            let a = -n * (n + 1.0);
            b += 4.0;
            d = C64::new(1.0, 0.0) / (a * d + b);
            cc = b + a / cc;
            let del = cc * d;
            h *= del;
            if (del.re - 1.0).abs() + del.im.abs() < EPS {
                break;
            }
        }
        h *= C64::new(ax, -ax);
        let cs = C64::new(0.5, 0.5) * (1.0 - C64::from_polar(1.0, 0.5 * pix2) * h);
        (cs.im, cs.re)
    };
    if x < 0.0 { (-s, -c) } else { (s, c) }
}

/// The UTD transition function F(x) = 2j √x e^{jx} ∫_{√x}^∞ e^{−jt²} dt (Kouyoumjian-Pathak).
pub fn transition(x: f64) -> C64 {
    if x <= 0.0 {
        return C64::new(0.0, 0.0);
    }
    let (s, c) = fresnel_integrals((2.0 * x / PI).sqrt());
    (PI * x / 2.0).sqrt() * C64::from_polar(1.0, x) * (C64::new(1.0, 1.0) - 2.0 * C64::new(s, c))
}

/// The four UTD wedge coefficients D1..D4 (Kouyoumjian-Pathak as written in Sionna's
/// EM primer) for a wedge of exterior angle n π, incidence and diffraction angles `phi_i`, `phi`
/// from the 0-face, Keller-cone angle `beta0`, wavenumber `k` and distance parameter `l`.
pub fn wedge_coefficients(n: f64, phi: f64, phi_i: f64, beta0: f64, k: f64, l: f64) -> [C64; 4] {
    let factor = -C64::from_polar(1.0, -PI / 4.0) / (2.0 * n * (2.0 * PI * k).sqrt() * beta0.sin());
    let a = |beta: f64, plus: bool| {
        let big_n = if plus {
            ((beta + PI) / (2.0 * n * PI)).round()
        } else {
            ((beta - PI) / (2.0 * n * PI)).round()
        };
        2.0 * ((2.0 * n * PI * big_n - beta) / 2.0).cos().powi(2)
    };
    let term = |sign: f64, beta: f64, plus: bool| {
        // On a shadow boundary cot -> inf while F(k L a) -> 0; their product is finite and
        // continuous there, so evaluate just beside it.
        let beta = if ((PI + sign * beta) / (2.0 * n)).tan().abs() < 1e-9 {
            beta + 1e-7
        } else {
            beta
        };
        let cot = 1.0 / ((PI + sign * beta) / (2.0 * n)).tan();
        factor * cot * transition(k * l * a(beta, plus))
    };
    [
        term(1.0, phi - phi_i, true),
        term(-1.0, phi - phi_i, false),
        term(1.0, phi + phi_i, true),
        term(-1.0, phi + phi_i, false),
    ]
}

/// ITU-R P.526 §4.1 single knife-edge loss J(v), dB (0 for v <= -0.78).
pub fn knife_edge_db(v: f64) -> f64 {
    if v <= -0.78 {
        return 0.0;
    }
    6.9 + 20.0 * (((v - 0.1).powi(2) + 1.0).sqrt() + v - 0.1).log10()
}

/// The Fresnel-Kirchhoff knife-edge loss, exact for the half-plane in the scalar approximation:
/// −20 log10 |(1 + j)/2 ∫_v^∞ e^{−jπt²/2} dt|, dB.
pub fn fresnel_kirchhoff_db(v: f64) -> f64 {
    let (s, c) = fresnel_integrals(v);
    let e = C64::new(0.5, 0.5) * C64::new(0.5 - c, -(0.5 - s));
    -20.0 * e.norm().log10()
}

/// The knife-edge parameter v = h √(2 (d1 + d2) / (λ d1 d2)).
pub fn knife_edge_v(h: f64, d1: f64, d2: f64, wavelength: f64) -> f64 {
    h * (2.0 * (d1 + d2) / (wavelength * d1 * d2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On the incident shadow boundary (φ − φ' = π) the coefficients stay finite and close to
    /// their values just beside it.
    #[test]
    fn shadow_boundaries_are_finite_and_continuous() {
        let k = 2.0 * PI / 0.0857;
        let on = wedge_coefficients(1.5, 1.5 * PI, 0.5 * PI, PI / 2.0, k, 30.0);
        let near = wedge_coefficients(1.5, 1.5 * PI + 1e-5, 0.5 * PI, PI / 2.0, k, 30.0);
        for (a, b) in on.iter().zip(&near) {
            assert!(a.re.is_finite() && a.im.is_finite(), "{on:?}");
            assert!((a - b).norm() < 1e-3 * b.norm().max(1e-3), "{a} vs {b}");
        }
    }

    /// Test vectors for F(x), computed apart from its integral.
    #[test]
    fn transition_function_test_vectors() {
        for (x, re, im) in [
            (0.001, 0.03959, 0.03767),
            (0.01, 0.12421, 0.10658),
            (0.1, 0.36810, 0.23445),
            (1.0, 0.80953, 0.23220),
            (3.0, 0.94724, 0.13258),
            (10.0, 0.99304, 0.04835),
            (100.0, 0.99993, 0.00500),
        ] {
            let f = transition(x);
            assert!(
                (f.re - re).abs() < 6e-5 && (f.im - im).abs() < 6e-5,
                "F({x}) = {f}, expected {re}+{im}j"
            );
        }
    }

    #[test]
    fn fresnel_integrals_known_values() {
        // Abramowitz & Stegun Table 7.7: C(1) = 0.7798934, S(1) = 0.4382591; limits 1/2.
        let (s, c) = fresnel_integrals(1.0);
        assert!((c - 0.779_893_4).abs() < 1e-7 && (s - 0.438_259_1).abs() < 1e-7);
        let (s, c) = fresnel_integrals(2.0);
        assert!((c - 0.488_253_4).abs() < 1e-7 && (s - 0.343_415_7).abs() < 1e-7);
        let (s, c) = fresnel_integrals(1e4);
        assert!((c - 0.5).abs() < 1e-4 && (s - 0.5).abs() < 1e-4);
    }

    /// J(v) at the ITU-R P.526 sample points, and J within 0.6 dB of the exact Fresnel-Kirchhoff
    /// loss it approximates.
    #[test]
    fn knife_edge_test_vectors() {
        for (v, j) in [
            (-0.5, 1.96),
            (0.0, 6.03),
            (0.5, 10.29),
            (1.0, 13.93),
            (2.0, 19.04),
            (3.0, 22.42),
            (5.0, 26.81),
        ] {
            assert!((knife_edge_db(v) - j).abs() < 0.01, "J({v})");
        }
        assert_eq!(knife_edge_db(-1.0), 0.0);
        for v in [-0.5, 0.0, 0.5, 1.0, 2.0, 3.0, 5.0] {
            let (j, fk) = (knife_edge_db(v), fresnel_kirchhoff_db(v));
            assert!(
                (j - fk).abs() < 0.6,
                "v {v}: J {j} vs Fresnel-Kirchhoff {fk}"
            );
        }
        assert!(
            (fresnel_kirchhoff_db(0.0) - 6.02).abs() < 0.01,
            "half the field at grazing"
        );
    }

    /// A perfectly conducting half-plane (n = 2) seen from the shadow side: the UTD field (soft
    /// and hard polarisations) matches the Fresnel-Kirchhoff knife edge near the shadow boundary,
    /// where both are accurate.
    #[test]
    fn half_plane_utd_matches_the_knife_edge() {
        let lambda = crate::rf::wavelength(3.5e9);
        let k = 2.0 * PI / lambda;
        // Source 100 m before the edge at grazing (phi' = pi), observer 50 m behind it, h below the
        // incident shadow boundary.
        let (s_i, s) = (100.0, 50.0);
        for h in [0.5f64, 1.0, 2.0, 4.0] {
            let theta = (h / s).atan(); // angle into the shadow, seen from the edge
            let (phi_i, phi) = (0.5 * PI, 1.5 * PI + theta);
            let l = s * s_i / (s + s_i);
            let d = wedge_coefficients(2.0, phi, phi_i, PI / 2.0, k, l);
            let soft = d[0] + d[1] - (d[2] + d[3]);
            let hard = d[0] + d[1] + (d[2] + d[3]);
            // Diffracted over free-space field at the unfolded distance.
            let rel = |dd: C64| dd.norm() * ((s + s_i) / (s * s_i)).sqrt();
            // Clearance in the knife-edge geometry: the edge sits h * s_i / (s + s_i) above the
            // direct line.
            let v = knife_edge_v(h * s_i / (s + s_i), s_i, s, lambda);
            let fk = fresnel_kirchhoff_db(v);
            for (name, dd) in [("soft", soft), ("hard", hard)] {
                let utd = -20.0 * rel(dd).log10();
                assert!(
                    (utd - fk).abs() < 1.0,
                    "h {h} v {v:.2} {name}: UTD {utd:.2} dB, Kirchhoff {fk:.2} dB"
                );
            }
        }
    }
}
