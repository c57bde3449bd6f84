//! Packets of coherent rays (a tile of a camera's pixels, a patch of parallel rays over a grid)
//! traversing the wide BVH together.
//!
//! Inner nodes are tested once for the whole packet, by interval arithmetic: every ray's origin
//! and inverse direction lie within per-axis intervals, and the eight child boxes are entered,
//! for some ray, no earlier than the interval bound (Wald, Boulos and Shirley, "Ray tracing
//! deformable scenes using dynamic bounding volume hierarchies", ACM TOG 2007). Float rounding
//! is monotone, so the bound computed in f32 from the intervals' corners is below every ray's own
//! f32 entry distance: the packet culls a box only when each of its rays would. Leaves are then
//! tested ray by ray, eight rays at a time, with the single-ray slab test, and their triangles
//! with the single-ray triangle test. A ray's hit is the smallest (t, triangle index) over every
//! triangle it meets, as in [`WideBvh::closest`]: the same bits.
//!
//! The loops over eight lanes are plain Rust; compiled inside an AVX2 function they vectorise.

use std::mem::MaybeUninit;

use glam::Vec3A;

use super::{
    Lanes, PAD, Scalar, Slabs, WIDTH, WideBvh, WideHit, closest_from, inverse, max, min, with_stack,
};
use crate::geom::sheared_ray::ShearedRay;

/// The most rays in one packet.
pub const PACKET: usize = 64;

/// Rays tested together against a leaf box.
const GROUP: usize = 8;

/// A packet's rays as structure of arrays, in groups of eight lanes.
struct Rays {
    n: usize,
    o: [[[f32; GROUP]; 3]; PACKET / GROUP],
    inv: [[[f32; GROUP]; 3]; PACKET / GROUP],
    sheared: [MaybeUninit<ShearedRay>; PACKET],
    best_t: [[f32; GROUP]; PACKET / GROUP],
    best_p: [[u32; GROUP]; PACKET / GROUP],
    /// Per axis, the smallest and largest origin and inverse direction over the packet.
    o_lo: [f32; 3],
    o_hi: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    /// How far apart the rays may be at distance t: `spread * t + offset` metres (the widest
    /// spread of a direction component, the widest spread of the origins).
    spread: f32,
    offset: f32,
}

/// A packet wider than this many times a node's box goes on ray by ray below it: most of its
/// rays miss most of what the box holds, and the packet's bounds enter it all.
const SPLIT_RATIO: f32 = 1.0;

/// The packet's traversal stack and a lone ray's.
type Stacks<'a> = (
    &'a mut [MaybeUninit<Entry>],
    &'a mut [MaybeUninit<super::Entry>],
);

/// A stack entry: a child, the packet's lower bound on its entry distance, and for a leaf the
/// node and slot holding its box.
#[derive(Clone, Copy, Default)]
struct Entry {
    index: u32,
    count: u32,
    near: f32,
    parent: u32,
    slot: u32,
}

impl WideBvh {
    /// The closest hits of up to [`PACKET`] rays whose directions share their signs on every
    /// axis (the caller splits a tile by octant): `out[i]` is what [`WideBvh::closest`] returns
    /// for `origins[i]`, `dirs[i]`, bit for bit.
    ///
    /// # Panics
    /// When the slices differ in length, hold more than [`PACKET`] rays, or mix signs.
    pub fn closest_packet(
        &self,
        origins: &[Vec3A],
        dirs: &[Vec3A],
        tmin: f32,
        tmax: f32,
        out: &mut [Option<WideHit>],
    ) {
        let n = origins.len();
        assert!(n == dirs.len() && n == out.len() && n <= PACKET);
        if n == 0 {
            return;
        }
        if self.nodes.is_empty() {
            out.fill(None);
            return;
        }
        // The packet's stack, and one for a ray going on alone below a node.
        with_stack(self.stack_need, |stack| {
            with_stack(self.stack_need, |single| {
                #[cfg(target_arch = "x86_64")]
                if self.simd {
                    // SAFETY: `simd` is only true when the CPU has AVX2.
                    return unsafe {
                        packet_avx2(self, origins, dirs, tmin, tmax, (stack, single), out)
                    };
                }
                packet::<Scalar>(self, origins, dirs, tmin, tmax, (stack, single), out)
            })
        })
    }
}

impl Rays {
    #[inline(always)]
    fn new(origins: &[Vec3A], dirs: &[Vec3A], tmin: f32, tmax: f32) -> Rays {
        let n = origins.len();
        let mut r = Rays {
            n,
            o: [[[0.0; GROUP]; 3]; PACKET / GROUP],
            inv: [[[1.0; GROUP]; 3]; PACKET / GROUP],
            sheared: [MaybeUninit::uninit(); PACKET],
            // Lanes past the last ray never pass a box test: no distance is below -inf.
            best_t: [[f32::NEG_INFINITY; GROUP]; PACKET / GROUP],
            best_p: [[u32::MAX; GROUP]; PACKET / GROUP],
            o_lo: [f32::INFINITY; 3],
            o_hi: [f32::NEG_INFINITY; 3],
            inv_lo: [f32::INFINITY; 3],
            inv_hi: [f32::NEG_INFINITY; 3],
            spread: 0.0,
            offset: 0.0,
        };
        let (mut d_lo, mut d_hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        // The intervals in registers: through the struct, each ray's update waited on the
        // last one's store.
        let (mut o_lo, mut o_hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        let (mut inv_lo, mut inv_hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        for (i, (&o, &d)) in origins.iter().zip(dirs).enumerate() {
            // Only the inverse: the lone ray's near and far rows are chosen if it goes on alone.
            let inv = inverse(d);
            let (g, l) = (i / GROUP, i % GROUP);
            for a in 0..3 {
                r.o[g][a][l] = o[a];
                r.inv[g][a][l] = inv[a];
            }
            let inv = Vec3A::from(inv);
            (o_lo, o_hi) = (o_lo.min(o), o_hi.max(o));
            (inv_lo, inv_hi) = (inv_lo.min(inv), inv_hi.max(inv));
            (d_lo, d_hi) = (d_lo.min(d), d_hi.max(d));
            r.sheared[i].write(ShearedRay::new(o, d, tmin));
            r.best_t[g][l] = tmax;
        }
        assert!(
            inv_lo.signum() == inv_hi.signum(),
            "a ray packet mixes direction signs"
        );
        (r.o_lo, r.o_hi) = (o_lo.to_array(), o_hi.to_array());
        (r.inv_lo, r.inv_hi) = (inv_lo.to_array(), inv_hi.to_array());
        r.spread = (d_hi - d_lo).max_element();
        r.offset = (o_hi - o_lo).max_element();
        r
    }

    /// The largest distance any ray still looks to.
    fn far(&self) -> f32 {
        let mut far = f32::NEG_INFINITY;
        for g in &self.best_t[..self.n.div_ceil(GROUP)] {
            for &t in g {
                far = max(far, t);
            }
        }
        far
    }

    #[inline(always)]
    fn write(&self, out: &mut [Option<WideHit>]) {
        for (i, o) in out.iter_mut().enumerate() {
            let (g, l) = (i / GROUP, i % GROUP);
            let p = self.best_p[g][l];
            *o = (p != u32::MAX).then_some(WideHit {
                t: self.best_t[g][l],
                prim: p,
            });
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn packet_avx2(
    bvh: &WideBvh,
    origins: &[Vec3A],
    dirs: &[Vec3A],
    tmin: f32,
    tmax: f32,
    stacks: Stacks,
    out: &mut [Option<WideHit>],
) {
    packet::<super::Avx2>(bvh, origins, dirs, tmin, tmax, stacks, out)
}

/// The packet's set-up, traversal and hits, inlined into the AVX2 function so that the loops
/// over lanes vectorise there.
#[inline(always)]
fn packet<L: Lanes>(
    bvh: &WideBvh,
    origins: &[Vec3A],
    dirs: &[Vec3A],
    tmin: f32,
    tmax: f32,
    stacks: Stacks,
    out: &mut [Option<WideHit>],
) {
    let mut rays = Rays::new(origins, dirs, tmin, tmax);
    traverse::<L>(bvh, &mut rays, tmin, tmax, stacks);
    rays.write(out);
}

/// Whether the packet, where it enters the box of inner node `e`, is wider than
/// [`SPLIT_RATIO`] times the box.
#[inline(always)]
fn wider_than_box(bvh: &WideBvh, r: &Rays, e: &Entry) -> bool {
    let parent = &bvh.nodes[e.parent as usize];
    let i = e.slot as usize;
    let size = (0..3)
        .map(|a| parent.hi(a)[i] - parent.lo(a)[i])
        .fold(0.0f32, max);
    r.spread * e.near.max(0.0) + r.offset > SPLIT_RATIO * size
}

/// The packet's lower bound on each child's entry distance and a bit per child some ray may
/// enter within [`tmin`, `far`].
#[inline(always)]
fn frustum_boxes(node: &super::Node, r: &Rays, tmin: f32, far: f32) -> (u32, [f32; WIDTH]) {
    let mut tn = [tmin; WIDTH];
    let mut tf = [far; WIDTH];
    for a in 0..3 {
        let (o0, o1, i0, i1) = (r.o_lo[a], r.o_hi[a], r.inv_lo[a], r.inv_hi[a]);
        for i in 0..WIDTH {
            // (plane - o) * inv is monotone in o and, for a fixed sign of (plane - o), in inv;
            // so are its rounded values. Its extremes over the intervals lie at the corners.
            let bound = |plane: f32| {
                let (d0, d1) = (plane - o1, plane - o0);
                let (p, q, s, t) = (d0 * i0, d0 * i1, d1 * i0, d1 * i1);
                (min(min(p, q), min(s, t)), max(max(p, q), max(s, t)))
            };
            let (lo_min, lo_max) = bound(node.lo(a)[i]);
            let (hi_min, hi_max) = bound(node.hi(a)[i]);
            tn[i] = max(tn[i], min(lo_min, hi_min));
            tf[i] = min(tf[i], max(lo_max, hi_max));
        }
    }
    (entered(&tn, &tf) & node.used, tn)
}

/// A bit per lane whose entry distance is within its (padded) exit distance.
#[inline(always)]
fn entered(tn: &[f32; 8], tf: &[f32; 8]) -> u32 {
    let mut mask = 0u32;
    for i in 0..8 {
        if tn[i] <= tf[i] + tf[i].abs() * PAD {
            mask |= 1 << i;
        }
    }
    mask
}

/// A bit per ray of group `g` that enters child `slot` of `node` before its own best distance:
/// the single-ray slab test ([`super::Scalar`]), eight rays at once.
#[inline(always)]
fn leaf_rays(node: &super::Node, slot: usize, r: &Rays, g: usize, tmin: f32) -> u32 {
    let mut tn = [tmin; GROUP];
    let mut tf = r.best_t[g];
    for a in 0..3 {
        let (lo, hi) = (node.lo(a)[slot], node.hi(a)[slot]);
        for l in 0..GROUP {
            let t1 = (lo - r.o[g][a][l]) * r.inv[g][a][l];
            let t2 = (hi - r.o[g][a][l]) * r.inv[g][a][l];
            tn[l] = max(tn[l], min(t1, t2));
            tf[l] = min(tf[l], max(t1, t2));
        }
    }
    entered(&tn, &tf)
}

#[inline(always)]
fn traverse<L: Lanes>(bvh: &WideBvh, r: &mut Rays, tmin: f32, tmax: f32, (stack, single): Stacks) {
    let groups = r.n.div_ceil(GROUP);
    let mut far = tmax;
    let mut top = 0usize;
    let mut cur = Entry {
        index: 0,
        count: 0,
        near: tmin,
        parent: 0,
        slot: 0,
    };
    loop {
        if cur.near <= far + far.abs() * PAD {
            if cur.count != 0 {
                let node = &bvh.nodes[cur.parent as usize];
                let first = cur.index as usize;
                let packets = &bvh.packets[first..first + cur.count as usize];
                let mut changed = false;
                for g in 0..groups {
                    let mut mask = leaf_rays(node, cur.slot as usize, r, g, tmin);
                    while mask != 0 {
                        let l = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        // SAFETY: lanes of live rays were written in `Rays::new`; dead lanes
                        // (best -inf) never pass `leaf_rays`.
                        let ray = unsafe { r.sheared[g * GROUP + l].assume_init_ref() };
                        let (mut bt, mut bp) = (r.best_t[g][l], r.best_p[g][l]);
                        for packet in packets {
                            for (t, p) in packet.intersect(ray, tmax).into_iter().zip(packet.prim) {
                                if t < tmax && t <= bt && (t < bt || p < bp) {
                                    (bt, bp) = (t, p);
                                }
                            }
                        }
                        if bt != r.best_t[g][l] {
                            changed = true;
                        }
                        (r.best_t[g][l], r.best_p[g][l]) = (bt, bp);
                    }
                }
                if changed {
                    far = r.far();
                }
            } else if cur.index != 0 && wider_than_box(bvh, r, &cur) {
                for g in 0..groups {
                    for l in 0..GROUP {
                        if r.best_t[g][l] == f32::NEG_INFINITY {
                            continue;
                        }
                        // SAFETY: as above, a live lane.
                        let ray = unsafe { r.sheared[g * GROUP + l].assume_init_ref() };
                        let slabs = Slabs::from_inv(
                            [0, 1, 2].map(|a| r.o[g][a][l]),
                            [0, 1, 2].map(|a| r.inv[g][a][l]),
                        );
                        let best = (r.best_t[g][l], r.best_p[g][l]);
                        (r.best_t[g][l], r.best_p[g][l]) = closest_from::<L>(
                            bvh, ray, &slabs, tmin, tmax, single, cur.index, best,
                        );
                    }
                }
                far = r.far();
            } else {
                let node = &bvh.nodes[cur.index as usize];
                let (mut mask, near) = frustum_boxes(node, r, tmin, far);
                // Nearest child next, the others on the stack farthest first.
                let mut order = [Entry::default(); WIDTH];
                let mut n = 0;
                while mask != 0 {
                    let i = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let e = Entry {
                        index: node.index[i],
                        count: node.count[i] as u32,
                        near: near[i],
                        parent: cur.index,
                        slot: i as u32,
                    };
                    let mut j = n;
                    while j > 0 && order[j - 1].near < e.near {
                        order[j] = order[j - 1];
                        j -= 1;
                    }
                    order[j] = e;
                    n += 1;
                }
                if n > 0 {
                    for e in &order[..n - 1] {
                        stack[top].write(*e);
                        top += 1;
                    }
                    cur = order[n - 1];
                    continue;
                }
            }
        }
        if top == 0 {
            break;
        }
        top -= 1;
        // SAFETY: entries below `top` were written by the pushes above.
        cur = unsafe { stack[top].assume_init() };
    }
}
