//! Evaluation (Sec. 5, Table 1): predictions scored against measurements, reconstruction scored
//! against references, and the report.

pub mod evaluate;
pub mod footprint_score;
pub mod point_stats;
pub mod raster_stats;
pub mod report;
