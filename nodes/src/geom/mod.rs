//! Geometric primitives: closed solids and their checks, exact Booleans, polygons, charts on
//! building surfaces, the terrain mesh, robust line fits, and ray casting over a BVH. The
//! paper's steps that use them live in `buildings/` (Sec. 4.1) and `street/` (Sec. 4.2).

pub mod boolean;
pub mod charts;
pub mod from_above;
pub mod mesh_build;
pub mod mesh_check;
pub mod polygon;
pub mod raycast;
pub mod sheared_ray;
pub mod terrain_mesh;
pub mod theil_sen;
pub mod tri_packet;
pub mod union_find;
pub mod wide_bvh;
