//! The registration on small scenes with known answers.

use super::labels::{Facade, Rendered, Seen, agreement, label};
use super::*;
use crate::artifact::Material;
use crate::artifact::ObjectClass;
use crate::artifact::{Instances, Intrinsics, PodVec, SceneObject};
use crate::geom::mesh_build::cuboid;
use crate::stage::NoProgress;

/// A camera at `position` looking level along `heading` (radians from east).
fn look(position: [f64; 3], heading: f64) -> Pose {
    let (s, c) = heading.sin_cos();
    let (right, down, fwd) = ([s, -c, 0.0], [0.0, 0.0, -1.0], [c, s, 0.0]);
    Pose {
        position,
        rotation: std::array::from_fn(|i| [right[i], down[i], fwd[i]]),
    }
}

fn object(id: &str, class: ObjectClass, mesh: crate::artifact::Mesh) -> SceneObject {
    SceneObject {
        id: id.into(),
        class,
        mesh,
    }
}

/// Ground, and buildings given as (centre, size).
fn scene(buildings: &[([f64; 2], [f64; 3])]) -> Scene {
    let mut objects = vec![object(
        "terrain",
        ObjectClass::Terrain,
        cuboid(
            [0.0, 0.0],
            [600.0, 600.0, 1.0],
            0.0,
            -1.0,
            Material::Concrete,
        ),
    )];
    for (k, (c, s)) in buildings.iter().enumerate() {
        objects.push(object(
            &format!("building-{k}"),
            ObjectClass::Building,
            cuboid(*c, *s, 0.0, 0.0, Material::Brick),
        ));
    }
    Scene { objects }
}

/// What a segmentation and a depth model would give from `pose`: one wall instance per
/// building, roofs, sky at infinite depth; reported at `reported`. Objects named `balcony-*`
/// or `drainpipe-*` are labelled by that class.
fn view(scene: &Scene, pose: Pose, reported: Pose) -> View {
    let (w, h) = (320u32, 240u32);
    let f = 160.0;
    let mut v = View {
        id: "v".into(),
        width: w,
        height: h,
        intrinsics: Intrinsics {
            fx: f,
            fy: f,
            cx: 160.0,
            cy: 120.0,
        },
        pose,
        captured_at: None,
        pose_source: None,
        distortion: None,
        image: PodVec(vec![[0; 3]; (w * h) as usize]),
        arch: None,
        clutter: None,
        material: None,
        depth: None,
        normal: None,
    };
    let rays = SceneRays::new(scene);
    let mut ids = vec![0u16; (w * h) as usize];
    let mut depth = vec![f32::INFINITY; (w * h) as usize];
    let mut classes = std::collections::BTreeMap::new();
    for y in 0..h {
        for x in 0..w {
            let (dir, norm) = v.pixel_ray(x as f64 + 0.5, y as f64 + 0.5);
            let o = pose.position.map(|c| c as f32);
            let Some(hit) = rays.cast(o, dir.map(|c| c as f32), 1e-3, 2000.0) else {
                continue;
            };
            let px = (y * w + x) as usize;
            depth[px] = (hit.t as f64 / norm) as f32;
            if scene.objects[hit.object].class == ObjectClass::Building {
                let roof = hit.normal[2] > 0.7;
                let id = (2 * hit.object + roof as usize) as u16;
                ids[px] = id;
                let name = &scene.objects[hit.object].id;
                let class = if let Some(c) = ["balcony", "drainpipe"]
                    .into_iter()
                    .find(|c| name.starts_with(c))
                {
                    c
                } else if roof {
                    "roof"
                } else {
                    "wall"
                };
                classes.insert(id, class.to_string());
            }
        }
    }
    v.arch = Some(Instances {
        ids: PodVec(ids),
        classes,
    });
    v.depth = Some(PodVec(depth));
    v.pose = reported;
    v
}

/// Two detached houses across the street from a camera at (0, 0, 2) looking north: 8 m and 9 m
/// wide, 7 m and 9 m tall, a 3.5 m gap between them.
/// `register_views` on `v` alone.
fn register_one(s: &Scene, v: &View, p: &RegistrationParams) -> Vec<(Pose, Refinement)> {
    let parts = crate::stage::MemParts::new();
    let set = crate::artifact::ViewSet::store(vec![v.clone()], Vec::new(), &parts)
        .unwrap()
        .unwrap();
    register_views(s, set.with(&parts), p, &NoProgress).unwrap()
}

fn two_houses() -> Scene {
    scene(&[
        ([-6.0, 12.0], [8.0, 6.0, 7.0]),
        ([6.0, 12.0], [9.0, 6.0, 9.0]),
    ])
}

fn moved(p: Pose, dx: f64, dy: f64, yaw_deg: f64) -> Pose {
    turned(&p, [dx, dy, yaw_deg.to_radians(), 0.0, 0.0, 0.0, 0.0])
}

/// The angle between the two poses' down axes (roll and pitch together), degrees.
fn tilt_between(a: &Pose, b: &Pose) -> f64 {
    let down = |p: &Pose| [p.rotation[0][1], p.rotation[1][1], p.rotation[2][1]];
    let (u, v) = (down(a), down(b));
    let dot = (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]).clamp(-1.0, 1.0);
    dot.acos().to_degrees()
}

/// A reported roll (the camera's horizon tilted) comes back when roll is searched: the two
/// houses' eaves, tilted in the view, are level again once the view is rolled; the default
/// search (roll off) leaves it.
#[test]
fn a_rolled_view_is_rolled_back() {
    let s = two_houses();
    let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
    for roll_deg in [0.8f64, -0.6] {
        let reported = turned(
            &truth,
            [0.2, -0.1, 0.0, 0.0, 0.0, 0.0, roll_deg.to_radians()],
        );
        assert!((tilt_between(&reported, &truth) - roll_deg.abs()).abs() < 1e-6);
        let v = view(&s, truth, reported);
        let with_roll = RegistrationParams {
            search_roll_deg: 1.0,
            ..Default::default()
        };
        let (pose, r) = register_one(&s, &v, &with_roll)[0];
        assert!(r.accepted, "{r:?}");
        let left = tilt_between(&pose, &truth);
        println!("rolled {roll_deg} deg: {left:.3} deg left, {r:?}");
        assert!(left <= 0.15, "rolled {roll_deg}: {left:.3} deg left, {r:?}");
        let (kept, _) = register_one(&s, &v, &RegistrationParams::default())[0];
        assert!(
            tilt_between(&kept, &truth) >= 0.5 * roll_deg.abs(),
            "without the roll search the tilt stays"
        );
    }
}

fn heading(p: &Pose) -> f64 {
    p.rotation[1][2].atan2(p.rotation[0][2])
}

#[test]
fn the_agreement_table_is_symmetric_where_it_should_be() {
    use Rendered as R;
    assert_eq!(agreement(Seen::Building, R::Building), 1);
    assert_eq!(agreement(Seen::Building, R::Sky), -1);
    assert_eq!(agreement(Seen::Ground, R::Building), -1);
    assert_eq!(agreement(Seen::Sky, R::Building), -1);
    // Beyond the terrain's edge the twin shows sky where the view sees far ground.
    assert_eq!(agreement(Seen::Sky, R::Ground), 0);
    assert_eq!(agreement(Seen::Ground, R::Sky), 0);
    // Clutter in the twin says nothing.
    assert_eq!(agreement(Seen::Building, R::Other), 0);
}

/// Two detached houses across the street: their ends and the gap between them pin the
/// camera along the street, their eaves and bases across it.
#[test]
fn a_view_of_two_houses_is_moved_back_to_where_it_was() {
    let s = two_houses();
    let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
    let p = RegistrationParams::default();
    for (dx, dy, dyaw) in [(0.6, -0.4, 1.0), (-0.9, 0.3, -1.5), (0.2, 0.8, 0.5)] {
        let v = view(&s, truth, moved(truth, dx, dy, dyaw));
        let out = register_one(&s, &v, &p);
        let (pose, r) = out[0];
        assert!(r.accepted, "{r:?}");
        let err = ((pose.position[0] - truth.position[0]).powi(2)
            + (pose.position[1] - truth.position[1]).powi(2))
        .sqrt();
        let yaw_err = (heading(&pose) - heading(&truth)).to_degrees();
        println!("two houses: moved ({dx}, {dy}, {dyaw}): {err:.3} m, {yaw_err:.2} deg, {r:?}");
        // 0.05-0.07 m and up to 0.25 deg while the search stopped at 6 cm steps.
        assert!(
            err <= 0.05,
            "moved ({dx}, {dy}): left {err:.3} m off, {r:?}"
        );
        assert!(
            yaw_err.abs() <= 0.15,
            "turned {dyaw}: left {yaw_err:.2} deg off"
        );
        assert!(r.after > r.before);
    }
}

/// Pixels of a balcony or a drainpipe, which stand off the wall where the twin has none, say
/// nothing about the pose: neither silhouette nor façade consensus (from one view to the next
/// a balcony lands on a different patch of the wall behind it). A window's pixels do.
#[test]
fn features_off_the_wall_say_nothing_about_the_pose() {
    let s = two_houses();
    let mut with = s.clone();
    with.objects.push(object(
        "balcony-0",
        ObjectClass::Building,
        cuboid([9.5, 8.4], [2.0, 1.2, 1.1], 0.0, 3.0, Material::Concrete),
    ));
    let pose = look([0.0, 0.0, 2.0], 90f64.to_radians());
    let mut v = view(&with, pose, pose);
    let arch = v.arch.as_mut().unwrap();
    let balcony = (0..arch.ids.len())
        .find(|&px| {
            arch.classes
                .get(&arch.ids[px])
                .is_some_and(|c| c == "balcony")
        })
        .expect("the balcony is in view");
    let wall = (0..arch.ids.len())
        .find(|&px| arch.classes.get(&arch.ids[px]).is_some_and(|c| c == "wall"))
        .unwrap();
    // The same wall pixel relabelled a window: a feature on the wall.
    let window_id = 1000;
    arch.classes.insert(window_id, "window".into());
    let wall_id = arch.ids[wall];
    arch.ids[wall] = window_id;
    let p = RegistrationParams::default();
    assert!(label(&v, balcony, &p).is_none());
    assert_eq!(
        label(&v, wall, &p),
        Some((Seen::Building, 0, Facade::Feature))
    );
    let counted = RegistrationParams {
        off_wall_classes: Vec::new(),
        ..Default::default()
    };
    assert_eq!(
        label(&v, balcony, &counted).map(|l| (l.0, l.2)),
        Some((Seen::Building, Facade::Feature))
    );
    v.arch.as_mut().unwrap().ids[wall] = wall_id;
    assert_eq!(
        label(&v, wall, &p),
        Some((Seen::Building, wall_id, Facade::Wall))
    );
}

/// One long wall filling the frame from edge to edge: nothing says where along it the
/// camera stood, so the metadata stands.
#[test]
fn a_view_of_one_endless_wall_keeps_its_metadata() {
    let s = scene(&[([0.0, 10.0], [400.0, 6.0, 40.0])]);
    let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
    let reported = moved(truth, 0.8, 0.0, 0.0);
    let v = view(&s, truth, reported);
    let out = register_one(&s, &v, &RegistrationParams::default());
    let (pose, r) = out[0];
    assert!(!r.accepted, "{r:?}");
    assert_eq!(pose, reported);
}

#[test]
fn a_window_of_zero_keeps_the_metadata() {
    let s = two_houses();
    let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
    let reported = moved(truth, 0.6, -0.4, 1.0);
    let v = view(&s, truth, reported);
    let off = RegistrationParams {
        search_m: 0.0,
        search_deg: 0.0,
        ..Default::default()
    };
    let out = register_one(&s, &v, &off);
    assert_eq!(out[0].0, reported);
    assert!(!out[0].1.accepted);
    // Heading alone: the position stays, the heading comes back.
    let yaw_only = RegistrationParams {
        search_m: 0.0,
        ..Default::default()
    };
    let v = view(&s, truth, moved(truth, 0.0, 0.0, 1.5));
    let (pose, r) = register_one(&s, &v, &yaw_only)[0];
    assert!(r.accepted, "{r:?}");
    assert_eq!(pose.position, truth.position);
    assert!((heading(&pose) - heading(&truth)).to_degrees().abs() <= 0.4);
}

#[test]
fn a_view_without_labels_is_left_alone_and_bad_knobs_are_refused() {
    let s = scene(&[([0.0, 12.0], [8.0, 6.0, 7.0])]);
    let truth = look([0.0, 0.0, 2.0], 90f64.to_radians());
    let mut v = view(&s, truth, moved(truth, 0.5, 0.0, 0.0));
    v.arch = None;
    let out = register_one(&s, &v, &RegistrationParams::default());
    assert!(!out[0].1.accepted);
    assert_eq!(out[0].0, v.pose);
    for bad in [
        RegistrationParams {
            search_m: f64::NAN,
            ..Default::default()
        },
        RegistrationParams {
            search_m: 50.0,
            ..Default::default()
        },
        RegistrationParams {
            search_deg: -1.0,
            ..Default::default()
        },
        RegistrationParams {
            samples: 0,
            ..Default::default()
        },
        RegistrationParams {
            samples: 100_000_000,
            ..Default::default()
        },
        RegistrationParams {
            prior_weight: f64::INFINITY,
            ..Default::default()
        },
        RegistrationParams {
            consensus_cell_m: 0.0,
            ..Default::default()
        },
        RegistrationParams {
            search_roll_deg: f64::NAN,
            ..Default::default()
        },
        RegistrationParams {
            off_wall_classes: vec!["balcony".into(); 65],
            ..Default::default()
        },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
    assert!(RegistrationParams::default().validate().is_ok());
}

#[test]
fn the_rays_of_a_pose_are_the_same_bits_on_every_code_path() {
    use super::labels::Sample;
    use super::twin::{Turn, rays_of, rays_of_any};
    let pose = Pose::from_angles([3.0, -2.0, 1.6], 37.0, 4.0, -1.5);
    let samples: Vec<Sample> = (0..97)
        .map(|k| {
            let (a, b) = (k as f64 * 0.013 - 0.6, (k % 11) as f64 * 0.05 - 0.25);
            let n = (1.0 + a * a + b * b).sqrt();
            Sample {
                dir: [a / n, 1.0 / n, b / n],
                seen: Seen::Building,
                wall: 0,
                facade: Facade::None,
                right: u32::MAX,
                down: u32::MAX,
                tile: k / 8,
            }
        })
        .collect();
    // Candidates that take every branch: no turn, each turn alone, all of them with a zoom.
    let poses: Vec<([f64; 3], Turn)> = [
        [0.0; 7],
        [0.1, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0],
        [0.0, -0.2, 0.0, 0.05, 0.004, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.003],
        [0.03, 0.02, -0.02, -0.01, 0.002, 0.0065, 0.001],
    ]
    .iter()
    .map(|c| ([3.0 + c[0], -2.0 + c[1], 1.6 + c[3]], Turn::of(&pose, *c)))
    .collect();
    let (mut fast, mut plain) = (Vec::new(), Vec::new());
    rays_of(&samples, &poses, &mut fast);
    rays_of_any(&samples, &poses, &mut plain);
    assert_eq!(fast.len(), samples.len() * poses.len());
    let bits = |r: &[([f32; 3], [f32; 3])]| -> Vec<[u32; 6]> {
        r.iter()
            .map(|(o, d)| [o[0], o[1], o[2], d[0], d[1], d[2]].map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&fast), bits(&plain));
}
