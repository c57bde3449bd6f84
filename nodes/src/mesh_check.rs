//! Checks a mesh must pass before it is emitted as a solid: closed, 2-manifold, consistently and
//! outwardly oriented, without degenerate faces. (Self-intersection tests join these with the
//! reconstruction stages.)

use std::collections::HashMap;

use crate::artifact::Mesh;

/// What a closed-solid check found.
#[derive(Debug, Clone, PartialEq)]
pub struct SolidReport {
    /// Enclosed volume, m³.
    pub volume_m3: f64,
    /// Triangles.
    pub triangles: usize,
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
        let (u, v) = (
            [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
            [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
        );
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        if (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() < 1e-9 {
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
