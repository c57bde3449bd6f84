//! Surfaces and texels (paper Sec. 4.2): each building solid's faces grouped into planar charts,
//! each with a UV frame and a texel grid, and per-texel layers fused from street views onto them.
//!
//! A wall chart's `u` runs along the wall and `v` up it (in the wall's plane); a roof chart's `u`
//! and `v` are plan x and y, so a roof texel is square in plan. Texel (i, j) covers
//! `[i, i + 1) x [j, j + 1)` texel units from the chart's `origin`; its centre is at `i + 0.5`.

use serde::{Deserialize, Serialize};

use super::PodVec;

/// What a chart covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ChartKind {
    /// A façade: a face whose normal is within 60 degrees of horizontal.
    Wall,
    /// A roof facet: a face looking up.
    Roof,
}

/// One planar chart on one building.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Chart {
    /// Index of the building's object in the scene the charts were made from.
    pub object: u32,
    /// That object's id (`building-<n>`).
    pub building: String,
    /// Wall or roof.
    pub kind: ChartKind,
    /// World position of texel coordinate (0, 0), site frame, metres.
    pub origin: [f64; 3],
    /// Unit vector of increasing `u` (walls: along the wall; roofs: +x).
    pub u_axis: [f64; 3],
    /// Unit vector of increasing `v` (walls: up the wall; roofs: +y).
    pub v_axis: [f64; 3],
    /// Outward unit normal of the plane.
    pub normal: [f64; 3],
    /// Texel edge, metres (in plan for roofs).
    pub texel_m: f64,
    /// Texels along `u`.
    pub width: u32,
    /// Texels along `v`.
    pub height: u32,
    /// The object's triangles that make up this chart.
    pub triangles: PodVec<u32>,
    /// Per texel (row-major, `v` rows), the chart triangle under its centre, or `u32::MAX` when
    /// the centre is off the surface (outside the chart's outline).
    pub triangle_at: PodVec<u32>,
}

impl Chart {
    /// Texel count.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// True when the grid has no texels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Texels whose centre lies on the surface.
    pub fn covered(&self) -> usize {
        self.triangle_at.iter().filter(|&&t| t != u32::MAX).count()
    }

    /// Continuous texel coordinates (u, v) of world point `p` (on or near the plane).
    pub fn uv_of(&self, p: [f64; 3]) -> (f64, f64) {
        match self.kind {
            ChartKind::Wall => {
                let d = sub(p, self.origin);
                (
                    dot(d, self.u_axis) / self.texel_m,
                    dot(d, self.v_axis) / self.texel_m,
                )
            }
            ChartKind::Roof => (
                (p[0] - self.origin[0]) / self.texel_m,
                (p[1] - self.origin[1]) / self.texel_m,
            ),
        }
    }

    /// World position of continuous texel coordinates (u, v), on the chart's plane.
    pub fn world_of(&self, u: f64, v: f64) -> [f64; 3] {
        let (su, sv) = (u * self.texel_m, v * self.texel_m);
        match self.kind {
            ChartKind::Wall => {
                std::array::from_fn(|k| self.origin[k] + su * self.u_axis[k] + sv * self.v_axis[k])
            }
            ChartKind::Roof => {
                let (x, y) = (self.origin[0] + su, self.origin[1] + sv);
                // On the plane n . (p - origin) = 0, solved for z (roofs look up: n_z > 0.5).
                let n = self.normal;
                let z = self.origin[2] - (n[0] * su + n[1] * sv) / n[2];
                [x, y, z]
            }
        }
    }

    /// World position of texel (i, j)'s centre.
    pub fn texel_center(&self, i: u32, j: u32) -> [f64; 3] {
        self.world_of(i as f64 + 0.5, j as f64 + 0.5)
    }

    /// The texel holding world point `p`, if inside the grid.
    pub fn texel_of(&self, p: [f64; 3]) -> Option<(u32, u32)> {
        let (u, v) = self.uv_of(p);
        let (i, j) = (u.floor(), v.floor());
        (i >= 0.0 && j >= 0.0 && i < self.width as f64 && j < self.height as f64)
            .then_some((i as u32, j as u32))
    }
}

/// The charts of every building of a scene.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChartSet {
    /// In object order, then by first triangle.
    pub charts: Vec<Chart>,
}

/// The per-texel layers of one chart, fused from street views (eq. (2)-(3)).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChartLayers {
    /// Texels along `u` (the chart's width).
    pub width: u32,
    /// Texels along `v`.
    pub height: u32,
    /// Exposure W_exp: the sum of the kernel weights ω of every pixel that saw the texel.
    pub w_exp: PodVec<f32>,
    /// Pixel hits whose centre landed in the texel (saturating at 65535).
    pub hits: PodVec<u16>,
    /// Vote totals per class (an index into [`TexelLayers::classes`]): the sum of ω over pixels
    /// labelled with that class. Only classes with a vote on this chart are stored.
    pub votes: Vec<(u16, PodVec<f32>)>,
}

impl ChartLayers {
    /// The class with the most votes at texel `k` (the lowest index on a tie), `None` where no
    /// class has a vote.
    pub fn winner(&self, k: usize) -> Option<u16> {
        let mut best: Option<(u16, f32)> = None;
        for (c, v) in &self.votes {
            let x = v.get(k).copied().unwrap_or(0.0);
            if x > 0.0 && best.is_none_or(|(_, b)| x > b) {
                best = Some((*c, x));
            }
        }
        best.map(|(c, _)| c)
    }
}

/// Layers over a set of charts: one [`ChartLayers`] per chart, in the charts' order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TexelLayers {
    /// Class names the votes index.
    pub classes: Vec<String>,
    /// One per chart.
    pub charts: Vec<ChartLayers>,
    /// Views that contributed, and pixel rays cast, hit a chart, passed the angle gate.
    pub stats: FusionStats,
}

/// What a fusion saw: the numbers behind its exposure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FusionStats {
    /// Views fused.
    pub views: u64,
    /// Pixel rays cast.
    pub rays: u64,
    /// Rays whose closest hit is on a building chart.
    pub chart_hits: u64,
    /// Of those, rays within the angle gate theta_max that voted or counted as exposure.
    pub accepted: u64,
    /// Rays dropped because their pixel belongs to a clutter instance (occlusion masking).
    pub masked: u64,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
