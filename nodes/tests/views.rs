//! Street views: the synthetic renderer checked against the terrain it looks at, the on-disk
//! layout round trip, the error knobs, and bad view sets.

mod common;
use common::*;

use std::sync::Arc;

use kodama_nodes::artifact::height_at;
use kodama_nodes::artifact::{City, RMSNET_CLASSES, Scene};
use kodama_nodes::io::views_io::{read_viewset, write_viewset};
use kodama_nodes::stage::{Slot, process_parts};
use kodama_nodes::synth::synth_city::generate;
use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
use kodama_nodes::{Artifact, Ctx, Inputs, Stage};

fn city_and_scene() -> (City, Scene) {
    let city = generate(&small_city());
    let scene = scene_of(&city);
    (city, scene)
}

fn render(p: &SynthViewsParams) -> (City, Loaded) {
    let (city, scene) = city_and_scene();
    let inputs = Inputs::new()
        .with("scene", Slot::One(Arc::new(Artifact::Scene(scene))))
        .with("city", Slot::One(Arc::new(Artifact::City(city.clone()))));
    (
        city.clone(),
        loaded(&SynthViews::run(p, &inputs, &Ctx::new(&site(), &[])).unwrap()),
    )
}

fn small(p: SynthViewsParams) -> SynthViewsParams {
    SynthViewsParams {
        size: (160, 120),
        max_views: 6,
        ..p
    }
}

#[test]
fn ground_pixels_back_project_onto_the_terrain() {
    let (city, set) = render(&small(SynthViewsParams::exact()));
    assert_eq!(set.views.len(), 6);
    // The synthetic terrain is medium dry ground, which a material model calls gravel.
    let ground = RMSNET_CLASSES.iter().position(|c| *c == "gravel").unwrap() as u8;
    let mut checked = 0;
    for v in &set.views {
        let (depth, material) = (v.depth.as_ref().unwrap(), v.material.as_ref().unwrap());
        for (i, (&d, &m)) in depth.iter().zip(material.iter()).enumerate() {
            if m != ground || !d.is_finite() {
                continue;
            }
            let (u, w) = (
                (i as u32 % v.width) as f64 + 0.5,
                (i as u32 / v.width) as f64 + 0.5,
            );
            let cam = [
                (u - v.intrinsics.cx) / v.intrinsics.fx * d as f64,
                (w - v.intrinsics.cy) / v.intrinsics.fy * d as f64,
                d as f64,
            ];
            let r = v.pose.to_site(cam);
            let (x, y, z) = (
                v.pose.position[0] + r[0],
                v.pose.position[1] + r[1],
                v.pose.position[2] + r[2],
            );
            // The terrain mesh interpolates the function linearly between 2 m vertices.
            assert!(
                (z - height_at(&city.terrain, x, y)).abs() < 0.08,
                "{} pixel {i}: z {z} vs terrain {}",
                v.id,
                height_at(&city.terrain, x, y)
            );
            checked += 1;
        }
    }
    assert!(checked > 5000, "{checked}");
}

#[test]
fn views_round_trip_through_the_on_disk_layout() {
    let (_, set) = render(&small(SynthViewsParams::default()));
    let files = write_viewset(&set.set, process_parts()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (rel, bytes) in files {
        let f = dir.path().join(rel);
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
        std::fs::write(f, bytes).unwrap();
    }
    let back =
        loaded(&read_viewset(&dir.path().join("views.json"), &site(), process_parts()).unwrap());
    assert_eq!(back.material_classes, set.material_classes);
    assert_eq!(back.views.len(), set.views.len());
    for (a, b) in back.views.iter().zip(&set.views) {
        assert_eq!(
            (&a.id, a.width, a.height, &a.intrinsics),
            (&b.id, b.width, b.height, &b.intrinsics)
        );
        assert!(a.image == b.image, "{}: image", a.id);
        assert!(a.material == b.material, "{}: material", a.id);
        assert!(a.arch == b.arch, "{}: arch instances", a.id);
        assert!(a.clutter == b.clutter, "{}: clutter instances", a.id);
        assert!(
            a.depth
                .as_ref()
                .unwrap()
                .iter()
                .zip(b.depth.as_ref().unwrap().iter())
                .all(|(x, y)| x == y)
        );
        assert_eq!(a.normal, b.normal);
        for r in 0..3 {
            for c in 0..3 {
                assert!(
                    (a.pose.rotation[r][c] - b.pose.rotation[r][c]).abs() < 1e-9,
                    "rotation through the quaternion"
                );
            }
        }
        assert_eq!(a.pose.position, b.pose.position);
    }
}

#[test]
fn error_knobs_act() {
    let exact = render(&small(SynthViewsParams::exact())).1;
    let missed = render(&small(SynthViewsParams {
        instance_miss: 1.0,
        instance_spurious: 0.0,
        ..Default::default()
    }))
    .1;
    assert!(
        exact
            .views
            .iter()
            .any(|v| v.arch.as_ref().unwrap().ids.iter().any(|&i| i > 0))
    );
    assert!(
        missed
            .views
            .iter()
            .all(|v| v.arch.as_ref().unwrap().ids.iter().all(|&i| i == 0))
    );
    let relative = render(&small(SynthViewsParams {
        depth_scale: 0.5,
        ..SynthViewsParams::exact()
    }))
    .1;
    let (d0, d1) = (
        exact.views[0].depth.as_ref().unwrap(),
        relative.views[0].depth.as_ref().unwrap(),
    );
    assert!(
        d0.iter()
            .zip(d1.iter())
            .filter(|(a, _)| a.is_finite())
            .all(|(a, b)| (a * 0.5 - b).abs() <= 1e-4 * a)
    );
    let noisy = render(&small(SynthViewsParams {
        material_error: 0.5,
        ..SynthViewsParams::exact()
    }))
    .1;
    let differ = noisy
        .views
        .iter()
        .zip(&exact.views)
        .map(|(a, b)| {
            a.material
                .as_ref()
                .unwrap()
                .iter()
                .zip(b.material.as_ref().unwrap().iter())
                .filter(|(x, y)| x != y)
                .count()
        })
        .sum::<usize>();
    assert!(differ > 0);
}

#[test]
fn a_view_pointing_at_a_missing_image_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("views.json");
    std::fs::write(&json, r#"[{"id": "a", "image": "img/a.jpg", "width": 4, "height": 3, "intrinsics": {"hfov_deg": 90}, "pose": {"x": 0, "y": 0, "z": 2}, "orientation": {"heading_deg": 0}}]"#).unwrap();
    let e = read_viewset(&json, &site(), process_parts()).unwrap_err();
    assert!(
        e.to_string()
            .contains("views.json: view \"a\", image: the image")
            && e.to_string().contains("img/a.jpg does not exist"),
        "{e}"
    );
    std::fs::write(&json, r#"[{"id": "a", "image": "img/a.jpg", "width": 4, "height": 3, "pose": {"x": 0, "y": 0, "z": 2}, "orientation": {"heading_deg": 0}}]"#).unwrap();
    assert!(
        read_viewset(&json, &site(), process_parts())
            .unwrap_err()
            .to_string()
            .contains("intrinsics")
    );
}

#[test]
fn facade_features_are_instances_and_metadata_noise_moves_only_the_reported_pose() {
    let exact = render(&small(SynthViewsParams {
        max_views: 12,
        ..SynthViewsParams::exact()
    }))
    .1;
    let classes: std::collections::BTreeSet<&str> = exact
        .views
        .iter()
        .flat_map(|v| {
            v.arch
                .as_ref()
                .unwrap()
                .classes
                .values()
                .map(String::as_str)
        })
        .collect();
    for c in ["wall", "window", "door"] {
        assert!(classes.contains(c), "no {c} instance in {classes:?}");
    }
    assert_eq!(exact.material_classes.len(), 20);
    let noisy = render(&small(SynthViewsParams {
        max_views: 12,
        pose_noise_m: 1.0,
        heading_noise_deg: 2.0,
        height_noise_m: 0.5,
        pitch_noise_deg: 0.5,
        roll_noise_deg: 0.5,
        focal_noise: 0.02,
        depth_scale: 0.8,
        depth_offset_m: 1.5,
        ..SynthViewsParams::exact()
    }))
    .1;
    let mut moved = 0.0;
    for (a, b) in exact.views.iter().zip(&noisy.views) {
        // Rendered from the same true pose: the same pixels; only the metadata differs.
        assert!(a.image == b.image && a.arch == b.arch, "{}", a.id);
        assert!(a.intrinsics.cx == b.intrinsics.cx && a.intrinsics.fx != b.intrinsics.fx);
        moved += (a.pose.position[0] - b.pose.position[0])
            .hypot(a.pose.position[1] - b.pose.position[1]);
        // Depth d' = 0.8 d + 1.5, the affine bias a calibration must undo.
        for (x, y) in a
            .depth
            .as_ref()
            .unwrap()
            .iter()
            .zip(b.depth.as_ref().unwrap().iter())
        {
            if x.is_finite() {
                assert!((0.8 * x + 1.5 - y).abs() <= 1e-3 * (1.0 + x), "{x} -> {y}");
            }
        }
    }
    let mean = moved / exact.views.len() as f64;
    assert!(
        mean > 0.3 && mean < 3.0,
        "mean position error {mean} m for sigma 1 m"
    );
}

/// Provider views carry poses and pixels only; the outputs of models run on them come from a
/// folder and are attached by view id. A view without files keeps nothing (and is warned
/// about), a file of the wrong size is refused by name, a folder with no outputs at all is
/// refused.
#[test]
fn model_outputs_attach_to_provider_views_by_id() {
    use kodama_nodes::stages::ingest::read_view_outputs::{ReadViewOutputs, ReadViewOutputsParams};
    let (_, set) = render(&small(SynthViewsParams::default()));
    let dir = tempfile::tempdir().unwrap();
    for (rel, bytes) in write_viewset(&set.set, process_parts()).unwrap() {
        // The images and views.json stay with the provider; only the model outputs are here.
        if rel.starts_with("img/") || rel == "views.json" {
            continue;
        }
        let f = dir.path().join(rel);
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
        std::fs::write(f, bytes).unwrap();
    }
    let mut bare = set.views.clone();
    for v in &mut bare {
        (v.arch, v.clutter, v.material, v.depth, v.normal) = (None, None, None, None, None);
    }
    let bare = stored(bare, Vec::new());
    let last = &set.views.last().unwrap().id;
    for kind in ["arch", "clutter", "material", "depth", "normal"] {
        for ext in ["png", "json", "exr"] {
            let _ = std::fs::remove_file(dir.path().join(kind).join(format!("{last}.{ext}")));
        }
    }
    let params = |require_all: bool| ReadViewOutputsParams {
        path: "outputs".into(),
        material_classes: RMSNET_CLASSES.iter().map(|s| s.to_string()).collect(),
        require_all,
    };
    let run = |p: &ReadViewOutputsParams, d: &std::path::Path| {
        let files = [d.to_path_buf()];
        ReadViewOutputs::run(
            p,
            &Inputs::new().with("views", Slot::One(Arc::new(Artifact::Views(bare.clone())))),
            &Ctx::new(&site(), &files),
        )
    };
    let got = loaded(&run(&params(false), dir.path()).unwrap());
    assert_eq!(got.material_classes, set.material_classes);
    let n = set.views.len();
    for (a, b) in got.views.iter().zip(&set.views).take(n - 1) {
        assert!(a.arch == b.arch && a.clutter == b.clutter, "{}", a.id);
        assert!(a.material == b.material && a.normal == b.normal, "{}", a.id);
        assert!(a.depth.is_some() && a.image == b.image && a.pose == b.pose);
    }
    let l = got.views.last().unwrap();
    assert!(l.arch.is_none() && l.material.is_none() && l.depth.is_none());
    let e = run(&params(true), dir.path()).unwrap_err().to_string();
    assert!(
        e.contains("1 view(s) have no model output") && e.contains(last.as_str()),
        "{e}"
    );

    // A material map of the wrong size is refused with its path.
    let first = &set.views[0].id;
    let tiny = image::GrayImage::new(3, 2);
    tiny.save(dir.path().join("material").join(format!("{first}.png")))
        .unwrap();
    let e = run(&params(false), dir.path()).unwrap_err().to_string();
    assert!(
        e.contains(&format!("material/{first}.png")) && e.contains("3 x 2 pixels"),
        "{e}"
    );
    let empty = tempfile::tempdir().unwrap();
    let e = run(&params(false), empty.path()).unwrap_err().to_string();
    assert!(e.contains("no model output for any of the"), "{e}");
}

/// The default sensor errors, measured against the same views rendered exactly: the depth's
/// error left after the per-image affine fit a calibration makes (AbsRel), the normals' median
/// angular error, the share of labelled pixels whose instance class differs; and the same bytes
/// at one and two threads.
#[test]
fn default_sensor_errors_are_at_the_levels_of_real_models() {
    let p = small(SynthViewsParams {
        max_views: 12,
        ..Default::default()
    });
    let noisy = render(&p).1;
    let exact = render(&small(SynthViewsParams {
        max_views: 12,
        ..SynthViewsParams::exact()
    }))
    .1;
    let (mut abs_rel, mut angles, mut mask_diff) = (Vec::new(), Vec::new(), Vec::new());
    for (a, b) in noisy.views.iter().zip(&exact.views) {
        let (da, db) = (a.depth.as_ref().unwrap(), b.depth.as_ref().unwrap());
        let pairs: Vec<(f64, f64)> = db
            .iter()
            .zip(da.iter())
            .filter(|(t, r)| t.is_finite() && r.is_finite())
            .map(|(&t, &r)| (t as f64, r as f64))
            .collect();
        if pairs.len() < 100 {
            continue;
        }
        // Least squares r = s t + o, then AbsRel of (r - o) / s against t.
        let n = pairs.len() as f64;
        let (mt, mr) = (
            pairs.iter().map(|p| p.0).sum::<f64>() / n,
            pairs.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let cov: f64 = pairs.iter().map(|p| (p.0 - mt) * (p.1 - mr)).sum();
        let var: f64 = pairs.iter().map(|p| (p.0 - mt).powi(2)).sum();
        let s = cov / var;
        let o = mr - s * mt;
        abs_rel.push(
            pairs
                .iter()
                .map(|p| ((p.1 - o) / s - p.0).abs() / p.0)
                .sum::<f64>()
                / n,
        );
        for (x, y) in a
            .normal
            .as_ref()
            .unwrap()
            .iter()
            .zip(b.normal.as_ref().unwrap().iter())
        {
            if *y != [0.0; 3] {
                let d = (x[0] * y[0] + x[1] * y[1] + x[2] * y[2]).clamp(-1.0, 1.0);
                angles.push((d as f64).acos().to_degrees());
            }
        }
        let (ia, ib) = (a.arch.as_ref().unwrap(), b.arch.as_ref().unwrap());
        let class = |inst: &kodama_nodes::artifact::Instances, i: usize| {
            inst.classes.get(&inst.ids[i]).cloned()
        };
        let labelled: Vec<usize> = (0..ib.ids.len()).filter(|&i| ib.ids[i] != 0).collect();
        let differ = labelled
            .iter()
            .filter(|&&i| class(ia, i) != class(ib, i))
            .count();
        mask_diff.push(differ as f64 / labelled.len().max(1) as f64);
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (ar, ang, md) = (med(&mut abs_rel), med(&mut angles), med(&mut mask_diff));
    println!(
        "default sensor errors: depth AbsRel after the affine fit, median over views {ar:.3}; normals median angular error {ang:.1} deg; labelled pixels of another class, median {:.1} %",
        100.0 * md
    );
    assert!(ar > 0.02 && ar < 0.15, "{ar}");
    assert!(ang > 8.0 && ang < 18.0, "{ang}");
    assert!(md > 0.005 && md < 0.3, "{md}");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| render(&p).1);
    assert!(one == noisy, "views differ between thread counts");
}

/// In a tiled run, a tile renders the untiled run's stations whose cameras stand in its window:
/// the same views, ids and pixels, and no other.
#[test]
fn a_window_renders_the_untiled_views_standing_in_it() {
    let p = SynthViewsParams {
        size: (96, 72),
        max_views: 40,
        ..SynthViewsParams::default()
    };
    let (city, scene) = city_and_scene();
    let inputs = Inputs::new()
        .with("scene", Slot::One(Arc::new(Artifact::Scene(scene))))
        .with("city", Slot::One(Arc::new(Artifact::City(city))));
    let site = site();
    let all = loaded(&SynthViews::run(&p, &inputs, &Ctx::new(&site, &[])).unwrap());
    // The window's edge in the widest gap between cameras: the reported poses carry noise, the
    // window is applied to the true stations.
    let mut xs: Vec<f64> = all.views.iter().map(|v| v.pose.position[0]).collect();
    xs.sort_by(f64::total_cmp);
    let gap = (1..xs.len())
        .max_by(|&a, &b| (xs[a] - xs[a - 1]).total_cmp(&(xs[b] - xs[b - 1])))
        .unwrap();
    assert!(xs[gap] - xs[gap - 1] > 5.0, "{xs:?}");
    let mid = (xs[gap] + xs[gap - 1]) / 2.0;
    let window = kodama_nodes::Window {
        min: (-1e4, -1e4),
        max: (mid, 1e4),
    };
    let ctx = Ctx::new(&site, &[]).with_window(window);
    let tile = loaded(&SynthViews::run(&p, &inputs, &ctx).unwrap());
    let want: Vec<_> = all
        .views
        .iter()
        .zip(&all.set.views)
        .filter(|(v, _)| v.pose.position[0] < mid)
        .collect();
    assert!(
        !want.is_empty() && want.len() < all.views.len(),
        "{} of {}",
        want.len(),
        all.views.len()
    );
    assert_eq!(tile.views.len(), want.len());
    for ((got, head), (v, untiled_head)) in tile.views.iter().zip(&tile.set.views).zip(want) {
        assert_eq!(got.id, v.id);
        assert_eq!(got.pose, v.pose, "{}", v.id);
        assert_eq!(head.pixels, untiled_head.pixels, "{}: pixels differ", v.id);
    }
}
