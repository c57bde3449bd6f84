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

/// Stores a view a model stage filled in: its layers were sized to the view by the stage, so a
/// view that fails [`crate::artifact::View::check`] is the stage's fault, not the user's.
#[cfg(feature = "onnx")]
fn store_output(
    view: crate::artifact::View,
    n_classes: usize,
    parts: &dyn crate::stage::PartStore,
) -> Result<crate::artifact::ViewHead, crate::stage::StageError> {
    let id = view.id.clone();
    view.store(n_classes, parts)?.map_err(|(what, m)| {
        crate::stage::StageError::Failed(format!(
            "view {id:?}: the model's {what} is not what the view needs (expected {m}; a bug)"
        ))
    })
}
