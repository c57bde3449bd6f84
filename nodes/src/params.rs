//! Checks and conventions shared by stages' parameters.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::io::crs::Crs;
use crate::stage::ParamError;

/// An optional cell size must be positive (rejects NaN too).
pub fn check_cell(cell_m: Option<f64>) -> Result<(), ParamError> {
    match cell_m {
        Some(c) if !(c > 0.0) => Err(ParamError::new(
            "cell_m",
            "expected a positive cell size in metres",
        )),
        _ => Ok(()),
    }
}

/// An optional CRS must be one we can build (`EPSG:<code>` or a `+proj` string).
pub fn check_crs(crs: &Option<String>) -> Result<(), ParamError> {
    if let Some(c) = crs {
        Crs::from_user(c).map_err(|m| ParamError::new("crs", m))?;
    }
    Ok(())
}

/// The folder holding `path` (`.` for a bare file name): what a node whose data is a folder of
/// files (a tileset, a view set) declares as its input.
pub fn folder_of(path: &str) -> String {
    Path::new(path)
        .parent()
        .map(|f| f.to_string_lossy().into_owned())
        .filter(|f| !f.is_empty())
        .unwrap_or_else(|| ".".into())
}

/// The params of a stage that takes none.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoParams {}
