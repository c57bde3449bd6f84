//! Trace: the links of a drive test traced through a scene by the native ray tracer of `rf`
//! (paper Sec. 5).

use std::path::Path;

use crate::artifact::{ArtifactType, Measurements, Metrics, Raster, Scene};
use crate::rf::calibration;
use crate::rf::traced_links::trace_groups;
pub use crate::rf::traced_links::{LinkOptions, TraceParams};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

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
        InputSpec::optional(
            "calibration",
            ArtifactType::Metrics,
            "a Calibrate node's factors on the materials and foliage rate, and antenna mounts (tilt, bearing, height)",
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
        let calibration = match inputs.optional::<Metrics>("calibration")? {
            Some(m) => calibration::calibration_from(m).map_err(|e| {
                StageError::bad_input(Path::new("the `calibration` input"), "its values", e)
            })?,
            None => calibration::Calibration::default(),
        };
        let mut out = links.clone();
        trace_groups(p, scene, links, terrain, &calibration, ctx, |g| {
            for (&i, r) in g.links.iter().zip(&g.paths) {
                let gain = if p.coherent {
                    r.coherent_gain_db
                } else {
                    r.gain_db
                };
                let l = &mut out.links[i];
                l.path_loss_db = Some(-gain);
                l.rx_power_dbm = None;
                l.los = Some(r.paths.iter().any(|p| p.interactions.is_empty()));
            }
            Ok(())
        })?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Grid;
    use crate::artifact::{Endpoint, Height, Link, PodVec};
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
            LinkOptions {
                scattering_pattern: crate::rf::scattering::ScatteringPattern::Directive {
                    alpha_r: 101,
                },
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

    /// `device: cpu` leaves the params' serialisation (the cache key) as it was; `cuda` enters
    /// it; asking for cuda where it cannot run (no feature, or no driver here) is a param error
    /// before anything is traced.
    #[test]
    fn device_param_keys_and_errors() {
        use crate::rf::gpu::Device;
        let p: TraceParams = serde_json::from_str("{}").unwrap();
        assert_eq!(p.device, Device::Cpu);
        assert!(!serde_json::to_string(&p).unwrap().contains("device"));
        let q: TraceParams = serde_json::from_str(r#"{"device": "cuda"}"#).unwrap();
        assert!(
            serde_json::to_string(&q)
                .unwrap()
                .contains(r#""device":"cuda""#)
        );
        assert!(serde_json::from_str::<TraceParams>(r#"{"device": "gpu"}"#).is_err());
        if crate::rf::gpu::device_unavailable(Device::Cuda).is_none() {
            println!("skipped: this machine can trace on cuda, so nothing is refused");
            return;
        }
        let inputs = Inputs::new()
            .with(
                "scene",
                Slot::One(Arc::new(Artifact::Scene(Scene::default()))),
            )
            .with(
                "links",
                Slot::One(Arc::new(Artifact::Measurements(one_link()))),
            )
            .with(
                "terrain",
                Slot::Optional(Some(Arc::new(Artifact::Raster(flat(12.0))))),
            );
        let s = site();
        match Trace::run(&q, &inputs, &Ctx::new(&s, &[])) {
            Err(StageError::Param(e)) => assert_eq!(e.field, "device"),
            other => panic!("expected a device error, got {:?}", other.map(|_| ())),
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
