//! Exact Booleans on closed meshes, with `manifold-rust`'s exact engine (Manifold's algorithm:
//! symbolic perturbation, so coplanar and touching faces are decided consistently). Per-triangle
//! materials ride through as Manifold face IDs: every input triangle carries its material as its
//! face ID, and every output triangle reports the face ID of the input triangle it is a piece of.
//! Façade relief carving and the synthetic truth's buildings are built with it.

use manifold_rust::manifold::Manifold;
use manifold_rust::types::{BooleanEngine, Error, MeshGL64, OpType};

use crate::artifact::{Mesh, PodVec};
use crate::geom::mesh_check::check_solid;
use crate::rf::materials::Material;

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
/// the scene can represent. Whether what remains is still a solid is for the caller's check.
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
    Mesh {
        positions: PodVec(positions),
        triangles: PodVec(triangles),
        materials: PodVec(materials),
    }
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
    let mesh = from_manifold(&out, fallback);
    check_solid(&mesh).map_err(|e| format!("the result fails the solid check: {e}"))?;
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
