//! Measured links traced group by group (one carrier, one transmitter bearing), as the Trace and
//! Calibrate stages trace them (paper Sec. 5): the params both take, and the tracing itself.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::antenna::Antenna;
use super::calibration::{self, Calibration};
use super::foliage::{FoliageLaw, is_linear};
use super::gpu::{Device, device_unavailable};
use super::path::{LinkPaths, TraceOptions};
use super::paths::trace_links_on;
use super::scattering::ScatteringPattern;
use super::scene::RfScene;
use crate::artifact::{Endpoint, Measurements, ObjectClass, Raster, Scene};
use crate::stage::{Ctx, ParamError, StageError};

/// The params of a Trace node (and a Calibrate node's `trace`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TraceParams {
    /// Interactions and effort. Default: every field's default.
    pub options: LinkOptions,
    /// Transmit antenna; its `azimuth_deg` is a compass bearing, degrees clockwise from grid north
    /// (the site frame's +y). A link's own azimuth (the measurements' `Endpoint::azimuth_deg`, a
    /// grid bearing too) replaces it. Default isotropic, vertical.
    pub tx_antenna: Antenna,
    /// Receive antenna (bearing as `tx_antenna`'s). Default isotropic, vertical.
    pub rx_antenna: Antenna,
    /// Report the coherent sum |Σ a e^{-j2πfτ}|² instead of Σ |a|². Default false.
    pub coherent: bool,
    /// Use P.2040 laws outside their frequency ranges. Default false. Ground above 10 GHz needs
    /// none: it is ITU-R P.527 soil there (`rf::materials`).
    pub extrapolate: bool,
    /// How far the links' work reaches, metres: when set, each group of links (one carrier and
    /// transmitter bearing) is traced through only what meets the box around its ends grown by
    /// this much (buildings and other objects whole, the terrain cut), so a drive test across a
    /// city traces each transmitter through its own neighbourhood. A path that leaves the box is
    /// not traced: choose the reach beyond which nothing matters (README, "Radio, by
    /// transmitter"). Default none: the whole scene.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reach_m: Option<f64>,
    /// Where the rays of the links' sequence search run: `cpu` (the default) or `cuda` (a build
    /// with feature `cuda` and an NVIDIA driver; README, "GPU backend (optional)"). The paths
    /// are the same bits on either. Left out of the params' encoding at `cpu`, so earlier cache
    /// entries stay valid.
    #[serde(default, skip_serializing_if = "Device::is_cpu")]
    pub device: Device,
}

/// `options` of [`TraceParams`]: which interactions the links follow, and how hard the trace
/// looks. The defaults are Sionna RT's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkOptions {
    /// Most interactions (reflections + transmissions) along one path. Default 3.
    pub max_depth: u32,
    /// Line-of-sight paths. Default true.
    pub los: bool,
    /// Specular reflection. Default true.
    pub reflection: bool,
    /// Transmission through surfaces as thin slabs (P.2040). Default true.
    pub transmission: bool,
    /// UTD diffraction at convex edges, one edge a path, chained with reflections before and
    /// after it up to the depth (as Sionna RT 2.2). Default false.
    pub diffraction: bool,
    /// Diffuse reflection off the last surface (effective roughness). Default false.
    pub diffuse: bool,
    /// Scattering coefficient S of every surface, in [0, 1]; specular reflection keeps
    /// √(1 − S²) of the field. Default 0.
    pub scattering_coefficient: f64,
    /// The diffuse pattern. Default Lambertian.
    pub scattering_pattern: ScatteringPattern,
    /// Rays shot from each transmitter to find paths (> 0). Default 1 000 000.
    pub rays: u32,
    /// Loss inside foliage, dB/m (≥ 0). Default: ITU-R P.833 at the link's carrier.
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

impl Default for LinkOptions {
    fn default() -> Self {
        let o = TraceOptions::default();
        LinkOptions {
            max_depth: o.max_depth,
            los: o.los,
            reflection: o.reflection,
            transmission: o.transmission,
            diffraction: o.diffraction,
            diffuse: o.diffuse,
            scattering_coefficient: o.scattering_coefficient,
            scattering_pattern: o.scattering_pattern,
            rays: o.rays,
            foliage_db_per_m: o.foliage_db_per_m,
            foliage_law: o.foliage_law,
            min_wedge_deg: o.min_wedge_deg,
            finite_faces: o.finite_faces,
        }
    }
}

impl LinkOptions {
    /// The tracer's settings.
    pub fn trace_options(&self) -> TraceOptions {
        TraceOptions {
            max_depth: self.max_depth,
            los: self.los,
            reflection: self.reflection,
            transmission: self.transmission,
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

/// One group of links traced together (one carrier, one transmitter bearing): which links of
/// the measurements, the radio scene and options they were traced with, each link's ends and
/// its paths.
pub struct TracedGroup<'a> {
    /// The links' indices in the measurements.
    pub links: &'a [usize],
    /// The carrier, Hz.
    pub freq_hz: f64,
    /// The transmit antenna (the group's bearing).
    pub tx_antenna: Antenna,
    /// The scene as traced (cut to the reach, calibrated).
    pub rf: RfScene,
    /// The options as traced (a calibrated foliage rate set).
    pub options: TraceOptions,
    /// Each link's (transmitter, receiver), site frame.
    pub ends: Vec<([f64; 3], [f64; 3])>,
    /// Each link's paths.
    pub paths: Vec<LinkPaths>,
}

/// Traces `links` through `scene` with `p`, as the Trace and Calibrate stages do: one radio scene per carrier, one
/// trace per (carrier, transmitter bearing), each cut to `p.reach_m` when set, with the factors
/// of `calibration` on its materials and foliage rate and its mounts on each cell's transmit
/// antenna (turned, raised; a cell its own group then); `each` takes every group in turn.
pub fn trace_groups(
    p: &TraceParams,
    scene: &Scene,
    links: &Measurements,
    terrain: Option<&Raster>,
    calibration: &Calibration,
    ctx: &Ctx,
    mut each: impl FnMut(TracedGroup) -> Result<(), StageError>,
) -> Result<(), StageError> {
    // Refused before any group is traced, not after the first.
    if let Some(why) = device_unavailable(p.device) {
        return Err(StageError::Param(ParamError::new("device", why)));
    }
    let z = |e: &Endpoint| -> Result<f64, StageError> {
        e.absolute_z(terrain.and_then(|t| t.bilinear(e.x, e.y)))
            .ok_or_else(|| {
                StageError::Failed(format!(
                    "a height above ground at ({:.1}, {:.1}) needs a terrain input covering it",
                    e.x, e.y
                ))
            })
    };
    // The links' azimuths and the antenna's are both grid bearings: no conversion.
    let by_cell = !calibration.mounts.is_empty();
    let mut groups: BTreeMap<(u64, u64, &str), Vec<usize>> = BTreeMap::new();
    let mut ends = Vec::with_capacity(links.links.len());
    for (i, l) in links.links.iter().enumerate() {
        let raised = calibration.mounts.get(&l.tx.id).map_or(0.0, |m| m.height_m);
        let (tx, rx) = (
            [l.tx.x, l.tx.y, z(&l.tx)? + raised],
            [l.rx.x, l.rx.y, z(&l.rx)?],
        );
        for (end, p) in [("transmitter", tx), ("receiver", rx)] {
            crate::params::check_point(p).map_err(|m| {
                StageError::bad_input(
                    Path::new("the `links` input"),
                    format!("link {i}, {end}"),
                    format!("expected {m}"),
                )
            })?;
        }
        ends.push((tx, rx));
        let az = l.tx.azimuth_deg.unwrap_or(f64::NAN);
        groups
            .entry((
                l.freq_hz.to_bits(),
                az.to_bits(),
                if by_cell { l.tx.id.as_str() } else { "" },
            ))
            .or_default()
            .push(i);
    }
    ctx.progress.set_total(groups.len() as u64);
    let options = p.options.trace_options();
    for ((f_bits, az_bits, cell), idx) in &groups {
        let freq = f64::from_bits(*f_bits);
        let near;
        let traced = match p.reach_m {
            Some(r) => {
                let (lo, hi) = idx.iter().flat_map(|&i| [ends[i].0, ends[i].1]).fold(
                    (
                        (f64::INFINITY, f64::INFINITY),
                        (f64::NEG_INFINITY, f64::NEG_INFINITY),
                    ),
                    |(lo, hi), e| {
                        (
                            (lo.0.min(e[0]), lo.1.min(e[1])),
                            (hi.0.max(e[0]), hi.1.max(e[1])),
                        )
                    },
                );
                near = within_reach(scene, (lo.0 - r, lo.1 - r), (hi.0 + r, hi.1 + r));
                &near
            }
            None => scene,
        };
        let rf = RfScene::new(traced, freq, p.extrapolate).map_err(StageError::Failed)?;
        let (rf, options) = calibration::apply(rf, &options, freq, &calibration.factors);
        let mut tx_antenna = p.tx_antenna;
        let az = f64::from_bits(*az_bits);
        if az.is_finite() {
            tx_antenna.azimuth_deg = az;
        }
        if let Some(m) = calibration.mounts.get(*cell) {
            tx_antenna.tilt_deg += m.tilt_deg;
            tx_antenna.azimuth_deg += m.azimuth_deg;
        }
        let pairs: Vec<_> = idx.iter().map(|&i| ends[i]).collect();
        let ends_antennas = (&tx_antenna, &p.rx_antenna);
        let paths = trace_links_on(p.device, &rf, &pairs, ends_antennas, &options, freq)
            .map_err(|e| StageError::Param(ParamError::new("device", e)))?;
        each(TracedGroup {
            links: idx,
            freq_hz: freq,
            tx_antenna,
            rf,
            options,
            ends: pairs,
            paths,
        })?;
        ctx.progress.advance(1);
    }
    Ok(())
}

/// What a transmitter bounded by its reach traces: the part of `scene` meeting the box from
/// `lo` to `hi`, every object whole (a building cut open would let rays in without walls) but
/// the terrain, which is one object city-wide and is cut to the triangles meeting the box.
pub fn within_reach(scene: &Scene, lo: (f64, f64), hi: (f64, f64)) -> Scene {
    scene.near(lo, hi, |o| o.class != ObjectClass::Terrain)
}
