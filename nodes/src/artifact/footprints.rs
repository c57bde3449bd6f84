//! Building footprints in the site frame.

use serde::{Deserialize, Serialize};

/// A polygon in the site frame: exterior counter-clockwise, holes clockwise, rings open (the
/// closing vertex is not repeated).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    /// Outer ring.
    pub exterior: Vec<[f64; 2]>,
    /// Inner rings (courtyards).
    pub holes: Vec<Vec<[f64; 2]>>,
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
