//! Diffuse reflection by the effective-roughness model (Degli-Esposti, as in Sionna RT): a fraction
//! S² of the reflected power is scattered over the hemisphere by a pattern f_s normalised to one,
//! the specular part keeps √(1 − S²) of the field.

use std::f64::consts::PI;

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// How scattered power spreads over the hemisphere.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ScatteringPattern {
    /// f_s = cos θ_s / π.
    Lambertian,
    /// A lobe round the specular direction: f_s = ((1 + k_r·k_s)/2)^α_R / F_α_R(θ_i).
    Directive {
        /// The lobe's exponent α_R (1 = wide, 10 = narrow).
        alpha_r: u32,
    },
}

fn binomial(n: u32, k: u32) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// The directive pattern's normaliser F_α(θ_i) = 2^−α Σ_k C(α, k) I_k (Degli-Esposti's directive
/// model).
pub fn directive_norm(alpha: u32, theta_i: f64) -> f64 {
    let (s2, c) = (theta_i.sin().powi(2), theta_i.cos());
    let sum: f64 = (0..=alpha)
        .map(|k| {
            let i_k = if k % 2 == 0 {
                2.0 * PI / (k + 1) as f64
            } else {
                2.0 * PI / (k + 1) as f64
                    * c
                    * (0..=(k - 1) / 2)
                        .map(|w| binomial(2 * w, w) * s2.powi(w as i32) / 4f64.powi(w as i32))
                        .sum::<f64>()
            };
            binomial(alpha, k) * i_k
        })
        .sum();
    sum / 2f64.powi(alpha as i32)
}

/// f_s for incidence direction `ki` (towards the surface), scattering direction `ks` and the
/// normal `n` on the side the wave comes from (n·ks > 0; 0 on the far side).
pub fn pattern(p: ScatteringPattern, ki: DVec3, ks: DVec3, n: DVec3) -> f64 {
    let cos_s = ks.dot(n);
    if cos_s <= 0.0 {
        return 0.0;
    }
    match p {
        ScatteringPattern::Lambertian => cos_s / PI,
        ScatteringPattern::Directive { alpha_r } => {
            let kr = ki - 2.0 * ki.dot(n) * n;
            let theta_i = (-ki.dot(n)).clamp(-1.0, 1.0).acos();
            ((1.0 + kr.dot(ks)) / 2.0).powi(alpha_r as i32) / directive_norm(alpha_r, theta_i)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pattern integrates to one over the hemisphere, at any incidence.
    #[test]
    fn patterns_are_normalised() {
        let n = DVec3::Z;
        for p in [
            ScatteringPattern::Lambertian,
            ScatteringPattern::Directive { alpha_r: 1 },
            ScatteringPattern::Directive { alpha_r: 4 },
            ScatteringPattern::Directive { alpha_r: 9 },
        ] {
            for theta_i in [0.0f64, 0.5, 1.0, 1.4] {
                let ki = DVec3::new(theta_i.sin(), 0.0, -theta_i.cos());
                let (nt, np) = (400, 400);
                let mut sum = 0.0;
                for a in 0..nt {
                    let th = (a as f64 + 0.5) * (PI / 2.0) / nt as f64;
                    for b in 0..np {
                        let ph = (b as f64 + 0.5) * 2.0 * PI / np as f64;
                        let ks = DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                        sum += pattern(p, ki, ks, n)
                            * th.sin()
                            * (PI / 2.0 / nt as f64)
                            * (2.0 * PI / np as f64);
                    }
                }
                assert!((sum - 1.0).abs() < 2e-3, "{p:?} at {theta_i}: {sum}");
            }
        }
    }
}
