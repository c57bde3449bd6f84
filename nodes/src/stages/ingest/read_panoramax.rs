//! Ingest of street-level views from Panoramax (STAC Items with their images), placed in the site
//! frame from their heading, pitch and roll (paper Sec. 4.2: registration of street views from
//! their metadata).

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Raster, ViewSet};
use crate::io::street_imagery::panoramax::read_panoramax;
use crate::io::street_imagery::provider::{
    PanoramaCut, ReadOptions, check_options, default_camera_height_m, default_panorama_hfov_deg,
    default_panorama_views,
};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadPanoramax`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadPanoramaxParams {
    /// The folder of STAC Item `*.json` files (or an ItemCollection) and their images (see
    /// [`crate::io::street_imagery::panoramax`]). The whole folder is the node's input.
    pub path: String,
    /// Camera height above the terrain, metres. Default 2.5.
    #[serde(default = "default_camera_height_m")]
    pub camera_height_m: f64,
    /// Take z from the geometry's third coordinate (ellipsoidal) instead of the `terrain` input
    /// plus `camera_height_m`. Default false.
    #[serde(default)]
    pub trust_altitude: bool,
    /// Pinhole views cut from each 360° panorama, evenly in heading. Default 4.
    #[serde(default = "default_panorama_views")]
    pub panorama_views: u32,
    /// Field of view of each panorama view, degrees. Default 90.
    #[serde(default = "default_panorama_hfov_deg")]
    pub panorama_hfov_deg: f64,
    /// Side of each (square) panorama view, pixels. Default: the panorama's resolution.
    #[serde(default)]
    pub panorama_size_px: Option<u32>,
}

/// Reads Panoramax STAC items into views in the site frame (no model outputs yet).
pub struct ReadPanoramax;

impl Stage for ReadPanoramax {
    const KIND: &'static str = "ReadPanoramax";
    // 2: the views' pixels are parts (one per view), the set holds their heads.
    const VERSION: u32 = 2;
    const DOC: &'static str = "Panoramax STAC items (+ images) into street views in the site frame, panoramas cut into pinhole views, Sec. 4.2";
    const INPUTS: &'static [InputSpec] = &[InputSpec::optional(
        "terrain",
        ArtifactType::Raster,
        "terrain heights: camera z = terrain + camera_height_m (needed unless trust_altitude)",
    )];
    type Params = ReadPanoramaxParams;
    type Output = ViewSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        check_options(p.camera_height_m, &cut(p))
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }]
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ViewSet, StageError> {
        let terrain = inputs.optional::<Raster>("terrain")?;
        let opts = ReadOptions::new(terrain, p.trust_altitude, p.camera_height_m, cut(p), 180.0)?
            .storing_in(ctx.parts);
        let folder = ctx.file(0)?;
        read_panoramax(folder, ctx.site, &opts)?.finish(folder, &opts, ctx.progress, ctx.parts)
    }
}

fn cut(p: &ReadPanoramaxParams) -> PanoramaCut {
    PanoramaCut {
        views: p.panorama_views,
        hfov_deg: p.panorama_hfov_deg,
        size_px: p.panorama_size_px,
    }
}
