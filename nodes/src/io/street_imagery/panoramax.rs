//! Street-level views from Panoramax: STAC Items (one per `*.json`, or ItemCollections, anywhere
//! under a folder) with their images, read into the site frame.
//!
//! # Fields
//! `id`; `geometry` (GeoJSON Point [lon, lat] or [lon, lat, ellipsoidal height]);
//! `properties.view:azimuth`, else `properties.pers:yaw` (heading, degrees clockwise from true
//! north); `properties.pers:pitch` (up positive) and `properties.pers:roll` (clockwise seen from
//! behind), default 0; `properties.pers:interior_orientation`: `field_of_view` (horizontal,
//! degrees; 360 is an equirectangular panorama, as is `properties.exif` `Xmp.GPano.ProjectionType`
//! = `equirectangular`), else `focal_length` over `pixel_spacing` (mm, at
//! `sensor_array_dimensions`); `sensor_array_dimensions` (checked against the image's aspect);
//! `camera_manufacturer` and `camera_model` are not used; `properties.datetime` (ISO 8601).
//! JSON files that are neither an Item nor an ItemCollection (a STAC Collection) are skipped.
//! The image is the asset `hd`, else `sd`: its `href` relative to the item's file (it may not
//! leave the folder), or for a URL the file `<id>.jpg` (`.jpeg`, `.png`, `.webp`) anywhere under the
//! folder.
//!
//! # Pose
//! As for Mapillary ([`super::mapillary`]): camera to site = A · (heading, pitch, roll) with A
//! the ENU-to-site turn by the meridian convergence; z from the terrain plus a camera height, or
//! the geometry's height with `trust_altitude`. Panoramax serves images upright. Panoramas are cut
//! into level pinhole views `<id>-<k>` from the panorama's heading.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::camera::{cut_panorama, plain_view};
use super::folder::{ImageIndex, load_image, same_aspect, scan_folder};
use super::provider::{
    DropReason, Geo, ProviderView, ProviderViews, ReadOptions, RecordViews, camera_z, read_records,
};
use super::record::{Record, parse_json};
use super::rotation::{from_rows, to_rows};
use crate::artifact::Pose;
use crate::site::Site;
use crate::stage::StageError;

/// Reads the STAC items under `folder` (see the module docs) into views in the site frame.
pub fn read_panoramax(
    folder: &Path,
    site: &Site,
    opts: &ReadOptions,
) -> Result<ProviderViews, StageError> {
    let (texts, images) = scan_folder(folder, &["json"])?;
    let (mut items, mut skipped) = (Vec::new(), Vec::new());
    for (f, text) in &texts {
        let v = parse_json(f, text, "")?;
        match v.get("type").and_then(Value::as_str) {
            Some("Feature") => items.push((f, String::new(), v)),
            Some("FeatureCollection") => {
                let features = v.get("features").and_then(Value::as_array).ok_or_else(|| {
                    StageError::bad_input(f, "features", "expected an array of STAC Items")
                })?;
                items.extend(
                    features
                        .iter()
                        .enumerate()
                        .map(|(i, item)| (f, format!("features[{i}]"), item.clone())),
                );
            }
            // A STAC Collection or Catalog, or any other JSON: no items.
            _ => skipped.push(f.clone()),
        }
    }
    read_records(
        (folder, site),
        (&items, skipped),
        (
            "item",
            "STAC Item JSON files (or an ItemCollection) with their images",
        ),
        opts.store,
        |id, rec, geo| read_item(id, rec, geo, &images, opts),
    )
}

const IO: &str = "properties.pers:interior_orientation";

/// One item's views, or why it gave none.
fn read_item(
    id: &str,
    rec: &Record,
    geo: &Geo,
    images: &ImageIndex,
    opts: &ReadOptions,
) -> Result<RecordViews, StageError> {
    let (lon_lat, altitude) = rec.point("geometry")?.ok_or_else(|| {
        rec.bad(
            "geometry",
            "the image's position: a GeoJSON Point [lon, lat]",
        )
    })?;
    let projection = rec
        .get("properties.exif")
        .and_then(|e| e.get("Xmp.GPano.ProjectionType"))
        .and_then(Value::as_str);
    let fov = rec.num(&format!("{IO}.field_of_view"))?;
    let spherical = fov == Some(360.0) || projection == Some("equirectangular");
    let (heading, mut orient_field) = match (
        rec.num("properties.view:azimuth")?,
        rec.num("properties.pers:yaw")?,
    ) {
        (Some(h), _) => (h, "view:azimuth".to_owned()),
        (None, Some(h)) => (h, "pers:yaw".to_owned()),
        (None, None) => {
            return Err(rec.bad(
                "properties.view:azimuth",
                "the image's heading in view:azimuth or pers:yaw",
            ));
        }
    };
    let (pitch, roll) = (
        rec.num("properties.pers:pitch")?,
        rec.num("properties.pers:roll")?,
    );
    if pitch.is_some_and(|p| p.abs() > 90.0) {
        return Err(rec.bad("properties.pers:pitch", "a pitch within ±90 degrees"));
    }
    if pitch.is_some() || roll.is_some() {
        orient_field.push_str(" + pers:pitch/roll");
    }
    let sensor = rec.nums(&format!("{IO}.sensor_array_dimensions"), 2..=2)?;
    if let Some(s) = &sensor
        && !(s[0] >= 1.0 && s[1] >= 1.0 && s[0] <= 1e5 && s[1] <= 1e5)
    {
        return Err(rec.bad(
            &format!("{IO}.sensor_array_dimensions"),
            "[width, height] in pixels, 1 to 100000",
        ));
    }
    let (xy, enu_to_site) = geo
        .enu_to_site(lon_lat[0], lon_lat[1])
        .map_err(|m| rec.bad("geometry", format!("a position the site CRS covers: {m}")))?;
    let altitude = altitude.map(|a| (a, "geometry altitude"));
    let Some((z, height_source)) = camera_z(&opts.heights, xy, altitude, rec, "geometry")? else {
        return Ok(Err(DropReason::NoTerrain));
    };
    let position = [xy[0], xy[1], z];
    let c2e =
        Pose::from_angles([0.0; 3], heading, pitch.unwrap_or(0.0), roll.unwrap_or(0.0)).rotation;
    let c2s = enu_to_site * from_rows(&c2e);
    let pose_source = format!("{orient_field}, geometry, {height_source}");
    let captured_at = rec.str("properties.datetime")?.map(str::to_owned);
    let path = image_path(id, rec, images)?;
    let img = load_image(&path)?;
    if let Some(s) = &sensor
        && !same_aspect(img.dimensions(), (s[0] as u32, s[1] as u32))
    {
        return Err(StageError::bad_input(
            &path,
            "size",
            format!(
                "{} x {} pixels, the aspect of sensor_array_dimensions [{}, {}] in {}",
                img.width(),
                img.height(),
                s[0],
                s[1],
                rec.file.display()
            ),
        ));
    }
    let views = if spherical {
        cut_panorama(&img, id, position, &c2s, &opts.panorama, &captured_at)
    } else {
        let f = focal_px(rec, fov, sensor.as_deref(), img.width())?;
        let pose = Pose {
            position,
            rotation: to_rows(c2s),
        };
        vec![plain_view(id.to_owned(), img, f, pose, captured_at)]
    };
    Ok(Ok(views
        .into_iter()
        .map(|mut view| {
            view.pose_source = Some(pose_source.clone());
            ProviderView {
                view,
                pose_source: pose_source.clone(),
                distortion: None,
                stored: None,
            }
        })
        .collect()))
}

/// The focal length in pixels of an image `width` across: from the field of view, else from the
/// focal length and pixel spacing at the sensor's width.
fn focal_px(
    rec: &Record,
    fov: Option<f64>,
    sensor: Option<&[f64]>,
    width: u32,
) -> Result<f64, StageError> {
    let field = format!("{IO}.field_of_view");
    match fov {
        Some(h) if h > 0.0 && h < 180.0 => {
            return Ok(width as f64 / 2.0 / (h.to_radians() / 2.0).tan());
        }
        Some(h) => {
            return Err(rec.bad(
                &field,
                format!("a horizontal field of view in (0, 180) degrees, or 360, found {h}"),
            ));
        }
        None => {}
    }
    let focal = rec.num(&format!("{IO}.focal_length"))?;
    let spacing = rec.nums(&format!("{IO}.pixel_spacing"), 1..=2)?;
    match (focal, spacing.and_then(|s| s.first().copied()), sensor) {
        (Some(f), Some(p), Some(s)) if f > 0.0 && p > 0.0 => Ok(f / p * width as f64 / s[0]),
        (Some(f), ..) if !(f > 0.0) => Err(rec.bad(
            &format!("{IO}.focal_length"),
            format!("a positive focal length in mm, found {f}"),
        )),
        _ => Err(rec.bad(
            &field,
            "the horizontal field of view (or focal_length with pixel_spacing and \
             sensor_array_dimensions)",
        )),
    }
}

/// The item's image: asset `hd`, else `sd`, relative to its file; for URLs, `<id>.jpg` anywhere.
fn image_path(id: &str, rec: &Record, images: &ImageIndex) -> Result<PathBuf, StageError> {
    let dir = rec.file.parent().unwrap_or(Path::new("."));
    let mut tried = Vec::new();
    for asset in ["hd", "sd"] {
        let field = format!("assets.{asset}.href");
        let Some(href) = rec.str(&field)? else {
            continue;
        };
        if href.contains("://") {
            continue;
        }
        let p =
            crate::io::safe_name::resolve_inside(dir, dir, href).map_err(|m| rec.bad(&field, m))?;
        if p.is_file() {
            return Ok(p);
        }
        tried.push(p.display().to_string());
    }
    if let Some(p) = images.find(id, Some(dir), None) {
        return Ok(p.to_path_buf());
    }
    let field = if tried.is_empty() {
        "assets.hd.href"
    } else {
        "assets"
    };
    Err(rec.bad(
        field,
        format!(
            "the image: {} or {id}.jpg anywhere under the folder",
            if tried.is_empty() {
                "an hd or sd asset".to_owned()
            } else {
                tried.join(" or ")
            }
        ),
    ))
}
