//! Radio materials: the ITU-R P.2040 classes (Table 3) as Sionna RT names them, plus foliage.
//!
//! # References
//! ITU-R P.2040-3, Table 3; the same values as Sionna RT v1.0.1 `radio_materials/itu.py`
//! (../shared/reference/rf.md §1).

use crate::artifact::Material;

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
    /// wall as one surface with the single-layer slab coefficients (rf.md §2.2), so the thickness
    /// decides how much a surface transmits. Sionna's default is 0.1 m for everything; these are
    /// typical thicknesses of what each class is on a building:
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

    /// Relative permittivity eps_r' and conductivity sigma (S/m) at `freq_hz` (P.2040 eqs (58),
    /// (59) as cited by MathWorks; Sionna `itu.py`). Outside the table's range this is an error
    /// unless `extrapolate` (Sionna refuses; MathWorks extrapolates).
    pub fn eps_sigma(self, freq_hz: f64, extrapolate: bool) -> Result<(f64, f64), String> {
        let law = self
            .law()
            .ok_or_else(|| format!("{self:?} has no P.2040 law"))?;
        let f = freq_hz / 1e9;
        let in_range = law.lo_ghz < f && f < law.hi_ghz;
        if !in_range && !extrapolate {
            return Err(format!(
                "{} is specified for {}-{} GHz by ITU-R P.2040, not {f} GHz (allow extrapolation to use it anyway)",
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

    /// rf.md §8 / compute_checks.out: concrete at 3.5 GHz eps 5.24, sigma 0.1231; at 28 GHz
    /// sigma 0.626; medium-dry ground at 3.5 GHz eta = 13.234 - j1.385.
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
        assert!(Material::Brick.eps_sigma(60e9, true).is_ok());
    }

    /// With the thickness table a window transmits like a window: at 3.5 GHz and normal incidence
    /// 1 cm of glass loses 3.17 dB (mostly reflection at eps 6.31), 20 cm of concrete 19.03 dB
    /// (0.1 m: 10.36 dB, rf.md §8); values from the slab formula of rf.md §2.2 evaluated apart.
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
