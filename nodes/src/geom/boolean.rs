//! Exact Booleans on closed meshes, with `manifold-rust`'s exact engine (Manifold's algorithm:
//! symbolic perturbation, so coplanar and touching faces are decided consistently). Per-triangle
//! materials ride through as Manifold face IDs: every input triangle carries its material as its
//! face ID, and every output triangle reports the face ID of the input triangle it is a piece of.
//! Façade relief carving and the synthetic truth's buildings are built with it.

use manifold_rust::manifold::Manifold;
use manifold_rust::types::{BooleanEngine, Error, MeshGL64, OpType};

use crate::artifact::Material;
use crate::artifact::{Mesh, PodVec};
use crate::geom::mesh_check::{check_solid, is_degenerate};

/// `m` as a Manifold, its materials as face IDs; an error when it is not a closed 2-manifold.
pub fn to_manifold(m: &Mesh) -> Result<Manifold, String> {
    let mut gl = MeshGL64 {
        num_prop: 3,
        vert_properties: m
            .positions
            .iter()
            .flat_map(|p| p.map(|c| c as f64))
            .collect(),
        tri_verts: m
            .triangles
            .iter()
            .flat_map(|t| t.map(|i| i as u64))
            .collect(),
        face_id: m.materials.iter().map(|&x| x as u64).collect(),
        ..Default::default()
    };
    gl.merge();
    let out = Manifold::from_mesh_gl64(&gl);
    match out.status() {
        Error::NoError => Ok(out),
        e => Err(format!("Manifold rejected the mesh: {e:?}")),
    }
}

/// The mesh of `m`; a triangle whose face ID is no material takes `fallback`.
///
/// Positions are rounded to f32 (the scene's precision): two vertices the Boolean made closer
/// than an f32 step apart (6e-5 m a kilometre from the origin) become one, and the triangles
/// between them, now with a repeated corner, are dropped: the collapse of an edge shorter than
/// the scene can represent. Slivers whose three corners the rounding leaves on one line are
/// mended ([`mend_slivers`]). Whether what remains is still a solid is for the caller's check.
pub fn from_manifold(m: &Manifold, fallback: Material) -> Mesh {
    let gl = m.get_mesh_gl64(-1);
    let np = gl.num_prop as usize;
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut index_of: std::collections::HashMap<[u32; 3], u32> = Default::default();
    let remap: Vec<u32> = gl
        .vert_properties
        .chunks_exact(np.max(3))
        .map(|v| {
            let p = [v[0] as f32, v[1] as f32, v[2] as f32];
            *index_of
                .entry(p.map(|c| (c + 0.0).to_bits()))
                .or_insert_with(|| {
                    positions.push(p);
                    (positions.len() - 1) as u32
                })
        })
        .collect();
    let (mut triangles, mut materials) = (Vec::new(), Vec::new());
    for (k, t) in gl.tri_verts.chunks_exact(3).enumerate() {
        let t = [t[0], t[1], t[2]].map(|i| remap[i as usize]);
        if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            continue;
        }
        triangles.push(t);
        materials.push(
            gl.face_id
                .get(k)
                .and_then(|&f| u8::try_from(f).ok())
                .filter(|&f| Material::from_u8(f).is_some())
                .unwrap_or(fallback as u8),
        );
    }
    mend_slivers(&positions, &mut triangles, &mut materials, 0.0);
    Mesh {
        positions: PodVec(positions),
        triangles: PodVec(triangles),
        materials: PodVec(materials),
    }
}

/// Whether triangle `t` of `positions` is a sliver: [`check_solid`]'s degenerate test, or a
/// corner within `thin_m` of the opposite edge (0: the degenerate test alone).
fn is_sliver(positions: &[[f32; 3]], t: [u32; 3], thin_m: f64) -> bool {
    let p = t.map(|i| positions[i as usize]);
    if is_degenerate(p) {
        return true;
    }
    if thin_m <= 0.0 {
        return false;
    }
    let p = p.map(|v| glam::DVec3::from(v.map(f64::from)));
    let twice_area = (p[1] - p[0]).cross(p[2] - p[0]).length();
    let longest = (0..3)
        .map(|i| p[i].distance(p[(i + 1) % 3]))
        .fold(0.0, f64::max);
    twice_area < thin_m * longest
}

/// How far off its longest edge a sliver's middle corner may lie for [`subtract_then_add`] to
/// mend it when the result fails the check: a few f32 steps a kilometre out (6e-5 m each). The
/// Boolean's exact result rounded to f32 can leave a T-junction's sliver just off its line,
/// folded over its neighbour, and the check then reports the two as intersecting.
const THIN_SLIVER_M: f64 = 2e-4;

/// Removes the slivers the Boolean leaves at T-junctions, whose three corners lie on one line
/// once rounded to f32, keeping the surface closed: the neighbour across a sliver's longest edge
/// is split at its middle corner, and the sliver goes. A sliver whose neighbour is another
/// sliver, or has none, stays for the caller's check to report.
fn mend_slivers(
    positions: &[[f32; 3]],
    triangles: &mut Vec<[u32; 3]>,
    materials: &mut Vec<u8>,
    thin_m: f64,
) {
    // A sliver beside another is mended once that one is: pass again while a pass mends any.
    for _ in 0..MEND_PASSES {
        if !mend_pass(positions, triangles, materials, thin_m) {
            break;
        }
    }
}

/// Passes of [`mend_slivers`] at most: a chain of slivers side by side takes one pass each.
const MEND_PASSES: usize = 8;

/// One pass of [`mend_slivers`]: whether it mended any sliver.
fn mend_pass(
    positions: &[[f32; 3]],
    triangles: &mut Vec<[u32; 3]>,
    materials: &mut Vec<u8>,
    thin_m: f64,
) -> bool {
    let mut owner: std::collections::HashMap<(u32, u32), usize> = Default::default();
    for (k, t) in triangles.iter().enumerate() {
        for e in 0..3 {
            owner.insert((t[e], t[(e + 1) % 3]), k);
        }
    }
    let len2 = |p: u32, q: u32| {
        let (a, b) = (positions[p as usize], positions[q as usize]);
        (0..3).map(|k| ((a[k] - b[k]) as f64).powi(2)).sum::<f64>()
    };
    let mut gone = vec![false; triangles.len()];
    for k in 0..triangles.len() {
        let t = triangles[k];
        if gone[k] || !is_sliver(positions, t, thin_m) {
            continue;
        }
        // The longest edge (x, y), in the sliver's order; m the corner between them.
        let e = (0..3)
            .max_by(|&i, &j| len2(t[i], t[(i + 1) % 3]).total_cmp(&len2(t[j], t[(j + 1) % 3])))
            .unwrap_or(0);
        let (x, y, m) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
        let Some(&nk) = owner.get(&(y, x)) else {
            continue;
        };
        let n = triangles[nk];
        if gone[nk] || nk == k || is_sliver(positions, n, thin_m) {
            continue;
        }
        let Some(i) = (0..3).find(|&i| n[i] == y && n[(i + 1) % 3] == x) else {
            continue;
        };
        let r = n[(i + 2) % 3];
        let (first, second) = ([y, m, r], [m, x, r]);
        if is_sliver(positions, first, thin_m) || is_sliver(positions, second, thin_m) {
            continue;
        }
        for (p, q) in [(x, y), (y, m), (m, x), (y, x), (x, r), (r, y)] {
            owner.remove(&(p, q));
        }
        triangles[nk] = first;
        triangles.push(second);
        materials.push(materials[nk]);
        gone.push(false);
        gone[k] = true;
        let added = triangles.len() - 1;
        for (p, q, o) in [
            (y, m, nk),
            (m, r, nk),
            (r, y, nk),
            (m, x, added),
            (x, r, added),
            (r, m, added),
        ] {
            owner.insert((p, q), o);
        }
    }
    let mut k = 0..;
    triangles.retain(|_| !gone[k.next().unwrap_or(0)]);
    let mut k = 0..;
    materials.retain(|_| !gone[k.next().unwrap_or(0)]);
    gone.contains(&true)
}

fn op(a: &Manifold, b: &Manifold, o: OpType) -> Result<Manifold, String> {
    let r = a.boolean_with_engine(b, o, BooleanEngine::Exact);
    match r.status() {
        Error::NoError => Ok(r),
        e => Err(format!("Boolean failed: {e:?}")),
    }
}

/// The union of `parts`, `None` when there are none. Pairwise in a balanced tree, so each part
/// is merged O(log n) times rather than into one ever-growing solid.
pub fn union_all(parts: &[&Manifold]) -> Result<Option<Manifold>, String> {
    let mut level: Vec<Manifold> = parts.iter().map(|&m| m.clone()).collect();
    while level.len() > 1 {
        let mut next = Vec::with_capacity(level.len().div_ceil(2));
        let mut it = level.chunks(2);
        for pair in &mut it {
            next.push(match pair {
                [a, b] => op(a, b, OpType::Add)?,
                [a] => a.clone(),
                _ => unreachable!("chunks of two"),
            });
        }
        level = next;
    }
    Ok(level.pop())
}

/// `base` less the union of `recesses`, plus the union of `protrusions`: the result as a mesh,
/// checked by [`check_solid`]. Triangles of no material take `fallback`.
pub fn subtract_then_add(
    base: &Manifold,
    recesses: &[&Manifold],
    protrusions: &[&Manifold],
    fallback: Material,
) -> Result<Mesh, String> {
    let mut out = base.clone();
    if let Some(r) = union_all(recesses)? {
        out = op(&out, &r, OpType::Subtract)?;
    }
    if let Some(pr) = union_all(protrusions)? {
        out = op(&out, &pr, OpType::Add)?;
    }
    let mut mesh = from_manifold(&out, fallback);
    if check_solid(&mesh).is_err() {
        // Only then: a mesh that passes keeps its bytes.
        mend_slivers(
            &mesh.positions,
            &mut mesh.triangles.0,
            &mut mesh.materials.0,
            THIN_SLIVER_M,
        );
        check_solid(&mesh).map_err(|e| format!("the result fails the solid check: {e}"))?;
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::mesh_build::cuboid;

    fn volume(m: &Mesh) -> f64 {
        m.triangles
            .iter()
            .map(|t| {
                let [a, b, c] =
                    t.map(|i| glam::DVec3::from(m.positions[i as usize].map(f64::from)));
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// A tetrahedron whose bottom face has its edge P1-P0 split at `m` while the side face
    /// across it keeps the whole edge, closed by the sliver (P0, M, P1): the T-junction a
    /// Boolean leaves. Positions, then triangles (the sliver last).
    fn t_junction(m: [f32; 3]) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let positions = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            m,
        ];
        let (p0, p1, p2, p3, m) = (0, 1, 2, 3, 4);
        let triangles = vec![
            [p0, p2, m],
            [m, p2, p1],
            [p0, p1, p3],
            [p0, p3, p2],
            [p1, p2, p3],
            [p0, m, p1],
        ];
        (positions, triangles)
    }

    /// The T-junction with M rounded 0.02 mm off the edge, outside it: the sliver folds
    /// back over the bottom face, and the check reports the two as intersecting. The exact test
    /// leaves it; mended as thin as [`THIN_SLIVER_M`], the tetrahedron is a solid again.
    #[test]
    fn a_sliver_folded_just_off_its_line_is_mended_when_thin_ones_are() {
        let (positions, triangles) = t_junction([0.5, -2e-5, 0.0]);
        let materials = vec![0; 6];
        let mesh = |t: &Vec<[u32; 3]>| Mesh {
            positions: PodVec(positions.clone()),
            triangles: PodVec(t.clone()),
            materials: PodVec(vec![0; t.len()]),
        };
        let err = check_solid(&mesh(&triangles)).unwrap_err();
        assert!(err.contains("intersect"), "{err}");
        let (mut exact, mut mat) = (triangles.clone(), materials.clone());
        mend_slivers(&positions, &mut exact, &mut mat, 0.0);
        assert_eq!(exact, triangles);
        let (mut thin, mut mat) = (triangles.clone(), materials);
        mend_slivers(&positions, &mut thin, &mut mat, THIN_SLIVER_M);
        check_solid(&mesh(&thin)).unwrap();
        assert_eq!(thin.len(), 6);
        assert!((volume(&mesh(&thin)) - 1.0 / 6.0).abs() < 1e-5);
    }

    /// The T-junction with M on the edge: mended, the side face is split at M instead and the
    /// sliver is gone.
    #[test]
    fn a_sliver_at_a_t_junction_is_mended_into_its_neighbour() {
        let (positions, mut triangles) = t_junction([0.5, 0.0, 0.0]);
        let mut materials = vec![0, 0, 1, 0, 0, 0];
        let mesh = |t: &Vec<[u32; 3]>, mt: &Vec<u8>| Mesh {
            positions: PodVec(positions.clone()),
            triangles: PodVec(t.clone()),
            materials: PodVec(mt.clone()),
        };
        assert!(
            check_solid(&mesh(&triangles, &materials)).is_err_and(|e| e.contains("degenerate"))
        );
        mend_slivers(&positions, &mut triangles, &mut materials, 0.0);
        let mended = mesh(&triangles, &materials);
        check_solid(&mended).unwrap();
        assert_eq!(triangles.len(), 6);
        assert!((volume(&mended) - 1.0 / 6.0).abs() < 1e-9);
        // The split side face keeps its material.
        assert_eq!(materials.iter().filter(|&&x| x == 1).count(), 2);
    }

    /// A 4 m cube less a 1 m notch at one corner and a 2 m one through the middle of a face, plus
    /// a 1 m box standing on top: the volumes add up, the notch's faces keep its material, and
    /// the overlapping recesses (they share a corner region) are merged once.
    #[test]
    fn subtract_then_add_keeps_volumes_and_materials() {
        // An upright cube of side `size` centred at (x, y), its floor at `z`.
        let cube = |center: [f64; 2], size: f64, z: f64, mat: Material| {
            to_manifold(&cuboid(center, [size; 3], 0.0, z, mat)).unwrap()
        };
        let base = cube([0.0, 0.0], 4.0, 0.0, Material::Brick);
        let notch = cube([2.0, 2.0], 1.0, 3.5, Material::Glass);
        let overlap = cube([1.75, 1.75], 1.0, 3.5, Material::Glass);
        let slot = cube([0.0, 2.0], 2.0, 1.0, Material::Wood);
        let top = cube([0.0, 0.0], 1.0, 4.0, Material::Metal);
        let out = subtract_then_add(
            &base,
            &[&notch, &overlap, &slot],
            &[&top],
            Material::Concrete,
        )
        .unwrap();
        // Notch and overlap inside the cube: 0.5^3 and the L-shaped union's inside part.
        let notch_in = 0.5 * 0.5 * 0.5;
        let overlap_in = 0.75 * 0.75 * 0.5;
        let shared = 0.5 * 0.5 * 0.5;
        let slot_in = 2.0 * 1.0 * 2.0;
        let expected = 64.0 - (notch_in + overlap_in - shared) - slot_in + 1.0;
        assert!(
            (volume(&out) - expected).abs() < 1e-4,
            "{} vs {expected}",
            volume(&out)
        );
        for mat in [
            Material::Brick,
            Material::Glass,
            Material::Wood,
            Material::Metal,
        ] {
            assert!(out.materials.contains(&(mat as u8)), "{mat:?} lost");
        }
        assert!(!out.materials.contains(&(Material::Concrete as u8)));
    }

    #[test]
    fn union_of_nothing_is_none_and_of_one_is_itself() {
        assert!(union_all(&[]).unwrap().is_none());
        let a = to_manifold(&cuboid([0.0; 2], [1.0; 3], 0.0, 0.0, Material::Metal)).unwrap();
        let u = union_all(&[&a]).unwrap().unwrap();
        assert!((u.volume() - 1.0).abs() < 1e-9);
    }
}
