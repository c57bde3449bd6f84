//! PlaceClutter (paper Sec. 4.2.4): clutter instances of street views, their depth calibrated
//! per view against the twin (Theil-Sen), lifted to world positions, clustered across views,
//! kept where enough of the views framing them detected them, suppressed by class and distance,
//! filtered by a scene grammar and instantiated from the asset library. It emits the objects as a scene for `AssembleScene`, and its report `counts` says
//! what the chain did (detections, clusters, suppressed, each grammar rule's effect, placed per
//! class, the calibration figures).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Metrics, Raster, Scene, Typed, ViewSet};
use crate::geom::mesh_check::check_solid;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, ReportSpec, Reported, Stage, StageError};
use crate::street::clutter::assets::AssetKind;
use crate::street::clutter::{ClutterConfig, Placed, default_classes, instantiate, place_clutter};

/// Params of [`PlaceClutter`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlaceClutterParams {
    /// View class name -> asset. Default: car, van, truck (a van), bus, pole, sign, bench,
    /// shelter, hydrant, tree (a small tree).
    pub classes: BTreeMap<String, AssetKind>,
    /// One calibration ray every this many pixels each way. Default 6.
    pub calib_stride: u32,
    /// Instances with fewer pixels are ignored. Default 12.
    pub min_pixels: u32,
    /// Lifted points farther than this from the camera are ignored, metres. Default 45.
    pub max_range_m: f64,
    /// Cluster radius in class lengths (at least 1 m). Default 0.6.
    pub cluster_factor: f64,
    /// Suppression radius in class lengths (at least 1.5 m). Default 1.
    pub nms_factor: f64,
    /// Objects seen from fewer views are dropped. Default 1.
    pub min_views: u32,
    /// Objects detected by fewer than this share of the views that should have seen them
    /// (framed, within `max_range_m`, large enough, not hidden behind nearer depth) are
    /// dropped: a segmenter's one-off errors, such as a car read as a shelter in one frame of
    /// six. 0 turns the test off. Default 0.4.
    pub min_view_share: f64,
    /// Slack of that occlusion test, metres (plus 5 % of the range). Default 1.
    pub occlusion_tol_m: f64,
    /// Vehicles farther than this from the nearest street axis the camera track draws are
    /// off the road, metres.
    /// Default 7.
    pub road_half_width_m: f64,
    /// Vehicles closer than this to a building are on the sidewalk, metres. Default 2.
    pub vehicle_building_gap_m: f64,
    /// Roadside furniture closer than this to the nearest street axis the track draws is in
    /// the carriageway, metres.
    /// Default 4.
    pub roadside_min_m: f64,
    /// Free of buildings this far on both sides across the street: an intersection, metres.
    /// Default 20.
    pub intersection_run_m: f64,
    /// Whether vehicles in intersections are dropped (counted either way). Default true.
    pub drop_vehicles_in_intersections: bool,
    /// Seed of the Theil-Sen pair draws. Default 7.
    pub seed: u64,
}

impl Default for PlaceClutterParams {
    fn default() -> Self {
        let c = ClutterConfig::default();
        PlaceClutterParams {
            classes: default_classes(),
            calib_stride: c.calib_stride,
            min_pixels: c.min_pixels as u32,
            max_range_m: c.max_range_m,
            cluster_factor: c.cluster_factor,
            nms_factor: c.nms_factor,
            min_views: c.min_views as u32,
            min_view_share: c.min_view_share,
            occlusion_tol_m: c.occlusion_tol_m,
            road_half_width_m: c.road_half_width_m,
            vehicle_building_gap_m: c.vehicle_building_gap_m,
            roadside_min_m: c.roadside_min_m,
            intersection_run_m: c.intersection_run_m,
            drop_vehicles_in_intersections: c.drop_vehicles_in_intersections,
            seed: c.seed,
        }
    }
}

impl PlaceClutterParams {
    /// The chain's configuration.
    pub fn config(&self) -> ClutterConfig {
        ClutterConfig {
            classes: self.classes.clone(),
            calib_stride: self.calib_stride,
            min_calib_samples: 50,
            min_pixels: self.min_pixels as usize,
            max_range_m: self.max_range_m,
            cluster_factor: self.cluster_factor,
            nms_factor: self.nms_factor,
            min_views: self.min_views as usize,
            min_view_share: self.min_view_share,
            occlusion_tol_m: self.occlusion_tol_m,
            road_half_width_m: self.road_half_width_m,
            vehicle_building_gap_m: self.vehicle_building_gap_m,
            roadside_min_m: self.roadside_min_m,
            intersection_run_m: self.intersection_run_m,
            drop_vehicles_in_intersections: self.drop_vehicles_in_intersections,
            seed: self.seed,
        }
    }
}

fn validate(p: &PlaceClutterParams) -> Result<(), ParamError> {
    if !(1..=64).contains(&p.calib_stride) {
        return Err(ParamError::new("calib_stride", "expected 1 to 64 pixels"));
    }
    if !(1..=1_000_000).contains(&p.min_pixels) {
        return Err(ParamError::new(
            "min_pixels",
            "expected 1 to 1000000 pixels",
        ));
    }
    if !(1..=1000).contains(&p.min_views) {
        return Err(ParamError::new("min_views", "expected 1 to 1000 views"));
    }
    for (name, v, lo, hi) in [
        ("max_range_m", p.max_range_m, 1.0, 1000.0),
        ("cluster_factor", p.cluster_factor, 0.0, 10.0),
        ("nms_factor", p.nms_factor, 0.0, 10.0),
        ("min_view_share", p.min_view_share, 0.0, 1.0),
        ("occlusion_tol_m", p.occlusion_tol_m, 0.0, 100.0),
        ("road_half_width_m", p.road_half_width_m, 0.0, 100.0),
        (
            "vehicle_building_gap_m",
            p.vehicle_building_gap_m,
            0.0,
            100.0,
        ),
        ("roadside_min_m", p.roadside_min_m, 0.0, 100.0),
        ("intersection_run_m", p.intersection_run_m, 1.0, 500.0),
    ] {
        if !(v >= lo && v <= hi) {
            return Err(ParamError::new(
                name,
                format!("expected a finite value in [{lo}, {hi}]"),
            ));
        }
    }
    if p.classes.is_empty() {
        return Err(ParamError::new("classes", "expected at least one class"));
    }
    Ok(())
}

const INPUTS: &[InputSpec] = &[
    InputSpec::one(
        "views",
        ArtifactType::Views,
        "the street views with clutter instances and depth",
    ),
    InputSpec::one(
        "scene",
        ArtifactType::Scene,
        "the twin (terrain and buildings): depth calibration rays and where buildings stand",
    ),
    InputSpec::one(
        "terrain",
        ArtifactType::Raster,
        "the terrain T everything stands on",
    ),
    InputSpec::optional(
        "canopies",
        ArtifactType::Scene,
        "canopy volumes: trees from the views inside one are dropped",
    ),
];

fn chain(
    p: &PlaceClutterParams,
    inputs: &Inputs,
    ctx: &Ctx,
) -> Result<(Vec<Placed>, Metrics), StageError> {
    let views: &ViewSet = inputs.one("views")?;
    let scene: &Scene = inputs.one("scene")?;
    let terrain: &Raster = inputs.one("terrain")?;
    let canopies: Option<&Scene> = inputs.optional("canopies")?;
    if terrain.grid.is_empty() {
        return Err(StageError::Failed("the terrain raster is empty".into()));
    }
    place_clutter(views.with(ctx.parts), scene, terrain, canopies, &p.config())
}

/// Street clutter placed from the views, as a scene of asset instances.
pub struct PlaceClutter;

impl Stage for PlaceClutter {
    const KIND: &'static str = "PlaceClutter";
    // 2: a vehicle seen short of its length is placed from the end no image side or nearer
    // object hides.
    // 3: a round asset seen narrower than it is with one side hidden is placed from the side
    // that shows.
    // 4: the road at a point is the nearest of the streets the track draws there, not one axis
    // fitted across a crossing.
    // 5: a cluster detected by under `min_view_share` of the views that should have seen it is
    // dropped (the segmenter's one-off class confusions of issue 51's sensors).
    const VERSION: u32 = 5;
    const DOC: &'static str = "street clutter from views: Theil-Sen depth calibration, lifting, clustering, multi-view support, NMS, scene grammar, asset library, Sec. 4.2.4";
    const INPUTS: &'static [InputSpec] = INPUTS;
    type Params = PlaceClutterParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        validate(p)
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        Ok(Self::run_reported(p, inputs, ctx)?.output)
    }

    const REPORTS: &'static [ReportSpec] = &[ReportSpec {
        name: "counts",
        ty: ArtifactType::Metrics,
        doc: "what the chain did: detections, clusters, suppressed, each grammar rule's effect (grammar_*), placed per class, the calibration figures",
    }];

    fn run_reported(
        p: &Self::Params,
        inputs: &Inputs,
        ctx: &Ctx,
    ) -> Result<Reported<Scene>, StageError> {
        let (placed, counts) = chain(p, inputs, ctx)?;
        let scene = instantiate(&placed);
        for o in &scene.objects {
            check_solid(&o.mesh).map_err(|e| StageError::Failed(format!("{}: {e}", o.id)))?;
        }
        Ok(Reported {
            output: scene,
            reports: vec![("counts", counts.into_artifact())],
        })
    }
}
