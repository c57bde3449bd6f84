//! Edge diffraction by the UTD (Kouyoumjian-Pathak, with Luebbers'
//! finite-conductivity reflection factors), the geometry and the field: the wedges of a scene's
//! meshes, the diffraction point on each edge (Keller's cone: equal angles, the shortest path over
//! the edge), and the diffracted field in the edge-fixed bases. Which wedges a link tries and the
//! paths over them are `diffracted`'s.

use std::collections::HashMap;
use std::f64::consts::PI;

use glam::DVec3;
use num_complex::Complex64 as C64;

use super::field::{self, CVec};
use super::path::TraceOptions;
use super::scene::RfScene;
use super::utd::wedge_coefficients;
use crate::geom::polygon::convex_hull;
use crate::geom::union_find::UnionFind;

/// An edge where two faces meet at an exterior angle n π > π (a convex corner).
#[derive(Clone, Copy, Debug)]
pub struct Wedge {
    /// One end of the edge.
    pub a: DVec3,
    /// Unit edge direction, n0 × nn.
    pub e: DVec3,
    /// Edge length, metres.
    pub length: f64,
    /// Outward normal of the 0-face.
    pub n0: DVec3,
    /// Outward normal of the n-face.
    pub nn: DVec3,
    /// Exterior angle over π.
    pub n: f64,
    /// The 0-face's triangle (for its material).
    pub tri0: u32,
    /// The n-face's triangle.
    pub trin: u32,
    /// The flat face the 0-face's triangle belongs to ([`Wedges::face`]).
    pub face0: u32,
    /// The flat face of the n-face's triangle.
    pub facen: u32,
    /// The wedge's size, which bounds what it diffracts ([`bounded_by_size`]). `None`: faces
    /// and edge unbounded, as the UTD takes them.
    pub size: Option<WedgeSize>,
}

/// How big a wedge is ([`wedge_sizes`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WedgeSize {
    /// How far the 0-face reaches from the edge, across it, metres.
    pub reach0: f64,
    /// How far the n-face reaches from the edge, metres.
    pub reachn: f64,
    /// Length of the edge the wedge is a piece of, metres: the pieces between the same two flat
    /// faces end to end, whatever their materials (a corner painted glass and brick storey by
    /// storey is one edge to the wave).
    pub run: f64,
}

/// A scene's wedges and its flat faces.
#[derive(Clone, Debug, Default)]
pub struct Wedges {
    /// The wedges, one per run of edge between the same two faces and materials.
    pub list: Vec<Wedge>,
    /// Per triangle, its flat face: the triangles joined across the edges where the surface
    /// does not bend, named by the smallest triangle index among them.
    pub face: Vec<u32>,
}

impl Wedge {
    /// Whether a wave from `p` can reach the edge from outside the wedge: `p` in front of either
    /// face's plane (Sionna's test). False for an inner corner seen from the air.
    pub fn lit_from(&self, p: DVec3) -> bool {
        let k = p - self.a;
        k.dot(self.n0) > 1e-9 || k.dot(self.nn) > 1e-9
    }

    /// Whether the wave of a transmitter at `tx` can diffract here: one of the wedge's flat
    /// faces among those it lights (`lights`, from where its rays first land, as Sionna samples
    /// wedges, but by face rather than by triangle), and the wedge met from outside.
    pub fn diffracts_from(&self, tx: DVec3, lights: impl Fn(u32) -> bool) -> bool {
        (lights(self.face0) || lights(self.facen)) && self.lit_from(tx)
    }

    /// The same wedge labelled so that its 0-face is one a wave travelling along `ki` meets from
    /// outside (`ki · n0 <= 0`), as Sionna RT does, and of two lit faces the one it meets more
    /// squarely. The UTD's face reflection factors are taken at the incidence angle on the
    /// 0-face, which only means something for a face the wave lights; labelled the other way
    /// round, a wave grazing one face of a corner was weighted by the other face's near-normal
    /// reflection, and the same corner diffracted 20 dB apart depending on which of its
    /// triangles came first. Luebbers' factors are not symmetric in the two faces, so the
    /// labelling of a corner lit on both faces is fixed too, never left to the mesh's order.
    pub fn facing(&self, ki: DVec3) -> Wedge {
        let (c0, cn) = (ki.dot(self.n0), ki.dot(self.nn));
        let keep = if c0 <= 0.0 && cn <= 0.0 {
            c0 <= cn
        } else {
            c0 <= 0.0
        };
        if keep {
            return *self;
        }
        Wedge {
            a: self.a + self.e * self.length,
            e: -self.e,
            n0: self.nn,
            nn: self.n0,
            tri0: self.trin,
            trin: self.tri0,
            face0: self.facen,
            facen: self.face0,
            size: self.size.map(|s| WedgeSize {
                reach0: s.reachn,
                reachn: s.reach0,
                ..s
            }),
            ..*self
        }
    }
}

/// The wedges of `scene` that `opt` allows ([`wedges`] with its minimum angle, whether edges
/// between objects count, and finite faces).
pub fn wedges_for(scene: &RfScene, opt: &TraceOptions) -> Wedges {
    wedges(
        scene,
        opt.min_wedge_deg,
        opt.wedges_across_objects,
        opt.finite_faces,
    )
}

/// The edges of `scene` that can diffract: edges shared by exactly two triangles (matched by
/// vertex position, to the micrometre) whose faces turn by more than `min_deg` degrees (and by
/// more than 0.08 degrees, where a plane split into triangles rounds). Each is a wedge of the
/// angle under π between its faces, both normals turned away from the other face, as Sionna RT
/// orients them: whichever way the mesh winds its triangles (Sionna's own scenes wind their
/// buildings inwards), a solid's corner is a wedge whose outside is the air. At a corner where the
/// air is the narrow side (an inner corner), the wedge's outside is the solid and no wave from the
/// air diffracts there ([`Wedge::lit_from`]). Without `across_objects`, only edges whose two
/// triangles belong to one object (as Sionna RT 2.2 finds them, within a shape).
///
/// Where do the wedges' faces end? A wall split into many triangles (painted by material
/// regions, carved around windows) is still one flat face, and its corner one edge: the
/// triangles joined across unbent edges make the faces, and the pieces of edge one after the
/// other between the same two faces and materials make one wedge. Which wedges a wave lights
/// then does not hang on whether a ray happened to land on the sliver of triangle beside the
/// edge (Sionna's sampling by triangle loses most edges of a finely split wall).
///
/// With `finite_faces`, each wedge carries its size ([`Wedge::size`]: how far its two faces
/// reach from the edge, how long the edge runs), which bounds what it diffracts; without, faces
/// and edge are unbounded, as the UTD (and Sionna RT) takes them.
pub fn wedges(scene: &RfScene, min_deg: f64, across_objects: bool, finite_faces: bool) -> Wedges {
    let max_cos = (1.0 - 1e-6f64).min(min_deg.to_radians().cos());
    let key = |p: DVec3| [p.x, p.y, p.z].map(|c| (c * 1e6).round() as i64);
    // Every triangle's edges by their ends' quantised positions, sorted (stably, so each edge's
    // triangles stay in triangle order): an edge's triangles are a run. A sort, not a hash map
    // of lists: the map's hashing and its list per edge were most of the time.
    type EdgeKey = ([i64; 3], [i64; 3]);
    let mut sides: Vec<(EdgeKey, (u32, DVec3, DVec3))> = Vec::with_capacity(3 * scene.tris.len());
    for (t, tri) in scene.tris.iter().enumerate() {
        if scene.normals[t] == DVec3::ZERO || scene.is_foliage(t as u32) {
            continue;
        }
        for k in 0..3 {
            let (p, q) = (tri[k], tri[(k + 1) % 3]);
            let (kp, kq) = (key(p), key(q));
            let (lo, hi, a, b) = if kp < kq {
                (kp, kq, p, q)
            } else {
                (kq, kp, q, p)
            };
            sides.push(((lo, hi), (t as u32, a, b)));
        }
    }
    sides.sort_by_key(|s| s.0);
    // (t0, t1, a, b, n0, nn, cos of the bend) per edge that bends.
    let mut bends = Vec::new();
    let mut faces = UnionFind::new(scene.tris.len());
    for run in sides.chunk_by(|x, y| x.0 == y.0) {
        // An edge of two triangles, or none that can bend.
        let [(_, (t0, a, b)), (_, (t1, _, _))] = *run else {
            continue;
        };
        let third = |t: u32| {
            scene.tris[t as usize]
                .iter()
                .copied()
                .max_by(|p, q| {
                    ((*p - a).cross(b - a))
                        .length()
                        .total_cmp(&((*q - a).cross(b - a)).length())
                })
                .expect("three vertices")
        };
        // Each normal turned away from the other face; a face in the other's plane either way
        // round is no bend at all.
        let away = |n: DVec3, other: u32| {
            let h = (third(other) - a).dot(n);
            (h.abs() > 1e-9).then_some(if h > 0.0 { -n } else { n })
        };
        let (Some(n0), Some(nn)) = (
            away(scene.normals[t0 as usize], t1),
            away(scene.normals[t1 as usize], t0),
        ) else {
            faces.join(t0, t1);
            continue;
        };
        let c = n0.dot(nn).clamp(-1.0, 1.0);
        if c >= 1.0 - 1e-6 {
            faces.join(t0, t1);
            continue;
        }
        if c >= max_cos {
            continue; // a bend below the threshold
        }
        if !across_objects && scene.object[t0 as usize] != scene.object[t1 as usize] {
            continue;
        }
        bends.push((t0, t1, a, b, n0, nn, c));
    }
    let face = faces.names();
    let mut out: Vec<Wedge> = Vec::with_capacity(bends.len());
    for (t0, t1, a, b, n0, nn, c) in bends {
        // The face named first is the 0-face, so every piece of one edge points the same way.
        let (t0, t1, n0, nn) = if face[t0 as usize] <= face[t1 as usize] {
            (t0, t1, n0, nn)
        } else {
            (t1, t0, nn, n0)
        };
        let e = n0.cross(nn);
        if e.length() < 1e-9 {
            continue;
        }
        let e = e.normalize();
        let (a, b) = if (b - a).dot(e) >= 0.0 {
            (a, b)
        } else {
            (b, a)
        };
        out.push(Wedge {
            a,
            e,
            length: (b - a).length(),
            n0,
            nn,
            n: 1.0 + c.acos() / PI,
            tri0: t0,
            trin: t1,
            face0: face[t0 as usize],
            facen: face[t1 as usize],
            size: None,
        });
    }
    let mut list = join_pieces(out, scene);
    if finite_faces {
        wedge_sizes(&mut list, scene, &face);
    }
    Wedges { list, face }
}

/// Sets each wedge's size. A face's reach is the farthest any vertex of the flat face lies from
/// the edge's line. A face that reaches past the edge's ends counts its whole reach, so a reach
/// errs wide (the UTD as without the bound) rather than narrow; but a face is what [`wedges`]
/// joins across shared edges, and a wall whose triangles meet at T-junctions is several faces,
/// each reaching less (the meshes the graph builds share their edges). The farthest point of a
/// flat face from a line in its plane is a corner of its convex hull, so only those are visited
/// (a carved wall is thousands of vertices and dozens of wedges, its hull a handful).
fn wedge_sizes(list: &mut [Wedge], scene: &RfScene, face: &[u32]) {
    let mut slot: HashMap<u32, usize> = HashMap::new();
    for w in list.iter() {
        for f in [w.face0, w.facen] {
            let next = slot.len();
            slot.entry(f).or_insert(next);
        }
    }
    let mut verts: Vec<(DVec3, Vec<DVec3>)> = vec![(DVec3::ZERO, Vec::new()); slot.len()];
    for (t, f) in face.iter().enumerate() {
        if let Some(&k) = slot.get(f) {
            verts[k].0 = scene.normals[t];
            verts[k].1.extend_from_slice(&scene.tris[t]);
        }
    }
    let hulls: Vec<Vec<DVec3>> = verts
        .into_iter()
        .map(|(n, v)| hull_in_plane(n, &v))
        .collect();
    let reach = |w: &Wedge, f: u32| {
        hulls[slot[&f]]
            .iter()
            .map(|&v| {
                let d = v - w.a;
                (d - w.e * d.dot(w.e)).length()
            })
            .fold(0.0, f64::max)
    };
    let run = edge_runs(list);
    for (w, run) in list.iter_mut().zip(run) {
        w.size = Some(WedgeSize {
            reach0: reach(w, w.face0),
            reachn: reach(w, w.facen),
            run,
        });
    }
}

/// Per wedge, the length of the run of edge it belongs to: its pieces between the same two
/// flat faces, end to end, whatever their materials.
fn edge_runs(list: &[Wedge]) -> Vec<f64> {
    let start = |w: &Wedge| w.a.dot(w.e);
    let mut order: Vec<usize> = (0..list.len()).collect();
    order.sort_by(|&i, &j| {
        let (p, q) = (&list[i], &list[j]);
        (p.face0, p.facen)
            .cmp(&(q.face0, q.facen))
            .then(start(p).total_cmp(&start(q)))
    });
    let mut run = vec![0.0; list.len()];
    let mut k = 0;
    while k < order.len() {
        // Pieces [k, end) touch end to end.
        let first = &list[order[k]];
        let mut end = k + 1;
        let mut reach_to = first.a + first.e * first.length;
        while end < order.len() {
            let w = &list[order[end]];
            if (w.face0, w.facen) != (first.face0, first.facen) || w.a.distance(reach_to) >= 1e-6 {
                break;
            }
            reach_to = w.a + w.e * w.length;
            end += 1;
        }
        let total = (reach_to - first.a).dot(first.e);
        for &i in &order[k..end] {
            run[i] = total;
        }
        k = end;
    }
    run
}

/// The corners of the convex hull of points `p` lying in one plane of normal `n`.
fn hull_in_plane(n: DVec3, p: &[DVec3]) -> Vec<DVec3> {
    let Some(&o) = p.first() else {
        return Vec::new();
    };
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let key = |c: [f64; 2]| c.map(f64::to_bits);
    let mut back = HashMap::new();
    let flat = p
        .iter()
        .map(|&q| {
            let c = [(q - o).dot(u), (q - o).dot(v)];
            back.insert(key(c), q);
            c
        })
        .collect();
    // The hull's corners are copies of input coordinates: each maps back to its vertex.
    convex_hull(flat)
        .into_iter()
        .map(|c| back[&key(c)])
        .collect()
}

/// The pieces of one edge between the same two faces and materials, end to end, as one wedge
/// each run; the rest as they are, in order of faces, materials and place along the edge.
fn join_pieces(mut pieces: Vec<Wedge>, scene: &RfScene) -> Vec<Wedge> {
    let mat = |t: u32| scene.material[t as usize];
    let run_key = |w: &Wedge| (w.face0, w.facen, mat(w.tri0), mat(w.trin));
    pieces.sort_by(|p, q| {
        run_key(p)
            .cmp(&run_key(q))
            .then(p.a.dot(p.e).total_cmp(&q.a.dot(q.e)))
    });
    let mut out: Vec<Wedge> = Vec::with_capacity(pieces.len());
    for w in pieces {
        if let Some(last) = out.last_mut()
            && run_key(last) == run_key(&w)
            && (last.a + last.e * last.length).distance(w.a) < 1e-6
        {
            last.length = (w.a + w.e * w.length - last.a).dot(last.e);
            continue;
        }
        out.push(w);
    }
    out
}

/// The point of the edge where the path `s1 -> Q -> s2` is shortest (Keller's cone: equal angles
/// with the edge), as a distance along it, if strictly inside the edge. Unfolding the two ends
/// about the edge line makes the path straight, so Q divides the ends' projections on the edge in
/// the ratio of their distances from it.
pub fn diffraction_point(w: &Wedge, s1: DVec3, s2: DVec3) -> Option<f64> {
    let (u1, u2) = ((s1 - w.a).dot(w.e), (s2 - w.a).dot(w.e));
    let r1 = (s1 - w.a - w.e * u1).length();
    let r2 = (s2 - w.a - w.e * u2).length();
    if r1 + r2 < 1e-12 {
        return None;
    }
    let u = u1 + (u2 - u1) * r1 / (r1 + r2);
    (u > 1e-6 && u < w.length - 1e-6).then_some(u)
}

/// The direction at cone angle `phi` from the 0-face (towards its outside) on the Keller cone of
/// a wave along `ki` at `w`: the angle to the edge kept, continuing forward along it.
pub fn keller_cone(w: &Wedge, ki: DVec3, phi: f64) -> DVec3 {
    let t0 = w.n0.cross(w.e).normalize();
    let along = ki.dot(w.e);
    let e_fwd = if along > 0.0 { w.e } else { -w.e };
    let cos_b = along.abs().min(1.0);
    let sin_b = (1.0 - cos_b * cos_b).sqrt();
    (w.n0 * (phi.sin() * sin_b) + t0 * (phi.cos() * sin_b) + e_fwd * cos_b).normalize()
}

/// The angle of `s` (a unit direction away from the edge, projected across it) from the 0-face,
/// in [0, 2π) (as Sionna RT's EM primer measures it).
fn face_angle(w: &Wedge, s: DVec3) -> f64 {
    let t0 = w.n0.cross(w.e);
    let st = (s - w.e * s.dot(w.e)).normalize_or_zero();
    let sgn = if st.dot(w.n0) >= 0.0 { 1.0 } else { -1.0 };
    PI - (PI - st.dot(t0).clamp(-1.0, 1.0).acos()) * sgn
}

/// A face's reflection of a wave along `ki` (with its edge-fixed basis `phi_in`, `beta_in`) as
/// a matrix on edge-fixed components ((φ, β) in, (φ, β) of the reflected direction out): the
/// face's slab coefficients at the wave's incidence on it, in our Fresnel bases
/// (`field::reflect`).
fn face_reflection(
    scene: &RfScene,
    tri: u32,
    normal: DVec3,
    (ki, phi_in, beta_in): (DVec3, DVec3, DVec3),
    e: DVec3,
) -> [[C64; 2]; 2] {
    let (r, _) = scene.slab(tri, ki.dot(normal).abs().min(1.0));
    let kr = field::mirror(ki, normal);
    let phi_out = -(kr.cross(e)).normalize();
    let beta_out = phi_out.cross(kr);
    let cols = [phi_in, beta_in].map(|v| field::reflect(&field::real(v), ki, normal, r).0);
    [phi_out, beta_out].map(|o| [field::dot(&cols[0], o), field::dot(&cols[1], o)])
}

/// The UTD coefficients of a wedge of finite size: no more than a scatterer of that size can
/// give. The UTD takes the edge and both faces as unbounded, and two of its assumptions fail on
/// a street post's 0.1 m facets or a drainpipe's front:
///
/// - The field comes from the first Fresnel zone along the edge, √(λ L_e) long with
///   1/L_e = sin² β0 (1/s' + 1/s) (the path's curvature along the edge at the stationary
///   point). An edge of length ℓ (the whole run the wedge is a piece of, [`WedgeSize::run`])
///   spans at most ℓ of it, and the integral of a unit phasor over ℓ
///   is at most ℓ: every term is scaled by min(1, ℓ / √(λ L_e)).
/// - On a face's reflection shadow boundary its term (D3 for the n-face, D4 for the 0-face) is
///   half the field the face would reflect if it were unbounded. A strip of width w reflects at
///   most what physical optics gives at its specular peak, a 2-D coefficient of w √(k / 2π)
///   (the strip's bistatic width k w², over 2π; over sin β0 as the UTD's own): each face's
///   term is capped at half of that, its phase kept, so that the two edges of a strip in phase
///   give the strip's peak.
///
/// Edges and faces metres long never reach either bound at the distances of a street (they bind
/// where ℓ or w is under about √(λ L)); what they take away is a small object shining like a
/// wall.
fn bounded_by_size(
    d: &mut [C64; 4],
    size: WedgeSize,
    (k, sin_b): (f64, f64),
    (si, so): (f64, f64),
) {
    let fresnel_zone = (2.0 * PI / k / (sin_b * sin_b * (1.0 / si + 1.0 / so))).sqrt();
    let along = (size.run / fresnel_zone).min(1.0);
    let cap = |d: C64, reach: f64| {
        let most = 0.5 * reach * (k / (2.0 * PI)).sqrt() / sin_b;
        let norm = d.norm();
        if norm > most { d * (most / norm) } else { d }
    };
    d[2] = cap(d[2], size.reachn);
    d[3] = cap(d[3], size.reach0);
    for t in d.iter_mut() {
        *t *= along;
    }
}

/// The diffracted field at `rx` of a wave leaving `tx` with field `e_tx` (at unit distance),
/// over wedge `w` at `q`, as a field vector (spreading included, propagation phase not), or
/// `None` when either end is inside the wedge.
pub fn diffracted_field(
    scene: &RfScene,
    w: &Wedge,
    q: DVec3,
    tx: DVec3,
    rx: DVec3,
    e_tx: &CVec,
) -> Option<CVec> {
    let (si, so) = ((q - tx).length(), (rx - q).length());
    let ki = (q - tx) / si; // incident direction
    let ko = (rx - q) / so; // diffracted direction
    let w = &w.facing(ki);
    let phi_i = face_angle(w, -ki);
    let phi = face_angle(w, ko);
    let limit = w.n * PI;
    if !(phi_i > 0.0 && phi_i < limit && phi > 0.0 && phi < limit) {
        return None;
    }
    let sin_b = ki.cross(w.e).length();
    if sin_b < 1e-6 {
        return None;
    }
    // Square to the edge |k × e| can round to just above 1, and asin would give NaN.
    let beta0 = sin_b.min(1.0).asin();
    let k = 2.0 * PI / scene.wavelength;
    let l = si * so * sin_b * sin_b / (si + so);
    let mut d = wedge_coefficients(w.n, phi, phi_i, beta0, k, l);
    if let Some(size) = w.size {
        bounded_by_size(&mut d, size, (k, sin_b), (si, so));
    }
    // Edge-fixed bases.
    let phi_hat_i = ki.cross(w.e).normalize();
    let beta_hat_i = phi_hat_i.cross(ki);
    let phi_hat_o = -(ko.cross(w.e)).normalize();
    let beta_hat_o = phi_hat_o.cross(ko);
    // Face reflection factors (Luebbers), as matrices on the edge-fixed components: each face's
    // reflection of the incident wave at its true angle of incidence on that face (|k · n|), taken
    // from the incident edge-fixed basis into the face's (⊥, ∥) basis and back out into the
    // edge-fixed basis of the reflected direction (the W matrices of Sionna RT's EM primer, with
    // the reflected direction's basis as Hashimoto et al. and Sionna RT take it: the factor is the
    // reflected field's own across its shadow boundary, where it matters). Square to the edge (β0 =
    // 90°) this is −diag(r_∥, r_⊥): the classic soft (β) and hard (φ) coefficients for a perfect
    // conductor; oblique to it the components mix.
    let incident = (ki, phi_hat_i, beta_hat_i);
    let r0 = face_reflection(scene, w.tri0, w.n0, incident, w.e);
    let rn = face_reflection(scene, w.trin, w.nn, incident, w.e);
    let e_in = [field::dot(e_tx, phi_hat_i), field::dot(e_tx, beta_hat_i)];
    let spread = (1.0 / (si * so * (si + so))).sqrt();
    let apply = |r: &[[C64; 2]; 2], i: usize| r[i][0] * e_in[0] + r[i][1] * e_in[1];
    let comp = |i: usize| -> C64 {
        -((d[0] + d[1]) * e_in[i] - d[2] * apply(&rn, i) - d[3] * apply(&r0, i)) * spread
    };
    let (out_phi, out_beta) = (comp(0), comp(1));
    Some([0, 1, 2].map(|c| out_phi * phi_hat_o[c] + out_beta * beta_hat_o[c]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::artifact::{ObjectClass, Scene, SceneObject};
    use crate::geom::mesh_build::cuboid;

    fn concrete_box() -> RfScene {
        one_box([10.0, 10.0, 10.0], Material::Concrete)
    }

    fn one_box(size: [f64; 3], m: Material) -> RfScene {
        let scene = Scene {
            objects: vec![SceneObject {
                id: "box".into(),
                class: ObjectClass::Building,
                mesh: cuboid([0.0, 0.0], size, 0.0, 0.0, m),
            }],
        };
        RfScene::new(&scene, 3.5e9, false).unwrap()
    }

    /// The field over the wedge of `rf` whose edge runs along `dir` through `through` (its
    /// faces bounded or not), a vertically polarised unit wave from `tx`.
    fn field_over(
        rf: &RfScene,
        finite: bool,
        (through, dir): (DVec3, DVec3),
        tx: DVec3,
        rx: DVec3,
    ) -> f64 {
        let all = wedges(rf, 0.0, true, finite);
        let w = all
            .list
            .iter()
            .find(|w| {
                // Meshes hold f32 positions.
                w.e.cross(dir).length() < 1e-6 && (through - w.a).cross(w.e).length() < 1e-6
            })
            .expect("the wedge");
        let u = diffraction_point(w, tx, rx).expect("a diffraction point on the edge");
        let e = diffracted_field(rf, w, w.a + w.e * u, tx, rx, &field::real(DVec3::Z)).unwrap();
        e.iter().map(|c| c.norm_sqr()).sum::<f64>().sqrt()
    }

    /// Pieces of one edge painted in different materials make one run; a stretch of the same
    /// two faces elsewhere (past a notch) is a run of its own.
    #[test]
    fn a_corner_painted_storey_by_storey_is_one_edge() {
        let piece = |from: f64, to: f64, tri0: u32| Wedge {
            a: DVec3::new(0.0, 0.0, from),
            e: DVec3::Z,
            length: to - from,
            n0: DVec3::NEG_Y,
            nn: DVec3::NEG_X,
            n: 1.5,
            tri0,
            trin: 1,
            face0: 0,
            facen: 1,
            size: None,
        };
        let list = [
            piece(3.0, 6.0, 7),
            piece(0.0, 3.0, 5),
            piece(8.0, 9.5, 5),
            piece(6.0, 6.4, 9),
        ];
        assert_eq!(edge_runs(&list), vec![6.4, 6.4, 1.5, 6.4]);
    }

    /// A building's corner is metres wide and long: its size bounds nothing, and the field is
    /// the UTD's to the bit.
    #[test]
    fn a_wall_corner_diffracts_as_the_unbounded_utd() {
        let rf = concrete_box();
        let edge = (DVec3::new(5.0, 5.0, 0.0), DVec3::Z);
        for (tx, rx) in [
            (DVec3::new(35.0, 25.0, 6.0), DVec3::new(21.7, -6.0, 1.5)),
            (DVec3::new(40.0, 30.0, 9.0), DVec3::new(-20.0, 12.0, 2.0)),
            (DVec3::new(5.0, 60.0, 8.0), DVec3::new(60.0, 2.0, 1.5)),
        ] {
            let (bounded, utd) = (
                field_over(&rf, true, edge, tx, rx),
                field_over(&rf, false, edge, tx, rx),
            );
            assert_eq!(bounded, utd, "{tx} -> {rx}");
        }
    }

    /// On a face's reflection shadow boundary the UTD gives half the field an infinite mirror
    /// reflects. Bounded, a post's face 0.1 m wide gives half what a strip of that width
    /// reflects at its specular peak (physical optics: 2-D coefficient w √(k / 2π)), 14 dB less
    /// than its mirror here.
    #[test]
    fn a_narrow_face_reflects_no_more_than_a_strip_of_its_width() {
        let rf = one_box([0.1, 0.1, 8.0], Material::Metal);
        let a = DVec3::new(0.05, 0.05, 4.0);
        let tx = DVec3::new(30.0, 20.0, 4.0);
        // On the +x face's reflection shadow boundary from the edge, square to it.
        let ki = (a - tx).normalize();
        let rx = a + DVec3::new(-ki.x, ki.y, 0.0) * 20.0;
        let (si, so) = (tx.distance(a), rx.distance(a));
        let utd = field_over(&rf, false, (a, DVec3::Z), tx, rx);
        let mirror = 1.0 / (si + so); // |R| = 1 near enough for metal
        let db = |x: f64| 20.0 * x.log10();
        assert!(
            (db(utd) - db(0.5 * mirror)).abs() < 0.5,
            "UTD {} dB, half the mirror's {} dB",
            db(utd),
            db(0.5 * mirror)
        );
        let k = 2.0 * PI / rf.wavelength;
        let strip = 0.1 * (k / (2.0 * PI)).sqrt() / (si * so * (si + so)).sqrt();
        let bounded = field_over(&rf, true, (a, DVec3::Z), tx, rx);
        // The wedge's other terms, away from their boundaries, add about a decibel.
        assert!(
            (db(bounded) - db(0.5 * strip)).abs() < 1.5,
            "bounded {} dB, half the strip's peak {} dB",
            db(bounded),
            db(0.5 * strip)
        );
        assert!(db(utd) - db(bounded) > 12.0);
    }

    /// An edge shorter than the first Fresnel zone along it (a post's top) gives what the
    /// integral of the path's phase over its length gives, not the unbounded edge's
    /// stationary-phase field: the ratio is |∫ e^{-jk P(u)} du| over the edge, against
    /// √(λ L_e), with the path length P(u) summed numerically along the edge.
    #[test]
    fn a_short_edge_gives_what_its_length_of_the_fresnel_zone_gives() {
        let rf = one_box([0.1, 0.1, 8.0], Material::Metal);
        // The top edge along x over the +y face; away from every shadow boundary.
        let (a, dir) = (DVec3::new(-0.05, 0.05, 8.0), DVec3::X);
        let tx = DVec3::new(0.0, 30.0, 20.0);
        let rx = DVec3::new(0.0, -20.0, 30.0);
        let ratio =
            field_over(&rf, true, (a, dir), tx, rx) / field_over(&rf, false, (a, dir), tx, rx);
        let k = 2.0 * PI / rf.wavelength;
        let n = 2000;
        let du = 0.1 / n as f64;
        let sum: C64 = (0..n)
            .map(|i| {
                let q = a + dir * ((i as f64 + 0.5) * du);
                C64::from_polar(du, -k * (tx.distance(q) + rx.distance(q)))
            })
            .sum();
        let q = a + dir * 0.05;
        let l_e = 1.0 / (1.0 / tx.distance(q) + 1.0 / rx.distance(q)); // sin β0 = 1 here
        let expected = sum.norm() / (rf.wavelength * l_e).sqrt();
        assert!(expected < 0.2, "{expected}");
        assert!(
            (ratio / expected - 1.0).abs() < 0.01,
            "bounded / unbounded {ratio}, the edge's integral {expected}"
        );
    }

    /// Square to the edge the face factors are −diag(r_∥, r_⊥) on (φ, β): no mixing of the
    /// components, the soft and hard coefficients of the 2-D UTD. Oblique to it they mix.
    #[test]
    fn face_factors_square_to_the_edge_are_the_2d_ones_and_oblique_ones_mix() {
        let rf = concrete_box();
        let (tri, n, e) = (0, DVec3::X, DVec3::Z);
        let cos = 0.6;
        let (r, _) = rf.slab(tri, cos);
        // In the plane square to the edge, at incidence cosine 0.6 on the face x = const.
        let ki = DVec3::new(-0.6, 0.8, 0.0);
        let incident = |ki: DVec3| {
            let phi = ki.cross(e).normalize();
            (ki, phi, phi.cross(ki))
        };
        let m = face_reflection(&rf, tri, n, incident(ki), e);
        let close = |a: C64, b: C64| (a - b).norm() < 1e-12;
        assert!(
            close(m[0][0], -r.1) && close(m[1][1], -r.0),
            "{m:?} against {r:?}"
        );
        assert!(m[0][1].norm() < 1e-12 && m[1][0].norm() < 1e-12, "{m:?}");
        // Oblique: the same face, the wave 40° off square to the edge.
        let ki = DVec3::new(-0.6, 0.8, 0.0) * 40f64.to_radians().cos()
            + DVec3::Z * 40f64.to_radians().sin();
        let m = face_reflection(&rf, tri, n, incident(ki), e);
        assert!(m[0][1].norm() > 1e-3 && m[1][0].norm() > 1e-3, "{m:?}");
    }
}
