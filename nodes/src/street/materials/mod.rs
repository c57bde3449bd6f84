//! Per-surface ITU-R P.2040 materials (paper Sec. 4.2.3): what the views' material maps say
//! about each texel, fused by eq. (5) ([`fusion`]), then written into the scene as per-triangle
//! materials ([`apply`]).

pub mod apply;
pub mod fusion;
