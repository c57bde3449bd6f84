//! The stages of the KODAMA pipeline, as plain functions over plain data.
//!
//! Every stage is a [`Stage`]: a `Params` struct read from the graph file, named typed inputs, one
//! output artifact, a `VERSION` bumped whenever the output for the same inputs would change, and a
//! `run` function. Artifacts ([`Artifact`]) are rasters, point sets, metrics and (as later stages
//! land) meshes, scenes and view sets, all serializable and deterministic.
//!
//! **Invariant:** this crate knows nothing about the engine: no graph, no cache, no scheduler. A
//! stage sees its parameters, its inputs, the site frame and a progress handle ([`Ctx`]), and nothing
//! else; it reads only the files its `files` function declares.
#![deny(missing_docs)]
// `!(x > 0.0)` is how params reject NaN along with non-positive values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[cfg(target_endian = "big")]
compile_error!(
    "artifact arrays are stored as little-endian bytes; big-endian targets are not supported"
);

pub mod artifact;
pub mod buildings;
pub mod geom;
pub mod io;
pub mod params;
pub mod raster;
pub mod rf;
pub mod rng;
pub mod site;
pub mod stage;
pub mod street;

pub mod stages;
pub mod synth;

pub use artifact::{Artifact, ArtifactType};
pub use site::{Site, Window};
pub use stage::{
    Arity, Ctx, FileRef, InputSpec, Inputs, ParamError, Progress, ReportSpec, Reported, Stage,
    StageError,
};

/// Calls `$m!` with the type of every node kind, in one list, so the engine can build its registry
/// without the stages knowing about it. A new stage is added here and nowhere else (a stage behind
/// a cargo feature goes in `__with_optional_stages!` below). Keep the trailing comma: the optional
/// stages are appended to this list.
#[macro_export]
macro_rules! for_each_stage {
    ($m:ident) => {
        $crate::__with_optional_stages! { $m;
            $crate::synth::synth_terrain::SynthTerrain,
            $crate::synth::synth_scan::SynthScan,
            $crate::synth::synth_city::SynthCity,
            $crate::synth::truth_scene::TruthScene,
            $crate::synth::synth_lidar::SynthLidar,
            $crate::stages::heights::rasterize_scene::RasterizeScene,
            $crate::synth::render_ortho::RenderOrtho,
            $crate::synth::city_footprints::CityFootprints,
            $crate::synth::synth_views::SynthViews,
            $crate::synth::synth_drive_test::SynthDriveTest,
            $crate::stages::ingest::read_las::ReadLas,
            $crate::stages::ingest::read_raster::ReadRaster,
            $crate::stages::ingest::read_measurements::ReadMeasurements,
            $crate::stages::ingest::read_footprints::ReadFootprints,
            $crate::stages::ingest::read_osm::ReadOsmBuildings,
            $crate::stages::ingest::read_tiles::ReadTileset,
            $crate::stages::ingest::read_views::ReadViews,
            $crate::stages::ingest::read_view_outputs::ReadViewOutputs,
            $crate::stages::ingest::read_mapillary::ReadMapillary,
            $crate::stages::ingest::read_panoramax::ReadPanoramax,
            $crate::stages::ingest::read_ortho::ReadOrtho,
            $crate::stages::ingest::read_sionna::ReadSionnaScene,
            $crate::stages::ingest::read_xyz::ReadXyz,
            $crate::stages::heights::rasterize_surface::RasterizeSurface,
            $crate::stages::heights::composite_height::CompositeHeight,
            $crate::stages::buildings::terrain_pass::TerrainPass,
            $crate::stages::buildings::above_ground::AboveGround,
            $crate::stages::buildings::building_mask::BuildingMask,
            $crate::stages::buildings::trace_footprints::TraceFootprints,
            $crate::stages::buildings::unassigned::UnassignedAbove,
            $crate::stages::buildings::roof_clean::RoofClean,
            $crate::stages::buildings::split_buildings::SplitBuildings,
            $crate::stages::buildings::building_solids::BuildingSolids,
            $crate::stages::baseline::osm_baseline::OsmBaseline,
            $crate::synth::osm_like::OsmLike,
            $crate::stages::buildings::assemble_scene::AssembleScene,
            $crate::stages::street::surface_charts::SurfaceCharts,
            $crate::stages::street::fuse_views::FuseViews,
            $crate::stages::street::register_views::RegisterViews,
            $crate::stages::street::relief::Relief,
            $crate::stages::street::carve_relief::CarveRelief,
            $crate::stages::street::fuse_materials::FuseMaterials,
            $crate::stages::street::apply_materials::ApplyMaterials,
            $crate::stages::street::place_clutter::PlaceClutter,
            $crate::stages::street::canopies::Canopies,
            $crate::stages::heights::coarsen::Coarsen,
            $crate::stages::heights::flat_ground::FlatGround,
            $crate::stages::heights::gaussian_blur::GaussianBlur,
            $crate::stages::heights::clamp::Clamp,
            $crate::stages::heights::difference::Difference,
            $crate::stages::radio::trace::Trace,
            $crate::stages::radio::calibrate::Calibrate,
            $crate::stages::radio::radio_map::RadioMap,
            $crate::stages::radio::coverage::Coverage,
            $crate::stages::baseline::tr38901::Tr38901,
            $crate::stages::eval::evaluate::Evaluate,
            $crate::stages::eval::report::Report,
            $crate::stages::eval::map_plot::MapPlot,
            $crate::stages::eval::relief_plot::ReliefPlot,
            $crate::stages::eval::material_plot::MaterialPlot,
            $crate::stages::eval::footprint_score::FootprintScore,
            $crate::stages::eval::raster_stats::RasterStats,
            $crate::stages::eval::point_stats::PointStats,
            $crate::stages::tiles::merge_scenes::MergeScenes,
            $crate::stages::tiles::merge_rasters::MergeRasters,
            $crate::stages::tiles::merge_points::MergePoints,
        }
    };
}

/// Calls `$m!` with the stage list it is given followed by the stages of this crate's enabled
/// optional features. The `cfg` is decided here, when this crate is compiled, so the registry
/// matches the features `kodama-nodes` was built with, whichever crate expands the macro.
#[cfg(feature = "onnx")]
#[doc(hidden)]
#[macro_export]
macro_rules! __with_optional_stages {
    ($m:ident; $($list:tt)*) => {
        $m! {
            $($list)*
            $crate::stages::models::segment_views::SegmentViews,
            $crate::stages::models::estimate_depth::EstimateDepth,
        }
    };
}

/// Without optional features: the list as it is.
#[cfg(not(feature = "onnx"))]
#[doc(hidden)]
#[macro_export]
macro_rules! __with_optional_stages {
    ($m:ident; $($list:tt)*) => {
        $m! { $($list)* }
    };
}
