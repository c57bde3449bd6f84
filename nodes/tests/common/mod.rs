//! Helpers shared by the stage tests: where the real data and fixtures are, the demo site, and the
//! synthetic chain the reconstruction tests start from.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use kodama_nodes::artifact::TerrainModel;
use kodama_nodes::artifact::{City, PointSet, Raster, Scene, View, ViewHead, ViewSet};
use kodama_nodes::stage::Slot;
use kodama_nodes::stage::process_parts;
use kodama_nodes::stages::buildings::above_ground::{AboveGround, AboveGroundParams};
use kodama_nodes::stages::buildings::terrain_pass::{TerrainPass, TerrainPassParams};
use kodama_nodes::stages::heights::rasterize_surface::{
    CellMode, RasterizeSurface, RasterizeSurfaceParams,
};
use kodama_nodes::stages::street::register_views::RegisterViews;
use kodama_nodes::street::registration::RegistrationParams;
use kodama_nodes::synth::synth_city::SynthCityParams;
use kodama_nodes::synth::synth_lidar::{SynthLidar, SynthLidarParams};
use kodama_nodes::synth::truth_scene::{TruthScene, TruthSceneParams};
use kodama_nodes::{Artifact, Ctx, Inputs, Site, Stage};

/// First-order diffraction alone (no line of sight, reflection or transmission), `rays` shot
/// (or, in a radio map, diffraction samples drawn).
pub fn diffraction_only(rays: u32) -> kodama_nodes::rf::path::TraceOptions {
    kodama_nodes::rf::path::TraceOptions {
        max_depth: 1,
        los: false,
        reflection: false,
        transmission: false,
        diffraction: true,
        rays,
        ..Default::default()
    }
}

/// A file of the real test data, which sits in `shared/data` beside the repository.
pub fn shared(rel: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(rel);
    assert!(
        p.exists(),
        "real test data missing: {} (shared/ must sit beside the repo)",
        p.display()
    );
    p
}

/// A committed fixture in `tests/fixtures` (each made by a script in `scripts/`).
pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fixtures")
        .join(name)
}

/// The demo graph's site frame.
pub fn site() -> Site {
    Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    }
}

/// `views` registered against `scene` by RegisterViews with its defaults, as the demo graph
/// does before every street-level stage.
pub fn register_views(views: &ViewSet, scene: &Scene) -> ViewSet {
    RegisterViews::run(
        &RegistrationParams::default(),
        &Inputs::new()
            .with("views", slot(Artifact::Views(views.clone())))
            .with("scene", slot(Artifact::Scene(scene.clone()))),
        &Ctx::new(&site(), &[]),
    )
    .unwrap()
}

/// A view set with every view's pixels read back, for tests that look at them.
#[derive(Clone, Debug, PartialEq)]
pub struct Loaded {
    /// The views, pixels and all.
    pub views: Vec<View>,
    /// The set's material classes.
    pub material_classes: Vec<String>,
    /// The set as stages pass it.
    pub set: ViewSet,
}

/// `set` with its views' pixels read from the store [`Ctx::new`] gives stages.
pub fn loaded(set: &ViewSet) -> Loaded {
    Loaded {
        views: set.with(process_parts()).load_all().unwrap(),
        material_classes: set.material_classes.clone(),
        set: set.clone(),
    }
}

/// `views` stored as a set in the store [`Ctx::new`] gives stages.
pub fn stored(views: Vec<View>, material_classes: Vec<String>) -> ViewSet {
    ViewSet::store(views, material_classes, process_parts())
        .unwrap()
        .unwrap()
}

/// The same set over the views `keep` keeps (their index, the view head).
pub fn subset(set: &ViewSet, keep: impl Fn(usize, &ViewHead) -> bool) -> ViewSet {
    ViewSet {
        views: set
            .views
            .iter()
            .enumerate()
            .filter(|(i, v)| keep(*i, v))
            .map(|(_, v)| v.clone())
            .collect(),
        material_classes: set.material_classes.clone(),
    }
}

/// Collects what a stage warns of.
#[derive(Default)]
pub struct Warnings(pub std::sync::Mutex<Vec<String>>);

impl kodama_nodes::stage::Progress for Warnings {
    fn set_total(&self, _: u64) {}
    fn advance(&self, _: u64) {}
    fn warn(&self, message: &str) {
        self.0.lock().unwrap().push(message.to_owned());
    }
}

/// A context over `files` whose warnings `warnings` collects.
pub fn ctx_warning_into<'a>(
    site: &'a kodama_nodes::site::Site,
    files: &'a [PathBuf],
    warnings: &'a Warnings,
) -> kodama_nodes::Ctx<'a> {
    kodama_nodes::Ctx {
        site,
        files,
        progress: warnings,
        seed: [0; 32],
        parts: process_parts(),
        window: None,
    }
}

/// An input slot holding one artifact.
pub fn slot(a: Artifact) -> Slot {
    Slot::One(Arc::new(a))
}

/// A 200 x 150 m city of four blocks: quick to scan and render.
pub fn small_city() -> SynthCityParams {
    SynthCityParams {
        size_m: (200.0, 150.0),
        blocks: (2, 2),
        terrain: TerrainModel {
            seed: 3,
            size_m: (200.0, 150.0),
            relief_m: 2.0,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// A steeper variant of the demo's terrain (6 % and 4 % slopes, 4 m relief): where a terrain
/// filter is most tempted to swallow buildings.
pub fn steep_terrain() -> TerrainModel {
    TerrainModel {
        seed: 11,
        size_m: (400.0, 300.0),
        slope: (0.06, -0.04),
        relief_m: 4.0,
        ..Default::default()
    }
}

/// The truth scene of `city`.
pub fn scene_of(city: &City) -> Scene {
    let inputs = Inputs::new().with("city", slot(Artifact::City(city.clone())));
    TruthScene::run(
        &TruthSceneParams::default(),
        &inputs,
        &Ctx::new(&site(), &[]),
    )
    .unwrap()
}

/// What the demo graph makes of a scene before the building stages.
pub struct Reconstruction {
    /// The default survey.
    pub lidar: PointSet,
    /// H: every return's maximum per 0.5 m cell, 1 m gap fill.
    pub dsm: Raster,
    /// T: the two passes of eq. (1) in graphs/demo.ron (DESIGN's example values).
    pub terrain: Raster,
    /// The first (coarse) pass alone.
    pub first_pass: Raster,
    /// A = max(H - T, 0).
    pub above: Raster,
}

/// Surveys `scene` and runs the demo's height-field chain on the survey.
pub fn reconstruct(scene: &Scene) -> Reconstruction {
    let s = site();
    let ctx = Ctx::new(&s, &[]);
    let lidar = SynthLidar::run(
        &SynthLidarParams::default(),
        &Inputs::new().with("scene", slot(Artifact::Scene(scene.clone()))),
        &ctx,
    )
    .unwrap();
    let dsm_params = RasterizeSurfaceParams {
        mode: CellMode::Max,
        cell_m: None,
        classes: None,
        exclude_classes: vec![7, 18],
        max_gap_m: 1.0,
    };
    let dsm = RasterizeSurface::run(
        &dsm_params,
        &Inputs::new().with("points", slot(Artifact::Points(lidar.clone()))),
        &ctx,
    )
    .unwrap();
    let pass = |p: TerrainPassParams, prev: Option<&Raster>| {
        let inputs = Inputs::new()
            .with("surface", slot(Artifact::Raster(dsm.clone())))
            .with(
                "previous",
                Slot::Optional(prev.map(|r| Arc::new(Artifact::Raster(r.clone())))),
            );
        TerrainPass::run(&p, &inputs, &ctx).unwrap()
    };
    let t1 = pass(
        TerrainPassParams {
            coarse_m: 32.0,
            percentile: 5.0,
            n_min: 0.9,
            tau_m: 4.0,
            sigma_m: 2.0,
            min_samples: 4,
        },
        None,
    );
    let terrain = pass(
        TerrainPassParams {
            coarse_m: 8.0,
            percentile: 10.0,
            n_min: 0.9,
            tau_m: 1.0,
            sigma_m: 1.0,
            min_samples: 4,
        },
        Some(&t1),
    );
    let inputs = Inputs::new()
        .with("surface", slot(Artifact::Raster(dsm.clone())))
        .with("terrain", slot(Artifact::Raster(terrain.clone())));
    let above = AboveGround::run(&AboveGroundParams {}, &inputs, &ctx).unwrap();
    Reconstruction {
        lidar,
        dsm,
        terrain,
        first_pass: t1,
        above,
    }
}
