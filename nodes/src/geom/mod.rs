//! Geometry shared by the stages: closed solids and their checks, polygons, the terrain mesh, and
//! ray casting over a BVH. Never imports a stage.

pub mod charts;
pub mod from_above;
pub mod fusion;
pub mod mesh_build;
pub mod mesh_check;
pub mod polygon;
pub mod raycast;
pub mod terrain_mesh;
