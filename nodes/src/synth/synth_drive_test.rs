//! A synthetic drive test: receivers along the synthetic city's streets, path loss traced through
//! the ground-truth scene (by default to the twins' depth, with diffraction and rough surfaces whose
//! specular reflections keep √(1 − S²) of the field; diffuse scattering is an option), plus
//! log-normal shadowing. What every twin and baseline is scored against.

use serde::{Deserialize, Serialize};

use crate::artifact::height_at;
use crate::artifact::{ArtifactType, City, Endpoint, Height, Link, Measurements, Scene};
use crate::rf::antenna::Antenna;
use crate::rf::foliage::{FoliageLaw, is_linear};
use crate::rf::path::TraceOptions;
use crate::rf::paths::trace_links;
use crate::rf::scattering::ScatteringPattern;
use crate::rf::scene::RfScene;
use crate::rng::{gaussian, mix};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`SynthDriveTest`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthDriveTestParams {
    /// Transmitters: id, (x, y) in the site frame and height above the ground.
    pub transmitters: Vec<(String, (f64, f64, f64))>,
    /// Carrier frequency, Hz.
    pub freq_hz: f64,
    /// Receiver spacing along each street, metres (> 0). Default 10.
    #[serde(default = "ten")]
    pub spacing_m: f64,
    /// Receiver height above the ground, metres. Default 1.5.
    #[serde(default = "one_and_a_half")]
    pub rx_height_m: f64,
    /// Log-normal shadowing standard deviation, dB (≥ 0). Default 4.
    #[serde(default = "four")]
    pub shadowing_db: f64,
    /// Links weaker than this path gain are below the noise floor and dropped, dB. Default -140.
    #[serde(default = "floor")]
    pub floor_db: f64,
    /// Seed of the shadowing draws. Default 1.
    #[serde(default = "one")]
    pub seed: u64,
    /// The truth trace's settings. Default: every field's default.
    #[serde(default)]
    pub options: TruthOptions,
}

/// `options` of [`SynthDriveTestParams`]: how far the truth trace goes. It always follows line of
/// sight, specular reflection and transmission; by default it goes as deep as the twins' traces
/// (3) and adds diffraction and rough surfaces (S = 0.3), but not diffuse scattering.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TruthOptions {
    /// Most interactions (reflections + transmissions) along one path. Default 3.
    pub max_depth: u32,
    /// UTD diffraction at convex edges, one edge a path, chained with reflections before and
    /// after it up to the depth. Default true.
    pub diffraction: bool,
    /// Diffuse reflection off the last surface. Default false: its cost grows with the number of
    /// receivers.
    pub diffuse: bool,
    /// Scattering coefficient S of every surface, in [0, 1]; specular reflections keep
    /// √(1 − S²) of the field. Default 0.3 (rough surfaces).
    pub scattering_coefficient: f64,
    /// The diffuse pattern. Default Lambertian.
    pub scattering_pattern: ScatteringPattern,
    /// Rays shot from each transmitter (> 0). Default 200 000.
    pub rays: u32,
    /// Loss inside foliage, dB/m (≥ 0). Default: ITU-R P.833 at `freq_hz`.
    pub foliage_db_per_m: Option<f64>,
    /// How foliage loss grows with depth: `Linear` (γ d, the paper's; default), `P833` (ITU-R
    /// P.833's saturating law, A_m from the recommendation's A1 f^α) or `P833Max(A_m dB)`.
    /// Left out of the params' encoding at its default, so earlier cache entries stay valid.
    #[serde(skip_serializing_if = "is_linear")]
    pub foliage_law: FoliageLaw,
    /// Diffract only where faces turn by at least this many degrees, in [0, 90]. Default 0.
    pub min_wedge_deg: f64,
    /// A wedge diffracts no more than an edge of its length and faces of their width can
    /// (`rf::diffraction::bounded_by_size`); false: the unbounded UTD, as Sionna RT. Default true.
    pub finite_faces: bool,
}

impl Default for TruthOptions {
    fn default() -> Self {
        TruthOptions {
            max_depth: 3,
            diffraction: true,
            diffuse: false,
            scattering_coefficient: 0.3,
            scattering_pattern: ScatteringPattern::Lambertian,
            rays: 200_000,
            foliage_db_per_m: None,
            foliage_law: FoliageLaw::Linear,
            min_wedge_deg: 0.0,
            finite_faces: true,
        }
    }
}

impl TruthOptions {
    /// The tracer's settings.
    pub fn trace_options(&self) -> TraceOptions {
        TraceOptions {
            max_depth: self.max_depth,
            los: true,
            reflection: true,
            transmission: true,
            diffraction: self.diffraction,
            diffuse: self.diffuse,
            scattering_coefficient: self.scattering_coefficient,
            scattering_pattern: self.scattering_pattern,
            rays: self.rays,
            foliage_db_per_m: self.foliage_db_per_m,
            foliage_law: self.foliage_law,
            min_wedge_deg: self.min_wedge_deg,
            wedges_across_objects: true,
            finite_faces: self.finite_faces,
        }
    }
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

/// Links from every transmitter to receivers every `spacing_m` along every street.
pub struct SynthDriveTest;

impl Stage for SynthDriveTest {
    const KIND: &'static str = "SynthDriveTest";
    // 4: slabs take their thickness per material (rf::materials).
    // 5: diffraction square to an edge no longer gives NaN (rf::diffraction).
    // 6: a wedge's 0-face is the face the wave lights (rf::diffraction::Wedge::facing).
    // 7: wedges from the faces' geometry, not the mesh's winding (rf::diffraction::wedges).
    // 8: UTD face factors at any incidence, in rotated bases (rf::diffraction).
    // 9: diffraction chained with reflections before and after the edge (rf::diffracted).
    // 10: wedges lit by flat face, one wedge per run of edge (rf::diffraction::wedges).
    // 11: a wedge diffracts no more than its size allows (rf::diffraction::bounded_by_size).
    // 12: a face's reflection term capped at half a strip's peak, as the UTD's at a boundary.
    // 13: an edge's length for that bound is its run across material changes.
    const VERSION: u32 = 13;
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
        if !p
            .transmitters
            .iter()
            .all(|(_, (x, y, h))| [x, y, h].iter().all(|v| v.is_finite()))
        {
            return Err(ParamError::new(
                "transmitters",
                "expected finite positions and heights in metres",
            ));
        }
        if !(p.spacing_m > 0.0 && p.spacing_m.is_finite()) {
            return Err(ParamError::new(
                "spacing_m",
                "expected a positive spacing in metres",
            ));
        }
        if !p.rx_height_m.is_finite() {
            return Err(ParamError::new(
                "rx_height_m",
                "expected a finite height in metres",
            ));
        }
        if p.floor_db.is_nan() {
            return Err(ParamError::new("floor_db", "expected a path gain in dB"));
        }
        if !(p.freq_hz > 0.0 && p.freq_hz.is_finite()) {
            return Err(ParamError::new(
                "freq_hz",
                "expected a positive frequency in Hz",
            ));
        }
        if !(p.shadowing_db >= 0.0 && p.shadowing_db.is_finite()) {
            return Err(ParamError::new(
                "shadowing_db",
                "expected a non-negative deviation in dB",
            ));
        }
        p.options
            .trace_options()
            .check()
            .map_err(|(field, m)| ParamError::new("options", format!("{field}: {m}")))
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Measurements, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let city: &City = inputs.one("city")?;
        let ground = |x: f64, y: f64| height_at(&city.terrain, x, y);
        // Receivers and links are sized by spacing_m: a tiny spacing is refused before the lists
        // are built (a link keeps two endpoints, about 160 bytes).
        let street_m: f64 = city
            .streets
            .iter()
            .map(|s| (s.b[0] - s.a[0]).hypot(s.b[1] - s.a[1]))
            .sum();
        crate::params::check_bytes(
            "the receivers' links",
            street_m / p.spacing_m * p.transmitters.len() as f64,
            160,
        )
        .map_err(|m| StageError::Param(ParamError::new("spacing_m", m)))?;
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
        let options = p.options.trace_options();
        let mut links = Vec::new();
        for (t, (id, (x, y, h))) in p.transmitters.iter().enumerate() {
            let tx = [*x, *y, ground(*x, *y) + h];
            let pairs: Vec<_> = receivers.iter().map(|r| (tx, *r)).collect();
            let res = trace_links(
                &rf,
                &pairs,
                &Antenna::default(),
                &Antenna::default(),
                &options,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_default_to_the_truth_settings_and_reject_bad_numbers() {
        let p: SynthDriveTestParams = serde_json::from_str(
            r#"{"transmitters": [["A", [0.0, 0.0, 25.0]]], "freq_hz": 3.5e9}"#,
        )
        .unwrap();
        assert!(SynthDriveTest::validate(&p).is_ok());
        let o = p.options.trace_options();
        assert!(o.los && o.reflection && o.transmission && o.diffraction && !o.diffuse);
        assert_eq!((o.scattering_coefficient, o.rays), (0.3, 200_000));
        for (q, field) in [
            (
                SynthDriveTestParams {
                    spacing_m: f64::NAN,
                    ..p.clone()
                },
                "spacing_m",
            ),
            (
                SynthDriveTestParams {
                    rx_height_m: f64::INFINITY,
                    ..p.clone()
                },
                "rx_height_m",
            ),
            (
                SynthDriveTestParams {
                    options: TruthOptions {
                        rays: 0,
                        ..Default::default()
                    },
                    ..p.clone()
                },
                "options",
            ),
            (
                SynthDriveTestParams {
                    options: TruthOptions {
                        foliage_db_per_m: Some(-0.5),
                        ..Default::default()
                    },
                    ..p.clone()
                },
                "options",
            ),
        ] {
            assert_eq!(SynthDriveTest::validate(&q).unwrap_err().field, field);
        }
    }
}
