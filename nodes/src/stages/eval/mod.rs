//! Evaluation (Sec. 5, Table 1): predictions scored against measurements, reconstruction scored
//! against references, and the report.

pub mod evaluate;
pub mod footprint_score;
pub mod map_plot;
pub mod material_plot;
pub mod point_stats;
pub mod raster_stats;
pub mod relief_plot;
pub mod report;
