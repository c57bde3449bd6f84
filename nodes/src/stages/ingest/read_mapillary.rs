//! Ingest of street-level views as downloaded from Mapillary (API v4 image entities with their
//! JPEGs), placed in the site frame from their computed poses (paper Sec. 4.2: registration of
//! street views from their metadata).

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Raster, ViewSet};
use crate::io::street_imagery::mapillary::read_mapillary;
use crate::io::street_imagery::provider::{
    PanoramaCut, ReadOptions, check_options, default_camera_height_m, default_panorama_hfov_deg,
    default_panorama_views,
};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadMapillary`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadMapillaryParams {
    /// The download folder: `<id>.json` beside `<id>.jpg`, or `metadata.jsonl` with
    /// `<date>/<sequence>/<id>.jpg` (see [`crate::io::street_imagery::mapillary`]). The whole folder is the
    /// node's input.
    pub path: String,
    /// Camera height above the terrain, metres. Default 2.5.
    #[serde(default = "default_camera_height_m")]
    pub camera_height_m: f64,
    /// Take z from `computed_altitude` (else `altitude`) as given (ellipsoidal, often metres off)
    /// instead of the `terrain` input plus `camera_height_m`. Default false.
    #[serde(default)]
    pub trust_altitude: bool,
    /// Pinhole views cut from each spherical panorama, evenly in heading. Default 4.
    #[serde(default = "default_panorama_views")]
    pub panorama_views: u32,
    /// Field of view of each panorama view, degrees. Default 90.
    #[serde(default = "default_panorama_hfov_deg")]
    pub panorama_hfov_deg: f64,
    /// Side of each (square) panorama view, pixels. Default: the panorama's resolution.
    #[serde(default)]
    pub panorama_size_px: Option<u32>,
    /// Drop images whose `computed_rotation` heading disagrees with `computed_compass_angle` by
    /// more than this, degrees (a failed reconstruction). Default 10.
    #[serde(default = "ten")]
    pub max_yaw_disagreement_deg: f64,
}

fn ten() -> f64 {
    10.0
}

/// Reads a Mapillary download into views in the site frame (no model outputs yet).
pub struct ReadMapillary;

impl Stage for ReadMapillary {
    const KIND: &'static str = "ReadMapillary";
    // 2: the views' pixels are parts (one per view), the set holds their heads.
    const VERSION: u32 = 2;
    const DOC: &'static str = "Mapillary API v4 download (entities + JPEGs) into street views in the site frame, panoramas cut into pinhole views, Sec. 4.2";
    const INPUTS: &'static [InputSpec] = &[InputSpec::optional(
        "terrain",
        ArtifactType::Raster,
        "terrain heights: camera z = terrain + camera_height_m (needed unless trust_altitude)",
    )];
    type Params = ReadMapillaryParams;
    type Output = ViewSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        check_options(p.camera_height_m, &cut(p))?;
        if !(0.0..=180.0).contains(&p.max_yaw_disagreement_deg) {
            return Err(ParamError::new(
                "max_yaw_disagreement_deg",
                "expected 0 to 180 degrees",
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
        let terrain = inputs.optional::<Raster>("terrain")?;
        let opts = ReadOptions::new(
            terrain,
            p.trust_altitude,
            p.camera_height_m,
            cut(p),
            p.max_yaw_disagreement_deg,
        )?
        .storing_in(ctx.parts);
        let folder = ctx.file(0)?;
        read_mapillary(folder, ctx.site, &opts)?.finish(folder, &opts, ctx.progress, ctx.parts)
    }
}

fn cut(p: &ReadMapillaryParams) -> PanoramaCut {
    PanoramaCut {
        views: p.panorama_views,
        hfov_deg: p.panorama_hfov_deg,
        size_px: p.panorama_size_px,
    }
}
