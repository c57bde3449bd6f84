//! Radio materials: the ITU-R P.2040 classes (Table 3) as Sionna RT names them, plus foliage.
//!
//! P.2040 defines the three ground classes only from 1 to 10 GHz. Above 10 GHz each continues with
//! the ITU-R P.527-6 soil model (`rf::p527`, §5.2) at [`p527::LOAM`] and a water content per class
//! ([`Material::p527_water_content`]) that reproduces the class's P.2040 ε' at 10 GHz: a documented
//! model where P.2040's class ends, not an extrapolation. Every other class keeps P.2040's range.
//!
//! # References
//! ITU-R P.2040-3, Table 3; the same values as Sionna RT v1.0.1 `radio_materials/itu.py`.
//! ITU-R P.527-6 §5.2 for ground above 10 GHz.

use crate::artifact::Material;
use crate::rf::p527;

/// Where P.2040's ground classes end and P.527 soil takes over, GHz: at and below it (down to
/// 1 GHz) the Table 3 laws, above it [`p527::soil`].
pub const GROUND_P2040_TOP_GHZ: f64 = 10.0;

/// The graph and command-line switches that turn P.2040 extrapolation on, as a user writes them;
/// named in the out-of-range error.
const EXTRAPOLATE_HINT: &str = "set `extrapolate: true` on the Trace or RadioMap node, or pass --extrapolate to `kodama-dag trace`/`radiomap`";

/// P.2040 Table 3 row: eps_r' = a f^b, sigma = c f^d (f in GHz), valid for f in (lo, hi) GHz.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ItuLaw {
    /// a.
    pub a: f64,
    /// b.
    pub b: f64,
    /// c, S/m.
    pub c: f64,
    /// d.
    pub d: f64,
    /// Lower end of the frequency range, GHz.
    pub lo_ghz: f64,
    /// Upper end, GHz.
    pub hi_ghz: f64,
}

impl Material {
    /// The slab thickness the tracer gives a surface of this material, metres: the tracer models a
    /// wall as one surface with the single-layer slab coefficients (ITU-R P.2040 §2.2.2.2), so the
    /// thickness decides how much a surface transmits. Sionna's default is 0.1 m for everything;
    /// these are typical thicknesses of what each class is on a building:
    /// - concrete 0.2 m: an exterior cast-in-place or block wall (0.15-0.3 m);
    /// - brick 0.215 m: a one-brick wall (the UK/EU brick length, 215 mm);
    /// - plasterboard 0.0125 m, ceiling board 0.015 m, chipboard and plywood 0.018 m,
    ///   floorboard 0.02 m: the standard sheet thicknesses;
    /// - wood 0.04 m: a door leaf (40-44 mm);
    /// - glass 0.01 m: the glass of a glazed unit (two 4-6 mm panes; the gap is air);
    /// - marble 0.03 m: façade cladding slabs (20-30 mm);
    /// - metal 0.002 m: sheet cladding (opaque at any thickness: sigma = 10^7 S/m);
    /// - the grounds 0.1 m: Sionna's default, kept so ground reflections match Sionna's (a lossy
    ///   slab that thick already reflects as a half-space at 1-10 GHz);
    /// - foliage: no slab (a volume); 0.
    pub fn slab_thickness_m(self) -> f64 {
        match self {
            Material::Concrete => 0.2,
            Material::Brick => 0.215,
            Material::Plasterboard => 0.0125,
            Material::Wood => 0.04,
            Material::Glass => 0.01,
            Material::CeilingBoard => 0.015,
            Material::Chipboard | Material::Plywood => 0.018,
            Material::Marble => 0.03,
            Material::Floorboard => 0.02,
            Material::Metal => 0.002,
            Material::VeryDryGround | Material::MediumDryGround | Material::WetGround => 0.1,
            Material::Foliage => 0.0,
        }
    }

    /// The P.2040 Table 3 law (first band), `None` for foliage.
    pub fn law(self) -> Option<ItuLaw> {
        let l = |a, b, c, d, lo_ghz, hi_ghz| {
            Some(ItuLaw {
                a,
                b,
                c,
                d,
                lo_ghz,
                hi_ghz,
            })
        };
        match self {
            Material::Concrete => l(5.24, 0.0, 0.0462, 0.7822, 1.0, 100.0),
            Material::Brick => l(3.91, 0.0, 0.0238, 0.16, 1.0, 40.0),
            Material::Plasterboard => l(2.73, 0.0, 0.0085, 0.9395, 1.0, 100.0),
            Material::Wood => l(1.99, 0.0, 0.0047, 1.0718, 0.001, 100.0),
            Material::Glass => l(6.31, 0.0, 0.0036, 1.3394, 0.1, 100.0),
            Material::CeilingBoard => l(1.48, 0.0, 0.0011, 1.0750, 1.0, 100.0),
            Material::Chipboard => l(2.58, 0.0, 0.0217, 0.7800, 1.0, 100.0),
            Material::Plywood => l(2.71, 0.0, 0.33, 0.0, 1.0, 40.0),
            Material::Marble => l(7.074, 0.0, 0.0055, 0.9262, 1.0, 60.0),
            Material::Floorboard => l(3.66, 0.0, 0.0044, 1.3515, 50.0, 100.0),
            Material::Metal => l(1.0, 0.0, 1e7, 0.0, 1.0, 100.0),
            Material::VeryDryGround => l(3.0, 0.0, 0.00015, 2.52, 1.0, 10.0),
            Material::MediumDryGround => l(15.0, -0.1, 0.035, 1.63, 1.0, 10.0),
            Material::WetGround => l(30.0, -0.4, 0.15, 1.30, 1.0, 10.0),
            Material::Foliage => None,
        }
    }

    /// The volumetric water content m_v (m³/m³) of [`p527::LOAM`] with which a ground class
    /// continues above 10 GHz, `None` for the other classes. Each is the m_v at which the P.527
    /// loam's ε' at 10 GHz equals the class's P.2040 ε' there (ε' matched, not σ: one free
    /// parameter fits one quantity), solved by bisection in `scripts/p527_reference.py`:
    /// - very dry ground (P.2040 ε' 3.0): m_v = 0, the dry loam, whose ε' is already 2.9986 (and
    ///   just above m_v = 0 the model leaves its domain at 10 GHz); σ is 0 above 10 GHz where
    ///   P.2040 gives 0.050 S/m at 10 GHz;
    /// - medium dry ground (ε' 11.9149): m_v = 0.234468; σ at 10 GHz 1.83 S/m (P.2040 1.49);
    /// - wet ground (ε' 11.9432): m_v = 0.235053; σ at 10 GHz 1.84 S/m (P.2040 2.99).
    ///
    /// P.2040's medium dry and wet grounds have nearly the same ε' at 10 GHz (their laws cross
    /// near 10.1 GHz), so above 10 GHz they are nearly the same soil; they differ in σ, which
    /// the single water content cannot fit at the same time.
    pub fn p527_water_content(self) -> Option<f64> {
        match self {
            Material::VeryDryGround => Some(0.0),
            Material::MediumDryGround => Some(0.234_467_735),
            Material::WetGround => Some(0.235_053_238),
            _ => None,
        }
    }

    /// Relative permittivity eps_r' and conductivity sigma (S/m) at `freq_hz` (P.2040 eqs (58),
    /// (59) as cited by MathWorks; Sionna `itu.py`). Outside the table's range this is an error
    /// unless `extrapolate` (Sionna refuses; MathWorks extrapolates), except for the ground
    /// classes above 10 GHz: there the P.527-6 soil model of [`Material::p527_water_content`]
    /// gives ε' and σ = 2π f ε0 ε'' (`p527::soil`, eqs (57)-(70)) whether or not `extrapolate`.
    /// At and below 10 GHz the grounds are P.2040's as before.
    pub fn eps_sigma(self, freq_hz: f64, extrapolate: bool) -> Result<(f64, f64), String> {
        let law = self
            .law()
            .ok_or_else(|| format!("{self:?} has no P.2040 law"))?;
        let f = freq_hz / 1e9;
        let ground_water = self.p527_water_content();
        if let Some(m_v) = ground_water.filter(|_| f > GROUND_P2040_TOP_GHZ) {
            let (re, im) = p527::soil(&p527::LOAM, f, m_v)
                .map_err(|e| format!("{} above 10 GHz: {e}", self.itu_type().unwrap_or("?")))?;
            return Ok((re, p527::conductivity(f, im)));
        }
        // A ground's P.2040 law holds up to 10 GHz itself, where P.527 takes over.
        let in_range =
            law.lo_ghz < f && (f < law.hi_ghz || (ground_water.is_some() && f == law.hi_ghz));
        if !in_range && !extrapolate {
            return Err(format!(
                "{} is specified for {}-{} GHz by ITU-R P.2040, not {f} GHz ({EXTRAPOLATE_HINT} to extrapolate its law anyway)",
                self.itu_type().unwrap_or("?"),
                law.lo_ghz,
                law.hi_ghz
            ));
        }
        Ok((law.a * f.powf(law.b), law.c * f.powf(law.d)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values computed apart from ITU-R P.2040 Table 3: concrete at 3.5 GHz eps 5.24,
    /// sigma 0.1231; at 28 GHz sigma 0.626; medium-dry ground at 3.5 GHz eta = 13.234 - j1.385.
    #[test]
    fn table_3_test_vectors() {
        let (e, s) = Material::Concrete.eps_sigma(3.5e9, false).unwrap();
        assert!(
            (e - 5.24).abs() < 1e-12 && (s - 0.1231).abs() < 5e-5,
            "{e} {s}"
        );
        let (_, s) = Material::Concrete.eps_sigma(28e9, false).unwrap();
        assert!((s - 0.626).abs() < 5e-4, "{s}");
        let (e, s) = Material::MediumDryGround.eps_sigma(3.5e9, false).unwrap();
        let im = 17.98 * s / 3.5;
        assert!(
            (e - 13.234).abs() < 5e-4 && (im - 1.385).abs() < 1e-3,
            "{e} {im}"
        );
    }

    #[test]
    fn out_of_range_is_an_error_unless_extrapolating() {
        let e = Material::Brick.eps_sigma(60e9, false).unwrap_err();
        assert!(e.contains("1-40 GHz"), "{e}");
        // The error names the switch as a graph or a command line spells it.
        assert!(
            e.contains("`extrapolate: true`") && e.contains("--extrapolate"),
            "{e}"
        );
        assert!(Material::Brick.eps_sigma(60e9, true).is_ok());
        // Ground below P.2040's range is still an error.
        assert!(Material::WetGround.eps_sigma(0.5e9, false).is_err());
    }

    const GROUNDS: [Material; 3] = [
        Material::VeryDryGround,
        Material::MediumDryGround,
        Material::WetGround,
    ];

    /// Each ground's water content reproduces its P.2040 ε' at 10 GHz (the very dry one within
    /// 0.05 %: dry loam), so ε' is continuous where P.527 takes over.
    #[test]
    fn ground_water_contents_match_p2040_at_10_ghz() {
        for m in GROUNDS {
            let law = m.law().unwrap();
            let p2040 = law.a * 10f64.powf(law.b);
            let (p527, _) = p527::soil(&p527::LOAM, 10.0, m.p527_water_content().unwrap()).unwrap();
            let tol = if m == Material::VeryDryGround {
                2e-3
            } else {
                1e-6
            };
            assert!(
                ((p527 - p2040) / p2040).abs() < tol,
                "{m:?}: {p527} vs {p2040}"
            );
            // At 10 GHz itself the grounds are still P.2040's.
            let (e, s) = m.eps_sigma(10e9, false).unwrap();
            assert_eq!((e, s), (p2040, law.c * 10f64.powf(law.d)));
        }
    }

    /// Above 10 GHz the grounds are P.527 soil with no `extrapolate`, finite and lossy (but for
    /// the dry loam), at Brooklyn's 16.95 GHz and Boulder's 28 GHz; values from
    /// `scripts/p527_reference.py` (same formulas).
    #[test]
    fn ground_above_10_ghz_is_p527_soil() {
        for (m, f, eps, sigma) in [
            (Material::VeryDryGround, 16.95, 2.9986, 0.0),
            (Material::VeryDryGround, 28.0, 2.9986, 0.0),
            (Material::MediumDryGround, 16.95, 9.6167, 3.4239),
            (Material::MediumDryGround, 28.0, 7.2539, 4.9538),
            (Material::WetGround, 16.95, 9.6372, 3.4376),
            (Material::WetGround, 28.0, 7.2666, 4.9737),
        ] {
            let (e, s) = m.eps_sigma(f * 1e9, false).unwrap();
            assert!(
                (e - eps).abs() < 1e-3 && (s - sigma).abs() < 1e-3,
                "{m:?} {f}: {e} {s}"
            );
            // `extrapolate` changes nothing for ground: P.527 is not an extrapolation.
            assert_eq!(m.eps_sigma(f * 1e9, true).unwrap(), (e, s));
        }
        // The other classes keep their P.2040 ranges: brick to 40 GHz, fine at 28 GHz.
        assert!(Material::Brick.eps_sigma(28e9, false).is_ok());
        assert!(Material::WetGround.eps_sigma(f64::NAN, false).is_err());
        assert!(Material::WetGround.eps_sigma(2e12, false).is_err());
    }

    /// Below 10 GHz nothing changed: the ground laws are bit for bit P.2040's.
    #[test]
    fn ground_below_10_ghz_is_p2040() {
        for m in GROUNDS {
            let law = m.law().unwrap();
            for f in [1.5, 3.6, 6.75, 9.99] {
                let got = m.eps_sigma(f * 1e9, false).unwrap();
                let f = f * 1e9 / 1e9;
                assert_eq!(got, (law.a * f.powf(law.b), law.c * f.powf(law.d)));
            }
        }
    }

    /// With the thickness table a window transmits like a window: at 3.5 GHz and normal incidence
    /// 1 cm of glass loses 3.17 dB (mostly reflection at eps 6.31), 20 cm of concrete 19.03 dB
    /// (0.1 m: 10.36 dB); values from the slab formula of ITU-R P.2040 §2.2.2.2 evaluated apart.
    #[test]
    fn glass_transmits_and_concrete_does_not() {
        use crate::rf::em::{db, permittivity, slab};
        let lam = crate::rf::wavelength(3.5e9);
        let t = |m: Material| {
            let eta = permittivity(m, 3.5e9, false).unwrap();
            let (_, (t_te, _)) = slab(1.0, eta, m.slab_thickness_m(), lam);
            -db(t_te)
        };
        let (glass, concrete) = (t(Material::Glass), t(Material::Concrete));
        assert!((glass - 3.170).abs() < 0.01, "glass {glass} dB");
        assert!((concrete - 19.025).abs() < 0.01, "concrete {concrete} dB");
        let eta = permittivity(Material::Concrete, 3.5e9, false).unwrap();
        let (_, (t01, _)) = slab(1.0, eta, 0.1, lam);
        assert!((-db(t01) - 10.36).abs() < 0.01);
    }

    #[test]
    fn names_round_trip() {
        for m in Material::ALL {
            assert_eq!(Material::from_u8(m as u8), Some(m));
            let name = m
                .itu_type()
                .map(|t| format!("itu_{t}"))
                .unwrap_or("foliage".into());
            assert_eq!(Material::from_name(&name), Some(m));
        }
        assert_eq!(
            Material::from_name("mat-itu_concrete"),
            Some(Material::Concrete)
        );
    }
}
