//! Synthetic street-level views of a scene with the model outputs a real pipeline would run on
//! them (architectural and clutter instances, material classes, depth, normals), rendered from
//! the ground truth and then degraded by error knobs, so the relief, material and clutter stages
//! can be scored against what they should have found.

use std::collections::HashMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::height_at;
use crate::artifact::{
    ArtifactType, City, Facades, FeatureKind, Instances, Intrinsics, ObjectClass, PodVec, Pose,
    RMSNET_CLASSES, Scene, View, ViewSet,
};
use crate::geom::raycast::{Hit, SceneRays};
use crate::io::export::material_color;
use crate::rng::{gaussian, mix, unit};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

pub mod errors;

use errors::{DepthErrors, MaskErrors, degrade_depth, degrade_instances, degrade_normals};

/// Params of [`SynthViews`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthViewsParams {
    /// Distance between camera stations along each street, metres. Default 40.
    pub spacing_m: f64,
    /// At most this many views (stations are taken in street order). Default 24.
    pub max_views: u32,
    /// Image size, pixels. Default (640, 480).
    pub size: (u32, u32),
    /// Horizontal field of view, degrees. Default 90.
    pub hfov_deg: f64,
    /// Camera height above the road, metres. Default 2.5.
    pub camera_height_m: f64,
    /// Upward tilt, degrees. Default 8.
    pub pitch_deg: f64,
    /// Relative standard deviation of the depth model's per-pixel noise at near range (it grows
    /// with depth, see `depth_far_m`). Default 0.02.
    pub depth_noise: f64,
    /// Depth is reported as `depth_scale` x depth + `depth_offset_m` (with the errors below): the
    /// affine bias of monocular depth before calibration; each image draws its own scale and
    /// offset about these (`depth_scale_jitter`, `depth_offset_jitter_m`). Default 1 (metric).
    pub depth_scale: f64,
    /// See `depth_scale`. Default 0.
    pub depth_offset_m: f64,
    /// Relative standard deviation of each image's own depth scale about `depth_scale` (a
    /// metric model's per-image scale error; an affine-invariant one's is arbitrary). Default 0.1.
    pub depth_scale_jitter: f64,
    /// Standard deviation of each image's own depth offset about `depth_offset_m`, metres.
    /// Default 0.5.
    pub depth_offset_jitter_m: f64,
    /// RMS of a smooth relative warp of each image's depth (five low-order 2D cosine terms with
    /// seeded weights) at near range. Default 0.04.
    pub depth_warp: f64,
    /// The depth model's relative errors (noise and warp) grow as 1 + depth / `depth_far_m`:
    /// at 40 m twice what they are near the camera. 0 turns the growth off. Default 40.
    pub depth_far_m: f64,
    /// Radius, pixels, within which depths mix across a depth discontinuity (edge bleeding, the
    /// "flying pixels" between a façade and the sky or a façade behind). Default 2.
    pub depth_edge_px: u32,
    /// Median angular error of the reported normals, degrees (half of the variance smooth over
    /// the image, half per pixel). Default 12.
    pub normal_noise_deg: f64,
    /// Radius, pixels, over which normals are averaged across a normal or depth edge. Default 2.
    pub normal_edge_px: u32,
    /// Standard deviation of the smooth displacement of every instance contour, pixels (dilation
    /// here, erosion there, along the contour). Default 1.5.
    pub instance_boundary_px: f64,
    /// Spurious façade instances (a "window" on a bare wall) per true façade-feature instance in
    /// the view. Default 0.05.
    pub instance_spurious: f64,
    /// Probability that two adjacent instances of one class on one building (two windows one
    /// pier apart) come out as one instance spanning both and the wall between. Default 0.1.
    pub instance_merge: f64,
    /// Probability that an instance is reported as a confusable class (window <-> door, balcony
    /// or drainpipe -> window, pole <-> sign, car <-> shelter). Default 0.05.
    pub class_confusion: f64,
    /// Standard deviation of the reported camera position, horizontally, metres (the views are
    /// rendered from the true pose; the metadata is off, as real metadata is). Default 0.5.
    pub pose_noise_m: f64,
    /// Standard deviation of the reported camera height, metres. Default 0.5.
    pub height_noise_m: f64,
    /// Standard deviation of the reported heading, degrees. Default 1.
    pub heading_noise_deg: f64,
    /// Standard deviation of the reported pitch, degrees. Default 0.5.
    pub pitch_noise_deg: f64,
    /// Standard deviation of the reported roll, degrees. Default 0.5.
    pub roll_noise_deg: f64,
    /// Relative standard deviation of the reported focal length (the views are rendered with the
    /// true one). Default 0.02.
    pub focal_noise: f64,
    /// Probability that an object's material is reported as another RMSNet class. Default 0.05.
    pub material_error: f64,
    /// Probability that an instance is missed (a façade feature's pixels go to its wall, any
    /// other instance's get id 0). Default 0.1.
    pub instance_miss: f64,
    /// Seed. Default 7.
    pub seed: u64,
}

impl Default for SynthViewsParams {
    fn default() -> Self {
        SynthViewsParams {
            spacing_m: 40.0,
            max_views: 24,
            size: (640, 480),
            hfov_deg: 90.0,
            camera_height_m: 2.5,
            pitch_deg: 8.0,
            depth_noise: 0.02,
            depth_scale: 1.0,
            depth_offset_m: 0.0,
            depth_scale_jitter: 0.1,
            depth_offset_jitter_m: 0.5,
            depth_warp: 0.04,
            depth_far_m: 40.0,
            depth_edge_px: 2,
            normal_noise_deg: 12.0,
            normal_edge_px: 2,
            instance_boundary_px: 1.5,
            instance_spurious: 0.05,
            instance_merge: 0.1,
            class_confusion: 0.05,
            pose_noise_m: 0.5,
            height_noise_m: 0.5,
            heading_noise_deg: 1.0,
            pitch_noise_deg: 0.5,
            roll_noise_deg: 0.5,
            focal_noise: 0.02,
            material_error: 0.05,
            instance_miss: 0.1,
            seed: 7,
        }
    }
}

impl SynthViewsParams {
    /// The same views with their true poses and focal lengths reported (every other sensor
    /// error kept): where the views were taken, to judge a registration against.
    pub fn with_true_poses(self) -> SynthViewsParams {
        SynthViewsParams {
            pose_noise_m: 0.0,
            height_noise_m: 0.0,
            heading_noise_deg: 0.0,
            pitch_noise_deg: 0.0,
            roll_noise_deg: 0.0,
            focal_noise: 0.0,
            ..self
        }
    }

    /// Views with every error off: exact depth, normals, masks, materials, poses and focal
    /// length (an oracle, for tests that isolate one stage's own error).
    pub fn exact() -> Self {
        SynthViewsParams {
            depth_noise: 0.0,
            depth_scale_jitter: 0.0,
            depth_offset_jitter_m: 0.0,
            depth_warp: 0.0,
            depth_far_m: 0.0,
            depth_edge_px: 0,
            normal_noise_deg: 0.0,
            normal_edge_px: 0,
            instance_boundary_px: 0.0,
            instance_spurious: 0.0,
            instance_merge: 0.0,
            class_confusion: 0.0,
            material_error: 0.0,
            instance_miss: 0.0,
            ..Default::default()
        }
        .with_true_poses()
    }
}

/// Renders street views of a city's truth scene.
pub struct SynthViews;

/// The most pixels a synthetic view set may hold over all its views (`size` x `max_views`).
pub const MAX_SET_PIXELS: u64 = 1 << 35;

impl Stage for SynthViews {
    const KIND: &'static str = "SynthViews";
    // 3: sensor errors after real models' and metadata's (issue 51): per-image depth scale and
    // offset, warp, far-range growth and edge bleeding; normal noise and edge blur; mask
    // boundaries, spurious, merged and confused instances; height, pitch, roll and focal noise.
    // 4: the views' pixels are parts (one per view), the set holds their heads.
    const VERSION: u32 = 4;
    const DOC: &'static str = "synthetic street views with instance, material, depth and normal maps (with error knobs), Sec. 4.2";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("scene", ArtifactType::Scene, "the ground-truth scene"),
        InputSpec::one(
            "city",
            ArtifactType::City,
            "the city (for its streets and terrain)",
        ),
    ];
    type Params = SynthViewsParams;
    type Output = ViewSet;
    // A tile renders the stations whose cameras stand in its window.
    const WINDOWED: bool = true;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        let prob = |v: f64| (0.0..=1.0).contains(&v);
        if !(p.spacing_m >= 1.0) {
            return Err(ParamError::new("spacing_m", "expected at least 1 m"));
        }
        if !(p.size.0 >= 16 && p.size.1 >= 16 && p.size.0 <= 8192 && p.size.1 <= 8192) {
            return Err(ParamError::new("size", "expected 16..8192 pixels each way"));
        }
        if !(p.hfov_deg > 1.0 && p.hfov_deg < 170.0) {
            return Err(ParamError::new(
                "hfov_deg",
                "expected a field of view in (1, 170) degrees",
            ));
        }
        if !(p.depth_scale > 0.0 && p.depth_scale.is_finite()) {
            return Err(ParamError::new("depth_scale", "expected a positive factor"));
        }
        for (name, v) in [
            ("depth_offset_m", p.depth_offset_m.abs()),
            ("pose_noise_m", p.pose_noise_m),
            ("heading_noise_deg", p.heading_noise_deg),
            ("height_noise_m", p.height_noise_m),
            ("pitch_noise_deg", p.pitch_noise_deg),
            ("roll_noise_deg", p.roll_noise_deg),
            ("depth_offset_jitter_m", p.depth_offset_jitter_m),
            ("depth_far_m", p.depth_far_m),
            ("normal_noise_deg", p.normal_noise_deg),
            ("instance_boundary_px", p.instance_boundary_px),
        ] {
            if !(v >= 0.0 && v <= 1000.0) {
                return Err(ParamError::new(name, "expected a finite value within 1000"));
            }
        }
        if p.depth_edge_px > 16 || p.normal_edge_px > 16 {
            return Err(ParamError::new(
                "depth_edge_px",
                "expected edge radii of at most 16 pixels",
            ));
        }
        if p.max_views > 100_000 {
            return Err(ParamError::new(
                "max_views",
                "expected at most 100000 views",
            ));
        }
        // Each factor within its range can still multiply past any disk: the set as a whole.
        let pixels = p.size.0 as u64 * p.size.1 as u64 * p.max_views as u64;
        if pixels > MAX_SET_PIXELS {
            return Err(ParamError::new(
                "max_views",
                format!(
                    "{} views of {} x {} pixels make {pixels} pixels; a view set holds at most \
                     {MAX_SET_PIXELS} (2^35, some 800 GB of parts before compression): lower \
                     max_views or size",
                    p.max_views, p.size.0, p.size.1
                ),
            ));
        }
        for (name, v) in [
            ("depth_noise", p.depth_noise),
            ("material_error", p.material_error),
            ("instance_miss", p.instance_miss),
            ("depth_scale_jitter", p.depth_scale_jitter),
            ("depth_warp", p.depth_warp),
            ("instance_spurious", p.instance_spurious),
            ("instance_merge", p.instance_merge),
            ("class_confusion", p.class_confusion),
            ("focal_noise", p.focal_noise),
        ] {
            if !prob(v) {
                return Err(ParamError::new(name, "expected a value in [0, 1]"));
            }
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ViewSet, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let city: &City = inputs.one("city")?;
        let rays = SceneRays::new(scene);
        // In a tiled run, the stations are the untiled run's (numbered as there, which seeds
        // each view's errors) whose cameras stand in the window.
        let poses: Vec<(usize, Pose)> = stations(city, p)
            .into_iter()
            .enumerate()
            .filter(|(_, pose)| {
                ctx.window
                    .is_none_or(|w| w.contains(pose.position[0], pose.position[1]))
            })
            .collect();
        ctx.progress.set_total(poses.len() as u64);
        let material_classes: Vec<String> = RMSNET_CLASSES.iter().map(|s| s.to_string()).collect();
        let buildings: HashMap<&str, Facades> = city
            .buildings
            .iter()
            .map(|b| (b.id.as_str(), b.facades()))
            .collect();
        let n_classes = material_classes.len();
        // Each view is stored as soon as it is rendered: a few in memory at a time.
        let views = poses
            .par_iter()
            .with_max_len(1)
            .map(|(k, pose)| {
                let (k, pose) = (*k, pose);
                let mut v = render(scene, &rays, &buildings, p, k, *pose);
                v.pose = reported_pose(&v.pose, p, k);
                v.intrinsics = reported_intrinsics(&v.intrinsics, p, k);
                ctx.progress.advance(1);
                let id = v.id.clone();
                v.store(n_classes, ctx.parts)?.map_err(|(what, m)| {
                    StageError::Failed(format!("rendered view {id:?}: {what}: expected {m}"))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(ViewSet {
            views,
            material_classes,
        })
    }
}

/// Camera poses: stations every `spacing_m` along each street, one camera looking to each side
/// (30 degrees forward of perpendicular).
fn stations(city: &City, p: &SynthViewsParams) -> Vec<Pose> {
    let mut out = Vec::new();
    for s in &city.streets {
        let (dx, dy) = (s.b[0] - s.a[0], s.b[1] - s.a[1]);
        let len = dx.hypot(dy);
        let along = dx.atan2(dy).to_degrees(); // heading of the street direction
        let mut d = p.spacing_m / 2.0;
        while d < len - 1.0 && out.len() < p.max_views as usize {
            let (x, y) = (s.a[0] + dx * d / len, s.a[1] + dy * d / len);
            let z = height_at(&city.terrain, x, y) + p.camera_height_m;
            for side in [-60.0, 60.0] {
                if out.len() < p.max_views as usize {
                    out.push(Pose::from_angles([x, y, z], along + side, p.pitch_deg, 0.0));
                }
            }
            d += p.spacing_m;
        }
    }
    out
}

/// The pose the metadata reports: the true one with noise in all six degrees of freedom
/// (east, north, height; heading about the site's vertical, pitch and roll about the camera's
/// right and forward axes).
fn reported_pose(truth: &Pose, p: &SynthViewsParams, k: usize) -> Pose {
    let s = mix(p.seed ^ mix(k as u64 ^ 0x9051_7E00));
    let g = |j: u64| gaussian(mix(s ^ j));
    let (dx, dy) = (p.pose_noise_m * g(1), p.pose_noise_m * g(2));
    let yaw = -(p.heading_noise_deg * g(3)).to_radians();
    // Drawn apart from the three above, so that turning these on leaves x, y and yaw as they were.
    let dz = p.height_noise_m * g(4);
    let pitch = (p.pitch_noise_deg * g(5)).to_radians();
    let roll = (p.roll_noise_deg * g(6)).to_radians();
    // Pitch and roll turn the camera about its own right and forward axes: R' = R Rx(pitch)
    // Rz(roll) on the columns (right, down, forward).
    let r = truth.rotation;
    let col = |c: usize| [r[0][c], r[1][c], r[2][c]];
    let (right, down, fwd) = (col(0), col(1), col(2));
    let (sp, cp) = pitch.sin_cos();
    let down1: [f64; 3] = std::array::from_fn(|a| cp * down[a] - sp * fwd[a]);
    let fwd1: [f64; 3] = std::array::from_fn(|a| sp * down[a] + cp * fwd[a]);
    let (sr, cr) = roll.sin_cos();
    let right2: [f64; 3] = std::array::from_fn(|a| cr * right[a] + sr * down1[a]);
    let down2: [f64; 3] = std::array::from_fn(|a| -sr * right[a] + cr * down1[a]);
    let r = [
        [right2[0], down2[0], fwd1[0]],
        [right2[1], down2[1], fwd1[1]],
        [right2[2], down2[2], fwd1[2]],
    ];
    // Heading noise turns the camera about the vertical: rotate its axes about site z.
    let (sn, cs) = yaw.sin_cos();
    let rotation = [
        [
            cs * r[0][0] - sn * r[1][0],
            cs * r[0][1] - sn * r[1][1],
            cs * r[0][2] - sn * r[1][2],
        ],
        [
            sn * r[0][0] + cs * r[1][0],
            sn * r[0][1] + cs * r[1][1],
            sn * r[0][2] + cs * r[1][2],
        ],
        r[2],
    ];
    Pose {
        position: [
            truth.position[0] + dx,
            truth.position[1] + dy,
            truth.position[2] + dz,
        ],
        rotation,
    }
}

/// The intrinsics the metadata reports: the focal length off by `focal_noise` (relative), the
/// same factor on both axes (EXIF gives one focal length).
fn reported_intrinsics(truth: &Intrinsics, p: &SynthViewsParams, k: usize) -> Intrinsics {
    let s = mix(p.seed ^ mix(k as u64 ^ 0xF0CA_1000));
    let f = (1.0 + p.focal_noise * gaussian(s)).max(0.5);
    Intrinsics {
        fx: truth.fx * f,
        fy: truth.fy * f,
        ..*truth
    }
}

/// What a material segmentation model (RMSNet's 20 classes) would call a truth material.
fn rmsnet_class(m: Material) -> &'static str {
    match m {
        Material::Concrete => "concrete",
        Material::Brick => "brick",
        Material::Plasterboard | Material::CeilingBoard => "plaster",
        Material::Wood | Material::Chipboard | Material::Plywood | Material::Floorboard => "wood",
        Material::Glass => "glass",
        Material::Marble => "cobblestone",
        Material::Metal => "metal",
        Material::VeryDryGround => "sand",
        Material::MediumDryGround => "gravel",
        Material::WetGround => "grass",
        Material::Foliage => "leaf",
    }
}

fn rmsnet_index(name: &str) -> u8 {
    RMSNET_CLASSES
        .iter()
        .position(|c| *c == name)
        .unwrap_or(255) as u8
}

/// The architectural class of a building hit: the façade feature there, else wall or roof.
fn arch_class(b: Option<&Facades>, at: [f64; 3], roof: bool) -> (Option<usize>, &'static str) {
    if let Some(f) = b.and_then(|b| b.feature_at(at, 0.01).map(|k| (k, b.spec.features[k].kind))) {
        let name = match f.1 {
            FeatureKind::Window => "window",
            FeatureKind::Door => "door",
            FeatureKind::Balcony => "balcony",
            FeatureKind::Drainpipe => "drainpipe",
        };
        return (Some(f.0), name);
    }
    (None, if roof { "roof" } else { "wall" })
}

/// View `k` of `scene` from `pose`: the camera's rays cast, each pixel painted from what it hits,
/// the buffers gathered into a view.
fn render(
    scene: &Scene,
    rays: &SceneRays,
    buildings: &HashMap<&str, Facades>,
    p: &SynthViewsParams,
    k: usize,
    pose: Pose,
) -> View {
    let (w, h) = p.size;
    let intrinsics = camera_intrinsics(p);
    let origin = pose.position.map(|v| v as f32);
    let pixel_rays = pixel_rays(&pose, &intrinsics, w, h);
    let hits = rays.cast_grid(
        w,
        h,
        |u, v| (origin, pixel_rays[(v * w + u) as usize].0.map(|d| d as f32)),
        1e-3,
        2000.0,
    );
    let painter = Painter {
        scene,
        buildings,
        p,
        pose: &pose,
        seed: mix(p.seed ^ mix(k as u64)),
    };
    let mut frame = Frame::new((w * h) as usize);
    for v in 0..h {
        for u in 0..w {
            let i = (v * w + u) as usize;
            match &hits[i] {
                Some(hit) => painter.paint(&mut frame, i, hit, pixel_rays[i]),
                None => frame.sky(i),
            }
        }
    }
    degrade(&mut frame, p, (w, h), painter.seed);
    frame.into_view(k, (w, h), intrinsics, pose)
}

/// The model outputs of a painted frame as real models give them: the depth model's per-image
/// scale and offset, warp, far-range growth and edge bleeding; the normal estimator's noise and
/// edge blur; the instance segmenter's merged, confused and spurious instances and displaced
/// contours (see [`errors`]).
fn degrade(frame: &mut Frame, p: &SynthViewsParams, (w, h): (u32, u32), seed: u64) {
    let g = |j: u64| gaussian(mix(seed ^ mix(j ^ 0xDE_9700)));
    let depth = DepthErrors {
        noise: p.depth_noise,
        scale: (p.depth_scale * (1.0 + p.depth_scale_jitter * g(1))).max(0.1 * p.depth_scale),
        offset_m: p.depth_offset_m + p.depth_offset_jitter_m * g(2),
        warp: p.depth_warp,
        far_m: p.depth_far_m,
        edge_px: p.depth_edge_px,
    };
    let true_depth = std::mem::take(&mut frame.depth);
    frame.normal = degrade_normals(
        &frame.normal,
        &true_depth,
        w,
        h,
        p.normal_noise_deg,
        p.normal_edge_px,
        mix(seed ^ 0x4E),
    );
    frame.depth = degrade_depth(&true_depth, w, h, &depth, mix(seed ^ 0xD7));
    let masks = MaskErrors {
        boundary_px: p.instance_boundary_px,
        spurious: p.instance_spurious,
        merge: p.instance_merge,
        confusion: p.class_confusion,
    };
    let mut object_of = HashMap::new();
    let mut host_of = HashMap::new();
    for (&(object, feature, roof), &id) in &frame.arch_of {
        object_of.insert(id, object);
        if feature.is_none() && !roof {
            host_of.insert(object, id);
        }
    }
    let walls: std::collections::HashSet<u16> = frame
        .arch
        .classes
        .iter()
        .filter(|(_, c)| c.as_str() == "wall")
        .map(|(&id, _)| id)
        .collect();
    degrade_instances(
        &mut frame.arch_ids,
        &mut frame.arch.classes,
        w,
        h,
        &object_of,
        &host_of,
        &|id| walls.contains(&id),
        "window",
        &masks,
        mix(seed ^ 0xA7C),
    );
    let object_of: HashMap<u16, usize> = frame.clutter_of.iter().map(|(&o, &id)| (id, o)).collect();
    degrade_instances(
        &mut frame.clutter_ids,
        &mut frame.clutter.classes,
        w,
        h,
        &object_of,
        &HashMap::new(),
        &|_| false,
        "",
        &MaskErrors {
            spurious: 0.0,
            ..masks
        },
        mix(seed ^ 0xC1),
    );
}

/// The pinhole camera of `p`'s image size and horizontal field of view, principal point at the
/// image centre.
fn camera_intrinsics(p: &SynthViewsParams) -> Intrinsics {
    let (w, h) = p.size;
    let f = w as f64 / 2.0 / (p.hfov_deg.to_radians() / 2.0).tan();
    Intrinsics {
        fx: f,
        fy: f,
        cx: w as f64 / 2.0,
        cy: h as f64 / 2.0,
    }
}

/// Per pixel, row by row, the unit ray through its centre in the site frame and the length of
/// the camera-frame ray it was normalised from (depth = t / that).
fn pixel_rays(pose: &Pose, intrinsics: &Intrinsics, w: u32, h: u32) -> Vec<([f64; 3], f64)> {
    let f = intrinsics.fx;
    let ray = |u: u32, v: u32| {
        let cam = [
            (u as f64 + 0.5 - intrinsics.cx) / f,
            (v as f64 + 0.5 - intrinsics.cy) / f,
            1.0,
        ];
        let norm = (cam[0] * cam[0] + cam[1] * cam[1] + 1.0).sqrt();
        (pose.to_site(cam.map(|c| c / norm)), norm)
    };
    (0..h)
        .flat_map(|v| (0..w).map(move |u| (u, v)))
        .map(|(u, v)| ray(u, v))
        .collect()
}

/// The buffers of one view being rendered, and its instances numbered as they are met.
struct Frame {
    image: Vec<[u8; 3]>,
    depth: Vec<f32>,
    normal: Vec<[f32; 3]>,
    material: Vec<u8>,
    arch_ids: Vec<u16>,
    clutter_ids: Vec<u16>,
    arch: Instances,
    clutter: Instances,
    /// One instance per (object, feature) and per (object, wall or roof), numbered in pixel
    /// order.
    arch_of: HashMap<(usize, Option<usize>, bool), u16>,
    clutter_of: HashMap<usize, u16>,
}

impl Frame {
    /// Buffers for `n` pixels: nothing seen yet.
    fn new(n: usize) -> Frame {
        Frame {
            image: vec![[0u8; 3]; n],
            depth: vec![f32::INFINITY; n],
            normal: vec![[0f32; 3]; n],
            material: vec![255u8; n],
            arch_ids: vec![0u16; n],
            clutter_ids: vec![0u16; n],
            arch: Instances::default(),
            clutter: Instances::default(),
            arch_of: HashMap::new(),
            clutter_of: HashMap::new(),
        }
    }

    /// Pixel `i` sees the sky.
    fn sky(&mut self, i: usize) {
        self.image[i] = [150, 185, 225];
        self.material[i] = rmsnet_index("sky");
    }

    /// The view, once every pixel is painted.
    fn into_view(self, k: usize, (w, h): (u32, u32), intrinsics: Intrinsics, pose: Pose) -> View {
        let Frame {
            image,
            depth,
            normal,
            material,
            arch_ids,
            clutter_ids,
            mut arch,
            mut clutter,
            ..
        } = self;
        arch.ids = PodVec(arch_ids);
        clutter.ids = PodVec(clutter_ids);
        View {
            id: format!("v{k:04}"),
            width: w,
            height: h,
            intrinsics,
            pose,
            captured_at: None,
            pose_source: Some(
                "synthetic: rendered from the true pose, reported with SynthViews' pose noise"
                    .into(),
            ),
            distortion: None,
            image: PodVec(image),
            arch: Some(arch),
            clutter: Some(clutter),
            material: Some(PodVec(material)),
            depth: Some(PodVec(depth)),
            normal: Some(PodVec(normal)),
        }
    }
}

/// What paints a view's pixels from their hits: the scene, its buildings' façade features, the
/// error knobs, the true pose and the view's seed.
struct Painter<'a> {
    scene: &'a Scene,
    buildings: &'a HashMap<&'a str, Facades<'a>>,
    p: &'a SynthViewsParams,
    pose: &'a Pose,
    seed: u64,
}

impl Painter<'_> {
    /// Pixel `i`, whose ray (`dir`, `norm` as [`pixel_rays`] gives them) hits `hit`: what the
    /// camera and each model output would say of it.
    fn paint(&self, frame: &mut Frame, i: usize, hit: &Hit, (dir, norm): ([f64; 3], f64)) {
        let obj = &self.scene.objects[hit.object];
        let mut nrm = hit.normal.map(|c| c as f64);
        if nrm[0] * dir[0] + nrm[1] * dir[1] + nrm[2] * dir[2] > 0.0 {
            nrm = nrm.map(|c| -c);
        }
        let z_depth = hit.t as f64 / norm;
        // The true depth: the depth model's errors are applied to the whole frame once painted.
        frame.depth[i] = z_depth as f32;
        frame.normal[i] = self.pose.to_camera(nrm).map(|c| c as f32);
        let m = obj
            .mesh
            .materials
            .get(hit.triangle)
            .copied()
            .and_then(Material::from_u8)
            .unwrap_or(Material::Concrete);
        frame.material[i] = self.reported_material(hit.object, m);
        frame.image[i] = shaded_color(m, nrm);
        match obj.class {
            ObjectClass::Building => self.label_building(frame, i, hit, dir, nrm),
            ObjectClass::Clutter | ObjectClass::Vegetation => self.label_clutter(frame, i, hit),
            _ => {}
        }
    }

    /// The RMSNet class the material model reports for material `m` of object `object`.
    /// Per-object material confusion: the same wrong class for all of the object's pixels.
    fn reported_material(&self, object: usize, m: Material) -> u8 {
        let h_obj = mix(self.seed ^ mix(object as u64 ^ 0xA5A5));
        let truth_class = rmsnet_index(rmsnet_class(m));
        if unit(h_obj) < self.p.material_error {
            (h_obj % RMSNET_CLASSES.len() as u64) as u8
        } else {
            truth_class
        }
    }

    /// Whether the instance model misses the instance of `key` (the same for all its pixels).
    fn missed(&self, key: u64) -> bool {
        unit(mix(self.seed ^ mix(key ^ 0x5EED))) < self.p.instance_miss
    }

    /// Pixel `i` on a building: its architectural instance (the façade feature there, else the
    /// wall or the roof), unless the model misses it.
    fn label_building(&self, frame: &mut Frame, i: usize, hit: &Hit, dir: [f64; 3], nrm: [f64; 3]) {
        let obj = &self.scene.objects[hit.object];
        let roof = nrm[2] > 0.7;
        let t = hit.t as f64;
        let at = std::array::from_fn(|a| self.pose.position[a] + dir[a] * t);
        let (feature, class) = arch_class(self.buildings.get(obj.id.as_str()), at, roof);
        let next = frame.arch_of.len() as u16 + 1;
        let id = *frame
            .arch_of
            .entry((hit.object, feature, roof))
            .or_insert(next);
        let key = |feature: Option<usize>| {
            (hit.object as u64) << 20 ^ feature.map_or(0xFFFFF, |f| f as u64) << 1 ^ roof as u64
        };
        if !self.missed(key(feature)) {
            frame.arch_ids[i] = id;
            frame.arch.classes.insert(id, class.into());
        } else if feature.is_some() && !self.missed(key(None)) {
            // A missed façade feature is seen as the wall (or roof) it is on.
            let next = frame.arch_of.len() as u16 + 1;
            let host = *frame
                .arch_of
                .entry((hit.object, None, roof))
                .or_insert(next);
            frame.arch_ids[i] = host;
            frame
                .arch
                .classes
                .insert(host, if roof { "roof" } else { "wall" }.into());
        }
    }

    /// Pixel `i` on clutter or vegetation: the object's instance, of the kind its id names,
    /// unless the model misses it.
    fn label_clutter(&self, frame: &mut Frame, i: usize, hit: &Hit) {
        let obj = &self.scene.objects[hit.object];
        let next = frame.clutter_of.len() as u16 + 1;
        let id = *frame.clutter_of.entry(hit.object).or_insert(next);
        if !self.missed(hit.object as u64 + (1 << 40)) {
            frame.clutter_ids[i] = id;
            let kind = obj.id.split('-').next().unwrap_or("object").to_owned();
            frame.clutter.classes.insert(id, kind);
        }
    }
}

/// The colour of material `m` under the fixed sun, Lambert-shaded on normal `nrm` (facing the
/// camera), gamma-encoded.
fn shaded_color(m: Material, nrm: [f64; 3]) -> [u8; 3] {
    let sun = [0.35f64, -0.45, 0.82];
    let lambert = (nrm[0] * sun[0] + nrm[1] * sun[1] + nrm[2] * sun[2]).max(0.0);
    let c = material_color(m);
    c.map(|x| {
        (255.0
            * (x as f64 * (0.45 + 0.55 * lambert))
                .clamp(0.0, 1.0)
                .powf(1.0 / 2.2)) as u8
    })
}
