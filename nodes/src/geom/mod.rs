//! Geometry shared by the stages: closed solids and their checks, polygons, the terrain mesh, and
//! ray casting over a BVH. Never imports a stage.

pub mod assets;
pub mod boolean;
pub mod canopy;
pub mod carve;
pub mod charts;
pub mod clutter;
pub mod from_above;
pub mod fusion;
pub mod material_apply;
pub mod material_fusion;
pub mod mesh_build;
pub mod mesh_check;
pub mod polygon;
pub mod raycast;
pub mod regularize;
pub mod relief;
pub mod roof_planes;
pub mod terrain_mesh;
pub mod theil_sen;
pub mod tri_packet;
pub mod union_find;
pub mod view_registration;
pub mod wide_bvh;
