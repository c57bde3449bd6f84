//! Planar charts on building solids (paper Sec. 4.2, "Surfaces and texels" in DESIGN.md): the
//! faces of each building grouped into planes joined along shared edges, each with a UV frame and
//! a texel grid whose texels know the triangle under their centre.

use std::collections::BTreeMap;

use glam::DVec3;

use crate::artifact::{Chart, ChartKind, ChartSet, Mesh, ObjectClass, PodVec, Scene};
use crate::geom::union_find::UnionFind;

/// How charts are cut and gridded.
#[derive(Clone, Copy, Debug)]
pub struct ChartSpec {
    /// Texel edge on walls, metres.
    pub wall_texel_m: f64,
    /// Texel edge on roofs (in plan), metres.
    pub roof_texel_m: f64,
    /// Two faces sharing an edge join one chart when their normals differ by less than this.
    pub max_bend_deg: f64,
    /// ... and their planes are this close at the shared edge's far vertices, metres.
    pub max_offset_m: f64,
    /// The most texels over all charts (a guard against a texel size typed too small).
    pub max_texels: u64,
}

impl Default for ChartSpec {
    fn default() -> Self {
        ChartSpec {
            wall_texel_m: 0.1,
            roof_texel_m: 0.25,
            max_bend_deg: 1.0,
            max_offset_m: 0.02,
            max_texels: 200_000_000,
        }
    }
}

/// Faces whose outward normal has a z component above this are roofs; below `-WALL_NZ` they
/// look down (floors, overhang soffits) and get no chart: street views never see them.
const WALL_NZ: f64 = 0.5;

/// The charts of every `Building` object of `scene`, in object order; within an object, by the
/// first triangle of each chart.
pub fn building_charts(scene: &Scene, spec: &ChartSpec) -> Result<ChartSet, String> {
    let mut charts = Vec::new();
    let mut texels = 0u64;
    for (k, o) in scene.objects.iter().enumerate() {
        if o.class != ObjectClass::Building {
            continue;
        }
        for group in planar_groups(&o.mesh, spec) {
            let Some(chart) = chart_of(k as u32, &o.id, &o.mesh, &group, spec)? else {
                continue;
            };
            texels += chart.len() as u64;
            if texels > spec.max_texels {
                return Err(format!(
                    "the charts need more than {} texels (at {} m on walls, {} m on roofs); use larger texels",
                    spec.max_texels, spec.wall_texel_m, spec.roof_texel_m
                ));
            }
            charts.push(chart);
        }
    }
    Ok(ChartSet { charts })
}

fn vertex(m: &Mesh, i: u32) -> DVec3 {
    DVec3::from(m.positions[i as usize].map(|c| c as f64))
}

/// Unit normal and twice the area of triangle `t`.
fn face(m: &Mesh, t: usize) -> (DVec3, f64) {
    let [a, b, c] = m.triangles[t].map(|i| vertex(m, i));
    let n = (b - a).cross(c - a);
    let len = n.length();
    if len == 0.0 {
        return (DVec3::ZERO, 0.0);
    }
    (n / len, len)
}

/// Triangles grouped into planar charts: union-find over shared edges between faces of nearly
/// the same plane. Degenerate faces join nothing and are left out.
fn planar_groups(m: &Mesh, spec: &ChartSpec) -> Vec<Vec<u32>> {
    let n = m.triangles.len();
    let faces: Vec<(DVec3, f64)> = (0..n).map(|t| face(m, t)).collect();
    let mut sets = UnionFind::new(n);
    let mut by_edge: BTreeMap<(u32, u32), Vec<u32>> = BTreeMap::new();
    for (t, tri) in m.triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            by_edge
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push(t as u32);
        }
    }
    let cos_max = spec.max_bend_deg.to_radians().cos();
    for tris in by_edge.values() {
        for (x, &s) in tris.iter().enumerate() {
            for &t in &tris[x + 1..] {
                let ((ns, as_), (nt, at)) = (faces[s as usize], faces[t as usize]);
                if as_ == 0.0 || at == 0.0 || ns.dot(nt) < cos_max {
                    continue;
                }
                // Same plane: every vertex of t lies within the offset of s's plane.
                let p0 = vertex(m, m.triangles[s as usize][0]);
                let flat = m.triangles[t as usize]
                    .iter()
                    .all(|&i| (vertex(m, i) - p0).dot(ns).abs() <= spec.max_offset_m);
                if flat {
                    sets.join(s, t);
                }
            }
        }
    }
    let mut groups: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for t in 0..n as u32 {
        if faces[t as usize].1 > 0.0 {
            groups.entry(sets.root(t)).or_default().push(t);
        }
    }
    groups.into_values().collect()
}

/// One chart over `tris`: its frame from the area-weighted normal, its grid from the triangles'
/// extent in UV, and the triangle under each texel centre. `None` for faces looking down.
fn chart_of(
    object: u32,
    id: &str,
    m: &Mesh,
    tris: &[u32],
    spec: &ChartSpec,
) -> Result<Option<Chart>, String> {
    let mut n = DVec3::ZERO;
    for &t in tris {
        let (nt, a) = face(m, t as usize);
        n += nt * a;
    }
    let n = (n / n.length()).to_array();
    let (kind, u_axis, v_axis, texel_m) = if n[2] > WALL_NZ {
        (
            ChartKind::Roof,
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            spec.roof_texel_m,
        )
    } else if n[2] >= -WALL_NZ {
        // u along the wall (horizontal), v up the wall in its plane: (u, v, n) right-handed.
        let h = (n[0] * n[0] + n[1] * n[1]).sqrt();
        let u = [-n[1] / h, n[0] / h, 0.0];
        (
            ChartKind::Wall,
            u,
            DVec3::from(n).cross(u.into()).to_array(),
            spec.wall_texel_m,
        )
    } else {
        return Ok(None);
    };
    // A point on the plane; the grid's corner is placed from the UV extent below.
    let p0 = vertex(m, m.triangles[tris[0] as usize][0]).to_array();
    let mut chart = Chart {
        object,
        building: id.to_owned(),
        kind,
        origin: p0,
        u_axis,
        v_axis,
        normal: n,
        texel_m,
        width: 0,
        height: 0,
        triangles: PodVec(tris.to_vec()),
        triangle_at: PodVec(Vec::new()),
    };
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for &t in tris {
        for &i in &m.triangles[t as usize] {
            let (u, v) = chart.uv_of(vertex(m, i).to_array());
            lo = [lo[0].min(u), lo[1].min(v)];
            hi = [hi[0].max(u), hi[1].max(v)];
        }
    }
    let (w, h) = (
        (hi[0] - lo[0]).ceil().max(1.0),
        (hi[1] - lo[1]).ceil().max(1.0),
    );
    if !(w * h <= spec.max_texels as f64) {
        return Err(format!(
            "a chart of {id} would need {w} x {h} texels; use larger texels"
        ));
    }
    chart.origin = chart.world_of(lo[0].floor(), lo[1].floor());
    chart.width = w as u32 + 1;
    chart.height = h as u32 + 1;
    chart.triangle_at = PodVec(texel_triangles(&chart, m));
    Ok(Some(chart))
}

/// For each texel centre, the chart triangle containing it in UV (the first, in triangle order,
/// where triangles share an edge), else `u32::MAX`.
fn texel_triangles(c: &Chart, m: &Mesh) -> Vec<u32> {
    let mut at = vec![u32::MAX; c.len()];
    for &t in c.triangles.iter() {
        let uv = m.triangles[t as usize].map(|i| c.uv_of(vertex(m, i).to_array()));
        let (u0, u1) = (
            uv.iter().map(|p| p.0).fold(f64::INFINITY, f64::min),
            uv.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max),
        );
        let (v0, v1) = (
            uv.iter().map(|p| p.1).fold(f64::INFINITY, f64::min),
            uv.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max),
        );
        let area = orient(uv[0], uv[1], uv[2]);
        if area == 0.0 {
            continue;
        }
        let i_lo = (u0 - 0.5).ceil().max(0.0) as u32;
        let i_hi = ((u1 - 0.5).floor().max(-1.0) as i64).min(c.width as i64 - 1);
        let j_lo = (v0 - 0.5).ceil().max(0.0) as u32;
        let j_hi = ((v1 - 0.5).floor().max(-1.0) as i64).min(c.height as i64 - 1);
        for j in j_lo as i64..=j_hi {
            for i in i_lo as i64..=i_hi {
                let p = (i as f64 + 0.5, j as f64 + 0.5);
                let s = area.signum();
                let inside = [(0, 1), (1, 2), (2, 0)]
                    .iter()
                    .all(|&(a, b)| orient(uv[a], uv[b], p) * s >= 0.0);
                let k = j as usize * c.width as usize + i as usize;
                if inside && at[k] == u32::MAX {
                    at[k] = t;
                }
            }
        }
    }
    at
}

fn orient(a: (f64, f64), b: (f64, f64), p: (f64, f64)) -> f64 {
    (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::artifact::SceneObject;
    use crate::geom::mesh_build::cuboid;

    fn box_scene() -> Scene {
        Scene {
            objects: vec![SceneObject {
                id: "building-0".into(),
                class: ObjectClass::Building,
                mesh: cuboid([12.0, 21.5], [4.0, 3.0, 6.0], 0.0, 0.0, Material::Concrete),
            }],
        }
    }

    #[test]
    fn a_box_has_four_walls_and_a_roof_and_no_floor_chart() {
        let c = building_charts(&box_scene(), &ChartSpec::default()).unwrap();
        let walls = c
            .charts
            .iter()
            .filter(|c| c.kind == ChartKind::Wall)
            .count();
        let roofs = c
            .charts
            .iter()
            .filter(|c| c.kind == ChartKind::Roof)
            .count();
        assert_eq!((walls, roofs), (4, 1));
        for ch in &c.charts {
            // v runs up every wall; every texel centre of a rectangle face is on it.
            if ch.kind == ChartKind::Wall {
                assert!((ch.v_axis[2] - 1.0).abs() < 1e-9);
                let area = ch.covered() as f64 * 0.01;
                assert!(area == 4.0 * 6.0 || area == 3.0 * 6.0, "{area}");
            } else {
                assert_eq!(ch.covered(), 16 * 12);
            }
        }
    }

    #[test]
    fn texel_to_world_to_texel_round_trips_within_half_a_texel() {
        let c = building_charts(&box_scene(), &ChartSpec::default()).unwrap();
        for ch in &c.charts {
            for j in 0..ch.height {
                for i in 0..ch.width {
                    let p = ch.texel_center(i, j);
                    assert_eq!(ch.texel_of(p), Some((i, j)));
                    let (u, v) = ch.uv_of(p);
                    assert!((u - i as f64 - 0.5).abs() < 1e-6 && (v - j as f64 - 0.5).abs() < 1e-6);
                    // The centre lies on the chart's plane.
                    let d = DVec3::from(p) - DVec3::from(ch.origin);
                    assert!(d.dot(ch.normal.into()).abs() < 1e-6);
                }
            }
        }
    }
}
