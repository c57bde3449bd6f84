//! A synthetic drive test: receivers along the synthetic city's streets, path loss traced through
//! the ground-truth scene with richer settings than the twins get (deeper, with diffraction and
//! diffuse scattering), plus log-normal shadowing. What every twin and baseline is scored against.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, City, Endpoint, Height, Link, Measurements, Scene};
use crate::rf::antenna::Antenna;
use crate::rf::paths::{TraceOptions, trace_links};
use crate::rf::scattering::ScatteringPattern;
use crate::rf::scene::RfScene;
use crate::rng::{gaussian, mix};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::artifact::height_at;

/// Params of [`SynthDriveTest`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthDriveTestParams {
    /// Transmitters: id, (x, y) in the site frame and height above the ground.
    pub transmitters: Vec<(String, (f64, f64, f64))>,
    /// Carrier frequency, Hz.
    pub freq_hz: f64,
    /// Receiver spacing along each street, metres. Default 10.
    #[serde(default = "ten")]
    pub spacing_m: f64,
    /// Receiver height above the ground, metres. Default 1.5.
    #[serde(default = "one_and_a_half")]
    pub rx_height_m: f64,
    /// Log-normal shadowing standard deviation, dB. Default 4.
    #[serde(default = "four")]
    pub shadowing_db: f64,
    /// Links weaker than this path gain are below the noise floor and dropped, dB. Default -140.
    #[serde(default = "floor")]
    pub floor_db: f64,
    /// Seed of the shadowing draws. Default 1.
    #[serde(default = "one")]
    pub seed: u64,
    /// The truth trace's settings. Default: depth 3, transmission, diffraction, rough surfaces
    /// (S = 0.3: specular reflections keep √(1 − S²)), 200 000 rays. Diffuse paths are off by
    /// default: their cost grows with the number of receivers.
    #[serde(default = "truth_options")]
    pub options: TraceOptions,
}

fn ten() -> f64 {
    10.0
}
fn one_and_a_half() -> f64 {
    1.5
}
fn four() -> f64 {
    4.0
}
fn floor() -> f64 {
    -140.0
}
fn one() -> u64 {
    1
}
fn truth_options() -> TraceOptions {
    TraceOptions {
        max_depth: 3,
        diffraction: true,
        scattering_coefficient: 0.3,
        scattering_pattern: ScatteringPattern::Lambertian,
        rays: 200_000,
        ..Default::default()
    }
}

/// Links from every transmitter to receivers every `spacing_m` along every street.
pub struct SynthDriveTest;

impl Stage for SynthDriveTest {
    const KIND: &'static str = "SynthDriveTest";
    const VERSION: u32 = 2;
    const DOC: &'static str = "drive-test measurements traced through the ground truth (richer settings) plus log-normal shadowing";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("scene", ArtifactType::Scene, "the ground-truth scene"),
        InputSpec::one(
            "city",
            ArtifactType::City,
            "the synthetic city (streets, terrain)",
        ),
    ];
    type Params = SynthDriveTestParams;
    type Output = Measurements;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if p.transmitters.is_empty() {
            return Err(ParamError::new(
                "transmitters",
                "expected at least one transmitter",
            ));
        }
        if !(p.spacing_m > 0.0) {
            return Err(ParamError::new(
                "spacing_m",
                "expected a positive spacing in metres",
            ));
        }
        if !(p.freq_hz > 0.0 && p.freq_hz.is_finite()) {
            return Err(ParamError::new(
                "freq_hz",
                "expected a positive frequency in Hz",
            ));
        }
        if !(p.shadowing_db >= 0.0) {
            return Err(ParamError::new(
                "shadowing_db",
                "expected a non-negative deviation in dB",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Measurements, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let city: &City = inputs.one("city")?;
        let ground = |x: f64, y: f64| height_at(&city.terrain, x, y);
        let mut receivers = Vec::new();
        for s in &city.streets {
            let len = (s.b[0] - s.a[0]).hypot(s.b[1] - s.a[1]);
            let n = (len / p.spacing_m).floor() as usize;
            for k in 1..n {
                let t = k as f64 * p.spacing_m / len;
                let (x, y) = (
                    s.a[0] + t * (s.b[0] - s.a[0]),
                    s.a[1] + t * (s.b[1] - s.a[1]),
                );
                receivers.push([x, y, ground(x, y) + p.rx_height_m]);
            }
        }
        let rf = RfScene::new(scene, p.freq_hz, false).map_err(StageError::Failed)?;
        ctx.progress.set_total(p.transmitters.len() as u64);
        let mut links = Vec::new();
        for (t, (id, (x, y, h))) in p.transmitters.iter().enumerate() {
            let tx = [*x, *y, ground(*x, *y) + h];
            let pairs: Vec<_> = receivers.iter().map(|r| (tx, *r)).collect();
            let res = trace_links(
                &rf,
                &pairs,
                &Antenna::default(),
                &Antenna::default(),
                &p.options,
                p.freq_hz,
            );
            for (k, (r, got)) in receivers.iter().zip(res).enumerate() {
                if !(got.gain_db > p.floor_db) {
                    continue;
                }
                let shadow =
                    p.shadowing_db * gaussian(mix(p.seed ^ mix(((t as u64) << 32) | k as u64)));
                links.push(Link {
                    tx: Endpoint {
                        id: id.clone(),
                        x: *x,
                        y: *y,
                        z: Height::AboveGround(*h),
                        azimuth_deg: None,
                    },
                    rx: Endpoint {
                        id: format!("rx{k}"),
                        x: r[0],
                        y: r[1],
                        z: Height::AboveGround(p.rx_height_m),
                        azimuth_deg: None,
                    },
                    freq_hz: p.freq_hz,
                    path_loss_db: Some(-got.gain_db + shadow),
                    rx_power_dbm: None,
                    tx_eirp_dbm: None,
                    los: Some(got.paths.iter().any(|q| q.interactions.is_empty())),
                });
            }
            ctx.progress.advance(1);
        }
        Ok(Measurements { links })
    }
}
