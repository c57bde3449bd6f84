//! Per-pixel segmentation of street views by the user's ONNX model, in process (paper Sec. 4.2.1:
//! the semantic and material masks the relief, material and clutter steps read).
//!
//! The model gives per-pixel class logits [1, C, H', W'] (argmax taken here) or class ids
//! [1, H', W'] / [1, 1, H', W'], at any resolution: the output is resized back to the view by
//! nearest neighbour. A label table (RON, `graphs/labels/*.ron`) maps the model's classes onto
//! ours; the result becomes the view's material map, or its architectural and clutter instances
//! (each 4-connected region of one mapped class is an instance).

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Instances, PodVec, RMSNET_CLASSES, ViewSet};
use crate::io::onnx::{ImageInput, ModelOutput, OnnxModel, OutputData};
use crate::io::onnx::{check_model_params, model_files, resize_nearest, single_plane};
use crate::raster::label::label_regions;
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Architectural classes: building parts, written to `View::arch`.
pub const ARCH_CLASSES: &[&str] = &["wall", "roof", "window", "door", "balcony", "drainpipe"];
/// Clutter classes: objects in front of buildings, written to `View::clutter`.
pub const CLUTTER_CLASSES: &[&str] = &[
    "car",
    "van",
    "bus",
    "truck",
    "bicycle",
    "person",
    "pole",
    "sign",
    "traffic light",
    "bench",
    "shelter",
    "hydrant",
    "tree",
    "vegetation",
];
/// The most classes a label table (and so a model) may have.
pub const MAX_CLASSES: usize = 1024;

/// Which layer of the views the segmentation becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Target {
    /// The material map (`View::material`); the table maps to material names (RMSNet's, or
    /// names already in the view set's material table).
    Material,
    /// Both instance layers: architectural classes to `arch`, clutter classes to `clutter`.
    Instances,
    /// Only `arch` (clutter classes in the table are ignored; `clutter` is kept).
    Arch,
    /// Only `clutter` (architectural classes are ignored; `arch` is kept).
    Clutter,
}

fn default_min_pixels() -> u32 {
    16
}
fn one() -> u32 {
    1
}

/// Params of [`SegmentViews`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentViewsParams {
    /// The ONNX model file.
    pub model: String,
    /// Models over 2 GB keep their weights in a file beside the `.onnx` (ONNX external data):
    /// name it here so its contents enter the cache key.
    #[serde(default)]
    pub model_data: Option<String>,
    /// The label table (RON): model class index -> our class, e.g.
    /// `graphs/labels/cityscapes.ron`.
    pub labels: String,
    /// The layer written.
    pub target: Target,
    /// How pixels become the model's input (size, mean, std, layout, channel order).
    #[serde(default)]
    pub input: ImageInput,
    /// The model output to read (default: the first).
    #[serde(default)]
    pub output: Option<String>,
    /// Instance targets: regions smaller than this many pixels are dropped (default 16).
    #[serde(default = "default_min_pixels")]
    pub min_pixels: u32,
    /// ONNX Runtime intra-op threads, 1 to 64 (default 1: bit-identical results whatever the
    /// machine's core count).
    #[serde(default = "one")]
    pub threads: u32,
}

/// A label table file (`graphs/labels/*.ron`): `(model: "...", classes: [("road", None),
/// ("building", Some("wall")), ...])`, the model's classes in index order.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LabelTable {
    /// The model family (free text).
    pub model: String,
    /// Per model class, in index order: the model's class name and ours (`None`: ignored).
    pub classes: Vec<(String, Option<String>)>,
}

impl LabelTable {
    /// Reads and checks a table: RON of this shape, 1 to [`MAX_CLASSES`] classes.
    pub fn read(path: &Path) -> Result<LabelTable, StageError> {
        let text = crate::io::open::read_regular_to_string(path).map_err(|e| {
            StageError::bad_input(path, "file", format!("a readable label table: {e}"))
        })?;
        let table: LabelTable = ron::from_str(&text).map_err(|e| {
            StageError::bad_input(
                path,
                format!("line {}, column {}", e.span.start.line, e.span.start.col),
                format!(
                    "a label table `(model: \"...\", classes: [(\"model class\", Some(\"our class\")) or (\"model class\", None), ...])`: {}",
                    e.code
                ),
            )
        })?;
        if table.classes.is_empty() || table.classes.len() > MAX_CLASSES {
            return Err(StageError::bad_input(
                path,
                "classes",
                format!("1 to {MAX_CLASSES} classes, found {}", table.classes.len()),
            ));
        }
        Ok(table)
    }
}

/// Runs a segmentation model over every view.
pub struct SegmentViews;

impl Stage for SegmentViews {
    const KIND: &'static str = "SegmentViews";
    // 2: the views' pixels are parts (one per view), the set holds their heads.
    const VERSION: u32 = 2;
    const DOC: &'static str = "street views segmented in process by an ONNX model (feature `onnx`), mapped by a label table into arch/clutter instances (Sec. 4.2.1) or material maps (Sec. 4.2.3)";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "views",
        ArtifactType::Views,
        "the view set whose images are segmented",
    )];
    type Params = SegmentViewsParams;
    type Output = ViewSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        check_model_params(&p.input, p.threads)?;
        if p.min_pixels == 0 {
            return Err(ParamError::new("min_pixels", "expected at least 1 pixel"));
        }
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        let labels = FileRef {
            field: "labels",
            path: p.labels.clone(),
        };
        [vec![labels], model_files(&p.model, p.model_data.as_deref())].concat()
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ViewSet, StageError> {
        let views: &ViewSet = inputs.one("views")?;
        let (labels_path, model_path) = (ctx.file(0)?, ctx.file(1)?);
        let table = LabelTable::read(labels_path)?;
        let mut out = views.clone();
        let classes = map_classes(&table, p.target, labels_path, &mut out.material_classes)?;
        let mut model =
            OnnxModel::open(model_path, p.threads, p.input.layout, p.output.as_deref())?;
        ctx.progress.set_total(out.views.len() as u64);
        let needed = table
            .classes
            .iter()
            .rposition(|(_, ours)| ours.is_some())
            .map_or(0, |i| i + 1);
        let n_classes = out.material_classes.len();
        // One view in memory at a time: load, run the model, store, drop.
        for head in &mut out.views {
            let mut view = head.load(ctx.parts)?;
            let result = model.run(&view.image, view.width, view.height, &p.input, "input")?;
            let (ids, (oh, ow)) = class_ids(&model, &result, table.classes.len(), needed)?;
            let (w, h) = (view.width as usize, view.height as usize);
            let per_pixel = resize_nearest(&ids, ow, oh, w, h);
            match p.target {
                Target::Material => {
                    view.material = Some(PodVec(
                        per_pixel
                            .iter()
                            .map(|&c| classes.material[c as usize])
                            .collect(),
                    ));
                }
                Target::Instances | Target::Arch | Target::Clutter => {
                    let min = p.min_pixels as usize;
                    let size = (w, h, min);
                    if p.target != Target::Clutter {
                        let (layer, dropped) =
                            instances(&per_pixel, &classes.arch, ARCH_CLASSES, size);
                        warn_dropped(ctx, &view.id, "arch", dropped);
                        view.arch = Some(layer);
                    }
                    if p.target != Target::Arch {
                        let (layer, dropped) =
                            instances(&per_pixel, &classes.clutter, CLUTTER_CLASSES, size);
                        warn_dropped(ctx, &view.id, "clutter", dropped);
                        view.clutter = Some(layer);
                    }
                }
            }
            *head = super::store_output(view, n_classes, ctx.parts)?;
            ctx.progress.advance(1);
        }
        Ok(out)
    }
}

/// Per model class: its material index (255 = none), or its class index + 1 in the arch and
/// clutter vocabularies (0 = not that layer).
struct ClassMap {
    material: Vec<u8>,
    arch: Vec<u32>,
    clutter: Vec<u32>,
}

/// Checks the table's names against the target's vocabulary and maps each model class; for
/// materials, adds the table's names missing from the view set's material table (in table order).
fn map_classes(
    table: &LabelTable,
    target: Target,
    path: &Path,
    materials: &mut Vec<String>,
) -> Result<ClassMap, StageError> {
    let n = table.classes.len();
    let mut map = ClassMap {
        material: vec![255; n],
        arch: vec![0; n],
        clutter: vec![0; n],
    };
    for (i, (theirs, ours)) in table.classes.iter().enumerate() {
        let Some(ours) = ours else { continue };
        let place = || format!("classes[{i}] (\"{theirs}\")");
        if target == Target::Material {
            let known = RMSNET_CLASSES.contains(&ours.as_str()) || materials.contains(ours);
            if !known {
                return Err(StageError::bad_input(
                    path,
                    place(),
                    format!(
                        "a material class ({}, or one of the view set's materials {:?}) or None, found \"{ours}\"",
                        RMSNET_CLASSES.join(", "),
                        materials
                    ),
                ));
            }
            let k = match materials.iter().position(|m| m == ours) {
                Some(k) => k,
                None => {
                    materials.push(ours.clone());
                    materials.len() - 1
                }
            };
            if k >= 255 {
                return Err(StageError::bad_input(
                    path,
                    place(),
                    "at most 255 material classes in the view set's table (255 means none)",
                ));
            }
            map.material[i] = k as u8;
        } else if let Some(k) = ARCH_CLASSES.iter().position(|c| c == ours) {
            map.arch[i] = k as u32 + 1;
        } else if let Some(k) = CLUTTER_CLASSES.iter().position(|c| c == ours) {
            map.clutter[i] = k as u32 + 1;
        } else {
            return Err(StageError::bad_input(
                path,
                place(),
                format!(
                    "an architectural class ({}), a clutter class ({}) or None, found \"{ours}\"",
                    ARCH_CLASSES.join(", "),
                    CLUTTER_CLASSES.join(", ")
                ),
            ));
        }
    }
    Ok(map)
}

/// The model's class per output pixel and the output's (height, width). Logits need one channel
/// per table class; the table's trailing ignored classes may be missing from the model (`needed`:
/// the classes up to the last mapped one).
fn class_ids(
    model: &OnnxModel,
    out: &ModelOutput,
    n: usize,
    needed: usize,
) -> Result<(Vec<u32>, (usize, usize)), StageError> {
    let expected = || {
        format!(
            "per-pixel logits of shape [1, {n}, H, W] (the label table's {n} classes) or class ids of shape [1, H, W]"
        )
    };
    let bad_shape = || model.bad_output(&expected(), &out.shape);
    let ids: Vec<i64> = match (&out.data, out.shape.as_slice()) {
        (OutputData::F32(v), &[1, c, h, w]) if c > 1 => {
            if c > n || c < needed || h == 0 || w == 0 {
                return Err(bad_shape());
            }
            return Ok((argmax(v, c, h * w), (h, w)));
        }
        (OutputData::Int(v), _) => v.clone(),
        (OutputData::F32(v), _) => v
            .iter()
            .map(|&x| if x.fract() == 0.0 { x as i64 } else { -1 })
            .collect(),
    };
    let (h, w) = single_plane(&out.shape).ok_or_else(bad_shape)?;
    let mut classes = Vec::with_capacity(ids.len());
    for &id in &ids {
        if id < 0 || id as usize >= n {
            return Err(model.bad_output(
                &format!(
                    "class ids 0 to {} (the label table's classes), found {id}",
                    n - 1
                ),
                &out.shape,
            ));
        }
        classes.push(id as u32);
    }
    Ok((classes, (h, w)))
}

/// Per pixel of `c` planes of `plane` values, the plane holding the largest value (the first on
/// ties; NaN never wins).
fn argmax(v: &[f32], c: usize, plane: usize) -> Vec<u32> {
    let mut best = vec![0u32; plane];
    let mut top: Vec<f32> = v[..plane].to_vec();
    for k in 1..c {
        for (i, &x) in v[k * plane..(k + 1) * plane].iter().enumerate() {
            if x > top[i] || (top[i].is_nan() && !x.is_nan()) {
                top[i] = x;
                best[i] = k as u32;
            }
        }
    }
    best
}

/// Instances of one layer: 4-connected regions of equal class (`class_of[model class]`: index + 1
/// in `vocabulary`, 0 = not this layer) of at least `min` pixels, numbered 1, 2, ... in raster
/// order of their first pixel. Also returns how many regions were dropped past the 65535 ids a
/// layer holds.
fn instances(
    per_pixel: &[u32],
    class_of: &[u32],
    vocabulary: &[&str],
    (w, h, min): (usize, usize, usize),
) -> (Instances, usize) {
    let key: Vec<u32> = per_pixel.iter().map(|&c| class_of[c as usize]).collect();
    let labels = label_regions(&key, w as u32, h as u32, min);
    let mut classes = BTreeMap::new();
    let mut last = 0u32;
    let ids = labels
        .iter()
        .zip(&key)
        .map(|(&l, &k)| {
            last = last.max(l);
            match u16::try_from(l) {
                Ok(0) | Err(_) => 0,
                Ok(id) => {
                    classes
                        .entry(id)
                        .or_insert_with(|| vocabulary[k as usize - 1].to_owned());
                    id
                }
            }
        })
        .collect();
    let dropped = last.saturating_sub(u16::MAX as u32) as usize;
    (
        Instances {
            ids: PodVec(ids),
            classes,
        },
        dropped,
    )
}

fn warn_dropped(ctx: &Ctx, view: &str, layer: &str, dropped: usize) {
    if dropped > 0 {
        ctx.progress.warn(&format!(
            "view {view}: {dropped} {layer} regions past the 65535 a layer holds were dropped; raise min_pixels"
        ));
    }
}
