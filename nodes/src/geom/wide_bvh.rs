//! An 8-wide BVH collapsed from obvhs's BVH2, traversed one ray at a time with the eight child
//! boxes tested together: AVX2 where the CPU has it (detected at run time), a scalar loop doing the
//! same IEEE operations in the same order elsewhere, so both paths visit the same nodes and return
//! the same bits. Leaves hold packets of four triangles tested together ([`TriPacket`]).
//!
//! Hits are the smallest (t, triangle index) over every triangle the ray meets: ties between equal
//! distances go to the lower index whatever the tree's layout or the traversal order, so a hit
//! does not depend on the build, the SIMD path or the thread count.

use std::mem::MaybeUninit;

use glam::Vec3A;
use obvhs::bvh2::Bvh2;
use obvhs::triangle::Triangle;

use super::sheared_ray::ShearedRay;
use super::tri_packet::{LANES, TriPacket};

mod packet;
pub use packet::PACKET;

/// Relative slack on a box's exit distance: the slab test and the triangle test round
/// differently, and a box must never be culled for a triangle it holds.
const PAD: f32 = 4.0 / (1 << 20) as f32;

/// Children per node.
const WIDTH: usize = 8;

/// u32 words per node in [`WideBvh::gpu_words`] (256 bytes, the CPU node's size).
pub const GPU_NODE_WORDS: usize = 64;

/// u32 words per triangle packet in [`WideBvh::gpu_words`] (160 bytes).
pub const GPU_PACKET_WORDS: usize = 40;

/// A node: its children's boxes as structure of arrays, so one load fetches an axis bound of all
/// eight. A child is a node (`count` 0, `index` the node) or a leaf (`count` triangle packets
/// from `index`). An unused slot's box is empty (lower bounds +inf, upper -inf), which no ray
/// enters.
#[repr(C, align(32))]
#[derive(Clone, Copy)]
struct Node {
    /// Rows 0-2: the lower bounds on x, y, z; rows 3-5: the upper bounds.
    planes: [[f32; WIDTH]; 6],
    index: [u32; WIDTH],
    count: [u8; WIDTH],
    /// Bit i set when child slot i is used.
    used: u32,
}

impl Node {
    #[inline(always)]
    fn lo(&self, axis: usize) -> &[f32; WIDTH] {
        &self.planes[axis]
    }

    #[inline(always)]
    fn hi(&self, axis: usize) -> &[f32; WIDTH] {
        &self.planes[3 + axis]
    }
}

/// The wide BVH over a triangle list.
pub struct WideBvh {
    nodes: Vec<Node>,
    /// The leaves' triangles, in leaf order.
    packets: Vec<TriPacket>,
    /// Stack entries a traversal can need.
    stack_need: usize,
    /// The median over the leaves of a leaf box's longest side: the scale of the scene's detail.
    leaf_size: f32,
    simd: bool,
}

/// A hit: the distance and the input triangle's index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WideHit {
    /// Distance along the direction.
    pub t: f32,
    /// Index of the triangle in the list the BVH was built over.
    pub prim: u32,
}

/// The per-ray constants of the slab test.
#[derive(Clone, Copy)]
struct Slabs {
    o: [f32; 3],
    inv: [f32; 3],
    /// `inv` scaled away from zero by 1 + `PAD`: a box's exit distance comes out padded with
    /// no extra operation on the chain from one node to the next.
    inv_far: [f32; 3],
    /// The row of [`Node::planes`] a ray enters each axis's slab by (the lower bound when the
    /// direction is positive), and the row it leaves by.
    near_row: [usize; 3],
    far_row: [usize; 3],
}

impl Slabs {
    #[inline(always)]
    fn new(o: Vec3A, d: Vec3A) -> Slabs {
        Slabs::from_inv(o.to_array(), inverse(d))
    }

    #[inline(always)]
    fn from_inv(o: [f32; 3], inv: [f32; 3]) -> Slabs {
        let positive = inv.map(|c| c > 0.0);
        Slabs {
            o,
            inv,
            inv_far: inv.map(|c| c * (1.0 + PAD)),
            near_row: [0, 1, 2].map(|a| if positive[a] { a } else { 3 + a }),
            far_row: [0, 1, 2].map(|a| if positive[a] { 3 + a } else { a }),
        }
    }
}

/// 1 / each component of `d`. A zero component would give inf * 0 = NaN on a box face through
/// the origin; a tiny one of the same sign keeps every distance finite and the box test exact in
/// its sign.
#[inline(always)]
fn inverse(d: Vec3A) -> [f32; 3] {
    d.to_array().map(|c| {
        let c = if c.abs() < 1e-20 {
            1e-20f32.copysign(c + 0.0)
        } else {
            c
        };
        1.0 / c
    })
}

/// `t` padded by `PAD` away from zero: the limit a box's entry distance is held to.
#[inline(always)]
fn padded(t: f32) -> f32 {
    t + t.abs() * PAD
}

/// Eight box tests: a bit per child whose box the ray enters within [tmin, `far`], and the
/// entry distances. `far` is already padded ([`padded`]); the boxes' exit distances are padded
/// by [`Slabs::inv_far`]. Rounding is monotone, so a zero-thickness box (a wall on an axis
/// plane) enters and leaves at the same unpadded distance and is kept.
trait Lanes {
    fn boxes(node: &Node, s: &Slabs, tmin: f32, far: f32) -> (u32, [f32; WIDTH]);
}

struct Scalar;

impl Lanes for Scalar {
    #[inline(always)]
    fn boxes(node: &Node, s: &Slabs, tmin: f32, far: f32) -> (u32, [f32; WIDTH]) {
        let mut near = [0.0f32; WIDTH];
        let mut mask = 0u32;
        for i in 0..WIDTH {
            let t = |a: usize| {
                (
                    (node.planes[s.near_row[a]][i] - s.o[a]) * s.inv[a],
                    (node.planes[s.far_row[a]][i] - s.o[a]) * s.inv_far[a],
                )
            };
            let ((nx, fx), (ny, fy), (nz, fz)) = (t(0), t(1), t(2));
            let tn = max(max(nx, ny), max(nz, tmin));
            let tf = min(min(fx, fy), min(fz, far));
            near[i] = tn;
            if tn <= tf {
                mask |= 1 << i;
            }
        }
        (mask, near)
    }
}

/// `_mm256_min_ps`'s rule (the second operand unless the first is smaller), so the scalar path
/// picks the same bits.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

#[cfg(target_arch = "x86_64")]
struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    #[inline(always)]
    fn boxes(node: &Node, s: &Slabs, tmin: f32, far: f32) -> (u32, [f32; WIDTH]) {
        use std::arch::x86_64::*;
        // SAFETY: only reached from `closest_avx2` / `any_avx2`, which run after
        // `is_x86_feature_detected!("avx2")`; `Node` is 32-byte aligned, so are its rows.
        unsafe {
            // A loop, not a closure: closures do not inherit `target_feature`, and the
            // intrinsics would become calls.
            let mut tn = [_mm256_setzero_ps(); 3];
            let mut tf = [_mm256_setzero_ps(); 3];
            for a in 0..3 {
                let o = _mm256_set1_ps(s.o[a]);
                let near = _mm256_load_ps(node.planes[s.near_row[a]].as_ptr());
                let far = _mm256_load_ps(node.planes[s.far_row[a]].as_ptr());
                tn[a] = _mm256_mul_ps(_mm256_sub_ps(near, o), _mm256_set1_ps(s.inv[a]));
                tf[a] = _mm256_mul_ps(_mm256_sub_ps(far, o), _mm256_set1_ps(s.inv_far[a]));
            }
            // min_ps(a, b) = a < b ? a : b and max_ps(a, b) = a > b ? a : b: the scalar
            // `min` and `max`.
            let tn = _mm256_max_ps(
                _mm256_max_ps(tn[0], tn[1]),
                _mm256_max_ps(tn[2], _mm256_set1_ps(tmin)),
            );
            let tf = _mm256_min_ps(
                _mm256_min_ps(tf[0], tf[1]),
                _mm256_min_ps(tf[2], _mm256_set1_ps(far)),
            );
            let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf);
            let mut near = [0.0f32; WIDTH];
            _mm256_storeu_ps(near.as_mut_ptr(), tn);
            (_mm256_movemask_ps(hit) as u32, near)
        }
    }
}

/// A traversal stack entry: a child and its entry distance.
#[derive(Clone, Copy, Default)]
struct Entry {
    index: u32,
    count: u32,
    near: f32,
}

impl WideBvh {
    /// A BVH over nothing: every ray misses.
    pub fn empty() -> WideBvh {
        WideBvh {
            nodes: Vec::new(),
            packets: Vec::new(),
            stack_need: 1,
            leaf_size: 0.0,
            simd: simd_available(),
        }
    }

    /// Collapses `bvh` (built over `tris`) into eight-wide nodes.
    pub fn new(bvh: &Bvh2, tris: &[Triangle]) -> WideBvh {
        let mut w = WideBvh::empty();
        if bvh.nodes.is_empty() || tris.is_empty() {
            return w;
        }
        let depth = w.collapse(bvh, tris, 0, 1);
        // Each level pushes at most WIDTH - 1 entries beyond the one it pops.
        w.stack_need = depth * (WIDTH - 1) + 2;
        w.leaf_size = w.median_leaf_side();
        w
    }

    /// The median over the leaves of a leaf box's longest side (0 for an empty tree).
    pub fn leaf_size(&self) -> f32 {
        self.leaf_size
    }

    fn median_leaf_side(&self) -> f32 {
        let mut sides: Vec<f32> = self
            .nodes
            .iter()
            .flat_map(|n| {
                (0..WIDTH)
                    .filter(move |&i| n.used >> i & 1 != 0 && n.count[i] != 0)
                    .map(move |i| (0..3).map(|a| n.hi(a)[i] - n.lo(a)[i]).fold(0.0f32, max))
            })
            .collect();
        if sides.is_empty() {
            return 0.0;
        }
        let mid = sides.len() / 2;
        *sides.select_nth_unstable_by(mid, f32::total_cmp).1
    }

    /// The tree as flat words for another traverser (the GPU backend, `rf::gpu`): per node
    /// [`GPU_NODE_WORDS`] u32 (the six plane rows' f32 bits, the eight indices, the eight
    /// counts packed four to a word, the used mask, zero padding), per packet
    /// [`GPU_PACKET_WORDS`] (`v[vertex][axis][lane]` f32 bits, then the four triangle
    /// indices), and the stack entries a traversal can need.
    pub fn gpu_words(&self) -> (Vec<u32>, Vec<u32>, usize) {
        let mut nodes = Vec::with_capacity(self.nodes.len() * GPU_NODE_WORDS);
        for n in &self.nodes {
            nodes.extend(n.planes.iter().flatten().map(|f| f.to_bits()));
            nodes.extend(n.index);
            nodes.extend(
                n.count
                    .chunks(4)
                    .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            );
            nodes.push(n.used);
            nodes.resize(nodes.len().next_multiple_of(GPU_NODE_WORDS), 0);
        }
        let mut packets = Vec::with_capacity(self.packets.len() * GPU_PACKET_WORDS);
        for p in &self.packets {
            let tris: Vec<Triangle> = (0..LANES).map(|lane| p.triangle(lane)).collect();
            for k in 0..3 {
                for a in 0..3 {
                    packets.extend(tris.iter().map(|t| [t.v0, t.v1, t.v2][k][a].to_bits()));
                }
            }
            packets.extend(p.prim);
        }
        (nodes, packets, self.stack_need)
    }

    /// Uses the scalar box test even where AVX2 is available (to compare the two).
    pub fn force_scalar(&mut self) {
        self.simd = false;
    }

    /// True when traversal uses AVX2.
    pub fn uses_simd(&self) -> bool {
        self.simd
    }

    /// Builds the wide node for BVH2 node `id` and its subtree; returns the subtree's depth.
    fn collapse(&mut self, bvh: &Bvh2, tris: &[Triangle], id: usize, level: usize) -> usize {
        let me = self.nodes.len();
        self.nodes.push(Node {
            planes: [
                [f32::INFINITY; WIDTH],
                [f32::INFINITY; WIDTH],
                [f32::INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
            ],
            index: [0; WIDTH],
            count: [0; WIDTH],
            used: 0,
        });
        // Open the child with the largest surface until eight are open or all are leaves:
        // the greedy collapse that keeps big boxes from being tested alone.
        let mut open: Vec<usize> = if bvh.nodes[id].is_leaf() {
            vec![id]
        } else {
            let f = bvh.nodes[id].first_index as usize;
            vec![f, f + 1]
        };
        while open.len() < WIDTH {
            let best = open
                .iter()
                .enumerate()
                .filter(|(_, c)| !bvh.nodes[**c].is_leaf())
                .max_by(|a, b| {
                    let (sa, sb) = (
                        bvh.nodes[*a.1].aabb().half_area(),
                        bvh.nodes[*b.1].aabb().half_area(),
                    );
                    sa.total_cmp(&sb).then(b.0.cmp(&a.0))
                })
                .map(|(k, _)| k);
            let Some(k) = best else { break };
            let f = bvh.nodes[open[k]].first_index as usize;
            open.splice(k..=k, [f, f + 1]);
        }
        let mut depth = level;
        for (slot, &c) in open.iter().enumerate() {
            let n = &bvh.nodes[c];
            let (lo, hi) = (n.aabb().min, n.aabb().max);
            // obvhs keeps leaves to 255 primitives, so at most 64 packets.
            let (index, count) = if n.is_leaf() {
                let first = self.packets.len() as u32;
                let leaf: Vec<(Triangle, u32)> = (0..n.prim_count)
                    .map(|k| {
                        let p = bvh.primitive_indices[(n.first_index + k) as usize];
                        (tris[p as usize], p)
                    })
                    .collect();
                for packet in leaf.chunks(LANES) {
                    self.packets.push(TriPacket::new(packet));
                }
                (first, (self.packets.len() as u32 - first).min(255) as u8)
            } else {
                let child = self.nodes.len() as u32;
                depth = depth.max(self.collapse(bvh, tris, c, level + 1));
                (child, 0)
            };
            let node = &mut self.nodes[me];
            for a in 0..3 {
                node.planes[a][slot] = lo[a];
                node.planes[3 + a][slot] = hi[a];
            }
            node.index[slot] = index;
            node.count[slot] = count;
            node.used |= 1 << slot;
        }
        depth
    }

    /// The closest hit of `origin + t dir`, t in (`tmin`, `tmax`).
    // Always inlined: left to the inliner, the radio map's bounce loop came to call it out as
    // the crate grew, and the map took 15 % longer (docs/benchmarks-log.md, 2026-11-27, commit 34e95bb).
    #[inline(always)]
    pub fn closest(&self, origin: Vec3A, dir: Vec3A, tmin: f32, tmax: f32) -> Option<WideHit> {
        if self.nodes.is_empty() {
            return None;
        }
        let ray = ShearedRay::new(origin, dir, tmin);
        let slabs = Slabs::new(origin, dir);
        with_stack(self.stack_need, |stack| {
            #[cfg(target_arch = "x86_64")]
            if self.simd {
                // SAFETY: `simd` is only true when the CPU has AVX2.
                return unsafe { closest_avx2(self, &ray, &slabs, tmin, tmax, stack) };
            }
            closest::<Scalar>(self, &ray, &slabs, tmin, tmax, stack)
        })
    }

    /// Whether anything lies on `origin + t dir`, t in (`tmin`, `tmax`).
    pub fn any(&self, origin: Vec3A, dir: Vec3A, tmin: f32, tmax: f32) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let ray = ShearedRay::new(origin, dir, tmin);
        let slabs = Slabs::new(origin, dir);
        with_stack(self.stack_need, |stack| {
            #[cfg(target_arch = "x86_64")]
            if self.simd {
                // SAFETY: `simd` is only true when the CPU has AVX2.
                return unsafe { any_avx2(self, &ray, &slabs, tmin, tmax, stack) };
            }
            any::<Scalar>(self, &ray, &slabs, tmin, tmax, stack)
        })
    }
}

/// Runs `f` with a traversal stack of `need` entries: on the call stack when it is small enough
/// (almost always), else on the heap. Uninitialised: zeroing 1.5 kB per ray showed up in
/// profiles; a traversal reads only the entries it pushed.
#[inline(always)]
fn with_stack<E: Copy, R>(need: usize, f: impl FnOnce(&mut [MaybeUninit<E>]) -> R) -> R {
    let mut small = [MaybeUninit::<E>::uninit(); 128];
    if need <= small.len() {
        f(&mut small)
    } else {
        f(&mut vec![MaybeUninit::uninit(); need])
    }
}

/// Whether this CPU runs the AVX2 code paths (x86-64 with AVX2).
pub(crate) fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn closest_avx2(
    bvh: &WideBvh,
    ray: &ShearedRay,
    slabs: &Slabs,
    tmin: f32,
    tmax: f32,
    stack: &mut [MaybeUninit<Entry>],
) -> Option<WideHit> {
    closest::<Avx2>(bvh, ray, slabs, tmin, tmax, stack)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn any_avx2(
    bvh: &WideBvh,
    ray: &ShearedRay,
    slabs: &Slabs,
    tmin: f32,
    tmax: f32,
    stack: &mut [MaybeUninit<Entry>],
) -> bool {
    any::<Avx2>(bvh, ray, slabs, tmin, tmax, stack)
}

#[inline(always)]
fn closest<L: Lanes>(
    bvh: &WideBvh,
    ray: &ShearedRay,
    slabs: &Slabs,
    tmin: f32,
    tmax: f32,
    stack: &mut [MaybeUninit<Entry>],
) -> Option<WideHit> {
    let (best_t, best_p) =
        closest_from::<L>(bvh, ray, slabs, tmin, tmax, stack, 0, (tmax, u32::MAX));
    (best_p != u32::MAX).then_some(WideHit {
        t: best_t,
        prim: best_p,
    })
}

/// The closest hit under inner node `start`, given the best (distance, triangle) found so far
/// (`u32::MAX`: none): the smaller of the two by the same rule.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn closest_from<L: Lanes>(
    bvh: &WideBvh,
    ray: &ShearedRay,
    slabs: &Slabs,
    tmin: f32,
    tmax: f32,
    stack: &mut [MaybeUninit<Entry>],
    start: u32,
    (mut best_t, mut best_p): (f32, u32),
) -> (f32, u32) {
    let mut top = 0usize;
    let mut cur = Entry {
        index: start,
        count: 0,
        near: tmin,
    };
    // Padded like the box test: the entry distance of a box and the distance of a triangle
    // on its face round differently.
    let mut limit = padded(best_t);
    loop {
        if cur.near <= limit {
            if cur.count != 0 {
                let first = cur.index as usize;
                for packet in &bvh.packets[first..first + cur.count as usize] {
                    for (t, p) in packet.intersect(ray, tmax).into_iter().zip(packet.prim) {
                        if t < tmax && t <= best_t && (t < best_t || p < best_p) {
                            (best_t, best_p) = (t, p);
                        }
                    }
                }
                limit = padded(best_t);
            } else {
                let node = &bvh.nodes[cur.index as usize];
                let (mut mask, near) = L::boxes(node, slabs, tmin, limit);
                if mask != 0 {
                    let entry = |i: usize| Entry {
                        index: node.index[i],
                        count: node.count[i] as u32,
                        near: near[i],
                    };
                    let first = entry(mask.trailing_zeros() as usize);
                    mask &= mask - 1;
                    // One or two children (the usual case) need no sort.
                    if mask == 0 {
                        cur = first;
                        continue;
                    }
                    let second = entry(mask.trailing_zeros() as usize);
                    mask &= mask - 1;
                    if mask == 0 {
                        let (near, far) = if second.near < first.near {
                            (second, first)
                        } else {
                            (first, second)
                        };
                        stack[top].write(far);
                        top += 1;
                        cur = near;
                        continue;
                    }
                    // Nearest child next, the others on the stack farthest first.
                    let mut order = [Entry::default(); WIDTH];
                    order[0] = first;
                    let mut n = 1;
                    for e in std::iter::once(second).chain(std::iter::from_fn(|| {
                        (mask != 0).then(|| {
                            let i = mask.trailing_zeros() as usize;
                            mask &= mask - 1;
                            entry(i)
                        })
                    })) {
                        let mut j = n;
                        while j > 0 && order[j - 1].near < e.near {
                            order[j] = order[j - 1];
                            j -= 1;
                        }
                        order[j] = e;
                        n += 1;
                    }
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
    (best_t, best_p)
}

#[inline(always)]
fn any<L: Lanes>(
    bvh: &WideBvh,
    ray: &ShearedRay,
    slabs: &Slabs,
    tmin: f32,
    tmax: f32,
    stack: &mut [MaybeUninit<Entry>],
) -> bool {
    let mut top = 0usize;
    let (mut cur, mut count) = (0u32, 0u32);
    let limit = padded(tmax);
    loop {
        if count != 0 {
            let first = cur as usize;
            for packet in &bvh.packets[first..first + count as usize] {
                if packet.intersect(ray, tmax).iter().any(|t| t.is_finite()) {
                    return true;
                }
            }
        } else {
            let node = &bvh.nodes[cur as usize];
            let (mut mask, _) = L::boxes(node, slabs, tmin, limit);
            if mask != 0 {
                let i = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                (cur, count) = (node.index[i], node.count[i] as u32);
                while mask != 0 {
                    let j = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    stack[top].write(Entry {
                        index: node.index[j],
                        count: node.count[j] as u32,
                        near: 0.0,
                    });
                    top += 1;
                }
                continue;
            }
        }
        if top == 0 {
            return false;
        }
        top -= 1;
        // SAFETY: entries below `top` were written by the pushes above.
        let e = unsafe { stack[top].assume_init() };
        (cur, count) = (e.index, e.count);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Scene;
    use crate::geom::raycast::SceneRays;
    use crate::rng::{mix, unit};

    fn u(seed: &mut u64) -> f32 {
        *seed = mix(*seed);
        unit(*seed) as f32
    }

    /// Boxes, loose triangles, slivers, points, lines and exact duplicates (ties), with
    /// coordinates on a grid so that many rays pass through shared edges and vertices.
    fn messy_triangles() -> Vec<Triangle> {
        let mut s = 7u64;
        let mut tris = Vec::new();
        let v = |x: f32, y: f32, z: f32| Vec3A::new(x, y, z);
        for _ in 0..300 {
            let p = Vec3A::new(
                (u(&mut s) * 40.0).round() - 20.0,
                (u(&mut s) * 40.0).round() - 20.0,
                (u(&mut s) * 40.0).round() - 20.0,
            );
            let e = Vec3A::new(
                (u(&mut s) * 6.0).round() + 1.0,
                (u(&mut s) * 6.0).round() + 1.0,
                (u(&mut s) * 6.0).round() + 1.0,
            );
            let c =
                |i: u32| p + e * Vec3A::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2) as f32);
            for f in [
                [0, 1, 3, 2],
                [4, 6, 7, 5],
                [0, 4, 5, 1],
                [2, 3, 7, 6],
                [0, 2, 6, 4],
                [1, 5, 7, 3],
            ] {
                tris.push(Triangle {
                    v0: c(f[0]),
                    v1: c(f[1]),
                    v2: c(f[2]),
                });
                tris.push(Triangle {
                    v0: c(f[0]),
                    v1: c(f[2]),
                    v2: c(f[3]),
                });
            }
        }
        for _ in 0..500 {
            let a = v(
                u(&mut s) * 50.0 - 25.0,
                u(&mut s) * 50.0 - 25.0,
                u(&mut s) * 50.0 - 25.0,
            );
            let b = a + v(
                u(&mut s) * 8.0 - 4.0,
                u(&mut s) * 8.0 - 4.0,
                u(&mut s) * 8.0 - 4.0,
            );
            let c = a + v(
                u(&mut s) * 8.0 - 4.0,
                u(&mut s) * 8.0 - 4.0,
                u(&mut s) * 8.0 - 4.0,
            );
            tris.push(Triangle {
                v0: a,
                v1: b,
                v2: c,
            });
            // Degenerate: a point, a line, and a duplicate (an exact tie).
            tris.push(Triangle {
                v0: a,
                v1: a,
                v2: a,
            });
            tris.push(Triangle {
                v0: a,
                v1: b,
                v2: a + (b - a) * 0.5,
            });
            tris.push(Triangle {
                v0: a,
                v1: b,
                v2: c,
            });
        }
        tris
    }

    fn build(tris: &[Triangle]) -> WideBvh {
        let bvh2 = obvhs::bvh2::builder::build_bvh2_from_tris(
            tris,
            obvhs::BvhBuildParams::medium_build(),
            &mut std::time::Duration::default(),
        );
        WideBvh::new(&bvh2, tris)
    }

    /// The closest hit over every triangle, ties to the lower index.
    fn brute(tris: &[Triangle], o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<WideHit> {
        let ray = ShearedRay::new(o, d, tmin);
        let mut best: Option<WideHit> = None;
        for (k, tri) in tris.iter().enumerate() {
            let t = ray.intersect(tri, tmax);
            if t < tmax && best.is_none_or(|b| t < b.t) {
                best = Some(WideHit { t, prim: k as u32 });
            }
        }
        best
    }

    fn rays(n: usize, seed: u64, span: f32) -> Vec<(Vec3A, Vec3A)> {
        let mut s = seed;
        (0..n)
            .map(|i| {
                let o = Vec3A::new(
                    u(&mut s) * span - span / 2.0,
                    u(&mut s) * span - span / 2.0,
                    u(&mut s) * span - span / 2.0,
                );
                let mut d = Vec3A::new(u(&mut s) - 0.5, u(&mut s) - 0.5, u(&mut s) - 0.5);
                // Axis-aligned and grid-aimed rays hit faces and edges exactly.
                match i % 4 {
                    0 => d = Vec3A::new(0.0, 0.0, if d.z < 0.0 { -1.0 } else { 1.0 }),
                    1 => d = Vec3A::new(d.x, 0.0, 0.0),
                    2 => {
                        let target = o.round() + Vec3A::new(3.0, -2.0, 1.0);
                        d = target - o;
                    }
                    _ => {}
                }
                (o, d.normalize_or(Vec3A::X))
            })
            .collect()
    }

    #[test]
    fn closest_is_the_brute_force_minimum_and_any_agrees() {
        let tris = messy_triangles();
        let mut bvh = build(&tris);
        let mut scalar = build(&tris);
        scalar.force_scalar();
        for (o, d) in rays(20_000, 3, 60.0) {
            for (tmin, tmax) in [(0.0, f32::INFINITY), (1e-3, 7.5)] {
                let want = brute(&tris, o, d, tmin, tmax);
                let got = bvh.closest(o, d, tmin, tmax);
                assert_eq!(got, want, "ray {o} {d}");
                assert_eq!(scalar.closest(o, d, tmin, tmax), want);
                assert_eq!(bvh.any(o, d, tmin, tmax), want.is_some());
                assert_eq!(scalar.any(o, d, tmin, tmax), want.is_some());
            }
        }
        bvh.force_scalar();
        assert!(!bvh.uses_simd());
    }

    /// Packets as casters make them: tiles of a camera's pixels (a shared origin, directions in
    /// a narrow cone, some aimed at the grid's edges), parallel rays from a patch of a grid, and
    /// scattered rays of one octant. Every ray's hit is the single-ray hit, on both paths.
    #[test]
    fn a_packet_gives_each_ray_its_own_hit() {
        let tris = messy_triangles();
        let bvh = build(&tris);
        let mut scalar = build(&tris);
        scalar.force_scalar();
        let mut s = 5u64;
        let mut checked = 0;
        for case in 0..600 {
            let centre = Vec3A::new(
                u(&mut s) * 60.0 - 30.0,
                u(&mut s) * 60.0 - 30.0,
                u(&mut s) * 60.0 - 30.0,
            );
            let axis = Vec3A::new(u(&mut s) - 0.5, u(&mut s) - 0.5, u(&mut s) - 0.5)
                .normalize_or(Vec3A::Z);
            let spread = [0.002, 0.05, 0.5][case % 3];
            let n = 1 + (u(&mut s) * PACKET as f32) as usize % PACKET;
            let mut rays: Vec<(Vec3A, Vec3A)> = (0..n)
                .map(|i| {
                    let jitter =
                        Vec3A::new(u(&mut s) - 0.5, u(&mut s) - 0.5, u(&mut s) - 0.5) * spread;
                    match case % 4 {
                        // A camera: one origin, a cone of directions, every fifth at a vertex.
                        0 | 1 if i % 5 == 0 => {
                            let target = (centre + axis * 20.0 + jitter * 40.0).round();
                            (centre, (target - centre).normalize())
                        }
                        0 | 1 => (centre, (axis + jitter).normalize()),
                        // A grid of parallel rays.
                        2 => (centre + jitter * 20.0, axis),
                        _ => (centre + jitter * 80.0, (axis + jitter * 2.0).normalize()),
                    }
                })
                .collect();
            // One octant per packet, as `SceneRays::cast_coherent` splits them.
            let sign = |d: Vec3A| d.to_array().map(|c| (c + 0.0).is_sign_negative());
            let first = sign(rays[0].1);
            rays.retain(|r| sign(r.1) == first);
            let (o, d): (Vec<Vec3A>, Vec<Vec3A>) = rays.iter().copied().unzip();
            for (tmin, tmax) in [(0.0, f32::INFINITY), (1e-3, 7.5)] {
                for b in [&bvh, &scalar] {
                    let mut out = vec![None; o.len()];
                    b.closest_packet(&o, &d, tmin, tmax, &mut out);
                    for (k, got) in out.iter().enumerate() {
                        assert_eq!(
                            *got,
                            b.closest(o[k], d[k], tmin, tmax),
                            "case {case} ray {k}"
                        );
                        checked += got.is_some() as usize;
                    }
                }
            }
        }
        assert!(checked > 10_000, "{checked} hits");
    }

    #[test]
    fn empty_and_single_triangle_scenes() {
        let none = WideBvh::empty();
        assert_eq!(none.closest(Vec3A::ZERO, Vec3A::X, 0.0, 1.0), None);
        assert!(!none.any(Vec3A::ZERO, Vec3A::X, 0.0, 1.0));
        let one = [Triangle {
            v0: Vec3A::new(5.0, -1.0, -1.0),
            v1: Vec3A::new(5.0, 1.0, -1.0),
            v2: Vec3A::new(5.0, 0.0, 1.0),
        }];
        let bvh = build(&one);
        // One leaf, 2 m across on its longest sides.
        assert_eq!((none.leaf_size(), bvh.leaf_size()), (0.0, 2.0));
        let h = bvh.closest(Vec3A::ZERO, Vec3A::X, 0.0, 10.0).unwrap();
        assert_eq!((h.t, h.prim), (5.0, 0));
        assert!(bvh.any(Vec3A::ZERO, Vec3A::X, 0.0, 10.0));
        assert!(!bvh.any(Vec3A::ZERO, Vec3A::X, 0.0, 4.0));
        assert_eq!(
            SceneRays::new(&Scene::default()).cast([0.0; 3], [1.0, 0.0, 0.0], 0.0, 1.0),
            None
        );
    }

    /// `cast_coherent` splits a run across octants and casts the non-finite alone.
    #[test]
    fn cast_coherent_and_cast_runs_are_cast_for_any_run() {
        let tris = messy_triangles();
        let n = tris.len() as u32;
        let scene = Scene {
            objects: vec![crate::artifact::SceneObject {
                id: "messy".into(),
                class: crate::artifact::ObjectClass::Unsegmented,
                mesh: crate::artifact::Mesh {
                    positions: tris
                        .iter()
                        .flat_map(|t| [t.v0.to_array(), t.v1.to_array(), t.v2.to_array()])
                        .collect::<Vec<_>>()
                        .into(),
                    triangles: (0..n)
                        .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
                        .collect::<Vec<_>>()
                        .into(),
                    materials: vec![0u8; n as usize].into(),
                },
            }],
        };
        let rays_ = SceneRays::new(&scene);
        let mut list: Vec<([f32; 3], [f32; 3])> = rays(5_000, 9, 60.0)
            .into_iter()
            .map(|(o, d)| (o.to_array(), d.to_array()))
            .collect();
        list.push(([0.0; 3], [f32::NAN, 0.0, 1.0]));
        list.push(([0.0; 3], [-0.0, -0.0, 1.0]));
        let got = rays_.cast_coherent(&list, 1e-3, 100.0);
        for ((o, d), g) in list.iter().zip(&got) {
            assert_eq!(*g, rays_.cast(*o, *d, 1e-3, 100.0));
        }
        // Cut into runs of every length from 1 to past a packet, ending short of the rays (the
        // rest in plain packets), and cut only at the end.
        let runs = vec![1, 2, 3, 63, 64, 65, 130, 5, 0, 200];
        for cut in [runs, vec![], vec![list.len() as u32 + 7]] {
            let got = rays_.cast_runs_index(&list, &cut, 1e-3, 100.0);
            for ((o, d), g) in list.iter().zip(&got) {
                assert_eq!(*g, rays_.cast_index(*o, *d, 1e-3, 100.0));
            }
        }
    }
}
