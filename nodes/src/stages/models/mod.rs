//! Models in process (Sec. 4.2.1, optional): per-pixel segmentation and monocular depth computed
//! from street images by the user's own ONNX models, for users who have not run them beforehand.
//! The file-based view layout (`io::views_io`) stays the primary path.
//!
//! Both stages need the `onnx` feature of this crate (off by default) and ONNX Runtime at run time
//! (`ORT_DYLIB_PATH`, see `io::onnx`).

#[cfg(feature = "onnx")]
pub mod estimate_depth;
#[cfg(feature = "onnx")]
pub mod segment_views;
