//! Street views straight from the providers: Mapillary API v4 downloads and Panoramax STAC items
//! read against poses computed independently by `scripts/make_mapillary_fixtures.py` (numpy +
//! pyproj, with the meridian convergence), the yaw-disagreement drop, panorama cutting, EXIF
//! orientation, the Mapillary writer round trip of the synthetic views, and bad input.

mod common;
use common::*;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use kodama_nodes::artifact::{Grid, PodVec, Raster, View, ViewSet};
use kodama_nodes::io::mapillary::{
    DropReason, Heights, PanoramaCut, ProviderViews, ReadOptions, read_mapillary, write_mapillary,
};
use kodama_nodes::io::panoramax::read_panoramax;
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::ingest::read_mapillary::{ReadMapillary, ReadMapillaryParams};
use kodama_nodes::stages::ingest::read_panoramax::{ReadPanoramax, ReadPanoramaxParams};
use kodama_nodes::synth::synth_city::generate;
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::{Artifact, Ctx, FileRef, Inputs, Stage, StageError};
use serde_json::Value;

/// A fixture folder of this crate's `tests/fixtures`.
fn fixtures(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(rel)
}

fn expected(provider: &str) -> Value {
    let text = std::fs::read_to_string(fixtures(provider).join("expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The terrain plane of the fixtures' expected.json, as a 1 m raster over the fixtures' cameras.
fn terrain_plane(e: &Value) -> Raster {
    let t = &e["terrain"];
    let (z0, gx, gy) = (
        t["z0"].as_f64().unwrap(),
        t["gx"].as_f64().unwrap(),
        t["gy"].as_f64().unwrap(),
    );
    let grid = Grid {
        x0: 0.0,
        y0: 200.0,
        cell_m: 1.0,
        width: 200,
        height: 200,
    };
    let data = (0..grid.height)
        .flat_map(|r| (0..grid.width).map(move |c| (c, r)))
        .map(|(c, r)| {
            let (x, y) = grid.center(c, r);
            (z0 + gx * x + gy * y) as f32
        })
        .collect();
    Raster {
        grid,
        data: PodVec(data),
    }
}

fn options(heights: Heights) -> ReadOptions {
    ReadOptions {
        heights,
        panorama: PanoramaCut {
            views: 4,
            hfov_deg: 90.0,
            size_px: None,
        },
        max_yaw_disagreement_deg: 10.0,
        store: None,
    }
}

fn mapillary(rel: &str, heights: Heights) -> ProviderViews {
    read_mapillary(&fixtures(rel), &site(), &options(heights)).unwrap()
}

/// The angle between two rotations, degrees.
fn angle_deg(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> f64 {
    let tr: f64 = (0..3)
        .map(|i| (0..3).map(|k| a[k][i] * b[k][i]).sum::<f64>())
        .sum();
    ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
}

fn rows(v: &Value) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| v[r][c].as_f64().unwrap()))
}

fn vec3(v: &Value) -> [f64; 3] {
    std::array::from_fn(|k| v[k].as_f64().unwrap())
}

/// Every view of `got` against expected.json's, positions from `position_<mode>`, pose sources
/// from `pose_source_<mode>`; and exactly the views of expected.json whose ids start with `ids`.
fn check_poses(got: &ProviderViews, e: &Value, mode: &str, ids: &str) {
    let views = e["views"].as_object().unwrap();
    assert_eq!(
        got.views
            .iter()
            .map(|v| v.view.id.clone())
            .collect::<Vec<_>>(),
        views
            .keys()
            .filter(|k| k.starts_with(ids))
            .cloned()
            .collect::<Vec<_>>(),
        "view ids"
    );
    for pv in &got.views {
        let (v, x) = (&pv.view, &views[&pv.view.id]);
        let want = vec3(&x[format!("position_{mode}")]);
        let off = (0..3)
            .map(|k| (v.pose.position[k] - want[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            off < 1e-3,
            "{}: position {:?} vs {want:?}",
            v.id,
            v.pose.position
        );
        let a = angle_deg(&v.pose.rotation, &rows(&x["rotation"]));
        assert!(a < 1e-3, "{}: rotation off by {a} degrees", v.id);
        // The view itself carries where its pose came from, for every stage downstream.
        assert_eq!(
            v.pose_source.as_deref(),
            Some(pv.pose_source.as_str()),
            "{}",
            v.id
        );
        assert_eq!(v.distortion, pv.distortion, "{}", v.id);
        assert_eq!(
            (v.width as u64, v.height as u64),
            (x["width"].as_u64().unwrap(), x["height"].as_u64().unwrap()),
            "{}: size",
            v.id
        );
        let f = x["f"].as_f64().unwrap();
        assert!(
            (v.intrinsics.fx - f).abs() < 1e-9 && (v.intrinsics.fy - f).abs() < 1e-9,
            "{}",
            v.id
        );
        assert_eq!(
            (v.intrinsics.cx, v.intrinsics.cy),
            (v.width as f64 / 2.0, v.height as f64 / 2.0)
        );
        assert_eq!(v.image.len(), (v.width * v.height) as usize);
        assert_eq!(
            pv.pose_source,
            x[format!("pose_source_{mode}")].as_str().unwrap(),
            "{}",
            v.id
        );
        assert_eq!(
            v.captured_at.as_deref(),
            x["captured_at"].as_str(),
            "{}",
            v.id
        );
        if let Some(d) = x.get("distortion") {
            let want = d
                .as_array()
                .map(|a| [a[0].as_f64().unwrap(), a[1].as_f64().unwrap()]);
            assert_eq!(pv.distortion, want, "{}: distortion", v.id);
        }
    }
}

fn view<'a>(got: &'a ProviderViews, id: &str) -> &'a View {
    &got.views.iter().find(|v| v.view.id == id).unwrap().view
}

fn pixel(v: &View, u: u32, w: u32) -> [u8; 3] {
    v.image[(w * v.width + u) as usize]
}

fn near(a: [u8; 3], b: [u8; 3]) -> bool {
    a.iter()
        .zip(b)
        .all(|(x, y)| (*x as i32 - y as i32).abs() <= 24)
}

/// The view looks where expected.json says: its centre pixel has the `centre_colour` of the
/// panorama's quadrant there.
fn assert_centre_colour(v: &View, x: &Value) {
    let colour = std::array::from_fn(|c| x["centre_colour"][c].as_u64().unwrap() as u8);
    assert_colour(v, (v.width / 2, v.height / 2), colour);
}

/// Pixel (u, w) of `v` is `colour`, give or take the JPEG.
fn assert_colour(v: &View, (u, w): (u32, u32), colour: [u8; 3]) {
    let got = pixel(v, u, w);
    assert!(
        near(got, colour),
        "{} ({u}, {w}): {got:?} vs {colour:?}",
        v.id
    );
}

#[test]
fn mapillary_poses_match_the_script_with_provider_altitudes() {
    let got = mapillary("mapillary/per_image", Heights::Provider);
    let e = expected("mapillary");
    check_poses(&got, &e, "trust", "1");
    // The site sits east of UTM 18N's central meridian: true north is west of grid north.
    let conv = e["views"]["1001"]["convergence_deg"].as_f64().unwrap();
    assert!((-0.7..-0.6).contains(&conv), "{conv}");
}

#[test]
fn mapillary_heights_come_from_the_terrain_plus_camera_height() {
    let e = expected("mapillary");
    let terrain = terrain_plane(&e);
    let got = mapillary(
        "mapillary/per_image",
        Heights::Terrain {
            terrain: &terrain,
            camera_height_m: 2.5,
        },
    );
    check_poses(&got, &e, "terrain", "1");
}

#[test]
fn yaw_disagreement_drops_the_view_with_a_warning() {
    let warnings = Warnings::default();
    let folder = fixtures("mapillary/per_image");
    let files = [folder];
    let the_site = site();
    let ctx = ctx_warning_into(&the_site, &files, &warnings);
    let p: ReadMapillaryParams =
        serde_json::from_value(serde_json::json!({"path": "x", "trust_altitude": true})).unwrap();
    let set = ReadMapillary::run(&p, &Inputs::new(), &ctx).unwrap();
    assert!(set.views.iter().all(|v| v.id != "1005"));
    assert_eq!(
        set.views.len(),
        8,
        "1001, four views of 1002, 1003, 1004, 1006"
    );
    let w = warnings.0.lock().unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with("1 image(s) dropped") && w[0].contains("(1005)"),
        "{}",
        w[0]
    );
    // computed_rotation looks at 45 degrees, computed_compass_angle says 75.
    let got = mapillary("mapillary/per_image", Heights::Provider);
    assert_eq!(got.dropped.len(), 1);
    assert_eq!(got.dropped[0].id, "1005");
    assert!(
        matches!(got.dropped[0].reason, DropReason::YawDisagreement(d) if (d + 30.0).abs() < 1e-6)
    );
    // A wider tolerance keeps it.
    let lax = ReadOptions {
        max_yaw_disagreement_deg: 31.0,
        ..options(Heights::Provider)
    };
    let all = read_mapillary(&fixtures("mapillary/per_image"), &site(), &lax).unwrap();
    assert!(all.dropped.is_empty() && all.views.iter().any(|v| v.view.id == "1005"));
}

#[test]
fn a_panorama_is_cut_into_level_views_evenly_in_heading() {
    let got = mapillary("mapillary/per_image", Heights::Provider);
    let e = expected("mapillary");
    let cut: Vec<&View> = got
        .views
        .iter()
        .map(|v| &v.view)
        .filter(|v| v.id.starts_with("1002-"))
        .collect();
    assert_eq!(cut.len(), 4);
    for (k, v) in cut.iter().enumerate() {
        let x = &e["views"][format!("1002-{k}")];
        let r = v.pose.rotation;
        // Level: forward has no z, down is straight down.
        assert!(
            r[2][2].abs() < 1e-12 && (r[2][1] + 1.0).abs() < 1e-12,
            "{}: {r:?}",
            v.id
        );
        let heading = r[0][2].atan2(r[1][2]).to_degrees().rem_euclid(360.0);
        let want = x["heading_deg"].as_f64().unwrap();
        assert!(
            (heading - want).abs() < 1e-6,
            "{}: heading {heading} vs {want}",
            v.id
        );
        // Each looks at its quadrant of the panorama: ahead, right, behind, left.
        assert_centre_colour(v, x);
    }
    // With more views, more of them; the count is bounded by the params.
    let eight = ReadOptions {
        panorama: PanoramaCut {
            views: 8,
            hfov_deg: 60.0,
            size_px: Some(32),
        },
        ..options(Heights::Provider)
    };
    let got = read_mapillary(&fixtures("mapillary/per_image"), &site(), &eight).unwrap();
    let cut: Vec<&View> = got
        .views
        .iter()
        .map(|v| &v.view)
        .filter(|v| v.id.starts_with("1002-"))
        .collect();
    assert_eq!(cut.len(), 8);
    assert!(cut.iter().all(|v| v.width == 32 && v.height == 32));
    let p = |n: u32| ReadMapillaryParams {
        panorama_views: n,
        ..serde_json::from_value(serde_json::json!({"path": "x"})).unwrap()
    };
    assert!(ReadMapillary::validate(&p(0)).is_err());
    assert!(ReadMapillary::validate(&p(17)).is_err());
    assert!(ReadMapillary::validate(&p(16)).is_ok());
}

#[test]
fn exif_orientation_6_turns_the_image_and_the_camera_axes() {
    let got = mapillary("mapillary/per_image", Heights::Provider);
    let v = view(&got, "1004");
    // Stored 24 x 16 sideways, upright 16 x 24; the red top-left quadrant as stored is top-right.
    assert_eq!((v.width, v.height), (16, 24));
    assert_colour(v, (13, 3), [230, 30, 30]);
    assert_colour(v, (2, 20), [128, 128, 128]);
    // The image's down axis points down (pitch 10 degrees, no roll): the upright camera.
    assert!(v.pose.rotation[2][1] < -0.9, "{:?}", v.pose.rotation);
    // A file already turned upright (width and height swapped) gives the same view.
    let dir = tempfile::tempdir().unwrap();
    let src = fixtures("mapillary/per_image");
    std::fs::copy(src.join("1004.json"), dir.path().join("1004.json")).unwrap();
    let stored = image::open(src.join("1004.jpg")).unwrap().into_rgb8();
    image::imageops::rotate90(&stored)
        .save(dir.path().join("1004.jpg"))
        .unwrap();
    let again = read_mapillary(dir.path(), &site(), &options(Heights::Provider)).unwrap();
    let w = view(&again, "1004");
    assert_eq!(
        (w.width, w.height, w.pose, w.intrinsics),
        (v.width, v.height, v.pose, v.intrinsics)
    );
    assert_colour(w, (13, 3), [230, 30, 30]);
}

#[test]
fn a_fisheye_is_resampled_to_a_pinhole_of_the_same_focal_length() {
    let got = mapillary("mapillary/per_image", Heights::Provider);
    let v = view(&got, "1003");
    assert_eq!((v.width, v.height, v.intrinsics.fx), (32, 24, 16.0));
    assert_colour(v, (16, 12), [220, 30, 220]);
    // Outside the magenta disk (4 px in the fisheye, 4.1 px in the pinhole): grey.
    assert_colour(v, (1, 1), [128, 128, 128]);
    let pv = got.views.iter().find(|p| p.view.id == "1003").unwrap();
    assert_eq!(pv.distortion, None, "applied by the resampling");
}

#[test]
fn without_computed_rotation_the_compass_gives_a_level_pose() {
    let got = mapillary("mapillary/per_image", Heights::Provider);
    let pv = got.views.iter().find(|p| p.view.id == "1006").unwrap();
    let r = pv.view.pose.rotation;
    assert!(
        r[2][2].abs() < 1e-12 && r[2][0].abs() < 1e-12,
        "level, no roll: {r:?}"
    );
    assert!(
        pv.pose_source.starts_with("computed_compass_angle,"),
        "{}",
        pv.pose_source
    );
}

#[test]
fn mapillary_downloader_layout_with_metadata_jsonl() {
    let got = mapillary("mapillary/jsonl", Heights::Provider);
    let e = expected("mapillary");
    check_poses(&got, &e, "trust", "2");
    // The downloader's progress.json holds no entity; its closing marker line is no image.
    assert_eq!(got.skipped.len(), 1);
    assert!(got.skipped[0].ends_with("jsonl/progress.json"));
    assert_eq!(got.dropped.len(), 1);
    assert_eq!(
        (got.dropped[0].id.as_str(), &got.dropped[0].reason),
        ("2001", &DropReason::Duplicate)
    );
    // 2002 lies in a darker image elsewhere under the folder, a lossy WebP (as Mapillary serves
    // its thumbnails; written by Pillow): found by id and decoded.
    assert_colour(&got.views[1].view, (3, 3), [90, 90, 90]);
}

#[test]
fn panoramax_items_match_the_script() {
    let e = expected("panoramax");
    let got = read_panoramax(
        &fixtures("panoramax/items"),
        &site(),
        &options(Heights::Provider),
    )
    .unwrap();
    check_poses(&got, &e, "trust", "");
    let terrain = terrain_plane(&e);
    let heights = Heights::Terrain {
        terrain: &terrain,
        camera_height_m: 2.5,
    };
    let got = read_panoramax(&fixtures("panoramax/items"), &site(), &options(heights)).unwrap();
    check_poses(&got, &e, "terrain", "");
    for k in 0..4 {
        let id = format!("b-{k}");
        assert_centre_colour(view(&got, &id), &e["views"][&id]);
    }
}

#[test]
fn stages_read_their_folder_and_need_terrain_or_trust() {
    for (files, path) in [
        (
            ReadMapillary::files(
                &serde_json::from_value(serde_json::json!({"path": "street/mly"})).unwrap(),
            ),
            "street/mly",
        ),
        (
            ReadPanoramax::files(
                &serde_json::from_value(serde_json::json!({"path": "street/pmx"})).unwrap(),
            ),
            "street/pmx",
        ),
    ] {
        assert_eq!(
            files,
            [FileRef {
                field: "path",
                path: path.into()
            }]
        );
    }
    let folder = [fixtures("panoramax/items")];
    let s = site();
    let ctx = Ctx::new(&s, &folder);
    let p: ReadPanoramaxParams = serde_json::from_value(serde_json::json!({"path": "x"})).unwrap();
    assert_eq!(
        (
            p.camera_height_m,
            p.trust_altitude,
            p.panorama_views,
            p.panorama_hfov_deg
        ),
        (2.5, false, 4, 90.0)
    );
    let err = ReadPanoramax::run(&p, &Inputs::new(), &ctx).unwrap_err();
    assert!(err.is_user_error());
    let msg = err.to_string();
    assert!(
        msg.contains("terrain") && msg.contains("trust_altitude"),
        "{msg}"
    );
    // With the terrain input.
    let e = expected("panoramax");
    let inputs = Inputs::new().with(
        "terrain",
        Slot::Optional(Some(Arc::new(Artifact::Raster(terrain_plane(&e))))),
    );
    let set = ReadPanoramax::run(&p, &inputs, &ctx).unwrap();
    assert_eq!(set.views.len(), 6);
    assert!(
        serde_json::from_value::<ReadPanoramaxParams>(serde_json::json!({"path": "x", "typo": 1}))
            .is_err()
    );
}

#[test]
fn reading_twice_gives_the_same_views() {
    let a = mapillary("mapillary/per_image", Heights::Provider);
    let b = mapillary("mapillary/per_image", Heights::Provider);
    assert!(a == b);
}

#[test]
fn synthetic_views_round_trip_through_the_mapillary_layout() {
    let city = generate(&small_city());
    let scene = scene_of(&city);
    let inputs = Inputs::new()
        .with("scene", slot(Artifact::Scene(scene)))
        .with("city", slot(Artifact::City(city)));
    let p = SynthViewsParams {
        size: (96, 64),
        max_views: 6,
        ..Default::default()
    };
    let set: ViewSet = SynthViews::run(&p, &inputs, &Ctx::new(&site(), &[])).unwrap();
    assert_eq!(set.views.len(), 6);
    let dir = tempfile::tempdir().unwrap();
    for (rel, bytes) in
        write_mapillary(&set, &site(), kodama_nodes::stage::process_parts()).unwrap()
    {
        std::fs::write(dir.path().join(rel), bytes).unwrap();
    }
    let back = read_mapillary(dir.path(), &site(), &options(Heights::Provider)).unwrap();
    assert!(back.dropped.is_empty());
    assert_eq!(back.views.len(), set.views.len());
    for (a, b) in back.views.iter().map(|v| &v.view).zip(&loaded(&set).views) {
        assert_eq!((&a.id, a.width, a.height), (&b.id, b.width, b.height));
        let off = (0..3)
            .map(|k| (a.pose.position[k] - b.pose.position[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(off < 0.01, "{}: {off} m", a.id);
        let deg = angle_deg(&a.pose.rotation, &b.pose.rotation);
        assert!(deg < 0.01, "{}: {deg} degrees", a.id);
        assert!(
            (a.intrinsics.fx - b.intrinsics.fx).abs() < 1e-9 && a.intrinsics.cx == b.intrinsics.cx
        );
        // JPEG: close, not exact.
        let mean = a
            .image
            .iter()
            .zip(b.image.iter())
            .map(|(x, y)| {
                (0..3)
                    .map(|c| (x[c] as f64 - y[c] as f64).abs())
                    .sum::<f64>()
            })
            .sum::<f64>()
            / (3 * a.image.len()) as f64;
        assert!(mean < 6.0, "{}: mean difference {mean}", a.id);
    }
}

// ------------------------------------------------------------------------------------------------
// Bad input: exit 2 (a user error) naming the file and the field.

/// `<id>.json` and `<id>.jpg` of the per-image fixture in a temporary folder, the JSON changed by
/// `edit`; `NAN` strings become bare NaN tokens, as Python's json writes them.
fn edited(id: &str, edit: impl FnOnce(&mut Value)) -> tempfile::TempDir {
    let src = fixtures("mapillary/per_image");
    let dir = tempfile::tempdir().unwrap();
    let mut v: Value =
        serde_json::from_str(&std::fs::read_to_string(src.join(format!("{id}.json"))).unwrap())
            .unwrap();
    edit(&mut v);
    let text = serde_json::to_string_pretty(&v)
        .unwrap()
        .replace("\"NAN\"", "NaN")
        .replace("\"INF\"", "Infinity");
    std::fs::write(dir.path().join(format!("{id}.json")), text).unwrap();
    std::fs::copy(
        src.join(format!("{id}.jpg")),
        dir.path().join(format!("{id}.jpg")),
    )
    .unwrap();
    dir
}

fn assert_bad(err: StageError, file: &str, field: &str) {
    assert!(err.is_user_error(), "{err}");
    match &err {
        StageError::BadInput { file: f, place, .. } => {
            assert!(f.ends_with(file), "{err}");
            assert!(place.contains(&format!("`{field}`")), "{err}");
        }
        other => panic!("expected BadInput, got {other}"),
    }
}

fn read_err(dir: &Path) -> StageError {
    read_mapillary(dir, &site(), &options(Heights::Provider)).unwrap_err()
}

#[test]
fn a_missing_image_names_the_json_and_the_image() {
    let dir = edited("1001", |_| {});
    std::fs::remove_file(dir.path().join("1001.jpg")).unwrap();
    let err = read_err(dir.path());
    assert!(err.to_string().contains("1001.jpg"), "{err}");
    assert_bad(err, "1001.json", "id");
}

#[test]
fn an_entity_without_a_position_is_refused() {
    let dir = edited("1001", |v| {
        let o = v.as_object_mut().unwrap();
        o.remove("computed_geometry");
        o.remove("geometry");
    });
    assert_bad(read_err(dir.path()), "1001.json", "computed_geometry");
    let dir = edited("1001", |v| {
        v["computed_geometry"] = serde_json::json!({"type": "LineString"})
    });
    assert_bad(read_err(dir.path()), "1001.json", "computed_geometry");
}

#[test]
fn an_unknown_camera_type_is_refused() {
    let dir = edited("1001", |v| v["camera_type"] = "cubemap".into());
    let err = read_err(dir.path());
    assert!(err.to_string().contains("cubemap"), "{err}");
    assert_bad(err, "1001.json", "camera_type");
}

#[test]
fn non_finite_numbers_are_refused_by_field() {
    let dir = edited("1001", |v| v["computed_rotation"][1] = "NAN".into());
    assert_bad(read_err(dir.path()), "1001.json", "computed_rotation");
    let dir = edited("1001", |v| v["width"] = "INF".into());
    assert_bad(read_err(dir.path()), "1001.json", "width");
    let dir = edited("1001", |v| v["computed_compass_angle"] = "NAN".into());
    assert_bad(read_err(dir.path()), "1001.json", "computed_compass_angle");
}

#[test]
fn zero_or_negative_sizes_are_refused() {
    for w in [0, -24] {
        let dir = edited("1001", |v| v["width"] = w.into());
        assert_bad(read_err(dir.path()), "1001.json", "width");
    }
    let dir = edited("1001", |v| v["height"] = 0.into());
    assert_bad(read_err(dir.path()), "1001.json", "height");
}

#[test]
fn a_zero_focal_length_is_refused() {
    let dir = edited("1001", |v| v["camera_parameters"][0] = 0.0.into());
    assert_bad(read_err(dir.path()), "1001.json", "camera_parameters");
    let dir = edited("1001", |v| {
        v.as_object_mut().unwrap().remove("camera_parameters");
    });
    assert_bad(read_err(dir.path()), "1001.json", "camera_parameters");
}

#[test]
fn other_bad_entities_name_their_field() {
    let dir = edited("1001", |v| v["exif_orientation"] = 5.into());
    assert_bad(read_err(dir.path()), "1001.json", "exif_orientation");
    let dir = edited("1001", |v| v["id"] = "../1001".into());
    assert_bad(read_err(dir.path()), "1001.json", "id");
    // An image whose aspect is not the entity's.
    let dir = edited("1001", |v| v["height"] = 24.into());
    let err = read_err(dir.path());
    assert!(
        matches!(&err, StageError::BadInput { file, .. } if file.ends_with("1001.jpg")),
        "{err}"
    );
    // trust_altitude with no altitude.
    let dir = edited("1001", |v| {
        let o = v.as_object_mut().unwrap();
        o.remove("computed_altitude");
        o.remove("altitude");
    });
    assert_bad(read_err(dir.path()), "1001.json", "computed_altitude");
    // A metadata.jsonl line names its line.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("metadata.jsonl"),
        "{\"id\": \"7\", \"width\": 4, \"height\": 4}\n",
    )
    .unwrap();
    let err = read_err(dir.path());
    assert_bad(err.clone(), "metadata.jsonl", "camera_parameters");
    assert!(err.to_string().contains("line 1 (image 7)"), "{err}");
    // An empty folder.
    let dir = tempfile::tempdir().unwrap();
    assert!(
        matches!(read_err(dir.path()), StageError::BadInput { place, .. } if place == "contents")
    );
}

#[test]
fn bad_panoramax_items_name_their_field() {
    let src = fixtures("panoramax/items");
    let item = |edit: &dyn Fn(&mut Value)| {
        let dir = tempfile::tempdir().unwrap();
        let mut v: Value =
            serde_json::from_str(&std::fs::read_to_string(src.join("a.json")).unwrap()).unwrap();
        edit(&mut v);
        std::fs::write(
            dir.path().join("a.json"),
            serde_json::to_string(&v).unwrap(),
        )
        .unwrap();
        std::fs::create_dir(dir.path().join("img")).unwrap();
        std::fs::copy(src.join("img/a_hd.jpg"), dir.path().join("img/a_hd.jpg")).unwrap();
        read_panoramax(dir.path(), &site(), &options(Heights::Provider)).unwrap_err()
    };
    let io = "properties.pers:interior_orientation";
    assert_bad(
        item(&|v| v["properties"]["pers:interior_orientation"]["field_of_view"] = Value::Null),
        "a.json",
        &format!("{io}.field_of_view"),
    );
    assert_bad(
        item(&|v| v["properties"]["pers:interior_orientation"]["field_of_view"] = 0.into()),
        "a.json",
        &format!("{io}.field_of_view"),
    );
    assert_bad(
        item(&|v| v["assets"]["hd"]["href"] = "../../secret.jpg".into()),
        "a.json",
        "assets.hd.href",
    );
    assert_bad(item(&|v| v["geometry"] = Value::Null), "a.json", "geometry");
    assert_bad(
        item(&|v| v["properties"]["view:azimuth"] = Value::Null),
        "a.json",
        "properties.view:azimuth",
    );
    assert_bad(
        item(&|v| v["assets"]["hd"]["href"] = "img/none.jpg".into()),
        "a.json",
        "assets",
    );
}

#[test]
fn cameras_off_the_terrain_are_dropped_with_a_warning() {
    let e = expected("mapillary");
    let mut terrain = terrain_plane(&e);
    // Keep x < 60 m: only 1001 (x = 50) stands on it.
    terrain.grid.width = 60;
    terrain.data = PodVec(
        terrain
            .data
            .chunks(200)
            .flat_map(|row| row[..60].to_vec())
            .collect(),
    );
    let heights = Heights::Terrain {
        terrain: &terrain,
        camera_height_m: 2.5,
    };
    let got = mapillary("mapillary/per_image", heights);
    assert_eq!(got.views.len(), 1);
    let reasons: Vec<(&str, bool)> = got
        .dropped
        .iter()
        .map(|d| (d.id.as_str(), d.reason == DropReason::NoTerrain))
        .collect();
    assert_eq!(
        reasons,
        [
            ("1002", true),
            ("1003", true),
            ("1004", true),
            ("1005", false),
            ("1006", true)
        ]
    );
    let w = got.warnings(10.0);
    assert!(
        w.iter()
            .any(|m| m.starts_with("4 image(s) dropped because they lie outside the terrain")),
        "{w:?}"
    );
}

/// With a store (as the stages give), each view is stored as it is read: the set is the same
/// views, a view at a time in memory.
#[test]
fn provider_views_stored_as_read_are_the_views_read_whole() {
    let folder = fixtures("mapillary/per_image");
    let whole = mapillary("mapillary/per_image", Heights::Provider);
    let parts = kodama_nodes::artifact::MemParts::new();
    let opts = options(Heights::Provider).storing_in(&parts);
    let read = read_mapillary(&folder, &site(), &opts).unwrap();
    assert!(
        read.views
            .iter()
            .all(|v| v.stored.is_some() && v.view.image.is_empty())
    );
    let set = read
        .finish(&folder, &opts, &kodama_nodes::stage::NoProgress, &parts)
        .unwrap();
    let loaded = set.with(&parts).load_all().unwrap();
    let expected: Vec<View> = whole.views.into_iter().map(|v| v.view).collect();
    assert!(!expected.is_empty());
    assert_eq!(loaded, expected);
}
