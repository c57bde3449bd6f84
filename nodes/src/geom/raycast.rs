//! Ray casting against a scene: every triangle of every object in one 8-wide BVH
//! ([`super::wide_bvh`], collapsed from obvhs's BVH2, built single-threaded so its layout is the
//! same on every run). Equal hits resolve to the lower triangle index, so a hit depends on neither
//! the layout nor the SIMD path.

use std::time::Duration;

use glam::Vec3A;
use obvhs::BvhBuildParams;
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::ploc::PlocSearchDistance;
use obvhs::triangle::Triangle;

pub use super::sheared_ray::ShearedRay;
pub use super::wide_bvh::PACKET;
use super::wide_bvh::{WideBvh, WideHit};
use crate::artifact::Scene;

/// Scenes up to this many triangles get the thorough build (a wide PLOC search, then reinsertion).
const THOROUGH_BUILD_MAX: usize = 250_000;

/// Fewer rays of one octant than this are cast one by one: a packet's set-up would cost more
/// than it saves.
const MIN_PACKET: usize = 4;

/// Packets whose directions spread wider than this (per component, about the angle in radians)
/// are cast ray by ray: the packet's bounds then enter boxes few of its rays do. Measured with
/// `cargo bench --bench raycast -- cast` (8 x 8 tiles of a panorama, packets against one by
/// one, packets that outgrow a node going on ray by ray below it): on munich 3.0 times faster
/// at 1.4 degrees, 2.1 times at 5.6; on the 1 km synthetic city seen from above its roofs 2.2
/// times at 1.4 degrees and 0.6 at 5.6. The bound keeps tiles up to about 2.9 degrees (a street
/// view's 8 x 8 pixels of 320 across 90 degrees span 2.25).
const MAX_SPREAD: f32 = 0.05;

/// Packets whose origins spread wider than this many times the scene's median leaf
/// ([`WideBvh::leaf_size`]) are cast ray by ray: near its leaves such a packet splits into lone
/// rays below nodes it entered only as a whole. Measured on a radio map's reflected rays
/// (`cargo bench --bench raycast -- cast --patch-order`): on the 1 km synthetic city (leaves of
/// 2 m) the bounces ran at 4.1 M rays/s per core with no limit and 5.1 with 4 m, on munich
/// (leaves of 16 m) at 24.0-24.5 with no limit and 23.9-24.5 with 32 m: munich's far ground
/// reflections go to the sky side by side, and a packet culls them all at once.
const MAX_ORIGIN_SPREAD_LEAVES: f32 = 2.0;

/// Whether the rays `run` of `chunk` point within [`MAX_SPREAD`] of one another and start within
/// `origin_spread` metres.
fn narrow(chunk: &[([f32; 3], [f32; 3])], run: &[u8], origin_spread: f32) -> bool {
    let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    let (mut o_lo, mut o_hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for &k in run {
        let (o, d) = chunk[k as usize];
        let (o, d) = (Vec3A::from(o), Vec3A::from(d));
        (lo, hi) = (lo.min(d), hi.max(d));
        (o_lo, o_hi) = (o_lo.min(o), o_hi.max(o));
    }
    (hi - lo).max_element() <= MAX_SPREAD && (o_hi - o_lo).max_element() <= origin_spread
}

/// The pixels of a `width` x `height` image in tiles of 8 x 8, row by row within a tile: the
/// order in which neighbouring pixels' rays form packets for [`SceneRays::cast_coherent`].
pub fn tile_order(width: u32, height: u32) -> Vec<u32> {
    tiles_of(width, height, 8)
}

/// The cells of a `width` x `height` grid in tiles of `side` x `side` (at least 1), row by row
/// within a tile, the tiles row by row.
pub fn tiles_of(width: u32, height: u32, side: u32) -> Vec<u32> {
    let side = side.max(1);
    let mut order = Vec::with_capacity((width as usize) * (height as usize));
    for ty in (0..height).step_by(side as usize) {
        for tx in (0..width).step_by(side as usize) {
            for v in ty..(ty + side).min(height) {
                for u in tx..(tx + side).min(width) {
                    order.push(v * width + u);
                }
            }
        }
    }
    order
}

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
    bvh: WideBvh,
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
        let bvh = if tris.is_empty() {
            WideBvh::empty()
        } else {
            // Leaves of one packet: four triangles cost one SSE test.
            // A more thorough build cuts the time per cast for a build that costs about 10^4
            // casts; past `THOROUGH_BUILD_MAX` triangles the build time would outweigh it.
            // Measured on munich (docs/benchmarks-log.md, 2026-11-27, commit 5ff914a): PLOC searching 14
            // neighbours in every merging pass after the first, without pre-splitting, casts
            // bounce rays 7-11 % faster than obvhs's `slow_build` (24 neighbours after the
            // second pass, pre-split) and shadow rays 7 % slower, in the same build time. The
            // hits are the same whatever the tree.
            let base = if tris.len() <= THOROUGH_BUILD_MAX {
                BvhBuildParams {
                    pre_split: false,
                    ploc_search_distance: PlocSearchDistance::Medium,
                    search_depth_threshold: 1,
                    ..BvhBuildParams::slow_build()
                }
            } else {
                BvhBuildParams::medium_build()
            };
            let params = BvhBuildParams {
                max_prims_per_leaf: super::tri_packet::LANES as u32,
                ..base
            };
            let bvh2 = build_bvh2_from_tris(&tris, params, &mut Duration::default());
            WideBvh::new(&bvh2, &tris)
        };
        SceneRays { tris, owner, bvh }
    }

    /// Traverses with the scalar box test even where AVX2 is available (tests compare the two).
    pub fn force_scalar(&mut self) {
        self.bvh.force_scalar();
    }

    /// True when casting uses AVX2.
    pub fn uses_simd(&self) -> bool {
        self.bvh.uses_simd()
    }

    /// The wide BVH (the GPU backend uploads it).
    pub fn wide_bvh(&self) -> &WideBvh {
        &self.bvh
    }

    /// The number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// True for a scene without triangles.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The closest hit of the ray from `origin` along the unit vector `dir` within (`tmin`, `tmax`).
    // Always inlined: left to the inliner, the radio map's bounce loop came to call it out as
    // the crate grew, and the map took 15 % longer (docs/benchmarks-log.md, 2026-11-27, commit 34e95bb).
    #[inline(always)]
    pub fn cast(&self, origin: [f32; 3], dir: [f32; 3], tmin: f32, tmax: f32) -> Option<Hit> {
        self.closest(origin, dir, tmin, tmax).map(|h| self.hit(h))
    }

    /// The BVH's closest hit. -0.0 and +0.0 must cast alike (computed directions carry either).
    #[inline(always)]
    fn closest(&self, origin: [f32; 3], dir: [f32; 3], tmin: f32, tmax: f32) -> Option<WideHit> {
        let dir = dir.map(|c| c + 0.0);
        self.bvh
            .closest(Vec3A::from(origin), Vec3A::from(dir), tmin, tmax)
    }

    #[inline(always)]
    fn hit(&self, hit: WideHit) -> Hit {
        let prim = hit.prim as usize;
        let (object, triangle) = self.owner[prim];
        Hit {
            t: hit.t,
            object: object as usize,
            triangle: triangle as usize,
            normal: self.normal(prim).into(),
        }
    }

    /// The unit geometric normal of the BVH's triangle `prim`, as a hit on it gives.
    #[inline(always)]
    fn normal(&self, prim: usize) -> Vec3A {
        let tri = &self.tris[prim];
        (tri.v1 - tri.v0).cross(tri.v2 - tri.v0).normalize_or_zero()
    }

    /// Every triangle's normal as [`SceneRays::cast`] gives it, indexed as the BVH's hits name
    /// triangles (`WideHit::prim`): what a GPU copy of the tree needs beside it.
    pub fn prim_normals(&self) -> Vec<[f32; 3]> {
        (0..self.tris.len())
            .map(|p| self.normal(p).into())
            .collect()
    }

    /// The closest hits of the rays of a `width` x `height` grid (a camera's pixels, a raster's
    /// cells), in row-major order: `ray(x, y)` gives the (origin, unit direction) of cell (x, y).
    /// Cast in 8 x 8 tiles, each a packet ([`SceneRays::cast_coherent`]).
    pub fn cast_grid(
        &self,
        width: u32,
        height: u32,
        ray: impl Fn(u32, u32) -> ([f32; 3], [f32; 3]),
        tmin: f32,
        tmax: f32,
    ) -> Vec<Option<Hit>> {
        let order = tile_order(width, height);
        let rays: Vec<_> = order.iter().map(|&i| ray(i % width, i / width)).collect();
        let mut hits = vec![None; order.len()];
        for (&i, hit) in order.iter().zip(self.cast_coherent(&rays, tmin, tmax)) {
            hits[i as usize] = hit;
        }
        hits
    }

    /// The closest hits of many (origin, unit direction) rays within (`tmin`, `tmax`), in order:
    /// [`SceneRays::cast`] of each, bit for bit. Runs of up to [`PACKET`] consecutive rays that
    /// lie close together (a tile of a camera's pixels, see [`tile_order`]; parallel rays over a
    /// patch of a grid) traverse the BVH as one packet, testing each inner node once for all of
    /// them; scattered rays gain nothing but lose nothing in the result.
    pub fn cast_coherent(
        &self,
        rays: &[([f32; 3], [f32; 3])],
        tmin: f32,
        tmax: f32,
    ) -> Vec<Option<Hit>> {
        let mut out = vec![None; rays.len()];
        self.packets(rays, tmin, tmax, |i, h| out[i] = h.map(|h| self.hit(h)));
        out
    }

    /// [`SceneRays::cast_coherent`] as [`SceneRays::cast_index`] answers: distance and
    /// triangle index.
    pub fn cast_coherent_index(
        &self,
        rays: &[([f32; 3], [f32; 3])],
        tmin: f32,
        tmax: f32,
    ) -> Vec<Option<(f32, u32)>> {
        let mut out = vec![None; rays.len()];
        self.cast_coherent_each(rays, tmin, tmax, |i, h| out[i] = h);
        out
    }

    /// [`SceneRays::cast_coherent_index`] telling `found` each ray's index and answer as it
    /// comes (in no set order), for callers that keep hits in their own form.
    pub fn cast_coherent_each(
        &self,
        rays: &[([f32; 3], [f32; 3])],
        tmin: f32,
        tmax: f32,
        mut found: impl FnMut(usize, Option<(f32, u32)>),
    ) {
        self.packets(rays, tmin, tmax, |i, h| found(i, h.map(|h| (h.t, h.prim))));
    }

    /// [`SceneRays::cast_coherent_index`] with the packets cut where the caller says: `runs`
    /// are the lengths of consecutive runs of `rays` (a longer one is cut every [`PACKET`];
    /// rays past them go in runs of [`PACKET`]), each cast as packets of one octant. For rays
    /// whose natural groups are smaller than a packet (the samples of a tile near an edge), so
    /// that a packet does not span two.
    pub fn cast_runs_index(
        &self,
        rays: &[([f32; 3], [f32; 3])],
        runs: &[u32],
        tmin: f32,
        tmax: f32,
    ) -> Vec<Option<(f32, u32)>> {
        let mut out = vec![None; rays.len()];
        let mut ranges = Vec::with_capacity(runs.len());
        let mut start = 0usize;
        for &n in runs {
            let end = (start + n as usize).min(rays.len());
            ranges.extend(
                (start..end)
                    .step_by(PACKET)
                    .map(|a| a..(a + PACKET).min(end)),
            );
            start = end;
        }
        // Rays past the runs go in plain packets of PACKET.
        ranges.extend(
            (start..rays.len())
                .step_by(PACKET)
                .map(|a| a..(a + PACKET).min(rays.len())),
        );
        self.packets_in(rays, ranges.into_iter(), tmin, tmax, |i, h| {
            out[i] = h.map(|h| (h.t, h.prim))
        });
        out
    }

    /// Casts `rays` in packets of one octant within each run of [`PACKET`], telling `found`
    /// each ray's index and hit.
    fn packets(
        &self,
        rays: &[([f32; 3], [f32; 3])],
        tmin: f32,
        tmax: f32,
        found: impl FnMut(usize, Option<WideHit>),
    ) {
        let ranges = (0..rays.len())
            .step_by(PACKET)
            .map(|s| s..(s + PACKET).min(rays.len()));
        self.packets_in(rays, ranges, tmin, tmax, found);
    }

    /// Casts the rays of each range (at most [`PACKET`] long) in packets of one octant.
    fn packets_in(
        &self,
        rays: &[([f32; 3], [f32; 3])],
        ranges: impl Iterator<Item = std::ops::Range<usize>>,
        tmin: f32,
        tmax: f32,
        mut found: impl FnMut(usize, Option<WideHit>),
    ) {
        let origin_spread = MAX_ORIGIN_SPREAD_LEAVES * self.bvh.leaf_size();
        let mut hits = [None; PACKET];
        let mut origins = [Vec3A::ZERO; PACKET];
        let mut dirs = [Vec3A::ZERO; PACKET];
        for range in ranges {
            let c0 = range.start;
            let chunk = &rays[range];
            debug_assert!(chunk.len() <= PACKET);
            // A packet's rays share their directions' signs: a tile across an axis splits into up
            // to eight, by a stable counting sort on the octant. Non-finite rays (octant 8) are
            // cast alone; they hit nothing.
            let mut key = [0u8; PACKET];
            let mut count = [0usize; 10];
            for (k, (_, d)) in chunk.iter().enumerate() {
                key[k] = if d.iter().all(|c| c.is_finite()) {
                    (0..3)
                        .map(|a| ((d[a] + 0.0).is_sign_negative() as u8) << a)
                        .sum()
                } else {
                    8
                };
                count[key[k] as usize + 1] += 1;
            }
            for o in 1..10 {
                count[o] += count[o - 1];
            }
            let start = count;
            let mut sorted = [0u8; PACKET];
            for (k, &o) in key[..chunk.len()].iter().enumerate() {
                sorted[count[o as usize]] = k as u8;
                count[o as usize] += 1;
            }
            for o in 0..9 {
                let run = &sorted[start[o]..start[o + 1]];
                if o == 8 || run.len() < MIN_PACKET || !narrow(chunk, run, origin_spread) {
                    for &k in run {
                        let (origin, dir) = chunk[k as usize];
                        found(c0 + k as usize, self.closest(origin, dir, tmin, tmax));
                    }
                    continue;
                }
                for (j, &k) in run.iter().enumerate() {
                    let (origin, dir) = chunk[k as usize];
                    origins[j] = Vec3A::from(origin);
                    dirs[j] = Vec3A::from(dir.map(|c| c + 0.0));
                }
                let n = run.len();
                self.bvh
                    .closest_packet(&origins[..n], &dirs[..n], tmin, tmax, &mut hits[..n]);
                for (&k, h) in run.iter().zip(&hits[..n]) {
                    found(c0 + k as usize, *h);
                }
            }
        }
    }

    /// The closest hit's distance and triangle index (counting every object's triangles in
    /// order, as the radio scene (`rf::scene::RfScene`) does): [`SceneRays::cast`] without the normal.
    pub fn cast_index(
        &self,
        origin: [f32; 3],
        dir: [f32; 3],
        tmin: f32,
        tmax: f32,
    ) -> Option<(f32, u32)> {
        self.closest(origin, dir, tmin, tmax).map(|h| (h.t, h.prim))
    }

    /// Whether any surface lies on the ray from `origin` along `dir` within (`tmin`, `tmax`):
    /// [`SceneRays::cast`] finding something, without looking for the closest.
    pub fn occluded(&self, origin: [f32; 3], dir: [f32; 3], tmin: f32, tmax: f32) -> bool {
        let dir = dir.map(|c| c + 0.0);
        self.bvh
            .any(Vec3A::from(origin), Vec3A::from(dir), tmin, tmax)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::artifact::{ObjectClass, SceneObject};
    use crate::geom::mesh_build::cuboid;

    /// Every cell once and each tile's cells together, for sizes the tiles do not divide (and a
    /// side of 0, taken as 1).
    #[test]
    fn tiles_cover_the_grid_once_each_tile_together() {
        for (w, h, side) in [(20, 15, 4), (7, 3, 8), (5, 5, 1), (3, 4, 0), (0, 4, 2)] {
            let order = tiles_of(w, h, side);
            let mut seen = order.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..w * h).collect::<Vec<_>>(), "{w} x {h} by {side}");
            let side = side.max(1);
            let tile = |k: u32| (k / w / side, k % w / side);
            for pair in order.windows(2) {
                let (a, b) = (tile(pair[0]), tile(pair[1]));
                // A tile's cells come together: the order moves to a later tile, never back.
                assert!(
                    a == b || (b.0, b.1) > (a.0, a.1),
                    "{w} x {h} by {side}: {pair:?}"
                );
            }
        }
        assert_eq!(tile_order(16, 8), tiles_of(16, 8, 8));
    }

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

    /// Rays through the shared diagonal of a quad, and through its shared corner, hit it.
    #[test]
    fn rays_through_shared_edges_and_vertices_hit() {
        let quad = Scene {
            objects: vec![SceneObject {
                id: "q".into(),
                class: ObjectClass::Building,
                mesh: crate::artifact::Mesh {
                    positions: crate::artifact::PodVec(vec![
                        [50.0, -20.0, -20.0],
                        [50.0, 20.0, -20.0],
                        [50.0, 20.0, 20.0],
                        [50.0, -20.0, 20.0],
                    ]),
                    triangles: crate::artifact::PodVec(vec![[0, 1, 2], [0, 2, 3]]),
                    materials: crate::artifact::PodVec(vec![0, 0]),
                },
            }],
        };
        let rays = SceneRays::new(&quad);
        for target in [[50.0f32, 0.0, 0.0], [50.0, 7.5, 7.5], [50.0, -20.0, -20.0]] {
            let o = [0.0f32, 0.3, -0.2];
            let d = [target[0] - o[0], target[1] - o[1], target[2] - o[2]];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let h = rays.cast(o, d.map(|c| c / l), 0.0, 1e3);
            assert!(h.is_some(), "missed {target:?}");
        }
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
