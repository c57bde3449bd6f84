//! ITU-R P.527-6 "Electrical characteristics of the surface of the Earth": the complex relative
//! permittivity ε = ε' − j ε'' of pure water (§5.1.1, the double-Debye model) and of soil (§5.2, a
//! mixing model of dry soil and free water with a relaxing effective conductivity), and the
//! conductivity σ = 2π f ε0 ε'' (eq. (3a)).
//!
//! Where it applies: the tracer's ground classes (`Material::{VeryDryGround, MediumDryGround,
//! WetGround}`) follow ITU-R P.2040 Table 3, which defines them only from 1 to 10 GHz; above 10 GHz
//! each class continues with [`soil`] at [`LOAM`] and a water content per class
//! (`rf::materials`). Nothing else uses this module.
//!
//! # References
//! ITU-R P.527-6 (2021), §5.1.1 eqs (5)-(13) and §5.2 eqs (57)-(70), as transcribed with their
//! equation numbers in /work/research-49.md §4 (from MathWorks' `earthSurfacePermittivity`, which
//! implements P.527-5/-6, an independent Python transcription, and `elvd/rf_sewer_pipes`
//! `itur_p527.py` for P.527-4; all three agree). Inputs: f in GHz, T in °C. Reference values:
//! `scripts/p527_reference.py`.

/// Vacuum permittivity, F/m (the value `rf::em` uses, so σ converts back to ε'' exactly).
const EPS0: f64 = 8.854_187_812_8e-12;

/// Highest frequency the models are used at, GHz (MathWorks caps P.527 water and soil at 1 THz).
pub const MAX_FREQ_GHZ: f64 = 1000.0;

/// Temperatures accepted, °C: P.527's pure-water range as MathWorks enforces it (−4 to 40 °C);
/// the soil model takes its free water from the same formulas, so it accepts the same range.
pub const TEMP_RANGE_C: (f64, f64) = (-4.0, 40.0);

/// A soil for [`soil`]: texture, density and temperature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Soil {
    /// Sand, percent by mass (P_S).
    pub sand_pct: f64,
    /// Clay, percent by mass (P_C); silt is the rest.
    pub clay_pct: f64,
    /// Specific gravity of the soil solids ρ_s, g/cm³ (about 2.5-2.7).
    pub specific_gravity: f64,
    /// Bulk density ρ_b, g/cm³; `None`: from the texture by eq. (57).
    pub bulk_density: Option<f64>,
    /// Temperature, °C.
    pub temp_c: f64,
}

/// The soil the ground classes continue with above 10 GHz: a loam (sand 40 %, clay 20 %, silt
/// 40 %), ρ_s = 2.66 g/cm³ (quartz, the usual mineral soil value), ρ_b from eq. (57) (1.6004 g/cm³),
/// 20 °C.
pub const LOAM: Soil = Soil {
    sand_pct: 40.0,
    clay_pct: 20.0,
    specific_gravity: 2.66,
    bulk_density: None,
    temp_c: 20.0,
};

fn check_freq(freq_ghz: f64) -> Result<(), String> {
    if !(freq_ghz.is_finite() && freq_ghz > 0.0 && freq_ghz <= MAX_FREQ_GHZ) {
        return Err(format!(
            "ITU-R P.527 needs a frequency in (0, {MAX_FREQ_GHZ}] GHz, not {freq_ghz} GHz"
        ));
    }
    Ok(())
}

fn check_temp(temp_c: f64) -> Result<(), String> {
    let (lo, hi) = TEMP_RANGE_C;
    if !(temp_c.is_finite() && (lo..=hi).contains(&temp_c)) {
        return Err(format!(
            "ITU-R P.527 water needs a temperature in [{lo}, {hi}] °C, not {temp_c} °C"
        ));
    }
    Ok(())
}

/// Complex relative permittivity (ε', ε'') of pure water at `freq_ghz` and `temp_c` (P.527-6
/// §5.1.1, eqs (5)-(13)): θ = 300/(T + 273.15) − 1 (eq. (11)); static ε_s = 77.66 + 103.3 θ
/// (eq. (8)); ε_1 = 0.0671 ε_s (eq. (9)); high-frequency ε_∞ = 3.52 − 7.52 θ (eq. (10)); relaxation
/// frequencies f_1 = 20.20 − 146.4 θ + 316 θ² GHz (eq. (12)) and f_2 = 39.8 f_1 (eq. (13)); ε'
/// by eq. (6), ε'' by eq. (7) (ε = ε' − j ε'', eq. (5)). Errors on a non-finite frequency or one
/// outside (0, 1000] GHz, or a temperature outside [−4, 40] °C.
pub fn pure_water(freq_ghz: f64, temp_c: f64) -> Result<(f64, f64), String> {
    check_freq(freq_ghz)?;
    check_temp(temp_c)?;
    Ok(double_debye(freq_ghz, temp_c))
}

/// Eqs (6)-(13) without the range checks of [`pure_water`].
fn double_debye(f: f64, temp_c: f64) -> (f64, f64) {
    let theta = 300.0 / (temp_c + 273.15) - 1.0;
    let eps_s = 77.66 + 103.3 * theta;
    let eps_1 = 0.0671 * eps_s;
    let eps_inf = 3.52 - 7.52 * theta;
    let f1 = 20.20 - 146.4 * theta + 316.0 * theta * theta;
    let f2 = 39.8 * f1;
    let (x1, x2) = (f / f1, f / f2);
    let (d1, d2) = (1.0 + x1 * x1, 1.0 + x2 * x2);
    let re = (eps_s - eps_1) / d1 + (eps_1 - eps_inf) / d2 + eps_inf;
    let im = x1 * (eps_s - eps_1) / d1 + x2 * (eps_1 - eps_inf) / d2;
    (re, im)
}

/// Complex relative permittivity (ε', ε'') of `soil` with volumetric water content `m_v` (m³/m³,
/// in [0, 1)) at `freq_ghz` (P.527-6 §5.2, eqs (57)-(70)):
/// - bulk density ρ_b = 1.07256 + 0.078886 ln P_S + 0.038753 ln P_C + 0.032732 ln P_silt when not
///   given (eq. (57));
/// - ε = [1 + (ρ_b/ρ_s)(ε_sm'^α − 1) + m_v^β' ε_fw'^α − m_v]^(1/α) − j [m_v^β'' ε_fw''^α]^(1/α)
///   (eqs (58)-(60)), with ε_sm' = (1.01 + 0.44 ρ_s)² − 0.062 (eq. (61)),
///   β' = 1.2748 − 0.00519 P_S − 0.00152 P_C (eq. (62)), β'' = 1.33797 − 0.00603 P_S − 0.00166 P_C
///   (eq. (63)), α = 0.65 (eq. (64));
/// - free water ε_fw = ε_pw + 18 (ρ_s − ρ_b)/(f ρ_s m_v) σ_eff (eqs (65), (66)), ε_pw the pure
///   water of [`pure_water`], σ_eff' = (f/1.35)(σ_1 − σ_2)/(1 + (f/1.35)²) (eq. (67)),
///   σ_eff'' = σ_2 + (σ_1 − σ_2)/(1 + (f/1.35)²) (eq. (68)), σ_1 = 0.0467 + 0.2204 ρ_b −
///   0.004111 P_S − 0.006614 P_C (eq. (69)), σ_2 = −1.645 + 1.939 ρ_b − 0.0225622 P_S + 0.01594 P_C
///   (eq. (70)).
///
/// At m_v = 0 the water terms vanish (their limit: m_v^β ε_fw^α ~ m_v^(β−α) → 0), leaving dry
/// soil. Errors on non-finite or out-of-range inputs (frequency, temperature as in
/// [`pure_water`]; texture percentages outside [0, 100] or summing above 100, or zero where eq.
/// (57) takes their logarithm; ρ_s not positive; ρ_b not in (0, ρ_s)), and where the model leaves
/// its domain (free water with ε_fw' ≤ 0 or ε_fw'' < 0: at very low water contents, where the
/// conductivity term 1/m_v dominates, e.g. loam below m_v ≈ 0.01 at 10 GHz).
pub fn soil(soil: &Soil, freq_ghz: f64, m_v: f64) -> Result<(f64, f64), String> {
    check_freq(freq_ghz)?;
    check_temp(soil.temp_c)?;
    let (ps, pc) = (soil.sand_pct, soil.clay_pct);
    let psilt = 100.0 - ps - pc;
    let pct_ok = |p: f64| p.is_finite() && (0.0..=100.0).contains(&p);
    if !(pct_ok(ps) && pct_ok(pc) && psilt >= 0.0) {
        return Err(format!(
            "P.527 soil needs sand and clay percentages in [0, 100] summing to at most 100, not sand {ps} %, clay {pc} %"
        ));
    }
    let rho_s = soil.specific_gravity;
    if !(rho_s.is_finite() && rho_s > 0.0) {
        return Err(format!(
            "P.527 soil needs a positive specific gravity, not {rho_s}"
        ));
    }
    let rho_b = match soil.bulk_density {
        Some(b) => b,
        None => {
            if !(ps > 0.0 && pc > 0.0 && psilt > 0.0) {
                return Err(format!(
                    "P.527 eq. (57) needs sand, clay and silt all above 0 % (sand {ps} %, clay {pc} %, silt {psilt} %); give the bulk density instead"
                ));
            }
            1.07256 + 0.078886 * ps.ln() + 0.038753 * pc.ln() + 0.032732 * psilt.ln()
        }
    };
    if !(rho_b.is_finite() && rho_b > 0.0 && rho_b < rho_s) {
        return Err(format!(
            "P.527 soil needs a bulk density in (0, specific gravity {rho_s}), not {rho_b}"
        ));
    }
    if !(m_v.is_finite() && (0.0..1.0).contains(&m_v)) {
        return Err(format!(
            "P.527 soil needs a volumetric water content in [0, 1), not {m_v}"
        ));
    }
    let f = freq_ghz;
    let alpha = 0.65;
    let eps_sm = (1.01 + 0.44 * rho_s).powi(2) - 0.062;
    let dry = 1.0 + (rho_b / rho_s) * (eps_sm.powf(alpha) - 1.0);
    if m_v == 0.0 {
        return Ok((dry.powf(1.0 / alpha), 0.0));
    }
    let beta_re = 1.2748 - 0.00519 * ps - 0.00152 * pc;
    let beta_im = 1.33797 - 0.00603 * ps - 0.00166 * pc;
    let sigma_1 = 0.0467 + 0.2204 * rho_b - 0.004111 * ps - 0.006614 * pc;
    let sigma_2 = -1.645 + 1.939 * rho_b - 0.0225622 * ps + 0.01594 * pc;
    let x = f / 1.35;
    let sigma_eff_re = x * (sigma_1 - sigma_2) / (1.0 + x * x);
    let sigma_eff_im = sigma_2 + (sigma_1 - sigma_2) / (1.0 + x * x);
    let (pw_re, pw_im) = pure_water(f, soil.temp_c)?;
    let k = 18.0 * (rho_s - rho_b) / (f * rho_s * m_v);
    let fw_re = pw_re + k * sigma_eff_re;
    let fw_im = pw_im + k * sigma_eff_im;
    if !(fw_re > 0.0 && fw_im >= 0.0) {
        return Err(format!(
            "P.527 soil at m_v = {m_v}, {f} GHz is outside the model's domain (free water eps' {fw_re:.4}, eps'' {fw_im:.4}; eqs (65), (66))"
        ));
    }
    let re = (dry + m_v.powf(beta_re) * fw_re.powf(alpha) - m_v).powf(1.0 / alpha);
    let im = (m_v.powf(beta_im) * fw_im.powf(alpha)).powf(1.0 / alpha);
    if !(re.is_finite() && im.is_finite()) {
        return Err(format!(
            "P.527 soil at m_v = {m_v}, {f} GHz gives a non-finite permittivity"
        ));
    }
    Ok((re, im))
}

/// Conductivity σ = 2π f ε0 ε'' (S/m) of a medium with loss factor `eps_im` at `freq_ghz`
/// (P.527-6 eq. (3a): σ ≈ 0.05563 f_GHz ε'').
pub fn conductivity(freq_ghz: f64, eps_im: f64) -> f64 {
    2.0 * std::f64::consts::PI * freq_ghz * 1e9 * EPS0 * eps_im
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent reference: the static permittivity of pure water at 20 °C is 80.2 and at 0 °C
    /// 87.9 (CRC Handbook of Chemistry and Physics, from memory); eq. (8) gives 80.07 and 87.81,
    /// and eq. (6) at 1 MHz is that static value.
    #[test]
    fn water_static_permittivity_is_about_80() {
        let (re, im) = pure_water(1e-3, 20.0).unwrap();
        assert!((re - 80.2).abs() < 0.2, "{re}");
        assert!(im < 0.01, "{im}");
        let (re0, _) = pure_water(1e-3, 0.0).unwrap();
        assert!((re0 - 87.9).abs() < 0.2, "{re0}");
    }

    /// Independent reference: measured pure water at 20 °C and 10 GHz is about 62 − j32 (Kaatze
    /// 1989, J. Chem. Eng. Data 34; Ellison 2007, J. Phys. Chem. Ref. Data 36(1); Meissner & Wentz
    /// 2004, IEEE TGRS 42(9): ε' 61-63, ε'' 31-33; values quoted from memory, not re-read here).
    /// The model gives 60.79 − j32.72. The relaxation peak (ε'' largest) sits near 17 GHz at
    /// 20 °C (relaxation time about 9.4 ps: 1/(2π τ) ≈ 17 GHz).
    #[test]
    fn water_at_10_ghz_matches_measurements() {
        let (re, im) = pure_water(10.0, 20.0).unwrap();
        assert!((re - 62.0).abs() < 1.5, "{re}");
        assert!((im - 32.0).abs() < 1.5, "{im}");
        let peak = (1..=60)
            .map(|f| (f, pure_water(f as f64, 20.0).unwrap().1))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap()
            .0;
        assert!((15..=19).contains(&peak), "peak at {peak} GHz");
    }

    /// Far above both relaxations ε' tends to ε_∞ = 3.52 − 7.52 θ (eq. (10); 3.344 at 20 °C,
    /// between the optical n² = 1.78 and ε_1) and ε'' to 0; at 1 THz (the highest frequency
    /// accepted) f/f_2 ≈ 1.5 and the second relaxation still lifts ε' to about 4.0.
    #[test]
    fn water_high_frequency_limit_is_eps_inf() {
        let theta: f64 = 300.0 / 293.15 - 1.0;
        let eps_inf = 3.52 - 7.52 * theta;
        assert!((eps_inf - 3.344).abs() < 1e-3, "{eps_inf}");
        let (re, im) = double_debye(1e7, 20.0);
        assert!((re - eps_inf).abs() < 1e-4 && im < 1e-3, "{re} {im}");
        let (re, _) = pure_water(1000.0, 20.0).unwrap();
        assert!(re > eps_inf && re < eps_inf + 1.0, "{re} vs {eps_inf}");
    }

    /// Regression values: computed by `scripts/p527_reference.py` from the same formulas (not an
    /// independent check; /work/research-49.md §4 lists them).
    #[test]
    fn water_regression_values() {
        for (f, re, im) in [
            (3.6, 76.8501, 15.1904),
            (6.75, 69.8503, 25.6947),
            (16.95, 42.7257, 37.4014),
            (28.0, 25.4056, 33.1789),
        ] {
            let (r, i) = pure_water(f, 20.0).unwrap();
            assert!(
                (r - re).abs() < 1e-3 && (i - im).abs() < 1e-3,
                "{f}: {r} {i}"
            );
        }
    }

    /// Independent of the wet-soil terms: at m_v = 0 the model is the dry-soil mixture
    /// (1 + (ρ_b/ρ_s)(ε_sm'^α − 1))^(1/α) with no loss, at every frequency.
    #[test]
    fn dry_soil_is_the_solid_mixture() {
        let rho_b: f64 =
            1.07256 + 0.078886 * 40f64.ln() + 0.038753 * 20f64.ln() + 0.032732 * 40f64.ln();
        assert!((rho_b - 1.6004).abs() < 1e-4, "{rho_b}");
        let eps_sm: f64 = (1.01 + 0.44 * 2.66f64).powi(2) - 0.062;
        let dry = (1.0 + (rho_b / 2.66) * (eps_sm.powf(0.65) - 1.0)).powf(1.0 / 0.65);
        for f in [1.0, 16.95, 28.0] {
            let (re, im) = soil(&LOAM, f, 0.0).unwrap();
            assert!((re - dry).abs() < 1e-12 && im == 0.0, "{f}: {re} {im}");
        }
        // Dry mineral soils measure ε' ≈ 2.5-3.5 (Hallikainen et al. 1985, IEEE TGRS 23; from memory).
        assert!((2.5..3.5).contains(&dry), "{dry}");
    }

    /// ε' rises with water content at every frequency (water is far more polar than the solids),
    /// and the loss with it.
    #[test]
    fn permittivity_rises_with_water() {
        for f in [3.6, 10.0, 16.95, 28.0] {
            let mut last = soil(&LOAM, f, 0.0).unwrap();
            for mv in [0.05, 0.1, 0.2, 0.3, 0.4] {
                let now = soil(&LOAM, f, mv).unwrap();
                assert!(now.0 > last.0 && now.1 > last.1, "{f} GHz m_v {mv}");
                last = now;
            }
        }
    }

    /// Regression values: computed by `scripts/p527_reference.py` from the same formulas (not an
    /// independent check; /work/research-49.md §4 lists them). Loam, ρ_s 2.66, 20 °C.
    #[test]
    fn soil_regression_values() {
        for (mv, f, re, im, s) in [
            (0.07, 3.6, 5.3447, 0.4817, 0.0965),
            (0.07, 6.75, 5.2920, 0.4965, 0.1864),
            (0.07, 16.95, 4.5997, 0.5499, 0.5185),
            (0.07, 28.0, 4.0687, 0.4689, 0.7303),
            (0.20, 3.6, 11.6863, 1.6486, 0.3302),
            (0.20, 16.95, 8.4429, 2.8186, 2.6579),
            (0.20, 28.0, 6.5220, 2.4635, 3.8374),
        ] {
            let (r, i) = soil(&LOAM, f, mv).unwrap();
            let sigma = conductivity(f, i);
            assert!(
                (r - re).abs() < 1e-3 && (i - im).abs() < 1e-3 && (sigma - s).abs() < 1e-3,
                "{mv} {f}: {r} {i} {sigma}"
            );
        }
        let given = Soil {
            bulk_density: Some(1.5),
            ..LOAM
        };
        let (r, i) = soil(&given, 28.0, 0.07).unwrap();
        assert!(
            (r - 3.9062).abs() < 1e-3 && (i - 0.4627).abs() < 1e-3,
            "{r} {i}"
        );
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(pure_water(f64::NAN, 20.0).is_err());
        assert!(pure_water(0.0, 20.0).is_err());
        assert!(pure_water(2000.0, 20.0).is_err());
        assert!(pure_water(10.0, 80.0).is_err());
        assert!(pure_water(10.0, f64::INFINITY).is_err());
        assert!(soil(&LOAM, 10.0, -0.1).is_err());
        assert!(soil(&LOAM, 10.0, 1.0).is_err());
        assert!(soil(&LOAM, 10.0, f64::NAN).is_err());
        assert!(soil(&LOAM, 10.0, 0.001).is_err(), "outside the domain");
        let bad = |s: Soil| soil(&s, 10.0, 0.2).is_err();
        assert!(bad(Soil {
            sand_pct: 90.0,
            clay_pct: 20.0,
            ..LOAM
        }));
        assert!(bad(Soil {
            clay_pct: 0.0,
            ..LOAM
        }));
        assert!(bad(Soil {
            specific_gravity: 0.0,
            ..LOAM
        }));
        assert!(bad(Soil {
            bulk_density: Some(3.0),
            ..LOAM
        }));
        assert!(!bad(Soil {
            clay_pct: 0.0,
            bulk_density: Some(1.5),
            ..LOAM
        }));
    }
}
