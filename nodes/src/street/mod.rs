//! Sec. 4.2 of the paper, "Recovering detail from street-level imagery": the algorithms behind the
//! `stages/street` nodes, one room per step as the paper names it. Views are registered
//! ([`registration`]), what they see is fused onto the building charts by the exposure-weighted
//! projection of eq. (2)-(3) ([`fusion`]), and that fusion feeds the façade relief of eq. (4)
//! ([`relief`], carved into the solids by [`relief::carve`]) and the materials of eq. (5)
//! ([`materials`]); clutter is lifted from the views' depth ([`clutter`]) and canopies come from
//! the above-ground field ([`canopy`]). Uses `geom/`, `raster/`, `rf/` and `io/`; never a stage.

pub mod canopy;
pub mod clutter;
pub mod fusion;
pub mod materials;
pub mod registration;
pub mod relief;
