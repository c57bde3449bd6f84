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
