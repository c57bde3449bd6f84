//! Monocular depth of street views by the user's ONNX model, in process (paper Sec. 4.2.2 and
//! 4.2.4: the depth the relief and clutter steps lift pixels with).
//!
//! The model gives one value per pixel, [1, 1, H', W'] or [1, H', W'], at any resolution: the map
//! is resized back to the view by nearest neighbour (no blending across depth edges). What the
//! value means is a param: depth, inverse depth (DepthAnything's relative models), or DepthPro's
//! canonical inverse depth, which the view's own focal length turns into metres. Relative depth
//! stays relative (a later stage calibrates it against the scene); it is scaled so that each
//! view's median depth is 1, one convention whatever the model's output scale.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, View, ViewSet};
use crate::io::onnx::{ImageInput, OnnxModel, OutputData};
use crate::io::onnx::{check_model_params, model_files, resize_nearest, single_plane};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// What the model's per-pixel value is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Predicts {
    /// Depth along the optical axis (DepthAnything V2 metric models, metres).
    Depth,
    /// Inverse depth, 1/z (DepthAnything's relative models: disparity up to a scale).
    InverseDepth,
    /// DepthPro's canonical inverse depth: inverse depth for a focal length equal to the image
    /// width, so z = fx / (width * value) with the view's own intrinsics, in metres.
    CanonicalInverseDepth,
}

/// Whether depth is in metres or known up to a scale only.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Units {
    /// Metres, written as they are.
    Metric,
    /// Up to a scale: each view's depth is divided by its median (finite depths), for a later
    /// stage to calibrate.
    Relative,
}

fn one() -> u32 {
    1
}

/// Params of [`EstimateDepth`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimateDepthParams {
    /// The ONNX model file.
    pub model: String,
    /// Models over 2 GB keep their weights in a file beside the `.onnx` (ONNX external data):
    /// name it here so its contents enter the cache key.
    #[serde(default)]
    pub model_data: Option<String>,
    /// What the model's value is.
    pub predicts: Predicts,
    /// Metric or relative.
    pub units: Units,
    /// How pixels become the model's input (size, mean, std, layout, channel order).
    #[serde(default)]
    pub input: ImageInput,
    /// The model output to read (default: the first).
    #[serde(default)]
    pub output: Option<String>,
    /// ONNX Runtime intra-op threads, 1 to 64 (default 1: bit-identical results whatever the
    /// machine's core count).
    #[serde(default = "one")]
    pub threads: u32,
}

/// Runs a depth model over every view.
pub struct EstimateDepth;

impl Stage for EstimateDepth {
    const KIND: &'static str = "EstimateDepth";
    // 2: the views' pixels are parts (one per view), the set holds their heads.
    const VERSION: u32 = 2;
    const DOC: &'static str = "monocular depth of street views in process by an ONNX model (feature `onnx`), metric or relative, Sec. 4.2.2";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "views",
        ArtifactType::Views,
        "the view set whose depth is estimated",
    )];
    type Params = EstimateDepthParams;
    type Output = ViewSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        check_model_params(&p.input, p.threads)?;
        if p.predicts == Predicts::CanonicalInverseDepth && p.units == Units::Relative {
            return Err(ParamError::new(
                "units",
                "CanonicalInverseDepth gives metres with the views' intrinsics: expected Metric",
            ));
        }
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        model_files(&p.model, p.model_data.as_deref())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ViewSet, StageError> {
        let views: &ViewSet = inputs.one("views")?;
        let mut model =
            OnnxModel::open(ctx.file(0)?, p.threads, p.input.layout, p.output.as_deref())?;
        let mut out = views.clone();
        ctx.progress.set_total(out.views.len() as u64);
        let n_classes = out.material_classes.len();
        // One view in memory at a time: load, run the model, store, drop.
        for head in &mut out.views {
            let mut view = head.load(ctx.parts)?;
            let result = model.run(&view.image, view.width, view.height, &p.input, "input")?;
            let expected = "a float32 depth map of shape [1, 1, H, W] or [1, H, W]";
            let (OutputData::F32(values), Some((h, w))) =
                (&result.data, single_plane(&result.shape))
            else {
                return Err(model.bad_output(expected, &result.shape));
            };
            let mut depth = resize_nearest(values, w, h, view.width as usize, view.height as usize);
            to_depth(&mut depth, p.predicts, &view);
            if p.units == Units::Relative {
                normalise_median(&mut depth);
            }
            view.depth = Some(PodVec(depth));
            *head = super::store_output(view, n_classes, ctx.parts)?;
            ctx.progress.advance(1);
        }
        Ok(out)
    }
}

/// Model values to depth in place; values that give no positive finite depth become inf (sky, or
/// unknown).
fn to_depth(values: &mut [f32], predicts: Predicts, view: &View) {
    // DepthPro: inverse depth at focal length = width, so z = (fx / width) / value.
    let scale = (view.intrinsics.fx / view.width as f64) as f32;
    for v in values {
        let z = match predicts {
            Predicts::Depth => *v,
            Predicts::InverseDepth => 1.0 / *v,
            Predicts::CanonicalInverseDepth => scale / *v,
        };
        *v = if z.is_finite() && z > 0.0 {
            z
        } else {
            f32::INFINITY
        };
    }
}

/// Divides finite depths by their median (the lower one for an even count); a view with no finite
/// depth is left as it is.
fn normalise_median(depth: &mut [f32]) {
    let mut finite: Vec<f32> = depth.iter().copied().filter(|d| d.is_finite()).collect();
    if finite.is_empty() {
        return;
    }
    let mid = (finite.len() - 1) / 2;
    let (_, &mut median, _) = finite.select_nth_unstable_by(mid, f32::total_cmp);
    for d in depth.iter_mut().filter(|d| d.is_finite()) {
        *d /= median;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_finite_depths_becomes_one() {
        let mut d = vec![4.0, f32::INFINITY, 2.0, 8.0, 6.0];
        normalise_median(&mut d);
        assert_eq!(d, vec![1.0, f32::INFINITY, 0.5, 2.0, 1.5]);
    }
}
