//! Raster mechanisms shared by the stages: gap filling, Gaussian blur, connected-component
//! labelling, morphology and surface normals. Never imports a stage.

pub mod blur;
pub mod gap_fill;
pub mod label;
pub mod morph;
pub mod normal;
