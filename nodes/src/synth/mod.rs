//! The synthetic site: a seeded city with known truth (terrain, buildings, facades, materials,
//! trees, clutter) and the sensor products a real site has (LiDAR, rasters, orthophoto, street views,
//! drive tests), each with error knobs, so every stage can be scored against the truth.

pub mod city_footprints;
pub mod osm_like;
pub mod render_ortho;
pub mod synth_city;
pub mod synth_drive_test;
pub mod synth_lidar;
pub mod synth_scan;
pub mod synth_terrain;
pub mod synth_views;
pub mod truth_scene;
