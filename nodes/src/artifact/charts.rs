//! Surfaces and texels (paper Sec. 4.2): each building solid's faces grouped into planar charts,
//! each with a UV frame and a texel grid, and per-texel layers fused from street views onto them.
//!
//! A wall chart's `u` runs along the wall and `v` up it (in the wall's plane); a roof chart's `u`
//! and `v` are plan x and y, so a roof texel is square in plan. Texel (i, j) covers
//! `[i, i + 1) x [j, j + 1)` texel units from the chart's `origin`; its centre is at `i + 0.5`.

use glam::DVec3;
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

#[cfg(test)]
impl Chart {
    /// For tests: a wall chart of `w` x `h` texels of 0.1 m, all on the surface, its origin at
    /// the site's origin, `u` along +x, `v` up, facing -y.
    pub(crate) fn flat_wall(w: u32, h: u32) -> Chart {
        Chart {
            object: 0,
            building: "building-0".into(),
            kind: ChartKind::Wall,
            origin: [0.0; 3],
            u_axis: [1.0, 0.0, 0.0],
            v_axis: [0.0, 0.0, 1.0],
            normal: [0.0, -1.0, 0.0],
            texel_m: 0.1,
            width: w,
            height: h,
            triangles: PodVec(vec![0]),
            triangle_at: PodVec(vec![0; (w * h) as usize]),
        }
    }
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
                let d = DVec3::from(p) - DVec3::from(self.origin);
                (
                    d.dot(self.u_axis.into()) / self.texel_m,
                    d.dot(self.v_axis.into()) / self.texel_m,
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
        plane_point(
            self.kind,
            self.origin,
            [self.u_axis, self.v_axis, self.normal],
            self.texel_m,
            u,
            v,
        )
    }

    /// Where the chart lies and which of its texels are on the surface, without the triangles:
    /// what a viewer needs to drape texel layers over the building.
    pub fn frame(&self) -> ChartFrame {
        let mut covered = vec![0u64; self.len().div_ceil(64)];
        for (k, &t) in self.triangle_at.iter().enumerate() {
            if t != u32::MAX {
                covered[k / 64] |= 1 << (k % 64);
            }
        }
        ChartFrame {
            kind: self.kind,
            origin: self.origin,
            u_axis: self.u_axis,
            v_axis: self.v_axis,
            normal: self.normal,
            texel_m: self.texel_m,
            width: self.width,
            height: self.height,
            covered,
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

/// A chart's plane, grid and surface coverage: [`Chart`] without its triangle index.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChartFrame {
    /// Wall or roof.
    pub kind: ChartKind,
    /// World position of texel coordinate (0, 0).
    pub origin: [f64; 3],
    /// Unit vector of increasing `u`.
    pub u_axis: [f64; 3],
    /// Unit vector of increasing `v`.
    pub v_axis: [f64; 3],
    /// Outward unit normal.
    pub normal: [f64; 3],
    /// Texel edge, metres.
    pub texel_m: f64,
    /// Texels along `u`.
    pub width: u32,
    /// Texels along `v`.
    pub height: u32,
    /// Bit k (row-major) set when texel k's centre lies on the surface.
    pub covered: Vec<u64>,
}

impl ChartFrame {
    /// World position of continuous texel coordinates (u, v), as [`Chart::world_of`].
    pub fn world_of(&self, u: f64, v: f64) -> [f64; 3] {
        plane_point(
            self.kind,
            self.origin,
            [self.u_axis, self.v_axis, self.normal],
            self.texel_m,
            u,
            v,
        )
    }

    /// True when texel k's centre lies on the surface.
    pub fn is_covered(&self, k: usize) -> bool {
        self.covered
            .get(k / 64)
            .is_some_and(|w| w >> (k % 64) & 1 == 1)
    }
}

/// The point at texel coordinates (u, v) of a chart plane: walls span `u_axis` and `v_axis`;
/// roofs are parametrised by plan x and y and lifted onto the plane.
fn plane_point(
    kind: ChartKind,
    origin: [f64; 3],
    [u_axis, v_axis, normal]: [[f64; 3]; 3],
    texel_m: f64,
    u: f64,
    v: f64,
) -> [f64; 3] {
    let (su, sv) = (u * texel_m, v * texel_m);
    match kind {
        ChartKind::Wall => std::array::from_fn(|k| origin[k] + su * u_axis[k] + sv * v_axis[k]),
        ChartKind::Roof => {
            // On the plane n . (p - origin) = 0, solved for z (roofs look up: n_z > 0.5).
            let z = origin[2] - (normal[0] * su + normal[1] * sv) / normal[2];
            [origin[0] + su, origin[1] + sv, z]
        }
    }
}

/// The charts of every building of a scene.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChartSet {
    /// In object order, then by first triangle.
    pub charts: Vec<Chart>,
}

impl ChartSet {
    /// Charts index the objects and triangles of the scene they were made from: `Err` naming
    /// the first chart that does not fit `scene`.
    pub fn check_made_from(&self, scene: &super::Scene) -> Result<(), String> {
        for c in &self.charts {
            let ok = scene.objects.get(c.object as usize).is_some_and(|o| {
                o.id == c.building
                    && c.triangles
                        .iter()
                        .all(|&t| (t as usize) < o.mesh.triangles.len())
            });
            if !ok {
                return Err(format!(
                    "the charts were not made from this scene (chart on {} at object {})",
                    c.building, c.object
                ));
            }
        }
        Ok(())
    }
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
    /// The charts' frames, in the same order, so the layers can be draped over the buildings
    /// (the glb export); empty for layers made before frames were kept.
    #[serde(default)]
    pub frames: Vec<ChartFrame>,
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
