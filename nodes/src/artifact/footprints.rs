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
                            if poly.contains([x, y]) {
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
    let mut inside = false;
    let n = ring.len();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + n - 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0]
        {
            inside = !inside;
        }
    }
    inside
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
