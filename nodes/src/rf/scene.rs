//! A scene prepared for radio tracing: triangles in f64 with unit normals, per-triangle materials
//! with their complex permittivity at the carrier, and a BVH for casting.

use glam::DVec3;
use num_complex::Complex64 as C64;

use crate::artifact::Material;
use crate::artifact::Scene;
use crate::geom::raycast::SceneRays;

use super::em::{permittivity, slab};

/// Sionna's default slab thickness for every surface, metres (what its scene files assume unless
/// they say otherwise). Our scenes use [`Material::slab_thickness_m`] per material.
pub const SLAB_THICKNESS_M: f64 = 0.1;

/// How far a ray keeps clear of the surface it leaves (and of a segment's ends), metres.
pub const EPS: f64 = 1e-3;

/// A surface hit along a ray.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    /// Distance along the ray, metres.
    pub t: f64,
    /// Global triangle index.
    pub triangle: u32,
}

/// The traceable scene.
pub struct RfScene {
    /// The BVH; its triangle indices are ours (both count every object's triangles in order).
    rays: SceneRays,
    /// Triangle vertices.
    pub tris: Vec<[DVec3; 3]>,
    /// Unit normals (zero for degenerate triangles).
    pub normals: Vec<DVec3>,
    /// Material per triangle.
    pub material: Vec<Material>,
    /// The index of the scene object each triangle comes from.
    pub object: Vec<u32>,
    eta: Vec<Option<C64>>,
    /// Slab thickness per material (index = discriminant), metres.
    thickness: Vec<f64>,
    /// The carrier's wavelength, metres.
    pub wavelength: f64,
    /// Axis-aligned bounds of every vertex.
    pub bounds: (DVec3, DVec3),
    /// Whether any triangle is foliage (asked once per ray segment, so kept).
    foliage: bool,
}

/// The least and most corner of `scene`'s triangles: [`RfScene::bounds`] without building the
/// radio scene.
pub fn scene_bounds(scene: &Scene) -> (DVec3, DVec3) {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for obj in &scene.objects {
        let p = &obj.mesh.positions;
        for t in obj.mesh.triangles.iter() {
            for i in t {
                let q = DVec3::from(p[*i as usize].map(f64::from));
                lo = lo.min(q);
                hi = hi.max(q);
            }
        }
    }
    (lo, hi)
}

impl RfScene {
    /// Prepares `scene` at `freq_hz`. A material outside its P.2040 frequency range is an error
    /// unless `extrapolate`.
    pub fn new(scene: &Scene, freq_hz: f64, extrapolate: bool) -> Result<RfScene, String> {
        if !(freq_hz > 0.0 && freq_hz.is_finite()) {
            return Err(format!("frequency {freq_hz} Hz is not a positive number"));
        }
        let (mut tris, mut normals, mut material) = (Vec::new(), Vec::new(), Vec::new());
        let mut object = Vec::new();
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for (o, obj) in scene.objects.iter().enumerate() {
            let p = &obj.mesh.positions;
            for (k, t) in obj.mesh.triangles.iter().enumerate() {
                let v = t.map(|i| DVec3::from(p[i as usize].map(f64::from)));
                for q in v {
                    lo = lo.min(q);
                    hi = hi.max(q);
                }
                tris.push(v);
                object.push(o as u32);
                normals.push((v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero());
                let m = obj
                    .mesh
                    .materials
                    .get(k)
                    .copied()
                    .unwrap_or(Material::Concrete as u8);
                material.push(
                    Material::from_u8(m)
                        .ok_or_else(|| format!("{}: unknown material id {m}", obj.id))?,
                );
            }
        }
        let mut eta = vec![None; Material::ALL.len()];
        let used: std::collections::BTreeSet<Material> = material.iter().copied().collect();
        for m in used {
            if m != Material::Foliage {
                eta[m as usize] = Some(permittivity(m, freq_hz, extrapolate)?);
            }
        }
        Ok(RfScene {
            rays: SceneRays::new(scene),
            tris,
            normals,
            foliage: material.contains(&Material::Foliage),
            material,
            object,
            eta,
            thickness: Material::ALL.iter().map(|m| m.slab_thickness_m()).collect(),
            wavelength: super::wavelength(freq_hz),
            bounds: (lo, hi),
        })
    }

    /// Every surface a slab of `d` metres, whatever its material: a scene made for Sionna's
    /// default ([`SLAB_THICKNESS_M`]), traced as Sionna traces it.
    pub fn with_uniform_thickness(mut self, d: f64) -> RfScene {
        self.thickness = vec![d; Material::ALL.len()];
        self
    }

    /// Material `m` with the relative permittivity `eta` (ε' − jσ/(ε0 ω)) instead of its P.2040
    /// value: a twin calibrated against measurements, or a synthetic truth whose materials are
    /// not the twin's. A material no triangle uses stays unused.
    pub fn with_permittivity(mut self, m: Material, eta: C64) -> RfScene {
        if self.eta[m as usize].is_some() {
            self.eta[m as usize] = Some(eta);
        }
        self
    }

    /// Surfaces of material `m` as slabs of `d` metres (a scene file's own thickness).
    pub fn with_thickness(mut self, m: Material, d: f64) -> RfScene {
        self.thickness[m as usize] = d;
        self
    }

    /// The scene's ray caster (the GPU backend uploads its BVH).
    pub fn rays(&self) -> &SceneRays {
        &self.rays
    }

    /// The closest surface along `o + t d` for t in (`tmin`, `tmax`).
    // Always inlined: left to the inliner, the radio map's bounce loop came to call it out as
    // the crate grew, and the map took 15 % longer (docs/benchmarks-log.md, 2026-11-27, commit 34e95bb).
    #[inline(always)]
    pub fn cast(&self, o: DVec3, d: DVec3, tmin: f64, tmax: f64) -> Option<SurfaceHit> {
        let hit = self.rays.cast_index(
            o.as_vec3().into(),
            d.as_vec3().into(),
            tmin as f32,
            tmax.min(f32::MAX as f64) as f32,
        )?;
        Some(self.refine(o, d, tmin, hit))
    }

    /// [`RfScene::cast`] from `o` along each of `dirs`, the same hits bit for bit, in order.
    /// Consecutive directions that lie close together (a patch of the launch lattice,
    /// [`crate::rf::fibonacci::patch_order`]) traverse the BVH as one packet
    /// ([`crate::geom::raycast::SceneRays::cast_coherent`]).
    pub fn cast_fan(
        &self,
        o: DVec3,
        dirs: &[DVec3],
        tmin: f64,
        tmax: f64,
    ) -> Vec<Option<SurfaceHit>> {
        let origin = o.as_vec3().to_array();
        let narrow: Vec<_> = dirs
            .iter()
            .map(|d| (origin, d.as_vec3().to_array()))
            .collect();
        self.cast_each(&narrow, |i| (o, dirs[i]), tmin, tmax)
    }

    /// [`RfScene::cast`] of each (origin, direction) of `rays`, the same hits bit for bit.
    /// Consecutive rays that lie close together traverse the BVH as one packet
    /// ([`crate::geom::raycast::SceneRays::cast_coherent`]).
    pub fn cast_coherent(
        &self,
        rays: &[(DVec3, DVec3)],
        tmin: f64,
        tmax: f64,
    ) -> Vec<Option<SurfaceHit>> {
        let narrow: Vec<_> = rays
            .iter()
            .map(|(o, d)| (o.as_vec3().to_array(), d.as_vec3().to_array()))
            .collect();
        self.cast_each(&narrow, |i| rays[i], tmin, tmax)
    }

    /// The coherent cast of `narrow`, ray i being `ray(i)` in f32, each hit refined.
    fn cast_each(
        &self,
        narrow: &[([f32; 3], [f32; 3])],
        ray: impl Fn(usize) -> (DVec3, DVec3),
        tmin: f64,
        tmax: f64,
    ) -> Vec<Option<SurfaceHit>> {
        let mut hits = vec![None; narrow.len()];
        self.rays.cast_coherent_each(
            narrow,
            tmin as f32,
            tmax.min(f32::MAX as f64) as f32,
            |i, hit| {
                let (o, d) = ray(i);
                hits[i] = hit.map(|h| self.refine(o, d, tmin, h));
            },
        );
        hits
    }

    /// Recomputes an f32 hit's distance in f64 against the triangle's plane: the BVH works in
    /// f32. A ray grazing the plane makes that division worse than the f32 hit (it once put a hit
    /// 1 mm ahead at t = 0, and a walk stepping from hit to hit stood still), so it refines only
    /// within the f32 hit's own error, and never below `tmin`.
    fn refine(&self, o: DVec3, d: DVec3, tmin: f64, (t32, triangle): (f32, u32)) -> SurfaceHit {
        let n = self.normals[triangle as usize];
        let denom = n.dot(d);
        let t64 = n.dot(self.tris[triangle as usize][0] - o) / denom;
        let t = if denom.abs() > 1e-12 && (t64 - t32 as f64).abs() <= 1e-3 * (1.0 + t32 as f64) {
            t64.max(tmin)
        } else {
            t32 as f64
        };
        SurfaceHit { t, triangle }
    }

    /// Whether a surface other than foliage lies strictly between `a` and `b` (`eps` metres kept
    /// clear at each end): one any-hit query where the scene has no foliage.
    pub fn blocked(&self, a: DVec3, b: DVec3, eps: f64) -> bool {
        if self.has_foliage() {
            return self
                .hits_between(a, b, eps)
                .iter()
                .any(|h| !self.is_foliage(h.triangle));
        }
        let len = (b - a).length();
        if len <= 2.0 * eps {
            return false;
        }
        let d = (b - a) / len;
        self.rays.occluded(
            a.as_vec3().into(),
            d.as_vec3().into(),
            eps as f32,
            (len - eps) as f32,
        )
    }

    /// Every surface crossed strictly between `a` and `b` (`eps` metres kept clear at each end),
    /// in order.
    pub fn hits_between(&self, a: DVec3, b: DVec3, eps: f64) -> Vec<SurfaceHit> {
        self.hits_between_until(a, b, eps, usize::MAX)
    }

    /// [`RfScene::hits_between`] up to the first surface other than foliage past `walls` of
    /// them: the same list for a caller that gives a path up once it crosses more walls than
    /// that, for fewer casts.
    pub fn hits_between_until(
        &self,
        a: DVec3,
        b: DVec3,
        eps: f64,
        walls: usize,
    ) -> Vec<SurfaceHit> {
        let len = (b - a).length();
        let d = (b - a) / len;
        let mut out = Vec::new();
        let mut tmin = eps;
        let mut solid = 0usize;
        while let Some(h) = self.cast(a, d, tmin, len - eps) {
            if h.t >= len - eps {
                break;
            }
            tmin = h.t.max(tmin) + eps;
            out.push(h);
            if !self.is_foliage(h.triangle) {
                solid += 1;
                if solid > walls {
                    break;
                }
            }
            if out.len() > 10_000 {
                break;
            }
        }
        out
    }

    /// Slab reflection and transmission coefficients ((R_TE, R_TM), (T_TE, T_TM)) of triangle
    /// `tri` at incidence cosine `cos_theta`; foliage is transparent.
    pub fn slab(&self, tri: u32, cos_theta: f64) -> ((C64, C64), (C64, C64)) {
        let m = self.material[tri as usize] as usize;
        match self.eta[m] {
            Some(eta) => slab(
                cos_theta.abs().min(1.0),
                eta,
                self.thickness[m],
                self.wavelength,
            ),
            None => {
                let (zero, one) = (C64::new(0.0, 0.0), C64::new(1.0, 0.0));
                ((zero, zero), (one, one))
            }
        }
    }

    /// How many materials the per-material tables hold (indexed by discriminant).
    pub fn material_count(&self) -> usize {
        self.eta.len()
    }

    /// Relative permittivity and slab thickness of material `m` (a discriminant); `None` for a
    /// transparent material (foliage) or one no triangle uses.
    pub fn slab_params(&self, m: usize) -> Option<(C64, f64)> {
        Some((self.eta.get(m).copied().flatten()?, self.thickness[m]))
    }

    /// True for foliage triangles: volume boundaries, not surfaces.
    pub fn is_foliage(&self, tri: u32) -> bool {
        self.material[tri as usize] == Material::Foliage
    }

    /// True when any triangle is foliage.
    pub fn has_foliage(&self) -> bool {
        self.foliage
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rf::fibonacci::{fibonacci_run, patch_order};
    use crate::rf::test_scenes::{STREET_TX, street_grid};

    /// A fan cast in packets lands where each ray cast alone does, to the bit: in a street grid,
    /// from a point between its blocks, in patch order and in the lattice's own (scattered)
    /// order.
    #[test]
    fn a_fan_lands_where_each_ray_does() {
        let scene = street_grid();
        // Down at 4.5 m, among the blocks.
        let tx = DVec3::new(STREET_TX.x, STREET_TX.y, 4.5);
        // Patches of 1.1 degrees: packets, not rays cast alone.
        let (n, start, len) = (2_000_000, 950_000, 30_000);
        let dirs: Vec<DVec3> = fibonacci_run(n, start, len).collect();
        let mut landed = 0;
        for order in [patch_order(n, start, len), (0..len).collect::<Vec<u32>>()] {
            let ordered: Vec<DVec3> = order.iter().map(|&k| dirs[k as usize]).collect();
            let fan = scene.cast_fan(tx, &ordered, EPS, 400.0);
            for (d, hit) in ordered.iter().zip(&fan) {
                let alone = scene.cast(tx, *d, EPS, 400.0);
                assert_eq!(
                    hit.map(|h| (h.t.to_bits(), h.triangle)),
                    alone.map(|h| (h.t.to_bits(), h.triangle)),
                    "{d}"
                );
                landed += hit.is_some() as u32;
            }
        }
        assert!(landed > len, "{landed}");
    }
}
