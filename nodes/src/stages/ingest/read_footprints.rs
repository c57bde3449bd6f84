//! Ingest of building footprints from GeoJSON (e.g. the Dutch BGT, or footprints exported from
//! QGIS), for scoring reconstructed footprints and for the OSM-style baseline (paper Sec. 5).

use serde::{Deserialize, Serialize};

use crate::artifact::Footprints;
use crate::io::crs::Crs;
use crate::io::geojson::{PropertyNames, read_footprints};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadFootprints`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadFootprintsParams {
    /// The GeoJSON file.
    pub path: String,
    /// Its CRS, overriding the file's `crs` member (default: that member, else WGS84 per RFC 7946).
    #[serde(default)]
    pub crs: Option<String>,
    /// Property holding the building id (default: the feature id, else `id`, else the index).
    #[serde(default)]
    pub id_field: Option<String>,
    /// Property holding the height in metres (default: `height`, else `height_m`).
    #[serde(default)]
    pub height_field: Option<String>,
}

/// Reads Polygon/MultiPolygon features as building footprints in the site frame.
pub struct ReadFootprints;

impl Stage for ReadFootprints {
    const KIND: &'static str = "ReadFootprints";
    const VERSION: u32 = 1;
    const DOC: &'static str = "GeoJSON building footprints into the site frame";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadFootprintsParams;
    type Output = Footprints;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::crs::check_crs_param(&p.crs)?;
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }]
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Footprints, StageError> {
        let crs = p
            .crs
            .as_deref()
            .map(Crs::from_user)
            .transpose()
            .map_err(|m| StageError::Param(ParamError::new("crs", m)))?;
        let names = PropertyNames {
            id: p.id_field.clone(),
            height: p.height_field.clone(),
        };
        read_footprints(ctx.file(0)?, crs.as_ref(), &names, ctx.site)
    }
}
