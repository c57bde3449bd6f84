//! What a link trace follows ([`TraceOptions`]) and what it finds ([`Path`], [`Interaction`],
//! [`LinkPaths`]), with the context every path is evaluated in ([`Tracer`]): the data the path
//! search (`paths`), its solvers (`sequences`, `image_method`, `diffracted`) and its field
//! (`path_field`, `diffuse`) share.

use num_complex::Complex64 as C64;
use serde::{Deserialize, Serialize};

use super::antenna::Antenna;
use super::foliage::{FoliageLaw, FoliageLoss, specific_attenuation_db_per_m};
use super::scattering::ScatteringPattern;
use super::scene::RfScene;

/// A transmitter and a receiver position, site frame.
pub type LinkEnds = ([f64; 3], [f64; 3]);

/// Which interactions a trace follows, and how hard it looks: the tracer's physics settings
/// (stages declare their own params and build these from them). `Default` is Sionna RT's.
#[derive(Clone, Debug, PartialEq)]
pub struct TraceOptions {
    /// Most interactions (reflections + transmissions) along one path. Default 3.
    pub max_depth: u32,
    /// Line-of-sight paths. Default true.
    pub los: bool,
    /// Specular reflection. Default true.
    pub reflection: bool,
    /// Transmission through surfaces as thin slabs (P.2040). Default true.
    pub transmission: bool,
    /// UTD diffraction at convex edges, one edge a path: in links with specular reflections
    /// before and after it up to the depth (as Sionna RT 2.2), in radio maps first order.
    /// Default false.
    pub diffraction: bool,
    /// Diffuse reflection (effective roughness): a fraction `scattering_coefficient`² of the
    /// reflected power scattered by `scattering_pattern`, last bounce only for links. Default
    /// false.
    pub diffuse: bool,
    /// S in [0, 1] for every surface; specular reflection keeps √(1 − S²) of the field whether
    /// or not diffuse paths are traced. Default 0.
    pub scattering_coefficient: f64,
    /// The diffuse pattern. Default Lambertian.
    pub scattering_pattern: ScatteringPattern,
    /// Rays shot from each transmitter. Default 10^6.
    pub rays: u32,
    /// Loss inside foliage volumes, dB per metre; `None`: ITU-R P.833 at the carrier
    /// ([`specific_attenuation_db_per_m`]).
    pub foliage_db_per_m: Option<f64>,
    /// How foliage loss grows with depth: linear (the paper's cumulative loss, default) or
    /// ITU-R P.833's saturating law ([`FoliageLaw`]).
    pub foliage_law: FoliageLaw,
    /// Diffraction only at edges where the faces' normals turn by at least this much, degrees
    /// in [0, 90]. Default 0: every convex edge bending by more than a split plane's rounding
    /// (0.08°) diffracts. Measured on the demo's twin (BENCHMARKS.md, "Which edges diffract"):
    /// the gentle edges of a faceted terrain change no link measurably, and some receivers
    /// behind a ridge are reached only over them; a radio map may set 5 for half the time at a
    /// median 0.05 dB.
    pub min_wedge_deg: f64,
    /// Diffraction also at edges where two objects meet (a wall's top edge against a separate
    /// roof). Sionna RT 2.2 finds a wedge's second face only within one shape; false diffracts
    /// as it does, to compare with it. Default true.
    pub wedges_across_objects: bool,
    /// Each wedge as big as the mesh makes it: no UTD term stronger than an edge of its run and
    /// faces of their reach can give (`diffraction::bounded_by_size`). False takes edge and
    /// faces unbounded, as the UTD and Sionna RT 2.2 do. Default true.
    pub finite_faces: bool,
}

impl Default for TraceOptions {
    fn default() -> Self {
        TraceOptions {
            max_depth: 3,
            los: true,
            reflection: true,
            transmission: true,
            diffraction: false,
            diffuse: false,
            scattering_coefficient: 0.0,
            scattering_pattern: ScatteringPattern::Lambertian,
            rays: 1_000_000,
            foliage_db_per_m: None,
            foliage_law: FoliageLaw::Linear,
            min_wedge_deg: 0.0,
            wedges_across_objects: true,
            finite_faces: true,
        }
    }
}

/// The narrowest directive diffuse lobe accepted, ((1 + cos ψ) / 2)^α_R: its normalisation sums
/// α_R + 1 terms for every diffuse event, and at 100 the lobe is already within 10° of the
/// specular direction at half power (Sionna's examples use 1 to 10).
pub const MAX_ALPHA_R: u32 = 100;

/// The deepest trace accepted: a ray walk between two parallel walls would otherwise bounce as
/// long as asked (Sionna's own examples stop at 8-10).
pub const MAX_DEPTH: u32 = 32;

impl TraceOptions {
    /// The first setting out of its range: its name and what it should be.
    pub fn check(&self) -> Result<(), (&'static str, &'static str)> {
        if self.max_depth > MAX_DEPTH {
            return Err(("max_depth", "expected at most 32 interactions"));
        }
        if !(0.0..=1.0).contains(&self.scattering_coefficient) {
            return Err(("scattering_coefficient", "expected a value in [0, 1]"));
        }
        if self.rays == 0 {
            return Err(("rays", "expected at least one ray"));
        }
        if !(0.0..=90.0).contains(&self.min_wedge_deg) {
            return Err(("min_wedge_deg", "expected an angle in [0, 90] degrees"));
        }
        if self
            .foliage_db_per_m
            .is_some_and(|v| !(v >= 0.0 && v.is_finite()))
        {
            return Err(("foliage_db_per_m", "expected a non-negative loss in dB/m"));
        }
        if let Err(m) = self.foliage_law.check() {
            return Err(("foliage_law", m));
        }
        if let ScatteringPattern::Directive { alpha_r } = self.scattering_pattern
            && alpha_r > MAX_ALPHA_R
        {
            return Err((
                "scattering_pattern",
                "expected a directive lobe's alpha_r of at most 100",
            ));
        }
        Ok(())
    }

    /// The foliage loss a trace at `freq_hz` applies: the specific attenuation and the law.
    pub fn foliage_loss(&self, freq_hz: f64) -> FoliageLoss {
        self.foliage_law
            .at(freq_hz, self.foliage_loss_db_per_m(freq_hz))
    }

    /// The foliage loss at `freq_hz`, dB/m: the one set, or P.833's.
    pub fn foliage_loss_db_per_m(&self, freq_hz: f64) -> f64 {
        self.foliage_db_per_m
            .unwrap_or_else(|| specific_attenuation_db_per_m(freq_hz))
    }
}

/// What happened at a path vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum InteractionKind {
    /// Specular reflection.
    Reflection,
    /// Transmission through a slab.
    Transmission,
    /// Diffraction at an edge (UTD).
    Diffraction,
}

/// One interaction of a path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Interaction {
    /// What it was.
    pub kind: InteractionKind,
    /// Where, site frame.
    pub point: [f64; 3],
    /// The global triangle index.
    pub triangle: u32,
}

/// A propagation path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Path {
    /// Interactions in order from the transmitter.
    pub interactions: Vec<Interaction>,
    /// Unfolded length, metres.
    pub length_m: f64,
    /// Delay, seconds.
    pub delay_s: f64,
    /// Complex gain a = (λ/4π) C_R^H T C_T / length (Sionna's `a`, without the e^{-j2πfτ}).
    pub a: [f64; 2],
    /// Path length inside foliage, metres (its loss is in `a`).
    pub foliage_m: f64,
}

impl Path {
    /// A path of `length_m` with gain `a`, its delay at the speed of light.
    pub(super) fn new(
        interactions: Vec<Interaction>,
        length_m: f64,
        a: C64,
        foliage_m: f64,
    ) -> Path {
        Path {
            interactions,
            length_m,
            delay_s: length_m / super::SPEED_OF_LIGHT,
            a: [a.re, a.im],
            foliage_m,
        }
    }
}

/// Every path of one link and the received power they add up to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkPaths {
    /// The paths, by delay.
    pub paths: Vec<Path>,
    /// Σ |a|², dB (-inf without paths).
    pub gain_db: f64,
    /// |Σ a e^{-j2πfτ}|², dB (diffuse power added incoherently).
    pub coherent_gain_db: f64,
    /// The diffusely scattered power alone, dB (-inf without it); included in both gains, not
    /// listed as paths.
    pub diffuse_gain_db: f64,
    /// The diffuse power (linear) by how many specular reflections came before the scattering
    /// surface: it moves with the scattering coefficient S as S² (1 − S²)^k. Empty without
    /// diffuse scattering.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub diffuse_by_reflections: Vec<f64>,
}

/// What every path of a trace is evaluated with.
pub(super) struct Tracer<'a> {
    pub scene: &'a RfScene,
    pub tx_antenna: &'a Antenna,
    pub rx_antenna: &'a Antenna,
    pub opt: &'a TraceOptions,
    /// The foliage loss in force.
    pub foliage: FoliageLoss,
}
