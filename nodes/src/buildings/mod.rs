//! Sec. 4.1 of the paper, "Reconstructing terrain and buildings": the mechanisms behind the
//! `stages/buildings` nodes that are more than one stage's business: building outlines squared
//! to their dominant orientation ([`regularize`]) and planar roof faces with the lines where they
//! meet ([`roof_planes`]). Uses `geom/` and `raster/`; never a stage.

pub mod regularize;
pub mod roof_planes;
