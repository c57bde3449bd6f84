//! Edge diffraction by the UTD (rf.md §3.1: Kouyoumjian-Pathak, with Luebbers'
//! finite-conductivity reflection factors), the geometry and the field: the wedges of a scene's
//! meshes, the diffraction point on each edge (Keller's cone: equal angles, the shortest path over
//! the edge), and the diffracted field in the edge-fixed bases. Which wedges a link tries and the
//! paths over them are `diffracted`'s.

use std::collections::HashMap;
use std::f64::consts::PI;

use glam::DVec3;
use num_complex::Complex64 as C64;

use super::field::{self, CVec};
use super::scene::RfScene;
use super::utd::wedge_coefficients;

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
}

impl Wedge {
    /// Whether a wave from `p` can reach the edge from outside the wedge: `p` in front of either
    /// face's plane (Sionna's test). False for an inner corner seen from the air.
    pub fn lit_from(&self, p: DVec3) -> bool {
        let k = p - self.a;
        k.dot(self.n0) > 1e-9 || k.dot(self.nn) > 1e-9
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
            ..*self
        }
    }
}

/// The edges of `scene` that can diffract: edges shared by exactly two triangles (matched by
/// vertex position, to the micrometre) whose faces turn by more than `min_deg` degrees (and by
/// more than 0.08 degrees, where a plane split into triangles rounds). Each is a wedge of the
/// angle under π between its faces, both normals turned away from the other face, as Sionna RT
/// orients them: whichever way the mesh winds its triangles (Sionna's own scenes wind their
/// buildings inwards), a solid's corner is a wedge whose outside is the air. At a corner where the
/// air is the narrow side (an inner corner), the wedge's outside is the solid and no wave from the
/// air diffracts there ([`Wedge::lit_from`]).
pub fn wedges(scene: &RfScene, min_deg: f64) -> Vec<Wedge> {
    let max_cos = (1.0 - 1e-6f64).min(min_deg.to_radians().cos());
    let key = |p: DVec3| [p.x, p.y, p.z].map(|c| (c * 1e6).round() as i64);
    // Edge (by its ends' quantised positions) -> the triangles on it, with the edge's ends.
    type EdgeKey = ([i64; 3], [i64; 3]);
    let mut edges: HashMap<EdgeKey, Vec<(u32, DVec3, DVec3)>> = HashMap::new();
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
            edges.entry((lo, hi)).or_default().push((t as u32, a, b));
        }
    }
    let mut out: Vec<Wedge> = Vec::new();
    let mut keys: Vec<_> = edges.keys().copied().collect();
    keys.sort_unstable();
    for k in keys {
        let faces = &edges[&k];
        if faces.len() != 2 {
            continue;
        }
        let (t0, a, b) = faces[0];
        let t1 = faces[1].0;
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
            continue;
        };
        let c = n0.dot(nn).clamp(-1.0, 1.0);
        if c >= max_cos {
            continue; // a bend below the threshold
        }
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
        });
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

/// The angle of `s` (a unit direction away from the edge, projected across it) from the 0-face,
/// in [0, 2π) (rf.md §3.1).
fn face_angle(w: &Wedge, s: DVec3) -> f64 {
    let t0 = w.n0.cross(w.e);
    let st = (s - w.e * s.dot(w.e)).normalize_or_zero();
    let sgn = if st.dot(w.n0) >= 0.0 { 1.0 } else { -1.0 };
    PI - (PI - st.dot(t0).clamp(-1.0, 1.0).acos()) * sgn
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
    let d = wedge_coefficients(w.n, phi, phi_i, beta0, k, l);
    // Edge-fixed bases.
    let phi_hat_i = ki.cross(w.e).normalize();
    let beta_hat_i = phi_hat_i.cross(ki);
    let phi_hat_o = -(ko.cross(w.e)).normalize();
    let beta_hat_o = phi_hat_o.cross(ko);
    // Face reflection factors (Luebbers): the β component (along the edge) is TE to the faces,
    // the φ component TM; incidence cosines |sin φ'| on the 0-face, |sin(nπ − φ)| on the n-face.
    // Rotated into the edge-fixed bases (the W matrices of rf.md §3.1, at β0 = 90°) each picks
    // up a sign: β̂ turns from +e to −e, and e_∥ = −φ̂' on the way in. So R = −diag(r_TM, r_TE),
    // which for a perfect conductor gives the classic soft (β) and hard (φ) coefficients.
    let (r0, _) = scene.slab(w.tri0, phi_i.sin().abs());
    let (rn, _) = scene.slab(w.trin, (limit - phi).sin().abs());
    let (r0, rn) = ((-r0.0, -r0.1), (-rn.0, -rn.1));
    let (e_phi, e_beta) = (field::dot(e_tx, phi_hat_i), field::dot(e_tx, beta_hat_i));
    let spread = (1.0 / (si * so * (si + so))).sqrt();
    let comp = |r0c: C64, rnc: C64, ei: C64| -> C64 {
        -((d[0] + d[1]) - d[2] * rnc - d[3] * r0c) * ei * spread
    };
    let out_phi = comp(r0.1, rn.1, e_phi);
    let out_beta = comp(r0.0, rn.0, e_beta);
    Some([0, 1, 2].map(|c| out_phi * phi_hat_o[c] + out_beta * beta_hat_o[c]))
}
