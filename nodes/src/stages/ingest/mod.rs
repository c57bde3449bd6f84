//! Ingest (Sec. 4): user data (LiDAR, rasters, orthophotos, footprints, OSM, 3D Tiles, street
//! views, measurements, Sionna scenes) read into typed artifacts in the site frame.

pub mod read_footprints;
pub mod read_las;
pub mod read_mapillary;
pub mod read_measurements;
pub mod read_ortho;
pub mod read_osm;
pub mod read_panoramax;
pub mod read_raster;
pub mod read_sionna;
pub mod read_tiles;
pub mod read_view_outputs;
pub mod read_views;
pub mod read_xyz;
