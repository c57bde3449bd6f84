//! ReadViewOutputs: the outputs of the segmentation, material, depth and normal models a user ran
//! on a provider's images (Mapillary, Panoramax), attached to the views that carry the poses
//! (paper Sec. 4.2.1: parsing is read from model outputs, see DESIGN.md, "Street views and model
//! outputs").

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, RMSNET_CLASSES, ViewSet};
use crate::io::views_io::read_view_outputs;
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadViewOutputs`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadViewOutputsParams {
    /// The folder holding `arch/<id>.png` (+ `.json`), `clutter/<id>.png` (+ `.json`),
    /// `material/<id>.png`, `depth/<id>.exr` and `normal/<id>.exr` per view id, any of them;
    /// the whole folder is the node's input.
    pub path: String,
    /// The classes the material maps index. Default RMSNet's 20 (`artifact::RMSNET_CLASSES`).
    #[serde(default = "rmsnet")]
    pub material_classes: Vec<String>,
    /// Fail, rather than warn, when a view has no output at all. Default false.
    #[serde(default)]
    pub require_all: bool,
}

fn rmsnet() -> Vec<String> {
    RMSNET_CLASSES.iter().map(|s| s.to_string()).collect()
}

/// Attaches model outputs from files to views read elsewhere.
pub struct ReadViewOutputs;

impl Stage for ReadViewOutputs {
    const KIND: &'static str = "ReadViewOutputs";
    // 2: the views' pixels are parts (one per view), the set holds their heads.
    const VERSION: u32 = 2;
    const DOC: &'static str = "model outputs (instances, materials, depth, normals) read from files and attached to provider views by id, Sec. 4.2.1";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "views",
        ArtifactType::Views,
        "the views the outputs belong to (ReadMapillary, ReadPanoramax, ReadViews)",
    )];
    type Params = ReadViewOutputsParams;
    type Output = ViewSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if p.material_classes.is_empty() || p.material_classes.len() > 255 {
            return Err(ParamError::new(
                "material_classes",
                "expected 1 to 255 class names (index 255 means none)",
            ));
        }
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }]
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ViewSet, StageError> {
        let views: &ViewSet = inputs.one("views")?;
        let dir = ctx.file(0)?;
        if !dir.is_dir() {
            return Err(StageError::bad_input(
                dir,
                "path",
                "expected a folder of model outputs (arch/, clutter/, material/, depth/, normal/)",
            ));
        }
        let mut out = views.clone();
        let mut bare = Vec::new();
        let mut from_files = vec![false; out.views.len()];
        ctx.progress.set_total(out.views.len() as u64);
        // One view in memory at a time: read its outputs, merge, store, drop.
        for (i, (head, material_read)) in out.views.iter_mut().zip(&mut from_files).enumerate() {
            let o = read_view_outputs(
                dir,
                &head.id,
                (head.width, head.height),
                &p.material_classes,
                dir,
            )?;
            ctx.progress.advance(1);
            if o.is_empty() {
                bare.push(head.id.clone());
                continue;
            }
            *material_read = o.material.is_some();
            let mut v = head.load(ctx.parts)?;
            // What the files give replaces what the view had; what they lack is kept.
            v.arch = o.arch.or(v.arch.take());
            v.clutter = o.clutter.or(v.clutter.take());
            v.material = o.material.or(v.material.take());
            v.depth = o.depth.or(v.depth.take());
            v.normal = o.normal.or(v.normal.take());
            // A map the files gave is checked against their table; one the view kept was
            // checked against the set's when it was stored, and goes below if the table changes.
            let n = if *material_read {
                p.material_classes.len()
            } else {
                views.material_classes.len()
            };
            *head = crate::io::views_io::store_checked(dir, i, v, n, ctx.parts)?;
        }
        if bare.len() == out.views.len() && !out.views.is_empty() {
            return Err(StageError::bad_input(
                dir,
                "path",
                format!(
                    "no model output for any of the {} views (looked for e.g. arch/{}.png); are the files named by view id?",
                    out.views.len(),
                    out.views[0].id
                ),
            ));
        }
        if !bare.is_empty() {
            let first: Vec<&str> = bare.iter().take(5).map(String::as_str).collect();
            let more = if bare.len() > 5 { ", ..." } else { "" };
            let msg = format!(
                "{} view(s) have no model output under {} ({}{more})",
                bare.len(),
                dir.display(),
                first.join(", ")
            );
            if p.require_all {
                return Err(StageError::bad_input(dir, "path", msg));
            }
            ctx.progress.warn(&msg);
        }
        if from_files.iter().any(|&m| m) && out.material_classes != p.material_classes {
            // One class table per view set: maps the views brought under another table go.
            for (i, (head, &read)) in out.views.iter_mut().zip(&from_files).enumerate() {
                if !read {
                    let mut v = head.load(ctx.parts)?;
                    if v.material.take().is_some() {
                        *head = crate::io::views_io::store_checked(
                            dir,
                            i,
                            v,
                            p.material_classes.len(),
                            ctx.parts,
                        )?;
                    }
                }
            }
            out.material_classes = p.material_classes.clone();
        }
        Ok(out)
    }
}
