//! Trace: the links of a drive test traced through a scene by the native ray tracer of `rf`
//! (paper Sec. 5).

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Endpoint, Measurements, Raster, Scene};
use crate::rf::antenna::Antenna;
use crate::rf::foliage::{FoliageLaw, is_linear};
use crate::rf::path::TraceOptions;
use crate::rf::paths::trace_links;
use crate::rf::scattering::ScatteringPattern;
use crate::rf::scene::RfScene;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`Trace`].
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

/// The links of the measurements with their predicted path loss (`path_loss_db` = −10 log10 of
/// the path gain; `los` = whether a line-of-sight path exists); measured values are dropped.
pub struct Trace;

impl Stage for Trace {
    const KIND: &'static str = "Trace";
    // 5: diffraction square to an edge no longer gives NaN (rf::diffraction).
    // 6: a wedge's 0-face is the face the wave lights (rf::diffraction::Wedge::facing).
    // 7: wedges from the faces' geometry, not the mesh's winding (rf::diffraction::wedges).
    // 8: UTD face factors at any incidence, in rotated bases (rf::diffraction).
    // 9: diffraction chained with reflections before and after the edge (rf::diffracted).
    // 10: wedges lit by flat face, one wedge per run of edge (rf::diffraction::wedges).
    // 11: a wedge diffracts no more than its size allows (rf::diffraction::bounded_by_size).
    // 12: a face's reflection term capped at half a strip's peak, as the UTD's at a boundary.
    // 13: an edge's length for that bound is its run across material changes.
    // 14: ground above 10 GHz is ITU-R P.527 soil, not an error or P.2040 extrapolated (rf::p527).
    // 15: antenna azimuths are compass bearings from grid north, as the links' azimuths already
    //     were (rf::antenna); the links' azimuths are grid, not true, bearings (ReadMeasurements).
    const VERSION: u32 = 15;
    const DOC: &'static str = "predicted path loss per link: LOS, specular reflection, slab transmission, foliage loss, Sec. 5";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("scene", ArtifactType::Scene, "the scene to trace"),
        InputSpec::one(
            "links",
            ArtifactType::Measurements,
            "the links (transmitter and receiver positions, frequency)",
        ),
        InputSpec::optional(
            "terrain",
            ArtifactType::Raster,
            "the terrain, for heights given above ground",
        ),
    ];
    type Params = TraceParams;
    type Output = Measurements;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::rf::antenna::check_antenna("tx_antenna", &p.tx_antenna)?;
        crate::rf::antenna::check_antenna("rx_antenna", &p.rx_antenna)?;
        super::check_reach(p.reach_m)?;
        p.options
            .trace_options()
            .check()
            .map_err(|(field, m)| ParamError::new("options", format!("{field}: {m}")))
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Measurements, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let links: &Measurements = inputs.one("links")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        let z = |e: &Endpoint| -> Result<f64, StageError> {
            e.absolute_z(terrain.and_then(|t| t.bilinear(e.x, e.y)))
                .ok_or_else(|| {
                    StageError::Failed(format!(
                        "a height above ground at ({:.1}, {:.1}) needs a terrain input covering it",
                        e.x, e.y
                    ))
                })
        };
        // One scene per carrier, one trace per (carrier, transmitter azimuth). The links' azimuths
        // and the antenna's are both grid bearings: no conversion.
        let mut groups: BTreeMap<(u64, u64), Vec<usize>> = BTreeMap::new();
        let mut ends = Vec::with_capacity(links.links.len());
        for (i, l) in links.links.iter().enumerate() {
            let (tx, rx) = ([l.tx.x, l.tx.y, z(&l.tx)?], [l.rx.x, l.rx.y, z(&l.rx)?]);
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
                .entry((l.freq_hz.to_bits(), az.to_bits()))
                .or_default()
                .push(i);
        }
        ctx.progress.set_total(groups.len() as u64);
        let mut out = links.clone();
        let options = p.options.trace_options();
        for ((f_bits, az_bits), idx) in groups {
            let freq = f64::from_bits(f_bits);
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
                    near = super::within_reach(scene, (lo.0 - r, lo.1 - r), (hi.0 + r, hi.1 + r));
                    &near
                }
                None => scene,
            };
            let rf = RfScene::new(traced, freq, p.extrapolate).map_err(StageError::Failed)?;
            let mut tx_antenna = p.tx_antenna;
            let az = f64::from_bits(az_bits);
            if az.is_finite() {
                tx_antenna.azimuth_deg = az;
            }
            let pairs: Vec<_> = idx.iter().map(|&i| ends[i]).collect();
            let res = trace_links(&rf, &pairs, &tx_antenna, &p.rx_antenna, &options, freq);
            for (&i, r) in idx.iter().zip(res) {
                let g = if p.coherent {
                    r.coherent_gain_db
                } else {
                    r.gain_db
                };
                let l = &mut out.links[i];
                l.path_loss_db = Some(-g);
                l.rx_power_dbm = None;
                l.los = Some(r.paths.iter().any(|p| p.interactions.is_empty()));
            }
            ctx.progress.advance(1);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Grid;
    use crate::artifact::{Height, Link, PodVec};
    use crate::stage::Slot;
    use crate::{Artifact, Site};
    use std::sync::Arc;

    fn site() -> Site {
        Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        }
    }

    fn flat(z: f32) -> Raster {
        Raster {
            grid: Grid {
                x0: 0.0,
                y0: 200.0,
                cell_m: 5.0,
                width: 40,
                height: 40,
            },
            data: PodVec(vec![z; 1600]),
        }
    }

    #[test]
    fn params_keep_the_graph_syntax_and_reject_bad_numbers() {
        let p: TraceParams =
            serde_json::from_str(r#"{"options": {"rays": 200000, "diffraction": true}}"#).unwrap();
        assert!(Trace::validate(&p).is_ok());
        assert!(serde_json::from_str::<TraceParams>(r#"{"options": {"ray": 1}}"#).is_err());
        for options in [
            LinkOptions {
                rays: 0,
                ..Default::default()
            },
            LinkOptions {
                scattering_coefficient: 1.5,
                ..Default::default()
            },
            LinkOptions {
                foliage_db_per_m: Some(f64::NAN),
                ..Default::default()
            },
            LinkOptions {
                max_depth: 33,
                ..Default::default()
            },
        ] {
            let q = TraceParams {
                options,
                ..Default::default()
            };
            assert_eq!(Trace::validate(&q).unwrap_err().field, "options");
        }
    }

    /// One 3.5 GHz link along y = 100: the transmitter 30 m above the ground at x = 20, the
    /// receiver 1.5 m above it at x = 170.
    fn one_link() -> Measurements {
        let end = |x: f64, h: f64| Endpoint {
            id: String::new(),
            x,
            y: 100.0,
            z: Height::AboveGround(h),
            azimuth_deg: None,
        };
        Measurements {
            links: vec![Link {
                tx: end(20.0, 30.0),
                rx: end(170.0, 1.5),
                freq_hz: 3.5e9,
                path_loss_db: None,
                rx_power_dbm: None,
                tx_eirp_dbm: None,
                los: None,
            }],
        }
    }

    #[test]
    fn trace_predicts_friis_in_free_space_with_heights_above_ground() {
        let mut links = one_link();
        links.links[0].path_loss_db = Some(99.0);
        let inputs = Inputs::new()
            .with(
                "scene",
                Slot::One(Arc::new(Artifact::Scene(Scene::default()))),
            )
            .with("links", Slot::One(Arc::new(Artifact::Measurements(links))))
            .with(
                "terrain",
                Slot::Optional(Some(Arc::new(Artifact::Raster(flat(12.0))))),
            );
        let s = site();
        let out = Trace::run(&TraceParams::default(), &inputs, &Ctx::new(&s, &[])).unwrap();
        let d = (150.0f64 * 150.0 + 28.5 * 28.5).sqrt();
        let pl = out.links[0].path_loss_db.unwrap();
        assert!((pl - crate::rf::em::fspl_db(d, 3.5e9)).abs() < 1e-9, "{pl}");
        assert_eq!(out.links[0].los, Some(true));
        // Without a terrain, heights above ground are an error, not a guess.
        let inputs = Inputs::new()
            .with(
                "scene",
                Slot::One(Arc::new(Artifact::Scene(Scene::default()))),
            )
            .with("links", Slot::One(Arc::new(Artifact::Measurements(out))));
        assert!(Trace::run(&TraceParams::default(), &inputs, &Ctx::new(&s, &[])).is_err());
    }

    /// With `reach_m`, a group of links is traced through what meets the box around its ends
    /// grown by the reach, exactly as through a scene holding only that; a building beyond it,
    /// which does change the links when traced, is left out.
    #[test]
    fn a_reach_traces_the_links_through_what_meets_their_box() {
        use crate::artifact::{Material, ObjectClass, SceneObject};
        use crate::geom::mesh_build::cuboid;
        let building = |id: &str, c: [f64; 2]| SceneObject {
            id: id.into(),
            class: ObjectClass::Building,
            mesh: cuboid(c, [30.0, 8.0, 40.0], 0.0, 12.0, Material::Concrete),
        };
        let (near, far) = (
            building("near", [100.0, 120.0]),
            building("far", [100.0, 160.0]),
        );
        let links = one_link();
        let s = site();
        let path_loss = |objects: Vec<SceneObject>, reach_m: Option<f64>| {
            let inputs = Inputs::new()
                .with(
                    "scene",
                    Slot::One(Arc::new(Artifact::Scene(Scene { objects }))),
                )
                .with(
                    "links",
                    Slot::One(Arc::new(Artifact::Measurements(links.clone()))),
                )
                .with(
                    "terrain",
                    Slot::Optional(Some(Arc::new(Artifact::Raster(flat(12.0))))),
                );
            let p = TraceParams {
                reach_m,
                ..Default::default()
            };
            Trace::run(&p, &inputs, &Ctx::new(&s, &[])).unwrap().links[0]
                .path_loss_db
                .unwrap()
        };
        // The links' box is y = 100 grown by 30 m: "near" (y 116-124) meets it, "far" (156-164)
        // does not.
        let bounded = path_loss(vec![near.clone(), far.clone()], Some(30.0));
        assert_eq!(bounded, path_loss(vec![near.clone()], None));
        let whole = path_loss(vec![near, far], None);
        assert!((whole - bounded).abs() > 0.01, "{whole} vs {bounded}");
        let bad = TraceParams {
            reach_m: Some(f64::NAN),
            ..Default::default()
        };
        assert_eq!(Trace::validate(&bad).unwrap_err().field, "reach_m");
    }
}
