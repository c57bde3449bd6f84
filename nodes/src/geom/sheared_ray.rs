//! One ray prepared for the watertight ray/triangle test that every cast shares (the scalar
//! leaves of `raycast`, the four-wide leaves of `tri_packet`, the wide BVH's traversal).

use glam::Vec3A;
use obvhs::triangle::Triangle;

/// The per-ray part of the watertight ray/triangle test (Woop, Benthin and Wald, JCGT 2013):
/// the dominant axis and the shear that maps the ray onto +z.
#[derive(Clone, Copy)]
pub struct ShearedRay {
    pub(crate) origin: Vec3A,
    /// The axes that become x, y and z.
    pub(crate) k: [usize; 3],
    /// The shear (x and y per unit z) and 1 / the direction's z.
    pub(crate) s: [f32; 3],
    pub(crate) tmin: f32,
}

impl ShearedRay {
    /// Prepares the ray `origin + t dir` for [`ShearedRay::intersect`].
    #[inline]
    pub fn new(origin: Vec3A, dir: Vec3A, tmin: f32) -> ShearedRay {
        let a = dir.abs();
        let kz = if a.x > a.y {
            if a.x > a.z { 0 } else { 2 }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        ShearedRay {
            origin,
            k: [kx, ky, kz],
            s: [dir[kx] / dir[kz], dir[ky] / dir[kz], 1.0 / dir[kz]],
            tmin,
        }
    }

    /// Watertight ray/triangle intersection: a ray through an edge or vertex shared by two
    /// triangles hits at least one of them, which Möller-Trumbore (what obvhs ships) does not
    /// guarantee. Radio paths aim at such points (reflection points on diagonals, cell centres at
    /// vertices), so misses there would let rays through walls. Returns the distance, or infinity
    /// on a miss.
    #[inline]
    pub fn intersect(&self, tri: &Triangle, tmax: f32) -> f32 {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.s;
        let (a, b, c) = (
            tri.v0 - self.origin,
            tri.v1 - self.origin,
            tri.v2 - self.origin,
        );
        let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
        let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
        let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
        let (mut u, mut v, mut w) = (cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax);
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // On an edge in f32: decide in f64 so both neighbours agree.
            let f =
                |p: f32, q: f32, r: f32, s: f32| (p as f64 * q as f64 - r as f64 * s as f64) as f32;
            u = f(cx, by, cy, bx);
            v = f(ax, cy, ay, cx);
            w = f(bx, ay, by, ax);
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return f32::INFINITY;
        }
        let det = u + v + w;
        if det == 0.0 {
            return f32::INFINITY;
        }
        let t = (u * sz * a[kz] + v * sz * b[kz] + w * sz * c[kz]) / det;
        if t > self.tmin && t < tmax {
            t
        } else {
            f32::INFINITY
        }
    }
}
