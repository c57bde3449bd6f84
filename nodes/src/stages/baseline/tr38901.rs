//! The 3GPP TR 38.901 §7.4 path-loss baseline (Table 7.4.1-1): UMa, UMi street canyon and RMa, LOS
//! and NLOS, with the LOS state from a trace of the scene or from the LOS probability of Table
//! 7.4.2-1.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Endpoint, Measurements, Raster};
use crate::rf::antenna::Antenna;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// A TR 38.901 scenario.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Scenario {
    /// Urban macro.
    UMa,
    /// Urban micro, street canyon.
    UMi,
    /// Rural macro.
    RMa,
}

const C: f64 = 3.0e8;

/// Path loss, dB (Table 7.4.1-1; f in GHz, distances and heights in metres). RMa uses the default
/// street width 20 m and building height 5 m; UMa the effective environment height 1 m.
pub fn path_loss(s: Scenario, los: bool, d2d: f64, h_bs: f64, h_ut: f64, fc_ghz: f64) -> f64 {
    let d3d = (d2d * d2d + (h_bs - h_ut).powi(2)).sqrt();
    let lg = f64::log10;
    match s {
        Scenario::UMa => {
            let pl_los = two_slope_los((28.0, 22.0, 9.0), d2d, h_bs, h_ut, fc_ghz);
            if los {
                pl_los
            } else {
                let nlos = 13.54 + 39.08 * lg(d3d) + 20.0 * lg(fc_ghz) - 0.6 * (h_ut - 1.5);
                pl_los.max(nlos)
            }
        }
        Scenario::UMi => {
            let pl_los = two_slope_los((32.4, 21.0, 9.5), d2d, h_bs, h_ut, fc_ghz);
            if los {
                pl_los
            } else {
                let nlos = 35.3 * lg(d3d) + 22.4 + 21.3 * lg(fc_ghz) - 0.3 * (h_ut - 1.5);
                pl_los.max(nlos)
            }
        }
        Scenario::RMa => {
            let (w, h): (f64, f64) = (20.0, 5.0);
            let dbp = 2.0 * std::f64::consts::PI * h_bs * h_ut * fc_ghz * 1e9 / C;
            let pl1 = |d: f64| {
                20.0 * lg(40.0 * std::f64::consts::PI * d * fc_ghz / 3.0)
                    + (0.03 * h.powf(1.72)).min(10.0) * lg(d)
                    - (0.044 * h.powf(1.72)).min(14.77)
                    + 0.002 * lg(h) * d
            };
            let pl_los = if d2d <= dbp {
                pl1(d3d)
            } else {
                pl1(dbp) + 40.0 * lg(d3d / dbp)
            };
            if los {
                pl_los
            } else {
                let nlos = 161.04 - 7.1 * lg(w) + 7.5 * lg(h)
                    - (24.37 - 3.7 * (h / h_bs).powi(2)) * lg(h_bs)
                    + (43.42 - 3.1 * lg(h_bs)) * (lg(d3d) - 3.0)
                    + 20.0 * lg(fc_ghz)
                    - (3.2 * lg(11.75 * h_ut).powi(2) - 4.97);
                pl_los.max(nlos)
            }
        }
    }
}

/// The UMa/UMi LOS loss: `a + b log10 d3D + 20 log10 fc` up to the breakpoint d'BP (effective
/// heights over hE = 1 m), `a + 40 log10 d3D + 20 log10 fc − c log10(d'BP² + (hBS − hUT)²)` beyond,
/// for `(a, b, c)` = (28, 22, 9) in UMa and (32.4, 21, 9.5) in UMi.
fn two_slope_los((a, b, c): (f64, f64, f64), d2d: f64, h_bs: f64, h_ut: f64, fc_ghz: f64) -> f64 {
    let lg = f64::log10;
    let d3d = (d2d * d2d + (h_bs - h_ut).powi(2)).sqrt();
    let dbp = 4.0 * (h_bs - 1.0) * (h_ut - 1.0) * fc_ghz * 1e9 / C;
    if d2d <= dbp {
        a + b * lg(d3d) + 20.0 * lg(fc_ghz)
    } else {
        a + 40.0 * lg(d3d) + 20.0 * lg(fc_ghz) - c * lg(dbp * dbp + (h_bs - h_ut).powi(2))
    }
}

/// LOS probability (Table 7.4.2-1).
pub fn los_probability(s: Scenario, d2d: f64, h_ut: f64) -> f64 {
    match s {
        Scenario::RMa => {
            if d2d <= 10.0 {
                1.0
            } else {
                (-(d2d - 10.0) / 1000.0).exp()
            }
        }
        Scenario::UMi => {
            if d2d <= 18.0 {
                1.0
            } else {
                18.0 / d2d + (-d2d / 36.0).exp() * (1.0 - 18.0 / d2d)
            }
        }
        Scenario::UMa => {
            if d2d <= 18.0 {
                return 1.0;
            }
            let c = if h_ut <= 13.0 {
                0.0
            } else {
                ((h_ut - 13.0) / 10.0).powf(1.5)
            };
            (18.0 / d2d + (-d2d / 63.0).exp() * (1.0 - 18.0 / d2d))
                * (1.0 + c * 1.25 * (d2d / 100.0).powi(3) * (-d2d / 150.0).exp())
        }
    }
}

/// Params of [`Tr38901`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tr38901Params {
    /// The scenario.
    pub scenario: Scenario,
    /// Transmit antenna: its gain toward each receiver is added to the link (the path loss falls
    /// by it). Its `azimuth_deg` is a compass bearing from grid north (the site frame's +y); a
    /// link's own azimuth (`Endpoint::azimuth_deg`) replaces it, as in `Trace`. Default none:
    /// the TR 38.901 formulas alone (an isotropic antenna).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tx_antenna: Option<Antenna>,
}

/// Predicted path loss per link by TR 38.901. With a `los` input (a `Trace` of the scene), each
/// link takes the LOS or NLOS formula by whether the trace found a line-of-sight path; without,
/// the LOS and NLOS losses are mixed by the LOS probability (power-weighted). With a
/// `tx_antenna`, its gain toward the receiver (along the straight line between the two, at their
/// site-frame heights) is subtracted from the loss.
pub struct Tr38901;

impl Stage for Tr38901 {
    const KIND: &'static str = "Tr38901";
    // 2: an optional transmit antenna (no change without one).
    const VERSION: u32 = 2;
    const DOC: &'static str =
        "3GPP TR 38.901 UMa/UMi/RMa path loss per link, LOS from a trace or the LOS probability";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("links", ArtifactType::Measurements, "the links"),
        InputSpec::optional(
            "los",
            ArtifactType::Measurements,
            "a trace of the same links: its `los` flags",
        ),
        InputSpec::optional(
            "terrain",
            ArtifactType::Raster,
            "the terrain, for heights above ground",
        ),
    ];
    type Params = Tr38901Params;
    type Output = Measurements;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        match &p.tx_antenna {
            Some(a) => crate::rf::antenna::check_antenna("tx_antenna", a),
            None => Ok(()),
        }
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Measurements, StageError> {
        let links: &Measurements = inputs.one("links")?;
        let los: Option<&Measurements> = inputs.optional("los")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        if let Some(l) = los
            && l.links.len() != links.links.len()
        {
            return Err(StageError::Failed(
                "the los input must trace the same links".into(),
            ));
        }
        // Absolute heights stand on the terrain, or on z = 0 without one.
        let ground = |e: &Endpoint| terrain.and_then(|t| t.bilinear(e.x, e.y)).unwrap_or(0.0);
        let height = |e: &Endpoint| {
            e.above_ground(Some(ground(e)))
                .expect("a ground height is given")
        };
        let mut out = links.clone();
        for (i, l) in out.links.iter_mut().enumerate() {
            let d2d = (l.tx.x - l.rx.x).hypot(l.tx.y - l.rx.y).max(1.0);
            let (h_bs, h_ut) = (height(&l.tx).max(1.5), height(&l.rx).clamp(1.0, 22.5));
            let fc = l.freq_hz / 1e9;
            let pl = match los.and_then(|m| m.links[i].los) {
                Some(flag) => path_loss(p.scenario, flag, d2d, h_bs, h_ut, fc),
                None => {
                    let pr = los_probability(p.scenario, d2d, h_ut);
                    let lin = |db: f64| 10f64.powf(-db / 10.0);
                    -10.0
                        * (pr * lin(path_loss(p.scenario, true, d2d, h_bs, h_ut, fc))
                            + (1.0 - pr) * lin(path_loss(p.scenario, false, d2d, h_bs, h_ut, fc)))
                        .log10()
                }
            };
            let g_db = match &p.tx_antenna {
                Some(a) => antenna_gain_db(a, &l.tx, &l.rx, &ground),
                None => 0.0,
            };
            l.path_loss_db = Some(pl - g_db);
            l.rx_power_dbm = None;
            l.los = los.and_then(|m| m.links[i].los);
        }
        Ok(out)
    }
}

/// The gain (dBi) of `antenna` at `tx` toward `rx`, along the straight line between their
/// site-frame positions (heights on the ground under each). `tx`'s own azimuth, when it has
/// one, replaces the antenna's, as in `Trace`. Straight down when the two coincide in plan and
/// height.
fn antenna_gain_db(
    antenna: &Antenna,
    tx: &Endpoint,
    rx: &Endpoint,
    ground: &dyn Fn(&Endpoint) -> f64,
) -> f64 {
    let mut a = *antenna;
    if let Some(az) = tx.azimuth_deg.filter(|v| v.is_finite()) {
        a.azimuth_deg = az;
    }
    let z = |e: &Endpoint| {
        e.absolute_z(Some(ground(e)))
            .expect("a ground height is given")
    };
    let d = [rx.x - tx.x, rx.y - tx.y, z(rx) - z(tx)];
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let k = if n > 0.0 {
        d.map(|v| v / n)
    } else {
        [0.0, 0.0, -1.0]
    };
    10.0 * a.gain_toward(k).log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values computed apart from the Table 7.4.1-1 formulas (hBS 25/10/35 m, hUT
    /// 1.5 m), every cell of the table.
    #[test]
    fn table_test_vectors() {
        let rows = [
            (3.5, 50.0, [77.21, 92.51, 79.09, 94.18, 79.15, 83.26]),
            (3.5, 200.0, [89.57, 114.46, 91.61, 115.23, 90.15, 103.64]),
            (
                3.5,
                1000.0,
                [109.41, 141.67, 119.15, 139.89, 105.46, 130.42],
            ),
            (28.0, 50.0, [95.27, 110.57, 97.15, 113.42, 97.21, 101.32]),
            (
                28.0,
                200.0,
                [107.63, 132.52, 109.67, 134.46, 108.21, 121.71],
            ),
            (
                28.0,
                1000.0,
                [122.95, 159.73, 124.34, 159.13, 123.52, 148.49],
            ),
        ];
        for (fc, d, want) in rows {
            let got = [
                path_loss(Scenario::UMa, true, d, 25.0, 1.5, fc),
                path_loss(Scenario::UMa, false, d, 25.0, 1.5, fc),
                path_loss(Scenario::UMi, true, d, 10.0, 1.5, fc),
                path_loss(Scenario::UMi, false, d, 10.0, 1.5, fc),
                path_loss(Scenario::RMa, true, d, 35.0, 1.5, fc),
                path_loss(Scenario::RMa, false, d, 35.0, 1.5, fc),
            ];
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 0.011, "fc {fc} d {d}: {got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn los_probability_test_vectors() {
        let close = |a: f64, b: f64| assert!((a - b).abs() < 6e-5, "{a} vs {b}");
        close(los_probability(Scenario::UMi, 50.0, 1.5), 0.5196);
        close(los_probability(Scenario::UMa, 50.0, 1.5), 0.6494);
        close(los_probability(Scenario::RMa, 50.0, 1.5), 0.9608);
        close(los_probability(Scenario::UMi, 200.0, 1.5), 0.0935);
        close(los_probability(Scenario::UMa, 200.0, 1.5), 0.1280);
        close(los_probability(Scenario::RMa, 1000.0, 1.5), 0.3716);
        close(los_probability(Scenario::UMa, 200.0, 20.0), 0.3257);
    }

    #[test]
    fn a_sector_antenna_adds_its_gain_toward_each_receiver() {
        use crate::artifact::{Height, Link};
        use crate::rf::antenna::{Pattern, Polarization};
        use crate::stage::Slot;
        use crate::{Artifact, Site};
        use std::sync::Arc;
        let end = |x: f64, y: f64, azimuth_deg: Option<f64>| Endpoint {
            id: String::new(),
            x,
            y,
            z: Height::Absolute(10.0),
            azimuth_deg,
        };
        let link = |rx: Endpoint, az: Option<f64>| Link {
            tx: end(0.0, 0.0, az),
            rx,
            freq_hz: 3.5e9,
            path_loss_db: None,
            rx_power_dbm: Some(-90.0),
            tx_eirp_dbm: None,
            los: None,
        };
        // Level links (both ends 10 m up): along the bearing, 90° off it, and one whose own
        // azimuth (east) replaces the antenna's (north).
        let links = Measurements {
            links: vec![
                link(end(0.0, 200.0, None), None),
                link(end(200.0, 0.0, None), None),
                link(end(200.0, 0.0, None), Some(90.0)),
            ],
        };
        let inputs =
            Inputs::new().with("links", Slot::One(Arc::new(Artifact::Measurements(links))));
        let site = Site {
            crs: "EPSG:32617".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        let ctx = Ctx::new(&site, &[]);
        let run = |tx_antenna| {
            let p = Tr38901Params {
                scenario: Scenario::UMa,
                tx_antenna,
            };
            Tr38901::validate(&p).unwrap();
            let m = Tr38901::run(&p, &inputs, &ctx).unwrap();
            m.links
                .iter()
                .map(|l| l.path_loss_db.unwrap())
                .collect::<Vec<_>>()
        };
        let omni = run(None);
        let sector = run(Some(Antenna {
            pattern: Pattern::Tr38901,
            polarization: Polarization::V,
            azimuth_deg: 0.0,
            tilt_deg: 0.0,
        }));
        let off = 8.0 - 12.0 * (90.0f64 / 65.0).powi(2);
        assert!(
            (omni[0] - sector[0] - 8.0).abs() < 1e-9,
            "{omni:?} {sector:?}"
        );
        assert!(
            (omni[1] - sector[1] - off).abs() < 1e-9,
            "{omni:?} {sector:?}"
        );
        assert!(
            (omni[2] - sector[2] - 8.0).abs() < 1e-9,
            "{omni:?} {sector:?}"
        );
        // Without the param the params serialize as before (no `tx_antenna` key).
        let p = Tr38901Params {
            scenario: Scenario::UMa,
            tx_antenna: None,
        };
        assert_eq!(serde_json::to_string(&p).unwrap(), r#"{"scenario":"UMa"}"#);
        let bad = Tr38901Params {
            scenario: Scenario::UMa,
            tx_antenna: Some(Antenna {
                azimuth_deg: f64::NAN,
                ..Antenna::default()
            }),
        };
        assert_eq!(Tr38901::validate(&bad).unwrap_err().field, "tx_antenna");
    }
}
