//! View sets on disk, in the layout of DESIGN.md (Street views and model outputs):
//!
//! ```text
//! views.json        {"material_classes": [...], "views": [{ "id", "image", "width", "height",
//!                    "intrinsics": {"fx","fy","cx","cy"} | {"hfov_deg"},
//!                    "pose": {"x","y","z"} | {"lat","lon","alt_m"},
//!                    "orientation": {"heading_deg","pitch_deg","roll_deg"} | {"quat_wxyz"},
//!                    "captured_at" }]}   (a bare array of views is accepted too)
//! arch/<id>.png     architectural instance ids (16-bit), arch/<id>.json: {"<id>": "<class>"}
//! clutter/<id>.png  clutter instance ids (16-bit), clutter/<id>.json likewise
//! material/<id>.png material class per pixel (8-bit index into material_classes; 255 = none)
//! depth/<id>.exr    depth along the optical axis, channel Z (or Y, R, the first)
//! normal/<id>.exr   camera-frame normals, channels R, G, B (or X, Y, Z)
//! ```
//! Model outputs are optional per view; a file that is referenced or present must be valid.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::artifact::{Instances, Intrinsics, PodVec, Pose, View, ViewHead, ViewSet};
use crate::io::crs::{Crs, ToSite};
use crate::io::exr_io::{Channels, read_exr_expecting, write_exr};
use crate::site::Site;
use crate::stage::{PartStore, StageError};

fn num(v: &Value, key: &str) -> Option<f64> {
    v.get(key).and_then(Value::as_f64)
}

/// Reads the view set described by `views_json`, each view's pixels stored in `parts` as soon
/// as it is read (one view at a time in memory).
pub fn read_viewset(
    views_json: &Path,
    site: &Site,
    parts: &dyn PartStore,
) -> Result<ViewSet, StageError> {
    let dir = views_json.parent().unwrap_or(Path::new("."));
    let doc = read_views_json(views_json)?;
    let (list, material_classes) = view_list(views_json, &doc)?;
    let wgs84 = ToSite::new(&Crs::from_epsg(4326).map_err(StageError::Failed)?, site)
        .map_err(StageError::Failed)?;
    let mut set = ViewSet::new(material_classes);
    for (i, v) in list.iter().enumerate() {
        let view = read_view(views_json, dir, &wgs84, &set.material_classes, i, v)?;
        let head = store_checked(views_json, i, view, set.material_classes.len(), parts)?;
        set.views.push(head);
    }
    Ok(set)
}

/// Stores view `i` of a set read from `file`, after [`View::check`]: what every reader of views
/// (views.json, provider downloads, model outputs) runs on each view before handing it on. A
/// view that fails the check is an error on `file` naming it.
pub fn store_checked(
    file: &Path,
    i: usize,
    view: View,
    n_classes: usize,
    parts: &dyn PartStore,
) -> Result<ViewHead, StageError> {
    let id = view.id.clone();
    view.store(n_classes, parts)?.map_err(|(what, m)| {
        StageError::bad_input(
            file,
            format!("view {i} ({id:?}), {what}"),
            format!("expected {m}"),
        )
    })
}

/// Every view of `views`, stored in `parts` on all threads ([`ViewSet::store`]); a view that
/// fails [`View::check`] is an error on `file` naming it, as [`store_checked`] gives.
pub fn store_all_checked(
    file: &Path,
    views: Vec<View>,
    material_classes: Vec<String>,
    parts: &dyn PartStore,
) -> Result<ViewSet, StageError> {
    ViewSet::store(views, material_classes, parts)?
        .map_err(|(place, m)| StageError::bad_input(file, place, format!("expected {m}")))
}

/// An image file decoded by its content (JPEG, PNG, ...), opened as [`crate::io::open`] opens
/// files: a FIFO or device named as an image is an error, not a wait.
fn decode_image(path: &Path) -> image::ImageResult<image::DynamicImage> {
    let file = crate::io::open::open_regular(path).map_err(image::ImageError::IoError)?;
    image::ImageReader::new(std::io::BufReader::new(file))
        .with_guessed_format()
        .map_err(image::ImageError::IoError)?
        .decode()
}

fn read_views_json(views_json: &Path) -> Result<Value, StageError> {
    let text = crate::io::open::read_regular_to_string(views_json)
        .map_err(|e| StageError::bad_input(views_json, "open", e.to_string()))?;
    serde_json::from_str(&text).map_err(|e| {
        StageError::bad_input(
            views_json,
            format!("line {}, column {}", e.line(), e.column()),
            format!("expected JSON: {e}"),
        )
    })
}

/// The view entries and the material class table, from either accepted top level.
fn view_list<'a>(
    views_json: &Path,
    doc: &'a Value,
) -> Result<(&'a [Value], Vec<String>), StageError> {
    match doc {
        Value::Array(a) => Ok((a, Vec::new())),
        Value::Object(o) => Ok((
            o.get("views").and_then(Value::as_array).ok_or_else(|| {
                StageError::bad_input(views_json, "top level", "expected a `views` array")
            })?,
            o.get("material_classes")
                .and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(|c| c.as_str().map(str::to_owned))
                        .collect()
                })
                .unwrap_or_default(),
        )),
        _ => Err(StageError::bad_input(
            views_json,
            "top level",
            "expected an array of views or {\"views\": [...]}",
        )),
    }
}

/// View `i` of views.json, `v`, with its image and whichever model outputs are present.
fn read_view(
    views_json: &Path,
    dir: &Path,
    wgs84: &ToSite,
    material_classes: &[String],
    i: usize,
    v: &Value,
) -> Result<View, StageError> {
    let id = view_id(views_json, i, v)?;
    let entry = Entry {
        views_json,
        id: &id,
    };
    let pixels = |key: &str| {
        num(v, key)
            .filter(|n| *n >= 1.0 && n.fract() == 0.0 && *n <= u32::MAX as f64)
            .map(|n| n as u32)
            .ok_or_else(|| entry.bad(key, "expected a pixel count (a positive whole number)"))
    };
    let (width, height) = (pixels("width")?, pixels("height")?);
    let intrinsics = intrinsics(&entry, v, width, height)?;
    let position = position(&entry, v, wgs84)?;
    let pose = orientation(&entry, v, position)?;
    let files = ViewFiles {
        dir,
        id: &id,
        width,
        height,
    };
    let img = files.image(&entry, v)?;
    let material = files.material(views_json, material_classes)?;
    let depth = files.depth()?;
    let normal = files.normal()?;
    Ok(View {
        id: id.clone(),
        width,
        height,
        intrinsics,
        pose,
        captured_at: v
            .get("captured_at")
            .and_then(Value::as_str)
            .map(str::to_owned),
        pose_source: v
            .get("pose_source")
            .and_then(Value::as_str)
            .map(str::to_owned),
        distortion: distortion(&entry, v)?,
        image: PodVec(img.pixels().map(|p| p.0).collect()),
        arch: files.instances("arch")?,
        clutter: files.instances("clutter")?,
        material,
        depth,
        normal,
    })
}

/// `"distortion": [k1, k2]`, when given: two finite numbers.
fn distortion(entry: &Entry, v: &Value) -> Result<Option<[f64; 2]>, StageError> {
    let Some(d) = v.get("distortion").filter(|d| !d.is_null()) else {
        return Ok(None);
    };
    match d
        .as_array()
        .map(|a| a.iter().map(Value::as_f64).collect::<Vec<_>>())
    {
        Some(k) if k.len() == 2 && k.iter().all(|x| x.is_some_and(f64::is_finite)) => {
            Ok(Some([k[0].unwrap_or(0.0), k[1].unwrap_or(0.0)]))
        }
        _ => Err(entry.bad("distortion", "two finite numbers [k1, k2]")),
    }
}

/// A string id, or a number as one.
fn view_id(views_json: &Path, i: usize, v: &Value) -> Result<String, StageError> {
    let id = v.get("id").and_then(|x| {
        x.as_str()
            .map(str::to_owned)
            .or_else(|| x.as_u64().map(|n| n.to_string()))
    });
    let id = id.ok_or_else(|| {
        StageError::bad_input(views_json, format!("view {i}"), "expected an `id`")
    })?;
    // The id names the view's output files (`depth/<id>.exr`): it must be a plain file name.
    crate::io::safe_name::check_file_name(&id).map_err(|m| {
        StageError::bad_input(
            views_json,
            format!("view {i}, id"),
            format!("an id usable as a file name: {m}"),
        )
    })?;
    Ok(id)
}

/// The model outputs of one view, as found on disk.
#[derive(Debug, Default)]
pub struct ViewOutputs {
    /// `arch/<id>.png` with its class table.
    pub arch: Option<Instances>,
    /// `clutter/<id>.png` with its class table.
    pub clutter: Option<Instances>,
    /// `material/<id>.png`.
    pub material: Option<PodVec<u8>>,
    /// `depth/<id>.exr`.
    pub depth: Option<PodVec<f32>>,
    /// `normal/<id>.exr`.
    pub normal: Option<PodVec<[f32; 3]>>,
}

impl ViewOutputs {
    /// True when no output was found.
    pub fn is_empty(&self) -> bool {
        self.arch.is_none()
            && self.clutter.is_none()
            && self.material.is_none()
            && self.depth.is_none()
            && self.normal.is_none()
    }
}

/// The model outputs of view `id` (`width` x `height` pixels) under `dir` in the layout above,
/// for views whose pose came from elsewhere (a provider download): absent files give `None`, a
/// present file must be valid and of the view's size. `table` names where `material_classes`
/// came from, for the error when a material map exists without one.
pub fn read_view_outputs(
    dir: &Path,
    id: &str,
    (width, height): (u32, u32),
    material_classes: &[String],
    table: &Path,
) -> Result<ViewOutputs, StageError> {
    let files = ViewFiles {
        dir,
        id,
        width,
        height,
    };
    Ok(ViewOutputs {
        arch: files.instances("arch")?,
        clutter: files.instances("clutter")?,
        material: files.material(table, material_classes)?,
        depth: files.depth()?,
        normal: files.normal()?,
    })
}

/// One entry of views.json, for errors that name the view.
struct Entry<'a> {
    views_json: &'a Path,
    id: &'a str,
}

impl Entry<'_> {
    fn place(&self, what: &str) -> String {
        format!("view {:?}, {what}", self.id)
    }

    fn bad(&self, what: &str, expected: &str) -> StageError {
        StageError::bad_input(self.views_json, self.place(what), expected.to_owned())
    }
}

fn intrinsics(entry: &Entry, v: &Value, width: u32, height: u32) -> Result<Intrinsics, StageError> {
    let k = v
        .get("intrinsics")
        .ok_or_else(|| entry.bad("intrinsics", "expected {fx, fy, cx, cy} or {hfov_deg}"))?;
    match (
        num(k, "fx"),
        num(k, "fy"),
        num(k, "cx"),
        num(k, "cy"),
        num(k, "hfov_deg"),
    ) {
        (Some(fx), Some(fy), Some(cx), Some(cy), _) => Ok(Intrinsics { fx, fy, cx, cy }),
        (_, _, _, _, Some(h)) if h > 0.0 && h < 180.0 => {
            let f = width as f64 / 2.0 / (h.to_radians() / 2.0).tan();
            Ok(Intrinsics {
                fx: f,
                fy: f,
                cx: width as f64 / 2.0,
                cy: height as f64 / 2.0,
            })
        }
        _ => Err(entry.bad(
            "intrinsics",
            "expected {fx, fy, cx, cy} or {hfov_deg} in (0, 180)",
        )),
    }
}

/// The camera position in the site frame; a WGS 84 pose keeps its altitude as z.
fn position(entry: &Entry, v: &Value, wgs84: &ToSite) -> Result<[f64; 3], StageError> {
    let p = v
        .get("pose")
        .ok_or_else(|| entry.bad("pose", "expected {x, y, z} or {lat, lon, alt_m}"))?;
    match (
        num(p, "x"),
        num(p, "y"),
        num(p, "z"),
        num(p, "lat"),
        num(p, "lon"),
        num(p, "alt_m"),
    ) {
        (Some(x), Some(y), Some(z), ..) => Ok([x, y, z]),
        (_, _, _, Some(lat), Some(lon), Some(alt)) => {
            let (x, y, _) = wgs84
                .apply(lon, lat, 0.0)
                .map_err(|m| entry.bad("pose", &m))?;
            Ok([x, y, alt])
        }
        _ => Err(entry.bad(
            "pose",
            "expected {x, y, z} (site frame) or {lat, lon, alt_m}",
        )),
    }
}

fn orientation(entry: &Entry, v: &Value, position: [f64; 3]) -> Result<Pose, StageError> {
    let o = v.get("orientation").ok_or_else(|| {
        entry.bad(
            "orientation",
            "expected {heading_deg, pitch_deg, roll_deg} or {quat_wxyz}",
        )
    })?;
    match (
        num(o, "heading_deg"),
        o.get("quat_wxyz").and_then(Value::as_array),
    ) {
        (Some(h), _) => Ok(Pose::from_angles(
            position,
            h,
            num(o, "pitch_deg").unwrap_or(0.0),
            num(o, "roll_deg").unwrap_or(0.0),
        )),
        (None, Some(q)) if q.len() == 4 && q.iter().all(|x| x.is_number()) => {
            Ok(Pose::from_quaternion(
                position,
                [0, 1, 2, 3].map(|j| q[j].as_f64().expect("checked")),
            ))
        }
        _ => Err(entry.bad(
            "orientation",
            "expected {heading_deg, pitch_deg, roll_deg} or {quat_wxyz: [w, x, y, z]}",
        )),
    }
}

/// The image files of one view: its photo and the model outputs `<kind>/<id>.<ext>` beside
/// views.json, each of which must have the size views.json gives.
struct ViewFiles<'a> {
    dir: &'a Path,
    id: &'a str,
    width: u32,
    height: u32,
}

impl ViewFiles<'_> {
    fn output(&self, kind: &str, ext: &str) -> PathBuf {
        self.dir.join(kind).join(format!("{}.{ext}", self.id))
    }

    fn check_size(&self, p: &Path, w: u32, h: u32) -> Result<(), StageError> {
        let (width, height) = (self.width, self.height);
        if (w, h) == (width, height) {
            Ok(())
        } else {
            Err(StageError::bad_input(
                p,
                "size",
                format!("{w} x {h} pixels, but views.json says {width} x {height}"),
            ))
        }
    }

    /// The photo that views.json names (required).
    fn image(&self, entry: &Entry, v: &Value) -> Result<image::RgbImage, StageError> {
        let image_rel = v
            .get("image")
            .and_then(Value::as_str)
            .ok_or_else(|| entry.bad("image", "expected the image's path"))?;
        let image_path = crate::io::safe_name::resolve_inside(self.dir, self.dir, image_rel)
            .map_err(|m| entry.bad("image", &m))?;
        if !image_path.is_file() {
            return Err(StageError::bad_input(
                entry.views_json,
                entry.place("image"),
                format!("the image {} does not exist", image_path.display()),
            ));
        }
        let img = decode_image(&image_path)
            .map_err(|e| {
                StageError::bad_input(
                    &image_path,
                    "image",
                    format!("expected a readable JPEG/PNG: {e}"),
                )
            })?
            .into_rgb8();
        self.check_size(&image_path, img.width(), img.height())?;
        Ok(img)
    }

    /// `arch` or `clutter` instance ids, with the class table beside them.
    fn instances(&self, kind: &str) -> Result<Option<Instances>, StageError> {
        let png = self.output(kind, "png");
        if !png.exists() {
            return Ok(None);
        }
        let img = decode_image(&png)
            .map_err(|e| {
                StageError::bad_input(
                    &png,
                    "image",
                    format!("expected a 16-bit PNG of instance ids: {e}"),
                )
            })?
            .into_luma16();
        self.check_size(&png, img.width(), img.height())?;
        let classes = read_instance_classes(&png)?;
        Ok(Some(Instances {
            ids: PodVec(img.into_raw()),
            classes,
        }))
    }

    /// Per-pixel indices into `material_classes`, which must then not be empty.
    fn material(
        &self,
        views_json: &Path,
        material_classes: &[String],
    ) -> Result<Option<PodVec<u8>>, StageError> {
        let material_png = self.output("material", "png");
        if !material_png.exists() {
            return Ok(None);
        }
        if material_classes.is_empty() {
            return Err(StageError::bad_input(
                views_json,
                "material_classes",
                format!(
                    "{} exists but views.json has no material_classes table",
                    material_png.display()
                ),
            ));
        }
        let m = decode_image(&material_png)
            .map_err(|e| {
                StageError::bad_input(
                    &material_png,
                    "image",
                    format!("expected an 8-bit PNG of class indices: {e}"),
                )
            })?
            .into_luma8();
        self.check_size(&material_png, m.width(), m.height())?;
        let n = material_classes.len();
        if let Some((x, y, c)) = m
            .enumerate_pixels()
            .find(|(_, _, c)| c.0[0] != 255 && c.0[0] as usize >= n)
        {
            return Err(StageError::bad_input(
                &material_png,
                format!("pixel ({x}, {y})"),
                format!(
                    "a class index below {n} (the material_classes table of {}) or 255 (none), found {}",
                    views_json.display(),
                    c.0[0]
                ),
            ));
        }
        Ok(Some(PodVec(m.into_raw())))
    }

    fn exr_channels(&self, kind: &str) -> Result<Option<Channels>, StageError> {
        let p = self.output(kind, "exr");
        if !p.exists() {
            return Ok(None);
        }
        // The header's size against the view's before a pixel is decoded: a depth map whose
        // header claims far more than its view would otherwise be decoded first.
        let (_, _, ch) = read_exr_expecting(&p, |w, h| self.check_size(&p, w as u32, h as u32))?;
        Ok(Some(ch))
    }

    fn depth(&self) -> Result<Option<PodVec<f32>>, StageError> {
        Ok(self
            .exr_channels("depth")?
            .map(|ch| {
                pick_channel(&ch, &["Z", "Y", "R"])
                    .or_else(|| ch.first().map(|c| c.1.clone()))
                    .unwrap_or_default()
            })
            .map(PodVec))
    }

    fn normal(&self) -> Result<Option<PodVec<[f32; 3]>>, StageError> {
        let Some(ch) = self.exr_channels("normal")? else {
            return Ok(None);
        };
        let (x, y, z) = match (
            pick_channel(&ch, &["R", "X"]),
            pick_channel(&ch, &["G", "Y"]),
            pick_channel(&ch, &["B", "Z"]),
        ) {
            (Some(x), Some(y), Some(z)) => (x, y, z),
            _ => {
                return Err(StageError::bad_input(
                    &self.output("normal", "exr"),
                    "channels",
                    "expected R, G, B (or X, Y, Z)",
                ));
            }
        };
        let n = self.width as usize * self.height as usize;
        Ok(Some(PodVec((0..n).map(|i| [x[i], y[i], z[i]]).collect())))
    }
}

/// The class table `<png stem>.json` that must sit beside an instance PNG.
fn read_instance_classes(png: &Path) -> Result<BTreeMap<u16, String>, StageError> {
    let json = png.with_extension("json");
    let Ok(t) = crate::io::open::read_regular_to_string(&json) else {
        return Err(StageError::bad_input(
            png,
            "classes",
            format!("expected the class table {} beside it", json.display()),
        ));
    };
    let m: BTreeMap<String, String> = serde_json::from_str(&t).map_err(|e| {
        StageError::bad_input(
            &json,
            "contents",
            format!("expected {{\"<instance id>\": \"<class>\"}}: {e}"),
        )
    })?;
    m.into_iter()
        .map(|(k, c)| {
            k.parse::<u16>().map(|k| (k, c)).map_err(|_| {
                StageError::bad_input(
                    &json,
                    format!("key {k:?}"),
                    "expected an instance id 1-65535",
                )
            })
        })
        .collect()
}

/// The first of `names` present among the channels.
fn pick_channel(ch: &[(String, Vec<f32>)], names: &[&str]) -> Option<Vec<f32>> {
    names
        .iter()
        .find_map(|n| ch.iter().find(|c| c.0 == *n).map(|c| c.1.clone()))
}

fn png(w: u32, h: u32, color: image::ExtendedColorType, bytes: &[u8]) -> Result<Vec<u8>, String> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(bytes, w, h, color)
        .map_err(|e| format!("PNG encoding failed: {e}"))?;
    Ok(out)
}

/// The files of a view set in the DESIGN layout, `views.json` first. Images are written as PNG so
/// the model outputs stay pixel-exact.
pub fn write_viewset(
    set: &ViewSet,
    parts: &dyn crate::stage::PartStore,
) -> Result<Vec<(String, Vec<u8>)>, String> {
    let mut files = Vec::new();
    let mut entries = Vec::new();
    for head in &set.views {
        let v = &head.load(parts).map_err(|e| e.to_string())?;
        let (w, h) = (v.width, v.height);
        entries.push(json!({
            "id": v.id,
            "image": format!("img/{}.png", v.id),
            "width": w,
            "height": h,
            "intrinsics": {"fx": v.intrinsics.fx, "fy": v.intrinsics.fy, "cx": v.intrinsics.cx, "cy": v.intrinsics.cy},
            "pose": {"x": v.pose.position[0], "y": v.pose.position[1], "z": v.pose.position[2]},
            "orientation": {"quat_wxyz": quaternion(&v.pose)},
            "captured_at": v.captured_at,
            "pose_source": v.pose_source,
            "distortion": v.distortion,
        }));
        files.push((
            format!("img/{}.png", v.id),
            png(
                w,
                h,
                image::ExtendedColorType::Rgb8,
                bytemuck::cast_slice(&v.image),
            )?,
        ));
        for (kind, inst) in [("arch", &v.arch), ("clutter", &v.clutter)] {
            if let Some(inst) = inst {
                // The encoder takes native-endian samples and writes PNG's big-endian itself.
                files.push((
                    format!("{kind}/{}.png", v.id),
                    png(
                        w,
                        h,
                        image::ExtendedColorType::L16,
                        bytemuck::cast_slice(&inst.ids),
                    )?,
                ));
                let classes: BTreeMap<String, &String> = inst
                    .classes
                    .iter()
                    .map(|(k, c)| (k.to_string(), c))
                    .collect();
                files.push((
                    format!("{kind}/{}.json", v.id),
                    serde_json::to_vec_pretty(&classes).map_err(|e| e.to_string())?,
                ));
            }
        }
        if let Some(m) = &v.material {
            files.push((
                format!("material/{}.png", v.id),
                png(w, h, image::ExtendedColorType::L8, m)?,
            ));
        }
        if let Some(d) = &v.depth {
            files.push((
                format!("depth/{}.exr", v.id),
                write_exr(w as usize, h as usize, vec![("Z", d.0.clone())])?,
            ));
        }
        if let Some(nrm) = &v.normal {
            let ch = |k: usize| nrm.iter().map(|n| n[k]).collect::<Vec<f32>>();
            files.push((
                format!("normal/{}.exr", v.id),
                write_exr(
                    w as usize,
                    h as usize,
                    vec![("R", ch(0)), ("G", ch(1)), ("B", ch(2))],
                )?,
            ));
        }
    }
    let doc = json!({"material_classes": set.material_classes, "views": entries});
    let mut out = vec![(
        "views.json".to_owned(),
        serde_json::to_vec_pretty(&doc).map_err(|e| e.to_string())?,
    )];
    out.extend(files);
    Ok(out)
}

/// The unit quaternion (w, x, y, z) of a pose's rotation (Shepperd's method).
fn quaternion(p: &Pose) -> [f64; 4] {
    let m = &p.rotation;
    let t = m[0][0] + m[1][1] + m[2][2];
    if t > 0.0 {
        let s = (t + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    }
}
