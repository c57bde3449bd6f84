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
    ArtifactType, BuildingSpec, City, FeatureKind, Instances, Intrinsics, ObjectClass, PodVec,
    Pose, RMSNET_CLASSES, Scene, View, ViewSet,
};
use crate::geom::raycast::{Hit, SceneRays};
use crate::io::export::material_color;
use crate::rng::{gaussian, mix, unit};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

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
    /// Relative standard deviation of depth noise. Default 0.02.
    pub depth_noise: f64,
    /// Depth is reported as `depth_scale` x true depth + `depth_offset_m` (with the noise): the
    /// affine bias of monocular depth before calibration. Default 1 (metric).
    pub depth_scale: f64,
    /// See `depth_scale`. Default 0.
    pub depth_offset_m: f64,
    /// Standard deviation of the reported camera position, horizontally, metres (the views are
    /// rendered from the true pose; the metadata is off, as real metadata is). Default 0.
    pub pose_noise_m: f64,
    /// Standard deviation of the reported heading, degrees. Default 0.
    pub heading_noise_deg: f64,
    /// Probability that an object's material is reported as another RMSNet class. Default 0.05.
    pub material_error: f64,
    /// Probability that an instance is missed (its pixels get id 0). Default 0.1.
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
            pose_noise_m: 0.0,
            heading_noise_deg: 0.0,
            material_error: 0.05,
            instance_miss: 0.1,
            seed: 7,
        }
    }
}

/// Renders street views of a city's truth scene.
pub struct SynthViews;

impl Stage for SynthViews {
    const KIND: &'static str = "SynthViews";
    const VERSION: u32 = 2;
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
        ] {
            if !(v >= 0.0 && v <= 1000.0) {
                return Err(ParamError::new(name, "expected a finite value within 1000"));
            }
        }
        if p.max_views > 100_000 {
            return Err(ParamError::new(
                "max_views",
                "expected at most 100000 views",
            ));
        }
        for (name, v) in [
            ("depth_noise", p.depth_noise),
            ("material_error", p.material_error),
            ("instance_miss", p.instance_miss),
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
        let poses = stations(city, p);
        ctx.progress.set_total(poses.len() as u64);
        let material_classes: Vec<String> = RMSNET_CLASSES.iter().map(|s| s.to_string()).collect();
        let buildings: HashMap<&str, &BuildingSpec> =
            city.buildings.iter().map(|b| (b.id.as_str(), b)).collect();
        let views = poses
            .par_iter()
            .enumerate()
            .map(|(k, pose)| {
                let mut v = render(scene, &rays, &buildings, p, k, *pose);
                v.pose = reported_pose(&v.pose, p, k);
                ctx.progress.advance(1);
                v
            })
            .collect();
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

/// The pose the metadata reports: the true one with position and heading noise.
fn reported_pose(truth: &Pose, p: &SynthViewsParams, k: usize) -> Pose {
    if p.pose_noise_m == 0.0 && p.heading_noise_deg == 0.0 {
        return *truth;
    }
    let s = mix(p.seed ^ mix(k as u64 ^ 0x9051_7E00));
    let (dx, dy) = (
        p.pose_noise_m * gaussian(mix(s ^ 1)),
        p.pose_noise_m * gaussian(mix(s ^ 2)),
    );
    let yaw = -(p.heading_noise_deg * gaussian(mix(s ^ 3))).to_radians();
    // Heading noise turns the camera about the vertical: rotate its axes about site z.
    let (sn, cs) = yaw.sin_cos();
    let r = truth.rotation;
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
            truth.position[2],
        ],
        rotation,
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
fn arch_class(b: Option<&BuildingSpec>, at: [f64; 3], roof: bool) -> (Option<usize>, &'static str) {
    if let Some(f) = b.and_then(|b| b.feature_at(at, 0.01).map(|k| (k, b.features[k].kind))) {
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
    buildings: &HashMap<&str, &BuildingSpec>,
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
    frame.into_view(k, (w, h), intrinsics, pose)
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
    buildings: &'a HashMap<&'a str, &'a BuildingSpec>,
    p: &'a SynthViewsParams,
    pose: &'a Pose,
    seed: u64,
}

impl Painter<'_> {
    /// Pixel `i`, whose ray (`dir`, `norm` as [`pixel_rays`] gives them) hits `hit`: what the
    /// camera and each model output would say of it.
    fn paint(&self, frame: &mut Frame, i: usize, hit: &Hit, (dir, norm): ([f64; 3], f64)) {
        let (p, seed) = (self.p, self.seed);
        let obj = &self.scene.objects[hit.object];
        let mut nrm = hit.normal.map(|c| c as f64);
        if nrm[0] * dir[0] + nrm[1] * dir[1] + nrm[2] * dir[2] > 0.0 {
            nrm = nrm.map(|c| -c);
        }
        let z_depth = hit.t as f64 / norm;
        let noise = 1.0 + p.depth_noise * gaussian(mix(seed ^ (i as u64).wrapping_mul(0x9E37)));
        frame.depth[i] = (z_depth * noise * p.depth_scale + p.depth_offset_m) as f32;
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
        let (feature, class) = arch_class(self.buildings.get(obj.id.as_str()).copied(), at, roof);
        let next = frame.arch_of.len() as u16 + 1;
        let id = *frame
            .arch_of
            .entry((hit.object, feature, roof))
            .or_insert(next);
        let key =
            (hit.object as u64) << 20 ^ feature.map_or(0xFFFFF, |f| f as u64) << 1 ^ roof as u64;
        if !self.missed(key) {
            frame.arch_ids[i] = id;
            frame.arch.classes.insert(id, class.into());
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
