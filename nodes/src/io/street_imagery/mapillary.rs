//! Street-level views as Mapillary (API v4) downloads hold them, read into the site frame, and the
//! writer of that layout: the API's image entities. The mechanics every street-view provider
//! shares (ENU to site frame, camera heights, panorama cutting, folder scans, field errors) are in
//! the modules beside this one ([`crate::io::street_imagery`]), which Panoramax uses too.
//!
//! # Layouts
//! A download folder holds image entities, in any mix of:
//! - `<id>.json`, one API v4 image entity per file, beside `<id>.jpg`;
//! - `metadata.jsonl` (any `*.jsonl`), one entity per line, as mapillary-downloader writes, the
//!   images at `<date>/<sequence>/<id>.jpg`;
//! - a saved API response `{"data": [entity, ...]}` (or a bare array of entities).
//!
//! Other JSON objects (mapillary-downloader's `progress.json`) and the downloader's closing
//! `{"__complete__": true}` line are skipped. An image is `<id>.jpg` (`.jpeg`, `.png`, `.webp`) beside its
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

use std::path::Path;

use glam::DMat3;
use image::RgbImage;
use serde_json::{Value, json};

use super::camera::{cut_panorama, exif_axes, plain_view, undistort_fisheye, upright};
use super::dates::{iso_from_ms, ms_from_iso};
use super::folder::{ImageIndex, extension, load_image, same_aspect, scan_folder};
use super::provider::{Geo, ProviderView, RecordViews, camera_z, read_records};
use super::record::{Record, parse_json};
use super::rotation::{angle_axis, from_rows, heading_deg, rodrigues, to_rows};
use crate::artifact::{Pose, ViewSet};
use crate::site::Site;
use crate::stage::StageError;

/// The reader's options and results, so that this module is all a caller of
/// [`read_mapillary`] needs.
pub use super::provider::{DropReason, Heights, PanoramaCut, ProviderViews, ReadOptions};

/// The camera models of `camera_type`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Camera {
    Perspective,
    Fisheye,
    Spherical,
}

impl Camera {
    /// The record's `camera_type`: perspective (the default), fisheye, spherical or
    /// equirectangular.
    fn of(rec: &Record) -> Result<Camera, StageError> {
        match rec.str("camera_type")?.unwrap_or("perspective") {
            "perspective" => Ok(Camera::Perspective),
            "fisheye" => Ok(Camera::Fisheye),
            "spherical" | "equirectangular" => Ok(Camera::Spherical),
            other => Err(rec.bad(
                "camera_type",
                format!("perspective, fisheye, spherical or equirectangular, found {other:?}"),
            )),
        }
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
        opts.store,
        |id, rec, geo| read_entity(id, rec, geo, &images, opts),
    )
}

/// One entity: its views, or why it gave none.
fn read_entity(
    id: &str,
    rec: &Record,
    geo: &Geo,
    images: &ImageIndex,
    opts: &ReadOptions,
) -> Result<RecordViews, StageError> {
    let camera = Camera::of(rec)?;
    let size = (rec.pixels("width")?, rec.pixels("height")?);
    let lens = lens(rec, camera)?;
    let orientation = exif_orientation(rec, camera)?;
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
    let c2s = enu_to_site * c2e;
    let pose = Pose {
        position: [xy[0], xy[1], z],
        rotation: to_rows(c2s),
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
            let cut = cut_panorama(&img, id, pose.position, &c2s, &opts.panorama, &captured_at);
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
                stored: None,
            }
        })
        .collect()))
}

/// The record's `exif_orientation`: 1 (the default, and always for spherical images), 3, 6 or 8.
fn exif_orientation(rec: &Record, camera: Camera) -> Result<u8, StageError> {
    match (rec.num("exif_orientation")?, camera) {
        (_, Camera::Spherical) | (None, _) => Ok(1),
        (Some(o), _) if [1.0, 3.0, 6.0, 8.0].contains(&o) => Ok(o as u8),
        (Some(o), _) => Err(rec.bad(
            "exif_orientation",
            format!("1, 3, 6 or 8 (mirrored images are not supported), found {o}"),
        )),
    }
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
) -> Result<Result<(DMat3, &'static str), DropReason>, StageError> {
    let compass = rec.num("computed_compass_angle")?;
    let level = |h: f64| from_rows(&Pose::from_angles([0.0; 3], h, 0.0, 0.0).rotation);
    match (
        rec.nums("computed_rotation", 3..=3)?,
        compass,
        rec.num("compass_angle")?,
    ) {
        (Some(r), ..) => {
            let stored = rodrigues([r[0], r[1], r[2]]).transpose();
            if let (Some(c), Some(h)) = (compass, heading_deg(&stored)) {
                let off = (h - c + 180.0).rem_euclid(360.0) - 180.0;
                if off.abs() > max_yaw_deg {
                    return Ok(Err(DropReason::YawDisagreement(off)));
                }
            }
            Ok(Ok((stored * exif_axes(orientation), "computed_rotation")))
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
pub fn write_mapillary(
    set: &ViewSet,
    site: &Site,
    parts: &dyn crate::stage::PartStore,
) -> Result<Vec<(String, Vec<u8>)>, String> {
    let geo = Geo::new(site).map_err(|e| e.to_string())?;
    let mut files = Vec::new();
    for head in &set.views {
        let v = &head.load(parts).map_err(|e| e.to_string())?;
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
        let c2e = enu_to_site.transpose() * from_rows(&v.pose.rotation);
        let compass = heading_deg(&c2e).unwrap_or(0.0);
        let point = json!({"type": "Point", "coordinates": [lon, lat]});
        let mut entity = json!({
            "id": v.id,
            "computed_geometry": point,
            "geometry": point,
            "computed_altitude": z,
            "altitude": z,
            "computed_rotation": angle_axis(&c2e.transpose()),
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
