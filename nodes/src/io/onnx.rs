//! Image models in ONNX, run in process (feature `onnx`; paper Sec. 4.2.1): ONNX Runtime loaded at
//! run time from `ORT_DYLIB_PATH`, a model file opened with a bounded thread count, an RGB image
//! resized and normalised into the model's input, the model's output read back as a grid, and
//! grids resized to the image by nearest neighbour.
//!
//! Determinism: a session runs single-threaded by default, with ONNX Runtime's deterministic
//! kernels and sequential execution, so the same model on the same pixels gives the same bits
//! whatever the engine's own thread count. More intra-op threads (`threads`) are faster; the
//! thread count enters the params, so a cached output always matches its own setting.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use ort::session::Session;
use ort::value::{Tensor, TensorElementType, ValueType};
use serde::{Deserialize, Serialize};

use crate::stage::{FileRef, ParamError, StageError};

/// The largest model input side, pixels.
pub const MAX_SIDE: u32 = 4096;
/// The most intra-op threads a session may use.
pub const MAX_THREADS: u32 = 64;

/// What to install and set when ONNX Runtime is missing.
pub const ORT_SETUP: &str = "the `onnx` stages load ONNX Runtime at run time from the file named by \
ORT_DYLIB_PATH; install it from PyPI and point ORT_DYLIB_PATH at the library inside the wheel: \
`pip install onnxruntime` then \
`export ORT_DYLIB_PATH=$(python3 -c \"import onnxruntime, os, glob; print(glob.glob(os.path.join(os.path.dirname(onnxruntime.__file__), 'capi', 'libonnxruntime.so*'))[0])\")` \
(on Linux the file is onnxruntime/capi/libonnxruntime.so.<version>, e.g. libonnxruntime.so.1.32.0; \
on macOS libonnxruntime.<version>.dylib; on Windows onnxruntime.dll)";

/// Where ONNX Runtime is, from `ORT_DYLIB_PATH`, or what to do when it is not set.
pub fn ort_dylib_path() -> Result<PathBuf, StageError> {
    match std::env::var_os("ORT_DYLIB_PATH") {
        Some(p) if !p.is_empty() => {
            let p = PathBuf::from(p);
            if p.is_file() {
                Ok(p)
            } else {
                Err(StageError::Failed(format!(
                    "ORT_DYLIB_PATH={} is not a file; {ORT_SETUP}",
                    p.display()
                )))
            }
        }
        _ => Err(StageError::Failed(format!(
            "ORT_DYLIB_PATH is not set; {ORT_SETUP}"
        ))),
    }
}

/// Loads ONNX Runtime once per process (later calls are free).
pub fn load_runtime() -> Result<(), StageError> {
    static LOADED: OnceLock<()> = OnceLock::new();
    if LOADED.get().is_some() {
        return Ok(());
    }
    let path = ort_dylib_path()?;
    let builder = ort::init_from(&path).map_err(|e| {
        StageError::Failed(format!(
            "could not load ONNX Runtime from ORT_DYLIB_PATH={}: {e}; {ORT_SETUP}",
            path.display()
        ))
    })?;
    // False when an environment was committed before (by another caller): that one is used.
    let _ = builder.with_name("kodama").with_telemetry(false).commit();
    let _ = LOADED.set(());
    Ok(())
}

/// How the image tensor is laid out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Layout {
    /// [1, 3, H, W] (PyTorch exports).
    #[default]
    Nchw,
    /// [1, H, W, 3] (TensorFlow exports).
    Nhwc,
}

/// The order of the colour channels in the tensor.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Channels {
    /// Red, green, blue.
    #[default]
    Rgb,
    /// Blue, green, red (OpenCV/detectron2-trained models).
    Bgr,
}

fn imagenet_mean() -> [f32; 3] {
    [0.485, 0.456, 0.406]
}
fn imagenet_std() -> [f32; 3] {
    [0.229, 0.224, 0.225]
}

/// How pixels become a model's input: the tensor value of channel `c` is
/// `(pixel / 255 - mean[c]) / std[c]`, the image resized bilinearly (half-pixel centres) to the
/// input size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageInput {
    /// Input (width, height) for a model whose input size is not fixed in the file; a fixed size
    /// wins, and a different `size` is an error. Default: the view's own size. At most
    /// [`MAX_SIDE`] a side.
    #[serde(default)]
    pub size: Option<(u32, u32)>,
    /// Per-channel mean on pixel values scaled to [0, 1], in tensor channel order (default
    /// ImageNet's, 0.485, 0.456, 0.406).
    #[serde(default = "imagenet_mean")]
    pub mean: [f32; 3],
    /// Per-channel standard deviation, likewise (default ImageNet's, 0.229, 0.224, 0.225).
    #[serde(default = "imagenet_std")]
    pub std: [f32; 3],
    /// Tensor layout (default `Nchw`).
    #[serde(default)]
    pub layout: Layout,
    /// Channel order (default `Rgb`).
    #[serde(default)]
    pub channels: Channels,
}

impl Default for ImageInput {
    fn default() -> Self {
        ImageInput {
            size: None,
            mean: imagenet_mean(),
            std: imagenet_std(),
            layout: Layout::default(),
            channels: Channels::default(),
        }
    }
}

impl ImageInput {
    /// Rejects a zero or oversized `size`, non-finite means and non-positive deviations.
    pub fn check(&self, field: &'static str) -> Result<(), ParamError> {
        if let Some((w, h)) = self.size
            && (w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE)
        {
            return Err(ParamError::new(
                field,
                format!("size: expected 1 to {MAX_SIDE} pixels a side, got ({w}, {h})"),
            ));
        }
        if self.mean.iter().any(|m| !m.is_finite()) {
            return Err(ParamError::new(field, "mean: expected finite numbers"));
        }
        if self.std.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(ParamError::new(field, "std: expected positive numbers"));
        }
        Ok(())
    }

    /// The tensor of `image` (`w` x `h`, row-major RGB) at `size` = (width, height).
    pub fn tensor(&self, image: &[[u8; 3]], w: u32, h: u32, size: (u32, u32)) -> Vec<f32> {
        let (dw, dh) = (size.0 as usize, size.1 as usize);
        let plane = dw * dh;
        let mut out = vec![0f32; 3 * plane];
        let xs: Vec<(usize, usize, f32)> = (0..dw).map(|x| taps(x, w as usize, dw)).collect();
        for y in 0..dh {
            let (y0, y1, fy) = taps(y, h as usize, dh);
            for (x, &(x0, x1, fx)) in xs.iter().enumerate() {
                let at = |r: usize, c: usize| image[r * w as usize + c];
                let (p00, p01, p10, p11) = (at(y0, x0), at(y0, x1), at(y1, x0), at(y1, x1));
                for k in 0..3 {
                    let src = match self.channels {
                        Channels::Rgb => k,
                        Channels::Bgr => 2 - k,
                    };
                    let top = lerp(p00[src] as f32, p01[src] as f32, fx);
                    let bottom = lerp(p10[src] as f32, p11[src] as f32, fx);
                    let v = (lerp(top, bottom, fy) / 255.0 - self.mean[k]) / self.std[k];
                    let i = y * dw + x;
                    match self.layout {
                        Layout::Nchw => out[k * plane + i] = v,
                        Layout::Nhwc => out[i * 3 + k] = v,
                    }
                }
            }
        }
        out
    }
}

/// The two source samples and the weight of the second for destination index `d` when `n`
/// samples are resized to `m` (half-pixel centres, clamped at the edges).
fn taps(d: usize, n: usize, m: usize) -> (usize, usize, f32) {
    let s = ((d as f64 + 0.5) * n as f64 / m as f64 - 0.5).clamp(0.0, (n - 1) as f64);
    let i = s.floor() as usize;
    let j = (i + 1).min(n - 1);
    (i, j, (s - i as f64) as f32)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    if t == 0.0 { a } else { a + (b - a) * t }
}

/// `src` (`sw` x `sh`, row-major) resized to `dw` x `dh` by nearest neighbour (pixel centres).
pub fn resize_nearest<T: Copy>(src: &[T], sw: usize, sh: usize, dw: usize, dh: usize) -> Vec<T> {
    let xs: Vec<usize> = (0..dw)
        .map(|x| ((2 * x + 1) * sw / (2 * dw)).min(sw - 1))
        .collect();
    let mut out = Vec::with_capacity(dw * dh);
    for y in 0..dh {
        let row = ((2 * y + 1) * sh / (2 * dh)).min(sh - 1) * sw;
        out.extend(xs.iter().map(|&x| src[row + x]));
    }
    out
}

/// The checks every model stage's params share: the image input and the thread count.
pub fn check_model_params(input: &ImageInput, threads: u32) -> Result<(), ParamError> {
    input.check("input")?;
    if !(1..=MAX_THREADS).contains(&threads) {
        return Err(ParamError::new(
            "threads",
            format!("expected 1 to {MAX_THREADS} threads"),
        ));
    }
    Ok(())
}

/// The files of a model: the `.onnx` (params field `model`) and, for a model over 2 GB, its
/// external-data file (`model_data`), so that both enter the cache key.
pub fn model_files(model: &str, model_data: Option<&str>) -> Vec<FileRef> {
    let mut files = vec![FileRef {
        field: "model",
        path: model.to_owned(),
    }];
    if let Some(d) = model_data {
        files.push(FileRef {
            field: "model_data",
            path: d.to_owned(),
        });
    }
    files
}

/// A model's output tensor, copied out of ONNX Runtime.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelOutput {
    /// Its shape.
    pub shape: Vec<usize>,
    /// Its values.
    pub data: OutputData,
}

/// The values of a [`ModelOutput`].
#[derive(Clone, Debug, PartialEq)]
pub enum OutputData {
    /// float32 values (logits, depth).
    F32(Vec<f32>),
    /// Integer values (class ids) of any integer element type, widened.
    Int(Vec<i64>),
}

/// A model file opened in ONNX Runtime, with its image input and the output it reads.
pub struct OnnxModel {
    session: Session,
    path: PathBuf,
    input: String,
    /// The input's declared shape (-1 where dynamic).
    input_shape: Vec<i64>,
    layout: Layout,
    output: String,
}

impl std::fmt::Debug for OnnxModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxModel")
            .field("path", &self.path)
            .field("input", &self.input)
            .field("input_shape", &self.input_shape)
            .field("output", &self.output)
            .finish()
    }
}

impl OnnxModel {
    /// Opens the model at `path` (the file a stage declared) with `threads` intra-op threads. The
    /// model must take one float32 image tensor in `layout`; `output` names the output to read
    /// (default: the first). Anything else is a `BadInput` naming the file.
    pub fn open(
        path: &Path,
        threads: u32,
        layout: Layout,
        output: Option<&str>,
    ) -> Result<OnnxModel, StageError> {
        load_runtime()?;
        let threads = threads.clamp(1, MAX_THREADS) as usize;
        let mut builder = Session::builder()
            .map_err(runtime_error)?
            .with_intra_threads(threads)
            .map_err(runtime_error)?
            .with_inter_threads(1)
            .map_err(runtime_error)?
            .with_parallel_execution(false)
            .map_err(runtime_error)?
            .with_deterministic_compute(true)
            .map_err(runtime_error)?
            .with_intra_op_spinning(false)
            .map_err(runtime_error)?;
        let session = builder.commit_from_file(path).map_err(|e| {
            StageError::bad_input(
                path,
                "model",
                format!("an ONNX model; ONNX Runtime could not load it: {e}"),
            )
        })?;
        let bad = |place: &str, expected: String| StageError::bad_input(path, place, expected);
        let want = match layout {
            Layout::Nchw => "[1, 3, H, W]",
            Layout::Nhwc => "[1, H, W, 3]",
        };
        let [input] = session.inputs() else {
            return Err(bad(
                "inputs",
                format!(
                    "one float32 image input of shape {want}, found {} inputs",
                    session.inputs().len()
                ),
            ));
        };
        let (ty, shape) = match input.dtype() {
            ValueType::Tensor { ty, shape, .. } => (*ty, shape.to_vec()),
            other => {
                return Err(bad(
                    &format!("input `{}`", input.name()),
                    format!("a float32 image tensor of shape {want}, found {other:?}"),
                ));
            }
        };
        let channel_axis = match layout {
            Layout::Nchw => 1,
            Layout::Nhwc => 3,
        };
        let shape_ok =
            shape.len() == 4 && matches!(shape[0], 1 | -1) && matches!(shape[channel_axis], 3 | -1);
        if ty != TensorElementType::Float32 || !shape_ok {
            return Err(bad(
                &format!("input `{}`", input.name()),
                format!(
                    "a float32 image tensor of shape {want} (layout {layout:?}), found {ty:?} of shape {}",
                    dims(&shape)
                ),
            ));
        }
        let output = match output {
            Some(name) => {
                if !session.outputs().iter().any(|o| o.name() == name) {
                    let names: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
                    return Err(bad(
                        "outputs",
                        format!("an output named `{name}`, found {names:?}"),
                    ));
                }
                name.to_owned()
            }
            None => match session.outputs().first() {
                Some(o) => o.name().to_owned(),
                None => return Err(bad("outputs", "at least one output".into())),
            },
        };
        Ok(OnnxModel {
            input: input.name().to_owned(),
            session,
            path: path.to_path_buf(),
            input_shape: shape,
            layout,
            output,
        })
    }

    /// The model file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The (width, height) the model is fed for an image of `image` size: its fixed input size,
    /// else `requested`, else the image's own (at most [`MAX_SIDE`] a side).
    pub fn input_size(
        &self,
        requested: Option<(u32, u32)>,
        image: (u32, u32),
        field: &'static str,
    ) -> Result<(u32, u32), StageError> {
        let (hi, wi) = match self.layout {
            Layout::Nchw => (2, 3),
            Layout::Nhwc => (1, 2),
        };
        let fixed = |d: i64| (d > 0).then_some(d);
        match (fixed(self.input_shape[wi]), fixed(self.input_shape[hi])) {
            (Some(w), Some(h)) => {
                if w > MAX_SIDE as i64 || h > MAX_SIDE as i64 {
                    return Err(StageError::bad_input(
                        &self.path,
                        format!("input `{}`", self.input),
                        format!("an input of at most {MAX_SIDE} pixels a side, found {w} x {h}"),
                    ));
                }
                let (w, h) = (w as u32, h as u32);
                match requested {
                    Some(r) if r != (w, h) => Err(StageError::Param(ParamError::new(
                        field,
                        format!(
                            "size: the model {} takes a fixed {w} x {h} input; leave size out or set ({w}, {h})",
                            self.path.display()
                        ),
                    ))),
                    _ => Ok((w, h)),
                }
            }
            (None, None) => {
                let (w, h) = requested.unwrap_or(image);
                if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
                    return Err(StageError::Param(ParamError::new(
                        field,
                        format!(
                            "size: the view is {} x {} and the model takes any size; set size to at most {MAX_SIDE} pixels a side",
                            image.0, image.1
                        ),
                    )));
                }
                Ok((w, h))
            }
            _ => Err(StageError::bad_input(
                &self.path,
                format!("input `{}`", self.input),
                format!(
                    "an input whose height and width are both fixed or both dynamic, found shape {}",
                    dims(&self.input_shape)
                ),
            )),
        }
    }

    /// Runs the model on `image` (`w` x `h` RGB) resized and normalised by `input`.
    pub fn run(
        &mut self,
        image: &[[u8; 3]],
        w: u32,
        h: u32,
        input: &ImageInput,
        field: &'static str,
    ) -> Result<ModelOutput, StageError> {
        if w == 0 || h == 0 || image.len() != w as usize * h as usize {
            return Err(StageError::Failed(format!(
                "a view of {w} x {h} pixels has {} pixels",
                image.len()
            )));
        }
        let size = self.input_size(input.size, (w, h), field)?;
        let data = input.tensor(image, w, h, size);
        let shape: [i64; 4] = match self.layout {
            Layout::Nchw => [1, 3, size.1 as i64, size.0 as i64],
            Layout::Nhwc => [1, size.1 as i64, size.0 as i64, 3],
        };
        let failed =
            |e: ort::Error| StageError::Failed(format!("running {}: {e}", self.path.display()));
        let tensor = Tensor::from_array((shape, data)).map_err(failed)?;
        let outputs = self
            .session
            .run(ort::inputs![self.input.as_str() => tensor])
            .map_err(|e| StageError::Failed(format!("running {}: {e}", self.path.display())))?;
        let value = outputs.get(self.output.as_str()).ok_or_else(|| {
            StageError::Failed(format!(
                "{}: no output `{}`",
                self.path.display(),
                self.output
            ))
        })?;
        let place = format!("output `{}`", self.output);
        let ty = value
            .dtype()
            .tensor_type()
            .ok_or_else(|| StageError::bad_input(&self.path, &place, "a tensor output"))?;
        let extract_err =
            |e: ort::Error| StageError::Failed(format!("{}: {e}", self.path.display()));
        let (shape, data) = match ty {
            TensorElementType::Float32 => {
                let (s, d) = value.try_extract_tensor::<f32>().map_err(extract_err)?;
                (s.to_vec(), OutputData::F32(d.to_vec()))
            }
            TensorElementType::Int64 => {
                let (s, d) = value.try_extract_tensor::<i64>().map_err(extract_err)?;
                (s.to_vec(), OutputData::Int(d.to_vec()))
            }
            TensorElementType::Int32 => {
                let (s, d) = value.try_extract_tensor::<i32>().map_err(extract_err)?;
                (
                    s.to_vec(),
                    OutputData::Int(d.iter().map(|&v| v as i64).collect()),
                )
            }
            TensorElementType::Uint8 => {
                let (s, d) = value.try_extract_tensor::<u8>().map_err(extract_err)?;
                (
                    s.to_vec(),
                    OutputData::Int(d.iter().map(|&v| v as i64).collect()),
                )
            }
            other => {
                return Err(StageError::bad_input(
                    &self.path,
                    &place,
                    format!("float32 values or int64/int32/uint8 class ids, found {other:?}"),
                ));
            }
        };
        Ok(ModelOutput {
            shape: shape.iter().map(|&d| d.max(0) as usize).collect(),
            data,
        })
    }

    /// A `BadInput` for an output of the wrong shape: the model file, the output, the shape
    /// expected and the one found.
    pub fn bad_output(&self, expected: &str, found: &[usize]) -> StageError {
        StageError::bad_input(
            &self.path,
            format!("output `{}`", self.output),
            format!("{expected}, found shape {found:?}"),
        )
    }
}

fn runtime_error<R>(e: ort::Error<R>) -> StageError {
    StageError::Failed(format!("ONNX Runtime: {e}"))
}

fn dims(shape: &[i64]) -> String {
    let d: Vec<String> = shape
        .iter()
        .map(|&d| if d < 0 { "?".into() } else { d.to_string() })
        .collect();
    format!("[{}]", d.join(", "))
}

/// The (height, width) of a per-pixel output of shape [1, H, W] or [1, 1, H, W] (any integer or
/// float ids, or one value per pixel), `None` for any other shape.
pub fn single_plane(shape: &[usize]) -> Option<(usize, usize)> {
    match *shape {
        [1, h, w] | [1, 1, h, w] if h > 0 && w > 0 => Some((h, w)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_resize_halves_and_doubles() {
        let src = [1, 2, 3, 4];
        assert_eq!(
            resize_nearest(&src, 2, 2, 4, 2),
            vec![1, 1, 2, 2, 3, 3, 4, 4]
        );
        let big: Vec<u32> = (0..16).collect();
        assert_eq!(resize_nearest(&big, 4, 4, 2, 2), vec![5, 7, 13, 15]);
        assert_eq!(resize_nearest(&big, 4, 4, 4, 4), big);
    }

    #[test]
    fn tensor_is_normalised_in_layout_and_channel_order() {
        let image = [[255, 0, 51], [0, 255, 0]];
        let input = ImageInput {
            mean: [0.0; 3],
            std: [1.0; 3],
            ..Default::default()
        };
        let t = input.tensor(&image, 2, 1, (2, 1));
        assert_eq!(t, vec![1.0, 0.0, 0.0, 1.0, 0.2, 0.0]);
        let bgr = ImageInput {
            layout: Layout::Nhwc,
            channels: Channels::Bgr,
            ..input
        };
        assert_eq!(
            bgr.tensor(&image, 2, 1, (2, 1)),
            vec![0.2, 0.0, 1.0, 0.0, 1.0, 0.0]
        );
    }

    #[test]
    fn uniform_blocks_survive_halving_exactly() {
        // 2x2 blocks of one colour, halved: every output pixel is its block's colour.
        let image: Vec<[u8; 3]> = (0..16)
            .map(|i| {
                let (x, y) = (i % 4, i / 4);
                [(x / 2 * 100) as u8, (y / 2 * 100) as u8, 7]
            })
            .collect();
        let input = ImageInput {
            mean: [0.0; 3],
            std: [1.0; 3],
            ..Default::default()
        };
        let t = input.tensor(&image, 4, 4, (2, 2));
        assert_eq!(&t[..4], &[0.0, 100.0 / 255.0, 0.0, 100.0 / 255.0]);
        assert_eq!(&t[4..8], &[0.0, 0.0, 100.0 / 255.0, 100.0 / 255.0]);
    }
}
