//! Four triangles against one ray at once: the watertight test of [`ShearedRay::intersect`] run
//! lane by lane on triangles stored as structure of arrays. Every lane does the same IEEE
//! operations in the same order as the scalar test (no fused multiply-add), and a lane that lands
//! exactly on an edge goes to the scalar test's f64 tie-break, so a packet returns the scalar
//! test's bits for each of its triangles. SSE2 on x86_64 (always present there), plain arrays
//! elsewhere.

use glam::Vec3A;
use obvhs::triangle::Triangle;

use super::sheared_ray::ShearedRay;

/// Triangles per packet.
pub const LANES: usize = 4;

/// Up to four triangles, SoA. Unused lanes repeat the first triangle and its index, so they can
/// only ever report a hit the packet already reports.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
pub struct TriPacket {
    /// `v[vertex][axis][lane]`.
    v: [[[f32; LANES]; 3]; 3],
    /// Each lane's index in the triangle list the BVH was built over.
    pub prim: [u32; LANES],
}

impl TriPacket {
    /// A packet of `tris` (1 to 4 triangles with their indices).
    pub fn new(tris: &[(Triangle, u32)]) -> TriPacket {
        debug_assert!(!tris.is_empty() && tris.len() <= LANES);
        let mut p = TriPacket {
            v: [[[0.0; LANES]; 3]; 3],
            prim: [0; LANES],
        };
        for lane in 0..LANES {
            let (tri, prim) = tris.get(lane).unwrap_or(&tris[0]);
            for (k, vertex) in [tri.v0, tri.v1, tri.v2].iter().enumerate() {
                for axis in 0..3 {
                    p.v[k][axis][lane] = vertex[axis];
                }
            }
            p.prim[lane] = *prim;
        }
        p
    }

    /// The triangle in `lane`.
    pub fn triangle(&self, lane: usize) -> Triangle {
        let vertex =
            |k: usize| Vec3A::new(self.v[k][0][lane], self.v[k][1][lane], self.v[k][2][lane]);
        Triangle {
            v0: vertex(0),
            v1: vertex(1),
            v2: vertex(2),
        }
    }

    /// Each lane's distance within (tmin, `tmax`), or infinity: [`ShearedRay::intersect`] of
    /// each triangle, bit for bit.
    #[inline(always)]
    pub fn intersect(&self, ray: &ShearedRay, tmax: f32) -> [f32; LANES] {
        let [kx, ky, kz] = ray.k;
        let [sx, sy, sz] = ray.s.map(F4::splat);
        let o = ray.origin.to_array();
        // Vertex k relative to the origin, sheared so the ray runs along +z.
        let shear = |k: usize| {
            let rel = |axis: usize| F4::load(&self.v[k][axis]).sub(F4::splat(o[axis]));
            let z = rel(kz);
            (rel(kx).sub(sx.mul(z)), rel(ky).sub(sy.mul(z)), z)
        };
        let (ax, ay, az) = shear(0);
        let (bx, by, bz) = shear(1);
        let (cx, cy, cz) = shear(2);
        let u = cx.mul(by).sub(cy.mul(bx));
        let v = ax.mul(cy).sub(ay.mul(cx));
        let w = bx.mul(ay).sub(by.mul(ax));
        let zero = F4::splat(0.0);
        let on_edge = u.eq(zero).or(v.eq(zero)).or(w.eq(zero)).bits();
        let below = u.lt(zero).or(v.lt(zero)).or(w.lt(zero));
        let above = u.gt(zero).or(v.gt(zero)).or(w.gt(zero));
        let det = u.add(v).add(w);
        let miss = below.and(above).or(det.eq(zero));
        // Most tests miss all four: skip the division (the slowest instruction here).
        if on_edge == 0 && miss.bits() == (1 << LANES) - 1 {
            return [f32::INFINITY; LANES];
        }
        let t = u
            .mul(sz)
            .mul(az)
            .add(v.mul(sz).mul(bz))
            .add(w.mul(sz).mul(cz))
            .div(det);
        let inside = t.gt(F4::splat(ray.tmin)).and(t.lt(F4::splat(tmax)));
        let mut out = inside
            .and_not(miss)
            .select(t, F4::splat(f32::INFINITY))
            .to_array();
        if on_edge != 0 {
            for (lane, t) in out.iter_mut().enumerate() {
                if on_edge >> lane & 1 != 0 {
                    *t = ray.intersect(&self.triangle(lane), tmax);
                }
            }
        }
        out
    }
}

/// Four f32 lanes; comparisons give all-ones or all-zero lanes.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct F4(std::arch::x86_64::__m128);

// SAFETY (every block below): SSE and SSE2 are part of the x86_64 baseline, and `load` reads a
// whole `[f32; 4]`.
#[cfg(target_arch = "x86_64")]
impl F4 {
    #[inline(always)]
    fn splat(x: f32) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_set1_ps(x) })
    }
    #[inline(always)]
    fn load(a: &[f32; LANES]) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_loadu_ps(a.as_ptr()) })
    }
    #[inline(always)]
    fn to_array(self) -> [f32; LANES] {
        let mut a = [0.0; LANES];
        unsafe { std::arch::x86_64::_mm_storeu_ps(a.as_mut_ptr(), self.0) };
        a
    }
    #[inline(always)]
    fn add(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_add_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn sub(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_sub_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn mul(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_mul_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn div(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_div_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn eq(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_cmpeq_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn lt(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_cmplt_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn gt(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_cmpgt_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn and(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_and_ps(self.0, b.0) })
    }
    #[inline(always)]
    fn or(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_or_ps(self.0, b.0) })
    }
    /// `self` and not `b`.
    #[inline(always)]
    fn and_not(self, b: F4) -> F4 {
        F4(unsafe { std::arch::x86_64::_mm_andnot_ps(b.0, self.0) })
    }
    /// Lane i of `a` where this mask is set, else of `b`.
    #[inline(always)]
    fn select(self, a: F4, b: F4) -> F4 {
        use std::arch::x86_64::*;
        F4(unsafe { _mm_or_ps(_mm_and_ps(self.0, a.0), _mm_andnot_ps(self.0, b.0)) })
    }
    /// Bit i set where mask lane i is set.
    #[inline(always)]
    fn bits(self) -> u32 {
        unsafe { std::arch::x86_64::_mm_movemask_ps(self.0) as u32 }
    }
}

/// The same lanes as plain arrays, masks as 0 or 1 in the bit pattern's sign.
#[cfg(not(target_arch = "x86_64"))]
#[derive(Clone, Copy)]
struct F4([f32; LANES]);

#[cfg(not(target_arch = "x86_64"))]
impl F4 {
    fn splat(x: f32) -> F4 {
        F4([x; LANES])
    }
    fn load(a: &[f32; LANES]) -> F4 {
        F4(*a)
    }
    fn to_array(self) -> [f32; LANES] {
        self.0
    }
    fn zip(self, b: F4, f: impl Fn(f32, f32) -> f32) -> F4 {
        F4(std::array::from_fn(|i| f(self.0[i], b.0[i])))
    }
    fn mask(self, b: F4, f: impl Fn(f32, f32) -> bool) -> F4 {
        self.zip(b, |x, y| f32::from_bits(if f(x, y) { u32::MAX } else { 0 }))
    }
    fn add(self, b: F4) -> F4 {
        self.zip(b, |x, y| x + y)
    }
    fn sub(self, b: F4) -> F4 {
        self.zip(b, |x, y| x - y)
    }
    fn mul(self, b: F4) -> F4 {
        self.zip(b, |x, y| x * y)
    }
    fn div(self, b: F4) -> F4 {
        self.zip(b, |x, y| x / y)
    }
    fn eq(self, b: F4) -> F4 {
        self.mask(b, |x, y| x == y)
    }
    fn lt(self, b: F4) -> F4 {
        self.mask(b, |x, y| x < y)
    }
    fn gt(self, b: F4) -> F4 {
        self.mask(b, |x, y| x > y)
    }
    fn and(self, b: F4) -> F4 {
        self.zip(b, |x, y| f32::from_bits(x.to_bits() & y.to_bits()))
    }
    fn or(self, b: F4) -> F4 {
        self.zip(b, |x, y| f32::from_bits(x.to_bits() | y.to_bits()))
    }
    fn and_not(self, b: F4) -> F4 {
        self.zip(b, |x, y| f32::from_bits(x.to_bits() & !y.to_bits()))
    }
    fn select(self, a: F4, b: F4) -> F4 {
        F4(std::array::from_fn(|i| {
            if self.0[i].to_bits() != 0 {
                a.0[i]
            } else {
                b.0[i]
            }
        }))
    }
    fn bits(self) -> u32 {
        (0..LANES).fold(0, |m, i| m | ((self.0[i].to_bits() >> 31) << i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{mix, unit};

    fn u(seed: &mut u64) -> f32 {
        *seed = mix(*seed);
        unit(*seed) as f32
    }

    /// Random triangles and rays on a coarse grid (so rays run through shared edges and
    /// vertices, and some triangles are degenerate): every lane gives the scalar test's bits.
    #[test]
    fn every_lane_is_the_scalar_test_bit_for_bit() {
        let mut s = 5u64;
        let mut grid = |span: f32| ((u(&mut s) * span).round() - span / 2.0) / 2.0;
        let mut hits = 0;
        for case in 0..20_000 {
            let tris: Vec<(Triangle, u32)> = (0..1 + case % LANES)
                .map(|k| {
                    let mut v = || Vec3A::new(grid(20.0), grid(20.0), grid(20.0) + 30.0);
                    (
                        Triangle {
                            v0: v(),
                            v1: v(),
                            v2: v(),
                        },
                        k as u32,
                    )
                })
                .collect();
            let o = Vec3A::new(grid(8.0), grid(8.0), grid(4.0));
            let target = Vec3A::new(grid(20.0), grid(20.0), 30.0 + grid(20.0));
            let Some(d) = (target - o).try_normalize() else {
                continue;
            };
            let ray = ShearedRay::new(o, d, 1e-3);
            let packet = TriPacket::new(&tris);
            for tmax in [f32::INFINITY, 31.0] {
                let got = packet.intersect(&ray, tmax);
                for lane in 0..LANES {
                    let (tri, prim) = tris.get(lane).unwrap_or(&tris[0]);
                    let want = ray.intersect(tri, tmax);
                    assert_eq!(
                        got[lane].to_bits(),
                        want.to_bits(),
                        "case {case} lane {lane}"
                    );
                    assert_eq!(packet.prim[lane], *prim);
                }
            }
            hits += packet
                .intersect(&ray, f32::INFINITY)
                .iter()
                .filter(|t| t.is_finite())
                .count();
        }
        assert!(
            hits > 1_000,
            "only {hits} hits: the rays miss too often to test much"
        );
    }
}
