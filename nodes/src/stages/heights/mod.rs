//! Height fields (Sec. 4): each source rasterized onto the site grid, composited, filtered and
//! compared.

pub mod clamp;
pub mod coarsen;
pub mod composite_height;
pub mod difference;
pub mod flat_ground;
pub mod gaussian_blur;
pub mod rasterize_scene;
pub mod rasterize_surface;
