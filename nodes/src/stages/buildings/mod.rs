//! Buildings (Sec. 4.1): terrain passes (eq. (1)), the above-ground field, building masks, cleaned
//! roofs, footprints and watertight solids, assembled into a scene.

pub mod above_ground;
pub mod assemble_scene;
pub mod building_mask;
pub mod building_solids;
pub mod roof_clean;
pub mod split_buildings;
pub mod terrain_pass;
pub mod trace_footprints;
pub mod unassigned;
