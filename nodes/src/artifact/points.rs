//! Point clouds in the site frame.

use serde::{Deserialize, Serialize};

use super::PodVec;

/// Points in the site frame (metres from the site origin, z up), with per-point attributes as
/// parallel arrays. Local coordinates keep f32 at sub-millimetre precision over tens of kilometres.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointSet {
    /// Positions, `[x, y, z]` per point.
    pub xyz: PodVec<[f32; 3]>,
    /// ASPRS classification per point (0 = never classified); empty when the source has none.
    pub class: PodVec<u8>,
    /// Return intensity per point; empty when the source has none.
    #[serde(default)]
    pub intensity: PodVec<u16>,
    /// Return number (1-based) per point; empty when the source has none.
    #[serde(default)]
    pub return_number: PodVec<u8>,
    /// Number of returns of the pulse per point; empty when the source has none.
    #[serde(default)]
    pub number_of_returns: PodVec<u8>,
    /// 16-bit RGB per point; empty when the source has none.
    #[serde(default)]
    pub rgb: PodVec<[u16; 3]>,
}

impl PointSet {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.xyz.len()
    }
    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.xyz.is_empty()
    }
    /// Axis-aligned bounds `(min, max)`, or `None` when empty.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let mut it = self.xyz.iter();
        let first = *it.next()?;
        Some(it.fold((first, first), |(mut lo, mut hi), p| {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
            (lo, hi)
        }))
    }
}
