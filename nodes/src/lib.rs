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
pub mod crs;
pub mod ecef;
pub mod export;
pub mod exrio;
pub mod geojson;
pub mod geotiff;
pub mod materials;
pub mod mesh_build;
pub mod mesh_check;
pub mod params;
pub mod rf;
pub mod rng;
pub mod sionna_xml;
pub mod site;
pub mod stage;
pub mod warp;

pub mod assemble_scene;
pub mod building_mask;
pub mod building_solids;
pub mod city_footprints;
pub mod coarsen;
pub mod composite_height;
pub mod evaluate;
pub mod footprint_score;
pub mod gaussian_blur;
pub mod osm_baseline;
pub mod osm_like;
pub mod raster_ops;
pub mod rasterize_scene;
pub mod rasterize_surface;
pub mod raycast;
pub mod read_footprints;
pub mod read_las;
pub mod read_measurements;
pub mod read_ortho;
pub mod read_osm;
pub mod read_raster;
pub mod read_sionna;
pub mod read_tiles;
pub mod read_views;
pub mod read_xyz;
pub mod report;
pub mod rf_trace;
pub mod roof_clean;
pub mod split_buildings;
pub mod stats;
pub mod synth_city;
pub mod synth_drive_test;
pub mod synth_lidar;
pub mod synth_scan;
pub mod synth_terrain;
pub mod synth_views;
pub mod terrain_pass;
pub mod tr38901;
pub mod trace_footprints;
pub mod truth_scene;
pub mod unassigned;
pub mod views_io;

pub use artifact::{Artifact, ArtifactType};
pub use site::Site;
pub use stage::{Arity, Ctx, FileRef, InputSpec, Inputs, ParamError, Progress, Stage, StageError};

/// Calls `$m!` with the type of every node kind, in one list, so the engine can build its registry
/// without the stages knowing about it. A new stage is added here and nowhere else.
#[macro_export]
macro_rules! for_each_stage {
    ($m:ident) => {
        $m! {
            $crate::synth_terrain::SynthTerrain,
            $crate::synth_scan::SynthScan,
            $crate::synth_city::SynthCity,
            $crate::truth_scene::TruthScene,
            $crate::synth_lidar::SynthLidar,
            $crate::rasterize_scene::RasterizeScene,
            $crate::rasterize_scene::RenderOrtho,
            $crate::city_footprints::CityFootprints,
            $crate::synth_views::SynthViews,
            $crate::synth_drive_test::SynthDriveTest,
            $crate::read_las::ReadLas,
            $crate::read_raster::ReadRaster,
            $crate::read_measurements::ReadMeasurements,
            $crate::read_footprints::ReadFootprints,
            $crate::read_osm::ReadOsmBuildings,
            $crate::read_tiles::ReadTileset,
            $crate::read_views::ReadViews,
            $crate::read_ortho::ReadOrtho,
            $crate::read_sionna::ReadSionnaScene,
            $crate::read_xyz::ReadXyz,
            $crate::rasterize_surface::RasterizeSurface,
            $crate::composite_height::CompositeHeight,
            $crate::terrain_pass::TerrainPass,
            $crate::terrain_pass::AboveGround,
            $crate::building_mask::BuildingMask,
            $crate::trace_footprints::TraceFootprints,
            $crate::unassigned::UnassignedAbove,
            $crate::roof_clean::RoofClean,
            $crate::split_buildings::SplitBuildings,
            $crate::building_solids::BuildingSolids,
            $crate::osm_baseline::OsmBaseline,
            $crate::osm_like::OsmLike,
            $crate::assemble_scene::AssembleScene,
            $crate::coarsen::Coarsen,
            $crate::gaussian_blur::GaussianBlur,
            $crate::raster_ops::Clamp,
            $crate::raster_ops::Difference,
            $crate::rf_trace::Trace,
            $crate::rf_trace::RadioMap,
            $crate::tr38901::Tr38901,
            $crate::evaluate::Evaluate,
            $crate::report::ReportStage,
            $crate::footprint_score::FootprintScore,
            $crate::stats::RasterStats,
            $crate::stats::PointStats,
        }
    };
}
