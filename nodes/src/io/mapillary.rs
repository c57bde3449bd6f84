//! Street-level views as Mapillary (API v4) downloads hold them, read into the site frame, and the
//! writer of that layout; with the mechanics every street-view provider shares (ENU to site frame,
//! camera heights, panorama cutting, folder scans, field errors), which [`crate::io::panoramax`]
//! uses too.
//!
//! # Layouts
//! A download folder holds image entities, in any mix of:
//! - `<id>.json`, one API v4 image entity per file, beside `<id>.jpg`;
//! - `metadata.jsonl` (any `*.jsonl`), one entity per line, as mapillary-downloader writes, the
//!   images at `<date>/<sequence>/<id>.jpg`;
//! - a saved API response `{"data": [entity, ...]}` (or a bare array of entities).
//!
//! Other JSON objects (mapillary-downloader's `progress.json`) and the downloader's closing
//! `{"__complete__": true}` line are skipped. An image is `<id>.jpg` (`.jpeg`, `.png`) beside its
//! JSON, else anywhere under the folder (one in a folder named after the entity's `sequence`
//! first). Files are read in sorted path order; an id seen twice keeps its first entity.
//!
//! # Fields
//! `id`; `computed_geometry` (GeoJSON Point [lon, lat]), else `geometry` (raw GPS);
//! `computed_rotation` (angle-axis, ENU to camera, OpenSfM axes x right, y down, z forward), else
//! `computed_compass_angle`, else `compass_angle` (degrees clockwise from true north, level camera);
//! `computed_altitude`, else `altitude` (only with `trust_altitude`); `camera_type` (`perspective`,
//! the default, `fisheye`, `spherical` or `equirectangular`); `camera_parameters` ([focal, k1, k2],
//! focal relative to max(width, height); needed unless spherical); `exif_orientation` (1, 3, 6, 8);
//! `width`, `height` (of the image as stored, before EXIF orientation); `captured_at` (ms since
//! 1970). `sequence` helps find images; `quality_score` is not used.
//!
//! # Pose
//! R = Rodrigues(`computed_rotation`) maps ENU vectors to camera vectors, so camera to ENU is Rᵀ.
//! ENU north is true north, not grid north: the rotation A from ENU to the site frame turns about z
//! by the meridian convergence γ, the grid bearing of true north, measured by projecting the points
//! 1e-4 degrees north and south of the camera through the site CRS (so any projection the site uses
//! is handled). Camera to site is then A · Rᵀ · M, M the EXIF orientation (below); a compass-only
//! pose is A · (heading, pitch 0, roll 0) in the upright image. The position is the site-frame
//! (x, y) of the point; z is the terrain under it plus `camera_height_m`, or with `trust_altitude`
//! the provider's altitude as given (GPS altitudes are ellipsoidal or worse: no geoid is applied).
//!
//! # Cameras
//! Perspective: the image as stored, fx = fy = focal · max(w, h), principal point at the centre;
//! k1, k2 (OpenSfM's radial terms on normalised coordinates) are kept beside the view
//! ([`ProviderView::distortion`]), not applied. Fisheye (OpenSfM's: r = f θ (1 + k1 θ² + k2 θ⁴))
//! is resampled to a pinhole image of the same size and focal length. Spherical (equirectangular;
//! the centre column looks along camera z, columns grow towards x, scale max(w, h) / 2π pixels per
//! radian) is cut into level pinhole views, `<id>-<k>`, evenly in heading from the panorama's.
//!
//! EXIF orientation: the entity's width, height and rotation describe the image as stored; the
//! view is the upright image (3: turned 180°, 6: turned 90° clockwise, 8: 90° anticlockwise, with
//! the camera axes turned alike). A file that is already upright (width and height swapped, for
//! 6 and 8) is recognised by its size. Orientation is ignored for spherical images.
//!
//! A `computed_rotation` whose optical axis points more than `max_yaw_disagreement_deg` away in
//! heading from `computed_compass_angle` marks a failed reconstruction: the view is dropped.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use image::RgbImage;
use rayon::prelude::*;
use serde_json::{Value, json};

use crate::artifact::{Intrinsics, PodVec, Pose, Raster, View, ViewSet};
use crate::io::crs::{Crs, ToSite};
use crate::site::Site;
use crate::stage::{ParamError, Progress, StageError};

/// A 3 x 3 matrix, rows.
pub type Mat3 = [[f64; 3]; 3];

/// The largest image side read, pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;
/// The most views one panorama is cut into.
pub const MAX_PANORAMA_VIEWS: u32 = 16;
/// The largest side of a view cut from a panorama, pixels.
pub const MAX_VIEW_SIDE: u32 = 4096;
/// How deep folders are searched for entities and images.
const MAX_DEPTH: usize = 8;

// ------------------------------------------------------------------------------------------------
// Options shared by the provider readers.

/// Where camera heights come from.
#[derive(Clone, Copy, Debug)]
pub enum Heights<'a> {
    /// Terrain under the camera (bilinear) plus a fixed camera height, metres.
    Terrain {
        /// The terrain heights, site frame.
        terrain: &'a Raster,
        /// Camera height above it.
        camera_height_m: f64,
    },
    /// The provider's altitude, as given.
    Provider,
}

impl<'a> Heights<'a> {
    /// The heights a stage's `terrain` input and `trust_altitude` param ask for; neither is an
    /// error saying which to give.
    pub fn choose(
        terrain: Option<&'a Raster>,
        trust_altitude: bool,
        camera_height_m: f64,
    ) -> Result<Self, StageError> {
        match (trust_altitude, terrain) {
            (true, _) => Ok(Heights::Provider),
            (false, Some(terrain)) => Ok(Heights::Terrain {
                terrain,
                camera_height_m,
            }),
            (false, None) => Err(StageError::Param(ParamError::new(
                "trust_altitude",
                "camera heights need a `terrain` input (z = terrain + camera_height_m) or \
                 trust_altitude: true (z = the provider's altitude, ellipsoidal)",
            ))),
        }
    }
}

/// How spherical panoramas are cut into pinhole views.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PanoramaCut {
    /// Views per panorama, evenly in heading.
    pub views: u32,
    /// Horizontal (and vertical) field of view of each, degrees.
    pub hfov_deg: f64,
    /// Side of each (square) view, pixels; default: the panorama's resolution at the view centre.
    pub size_px: Option<u32>,
}

/// What a provider reader needs besides the folder and the site.
#[derive(Clone, Copy, Debug)]
pub struct ReadOptions<'a> {
    /// Camera heights.
    pub heights: Heights<'a>,
    /// Panorama cutting.
    pub panorama: PanoramaCut,
    /// Views whose rotation and compass heading disagree by more are dropped, degrees.
    pub max_yaw_disagreement_deg: f64,
}

impl<'a> ReadOptions<'a> {
    /// The options of a provider stage: heights from its `terrain` input or, with
    /// `trust_altitude`, the provider's altitude (neither is an error saying which to give).
    pub fn new(
        terrain: Option<&'a Raster>,
        trust_altitude: bool,
        camera_height_m: f64,
        panorama: PanoramaCut,
        max_yaw_disagreement_deg: f64,
    ) -> Result<Self, StageError> {
        Ok(ReadOptions {
            heights: Heights::choose(terrain, trust_altitude, camera_height_m)?,
            panorama,
            max_yaw_disagreement_deg,
        })
    }
}

/// Default `camera_height_m` of the provider stages: 2.5 m.
pub fn default_camera_height_m() -> f64 {
    2.5
}
/// Default `panorama_views`: 4.
pub fn default_panorama_views() -> u32 {
    4
}
/// Default `panorama_hfov_deg`: 90.
pub fn default_panorama_hfov_deg() -> f64 {
    90.0
}

/// Checks the params every provider stage shares.
pub fn check_options(camera_height_m: f64, cut: &PanoramaCut) -> Result<(), ParamError> {
    if !(camera_height_m.is_finite() && camera_height_m.abs() <= 100.0) {
        return Err(ParamError::new(
            "camera_height_m",
            "expected a height in metres within ±100",
        ));
    }
    if !(1..=MAX_PANORAMA_VIEWS).contains(&cut.views) {
        return Err(ParamError::new(
            "panorama_views",
            format!("expected 1 to {MAX_PANORAMA_VIEWS} views per panorama"),
        ));
    }
    if !(cut.hfov_deg > 1.0 && cut.hfov_deg < 170.0) {
        return Err(ParamError::new(
            "panorama_hfov_deg",
            "expected a field of view in (1, 170) degrees",
        ));
    }
    if let Some(s) = cut.size_px
        && !(16..=MAX_VIEW_SIDE).contains(&s)
    {
        return Err(ParamError::new(
            "panorama_size_px",
            format!("expected 16 to {MAX_VIEW_SIDE} pixels"),
        ));
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------------
// What the readers return.

/// A view read from a provider, with what [`View`] has no field for.
#[derive(Clone, Debug, PartialEq)]
pub struct ProviderView {
    /// The view, in the site frame.
    pub view: View,
    /// Where the pose came from: `"<orientation>, <position>, <height>"`, e.g.
    /// `"computed_rotation, computed_geometry, terrain + 2.5 m"`.
    pub pose_source: String,
    /// Radial distortion [k1, k2] of the image (OpenSfM's perspective model on normalised
    /// coordinates), not applied to it; `None` where the image is distortion-free.
    pub distortion: Option<[f64; 2]>,
}

/// Why an entity gave no view.
#[derive(Clone, Debug, PartialEq)]
pub enum DropReason {
    /// The rotation's heading and the compass heading disagree by this much, degrees.
    YawDisagreement(f64),
    /// The camera is outside the terrain raster, or over its no-data.
    NoTerrain,
    /// An earlier entity has the same id.
    Duplicate,
}

/// An entity that gave no view.
#[derive(Clone, Debug, PartialEq)]
pub struct Dropped {
    /// The entity's id.
    pub id: String,
    /// Why.
    pub reason: DropReason,
}

/// The views a provider folder gave, and what it dropped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProviderViews {
    /// In file order (a panorama's views in heading order).
    pub views: Vec<ProviderView>,
    /// In file order.
    pub dropped: Vec<Dropped>,
    /// JSON files that hold no records (a downloader's `progress.json`, a STAC Collection).
    pub skipped: Vec<PathBuf>,
}

impl ProviderViews {
    /// One line per kind of drop, with the count and the first ids, for `Progress::warn`.
    pub fn warnings(&self, max_yaw_disagreement_deg: f64) -> Vec<String> {
        let kind = |r: &DropReason| match r {
            DropReason::YawDisagreement(_) => 0,
            DropReason::NoTerrain => 1,
            DropReason::Duplicate => 2,
        };
        let why = [
            format!(
                "their computed_rotation's heading disagrees with computed_compass_angle by more \
                 than {max_yaw_disagreement_deg} degrees"
            ),
            "they lie outside the terrain raster or over its no-data".to_owned(),
            "an earlier entity has the same id".to_owned(),
        ];
        let mut out = Vec::new();
        for (k, why) in why.iter().enumerate() {
            let ids: Vec<&str> = self
                .dropped
                .iter()
                .filter(|d| kind(&d.reason) == k)
                .map(|d| d.id.as_str())
                .collect();
            if ids.is_empty() {
                continue;
            }
            let first: Vec<&str> = ids.iter().take(5).copied().collect();
            let more = if ids.len() > 5 { ", ..." } else { "" };
            out.push(format!(
                "{} image(s) dropped because {} ({}{more})",
                ids.len(),
                why,
                first.join(", ")
            ));
        }
        if !self.skipped.is_empty() {
            let names: Vec<String> = self
                .skipped
                .iter()
                .take(5)
                .map(|p| p.display().to_string())
                .collect();
            let more = if self.skipped.len() > 5 { ", ..." } else { "" };
            out.push(format!(
                "{} JSON file(s) skipped: they hold no image records ({}{more})",
                self.skipped.len(),
                names.join(", ")
            ));
        }
        out
    }

    /// The view set (no model outputs, no material classes), after warning of what was dropped;
    /// an error naming `folder` when nothing is left.
    pub fn finish(
        self,
        folder: &Path,
        opts: &ReadOptions,
        progress: &dyn Progress,
    ) -> Result<ViewSet, StageError> {
        let warnings = self.warnings(opts.max_yaw_disagreement_deg);
        if self.views.is_empty() {
            return Err(StageError::bad_input(
                folder,
                "views",
                format!("at least one usable image; {}", warnings.join("; ")),
            ));
        }
        for w in &warnings {
            progress.warn(w);
        }
        Ok(ViewSet {
            views: self.views.into_iter().map(|v| v.view).collect(),
            material_classes: Vec::new(),
        })
    }
}

// ------------------------------------------------------------------------------------------------
// Frames.

/// `a · b`.
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

/// `aᵀ`.
pub fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| a[c][r]))
}

/// The rotation matrix of an angle-axis vector (Rodrigues).
pub fn rodrigues(v: [f64; 3]) -> Mat3 {
    let m = glam::DMat3::from_quat(glam::DQuat::from_scaled_axis(glam::DVec3::from_array(v)));
    transpose(&m.to_cols_array_2d())
}

/// The angle-axis vector of a rotation matrix.
pub fn angle_axis(m: &Mat3) -> [f64; 3] {
    let g = glam::DMat3::from_cols_array_2d(&transpose(m));
    glam::DQuat::from_mat3(&g).to_scaled_axis().to_array()
}

/// Heading (degrees clockwise from the frame's y axis, in [0, 360)) of a camera's optical axis,
/// `None` when it points straight up or down.
pub fn heading_deg(camera_to_frame: &Mat3) -> Option<f64> {
    let (x, y) = (camera_to_frame[0][2], camera_to_frame[1][2]);
    (x.hypot(y) > 1e-9).then(|| x.atan2(y).to_degrees().rem_euclid(360.0))
}

/// WGS 84 longitude/latitude into the site frame, with the local ENU axes there.
pub struct Geo {
    wgs84: ToSite,
}

impl Geo {
    /// The transform for `site`.
    pub fn new(site: &Site) -> Result<Geo, StageError> {
        let wgs84 = Crs::from_epsg(4326).map_err(StageError::Failed)?;
        Ok(Geo {
            wgs84: ToSite::new(&wgs84, site).map_err(StageError::Failed)?,
        })
    }

    /// Site-frame (x, y) of (lon, lat), degrees, and the rotation taking ENU vectors there: a turn
    /// about z by the meridian convergence (the grid bearing of true north).
    pub fn enu_to_site(&self, lon: f64, lat: f64) -> Result<([f64; 2], Mat3), String> {
        const D: f64 = 1e-4;
        let (x, y, _) = self.wgs84.apply(lon, lat, 0.0)?;
        let (xn, yn, _) = self.wgs84.apply(lon, lat + D, 0.0)?;
        let (xs, ys, _) = self.wgs84.apply(lon, lat - D, 0.0)?;
        let gamma = (xn - xs).atan2(yn - ys);
        let (s, c) = gamma.sin_cos();
        Ok(([x, y], [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]))
    }

    /// Longitude and latitude, degrees, of a site-frame point.
    pub fn lon_lat(&self, x: f64, y: f64) -> Result<(f64, f64), String> {
        self.wgs84.inverse(x, y)
    }
}

/// The camera's z: terrain + height, or the provider's altitude. `Ok(None)`: no terrain there.
/// `altitude` is the provider's value with the field it came from.
pub fn camera_z(
    heights: &Heights,
    xy: [f64; 2],
    altitude: Option<(f64, &str)>,
    rec: &Record,
    altitude_fields: &str,
) -> Result<Option<(f64, String)>, StageError> {
    match heights {
        Heights::Terrain {
            terrain,
            camera_height_m,
        } => {
            let inside = terrain.grid.cell_of(xy[0], xy[1]).is_some();
            Ok(inside
                .then(|| terrain.bilinear(xy[0], xy[1]))
                .flatten()
                .map(|t| {
                    (
                        t + camera_height_m,
                        format!("terrain + {camera_height_m} m"),
                    )
                }))
        }
        Heights::Provider => match altitude {
            Some((z, field)) => Ok(Some((z, format!("{field} (ellipsoidal)")))),
            None => Err(rec.bad(
                altitude_fields,
                "an altitude, since trust_altitude is set (or give a `terrain` input instead)",
            )),
        },
    }
}

// ------------------------------------------------------------------------------------------------
// Records and files.

/// A GeoJSON Point: [lon, lat] (degrees) and the height when given.
pub type LonLatAlt = ([f64; 2], Option<f64>);

/// One record of a provider file (an entity, a STAC item): reads its fields with errors that name
/// the file, the record and the field.
pub struct Record<'a> {
    /// The file.
    pub file: &'a Path,
    /// The record in it, e.g. `image 1234` or `line 7 (image 1234)`.
    pub at: String,
    /// Its JSON.
    pub v: &'a Value,
}

impl Record<'_> {
    /// A `BadInput` on `field`.
    pub fn bad(&self, field: &str, expected: impl Into<String>) -> StageError {
        StageError::bad_input(
            self.file,
            format!("{}, `{field}`", self.at),
            format!("expected {}", expected.into()),
        )
    }

    /// The value at a dotted path (`properties.view:azimuth`); null counts as absent.
    pub fn get(&self, path: &str) -> Option<&Value> {
        path.split('.')
            .try_fold(self.v, |v, k| v.get(k))
            .filter(|v| !v.is_null())
    }

    /// A finite number, if present.
    pub fn num(&self, path: &str) -> Result<Option<f64>, StageError> {
        self.get(path)
            .map(|v| finite(v).ok_or_else(|| self.bad(path, format!("a finite number, found {v}"))))
            .transpose()
    }

    /// A string, if present.
    pub fn str(&self, path: &str) -> Result<Option<&str>, StageError> {
        self.get(path)
            .map(|v| {
                v.as_str()
                    .ok_or_else(|| self.bad(path, format!("a string, found {v}")))
            })
            .transpose()
    }

    /// `n` finite numbers, if present.
    pub fn nums(
        &self,
        path: &str,
        n: std::ops::RangeInclusive<usize>,
    ) -> Result<Option<Vec<f64>>, StageError> {
        let Some(v) = self.get(path) else {
            return Ok(None);
        };
        let want = || {
            format!(
                "an array of {} to {} finite numbers, found {v}",
                n.start(),
                n.end()
            )
        };
        let a = v
            .as_array()
            .filter(|a| n.contains(&a.len()))
            .ok_or_else(|| self.bad(path, want()))?;
        a.iter()
            .map(|x| finite(x).ok_or_else(|| self.bad(path, want())))
            .collect::<Result<Vec<f64>, _>>()
            .map(Some)
    }

    /// A GeoJSON Point's [lon, lat] (degrees) and altitude, if present.
    pub fn point(&self, path: &str) -> Result<Option<LonLatAlt>, StageError> {
        let Some(g) = self.get(path) else {
            return Ok(None);
        };
        let expected = "a GeoJSON Point {\"type\": \"Point\", \"coordinates\": [lon, lat]}";
        if g.get("type").and_then(Value::as_str) != Some("Point") {
            return Err(self.bad(path, expected));
        }
        let c = self
            .nums(&format!("{path}.coordinates"), 2..=3)?
            .ok_or_else(|| self.bad(path, expected))?;
        if !(c[0].abs() <= 180.0 && c[1].abs() < 89.9) {
            return Err(self.bad(
                path,
                format!(
                    "a longitude within ±180 and a latitude within ±89.9 degrees, found [{}, {}]",
                    c[0], c[1]
                ),
            ));
        }
        Ok(Some(([c[0], c[1]], c.get(2).copied())))
    }

    /// A pixel count in 1..=100000, required.
    pub fn pixels(&self, path: &str) -> Result<u32, StageError> {
        let n = self.num(path)?;
        match n {
            Some(n) if (1.0..=100_000.0).contains(&n) && n.fract() == 0.0 => Ok(n as u32),
            _ => Err(self.bad(path, "a whole number of pixels, 1 to 100000")),
        }
    }
}

fn finite(v: &Value) -> Option<f64> {
    v.as_f64().filter(|x| x.is_finite())
}

/// A record id made safe for file names: ASCII letters, digits, `-`, `_`, `.`, not leading `.`.
pub fn record_id(rec: &Record, path: &str) -> Result<String, StageError> {
    let id = match rec.get(path) {
        Some(Value::String(s)) => s.clone(),
        Some(Value::Number(n)) if n.is_u64() => n.to_string(),
        _ => return Err(rec.bad(path, "an id (a string or a whole number)")),
    };
    let ok = !id.is_empty()
        && id.len() <= 128
        && !id.starts_with('.')
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    if ok {
        Ok(id)
    } else {
        Err(rec.bad(
            path,
            format!("an id of letters, digits, '-', '_' and '.', found {id:?}"),
        ))
    }
}

/// Parses JSON; the bare tokens `NaN`, `Infinity` and `-Infinity` that some writers emit are read
/// as strings, so that the field holding one is named by the reader of that field.
pub fn parse_json(file: &Path, text: &str, place: &str) -> Result<Value, StageError> {
    let mut quoted = String::with_capacity(text.len());
    let (mut in_str, mut escaped) = (false, false);
    let mut rest = text;
    while let Some(c) = rest.chars().next() {
        if !in_str {
            if let Some(tok) = ["NaN", "Infinity", "-Infinity"]
                .into_iter()
                .find(|t| rest.starts_with(t))
            {
                quoted.push('"');
                quoted.push_str(tok);
                quoted.push('"');
                rest = &rest[tok.len()..];
                continue;
            }
            in_str = c == '"';
        } else if escaped {
            escaped = false;
        } else if c == '\\' {
            escaped = true;
        } else if c == '"' {
            in_str = false;
        }
        quoted.push(c);
        rest = &rest[c.len_utf8()..];
    }
    serde_json::from_str(&quoted).map_err(|e| {
        StageError::bad_input(
            file,
            format!("{place}line {}, column {}", e.line(), e.column()),
            format!("expected JSON: {e}"),
        )
    })
}

/// Every file under `dir`, to a depth of 8, in sorted path order; links to folders are not
/// followed.
pub fn files_under(dir: &Path) -> Result<Vec<PathBuf>, StageError> {
    fn walk(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> Result<(), StageError> {
        let entries = std::fs::read_dir(dir).map_err(|e| {
            StageError::bad_input(dir, "folder", format!("expected a readable folder: {e}"))
        })?;
        for entry in entries.flatten() {
            let p = entry.path();
            match entry.file_type() {
                Ok(t) if t.is_dir() && depth < MAX_DEPTH => walk(&p, depth + 1, out)?,
                Ok(t) if t.is_file() || (t.is_symlink() && p.is_file()) => out.push(p),
                _ => {}
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, 0, &mut out)?;
    out.sort();
    Ok(out)
}

/// The texts of the files under `folder` whose extension is one of `exts`, in path order, and
/// the images there.
pub fn scan_folder(
    folder: &Path,
    exts: &[&str],
) -> Result<(Vec<(PathBuf, String)>, ImageIndex), StageError> {
    let files = files_under(folder)?;
    let texts = files
        .iter()
        .filter(|f| exts.contains(&extension(f).as_str()))
        .map(|f| {
            std::fs::read_to_string(f)
                .map(|t| (f.clone(), t))
                .map_err(|e| StageError::bad_input(f, "open", e.to_string()))
        })
        .collect::<Result<_, _>>()?;
    Ok((texts, ImageIndex::new(&files)))
}

/// The lower-case extension of a path.
pub fn extension(p: &Path) -> String {
    p.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// The images (jpg, jpeg, png) under a folder, by file stem.
pub struct ImageIndex(BTreeMap<String, Vec<PathBuf>>);

impl ImageIndex {
    /// The images among `files` (sorted, so each stem's paths are too).
    pub fn new(files: &[PathBuf]) -> ImageIndex {
        let mut m: BTreeMap<String, Vec<PathBuf>> = BTreeMap::new();
        for f in files {
            if ["jpg", "jpeg", "png"].contains(&extension(f).as_str())
                && let Some(stem) = f.file_stem()
            {
                m.entry(stem.to_string_lossy().into_owned())
                    .or_default()
                    .push(f.clone());
            }
        }
        ImageIndex(m)
    }

    /// The image of `id`: in `near` if there is one there, else in a folder named `folder_name`,
    /// else the first in path order.
    pub fn find(&self, id: &str, near: Option<&Path>, folder_name: Option<&str>) -> Option<&Path> {
        let list = self.0.get(id)?;
        let in_dir = |d: &Path| list.iter().find(|p| p.parent() == Some(d));
        let named = |n: &str| {
            list.iter()
                .find(|p| p.parent().and_then(Path::file_name).is_some_and(|f| f == n))
        };
        near.and_then(in_dir)
            .or_else(|| folder_name.and_then(named))
            .or_else(|| list.first())
            .map(PathBuf::as_path)
    }
}

/// Decodes an image as RGB, refusing empty images and sides over [`MAX_IMAGE_SIDE`].
pub fn load_image(path: &Path) -> Result<RgbImage, StageError> {
    let bad = |e: String| {
        StageError::bad_input(path, "image", format!("expected a readable JPEG/PNG: {e}"))
    };
    let mut reader = image::ImageReader::open(path)
        .map_err(|e| bad(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| bad(e.to_string()))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(2 << 30);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| bad(e.to_string()))?.into_rgb8();
    if img.width() == 0 || img.height() == 0 {
        return Err(bad("the image is empty".into()));
    }
    Ok(img)
}

/// True when (w, h) and (w2, h2) have the same aspect to within a pixel.
pub fn same_aspect((w, h): (u32, u32), (w2, h2): (u32, u32)) -> bool {
    let (w, h, w2, h2) = (w as f64, h as f64, w2 as f64, h2 as f64);
    (w * h2 - h * w2).abs() <= w.max(h).max(w2.max(h2))
}

// ------------------------------------------------------------------------------------------------
// Images and views.

/// A view with an image and no model outputs.
pub fn plain_view(
    id: String,
    img: RgbImage,
    f: f64,
    pose: Pose,
    captured_at: Option<String>,
) -> View {
    let (width, height) = img.dimensions();
    View {
        id,
        width,
        height,
        intrinsics: Intrinsics {
            fx: f,
            fy: f,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
        },
        pose,
        captured_at,
        pose_source: None,
        distortion: None,
        image: PodVec(img.pixels().map(|p| p.0).collect()),
        arch: None,
        clutter: None,
        material: None,
        depth: None,
        normal: None,
    }
}

/// An image of `w` x `h` whose pixel centre (u + 0.5, v + 0.5) takes `src` at `map(u + 0.5,
/// v + 0.5)` (continuous pixel coordinates, bilinear); outside `src` is black, unless `wrap`
/// (columns wrap around, rows clamp).
fn resample(
    src: &RgbImage,
    (w, h): (u32, u32),
    wrap: bool,
    map: impl Fn(f64, f64) -> Option<[f64; 2]> + Sync,
) -> RgbImage {
    let (sw, sh) = (src.width() as i64, src.height() as i64);
    let px = |x: i64, y: i64| -> [f64; 3] {
        let x = if wrap {
            x.rem_euclid(sw)
        } else {
            x.clamp(0, sw - 1)
        };
        let y = y.clamp(0, sh - 1);
        src.get_pixel(x as u32, y as u32).0.map(f64::from)
    };
    let rows: Vec<Vec<u8>> = (0..h)
        .into_par_iter()
        .map(|v| {
            let mut row = Vec::with_capacity(w as usize * 3);
            for u in 0..w {
                let rgb = map(u as f64 + 0.5, v as f64 + 0.5)
                    .filter(|[x, y]| {
                        wrap || (*x >= 0.0 && *y >= 0.0 && *x <= sw as f64 && *y <= sh as f64)
                    })
                    .map(|[x, y]| {
                        let (fx, fy) = (x - 0.5, y - 0.5);
                        let (x0, y0) = (fx.floor() as i64, fy.floor() as i64);
                        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
                        let (a, b) = (px(x0, y0), px(x0 + 1, y0));
                        let (c, d) = (px(x0, y0 + 1), px(x0 + 1, y0 + 1));
                        std::array::from_fn::<f64, 3, _>(|k| {
                            (a[k] * (1.0 - tx) + b[k] * tx) * (1.0 - ty)
                                + (c[k] * (1.0 - tx) + d[k] * tx) * ty
                        })
                    })
                    .unwrap_or([0.0; 3]);
                row.extend(rgb.map(|c| (c + 0.5).floor().clamp(0.0, 255.0) as u8));
            }
            row
        })
        .collect();
    RgbImage::from_raw(w, h, rows.concat()).unwrap_or_default()
}

/// A fisheye image (OpenSfM's model, focal `f` pixels, [k1, k2]) as a pinhole image of the same
/// size and focal length.
fn undistort_fisheye(src: &RgbImage, f: f64, k: [f64; 2]) -> RgbImage {
    let (cx, cy) = (src.width() as f64 / 2.0, src.height() as f64 / 2.0);
    resample(src, src.dimensions(), false, |u, v| {
        let (x, y) = ((u - cx) / f, (v - cy) / f);
        let l = x.hypot(y);
        if l < 1e-12 {
            return Some([cx, cy]);
        }
        let t = l.atan();
        let td = t * (1.0 + k[0] * t * t + k[1] * t.powi(4));
        Some([cx + f * td * x / l, cy + f * td * y / l])
    })
}

/// Level pinhole views cut from an equirectangular panorama whose camera-to-site rotation is
/// `c2s`: `cut.views` of them, evenly in heading from the panorama's forward heading, ids
/// `<id>-<k>`.
pub fn cut_panorama(
    pano: &RgbImage,
    id: &str,
    position: [f64; 3],
    c2s: &Mat3,
    cut: &PanoramaCut,
    captured_at: &Option<String>,
) -> Vec<View> {
    let (w, h) = pano.dimensions();
    let scale = w.max(h) as f64 / std::f64::consts::TAU;
    let tan = (cut.hfov_deg.to_radians() / 2.0).tan();
    let side = cut.size_px.unwrap_or_else(|| {
        (2.0 * scale * tan)
            .round()
            .clamp(16.0, MAX_VIEW_SIDE as f64) as u32
    });
    let f = side as f64 / 2.0 / tan;
    let heading0 = heading_deg(c2s).unwrap_or(0.0);
    let s2c = transpose(c2s);
    (0..cut.views)
        .map(|k| {
            let heading = heading0 + k as f64 * 360.0 / cut.views as f64;
            let pose = Pose::from_angles(position, heading.rem_euclid(360.0), 0.0, 0.0);
            let c = side as f64 / 2.0;
            let img = resample(pano, (side, side), true, |u, v| {
                let site = pose.to_site([(u - c) / f, (v - c) / f, 1.0]);
                let [x, y, z] = mat_vec(&s2c, site);
                let lon = x.atan2(z);
                let lat = (-y).atan2(x.hypot(z));
                Some([w as f64 / 2.0 + lon * scale, h as f64 / 2.0 - lat * scale])
            });
            plain_view(format!("{id}-{k}"), img, f, pose, captured_at.clone())
        })
        .collect()
}

/// `m · v`.
pub fn mat_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

/// ISO 8601 (UTC, milliseconds) of a time in milliseconds since 1970.
pub fn iso_from_ms(ms: i64) -> String {
    let (days, ms_of_day) = (ms.div_euclid(86_400_000), ms.rem_euclid(86_400_000));
    let z = days + 719_468;
    let (era, doe) = (z.div_euclid(146_097), z.rem_euclid(146_097));
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    let s = ms_of_day / 1000;
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:03}Z",
        s / 3600,
        s / 60 % 60,
        s % 60,
        ms_of_day % 1000
    )
}

/// Milliseconds since 1970 of `YYYY-MM-DDTHH:MM:SS[.fff][Z]` (UTC), the inverse of
/// [`iso_from_ms`].
pub fn ms_from_iso(s: &str) -> Option<i64> {
    let s = s.strip_suffix('Z').unwrap_or(s);
    let (date, time) = s.split_once('T')?;
    let d: Vec<i64> = date
        .split('-')
        .map(|x| x.parse().ok())
        .collect::<Option<_>>()?;
    let (hms, frac) = time.split_once('.').unwrap_or((time, "0"));
    let t: Vec<i64> = hms
        .split(':')
        .map(|x| x.parse().ok())
        .collect::<Option<_>>()?;
    let ([y, m, day], [hh, mm, ss]) =
        (<[i64; 3]>::try_from(d).ok()?, <[i64; 3]>::try_from(t).ok()?);
    let ms: i64 = format!("{frac:0<3}").get(..3)?.parse().ok()?;
    let y = if m <= 2 { y - 1 } else { y };
    let (era, yoe) = (y.div_euclid(400), y.rem_euclid(400));
    let doy = (153 * ((m + 9) % 12) + 2) / 5 + day - 1;
    let days = era * 146_097 + yoe * 365 + yoe / 4 - yoe / 100 + doy - 719_468;
    Some(((days * 24 + hh) * 60 + mm) * 60_000 + ss * 1000 + ms)
}

// ------------------------------------------------------------------------------------------------
// Mapillary.

/// The camera models of `camera_type`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Camera {
    Perspective,
    Fisheye,
    Spherical,
}

/// The camera axes of the upright image in the stored image's camera frame (columns), for EXIF
/// orientations 1, 3, 6 and 8.
fn exif_axes(orientation: u8) -> Mat3 {
    match orientation {
        3 => [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]],
        6 => [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        8 => [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        _ => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// The stored image turned upright for an EXIF orientation.
fn upright(img: RgbImage, orientation: u8) -> RgbImage {
    match orientation {
        3 => image::imageops::rotate180(&img),
        6 => image::imageops::rotate90(&img),
        8 => image::imageops::rotate270(&img),
        _ => img,
    }
}

/// Reads a Mapillary download folder (see the module docs) into views in the site frame.
pub fn read_mapillary(
    folder: &Path,
    site: &Site,
    opts: &ReadOptions,
) -> Result<ProviderViews, StageError> {
    let (texts, images) = scan_folder(folder, &["json", "jsonl"])?;
    let (mut docs, mut skipped) = (Vec::new(), Vec::new());
    for (f, text) in &texts {
        if extension(f) == "jsonl" {
            for (n, line) in text
                .lines()
                .enumerate()
                .filter(|(_, l)| !l.trim().is_empty())
            {
                let at = format!("line {}", n + 1);
                let v = parse_json(f, line, &format!("{at}, "))?;
                // mapillary-downloader ends a finished metadata.jsonl with {"__complete__": true}.
                if v.get("__complete__").is_none() {
                    docs.push((f, at, v));
                }
            }
        } else {
            let v = parse_json(f, text, "")?;
            match v {
                Value::Array(a) => docs.extend(
                    a.into_iter()
                        .enumerate()
                        .map(|(i, e)| (f, format!("entry {i}"), e)),
                ),
                Value::Object(ref o) if o.get("data").is_some_and(Value::is_array) => {
                    let a = o
                        .get("data")
                        .and_then(Value::as_array)
                        .cloned()
                        .unwrap_or_default();
                    docs.extend(
                        a.into_iter()
                            .enumerate()
                            .map(|(i, e)| (f, format!("data[{i}]"), e)),
                    );
                }
                Value::Object(ref o) if o.contains_key("id") => docs.push((f, String::new(), v)),
                // Not an entity (mapillary-downloader's progress.json, say).
                _ => skipped.push(f.clone()),
            }
        }
    }
    read_records(
        (folder, site),
        (&docs, skipped),
        (
            "image",
            "Mapillary image entities: <id>.json files or a metadata.jsonl",
        ),
        |id, rec, geo| read_entity(id, rec, geo, &images, opts),
    )
}

/// What one record gave: its views, or why it gave none.
pub type RecordViews = Result<Vec<ProviderView>, DropReason>;

/// Reads records (file, place in it, JSON) of a provider folder in parallel, in order: each id
/// once (later duplicates are dropped); `skipped` are the files that held none. `kind` names the
/// records in errors (`image 123`, `line 4 (image 123)`), `what` says what an empty folder should
/// have held.
pub fn read_records(
    (folder, site): (&Path, &Site),
    (docs, skipped): (&[(&PathBuf, String, Value)], Vec<PathBuf>),
    (kind, what): (&str, &str),
    read: impl Fn(&str, &Record, &Geo) -> Result<RecordViews, StageError> + Sync,
) -> Result<ProviderViews, StageError> {
    if docs.is_empty() {
        return Err(StageError::bad_input(
            folder,
            "contents",
            format!("expected {what}"),
        ));
    }
    let geo = Geo::new(site)?;
    let mut seen = BTreeSet::new();
    let mut out = ProviderViews {
        skipped,
        ..ProviderViews::default()
    };
    let mut todo = Vec::new();
    for (file, at, v) in docs {
        let rec = Record {
            file,
            at: at.clone(),
            v,
        };
        let id = record_id(&rec, "id")?;
        let at = if at.is_empty() {
            format!("{kind} {id}")
        } else {
            format!("{at} ({kind} {id})")
        };
        if seen.insert(id.clone()) {
            todo.push((id, Record { file, at, v }));
        } else {
            out.dropped.push(Dropped {
                id,
                reason: DropReason::Duplicate,
            });
        }
    }
    let done: Vec<Result<RecordViews, StageError>> = todo
        .par_iter()
        .map(|(id, rec)| read(id, rec, &geo))
        .collect();
    for (r, (id, _)) in done.into_iter().zip(&todo) {
        match r? {
            Ok(views) => out.views.extend(views),
            Err(reason) => out.dropped.push(Dropped {
                id: id.clone(),
                reason,
            }),
        }
    }
    Ok(out)
}

/// One entity: its views, or why it gave none.
fn read_entity(
    id: &str,
    rec: &Record,
    geo: &Geo,
    images: &ImageIndex,
    opts: &ReadOptions,
) -> Result<RecordViews, StageError> {
    let camera = match rec.str("camera_type")?.unwrap_or("perspective") {
        "perspective" => Camera::Perspective,
        "fisheye" => Camera::Fisheye,
        "spherical" | "equirectangular" => Camera::Spherical,
        other => {
            return Err(rec.bad(
                "camera_type",
                format!("perspective, fisheye, spherical or equirectangular, found {other:?}"),
            ));
        }
    };
    let size = (rec.pixels("width")?, rec.pixels("height")?);
    let lens = lens(rec, camera)?;
    let orientation = match (rec.num("exif_orientation")?, camera) {
        (_, Camera::Spherical) | (None, _) => 1,
        (Some(o), _) if [1.0, 3.0, 6.0, 8.0].contains(&o) => o as u8,
        (Some(o), _) => {
            return Err(rec.bad(
                "exif_orientation",
                format!("1, 3, 6 or 8 (mirrored images are not supported), found {o}"),
            ));
        }
    };
    let (lon_lat, pos_field) = match (rec.point("computed_geometry")?, rec.point("geometry")?) {
        (Some(p), _) => (p.0, "computed_geometry"),
        (None, Some(p)) => (p.0, "geometry"),
        (None, None) => {
            return Err(rec.bad(
                "computed_geometry",
                "the image's position: a GeoJSON Point in computed_geometry or geometry",
            ));
        }
    };
    let (c2e, orient_field) = match camera_to_enu(rec, orientation, opts.max_yaw_disagreement_deg)?
    {
        Ok(r) => r,
        Err(drop) => return Ok(Err(drop)),
    };
    let (xy, enu_to_site) = geo
        .enu_to_site(lon_lat[0], lon_lat[1])
        .map_err(|m| rec.bad(pos_field, format!("a position the site CRS covers: {m}")))?;
    let altitude = altitude(rec)?;
    let Some((z, height_source)) = camera_z(&opts.heights, xy, altitude, rec, "computed_altitude")?
    else {
        return Ok(Err(DropReason::NoTerrain));
    };
    let pose = Pose {
        position: [xy[0], xy[1], z],
        rotation: mat_mul(&enu_to_site, &c2e),
    };
    let pose_source = format!("{orient_field}, {pos_field}, {height_source}");
    let captured_at = captured_at(rec)?;
    let path = images
        .find(id, rec.file.parent(), rec.str("sequence").ok().flatten())
        .ok_or_else(|| {
            rec.bad(
                "id",
                format!("the image {id}.jpg beside the JSON or anywhere under the folder"),
            )
        })?;
    let img = stored_image(rec, path, size, orientation)?;
    let (views, distortion) = match lens {
        None => {
            let cut = cut_panorama(
                &img,
                id,
                pose.position,
                &pose.rotation,
                &opts.panorama,
                &captured_at,
            );
            (cut, None)
        }
        Some((focal, k)) => {
            let f = focal * img.width().max(img.height()) as f64;
            let (img, distortion) = if camera == Camera::Fisheye {
                (undistort_fisheye(&img, f, k), None)
            } else {
                (img, (k != [0.0, 0.0]).then_some(k))
            };
            let view = plain_view(
                id.to_owned(),
                upright(img, orientation),
                f,
                pose,
                captured_at,
            );
            (vec![view], distortion)
        }
    };
    Ok(Ok(views
        .into_iter()
        .map(|mut view| {
            view.pose_source = Some(pose_source.clone());
            view.distortion = distortion;
            ProviderView {
                view,
                pose_source: pose_source.clone(),
                distortion,
            }
        })
        .collect()))
}

/// `camera_parameters` as (focal relative to max(width, height), [k1, k2]); `None` for spherical.
fn lens(rec: &Record, camera: Camera) -> Result<Option<(f64, [f64; 2])>, StageError> {
    if camera == Camera::Spherical {
        return Ok(None);
    }
    let p = rec.nums("camera_parameters", 1..=3)?.ok_or_else(|| {
        rec.bad(
            "camera_parameters",
            "[focal, k1, k2], focal relative to max(width, height)",
        )
    })?;
    if !(p[0] > 0.0 && p[0] < 100.0) {
        return Err(rec.bad(
            "camera_parameters",
            format!(
                "a focal in (0, 100) times max(width, height), found {}",
                p[0]
            ),
        ));
    }
    let k = |i: usize| p.get(i).copied().unwrap_or(0.0);
    Ok(Some((p[0], [k(1), k(2)])))
}

/// The upright camera's axes in ENU and the field they came from: `computed_rotation` (turned by
/// the EXIF orientation; dropped when its heading is off `computed_compass_angle` by more than
/// `max_yaw_deg`), else a level camera on the compass heading.
fn camera_to_enu(
    rec: &Record,
    orientation: u8,
    max_yaw_deg: f64,
) -> Result<Result<(Mat3, &'static str), DropReason>, StageError> {
    let compass = rec.num("computed_compass_angle")?;
    let level = |h: f64| Pose::from_angles([0.0; 3], h, 0.0, 0.0).rotation;
    match (
        rec.nums("computed_rotation", 3..=3)?,
        compass,
        rec.num("compass_angle")?,
    ) {
        (Some(r), ..) => {
            let stored = transpose(&rodrigues([r[0], r[1], r[2]]));
            if let (Some(c), Some(h)) = (compass, heading_deg(&stored)) {
                let off = (h - c + 180.0).rem_euclid(360.0) - 180.0;
                if off.abs() > max_yaw_deg {
                    return Ok(Err(DropReason::YawDisagreement(off)));
                }
            }
            Ok(Ok((
                mat_mul(&stored, &exif_axes(orientation)),
                "computed_rotation",
            )))
        }
        (None, Some(h), _) => Ok(Ok((level(h), "computed_compass_angle"))),
        (None, None, Some(h)) => Ok(Ok((level(h), "compass_angle"))),
        (None, None, None) => Err(rec.bad(
            "computed_rotation",
            "the image's orientation: computed_rotation, computed_compass_angle or compass_angle",
        )),
    }
}

/// `computed_altitude`, else `altitude` (raw altitudes sometimes come as unsigned 32-bit wraps of
/// negative values), with the field it came from.
fn altitude(rec: &Record) -> Result<Option<(f64, &'static str)>, StageError> {
    let a = match (rec.num("computed_altitude")?, rec.num("altitude")?) {
        (Some(a), _) => Some((a, "computed_altitude")),
        (None, Some(a)) if (2_147_483_648.0..4_294_967_296.0).contains(&a) => {
            Some((a - 4_294_967_296.0, "altitude"))
        }
        (None, Some(a)) => Some((a, "altitude")),
        (None, None) => None,
    };
    match a {
        Some((a, field)) if a.abs() > 100_000.0 => {
            Err(rec.bad(field, format!("an altitude within ±100 km, found {a}")))
        }
        _ => Ok(a),
    }
}

/// `captured_at` as ISO 8601: from milliseconds since 1970, or a string as given.
fn captured_at(rec: &Record) -> Result<Option<String>, StageError> {
    match rec.get("captured_at") {
        Some(Value::String(s)) => Ok(Some(s.clone())),
        Some(_) => match rec.num("captured_at")? {
            Some(ms) if ms.abs() < 1e14 => Ok(Some(iso_from_ms(ms.round() as i64))),
            _ => Err(rec.bad("captured_at", "milliseconds since 1970")),
        },
        None => Ok(None),
    }
}

/// The image at `path` as stored (before EXIF orientation), checked against the entity's
/// width : height; a file already turned upright (6, 8) is turned back.
fn stored_image(
    rec: &Record,
    path: &Path,
    size: (u32, u32),
    orientation: u8,
) -> Result<RgbImage, StageError> {
    let img = load_image(path)?;
    if same_aspect(img.dimensions(), size) {
        return Ok(img);
    }
    if [6, 8].contains(&orientation) && same_aspect(img.dimensions(), (size.1, size.0)) {
        // 8 undoes 6, 6 undoes 8.
        return Ok(upright(img, 14 - orientation));
    }
    Err(StageError::bad_input(
        path,
        "size",
        format!(
            "{} x {} pixels, the aspect of width x height = {} x {} in {}",
            img.width(),
            img.height(),
            size.0,
            size.1,
            rec.file.display()
        ),
    ))
}

/// A view set in the Mapillary layout: `<id>.json` (an API v4 image entity: perspective camera,
/// computed pose, `computed_altitude` = the site z) and `<id>.jpg` per view. Needs square pixels
/// and a centred principal point.
pub fn write_mapillary(set: &ViewSet, site: &Site) -> Result<Vec<(String, Vec<u8>)>, String> {
    let geo = Geo::new(site).map_err(|e| e.to_string())?;
    let mut files = Vec::new();
    for v in &set.views {
        let k = v.intrinsics;
        let centred = (k.cx - v.width as f64 / 2.0).abs() < 1e-6
            && (k.cy - v.height as f64 / 2.0).abs() < 1e-6;
        if (k.fx - k.fy).abs() > 1e-9 * k.fx || !centred {
            return Err(format!(
                "view {}: Mapillary needs fx = fy and a centred principal point",
                v.id
            ));
        }
        let [x, y, z] = v.pose.position;
        let (lon, lat) = geo.lon_lat(x, y)?;
        let (_, enu_to_site) = geo.enu_to_site(lon, lat)?;
        let c2e = mat_mul(&transpose(&enu_to_site), &v.pose.rotation);
        let compass = heading_deg(&c2e).unwrap_or(0.0);
        let point = json!({"type": "Point", "coordinates": [lon, lat]});
        let mut entity = json!({
            "id": v.id,
            "computed_geometry": point,
            "geometry": point,
            "computed_altitude": z,
            "altitude": z,
            "computed_rotation": angle_axis(&transpose(&c2e)),
            "computed_compass_angle": compass,
            "compass_angle": compass,
            "camera_type": "perspective",
            "camera_parameters": [k.fx / v.width.max(v.height) as f64, 0.0, 0.0],
            "exif_orientation": 1,
            "width": v.width,
            "height": v.height,
            "sequence": "kodama",
        });
        if let Some(ms) = v.captured_at.as_deref().and_then(ms_from_iso) {
            entity["captured_at"] = json!(ms);
        }
        files.push((
            format!("{}.json", v.id),
            serde_json::to_vec_pretty(&entity).map_err(|e| e.to_string())?,
        ));
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 92)
            .encode(
                bytemuck::cast_slice(&v.image),
                v.width,
                v.height,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| format!("view {}: JPEG encoding failed: {e}", v.id))?;
        files.push((format!("{}.jpg", v.id), jpeg));
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_times_round_trip() {
        assert_eq!(iso_from_ms(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(iso_from_ms(951_782_400_000), "2000-02-29T00:00:00.000Z");
        for ms in [0, 1_714_566_896_789, 951_782_400_000, -86_400_001] {
            assert_eq!(ms_from_iso(&iso_from_ms(ms)), Some(ms), "{ms}");
        }
    }

    #[test]
    fn rodrigues_and_angle_axis_invert() {
        let v = [0.3, -1.2, 2.0];
        let back = angle_axis(&rodrigues(v));
        assert!(
            v.iter().zip(back).all(|(a, b)| (a - b).abs() < 1e-12),
            "{back:?}"
        );
        // About z by 90 degrees: x -> y.
        let m = rodrigues([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        assert!((mat_vec(&m, [1.0, 0.0, 0.0])[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn nonfinite_tokens_become_strings() {
        let v = parse_json(
            Path::new("x"),
            r#"{"a": NaN, "b": "NaN \" Infinity", "c": [-Infinity, 1]}"#,
            "",
        )
        .unwrap();
        assert_eq!(v["a"], "NaN");
        assert_eq!(v["b"], "NaN \" Infinity");
        assert_eq!(v["c"][0], "-Infinity");
    }
}
