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
    /// Appends the points of `other` at `indices`, with the attributes both sets carry; an
    /// attribute one of them lacks (when this set is not empty) is an error naming it.
    pub fn append_selected(&mut self, other: &PointSet, indices: &[usize]) -> Result<(), String> {
        let first = self.is_empty();
        fn take<T: Copy + bytemuck::Pod>(
            name: &str,
            into: &mut PodVec<T>,
            from: &PodVec<T>,
            n_from: usize,
            first: bool,
            indices: &[usize],
        ) -> Result<(), String> {
            let has = from.len() == n_from && n_from > 0;
            if !first && has == into.is_empty() {
                return Err(format!(
                    "the point sets disagree on whether points have {name}"
                ));
            }
            if has {
                into.extend(indices.iter().map(|&i| from[i]));
            }
            Ok(())
        }
        let n = other.len();
        self.xyz.extend(indices.iter().map(|&i| other.xyz[i]));
        take("a class", &mut self.class, &other.class, n, first, indices)?;
        take(
            "an intensity",
            &mut self.intensity,
            &other.intensity,
            n,
            first,
            indices,
        )?;
        take(
            "a return number",
            &mut self.return_number,
            &other.return_number,
            n,
            first,
            indices,
        )?;
        take(
            "a number of returns",
            &mut self.number_of_returns,
            &other.number_of_returns,
            n,
            first,
            indices,
        )?;
        take("a colour", &mut self.rgb, &other.rgb, n, first, indices)?;
        Ok(())
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
