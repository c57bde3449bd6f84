//! Checks a mesh must pass before it is emitted as a solid: closed, 2-manifold, consistently and
//! outwardly oriented, without degenerate faces ([`check_closed_solid`]) and, for the meshes the
//! reconstruction emits, without self-intersections ([`check_solid`]). The synthetic truth scenes
//! only need the first: their buildings are unions of closed shells that overlap on purpose.

use std::collections::HashMap;

use glam::DVec3;

use crate::artifact::Mesh;

/// What a closed-solid check found.
#[derive(Debug, Clone, PartialEq)]
pub struct SolidReport {
    /// Enclosed volume, m³.
    pub volume_m3: f64,
    /// Triangles.
    pub triangles: usize,
}

/// Whether a triangle's corners lie on one line (near-zero area), in the scene's f32.
pub fn is_degenerate([a, b, c]: [[f32; 3]; 3]) -> bool {
    let (u, v) = (
        [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
        [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
    );
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() < 1e-9
}

/// Checks that `mesh` is a closed, oriented 2-manifold with positive volume: every directed edge
/// appears exactly once and its reverse exactly once, no triangle has (near-)zero area.
pub fn check_closed_solid(mesh: &Mesh) -> Result<SolidReport, String> {
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    for (k, t) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| mesh.positions.get(i as usize).copied());
        let (Some(a), Some(b), Some(c)) = (a, b, c) else {
            return Err(format!("triangle {k} indexes a missing vertex"));
        };
        if is_degenerate([a, b, c]) {
            return Err(format!("triangle {k} is degenerate"));
        }
        for (p, q) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *directed.entry((p, q)).or_default() += 1;
        }
    }
    for (&(p, q), &n) in &directed {
        if n != 1 {
            return Err(format!(
                "edge {p}->{q} is used {n} times in the same direction (non-manifold or flipped faces)"
            ));
        }
        if directed.get(&(q, p)) != Some(&1) {
            return Err(format!(
                "edge {p}->{q} has no opposite edge: the mesh is open"
            ));
        }
    }
    let volume_m3 = mesh.volume();
    if volume_m3 <= 0.0 {
        return Err(format!(
            "volume {volume_m3:.3} m³ is not positive: faces point inward"
        ));
    }
    Ok(SolidReport {
        volume_m3,
        triangles: mesh.len(),
    })
}

/// Every check a reconstructed solid must pass: [`check_closed_solid`], no vertex shared by two
/// separate fans of faces (a pinch), and no two faces crossing or overlapping
/// ([`find_self_intersection`]).
pub fn check_solid(mesh: &Mesh) -> Result<SolidReport, String> {
    let report = check_closed_solid(mesh)?;
    check_vertex_manifold(mesh)?;
    if let Some((a, b)) = find_self_intersection(mesh) {
        return Err(format!("triangles {a} and {b} intersect"));
    }
    Ok(report)
}

/// On a closed 2-manifold the faces around every vertex form one fan; two fans meeting at a vertex
/// (two solids touching at a corner) make the vertex non-manifold even though every edge is fine.
fn check_vertex_manifold(mesh: &Mesh) -> Result<(), String> {
    // For each vertex, the outgoing edge after `v -> p` going around the fan: the face (v, p, q)
    // maps p to q. One cycle through all of a vertex's faces means one fan.
    let mut next: HashMap<u32, HashMap<u32, u32>> = HashMap::new();
    for t in mesh.triangles.iter() {
        for k in 0..3 {
            let (v, p, q) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            next.entry(v).or_default().insert(p, q);
        }
    }
    let mut vertices: Vec<_> = next.into_iter().collect();
    vertices.sort_unstable_by_key(|(v, _)| *v);
    for (v, fan) in vertices {
        let start = *fan.keys().min().expect("a vertex with faces");
        let (mut cur, mut steps) = (start, 0);
        loop {
            let Some(&n) = fan.get(&cur) else {
                return Err(format!("vertex {v} has an open fan"));
            };
            steps += 1;
            cur = n;
            if cur == start || steps > fan.len() {
                break;
            }
        }
        if steps != fan.len() {
            return Err(format!(
                "vertex {v} joins {} faces in more than one fan (solids touching at a point)",
                fan.len()
            ));
        }
    }
    Ok(())
}

/// Distances below this count as touching, metres: a few f32 steps at kilometre coordinates.
const TOUCH_M: f64 = 1e-5;

type P3 = DVec3;

/// A mesh vertex in f64, where the checks measure.
fn position(mesh: &Mesh, i: u32) -> P3 {
    DVec3::from(mesh.positions[i as usize].map(f64::from))
}

/// Signed distance of `p` from the plane of triangle `t` (positive on its front side).
fn plane_distance(t: &[P3; 3], p: P3) -> f64 {
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    n.dot(p - t[0]) / n.length()
}

/// Which side of the line through `p`, `q` the line through `a`, `b` passes, as a signed distance
/// between the two lines (the scaled orientation of the tetrahedron p, q, a, b).
fn line_side(p: P3, q: P3, a: P3, b: P3) -> f64 {
    let n = (q - p).cross(b - a);
    let len = n.length();
    if len < 1e-300 {
        return 0.0;
    }
    n.dot(a - p) / len
}

/// True when segment `p q` passes through the interior of triangle `t` (touching does not count).
fn segment_crosses(p: P3, q: P3, t: &[P3; 3]) -> bool {
    let (dp, dq) = (plane_distance(t, p), plane_distance(t, q));
    if !((dp > TOUCH_M && dq < -TOUCH_M) || (dp < -TOUCH_M && dq > TOUCH_M)) {
        return false;
    }
    let s = [
        line_side(p, q, t[0], t[1]),
        line_side(p, q, t[1], t[2]),
        line_side(p, q, t[2], t[0]),
    ];
    s.iter().all(|&v| v > TOUCH_M) || s.iter().all(|&v| v < -TOUCH_M)
}

/// Coplanar triangles: project on the plane's dominant axis and look for properly crossing edges
/// or a vertex strictly inside the other triangle.
fn coplanar_overlap(a: &[P3; 3], b: &[P3; 3]) -> bool {
    let n = (a[1] - a[0]).cross(a[2] - a[0]);
    let drop = (0..3)
        .max_by(|&i, &j| n[i].abs().total_cmp(&n[j].abs()))
        .expect("three axes");
    let (u, v) = ((drop + 1) % 3, (drop + 2) % 3);
    let to2 = |p: P3| [p[u], p[v]];
    let (a2, b2) = (a.map(to2), b.map(to2));
    let orient = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        let (d1, d2) = ([q[0] - p[0], q[1] - p[1]], [r[0] - p[0], r[1] - p[1]]);
        (d1[0] * d2[1] - d1[1] * d2[0]) / (d1[0].hypot(d1[1])).max(1e-300)
    };
    let strictly_inside = |t: &[[f64; 2]; 3], p: [f64; 2]| {
        let s = [
            orient(t[0], t[1], p),
            orient(t[1], t[2], p),
            orient(t[2], t[0], p),
        ];
        s.iter().all(|&v| v > TOUCH_M) || s.iter().all(|&v| v < -TOUCH_M)
    };
    for i in 0..3 {
        for j in 0..3 {
            let (p, q) = (a2[i], a2[(i + 1) % 3]);
            let (r, s) = (b2[j], b2[(j + 1) % 3]);
            let (o1, o2) = (orient(p, q, r), orient(p, q, s));
            let (o3, o4) = (orient(r, s, p), orient(r, s, q));
            if o1 * o2 < 0.0
                && o3 * o4 < 0.0
                && o1.abs().min(o2.abs()) > TOUCH_M
                && o3.abs().min(o4.abs()) > TOUCH_M
            {
                return true;
            }
        }
    }
    // A shared vertex sits on a corner of both, never strictly inside.
    (0..3).any(|i| strictly_inside(&a2, b2[i]) || strictly_inside(&b2, a2[i]))
}

/// The first pair of faces (in index order) that cross or overlap, if any. Faces sharing an edge
/// or a vertex are tested only away from what they share. A sweep over x bounds the pairs tested.
pub fn find_self_intersection(mesh: &Mesh) -> Option<(usize, usize)> {
    let tris: Vec<[P3; 3]> = mesh
        .triangles
        .iter()
        .map(|t| t.map(|i| position(mesh, i)))
        .collect();
    let bounds: Vec<([f64; 3], [f64; 3])> = tris
        .iter()
        .map(|t| {
            let lo = [0, 1, 2].map(|k| t.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min));
            let hi = [0, 1, 2].map(|k| t.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max));
            (lo, hi)
        })
        .collect();
    let mut order: Vec<usize> = (0..tris.len()).collect();
    order.sort_by(|&i, &j| bounds[i].0[0].total_cmp(&bounds[j].0[0]).then(i.cmp(&j)));
    let mut found: Option<(usize, usize)> = None;
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if bounds[j].0[0] > bounds[i].1[0] + TOUCH_M {
                break;
            }
            let overlap = (1..3).all(|d| {
                bounds[j].0[d] <= bounds[i].1[d] + TOUCH_M
                    && bounds[i].0[d] <= bounds[j].1[d] + TOUCH_M
            });
            if overlap && faces_intersect(mesh, &tris, i, j) {
                let pair = (i.min(j), i.max(j));
                if found.is_none_or(|f| pair < f) {
                    found = Some(pair);
                }
            }
        }
    }
    found
}

fn faces_intersect(mesh: &Mesh, tris: &[[P3; 3]], i: usize, j: usize) -> bool {
    let (ti, tj) = (mesh.triangles[i], mesh.triangles[j]);
    // shared[k] = position in face i of a vertex also in face j.
    let shared: Vec<usize> = (0..3).filter(|&k| tj.contains(&ti[k])).collect();
    let (a, b) = (&tris[i], &tris[j]);
    if shared.len() == 3 {
        return true;
    }
    let coplanar = b.iter().all(|&p| plane_distance(a, p).abs() <= TOUCH_M);
    if coplanar {
        if shared.len() == 2 {
            // Coplanar neighbours overlap when their third vertices lie on the same side of the
            // shared edge.
            let (e0, e1) = (ti[shared[0]], ti[shared[1]]);
            let third_a = (0..3).find(|k| !shared.contains(k)).expect("one left");
            let third_b = (0..3)
                .find(|&k| tj[k] != e0 && tj[k] != e1)
                .expect("one left");
            let (p, q) = (position(mesh, e0), position(mesh, e1));
            let n = (a[1] - a[0]).cross(a[2] - a[0]);
            let side = |r: P3| n.dot((q - p).cross(r - p));
            return side(a[third_a]) * side(b[third_b]) > 0.0;
        }
        return coplanar_overlap(a, b);
    }
    let edges = |t: &[P3; 3], idx: [u32; 3], other: [u32; 3]| -> Vec<(P3, P3)> {
        (0..3)
            .filter(|&k| !(other.contains(&idx[k]) && other.contains(&idx[(k + 1) % 3])))
            .map(|k| (t[k], t[(k + 1) % 3]))
            .collect()
    };
    edges(a, ti, tj)
        .iter()
        .any(|&(p, q)| segment_crosses(p, q, b))
        || edges(b, tj, ti)
            .iter()
            .any(|&(p, q)| segment_crosses(p, q, a))
}

/// What a stage does with a solid that fails [`check_solid`]: stop the run, leave the object out
/// (counted and warned about), or try to mend it first (how is the stage's to say) and leave it
/// out only if that fails.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OnInvalid {
    /// The stage fails, naming the object and the check it failed.
    Fail,
    /// The object is left out, counted in the stage's report and warned about.
    Drop,
    /// The stage tries its repairs, in its stated order; what none mends is dropped.
    Repair,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::artifact::Polygon;
    use crate::geom::mesh_build::{cuboid, dome, gabled, prism};

    fn two(a: &Mesh, b: &Mesh) -> Mesh {
        let mut m = a.clone();
        m.append(b);
        m
    }

    #[test]
    fn valid_solids_pass_every_check() {
        let court = Polygon::normalized(
            vec![[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0]],
            vec![vec![[5.0, 5.0], [15.0, 5.0], [15.0, 15.0], [5.0, 15.0]]],
        )
        .unwrap();
        let p = prism(&court, 0.0, 9.0, Material::Brick, Material::Concrete).unwrap();
        check_solid(&p).unwrap();
        check_solid(&dome([0.0, 0.0], 6.0, 4.0, 20.0, 32, Material::Metal)).unwrap();
        let rect = crate::artifact::Rect {
            corner: [400_000.0, 5_000_000.0],
            length: 20.0,
            width: 9.0,
            heading: 0.3,
        };
        check_solid(&gabled(
            &rect,
            1.0,
            6.0,
            9.0,
            Material::Brick,
            Material::Concrete,
        ))
        .unwrap();
        // Two separate shells are still a valid solid.
        let a = cuboid([0.0, 0.0], [2.0, 2.0, 2.0], 0.0, 0.0, Material::Metal);
        let b = cuboid([5.0, 0.0], [2.0, 2.0, 2.0], 0.0, 0.0, Material::Metal);
        check_solid(&two(&a, &b)).unwrap();
    }

    #[test]
    fn overlapping_shells_are_self_intersections() {
        let a = cuboid([0.0, 0.0], [2.0, 2.0, 2.0], 0.0, 0.0, Material::Metal);
        let b = cuboid([1.0, 0.5], [2.0, 2.0, 2.0], 0.4, 0.5, Material::Metal);
        assert!(
            check_closed_solid(&two(&a, &b)).is_ok(),
            "each shell is closed"
        );
        let err = check_solid(&two(&a, &b)).unwrap_err();
        assert!(err.contains("intersect"), "{err}");
        // Boxes on the same floor with the same height: their tops and bottoms overlap in a plane.
        let c = cuboid([1.5, 0.0], [2.0, 2.0, 2.0], 0.0, 0.0, Material::Metal);
        assert!(find_self_intersection(&two(&a, &c)).is_some());
    }

    #[test]
    fn shells_touching_at_a_shared_vertex_are_not_manifold() {
        // Two tetrahedra sharing vertex 0 only.
        let m = Mesh {
            positions: crate::artifact::PodVec(vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [-1.0, 0.0, 0.0],
                [0.0, -1.0, 0.0],
                [0.0, 0.0, -1.0],
            ]),
            triangles: crate::artifact::PodVec(vec![
                [0, 2, 1],
                [0, 1, 3],
                [0, 3, 2],
                [1, 2, 3],
                [0, 4, 5],
                [0, 6, 4],
                [0, 5, 6],
                [6, 5, 4],
            ]),
            materials: crate::artifact::PodVec(vec![0; 8]),
        };
        check_closed_solid(&m).unwrap();
        let err = check_solid(&m).unwrap_err();
        assert!(err.contains("more than one fan"), "{err}");
    }
}
