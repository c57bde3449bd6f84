//! Building closed, outward-oriented triangle meshes from simple solids: prisms over polygons with
//! holes, boxes, gabled and hipped roofs, domes, ellipsoids, and terrain surfaces.

use std::collections::HashMap;

use spade::handles::FixedVertexHandle;
use spade::{ConstrainedDelaunayTriangulation, HasPosition, Point2, Triangulation};

use crate::artifact::Material;
use crate::artifact::{Mesh, PodVec, Polygon, Rect};

/// A mesh under construction.
#[derive(Default)]
pub(crate) struct Builder {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    materials: Vec<u8>,
}

impl Builder {
    pub(crate) fn v(&mut self, p: [f64; 3]) -> u32 {
        self.positions.push([p[0] as f32, p[1] as f32, p[2] as f32]);
        self.positions.len() as u32 - 1
    }
    pub(crate) fn tri(&mut self, a: u32, b: u32, c: u32, m: Material) {
        self.triangles.push([a, b, c]);
        self.materials.push(m as u8);
    }
    pub(crate) fn quad(&mut self, a: u32, b: u32, c: u32, d: u32, m: Material) {
        self.tri(a, b, c, m);
        self.tri(a, c, d, m);
    }
    pub(crate) fn finish(self) -> Mesh {
        Mesh {
            positions: PodVec(self.positions),
            triangles: PodVec(self.triangles),
            materials: PodVec(self.materials),
        }
    }
}

/// Inserts the rings of `poly` (exterior first, then each hole) into `cdt` as closed chains of
/// constraint edges; `vertex` makes a vertex from a ring point and its index in the concatenated
/// rings. Returns the handles in that order. Rings that repeat a point, touch or cross are an error
/// (user polygons can do all three; spade would panic on crossing constraints).
pub fn insert_rings<V: HasPosition<Scalar = f64>>(
    cdt: &mut ConstrainedDelaunayTriangulation<V>,
    poly: &Polygon,
    mut vertex: impl FnMut([f64; 2], usize) -> V,
) -> Result<Vec<FixedVertexHandle>, String> {
    let total = poly.exterior.len() + poly.holes.iter().map(Vec::len).sum::<usize>();
    if total >= BULK_LOAD_FROM && cdt.num_vertices() == 0 {
        return bulk_load_rings(cdt, poly, vertex);
    }
    let mut handles = Vec::new();
    for ring in std::iter::once(&poly.exterior).chain(&poly.holes) {
        let first = handles.len();
        for p in ring {
            let before = cdt.num_vertices();
            let h = cdt
                .insert(vertex(*p, handles.len()))
                .map_err(|e| format!("cannot triangulate vertex {p:?}: {e:?}"))?;
            if cdt.num_vertices() == before {
                return Err(format!("the polygon's rings repeat the point {p:?}"));
            }
            handles.push(h);
        }
        let ring_handles = &handles[first..];
        for (i, &h) in ring_handles.iter().enumerate() {
            let next = ring_handles[(i + 1) % ring_handles.len()];
            if !cdt.can_add_constraint(h, next) {
                return Err(format!("the polygon's rings cross near {:?}", ring[i]));
            }
            cdt.add_constraint(h, next);
        }
    }
    Ok(handles)
}

/// Rings of at least this many vertices in all are bulk loaded ([`bulk_load_rings`]): inserted one
/// by one in ring order, the points of a long smooth outline (nearly cocircular) cost spade a
/// cascade of edge flips each, 7 s for 150,000. Smaller rings keep one-by-one insertion, the order
/// every mesh so far was built in (a Delaunay triangulation breaks its ties, the four corners of
/// a rectangle, by insertion order), so their triangles do not change.
const BULK_LOAD_FROM: usize = 4096;

/// [`insert_rings`] for large rings into an empty triangulation: every point and constraint
/// loaded at once (spade sorts them spatially), with the same errors.
fn bulk_load_rings<V: HasPosition<Scalar = f64>>(
    cdt: &mut ConstrainedDelaunayTriangulation<V>,
    poly: &Polygon,
    mut vertex: impl FnMut([f64; 2], usize) -> V,
) -> Result<Vec<FixedVertexHandle>, String> {
    let rings: Vec<&Vec<[f64; 2]>> = std::iter::once(&poly.exterior).chain(&poly.holes).collect();
    let points: Vec<[f64; 2]> = rings.iter().flat_map(|r| r.iter().copied()).collect();
    let vertices: Vec<V> = points
        .iter()
        .enumerate()
        .map(|(i, p)| vertex(*p, i))
        .collect();
    let mut edges = Vec::with_capacity(points.len());
    let mut start = 0;
    for r in &rings {
        for i in 0..r.len() {
            edges.push([start + i, start + (i + 1) % r.len()]);
        }
        start += r.len();
    }
    let mut conflict = None;
    let loaded = ConstrainedDelaunayTriangulation::try_bulk_load_cdt(vertices, edges, |e| {
        conflict.get_or_insert(e);
    })
    .map_err(|e| format!("cannot triangulate the polygon: {e:?}"))?;
    if loaded.num_vertices() != points.len() {
        return Err("the polygon's rings repeat a point".into());
    }
    if let Some([a, _]) = conflict {
        return Err(format!("the polygon's rings cross near {:?}", points[a]));
    }
    *cdt = loaded;
    // Bulk loading keeps the vertices in input order.
    Ok((0..points.len())
        .map(FixedVertexHandle::from_index)
        .collect())
}

/// Triangles covering a polygon with holes (indices into the concatenated rings: exterior first,
/// then each hole), counter-clockwise seen from above.
pub fn triangulate(poly: &Polygon) -> Result<Vec<[u32; 3]>, String> {
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let handles = insert_rings(&mut cdt, poly, |p, _| Point2::new(p[0], p[1]))?;
    let index_of: HashMap<usize, u32> = handles
        .iter()
        .enumerate()
        .map(|(k, h)| (h.index(), k as u32))
        .collect();
    let mut out = Vec::new();
    let inside = poly.index();
    for f in cdt.inner_faces() {
        let vs = f.vertices();
        let c = vs.iter().fold([0.0, 0.0], |acc, v| {
            [acc[0] + v.position().x / 3.0, acc[1] + v.position().y / 3.0]
        });
        if inside.contains(c) {
            let idx = vs.map(|v| index_of.get(&v.fix().index()).copied());
            match idx {
                [Some(a), Some(b), Some(c)] => out.push([a, b, c]),
                _ => return Err("the polygon's rings cross each other".into()),
            }
        }
    }
    Ok(out)
}

/// A closed prism: `poly` extruded from `z0` to `z1`, walls of `wall`, top of `top`.
pub fn prism(
    poly: &Polygon,
    z0: f64,
    z1: f64,
    wall: Material,
    top: Material,
) -> Result<Mesh, String> {
    let caps = triangulate(poly)?;
    let mut b = Builder::default();
    let rings: Vec<&Vec<[f64; 2]>> = std::iter::once(&poly.exterior).chain(&poly.holes).collect();
    let (mut bottom, mut upper) = (Vec::new(), Vec::new());
    for ring in &rings {
        for p in ring.iter() {
            bottom.push(b.v([p[0], p[1], z0]));
        }
    }
    for ring in &rings {
        for p in ring.iter() {
            upper.push(b.v([p[0], p[1], z1]));
        }
    }
    for t in &caps {
        b.tri(
            upper[t[0] as usize],
            upper[t[1] as usize],
            upper[t[2] as usize],
            top,
        );
        b.tri(
            bottom[t[0] as usize],
            bottom[t[2] as usize],
            bottom[t[1] as usize],
            top,
        );
    }
    let mut start = 0;
    for ring in &rings {
        let n = ring.len();
        for i in 0..n {
            let (a, c) = (start + i, start + (i + 1) % n);
            b.quad(bottom[a], bottom[c], upper[c], upper[a], wall);
        }
        start += n;
    }
    Ok(b.finish())
}

/// Maps local (u, v) to site (x, y): rotate by `heading` (radians, counter-clockwise from +x),
/// then translate to `origin`. A rotation keeps faces outward.
fn place(origin: [f64; 2], heading: f64) -> impl Fn(f64, f64, f64) -> [f64; 3] {
    let (s, c) = heading.sin_cos();
    move |u, v, z| [origin[0] + c * u - s * v, origin[1] + s * u + c * v, z]
}

/// A closed box of `size` (length along `heading`, width, height) standing on `z0`, centred on
/// `center`.
pub fn cuboid(center: [f64; 2], size: [f64; 3], heading: f64, z0: f64, m: Material) -> Mesh {
    let p = place(center, heading);
    let (hl, hw) = (size[0] / 2.0, size[1] / 2.0);
    let mut b = Builder::default();
    let corners = [(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)];
    let lo: Vec<u32> = corners.iter().map(|&(u, v)| b.v(p(u, v, z0))).collect();
    let hi: Vec<u32> = corners
        .iter()
        .map(|&(u, v)| b.v(p(u, v, z0 + size[2])))
        .collect();
    b.quad(lo[0], lo[3], lo[2], lo[1], m);
    b.quad(hi[0], hi[1], hi[2], hi[3], m);
    for i in 0..4 {
        let j = (i + 1) % 4;
        b.quad(lo[i], lo[j], hi[j], hi[i], m);
    }
    b.finish()
}

/// A closed box over a planar quadrilateral: `corners` (counter-clockwise seen from the side
/// `normal`, a unit vector, points to) swept from `from` to `to` metres along `normal`
/// (`from` < `to`). Faces: the one at `from` takes `back`, the four sides `side`, the one at `to`
/// `front`. A recess or a protrusion on a wall, in that wall's frame.
pub fn quad_prism(
    corners: [[f64; 3]; 4],
    normal: [f64; 3],
    (from, to): (f64, f64),
    [back, side, front]: [Material; 3],
) -> Mesh {
    let at = |c: [f64; 3], s: f64| -> [f32; 3] {
        std::array::from_fn(|k| (c[k] + normal[k] * s) as f32)
    };
    let mut positions = Vec::with_capacity(8);
    positions.extend(corners.iter().map(|&c| at(c, from)));
    positions.extend(corners.iter().map(|&c| at(c, to)));
    // The front keeps the corners' order, the back reverses it, each side (b_i, b_i+1, f_i+1,
    // f_i) faces away.
    let mut triangles = vec![[4, 5, 6], [4, 6, 7], [0, 2, 1], [0, 3, 2]];
    let mut materials = vec![front as u8, front as u8, back as u8, back as u8];
    for i in 0..4u32 {
        let j = (i + 1) % 4;
        triangles.push([i, j, j + 4]);
        triangles.push([i, j + 4, i + 4]);
        materials.extend([side as u8, side as u8]);
    }
    Mesh {
        positions: PodVec(positions),
        triangles: PodVec(triangles),
        materials: PodVec(materials),
    }
}

/// The floor and four walls of an oriented rectangle up to `eave`; returns the eave corners
/// (counter-clockwise), where the roof closes the solid.
fn walls_to_eave(
    b: &mut Builder,
    p: &impl Fn(f64, f64, f64) -> [f64; 3],
    l: f64,
    w: f64,
    z0: f64,
    eave: f64,
    wall: Material,
) -> [u32; 4] {
    let corners = [(0.0, 0.0), (l, 0.0), (l, w), (0.0, w)];
    let base = corners.map(|(u, v)| b.v(p(u, v, z0)));
    let e = corners.map(|(u, v)| b.v(p(u, v, eave)));
    b.quad(base[0], base[3], base[2], base[1], wall);
    for i in 0..4 {
        let j = (i + 1) % 4;
        b.quad(base[i], base[j], e[j], e[i], wall);
    }
    e
}

/// A closed gabled building on rectangle `r`: walls from `z0` to `eave`, the ridge along its length
/// at `ridge`, gable ends of `wall`.
pub fn gabled(r: &Rect, z0: f64, eave: f64, ridge: f64, wall: Material, roof: Material) -> Mesh {
    let p = place(r.corner, r.heading);
    let (l, w) = (r.length, r.width);
    let mut b = Builder::default();
    let e = walls_to_eave(&mut b, &p, l, w, z0, eave, wall);
    let r0 = b.v(p(0.0, w / 2.0, ridge));
    let r1 = b.v(p(l, w / 2.0, ridge));
    b.tri(e[1], e[2], r1, wall);
    b.tri(e[3], e[0], r0, wall);
    b.quad(e[0], e[1], r1, r0, roof);
    b.quad(e[2], e[3], r0, r1, roof);
    b.finish()
}

/// A closed hipped building on rectangle `r` (a pyramid roof when square): like [`gabled`], with
/// the ridge shortened by half the width at each end. The length must be at least the width.
pub fn hipped(r: &Rect, z0: f64, eave: f64, ridge: f64, wall: Material, roof: Material) -> Mesh {
    let p = place(r.corner, r.heading);
    let (l, w) = (r.length.max(r.width), r.width);
    let mut b = Builder::default();
    let e = walls_to_eave(&mut b, &p, l, w, z0, eave, wall);
    if l - w < 1e-6 {
        let apex = b.v(p(l / 2.0, w / 2.0, ridge));
        for i in 0..4 {
            b.tri(e[i], e[(i + 1) % 4], apex, roof);
        }
    } else {
        let r0 = b.v(p(w / 2.0, w / 2.0, ridge));
        let r1 = b.v(p(l - w / 2.0, w / 2.0, ridge));
        b.quad(e[0], e[1], r1, r0, roof);
        b.tri(e[1], e[2], r1, roof);
        b.quad(e[2], e[3], r0, r1, roof);
        b.tri(e[3], e[0], r0, roof);
    }
    b.finish()
}

/// A closed ellipsoid (latitude-longitude tessellation) centred on `c` with semi-axes `r`.
pub fn ellipsoid(c: [f64; 3], r: [f64; 3], segments: u32, m: Material) -> Mesh {
    spheroid_cap(c, r, segments, std::f64::consts::PI, m)
}

/// A closed cone: a disk of `radius` at `z0` under its apex `height` above, `segments` around. A
/// conifer's crown.
pub fn cone(
    center: [f64; 2],
    radius: f64,
    z0: f64,
    height: f64,
    segments: u32,
    m: Material,
) -> Mesh {
    let n = segments.max(3) as usize;
    let mut b = Builder::default();
    let apex = b.v([center[0], center[1], z0 + height]);
    let ring: Vec<u32> = (0..n)
        .map(|k| {
            let phi = std::f64::consts::TAU * k as f64 / n as f64;
            b.v([
                center[0] + radius * phi.cos(),
                center[1] + radius * phi.sin(),
                z0,
            ])
        })
        .collect();
    let bottom = b.v([center[0], center[1], z0]);
    for k in 0..n {
        let k1 = (k + 1) % n;
        b.tri(apex, ring[k], ring[k1], m);
        b.tri(bottom, ring[k1], ring[k], m);
    }
    b.finish()
}

/// A closed dome: the upper half of an ellipsoid of radius `radius` and height `height` on a
/// disk at `z0`.
pub fn dome(
    center: [f64; 2],
    radius: f64,
    height: f64,
    z0: f64,
    segments: u32,
    m: Material,
) -> Mesh {
    spheroid_cap(
        [center[0], center[1], z0],
        [radius, radius, height],
        segments,
        std::f64::consts::FRAC_PI_2,
        m,
    )
}

/// Polar angle 0 (top) to `theta_max`; closed by a flat disk when `theta_max` < pi.
fn spheroid_cap(c: [f64; 3], r: [f64; 3], segments: u32, theta_max: f64, m: Material) -> Mesh {
    let n_lon = segments.max(3) as usize;
    let n_lat = (segments as usize / 2).max(2);
    let mut b = Builder::default();
    let top = b.v([c[0], c[1], c[2] + r[2]]);
    let full = theta_max >= std::f64::consts::PI - 1e-9;
    let rings = if full { n_lat - 1 } else { n_lat };
    let mut ring_ids = Vec::new();
    for i in 1..=rings {
        let theta = theta_max * i as f64 / n_lat as f64;
        let ring: Vec<u32> = (0..n_lon)
            .map(|k| {
                let phi = std::f64::consts::TAU * k as f64 / n_lon as f64;
                b.v([
                    c[0] + r[0] * theta.sin() * phi.cos(),
                    c[1] + r[1] * theta.sin() * phi.sin(),
                    c[2] + r[2] * theta.cos(),
                ])
            })
            .collect();
        ring_ids.push(ring);
    }
    for k in 0..n_lon {
        let k1 = (k + 1) % n_lon;
        b.tri(top, ring_ids[0][k], ring_ids[0][k1], m);
        for i in 0..ring_ids.len() - 1 {
            b.quad(
                ring_ids[i][k],
                ring_ids[i + 1][k],
                ring_ids[i + 1][k1],
                ring_ids[i][k1],
                m,
            );
        }
    }
    let last = ring_ids.last().expect("at least one ring").clone();
    let bottom = if full {
        b.v([c[0], c[1], c[2] - r[2]])
    } else {
        b.v([c[0], c[1], c[2] + r[2] * theta_max.cos()])
    };
    for k in 0..n_lon {
        b.tri(bottom, last[(k + 1) % n_lon], last[k], m);
    }
    b.finish()
}

/// An open surface over a regular grid of `nx` x `ny` vertices spaced `step` metres from
/// `origin` (south-west), z from `height`, faces up.
pub fn height_surface(
    origin: [f64; 2],
    nx: u32,
    ny: u32,
    step: f64,
    height: impl Fn(f64, f64) -> f64,
    m: Material,
) -> Mesh {
    let mut b = Builder::default();
    for j in 0..ny {
        for i in 0..nx {
            let (x, y) = (origin[0] + i as f64 * step, origin[1] + j as f64 * step);
            b.v([x, y, height(x, y)]);
        }
    }
    for j in 0..ny.saturating_sub(1) {
        for i in 0..nx.saturating_sub(1) {
            let a = j * nx + i;
            b.quad(a, a + 1, a + nx + 1, a + nx, m);
        }
    }
    b.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::mesh_check::check_closed_solid;

    fn square(x0: f64, y0: f64, s: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]]
    }

    fn close(a: f64, b: f64, tol: f64) {
        assert!((a - b).abs() <= tol * b.abs().max(1.0), "{a} vs {b}");
    }

    #[test]
    fn prisms_with_courtyards_are_closed_with_the_right_volume() {
        let poly =
            Polygon::normalized(square(0.0, 0.0, 20.0), vec![square(5.0, 5.0, 10.0)]).unwrap();
        let m = prism(&poly, 2.0, 14.0, Material::Brick, Material::Concrete).unwrap();
        close(
            check_closed_solid(&m).unwrap().volume_m3,
            (400.0 - 100.0) * 12.0,
            1e-6,
        );
        let l_shape = Polygon::normalized(
            vec![
                [0.0, 0.0],
                [30.0, 0.0],
                [30.0, 10.0],
                [10.0, 10.0],
                [10.0, 25.0],
                [0.0, 25.0],
            ],
            vec![],
        )
        .unwrap();
        let m = prism(&l_shape, 0.0, 9.0, Material::Glass, Material::Concrete).unwrap();
        close(
            check_closed_solid(&m).unwrap().volume_m3,
            (300.0 + 150.0) * 9.0,
            1e-6,
        );
    }

    #[test]
    fn roofs_boxes_domes_and_ellipsoids_are_closed_solids() {
        let (l, w, e, r) = (24.0, 10.0, 7.0, 11.0);
        let g = gabled(
            &Rect {
                corner: [3.0, 4.0],
                length: l,
                width: w,
                heading: 0.7,
            },
            1.0,
            e,
            r,
            Material::Brick,
            Material::Concrete,
        );
        close(
            check_closed_solid(&g).unwrap().volume_m3,
            l * w * (e - 1.0) + l * w * (r - e) / 2.0,
            1e-4,
        );
        let h = hipped(
            &Rect {
                corner: [3.0, 4.0],
                length: l,
                width: w,
                heading: -0.3,
            },
            1.0,
            e,
            r,
            Material::Brick,
            Material::Concrete,
        );
        // Hipped roof: a prism over the ridge (W H (L - W) / 2) plus the two hip ends, which
        // together form a pyramid of base W x W (W^2 H / 3).
        close(
            check_closed_solid(&h).unwrap().volume_m3,
            l * w * (e - 1.0) + w * (r - e) * (l - w) / 2.0 + w * w * (r - e) / 3.0,
            1e-4,
        );
        let pyramid = hipped(
            &Rect {
                corner: [0.0, 0.0],
                length: 10.0,
                width: 10.0,
                heading: 0.0,
            },
            0.0,
            5.0,
            8.0,
            Material::Brick,
            Material::Metal,
        );
        close(
            check_closed_solid(&pyramid).unwrap().volume_m3,
            500.0 + 100.0 * 3.0 / 3.0,
            1e-4,
        );
        let bx = cuboid([5.0, 5.0], [4.5, 1.8, 1.5], 1.1, 10.0, Material::Metal);
        close(
            check_closed_solid(&bx).unwrap().volume_m3,
            4.5 * 1.8 * 1.5,
            1e-5,
        );
        let d = dome([0.0, 0.0], 6.0, 4.0, 20.0, 48, Material::Metal);
        close(
            check_closed_solid(&d).unwrap().volume_m3,
            2.0 / 3.0 * std::f64::consts::PI * 36.0 * 4.0,
            0.02,
        );
        let el = ellipsoid([0.0, 0.0, 8.0], [3.0, 3.0, 4.0], 48, Material::Foliage);
        close(
            check_closed_solid(&el).unwrap().volume_m3,
            4.0 / 3.0 * std::f64::consts::PI * 36.0,
            0.02,
        );
    }

    #[test]
    fn crossing_or_repeating_rings_are_errors_not_panics() {
        let bowtie = Polygon {
            exterior: vec![[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]],
            holes: vec![],
        };
        assert!(triangulate(&bowtie).unwrap_err().contains("cross"));
        let hole_out = Polygon {
            exterior: square(0.0, 0.0, 10.0),
            holes: vec![square(5.0, 5.0, 10.0).into_iter().rev().collect()],
        };
        assert!(triangulate(&hole_out).unwrap_err().contains("cross"));
        let repeated = Polygon {
            exterior: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [10.0, 0.0]],
            holes: vec![],
        };
        assert!(triangulate(&repeated).unwrap_err().contains("repeat"));
    }

    /// A ring of `n` vertices on a circle of radius `r` round `c`, counter-clockwise (or not).
    fn circle(c: [f64; 2], r: f64, n: usize, ccw: bool) -> Vec<[f64; 2]> {
        let ring: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                [c[0] + r * t.cos(), c[1] + r * t.sin()]
            })
            .collect();
        if ccw {
            ring
        } else {
            ring.into_iter().rev().collect()
        }
    }

    /// Rings past the bulk-loading threshold triangulate to the same covered area as the
    /// polygon, and keep the errors of one-by-one insertion.
    #[test]
    fn large_rings_are_bulk_loaded_with_the_same_coverage_and_errors() {
        let poly = Polygon {
            exterior: circle([0.0, 0.0], 50.0, 6000, true),
            holes: vec![circle([10.0, 0.0], 10.0, 3000, false)],
        };
        let tris = triangulate(&poly).unwrap();
        let rings: Vec<&Vec<[f64; 2]>> =
            std::iter::once(&poly.exterior).chain(&poly.holes).collect();
        let points: Vec<[f64; 2]> = rings.iter().flat_map(|r| r.iter().copied()).collect();
        let covered: f64 = tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| points[i as usize]);
                ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])) / 2.0
            })
            .sum();
        close(covered, poly.area(), 1e-9);
        // n vertices and h holes: n + 2h - 2 triangles.
        assert_eq!(tris.len(), 6000 + 3000);
        let crossing = Polygon {
            exterior: circle([0.0, 0.0], 50.0, 6000, true),
            holes: vec![circle([45.0, 0.0], 10.0, 3000, false)],
        };
        assert!(triangulate(&crossing).unwrap_err().contains("cross"));
        let mut repeated = poly.clone();
        repeated.exterior[100] = repeated.exterior[4000];
        assert!(triangulate(&repeated).is_err());
    }

    #[test]
    fn an_open_surface_is_not_a_solid() {
        let s = height_surface(
            [0.0, 0.0],
            4,
            3,
            1.0,
            |x, y| x + y,
            Material::MediumDryGround,
        );
        assert_eq!(s.len(), 12);
        assert!(check_closed_solid(&s).unwrap_err().contains("open"));
    }
}
