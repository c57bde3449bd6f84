//! RadioMap: a coverage map of one transmitter over a scene, by shoot-and-bounce (paper Sec. 5).

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Grid, Raster, Scene};
use crate::rf::antenna::Antenna;
use crate::rf::foliage::{FoliageLaw, is_linear};
use crate::rf::gpu::{Device, device_unavailable, radio_map_on};
use crate::rf::map_plane::{MapPlane, default_grid};
use crate::rf::path::TraceOptions;
use crate::rf::scattering::ScatteringPattern;
use crate::rf::scene::{RfScene, scene_bounds};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// Params of [`RadioMap`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadioMapParams {
    /// Transmitter position (x, y) in the site frame and its height: above the terrain when a
    /// terrain is given, else site-frame z.
    pub tx: (f64, f64, f64),
    /// Carrier frequency, Hz.
    pub freq_hz: f64,
    /// Cell size, metres (> 0). Default 5.
    #[serde(default = "five")]
    pub cell_m: f64,
    /// Height of the map: above the terrain when a terrain is given, else site-frame z. Default 1.5.
    #[serde(default = "one_and_a_half")]
    pub height_m: f64,
    /// Interactions and the number of rays. Default: every field's default.
    #[serde(default)]
    pub options: MapOptions,
    /// The transmit antenna; its `azimuth_deg` is a compass bearing, degrees clockwise from grid
    /// north (the site frame's +y). Default isotropic, vertical.
    #[serde(default)]
    pub antenna: Antenna,
    /// Use P.2040 laws outside their frequency ranges. Default false. Ground above 10 GHz needs
    /// none: it is ITU-R P.527 soil there (`rf::materials`).
    #[serde(default)]
    pub extrapolate: bool,
    /// How far the transmitter's work reaches, metres: when set, the map covers only the cells
    /// within this distance of the transmitter along each axis (a square centred on it), and
    /// the tracer sees only what meets that square (buildings and other objects whole, the
    /// terrain cut to it). A city's transmitters then each trace a bounded part of it, in
    /// memory and time independent of the city's size. A path that leaves the square before
    /// reaching a cell in it (a reflection off a building beyond it) is not traced: choose the
    /// reach where the signal no longer matters (past the noise floor, or the next cell's
    /// edge). Default none: the whole scene and the whole terrain's extent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reach_m: Option<f64>,
    /// Where to trace: `cpu` (default) or `cuda` (an NVIDIA GPU, a build with feature `cuda`).
    /// Part of the cache key when not `cpu` (a GPU map may differ from the CPU's in the last
    /// bits); a `cpu` map keeps the key it had before the parameter existed.
    #[serde(default, skip_serializing_if = "Device::is_cpu")]
    pub device: Device,
}

/// `options` of [`RadioMapParams`]: which interactions the rays follow, and how many there are.
/// The defaults are Sionna RT's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapOptions {
    /// Most interactions along one ray. Default 3.
    pub max_depth: u32,
    /// Count rays before their first interaction. Default true.
    pub los: bool,
    /// Specular reflection. Default true.
    pub reflection: bool,
    /// Transmission through surfaces as thin slabs (P.2040). Default true.
    pub transmission: bool,
    /// First-order UTD edge diffraction at the convex edges of the surfaces the transmitter
    /// lights, as many samples as rays (Sionna RT's estimator). Default false.
    pub diffraction: bool,
    /// Diffraction only where an edge's faces turn by at least this many degrees, in [0, 90].
    /// Default 0.
    pub min_wedge_deg: f64,
    /// A wedge diffracts no more than an edge of its length and faces of their width can
    /// (`rf::diffraction::bounded_by_size`); false: the unbounded UTD, as Sionna RT. Default true.
    pub finite_faces: bool,
    /// Diffuse reflection (effective roughness), at every bounce. Default false.
    pub diffuse: bool,
    /// Scattering coefficient S of every surface, in [0, 1]. Default 0.
    pub scattering_coefficient: f64,
    /// The diffuse pattern. Default Lambertian.
    pub scattering_pattern: ScatteringPattern,
    /// Rays shot from the transmitter (> 0). Default 1 000 000.
    pub rays: u32,
    /// Loss inside foliage, dB/m (≥ 0). Default: ITU-R P.833 at `freq_hz`.
    pub foliage_db_per_m: Option<f64>,
    /// How foliage loss grows with depth: `Linear` (γ d, the paper's; default), `P833` (ITU-R
    /// P.833's saturating law, A_m from the recommendation's A1 f^α) or `P833Max(A_m dB)`.
    /// Left out of the params' encoding at its default, so earlier cache entries stay valid.
    #[serde(skip_serializing_if = "is_linear")]
    pub foliage_law: FoliageLaw,
}

impl Default for MapOptions {
    fn default() -> Self {
        let o = TraceOptions::default();
        MapOptions {
            max_depth: o.max_depth,
            los: o.los,
            reflection: o.reflection,
            transmission: o.transmission,
            diffraction: o.diffraction,
            min_wedge_deg: o.min_wedge_deg,
            finite_faces: o.finite_faces,
            diffuse: o.diffuse,
            scattering_coefficient: o.scattering_coefficient,
            scattering_pattern: o.scattering_pattern,
            rays: o.rays,
            foliage_db_per_m: o.foliage_db_per_m,
            foliage_law: o.foliage_law,
        }
    }
}

impl MapOptions {
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

fn five() -> f64 {
    5.0
}
fn one_and_a_half() -> f64 {
    1.5
}

/// Path gain (dB, NaN where no ray arrived) over the terrain's extent, on a surface following the
/// terrain at `height_m`; without a terrain, over the scene on the plane z = `height_m`.
pub struct RadioMap;

impl Stage for RadioMap {
    const KIND: &'static str = "RadioMap";
    // 4: first-order edge diffraction in maps (rf::radiomap_diffraction).
    // 5: UTD face factors at any incidence, in rotated bases (rf::diffraction).
    // 6: wedges lit by flat face, one wedge per run of edge (rf::diffraction::wedges).
    // 7: a wedge diffracts no more than its size allows (rf::diffraction::bounded_by_size).
    // 8: a face's reflection term capped at half a strip's peak, as the UTD's at a boundary.
    // 9: an edge's length for that bound is its run across material changes.
    // 10: ground above 10 GHz is ITU-R P.527 soil, not an error or P.2040 extrapolated (rf::p527).
    // 11: the antenna's azimuth is a compass bearing from grid north, not an angle from +x
    //     (rf::antenna).
    const VERSION: u32 = 11;
    const DOC: &'static str = "radio map (path gain, dB) by shooting and bouncing rays, Sec. 5";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("scene", ArtifactType::Scene, "the scene to trace"),
        InputSpec::optional(
            "terrain",
            ArtifactType::Raster,
            "the terrain: map extent and heights above ground",
        ),
    ];
    type Params = RadioMapParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("dB")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.options
            .trace_options()
            .check()
            .map_err(|(field, m)| ParamError::new("options", format!("{field}: {m}")))?;
        if !(p.freq_hz > 0.0 && p.freq_hz.is_finite()) {
            return Err(ParamError::new(
                "freq_hz",
                "expected a positive frequency in Hz",
            ));
        }
        crate::params::check_point([p.tx.0, p.tx.1, p.tx.2])
            .map_err(|m| ParamError::new("tx", format!("expected {m}")))?;
        if !p.height_m.is_finite() {
            return Err(ParamError::new(
                "height_m",
                "expected a finite height in metres",
            ));
        }
        super::check_reach(p.reach_m)?;
        crate::rf::antenna::check_antenna("antenna", &p.antenna)?;
        crate::params::check_cell(Some(p.cell_m))?;
        if !p.cell_m.is_finite() {
            return Err(ParamError::new(
                "cell_m",
                "expected a finite cell size in metres",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        if let Some(why) = device_unavailable(p.device) {
            return Err(StageError::Param(ParamError::new("device", why)));
        }
        let whole: &Scene = inputs.one("scene")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        // The square the transmitter's work is bounded to, if any.
        let window = p
            .reach_m
            .map(|r| (p.tx.0 - r, p.tx.1 - r, p.tx.0 + r, p.tx.1 + r));
        let near;
        let scene = match window {
            Some((x0, y0, x1, y1)) => {
                near = super::within_reach(whole, (x0, y0), (x1, y1));
                &near
            }
            None => whole,
        };
        let rf = RfScene::new(scene, p.freq_hz, p.extrapolate).map_err(StageError::Failed)?;
        // Without a terrain the lattice is the whole scene's, so that maps cut to different
        // reaches lie on one lattice (Coverage combines them).
        let bounds = match window {
            Some(_) => scene_bounds(whole),
            None => rf.bounds,
        };
        let grid = map_grid(p, terrain, bounds, window)?;
        let (plane, tx) = match terrain {
            Some(t) => {
                let ground = t.bilinear(p.tx.0, p.tx.1).ok_or_else(|| {
                    StageError::Failed(format!(
                        "the transmitter at ({}, {}) is off the terrain",
                        p.tx.0, p.tx.1
                    ))
                })?;
                let plane = match window {
                    Some(_) => MapPlane::above_terrain_over(grid, t, p.height_m),
                    None => MapPlane::above_terrain(grid, t, p.height_m),
                };
                (
                    plane.map_err(StageError::Failed)?,
                    DVec3::new(p.tx.0, p.tx.1, ground + p.tx.2),
                )
            }
            None => (
                MapPlane::plane(grid, p.height_m),
                DVec3::new(p.tx.0, p.tx.1, p.tx.2),
            ),
        };
        let options = p.options.trace_options();
        let map = radio_map_on(p.device, &rf, tx, &p.antenna, &plane, &options, p.freq_hz)
            .map_err(|e| StageError::Param(ParamError::new("device", e)))?;
        Ok(crate::rf::radiomap::to_db(&map))
    }
}

/// The map's cells: the terrain's extent on a lattice of `cell_m` from its north-west corner
/// (without a terrain, the scene's horizontal `bounds`, centred), cut to `window` when the
/// transmitter's reach bounds it.
fn map_grid(
    p: &RadioMapParams,
    terrain: Option<&Raster>,
    bounds: (DVec3, DVec3),
    window: Option<(f64, f64, f64, f64)>,
) -> Result<Grid, StageError> {
    // The cells along each axis, checked before the map (and the tracer's per-cell
    // accumulators: path gain and hit counts, as f64, 16 bytes each) are allocated; a reach
    // only cuts them down.
    let (w, h) = match terrain {
        Some(t) => (
            (t.grid.width as f64 * t.grid.cell_m / p.cell_m).ceil(),
            (t.grid.height as f64 * t.grid.cell_m / p.cell_m).ceil(),
        ),
        None => (
            ((bounds.1.x - bounds.0.x) / p.cell_m).ceil().max(1.0),
            ((bounds.1.y - bounds.0.y) / p.cell_m).ceil().max(1.0),
        ),
    };
    crate::params::check_cells(w, h, 16).map_err(|m| {
        StageError::Param(ParamError::new(
            "cell_m",
            format!("{m}; use a coarser cell"),
        ))
    })?;
    let full = match terrain {
        Some(t) => Grid {
            cell_m: p.cell_m,
            width: w as u32,
            height: h as u32,
            ..t.grid
        },
        None => default_grid(bounds, p.cell_m),
    };
    match window {
        None => Ok(full),
        Some(w) => full.crop(w).map(|(g, _, _)| g).ok_or_else(|| {
            StageError::Failed(format!(
                "no cell of the map lies within reach_m = {} m of the transmitter at ({}, {})",
                p.reach_m.unwrap_or_default(),
                p.tx.0,
                p.tx.1
            ))
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::PodVec;
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
    fn params_accept_only_what_maps_model() {
        let parse = |options: &str| {
            serde_json::from_str::<RadioMapParams>(&format!(
                r#"{{"tx": [0.0, 0.0, 10.0], "freq_hz": 3.5e9, "options": {options}}}"#
            ))
        };
        let p = parse(r#"{"rays": 1000}"#).unwrap();
        assert!(RadioMap::validate(&p).is_ok());
        assert!(parse(r#"{"diffraction": true, "min_wedge_deg": 10.0}"#).is_ok());
        assert!(parse(r#"{"refraction": true}"#).is_err());
        let bad = [
            MapOptions {
                rays: 0,
                ..p.options.clone()
            },
            MapOptions {
                scattering_coefficient: f64::NAN,
                ..p.options.clone()
            },
            MapOptions {
                foliage_db_per_m: Some(-1.0),
                ..p.options.clone()
            },
            MapOptions {
                min_wedge_deg: f64::NAN,
                ..p.options.clone()
            },
        ];
        for options in bad {
            let q = RadioMapParams {
                options,
                ..p.clone()
            };
            assert_eq!(RadioMap::validate(&q).unwrap_err().field, "options");
        }
        for (q, field) in [
            (
                RadioMapParams {
                    height_m: f64::NAN,
                    ..p.clone()
                },
                "height_m",
            ),
            (
                RadioMapParams {
                    cell_m: f64::INFINITY,
                    ..p.clone()
                },
                "cell_m",
            ),
            (
                RadioMapParams {
                    tx: (0.0, f64::NAN, 1.0),
                    ..p.clone()
                },
                "tx",
            ),
        ] {
            assert_eq!(RadioMap::validate(&q).unwrap_err().field, field);
        }
    }

    /// `device: cpu` leaves the params' serialisation (the cache key) as it was; `cuda` enters
    /// it; asking for cuda where it cannot run (no feature, or no driver here) is a param error.
    #[test]
    fn device_param_keys_and_errors() {
        let json = r#"{"tx": [0.0, 0.0, 10.0], "freq_hz": 3.5e9}"#;
        let p: RadioMapParams = serde_json::from_str(json).unwrap();
        assert_eq!(p.device, Device::Cpu);
        assert!(!serde_json::to_string(&p).unwrap().contains("device"));
        let q: RadioMapParams =
            serde_json::from_str(r#"{"tx": [0.0, 0.0, 10.0], "freq_hz": 3.5e9, "device": "cuda"}"#)
                .unwrap();
        assert!(
            serde_json::to_string(&q)
                .unwrap()
                .contains(r#""device":"cuda""#)
        );
        let inputs = Inputs::new().with(
            "scene",
            Slot::One(Arc::new(Artifact::Scene(Scene::default()))),
        );
        let s = site();
        match RadioMap::run(&q, &inputs, &Ctx::new(&s, &[])) {
            Err(StageError::Param(e)) => assert_eq!(e.field, "device"),
            other => panic!("expected a device error, got {:?}", other.map(|_| ())),
        }
    }

    #[test]
    fn radio_map_follows_the_terrain_surface() {
        // Free space over "terrain" at 12 m: the map at 1.5 m above it is Friis from a transmitter
        // 30 m above it, averaged over each 5 m cell.
        let inputs = Inputs::new()
            .with(
                "scene",
                Slot::One(Arc::new(Artifact::Scene(Scene::default()))),
            )
            .with(
                "terrain",
                Slot::Optional(Some(Arc::new(Artifact::Raster(flat(12.0))))),
            );
        let p = RadioMapParams {
            tx: (100.0, 100.0, 30.0),
            freq_hz: 3.5e9,
            cell_m: 5.0,
            height_m: 1.5,
            options: MapOptions::default(),
            antenna: Antenna::default(),
            extrapolate: false,
            reach_m: None,
            device: Device::Cpu,
        };
        let s = site();
        let map = RadioMap::run(&p, &inputs, &Ctx::new(&s, &[])).unwrap();
        let (x, y) = map.grid.center(35, 20);
        let d2 = (x - 100.0).powi(2) + (y - 100.0).powi(2) + 28.5f64.powi(2);
        let friis = -crate::rf::em::fspl_db(d2.sqrt(), 3.5e9);
        assert!(
            (map.at(35, 20) as f64 - friis).abs() < 0.3,
            "{} vs {friis}",
            map.at(35, 20)
        );
    }

    /// The map of a transmitter whose reach bounds it: the cells within `reach_m` of it along
    /// each axis, on the unbounded map's lattice, with the unbounded map's values where every
    /// object lies within the reach (the bound cuts work, not physics it keeps).
    #[test]
    fn a_reach_bounds_the_map_to_the_cells_within_it() {
        use crate::artifact::{Material, ObjectClass, SceneObject};
        use crate::geom::mesh_build::cuboid;
        let building = |id: &str, c: [f64; 2]| SceneObject {
            id: id.into(),
            class: ObjectClass::Building,
            mesh: cuboid(c, [12.0, 8.0, 15.0], 0.3, 12.0, Material::Concrete),
        };
        let scene = Scene {
            objects: vec![building("a", [120.0, 110.0]), building("b", [80.0, 85.0])],
        };
        let scene = Arc::new(Artifact::Scene(scene));
        let inputs = Inputs::new().with("scene", Slot::One(scene.clone())).with(
            "terrain",
            Slot::Optional(Some(Arc::new(Artifact::Raster(flat(12.0))))),
        );
        let p = RadioMapParams {
            tx: (101.0, 99.0, 30.0),
            freq_hz: 3.5e9,
            cell_m: 5.0,
            height_m: 1.5,
            options: MapOptions {
                rays: 200_000,
                ..MapOptions::default()
            },
            antenna: Antenna::default(),
            extrapolate: false,
            reach_m: None,
            device: Device::Cpu,
        };
        let s = site();
        let full = RadioMap::run(&p, &inputs, &Ctx::new(&s, &[])).unwrap();
        let bounded = RadioMapParams {
            reach_m: Some(48.0),
            ..p.clone()
        };
        let near = RadioMap::run(&bounded, &inputs, &Ctx::new(&s, &[])).unwrap();
        // Cells whose centres lie within 48 m of x = 101, y = 99 on the 5 m lattice from
        // (0, 200): columns 11-29 (centres x 57.5-147.5), rows 11-29 (centres y 142.5-52.5).
        let g = near.grid;
        assert_eq!((g.cell_m, g.width, g.height), (5.0, 19, 19));
        assert_eq!((g.x0, g.y0), (55.0, 145.0));
        let mut compared = 0;
        for row in 0..g.height {
            for col in 0..g.width {
                let (x, y) = g.center(col, row);
                let (fc, fr) = full.grid.cell_of(x, y).unwrap();
                let (a, b) = (near.at(col, row), full.at(fc, fr));
                assert_eq!(a.is_nan(), b.is_nan(), "cell ({x}, {y}): {a} vs {b}");
                if a.is_finite() {
                    assert!((a - b).abs() < 0.01, "cell ({x}, {y}): {a} vs {b}");
                    compared += 1;
                }
            }
        }
        assert!(compared > 300, "{compared} cells compared");
        // Without a terrain the bounded map lies on the lattice of the whole scene's map too
        // (not one centred on what is left after the cut), with its values.
        let no_terrain = Inputs::new().with("scene", Slot::One(scene));
        let full = RadioMap::run(&p, &no_terrain, &Ctx::new(&s, &[])).unwrap();
        let near = RadioMap::run(&bounded, &no_terrain, &Ctx::new(&s, &[])).unwrap();
        let cols = (near.grid.x0 - full.grid.x0) / 5.0;
        let rows = (full.grid.y0 - near.grid.y0) / 5.0;
        assert!((cols - cols.round()).abs() < 1e-9 && (rows - rows.round()).abs() < 1e-9);
        let g = near.grid;
        for row in 0..g.height {
            for col in 0..g.width {
                let (x, y) = g.center(col, row);
                let Some((fc, fr)) = full.grid.cell_of(x, y) else {
                    continue;
                };
                let (a, b) = (near.at(col, row), full.at(fc, fr));
                assert!(
                    (a.is_nan() && b.is_nan()) || (a - b).abs() < 0.01,
                    "no terrain, cell ({x}, {y}): {a} vs {b}"
                );
            }
        }
        for bad in [0.0, -5.0, f64::NAN, f64::INFINITY, 2e5] {
            let q = RadioMapParams {
                reach_m: Some(bad),
                ..p.clone()
            };
            assert_eq!(RadioMap::validate(&q).unwrap_err().field, "reach_m");
        }
    }
}
