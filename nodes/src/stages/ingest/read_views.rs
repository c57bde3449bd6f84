//! Ingest of street-level view sets with the outputs of segmentation, depth and normal models
//! (paper Sec. 4.2: registration places them in the site frame from their metadata).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::artifact::ViewSet;
use crate::io::views_io::read_viewset;
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadViews`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadViewsParams {
    /// The `views.json`; its folder (images and model outputs) is the node's input.
    pub path: String,
}

/// Reads a view set in the layout of DESIGN.md (see [`crate::io::views_io`]).
pub struct ReadViews;

impl Stage for ReadViews {
    const KIND: &'static str = "ReadViews";
    // 2: the views' pixels are parts (one per view), the set holds their heads.
    const VERSION: u32 = 2;
    const DOC: &'static str = "street-view set (views.json, images, instance/material/depth/normal maps) into the site frame, Sec. 4.2";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadViewsParams;
    type Output = ViewSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !p.path.ends_with(".json") {
            return Err(ParamError::new("path", "expected the views.json file"));
        }
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        let folder = crate::params::folder_of(&p.path);
        vec![FileRef {
            field: "path",
            path: folder,
        }]
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<ViewSet, StageError> {
        let folder = ctx.file(0)?;
        read_viewset(
            &folder.join(Path::new(&p.path).file_name().unwrap_or_default()),
            ctx.site,
            ctx.parts,
        )
    }
}
