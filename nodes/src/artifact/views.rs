//! Street-level view sets with the outputs of the models run on them (paper Sec. 4.2).
//!
//! Camera conventions: the camera frame is OpenCV's (x right, y down, z forward); `heading_deg`
//! is clockwise from north, `pitch_deg` positive up, `roll_deg` clockwise seen from behind; the
//! position is in the site frame. Depth is along the optical axis (z), not along the ray.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::PodVec;
use super::{PartError, PartRef, PartStore};

/// The 20 material classes of RMSNet (Cai et al. 2024), the vocabulary material maps use by
/// default; `shared/DESIGN.md` maps them to ITU-R P.2040.
pub const RMSNET_CLASSES: [&str; 20] = [
    "asphalt",
    "concrete",
    "metal",
    "road marking",
    "fabric/leather",
    "glass",
    "plaster",
    "plastic",
    "rubber",
    "sand",
    "gravel",
    "ceramic",
    "cobblestone",
    "brick",
    "grass",
    "wood",
    "leaf",
    "water",
    "human body",
    "sky",
];

/// Pinhole intrinsics, pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x.
    pub fx: f64,
    /// Focal length along y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
}

/// Where a camera was and where it looked.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Site-frame position, metres.
    pub position: [f64; 3],
    /// Rotation camera frame -> site frame, rows of a 3x3 matrix (columns are right, down,
    /// forward).
    pub rotation: [[f64; 3]; 3],
}

/// Instance segmentation: an id per pixel (0 = none) and each id's class.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Instances {
    /// Per pixel, row-major.
    pub ids: PodVec<u16>,
    /// Instance id -> class name.
    pub classes: BTreeMap<u16, String>,
}

/// One street-level view and the model outputs for it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct View {
    /// Identifier; file names derive from it.
    pub id: String,
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Camera intrinsics.
    pub intrinsics: Intrinsics,
    /// Camera pose.
    pub pose: Pose,
    /// Capture time (ISO 8601), when known.
    pub captured_at: Option<String>,
    /// Where the pose came from, e.g. `"computed_rotation, computed_geometry, terrain + 2.5 m"`
    /// for a Mapillary image: evidence for how far to trust it.
    pub pose_source: Option<String>,
    /// Radial distortion [k1, k2] on normalised coordinates (OpenSfM's perspective model), not
    /// applied to the image; `None` where the image is distortion-free.
    pub distortion: Option<[f64; 2]>,
    /// 8-bit RGB, row-major.
    pub image: PodVec<[u8; 3]>,
    /// Architectural instances (walls, roofs, windows, doors, balconies...).
    pub arch: Option<Instances>,
    /// Clutter instances (cars, poles, signs, trees...).
    pub clutter: Option<Instances>,
    /// Material class per pixel: an index into [`ViewSet::material_classes`], 255 = none.
    pub material: Option<PodVec<u8>>,
    /// Depth along the optical axis per pixel (metric, or relative up to a scale); inf = sky.
    pub depth: Option<PodVec<f32>>,
    /// Camera-frame unit normals per pixel.
    pub normal: Option<PodVec<[f32; 3]>>,
}

impl View {
    /// A view of `width` x `height` pixels with a black image and no model outputs (no
    /// instances, materials, depth or normals), taken from `pose` through `intrinsics`.
    pub fn new(id: &str, width: u32, height: u32, intrinsics: Intrinsics, pose: Pose) -> View {
        View {
            id: id.to_owned(),
            width,
            height,
            intrinsics,
            pose,
            captured_at: None,
            pose_source: None,
            distortion: None,
            image: PodVec(vec![[0; 3]; width as usize * height as usize]),
            arch: None,
            clutter: None,
            material: None,
            depth: None,
            normal: None,
        }
    }

    /// The unit site-frame direction through image point (`x`, `y`) (pixel (i, j)'s centre is
    /// (i + 0.5, j + 0.5)), and the ray length per unit of depth along the optical axis (so a
    /// pixel's depth d is t = d times it along the ray).
    pub fn pixel_ray(&self, x: f64, y: f64) -> ([f64; 3], f64) {
        let k = self.intrinsics;
        let cam = [(x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0];
        let norm = (cam[0] * cam[0] + cam[1] * cam[1] + 1.0).sqrt();
        (self.pose.to_site(cam.map(|c| c / norm)), norm)
    }

    /// Where site-frame point `p` falls in the image: its image point (x, y) (pixel (i, j)'s
    /// centre is (i + 0.5, j + 0.5)) and its depth along the optical axis; `None` behind the
    /// camera. The inverse of [`View::pixel_ray`], distortion likewise not applied.
    pub fn project(&self, p: [f64; 3]) -> Option<([f64; 2], f64)> {
        let rel = std::array::from_fn(|a| p[a] - self.pose.position[a]);
        let c = self.pose.to_camera(rel);
        if c[2] <= 1e-9 {
            return None;
        }
        let k = self.intrinsics;
        Some(([k.fx * c[0] / c[2] + k.cx, k.fy * c[1] / c[2] + k.cy], c[2]))
    }
}

impl View {
    /// Refuses a view the projections cannot use: a size that is zero or past
    /// [`crate::params::MAX_CELLS`], a focal length that is zero or not finite, a position or
    /// rotation that is not finite, a rotation that is not one (a zero quaternion), per-pixel
    /// layers of another size than the image, a material index past the `n_classes` of the table
    /// (255 is none). The error is the part of the view and what was expected.
    pub fn check(&self, n_classes: usize) -> Result<(), (&'static str, String)> {
        let (w, h) = (self.width as usize, self.height as usize);
        if w == 0 || h == 0 {
            return Err((
                "size",
                format!("a positive width and height, found {w} x {h}"),
            ));
        }
        crate::params::check_cells(w as f64, h as f64, 3).map_err(|m| ("size", m))?;
        let k = self.intrinsics;
        if !(k.fx.is_finite() && k.fy.is_finite() && k.fx != 0.0 && k.fy != 0.0) {
            return Err((
                "intrinsics",
                format!(
                    "finite, non-zero focal lengths, found fx = {}, fy = {}",
                    k.fx, k.fy
                ),
            ));
        }
        if !(k.cx.is_finite() && k.cy.is_finite()) {
            return Err((
                "intrinsics",
                format!("a finite principal point, found ({}, {})", k.cx, k.cy),
            ));
        }
        if !self.pose.position.iter().all(|v| v.is_finite()) {
            return Err((
                "pose",
                format!("a finite position, found {:?}", self.pose.position),
            ));
        }
        let r = self.pose.rotation;
        let orthonormal = (0..3).all(|i| {
            (0..3).all(|j| {
                let dot: f64 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
                (dot - if i == j { 1.0 } else { 0.0 }).abs() < 1e-6
            })
        });
        if !orthonormal {
            return Err((
                "orientation",
                "a rotation (a non-zero quaternion, finite angles)".into(),
            ));
        }
        let n = w * h;
        let sizes = [
            ("image", Some(self.image.len())),
            ("arch", self.arch.as_ref().map(|a| a.ids.len())),
            ("clutter", self.clutter.as_ref().map(|a| a.ids.len())),
            ("material", self.material.as_ref().map(|m| m.len())),
            ("depth", self.depth.as_ref().map(|d| d.len())),
            ("normal", self.normal.as_ref().map(|d| d.len())),
        ];
        for (what, len) in sizes {
            if let Some(len) = len.filter(|&l| l != n) {
                return Err((what, format!("{n} pixels ({w} x {h}), found {len}")));
            }
        }
        if let Some(m) = &self.material
            && let Some((i, &c)) = m
                .iter()
                .enumerate()
                .find(|&(_, &c)| c != 255 && c as usize >= n_classes)
        {
            return Err((
                "material",
                format!(
                    "class indices below {n_classes} (the material_classes table) or 255 (none), found {c} at pixel ({}, {})",
                    i % w,
                    i / w
                ),
            ));
        }
        Ok(())
    }
}

/// A set of views sharing a material class table. The set holds each view's head (everything
/// but its per-pixel layers); the layers are one part per view in a [`PartStore`], compressed,
/// read one view at a time through [`Views`]. So a set of any size loads in kilobytes, a stage
/// that moves poses copies no pixel, and a stage reading views holds a few at once.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ViewSet {
    /// The views, in file order.
    pub views: Vec<ViewHead>,
    /// Material class names, indexed by the material maps.
    pub material_classes: Vec<String>,
}

/// A view without its per-pixel layers, which are the part `pixels` names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewHead {
    /// See [`View::id`].
    pub id: String,
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Camera intrinsics.
    pub intrinsics: Intrinsics,
    /// Camera pose.
    pub pose: Pose,
    /// See [`View::captured_at`].
    pub captured_at: Option<String>,
    /// See [`View::pose_source`].
    pub pose_source: Option<String>,
    /// See [`View::distortion`].
    pub distortion: Option<[f64; 2]>,
    /// The architectural instances' classes, when the view has them.
    pub arch_classes: Option<BTreeMap<u16, String>>,
    /// The clutter instances' classes, when the view has them.
    pub clutter_classes: Option<BTreeMap<u16, String>>,
    /// The per-pixel layers: [`ViewPixels`], MessagePack compressed with zstd.
    pub pixels: PartRef,
}

/// A view's per-pixel layers as one part stores them.
#[derive(Serialize, Deserialize)]
struct ViewPixels {
    image: PodVec<[u8; 3]>,
    arch: Option<PodVec<u16>>,
    clutter: Option<PodVec<u16>>,
    material: Option<PodVec<u8>>,
    depth: Option<PodVec<f32>>,
    normal: Option<PodVec<[f32; 3]>>,
}

/// zstd's level for view parts: level 1 compresses at several hundred MB/s a core, so storing a
/// view costs less than rendering or reading it, and halves what the model layers take.
const PIXELS_ZSTD_LEVEL: i32 = 1;

impl View {
    /// Stores this view's pixels in `parts` and returns its head. The view is checked first
    /// ([`View::check`] against `n_classes` material classes): the error is the place (`what`)
    /// and what was expected.
    pub fn store(
        self,
        n_classes: usize,
        parts: &dyn PartStore,
    ) -> Result<Result<ViewHead, (&'static str, String)>, PartError> {
        if let Err(e) = self.check(n_classes) {
            return Ok(Err(e));
        }
        let (arch, arch_classes) = split_instances(self.arch);
        let (clutter, clutter_classes) = split_instances(self.clutter);
        let pixels = ViewPixels {
            image: self.image,
            arch,
            clutter,
            material: self.material,
            depth: self.depth,
            normal: self.normal,
        };
        let packed = rmp_serde::to_vec(&pixels)
            .map_err(|e| PartError(format!("cannot encode view {:?}: {e}", self.id)))?;
        let zipped = zstd::bulk::compress(&packed, PIXELS_ZSTD_LEVEL)
            .map_err(|e| PartError(format!("cannot compress view {:?}: {e}", self.id)))?;
        Ok(Ok(ViewHead {
            pixels: parts.put(&zipped)?,
            id: self.id,
            width: self.width,
            height: self.height,
            intrinsics: self.intrinsics,
            pose: self.pose,
            captured_at: self.captured_at,
            pose_source: self.pose_source,
            distortion: self.distortion,
            arch_classes,
            clutter_classes,
        }))
    }
}

fn split_instances(i: Option<Instances>) -> (Option<PodVec<u16>>, Option<BTreeMap<u16, String>>) {
    match i {
        Some(i) => (Some(i.ids), Some(i.classes)),
        None => (None, None),
    }
}

impl ViewHead {
    /// The whole view: the head with its pixels read from `parts`.
    pub fn load(&self, parts: &dyn PartStore) -> Result<View, PartError> {
        let bad = |why: String| {
            PartError(format!(
                "the pixels of view {:?} cannot be read back: {why}",
                self.id
            ))
        };
        let zipped = parts.get(&self.pixels)?;
        // The bound is the layers of a view of this size, so a part can never ask for more.
        let n = self.width as usize * self.height as usize;
        let bound = 64 + n * (3 + 2 + 2 + 1 + 4 + 12) + 64;
        let packed = zstd::bulk::decompress(&zipped, bound).map_err(|e| bad(e.to_string()))?;
        let px: ViewPixels = rmp_serde::from_slice(&packed).map_err(|e| bad(e.to_string()))?;
        let instances = |ids: Option<PodVec<u16>>, classes: &Option<BTreeMap<u16, String>>| {
            ids.map(|ids| Instances {
                ids,
                classes: classes.clone().unwrap_or_default(),
            })
        };
        Ok(View {
            id: self.id.clone(),
            width: self.width,
            height: self.height,
            intrinsics: self.intrinsics,
            pose: self.pose,
            captured_at: self.captured_at.clone(),
            pose_source: self.pose_source.clone(),
            distortion: self.distortion,
            image: px.image,
            arch: instances(px.arch, &self.arch_classes),
            clutter: instances(px.clutter, &self.clutter_classes),
            material: px.material,
            depth: px.depth,
            normal: px.normal,
        })
    }
}

impl ViewSet {
    /// An empty set with material class table `material_classes`.
    pub fn new(material_classes: Vec<String>) -> ViewSet {
        ViewSet {
            views: Vec::new(),
            material_classes,
        }
    }

    /// A set of `views`, each stored in `parts` on all threads, in order. Each view is checked
    /// ([`View::check`]): the error is the place (the view's index and id, then the part) and
    /// what was expected.
    pub fn store(
        views: Vec<View>,
        material_classes: Vec<String>,
        parts: &dyn PartStore,
    ) -> Result<Result<ViewSet, (String, String)>, PartError> {
        use rayon::prelude::*;
        let n = material_classes.len();
        let heads: Vec<_> = views
            .into_par_iter()
            .enumerate()
            .map(|(i, v)| {
                let id = v.id.clone();
                v.store(n, parts)
                    .map(|r| r.map_err(|(what, m)| (format!("view {i} ({id:?}), {what}"), m)))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(heads
            .into_iter()
            .collect::<Result<Vec<_>, _>>()
            .map(|views| ViewSet {
                views,
                material_classes,
            }))
    }

    /// The views with the store their pixels are in.
    pub fn with<'a>(&'a self, parts: &'a dyn PartStore) -> Views<'a> {
        Views { set: self, parts }
    }

    /// Every part the set names.
    pub fn parts(&self) -> impl Iterator<Item = PartRef> + '_ {
        self.views.iter().map(|v| v.pixels)
    }
}

/// A view set and the store of its pixels: views read one at a time, so a stage going through
/// them in parallel holds as many as it has threads, whatever the set's size.
#[derive(Clone, Copy)]
pub struct Views<'a> {
    /// The heads.
    pub set: &'a ViewSet,
    /// Where the pixels are.
    pub parts: &'a dyn PartStore,
}

impl Views<'_> {
    /// How many views.
    pub fn len(&self) -> usize {
        self.set.views.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.set.views.is_empty()
    }

    /// View `i` with its pixels.
    pub fn load(&self, i: usize) -> Result<View, PartError> {
        self.set.views[i].load(self.parts)
    }

    /// Every view with its pixels, for a stage that needs them all at once: memory grows with
    /// the set.
    pub fn load_all(&self) -> Result<Vec<View>, PartError> {
        use rayon::prelude::*;
        (0..self.len())
            .into_par_iter()
            .with_max_len(1)
            .map(|i| self.load(i))
            .collect()
    }

    /// Runs `f` on every view in parallel, each loaded for its turn only, and returns what it
    /// made, in view order. Views are handed out one at a time: rayon's adaptive split would
    /// give a thread a run of hundreds of views that no idle thread can take from, and views
    /// cost unevenly (on the 1 km² street graph, one of two cores idled 7.5 s at the end of
    /// RegisterViews' first pass).
    pub fn map<R: Send>(
        &self,
        f: impl Fn(usize, &View) -> R + Sync + Send,
    ) -> Result<Vec<R>, PartError> {
        use rayon::prelude::*;
        (0..self.len())
            .into_par_iter()
            .with_max_len(1)
            .map(|i| self.load(i).map(|v| f(i, &v)))
            .collect()
    }
}

impl Pose {
    /// A pose from heading (clockwise from north), pitch (up) and roll, in degrees.
    pub fn from_angles(
        position: [f64; 3],
        heading_deg: f64,
        pitch_deg: f64,
        roll_deg: f64,
    ) -> Pose {
        let (h, p, r) = (
            heading_deg.to_radians(),
            pitch_deg.to_radians(),
            roll_deg.to_radians(),
        );
        let f = [h.sin() * p.cos(), h.cos() * p.cos(), p.sin()];
        // Level right and down, then rolled about the forward axis.
        let right0 = [h.cos(), -h.sin(), 0.0];
        let down0 = [
            f[1] * right0[2] - f[2] * right0[1],
            f[2] * right0[0] - f[0] * right0[2],
            f[0] * right0[1] - f[1] * right0[0],
        ];
        let (s, c) = r.sin_cos();
        let right: [f64; 3] = std::array::from_fn(|k| c * right0[k] + s * down0[k]);
        let down: [f64; 3] = std::array::from_fn(|k| -s * right0[k] + c * down0[k]);
        Pose {
            position,
            rotation: std::array::from_fn(|row| [right[row], down[row], f[row]]),
        }
    }

    /// A pose from a unit quaternion (w, x, y, z) rotating camera-frame vectors into the site frame.
    pub fn from_quaternion(position: [f64; 3], q: [f64; 4]) -> Pose {
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let [w, x, y, z] = q.map(|v| v / n);
        let rotation = [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ];
        Pose { position, rotation }
    }

    /// Site-frame direction of camera-frame vector `v`.
    pub fn to_site(&self, v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|r| {
            self.rotation[r][0] * v[0] + self.rotation[r][1] * v[1] + self.rotation[r][2] * v[2]
        })
    }

    /// Camera-frame direction of site-frame vector `v`.
    pub fn to_camera(&self, v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|c| {
            self.rotation[0][c] * v[0] + self.rotation[1][c] * v[1] + self.rotation[2][c] * v[2]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_inverts_pixel_ray() {
        let k = Intrinsics {
            fx: 50.0,
            fy: 52.0,
            cx: 31.0,
            cy: 25.0,
        };
        let pose = Pose::from_angles([3.0, -2.0, 1.6], 30.0, 4.0, -2.0);
        let view = View::new("v", 64, 48, k, pose);
        assert!(view.check(0).is_ok());
        let (dir, per_depth) = view.pixel_ray(10.5, 40.5);
        let depth = 7.0;
        let p = std::array::from_fn(|a| view.pose.position[a] + dir[a] * depth * per_depth);
        let (xy, d) = view.project(p).unwrap();
        assert!(
            (xy[0] - 10.5).abs() < 1e-9 && (xy[1] - 40.5).abs() < 1e-9,
            "{xy:?}"
        );
        assert!((d - depth).abs() < 1e-9, "{d}");
        // A point behind the camera projects nowhere.
        let behind = std::array::from_fn(|a| view.pose.position[a] - dir[a]);
        assert!(view.project(behind).is_none());
    }

    #[test]
    fn a_view_stored_as_a_part_reads_back_whole() {
        use crate::artifact::MemParts;
        let k = Intrinsics {
            fx: 50.0,
            fy: 50.0,
            cx: 8.0,
            cy: 6.0,
        };
        let mut view = View::new(
            "v",
            16,
            12,
            k,
            Pose::from_angles([1.0, 2.0, 3.0], 10.0, 0.0, 0.0),
        );
        view.image = PodVec((0..192).map(|i| [i as u8, 7, 9]).collect());
        view.depth = Some(PodVec((0..192).map(|i| i as f32 * 0.5).collect()));
        view.arch = Some(Instances {
            ids: PodVec((0..192).map(|i| (i % 3) as u16).collect()),
            classes: [(1, "wall".to_string()), (2, "window".to_string())].into(),
        });
        let parts = MemParts::new();
        let set = ViewSet::store(vec![view.clone()], vec!["glass".into()], &parts)
            .unwrap()
            .unwrap();
        assert_eq!(
            set.views[0].arch_classes,
            view.arch.as_ref().map(|a| a.classes.clone())
        );
        assert_eq!(set.with(&parts).load(0).unwrap(), view);
        // The same pixels are the same part: a moved pose names the part it had.
        let mut moved = view.clone();
        moved.pose.position[0] += 1.0;
        let again = ViewSet::store(vec![moved], vec!["glass".into()], &parts)
            .unwrap()
            .unwrap();
        assert_eq!(again.views[0].pixels, set.views[0].pixels);
        // A layer of another size is refused before anything is stored, naming the view.
        let mut bad = view.clone();
        bad.depth = Some(PodVec(vec![1.0; 5]));
        let (place, expected) = ViewSet::store(vec![bad], Vec::new(), &parts)
            .unwrap()
            .unwrap_err();
        assert!(
            place.contains("view 0") && place.contains("depth"),
            "{place}"
        );
        assert!(expected.contains("192 pixels"), "{expected}");
        // Read with another store, the part is not there: an error, not a panic.
        let e = set.with(&MemParts::new()).load(0).unwrap_err();
        assert!(e.0.contains("not in this store"), "{e}");
    }
}
