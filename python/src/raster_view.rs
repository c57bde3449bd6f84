//! A raster artifact's cells handed to NumPy as a view of the cache's mapped blob: the file's
//! pages are the array, so reading a raster costs no copy beyond the file read (the engine's
//! decode would copy every cell once more).
//!
//! MessagePack writes a `Raster`'s fields in order and `data` last, as raw bytes (`PodVec`):
//! the cells are the blob's last `width * height * 4` bytes, right after a `bin` header that
//! says so. The head (variant, grid) is read with the data skipped unread; the header before
//! the tail is checked byte for byte; anything else falls back to the decode.

use kodama_dag::cache::Blob;
use kodama_nodes::artifact::Grid;
use numpy::PyArray1;
use numpy::ndarray::ArrayView1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde::Deserialize;

/// The mapped blob, kept alive by the arrays that view it.
#[pyclass(frozen)]
pub(crate) struct MappedBlob(Blob);

/// The first variant of `Artifact` (`Raster`), its data skipped: any other artifact fails to
/// read as this.
#[derive(Deserialize)]
enum Head {
    Raster(RasterHead),
}

#[derive(Deserialize)]
struct RasterHead {
    grid: Grid,
    #[allow(dead_code)]
    data: serde::de::IgnoredAny,
}

/// The MessagePack `bin` header of `n` bytes.
fn bin_header(n: usize) -> Vec<u8> {
    if n <= u8::MAX as usize {
        vec![0xc4, n as u8]
    } else if n <= u16::MAX as usize {
        let mut h = vec![0xc5];
        h.extend_from_slice(&(n as u16).to_be_bytes());
        h
    } else {
        let mut h = vec![0xc6];
        h.extend_from_slice(&(n as u32).to_be_bytes());
        h
    }
}

/// Where a raster blob's cells start, and its grid; None when `bytes` is not a raster laid out
/// as `Artifact::Raster` serializes.
fn cells_of(bytes: &[u8]) -> Option<(usize, Grid)> {
    let Head::Raster(head) = rmp_serde::from_slice::<Head>(bytes).ok()?;
    let g = head.grid;
    let n = (g.width as usize)
        .checked_mul(g.height as usize)?
        .checked_mul(4)?;
    let start = bytes.len().checked_sub(n)?;
    let header = bin_header(n);
    let at = start.checked_sub(header.len())?;
    (bytes[at..start] == header[..]).then_some((start, g))
}

/// The raster dict `artifact` returns (`data` (height, width) float32), its data a read-only
/// view of `blob`; the blob back when it is not a raster of that layout. Tested from Python
/// (`python/tests/test_api.py`: rasters whose cells follow bin8, bin16 and bin32 headers).
pub(crate) fn raster_view<'py>(
    py: Python<'py>,
    blob: Blob,
) -> PyResult<Result<Bound<'py, PyDict>, Blob>> {
    let Some((start, g)) = cells_of(&blob) else {
        return Ok(Err(blob));
    };
    let owner = Bound::new(py, MappedBlob(blob))?;
    let bytes: &[u8] = &owner.get().0[start..];
    let view = ArrayView1::from(bytes);
    // SAFETY: `owner` holds the mapping the view points into, and becomes the array's base, so
    // the pages outlive the array; the array is made read-only below before anything sees it
    // (the mapping is read-only: a write would fault).
    let raw = unsafe { PyArray1::<u8>::borrow_from_array(&view, owner.clone().into_any()) };
    raw.call_method1("setflags", (false,))?;
    // Native-endian f32, as `PodVec` wrote them; NumPy marks the array unaligned where the
    // cells do not start on a 4-byte boundary, and reads it correctly either way.
    let cells = raw
        .call_method1("view", ("float32",))?
        .call_method1("reshape", ((g.height as usize, g.width as usize),))?;
    let d = PyDict::new(py);
    d.set_item("type", "Raster")?;
    d.set_item("x0", g.x0)?;
    d.set_item("y0", g.y0)?;
    d.set_item("cell_m", g.cell_m)?;
    d.set_item("data", cells)?;
    Ok(Ok(d))
}
