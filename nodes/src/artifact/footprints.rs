//! Building footprints in the site frame.

use serde::{Deserialize, Serialize};

use super::Grid;

/// A polygon in the site frame: exterior counter-clockwise, holes clockwise, rings open (the
/// closing vertex is not repeated).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    /// Outer ring.
    pub exterior: Vec<[f64; 2]>,
    /// Inner rings (courtyards).
    pub holes: Vec<Vec<[f64; 2]>>,
}

impl Polygon {
    /// A polygon from rings in any orientation, with a repeated closing vertex or not; rings of
    /// fewer than 3 distinct vertices are dropped. `None` if the exterior is degenerate.
    pub fn normalized(exterior: Vec<[f64; 2]>, holes: Vec<Vec<[f64; 2]>>) -> Option<Polygon> {
        let fix = |mut r: Vec<[f64; 2]>, ccw: bool| {
            if r.len() > 1 && r.first() == r.last() {
                r.pop();
            }
            if r.len() < 3 || ring_area(&r) == 0.0 {
                return None;
            }
            if (ring_area(&r) > 0.0) != ccw {
                r.reverse();
            }
            Some(r)
        };
        Some(Polygon {
            exterior: fix(exterior, true)?,
            holes: holes.into_iter().filter_map(|h| fix(h, false)).collect(),
        })
    }

    /// Area, m² (exterior minus holes).
    pub fn area(&self) -> f64 {
        ring_area(&self.exterior) + self.holes.iter().map(|h| ring_area(h)).sum::<f64>()
    }

    /// True when `p` is inside the exterior and outside every hole.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        point_in_ring(p, &self.exterior) && !self.holes.iter().any(|h| point_in_ring(p, h))
    }

    /// [`Polygon::contains`] for many points: each answer in time proportional to the edges
    /// near its y, not to every edge (a 150,000-vertex outline queried at every cell or
    /// triangle was quadratic).
    pub fn index(&self) -> PolygonIndex<'_> {
        PolygonIndex {
            exterior: RingIndex::new(&self.exterior),
            holes: self.holes.iter().map(|h| RingIndex::new(h)).collect(),
        }
    }
}

/// A polygon prepared for many [`Polygon::contains`] queries ([`Polygon::index`]).
pub struct PolygonIndex<'a> {
    exterior: RingIndex<'a>,
    holes: Vec<RingIndex<'a>>,
}

impl PolygonIndex<'_> {
    /// The same answer as [`Polygon::contains`], bit for bit.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        self.exterior.contains(p) && !self.holes.iter().any(|h| h.contains(p))
    }
}

/// A ring's edges sorted into horizontal slabs: [`point_in_ring`]'s even-odd test needs only the
/// edges whose y-range holds the point's y, and those all lie in the point's slab. The test per
/// edge is [`point_in_ring`]'s own, so the answers are the same.
pub struct RingIndex<'a> {
    ring: &'a [[f64; 2]],
    y_min: f64,
    y_max: f64,
    /// Slabs per metre of y.
    per_m: f64,
    /// Per slab, the edges (by their first vertex `i`: from `ring[i]` to `ring[i - 1]`) whose
    /// y-range meets it.
    slabs: Vec<Vec<u32>>,
}

impl<'a> RingIndex<'a> {
    /// Most entries per edge on average: edges spanning many slabs (a zig-zag of tall edges)
    /// get fewer slabs, so memory stays linear in the ring.
    const ENTRIES_PER_EDGE: usize = 16;

    /// Indexes `ring`.
    pub fn new(ring: &'a [[f64; 2]]) -> Self {
        let n = ring.len();
        let (y_min, y_max) = ring
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[1]), hi.max(p[1]))
            });
        let height = y_max - y_min;
        let mut count = if n >= 32 && height.is_finite() && height > 0.0 {
            (n / 8).clamp(1, 4096)
        } else {
            1
        };
        loop {
            let per_m = if count > 1 {
                count as f64 / height
            } else {
                0.0
            };
            let mut index = RingIndex {
                ring,
                y_min,
                y_max,
                per_m,
                slabs: vec![Vec::new(); count],
            };
            let spans: Vec<(usize, usize)> = (0..n)
                .map(|i| {
                    let (a, b) = (ring[i], ring[(i + n - 1) % n]);
                    (index.slab(a[1].min(b[1])), index.slab(a[1].max(b[1])))
                })
                .collect();
            let entries: usize = spans.iter().map(|(lo, hi)| hi + 1 - lo).sum();
            if count > 1 && entries > Self::ENTRIES_PER_EDGE * n {
                count /= 2;
                continue;
            }
            for (i, (lo, hi)) in spans.into_iter().enumerate() {
                for slab in &mut index.slabs[lo..=hi] {
                    slab.push(i as u32);
                }
            }
            return index;
        }
    }

    /// The slab holding y (clamped to the ring's range).
    fn slab(&self, y: f64) -> usize {
        let k = ((y - self.y_min) * self.per_m).floor();
        if k > 0.0 {
            (k as usize).min(self.slabs.len() - 1)
        } else {
            0
        }
    }

    /// [`point_in_ring`] for `p`.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        // Outside the ring's y-range (or NaN) no edge straddles p's y.
        if !(p[1] >= self.y_min && p[1] < self.y_max) {
            return false;
        }
        let n = self.ring.len();
        self.slabs[self.slab(p[1])]
            .iter()
            .fold(false, |inside, &i| {
                let i = i as usize;
                inside != crosses(p, self.ring[i], self.ring[(i + n - 1) % n])
            })
    }
}

/// One building: its polygons and what the source says about its height.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Footprint {
    /// The source's identifier.
    pub id: String,
    /// Its parts.
    pub polygons: Vec<Polygon>,
    /// Height of the top above ground, metres (OSM `height`).
    pub height_m: Option<f64>,
    /// Height of the bottom above ground, metres (OSM `min_height`).
    pub min_height_m: Option<f64>,
    /// Number of levels (OSM `building:levels`).
    pub levels: Option<f64>,
    /// Levels below the bottom (OSM `building:min_level`).
    pub min_level: Option<f64>,
}

/// A set of footprints.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Footprints {
    /// In source order.
    pub items: Vec<Footprint>,
}

impl Footprints {
    /// Which footprint covers each cell centre of `grid`: its index + 1, 0 for none (the first
    /// footprint wins where two overlap).
    pub fn rasterize(&self, grid: &Grid) -> Vec<u32> {
        let mut out = vec![0u32; grid.len()];
        for (k, f) in self.items.iter().enumerate() {
            for poly in &f.polygons {
                let (lo, hi) = poly.exterior.iter().fold(
                    ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
                    |(lo, hi), p| {
                        (
                            [lo[0].min(p[0]), lo[1].min(p[1])],
                            [hi[0].max(p[0]), hi[1].max(p[1])],
                        )
                    },
                );
                let index = poly.index();
                let col = |x: f64| ((x - grid.x0) / grid.cell_m).floor();
                let row = |y: f64| ((grid.y0 - y) / grid.cell_m).floor();
                let (c0, c1) = (col(lo[0]).max(0.0), col(hi[0]).min(grid.width as f64 - 1.0));
                let (r0, r1) = (
                    row(hi[1]).max(0.0),
                    row(lo[1]).min(grid.height as f64 - 1.0),
                );
                if c0 > c1 || r0 > r1 {
                    continue;
                }
                for r in r0 as u32..=r1 as u32 {
                    for c in c0 as u32..=c1 as u32 {
                        let i = (r * grid.width + c) as usize;
                        if out[i] == 0 {
                            let (x, y) = grid.center(c, r);
                            if index.contains([x, y]) {
                                out[i] = k as u32 + 1;
                            }
                        }
                    }
                }
            }
        }
        out
    }
}

/// Even-odd point-in-polygon test.
pub fn point_in_ring(p: [f64; 2], ring: &[[f64; 2]]) -> bool {
    let n = ring.len();
    (0..n).fold(false, |inside, i| {
        inside != crosses(p, ring[i], ring[(i + n - 1) % n])
    })
}

/// Whether edge a-b straddles p's y to the right of p: one flip of the even-odd count.
fn crosses(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> bool {
    (a[1] > p[1]) != (b[1] > p[1]) && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0]
}

/// Signed area of a ring (positive when counter-clockwise), m².
pub fn ring_area(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wobbly ring of `n` vertices round the origin (concave: seven lobes), with a notch
    /// every 97 vertices when `notched` (long edges spanning many slabs).
    fn wobbly(n: usize, notched: bool) -> Vec<[f64; 2]> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                let notch = if notched && i % 97 < 3 { 0.5 } else { 1.0 };
                let r = 20.0 * (1.0 + 0.3 * (7.0 * t).sin()) * notch;
                [r * t.cos(), r * t.sin()]
            })
            .collect()
    }

    /// The index gives point_in_ring's answers exactly: at random points, at every vertex, and
    /// at points on vertices' y (where edges start and end), for small and large rings.
    #[test]
    fn the_ring_index_answers_as_point_in_ring() {
        let mut state = 0x9e3779b97f4a7c15u64;
        let mut rnd = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for n in [3, 4, 31, 32, 100, 5000] {
            let ring = wobbly(n, true);
            let index = RingIndex::new(&ring);
            let mut points: Vec<[f64; 2]> = (0..4000)
                .map(|_| [rnd() * 60.0 - 30.0, rnd() * 60.0 - 30.0])
                .collect();
            points.extend(ring.iter().copied());
            points.extend(ring.iter().map(|v| [v[0] - 0.5, v[1]]));
            points.extend([[f64::NAN, 0.0], [0.0, f64::NAN], [0.0, 1e300]]);
            for p in points {
                assert_eq!(index.contains(p), point_in_ring(p, &ring), "n {n}, p {p:?}");
            }
        }
    }

    /// What makes it fast: a point meets few of a large ring's edges (a slab holds a small share
    /// of them on average), and the slabs stay linear in the ring however its edges zig-zag.
    #[test]
    fn a_large_ring_is_split_into_small_slabs() {
        let ring = wobbly(150_000, false);
        let index = RingIndex::new(&ring);
        let entries: usize = index.slabs.iter().map(Vec::len).sum();
        let mean = entries / index.slabs.len();
        assert!(mean < 150_000 / 500, "mean slab {mean}");
        // Every edge spanning the whole height.
        let zigzag: Vec<[f64; 2]> = (0..10_000)
            .map(|i| [i as f64, if i % 2 == 0 { 0.0 } else { 100.0 }])
            .collect();
        let index = RingIndex::new(&zigzag);
        let entries: usize = index.slabs.iter().map(Vec::len).sum();
        assert!(entries <= RingIndex::ENTRIES_PER_EDGE * zigzag.len());
    }
}
