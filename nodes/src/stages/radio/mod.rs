//! Radio (Sec. 5): link paths and radio maps traced through a scene.

pub mod coverage;
pub mod radio_map;
pub mod trace;
