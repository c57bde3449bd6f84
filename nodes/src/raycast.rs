//! Ray casting against a scene: every triangle of every object in one compressed wide BVH
//! (obvhs CWBVH, built single-threaded so its layout, and so every tie between equal hits, is the
//! same on every run).

use std::time::Duration;

use glam::Vec3A;
use obvhs::BvhBuildParams;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;

use crate::artifact::Scene;

/// The closest intersection of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) direction.
    pub t: f32,
    /// Index of the object in the scene.
    pub object: usize,
    /// Index of the triangle in that object's mesh.
    pub triangle: usize,
    /// Unit geometric normal (outward for closed solids).
    pub normal: [f32; 3],
}

/// A scene prepared for ray casting.
pub struct SceneRays {
    tris: Vec<Triangle>,
    owner: Vec<(u32, u32)>,
    bvh: Option<CwBvh>,
}

impl SceneRays {
    /// Builds the BVH over every triangle of `scene`.
    pub fn new(scene: &Scene) -> SceneRays {
        let mut tris = Vec::new();
        let mut owner = Vec::new();
        for (o, obj) in scene.objects.iter().enumerate() {
            let p = &obj.mesh.positions;
            for (k, t) in obj.mesh.triangles.iter().enumerate() {
                let v = |i: u32| Vec3A::from(p[i as usize]);
                tris.push(Triangle {
                    v0: v(t[0]),
                    v1: v(t[1]),
                    v2: v(t[2]),
                });
                owner.push((o as u32, k as u32));
            }
        }
        let bvh = (!tris.is_empty()).then(|| {
            build_cwbvh_from_tris(
                &tris,
                BvhBuildParams::medium_build(),
                &mut Duration::default(),
            )
        });
        SceneRays { tris, owner, bvh }
    }

    /// The closest hit of the ray from `origin` along the unit vector `dir` within (`tmin`, `tmax`).
    pub fn cast(&self, origin: [f32; 3], dir: [f32; 3], tmin: f32, tmax: f32) -> Option<Hit> {
        let bvh = self.bvh.as_ref()?;
        // obvhs picks the traversal octant from the direction's sign bits: a -0.0 component
        // (common in computed directions) sends it the wrong way and the ray misses everything.
        // Adding +0.0 turns -0.0 into +0.0 and leaves every other value as it is.
        let dir = dir.map(|c| c + 0.0);
        let ray = Ray::new(Vec3A::from(origin), Vec3A::from(dir), tmin, tmax);
        let mut hit = RayHit::none();
        if !bvh.ray_traverse(ray, &mut hit, |r, id| {
            self.tris[bvh.primitive_indices[id] as usize].intersect(r)
        }) {
            return None;
        }
        let prim = bvh.primitive_indices[hit.primitive_id as usize] as usize;
        let tri = &self.tris[prim];
        let n = (tri.v1 - tri.v0).cross(tri.v2 - tri.v0).normalize_or_zero();
        let (object, triangle) = self.owner[prim];
        Some(Hit {
            t: hit.t,
            object: object as usize,
            triangle: triangle as usize,
            normal: n.into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{ObjectClass, SceneObject};
    use crate::materials::Material;
    use crate::mesh_build::cuboid;

    #[test]
    fn hits_the_nearest_face_with_an_outward_normal() {
        let scene = Scene {
            objects: vec![
                SceneObject {
                    id: "a".into(),
                    class: ObjectClass::Building,
                    mesh: cuboid([0.0, 0.0], [10.0, 10.0, 10.0], 0.0, 0.0, Material::Concrete),
                },
                SceneObject {
                    id: "b".into(),
                    class: ObjectClass::Building,
                    mesh: cuboid([0.0, 0.0], [2.0, 2.0, 2.0], 0.0, 20.0, Material::Metal),
                },
            ],
        };
        let rays = SceneRays::new(&scene);
        let h = rays
            .cast([0.0, 0.0, 100.0], [0.0, 0.0, -1.0], 0.0, f32::INFINITY)
            .unwrap();
        assert_eq!((h.object, h.t), (1, 78.0));
        assert_eq!(h.normal, [0.0, 0.0, 1.0]);
        let h = rays
            .cast([3.0, 0.0, 100.0], [0.0, 0.0, -1.0], 0.0, f32::INFINITY)
            .unwrap();
        assert_eq!((h.object, h.t), (0, 90.0));
        let side = rays
            .cast([50.0, 1.0, 5.0], [-1.0, 0.0, 0.0], 0.0, f32::INFINITY)
            .unwrap();
        assert_eq!((side.t, side.normal), (45.0, [1.0, 0.0, 0.0]));
        assert!(
            rays.cast([50.0, 1.0, 5.0], [1.0, 0.0, 0.0], 0.0, f32::INFINITY)
                .is_none()
        );
    }

    /// Regression: a direction with a -0.0 component missed everything (found by the façade
    /// relief test, whose probe directions were computed as -outward).
    #[test]
    fn negative_zero_components_hit_like_positive_ones() {
        let scene = Scene {
            objects: vec![SceneObject {
                id: "a".into(),
                class: ObjectClass::Building,
                mesh: cuboid([0.0, 5.0], [10.0, 2.0, 10.0], 0.0, 0.0, Material::Concrete),
            }],
        };
        let rays = SceneRays::new(&scene);
        for o in [[0.0f32, -3.0, 1.0], [2.7, -3.0, 4.2], [-4.9, -3.0, 9.9]] {
            let plus = rays.cast(o, [0.0, 1.0, 0.0], 0.0, 100.0);
            let minus = rays.cast(o, [-0.0, 1.0, -0.0], 0.0, 100.0);
            assert!(plus.is_some());
            assert_eq!(plus, minus);
        }
    }
}
