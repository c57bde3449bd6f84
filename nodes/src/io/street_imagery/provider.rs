//! What the street-imagery providers share: the options of their readers (camera heights,
//! panorama cutting, the yaw check) and the params checks of their stages, what a reader returns
//! (views, drops, skipped files) and the warnings it gives, WGS 84 positions into the site frame
//! with the local ENU axes there, camera heights, and the parallel, ordered reading of a folder's
//! records.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use glam::DMat3;
use rayon::prelude::*;
use serde_json::Value;

use super::record::{Record, record_id};
use super::rotation::enu_to_grid;
use crate::artifact::{PartStore, Raster, View, ViewHead, ViewSet};
use crate::io::crs::{Crs, ToSite};
use crate::site::Site;
use crate::stage::{ParamError, Progress, StageError};

/// The most views one panorama is cut into.
pub const MAX_PANORAMA_VIEWS: u32 = 16;
/// The largest side of a view cut from a panorama, pixels.
pub const MAX_VIEW_SIDE: u32 = 4096;

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
#[derive(Clone, Copy)]
pub struct ReadOptions<'a> {
    /// Camera heights.
    pub heights: Heights<'a>,
    /// Panorama cutting.
    pub panorama: PanoramaCut,
    /// Views whose rotation and compass heading disagree by more are dropped, degrees.
    pub max_yaw_disagreement_deg: f64,
    /// Where each view's pixels go as soon as it is read (the stages give their `Ctx`'s store,
    /// so a folder of any size is read a few images at a time); `None` keeps them in the
    /// [`ProviderView`]s.
    pub store: Option<&'a dyn PartStore>,
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
            store: None,
        })
    }

    /// The same options, each view stored in `parts` as it is read.
    pub fn storing_in(self, parts: &'a dyn PartStore) -> Self {
        ReadOptions {
            store: Some(parts),
            ..self
        }
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
    /// The view as stored, when the options gave a store: `view` is then a placeholder of no
    /// pixels (its id, intrinsics and pose), the head holding the rest.
    pub stored: Option<ViewHead>,
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
        parts: &dyn crate::stage::PartStore,
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
        // With a store in the options every view was stored as it was read.
        if self.views.iter().all(|v| v.stored.is_some()) {
            return Ok(ViewSet {
                views: self.views.into_iter().filter_map(|v| v.stored).collect(),
                material_classes: Vec::new(),
            });
        }
        crate::io::views_io::store_all_checked(
            folder,
            self.views.into_iter().map(|v| v.view).collect(),
            Vec::new(),
            parts,
        )
    }
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
    pub fn enu_to_site(&self, lon: f64, lat: f64) -> Result<([f64; 2], DMat3), String> {
        const D: f64 = 1e-4;
        let (x, y, _) = self.wgs84.apply(lon, lat, 0.0)?;
        let (xn, yn, _) = self.wgs84.apply(lon, lat + D, 0.0)?;
        let (xs, ys, _) = self.wgs84.apply(lon, lat - D, 0.0)?;
        let gamma = (xn - xs).atan2(yn - ys);
        Ok(([x, y], enu_to_grid(gamma)))
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

/// `v` with its view stored in `parts` (checked by [`View::check`]; a view that fails it is an
/// error on the record's file, at the record): the head kept, the pixels dropped.
fn store_view(
    mut v: ProviderView,
    rec: &Record,
    parts: &dyn PartStore,
) -> Result<ProviderView, StageError> {
    let (id, k, pose) = (v.view.id.clone(), v.view.intrinsics, v.view.pose);
    let view = std::mem::replace(&mut v.view, View::new(&id, 0, 0, k, pose));
    let head = view.store(0, parts)?.map_err(|(what, m)| {
        StageError::bad_input(
            rec.file,
            format!("{} (view {id:?}), {what}", rec.at),
            format!("expected {m}"),
        )
    })?;
    v.stored = Some(head);
    Ok(v)
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
    store: Option<&dyn PartStore>,
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
        .map(|(id, rec)| {
            let views = read(id, rec, &geo)?;
            match (views, store) {
                (Ok(views), Some(parts)) => views
                    .into_iter()
                    .map(|v| store_view(v, rec, parts))
                    .collect::<Result<Vec<_>, _>>()
                    .map(Ok),
                (views, _) => Ok(views),
            }
        })
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
