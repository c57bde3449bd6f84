//! The stages of the pipeline, one module per node kind, in folders that follow the paper: ingest,
//! height fields, buildings (Sec. 4.1), street level (Sec. 4.2), radio, baselines and evaluation;
//! and the merges of a tiled run (`tiles`).
//!
//! **Invariant:** no stage imports another stage. What two stages share lives below them, in
//! `io`, `geom`, `raster`, `rf` or `artifact` (checked by `tests/layout.rs`).

pub mod baseline;
pub mod buildings;
pub mod eval;
pub mod heights;
pub mod ingest;
pub mod models;
pub mod radio;
pub mod street;
pub mod tiles;
