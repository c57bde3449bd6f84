//! Triangle-mesh scenes in the site frame: what ray tracers and exporters consume.

use serde::{Deserialize, Serialize};

use super::PodVec;

pub use crate::params::MAX_COORD_M;

/// A triangle mesh: vertices in the site frame (metres, z up), triangles counter-clockwise seen
/// from outside (normals point out of closed solids).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: PodVec<[f32; 3]>,
    /// Vertex indices, three per triangle.
    pub triangles: PodVec<[u32; 3]>,
    /// [`crate::artifact::Material`] discriminant per triangle.
    pub materials: PodVec<u8>,
}

impl Mesh {
    /// Appends `other`, shifting its indices.
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
        self.materials.extend_from_slice(&other.materials);
    }

    /// Refuses what a ray tracer or a mesh check cannot take: a vertex coordinate that is not
    /// finite or lies past [`MAX_COORD_M`] (its BVH's box areas would overflow), a triangle index
    /// past the vertices, a material list of another length than the triangles. Readers call it,
    /// so bad data is named where it is read. The error is the element and what was expected:
    /// (`vertex 17`, `a finite x, found NaN`).
    pub fn check(&self) -> Result<(), (String, String)> {
        for (i, p) in self.positions.iter().enumerate() {
            for (axis, v) in ["x", "y", "z"].iter().zip(p) {
                if !(v.abs() <= MAX_COORD_M) {
                    return Err((
                        format!("vertex {i}"),
                        format!(
                            "a finite {axis} within {MAX_COORD_M:e} m of the origin, found {v:e} (wrong CRS or units?)"
                        ),
                    ));
                }
            }
        }
        let n = self.positions.len();
        if let Some((t, bad)) = self
            .triangles
            .iter()
            .enumerate()
            .find_map(|(t, tri)| tri.iter().find(|&&v| v as usize >= n).map(|&v| (t, v)))
        {
            return Err((
                format!("triangle {t}"),
                format!("vertex indices below {n}, found {bad}"),
            ));
        }
        if self.materials.len() != self.triangles.len() {
            return Err((
                "materials".into(),
                format!(
                    "one material per triangle ({}), found {}",
                    self.triangles.len(),
                    self.materials.len()
                ),
            ));
        }
        Ok(())
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// True when there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The triangles for which `keep` (given their three corners) says yes, with their materials
    /// and only the vertices they use, in their order.
    pub fn select_triangles(&self, keep: impl Fn(&[[f32; 3]; 3]) -> bool) -> Mesh {
        let mut out = Mesh::default();
        let mut new_index = vec![u32::MAX; self.positions.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            if !keep(&tri.map(|i| self.positions[i as usize])) {
                continue;
            }
            let tri = tri.map(|i| {
                let slot = &mut new_index[i as usize];
                if *slot == u32::MAX {
                    *slot = out.positions.len() as u32;
                    out.positions.push(self.positions[i as usize]);
                }
                *slot
            });
            out.triangles.push(tri);
            out.materials.push(self.materials[t]);
        }
        out
    }

    /// The horizontal point that says where the object is, for a tiled run's ownership: the
    /// centroid of the enclosed volume (a prism's footprint centroid) for a closed solid, else the
    /// middle of its horizontal bounds. None for a mesh without vertices.
    pub fn owner_point(&self) -> Option<(f64, f64)> {
        let o = self.positions.first()?.map(|v| v as f64);
        let (mut vol, mut mx, mut my) = (0.0, 0.0, 0.0);
        for t in self.triangles.iter() {
            // Tetrahedra from the first vertex, which keeps the sums small far from the origin.
            let [a, b, c] = t.map(|i| {
                let p = self.positions[i as usize];
                [p[0] as f64 - o[0], p[1] as f64 - o[1], p[2] as f64 - o[2]]
            });
            let v = (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0;
            vol += v;
            mx += v * (a[0] + b[0] + c[0]) / 4.0;
            my += v * (a[1] + b[1] + c[1]) / 4.0;
        }
        let (lo, hi) = self.plan_bounds()?;
        let (x, y) = if vol > 1e-6 {
            (o[0] + mx / vol, o[1] + my / vol)
        } else {
            ((lo.0 + hi.0) / 2.0, (lo.1 + hi.1) / 2.0)
        };
        // A centroid outside the bounds can only be a mesh that is not closed after all.
        if (lo.0..=hi.0).contains(&x) && (lo.1..=hi.1).contains(&y) {
            Some((x, y))
        } else {
            Some(((lo.0 + hi.0) / 2.0, (lo.1 + hi.1) / 2.0))
        }
    }

    /// The horizontal bounds of the vertices, ((x, y) least, (x, y) most); None without any.
    pub fn plan_bounds(&self) -> Option<((f64, f64), (f64, f64))> {
        let first = self.positions.first()?;
        let start = (first[0] as f64, first[1] as f64);
        Some(self.positions.iter().fold((start, start), |(lo, hi), p| {
            let (x, y) = (p[0] as f64, p[1] as f64);
            ((lo.0.min(x), lo.1.min(y)), (hi.0.max(x), hi.1.max(y)))
        }))
    }

    /// Signed volume (positive for a closed, outward-oriented solid), m³.
    pub fn volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize].map(|v| v as f64));
                (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0]))
                    / 6.0
            })
            .sum()
    }
}

/// What an object is, for LiDAR classes, materials and the scene graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ObjectClass {
    /// The ground surface.
    Terrain,
    /// A building (one or more closed shells).
    Building,
    /// Tree crowns and trunks: absorbing volumes for radio.
    Vegetation,
    /// Cars, poles, signs, shelters.
    Clutter,
    /// A surface not yet split into objects (photogrammetry, a DSM mesh).
    Unsegmented,
}

/// One object of a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneObject {
    /// Stable identifier (e.g. `building-12`).
    pub id: String,
    /// What it is.
    pub class: ObjectClass,
    /// Its geometry.
    pub mesh: Mesh,
}

/// A scene: objects with meshes and per-triangle materials.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    /// In a stable order.
    pub objects: Vec<SceneObject>,
}

impl Scene {
    /// The part of the scene whose horizontal bounds meet the box from `lo` to `hi` (x, y; the
    /// east and north edges out, as a site window's), object by object in their order: an object for which `whole` says yes is kept whole when any of its
    /// triangles meets the box (a building is not cut open), the others are cut to the
    /// triangles that meet it (a city's terrain is one object).
    pub fn near(
        &self,
        lo: (f64, f64),
        hi: (f64, f64),
        whole: impl Fn(&SceneObject) -> bool,
    ) -> Scene {
        let meets = |ps: &[[f32; 3]; 3]| {
            let (mut a, mut b) = (
                (f64::INFINITY, f64::INFINITY),
                (f64::NEG_INFINITY, f64::NEG_INFINITY),
            );
            for p in ps {
                a = (a.0.min(p[0] as f64), a.1.min(p[1] as f64));
                b = (b.0.max(p[0] as f64), b.1.max(p[1] as f64));
            }
            a.0 < hi.0 && b.0 >= lo.0 && a.1 < hi.1 && b.1 >= lo.1
        };
        let corners = |m: &Mesh, t: &[u32; 3]| t.map(|i| m.positions[i as usize]);
        Scene {
            objects: self
                .objects
                .iter()
                .filter_map(|o| {
                    let mesh = if whole(o) {
                        o.mesh
                            .triangles
                            .iter()
                            .any(|t| meets(&corners(&o.mesh, t)))
                            .then(|| o.mesh.clone())?
                    } else {
                        o.mesh.select_triangles(meets)
                    };
                    (!mesh.is_empty()).then(|| SceneObject {
                        id: o.id.clone(),
                        class: o.class,
                        mesh,
                    })
                })
                .collect(),
        }
    }

    /// Leaves out every object whose mesh fails [`Mesh::check`] (a vertex not finite or past
    /// [`MAX_COORD_M`], an index past the vertices), returning each as `id: place: expected`.
    /// What the engine applies to every scene a stage builds: one building at 1e300 m (a height
    /// tag, a terrain cell of 3e38) costs that object, named, not the whole scene its BVH.
    pub fn drop_unsound(&mut self) -> Vec<String> {
        let mut dropped = Vec::new();
        self.objects.retain(|o| match o.mesh.check() {
            Ok(()) => true,
            Err((place, expected)) => {
                dropped.push(format!("{}: {place}: {expected}", o.id));
                false
            }
        });
        dropped
    }

    /// [`Mesh::check`] for every object, the place naming the object.
    pub fn check(&self) -> Result<(), (String, String)> {
        for o in &self.objects {
            o.mesh
                .check()
                .map_err(|(place, m)| (format!("object {:?}, {place}", o.id), m))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unsound_objects_are_left_out_and_named() {
        let mut bad = strip("far", ObjectClass::Building, 0.0);
        bad.mesh.positions.0[1][2] = 3e38;
        let mut scene = Scene {
            objects: vec![strip("a", ObjectClass::Building, 0.0), bad],
        };
        let dropped = scene.drop_unsound();
        assert_eq!(scene.objects.len(), 1);
        assert_eq!(scene.objects[0].id, "a");
        assert_eq!(dropped.len(), 1);
        assert!(
            dropped[0].starts_with("far: vertex 1: a finite z") && dropped[0].contains("3e38"),
            "{dropped:?}"
        );
    }

    /// Two triangles side by side along x, 0-10 m and 10-20 m (a quad each half).
    fn strip(id: &str, class: ObjectClass, x0: f32) -> SceneObject {
        SceneObject {
            id: id.into(),
            class,
            mesh: Mesh {
                positions: PodVec(vec![
                    [x0, 0.0, 0.0],
                    [x0 + 10.0, 0.0, 0.0],
                    [x0 + 10.0, 10.0, 0.0],
                    [x0 + 20.0, 10.0, 0.0],
                ]),
                triangles: PodVec(vec![[0, 1, 2], [1, 3, 2]]),
                materials: PodVec(vec![0, 1]),
            },
        }
    }

    #[test]
    fn near_keeps_whole_what_it_is_told_and_cuts_the_rest() {
        let scene = Scene {
            objects: vec![
                strip("ground", ObjectClass::Terrain, 0.0),
                strip("house", ObjectClass::Building, 0.0),
                strip("far", ObjectClass::Building, 100.0),
            ],
        };
        // A box over x 0-5: only the first triangle of each strip at 0 meets it.
        let near = scene.near((0.0, 0.0), (5.0, 5.0), |o| o.class == ObjectClass::Building);
        let ids: Vec<&str> = near.objects.iter().map(|o| o.id.as_str()).collect();
        assert_eq!(ids, ["ground", "house"]);
        assert_eq!(near.objects[0].mesh.triangles.len(), 1);
        assert_eq!(near.objects[0].mesh.positions.len(), 3);
        assert_eq!(near.objects[1].mesh, scene.objects[1].mesh);
        // The east and north edges are out, as a window's: a box ending where a strip begins
        // does not take it.
        let before = scene.near((-10.0, 0.0), (0.0, 5.0), |_| true);
        assert!(before.objects.is_empty());
    }
}
