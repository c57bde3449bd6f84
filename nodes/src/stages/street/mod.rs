//! Street level (Sec. 4.2): surface charts on the building solids, exposure-weighted multi-view
//! fusion of street views onto them (eq. (2)-(3)), and the stages built on it: façade relief
//! (eq. (4)), materials (eq. (5)), clutter and foliage.

pub mod apply_materials;
pub mod canopies;
pub mod carve_relief;
pub mod fuse_materials;
pub mod fuse_views;
pub mod place_clutter;
pub mod register_views;
pub mod relief;
pub mod surface_charts;
