//! Street-level imagery from the providers, read into the site frame: Mapillary's API v4 image
//! entities ([`mapillary`], which also writes that layout) and Panoramax's STAC items
//! ([`panoramax`]). Neither provider uses the other; what both need stands beside them:
//!
//! - [`provider`]: the readers' options and results, WGS 84 into the site frame, camera heights,
//!   a folder's records read in parallel and in order;
//! - [`record`]: the JSON of one record, read field by field with errors that name the field;
//! - [`folder`]: the files and images under a download folder;
//! - [`camera`]: camera models and resampling (pinhole views, fisheye, panorama cutting, EXIF
//!   orientation);
//! - [`rotation`]: rotations in glam's f64 types (angle-axis, the meridian convergence, headings);
//! - [`dates`]: ISO 8601 capture times through chrono.

pub mod camera;
pub mod dates;
pub mod folder;
pub mod mapillary;
pub mod panoramax;
pub mod provider;
pub mod record;
pub mod rotation;
