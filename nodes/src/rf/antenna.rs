//! Antenna patterns (Sionna RT's EM primer, TR 38.901 Table 7.3-1): the field pattern C(θ, φ) = √G
//! F as a vertical (θ̂) and horizontal (φ̂) component, in the antenna's own frame.

use serde::{Deserialize, Serialize};

use crate::stage::ParamError;

/// A radiation pattern.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Pattern {
    /// Unit gain in every direction.
    Isotropic,
    /// A short dipole along the antenna's z axis: G = 1.5 sin²θ.
    Dipole,
    /// The 3GPP TR 38.901 sector element: 65° beamwidths, 30 dB front-to-back, 8 dBi peak.
    Tr38901,
}

/// Polarisation of the element.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Polarization {
    /// Field along θ̂.
    V,
    /// Field along φ̂.
    H,
}

/// An antenna: pattern, polarisation, and where its boresight points (a compass bearing in the
/// site frame, and a downtilt, degrees).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Antenna {
    /// The pattern.
    pub pattern: Pattern,
    /// The polarisation.
    pub polarization: Polarization,
    /// Boresight azimuth: a compass bearing, degrees clockwise from grid north (the site frame's
    /// +y), so 0 points along +y and 90 along +x. Grid north is not true north: a true bearing
    /// becomes a grid bearing by subtracting the meridian convergence (`ReadMeasurements` does so
    /// for the bearings it reads).
    pub azimuth_deg: f64,
    /// Downtilt, degrees below the horizon.
    pub tilt_deg: f64,
}

impl Default for Antenna {
    fn default() -> Self {
        Antenna {
            pattern: Pattern::Isotropic,
            polarization: Polarization::V,
            azimuth_deg: 0.0,
            tilt_deg: 0.0,
        }
    }
}

/// Power gain (linear) of `pattern` at zenith angle `theta` and azimuth `phi` (radians) in the
/// antenna frame (boresight along +x).
pub fn gain(pattern: Pattern, theta: f64, phi: f64) -> f64 {
    match pattern {
        Pattern::Isotropic => 1.0,
        Pattern::Dipole => 1.5 * theta.sin().powi(2),
        Pattern::Tr38901 => {
            let th = theta.to_degrees();
            let ph = phi.to_degrees();
            let a_v = -(12.0 * ((th - 90.0) / 65.0).powi(2)).min(30.0);
            let a_h = -(12.0 * (ph / 65.0).powi(2)).min(30.0);
            let a = -(-(a_v + a_h)).min(30.0);
            10f64.powf((a + 8.0) / 10.0)
        }
    }
}

/// The slopes of [`gain`] in dB per radian of zenith θ and azimuth φ (the antenna frame's): 0
/// where a TR 38.901 term is saturated at 30 dB.
fn pattern_slopes_db(pattern: Pattern, theta: f64, phi: f64) -> (f64, f64) {
    match pattern {
        Pattern::Isotropic => (0.0, 0.0),
        Pattern::Dipole => (
            20.0 / std::f64::consts::LN_10 * theta.cos() / theta.sin(),
            0.0,
        ),
        Pattern::Tr38901 => {
            let (th, ph) = (theta.to_degrees(), phi.to_degrees());
            let v = 12.0 * ((th - 90.0) / 65.0).powi(2);
            let h = 12.0 * (ph / 65.0).powi(2);
            let (a_v, a_h) = (-v.min(30.0), -h.min(30.0));
            if -(a_v + a_h) >= 30.0 {
                return (0.0, 0.0);
            }
            let per_radian = 180.0 / std::f64::consts::PI;
            let d_v = if v < 30.0 {
                -24.0 * (th - 90.0) / (65.0 * 65.0)
            } else {
                0.0
            };
            let d_h = if h < 30.0 {
                -24.0 * ph / (65.0 * 65.0)
            } else {
                0.0
            };
            (d_v * per_radian, d_h * per_radian)
        }
    }
}

impl Antenna {
    /// An antenna as the command line and the Python package name it: `iso`, `dipole` or
    /// `tr38901:BEARING_DEG:TILT_DEG` (the TR 38.901 sector, boresight at a compass bearing
    /// clockwise from the frame's +y, downtilt below the horizon), vertically polarised.
    pub fn parse(s: &str) -> Result<Antenna, String> {
        let expected = "expected iso, dipole or tr38901:BEARING_DEG:TILT_DEG";
        let pattern = |pattern| Antenna {
            pattern,
            ..Antenna::default()
        };
        let parts: Vec<&str> = s.split(':').map(str::trim).collect();
        match parts.as_slice() {
            ["iso"] => Ok(pattern(Pattern::Isotropic)),
            ["dipole"] => Ok(pattern(Pattern::Dipole)),
            ["tr38901", bearing, tilt] => {
                let num = |name: &str, v: &str| match v.parse::<f64>() {
                    Ok(x) if x.is_finite() => Ok(x),
                    _ => Err(format!("{name} {v:?} is not a finite number of degrees")),
                };
                Ok(Antenna {
                    azimuth_deg: num("bearing", bearing)?,
                    tilt_deg: num("tilt", tilt)?,
                    ..pattern(Pattern::Tr38901)
                })
            }
            ["tr38901", ..] => Err(format!("{expected}: the sector needs a bearing and a tilt")),
            _ => Err(format!("{expected}, found {s:?}")),
        }
    }

    /// The transmitted field direction and amplitude for the unit direction `k` (site frame, away
    /// from the antenna): √G times θ̂ or φ̂ of the site frame (the polarisation stays vertical or
    /// horizontal in the site frame; the pattern is evaluated in the antenna's rotated frame).
    #[inline]
    pub fn field(&self, k: [f64; 3]) -> [f64; 3] {
        let g = self.gain_toward(k).sqrt();
        let (th, ph) = spherical_basis(k);
        let e = match self.polarization {
            Polarization::V => th,
            Polarization::H => ph,
        };
        e.map(|v| v * g)
    }

    /// Power gain (linear) toward the unit direction `k` (site frame, away from the antenna):
    /// the pattern evaluated in the antenna's rotated frame.
    #[inline]
    pub fn gain_toward(&self, k: [f64; 3]) -> f64 {
        match self.pattern {
            Pattern::Isotropic => 1.0,
            p => {
                let (theta, phi) = self.local_angles(k);
                gain(p, theta, phi)
            }
        }
    }

    /// The gain toward `k` in dB and its slopes in the antenna's tilt and bearing, dB per degree:
    /// the pattern's derivative carried through the rotation of [`Antenna::local_angles`]
    /// (0 where the pattern is flat, saturated, or at the frame's poles). What a calibration
    /// fits an antenna's tilt and bearing with (`rf::calibration`).
    pub fn gain_slopes_db(&self, k: [f64; 3]) -> (f64, f64, f64) {
        let g_db = 10.0 * self.gain_toward(k).log10();
        if self.pattern == Pattern::Isotropic {
            return (g_db, 0.0, 0.0);
        }
        let Frame {
            x1,
            y1,
            x2,
            z2,
            tilt: (st, ct),
        } = self.frame(k);
        let sin_theta = (1.0 - z2 * z2).max(0.0).sqrt();
        let rho2 = x2 * x2 + y1 * y1;
        if sin_theta < 1e-9 || rho2 < 1e-18 {
            return (g_db, 0.0, 0.0);
        }
        // θ = acos z2 and φ = atan2(y1, x2), differentiated in the tilt t and in the rotation α
        // = bearing - 90° (radians): dz2/dt = x2, dx2/dt = -z2; dx1/dα = -y1, dy1/dα = x1.
        let (dtheta_dt, dphi_dt) = (-x2 / sin_theta, y1 * z2 / rho2);
        let (dtheta_da, dphi_da) = (st * y1 / sin_theta, (x2 * x1 + ct * y1 * y1) / rho2);
        let theta = z2.clamp(-1.0, 1.0).acos();
        let phi = y1.atan2(x2);
        let (dg_dtheta, dg_dphi) = pattern_slopes_db(self.pattern, theta, phi);
        let per_degree = std::f64::consts::PI / 180.0;
        (
            g_db,
            (dg_dtheta * dtheta_dt + dg_dphi * dphi_dt) * per_degree,
            (dg_dtheta * dtheta_da + dg_dphi * dphi_da) * per_degree,
        )
    }

    /// Zenith and azimuth of `k` in the antenna frame: rotate about z by -(90° - bearing) (the
    /// bearing, clockwise from +y, is 90° - the angle counter-clockwise from +x), then by -tilt
    /// about the new y axis (a downtilt points boresight below the horizon).
    fn local_angles(&self, k: [f64; 3]) -> (f64, f64) {
        let Frame { y1, x2, z2, .. } = self.frame(k);
        let theta = z2.clamp(-1.0, 1.0).acos();
        let phi = y1.atan2(x2);
        (theta, phi)
    }

    /// `k` rotated into the antenna frame ([`Antenna::local_angles`]), with the intermediate
    /// coordinates its derivatives need.
    #[inline]
    fn frame(&self, k: [f64; 3]) -> Frame {
        let (sa, ca) = (self.azimuth_deg - 90.0).to_radians().sin_cos();
        let x1 = ca * k[0] - sa * k[1];
        let y1 = sa * k[0] + ca * k[1];
        let z1 = k[2];
        let (st, ct) = self.tilt_deg.to_radians().sin_cos();
        Frame {
            x1,
            y1,
            x2: ct * x1 - st * z1,
            z2: st * x1 + ct * z1,
            tilt: (st, ct),
        }
    }
}

/// A direction after the bearing's rotation (x1, y1) and then the tilt's (x2, y1, z2), with the
/// tilt's sine and cosine.
struct Frame {
    x1: f64,
    y1: f64,
    x2: f64,
    z2: f64,
    tilt: (f64, f64),
}

/// (θ̂, φ̂) at direction `k`; at the poles φ̂ is taken as +y and θ̂ = φ̂ × k.
#[inline]
pub fn spherical_basis(k: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    // `k` is a unit vector: no overflow for hypot's slower care to guard against.
    let rho = (k[0] * k[0] + k[1] * k[1]).sqrt();
    if rho < 1e-12 {
        let ph = [0.0, 1.0, 0.0];
        let th = [ph[1] * k[2], -ph[0] * k[2], 0.0];
        return (th, ph);
    }
    let (cp, sp) = (k[0] / rho, k[1] / rho);
    let (ct, st) = (k[2], rho);
    ([ct * cp, ct * sp, -st], [-sp, cp, 0.0])
}

/// An antenna's boresight must be finite (RON writes `NaN` and `inf`): a NaN azimuth would make
/// every gain NaN without an error.
pub fn check_antenna(field: &'static str, a: &Antenna) -> Result<(), ParamError> {
    if !(a.azimuth_deg.is_finite() && a.tilt_deg.is_finite()) {
        return Err(ParamError::new(
            field,
            format!(
                "expected a finite azimuth_deg and tilt_deg, found {} and {}",
                a.azimuth_deg, a.tilt_deg
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The gain's slopes in tilt and bearing against central differences of the gain itself,
    /// for the sector and the dipole over directions all round (the sector's 30 dB kinks, where
    /// the slope jumps, left out).
    #[test]
    fn gain_slopes_match_central_differences() {
        for pattern in [Pattern::Tr38901, Pattern::Dipole] {
            let a = Antenna {
                pattern,
                polarization: Polarization::V,
                azimuth_deg: 130.0,
                tilt_deg: 6.0,
            };
            let mut checked = 0;
            for i in 0..400 {
                let z = -0.95 + 1.9 * (i as f64 + 0.5) / 400.0;
                let az = 2.399963 * i as f64;
                let r = (1.0 - z * z).sqrt();
                let k = [r * az.cos(), r * az.sin(), z];
                let db = |a: &Antenna| 10.0 * a.gain_toward(k).log10();
                let h = 1e-5;
                let fd = |f: &dyn Fn(f64) -> Antenna| (db(&f(h)) - db(&f(-h))) / (2.0 * h);
                let tilt = fd(&|d| Antenna {
                    tilt_deg: a.tilt_deg + d,
                    ..a
                });
                let bearing = fd(&|d| Antenna {
                    azimuth_deg: a.azimuth_deg + d,
                    ..a
                });
                let (g, st, sb) = a.gain_slopes_db(k);
                assert!((g - db(&a)).abs() < 1e-12);
                if db(&a) <= 8.0 - 29.9 {
                    continue; // at the sector's 30 dB floor the slope jumps
                }
                assert!(
                    (tilt - st).abs() < 1e-4 * (1.0 + tilt.abs())
                        && (bearing - sb).abs() < 1e-4 * (1.0 + bearing.abs()),
                    "{pattern:?} k {k:?}: tilt {st} vs {tilt}, bearing {sb} vs {bearing}"
                );
                checked += 1;
            }
            assert!(checked > 150, "{pattern:?}: {checked}");
        }
    }

    #[test]
    fn patterns_have_their_textbook_gains() {
        assert_eq!(gain(Pattern::Isotropic, 0.3, 1.0), 1.0);
        assert!((gain(Pattern::Dipole, PI / 2.0, 0.0) - 1.5).abs() < 1e-12);
        assert!(gain(Pattern::Dipole, 0.0, 0.0) < 1e-20);
        // TR 38.901: 8 dBi at boresight, -3 dB at 32.5° off it, 30 dB down at the back.
        let g = |th: f64, ph: f64| {
            10.0 * gain(Pattern::Tr38901, th.to_radians(), ph.to_radians()).log10()
        };
        assert!((g(90.0, 0.0) - 8.0).abs() < 1e-12);
        assert!((g(90.0, 32.5) - 5.0).abs() < 1e-12);
        assert!((g(90.0, 180.0) - (8.0 - 30.0)).abs() < 1e-12);
        // Dipole: the power over the sphere is 4π.
        let n = 400;
        let mut sum = 0.0;
        for i in 0..n {
            let th = (i as f64 + 0.5) * PI / n as f64;
            sum += gain(Pattern::Dipole, th, 0.0) * th.sin() * (PI / n as f64) * 2.0 * PI;
        }
        assert!((sum - 4.0 * PI).abs() < 1e-3, "{sum}");
    }

    #[test]
    fn a_tilted_sector_points_down_its_boresight() {
        let a = Antenna {
            pattern: Pattern::Tr38901,
            polarization: Polarization::V,
            azimuth_deg: 90.0,
            tilt_deg: 10.0,
        };
        // Bearing 90°: east, +x.
        let bore = [10f64.to_radians().cos(), 0.0, -10f64.to_radians().sin()];
        let e = a.field(bore);
        let g = e.iter().map(|v| v * v).sum::<f64>();
        assert!((10.0 * g.log10() - 8.0).abs() < 1e-9, "{g}");
        // Vertical polarisation: the field lies in the vertical plane through k (no y part
        // here), across k.
        assert!(e[1].abs() < 1e-12, "{e:?}");
        assert!((e[0] * bore[0] + e[2] * bore[2]).abs() < 1e-12);
    }

    #[test]
    fn bearing_zero_points_to_grid_north_and_bearings_turn_clockwise() {
        let sector = |azimuth_deg: f64| Antenna {
            pattern: Pattern::Tr38901,
            polarization: Polarization::V,
            azimuth_deg,
            tilt_deg: 0.0,
        };
        let db = |a: &Antenna, k: [f64; 3]| 10.0 * a.gain_toward(k).log10();
        // Along the bearing: the element's peak, 8 dBi.
        assert!((db(&sector(0.0), [0.0, 1.0, 0.0]) - 8.0).abs() < 1e-9);
        assert!((db(&sector(90.0), [1.0, 0.0, 0.0]) - 8.0).abs() < 1e-9);
        assert!((db(&sector(210.79), bearing(210.79)) - 8.0).abs() < 1e-9);
        // 90° off boresight (east of a north-pointing sector, and west of it): the closed form
        // 8 - min(12 (90/65)², 30) dB = 8 - 23.0 dB, the same on both sides.
        let off = 8.0 - 12.0 * (90.0f64 / 65.0).powi(2);
        assert!((off - (8.0 - 23.005_917)).abs() < 1e-5, "{off}");
        for k in [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]] {
            assert!((db(&sector(0.0), k) - off).abs() < 1e-9, "{k:?}");
        }
        assert!((db(&sector(30.0), bearing(120.0)) - off).abs() < 1e-9);
        assert!((db(&sector(30.0), bearing(300.0)) - off).abs() < 1e-9);
        // Behind: 30 dB below the peak.
        assert!((db(&sector(0.0), [0.0, -1.0, 0.0]) - (8.0 - 30.0)).abs() < 1e-9);
    }

    /// The horizontal unit vector at compass bearing `b` degrees (clockwise from +y).
    fn bearing(b: f64) -> [f64; 3] {
        let (s, c) = b.to_radians().sin_cos();
        [s, c, 0.0]
    }
}
