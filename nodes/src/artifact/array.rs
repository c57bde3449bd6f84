//! Numeric arrays that serialize as one byte string.
//!
//! MessagePack would otherwise tag every element (5 bytes and a branch per f32); as raw
//! little-endian bytes a 4-million-cell raster serializes with one copy and hashes at memory speed.

use std::fmt;
use std::marker::PhantomData;
use std::ops::{Deref, DerefMut};

use bytemuck::Pod;
use serde::de::{Error, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A `Vec<T>` of plain numbers stored as little-endian bytes.
#[derive(Clone, PartialEq)]
pub struct PodVec<T: Pod>(pub Vec<T>);

impl<T: Pod> PodVec<T> {
    /// An array of `n` copies of `v`.
    pub fn filled(v: T, n: usize) -> Self {
        PodVec(vec![v; n])
    }
}

impl<T: Pod> Default for PodVec<T> {
    fn default() -> Self {
        PodVec(Vec::new())
    }
}

impl<T: Pod> From<Vec<T>> for PodVec<T> {
    fn from(v: Vec<T>) -> Self {
        PodVec(v)
    }
}

impl<T: Pod> Deref for PodVec<T> {
    type Target = Vec<T>;
    fn deref(&self) -> &Vec<T> {
        &self.0
    }
}

impl<T: Pod> DerefMut for PodVec<T> {
    fn deref_mut(&mut self) -> &mut Vec<T> {
        &mut self.0
    }
}

impl<T: Pod> fmt::Debug for PodVec<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "PodVec<{}>[{}]",
            std::any::type_name::<T>(),
            self.0.len()
        )
    }
}

impl<T: Pod> Serialize for PodVec<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(bytemuck::cast_slice(&self.0))
    }
}

struct PodVisitor<T>(PhantomData<T>);

impl<'de, T: Pod> Visitor<'de> for PodVisitor<T> {
    type Value = PodVec<T>;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(
            f,
            "a byte string holding {} values",
            std::any::type_name::<T>()
        )
    }
    fn visit_bytes<E: Error>(self, bytes: &[u8]) -> Result<Self::Value, E> {
        let size = std::mem::size_of::<T>();
        if !bytes.len().is_multiple_of(size) {
            return Err(E::custom(format!(
                "{} bytes is not a whole number of {size}-byte values",
                bytes.len()
            )));
        }
        // Copy rather than cast: the byte string need not be aligned for T.
        let mut v = vec![T::zeroed(); bytes.len() / size];
        bytemuck::cast_slice_mut::<T, u8>(&mut v).copy_from_slice(bytes);
        Ok(PodVec(v))
    }
    fn visit_byte_buf<E: Error>(self, bytes: Vec<u8>) -> Result<Self::Value, E> {
        self.visit_bytes(&bytes)
    }
}

impl<'de, T: Pod> Deserialize<'de> for PodVec<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_bytes(PodVisitor(PhantomData))
    }
}

/// A layer of `len` f32 values most of which read `fill`: the others are kept as runs of
/// consecutive indices with their values in index order. The relief's layers are four fifths
/// NaN or zero (texels no view saw well); stored dense, a 1 km² site wrote 2.6 GB of them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SparseLayer {
    /// Values in the layer, kept or not.
    pub len: u32,
    /// What every index outside the runs reads.
    pub fill: f32,
    /// Per run, its first index and the offset of its first value in `values`; ascending in
    /// both, disjoint. A run ends where the next run's values begin (the last at `values`' end).
    pub runs: PodVec<[u32; 2]>,
    /// The kept values, run after run.
    pub values: PodVec<f32>,
}

impl SparseLayer {
    /// A layer where every index reads `fill`.
    pub fn filled(fill: f32, len: u32) -> SparseLayer {
        SparseLayer {
            len,
            fill,
            ..Default::default()
        }
    }

    /// Keeps every value of `dense` that is not `fill` (bit for bit; any NaN counts as a NaN
    /// fill), so [`SparseLayer::to_dense`] gives `dense` back exactly.
    ///
    /// # Panics
    /// If `dense` holds more than `u32::MAX` values (a chart never does: SurfaceCharts bounds
    /// their texels).
    pub fn from_dense(dense: &[f32], fill: f32) -> SparseLayer {
        let len = u32::try_from(dense.len()).expect("a layer of at most u32::MAX values");
        let is_fill = |v: f32| {
            if fill.is_nan() {
                v.is_nan()
            } else {
                v.to_bits() == fill.to_bits()
            }
        };
        let mut out = SparseLayer::filled(fill, len);
        let mut k = 0;
        while k < dense.len() {
            let start = k + dense[k..].iter().take_while(|&&v| is_fill(v)).count();
            k = start + dense[start..].iter().take_while(|&&v| !is_fill(v)).count();
            if k > start {
                out.runs.push([start as u32, out.values.len() as u32]);
                out.values.extend_from_slice(&dense[start..k]);
            }
        }
        out
    }

    /// Values in the layer.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// True for a layer of no values at all.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Run `i`: its first index and its values.
    fn run(&self, i: usize) -> (usize, &[f32]) {
        let [start, offset] = self.runs[i];
        let end = self
            .runs
            .get(i + 1)
            .map_or(self.values.len(), |r| r[1] as usize);
        (
            start as usize,
            self.values.get(offset as usize..end).unwrap_or(&[]),
        )
    }

    /// Index `k`'s value; `fill` outside the runs and past the end.
    pub fn get(&self, k: usize) -> f32 {
        let i = self.runs.partition_point(|r| r[0] as usize <= k);
        let Some(i) = i.checked_sub(1) else {
            return self.fill;
        };
        let (start, values) = self.run(i);
        values.get(k - start).copied().unwrap_or(self.fill)
    }

    /// The kept values with their indices, in index order.
    pub fn kept(&self) -> impl Iterator<Item = (usize, f32)> + '_ {
        (0..self.runs.len()).flat_map(move |i| {
            let (start, values) = self.run(i);
            values.iter().enumerate().map(move |(j, &v)| (start + j, v))
        })
    }

    /// Every value, `fill` included.
    pub fn to_dense(&self) -> Vec<f32> {
        let mut out = vec![self.fill; self.len()];
        for (k, v) in self.kept() {
            if let Some(slot) = out.get_mut(k) {
                *slot = v;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sparse_layer_reads_back_its_dense_values_bit_for_bit() {
        let nan = f32::NAN;
        let dense = [nan, 1.0, 2.0, nan, nan, -0.0, 3.0, nan, 4.0];
        let s = SparseLayer::from_dense(&dense, nan);
        assert_eq!(s.runs.len(), 3);
        assert_eq!(s.values.len(), 5);
        for (k, &v) in dense.iter().enumerate() {
            assert_eq!(s.get(k).to_bits(), v.to_bits(), "index {k}");
        }
        let back = s.to_dense();
        assert!(
            back.iter()
                .zip(&dense)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        assert!(s.get(dense.len()).is_nan());
        // A zero fill keeps -0.0, which is not its bits.
        let z = SparseLayer::from_dense(&[0.0, -0.0, 0.0, 5.0], 0.0);
        assert_eq!(z.kept().collect::<Vec<_>>(), vec![(1, -0.0), (3, 5.0)]);
        assert_eq!(z.get(1).to_bits(), (-0.0f32).to_bits());
        assert_eq!(z.get(0).to_bits(), 0.0f32.to_bits());
        let bytes = rmp_serde::to_vec(&z).unwrap();
        let round: SparseLayer = rmp_serde::from_slice(&bytes).unwrap();
        assert_eq!(round, z);
    }

    #[test]
    fn an_all_fill_layer_keeps_nothing() {
        let s = SparseLayer::from_dense(&[0.0; 7], 0.0);
        assert!(s.runs.is_empty() && s.values.is_empty());
        assert_eq!(s.len(), 7);
        assert_eq!(s.to_dense(), vec![0.0; 7]);
        assert!(SparseLayer::default().is_empty());
    }
}
