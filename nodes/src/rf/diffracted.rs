//! Diffracted paths of a link (the UTD, `diffraction`): each candidate of `diffraction_search`
//! (reflections, one edge, reflections) solved exactly for one receiver. Unfolded in its mirrors,
//! the path is a first-order diffraction from the transmitter's image in the surfaces before the
//! edge to the receiver's image in those after it, so the diffraction point is Keller's for the two
//! images, and the reflection points follow by the image method on either side of it. The wedges
//! and the UTD field over them are `diffraction`'s.

use glam::{DMat3, DVec3};

use super::diffraction::{diffracted_field, diffraction_point};
use super::diffraction_search::DiffractionSequence;
use super::field::{self, CVec};
use super::foliage::{FoliageDepth, foliage_length};
use super::image_method::{image_points, images_of, mirrored};
use super::path::{Interaction, InteractionKind, Path, Tracer};
use super::path_field::specular;
use super::scene::{EPS, RfScene};

/// Clearance kept at a diffraction point when testing its legs: the edge's own faces meet there.
const EDGE_EPS: f64 = 1e-2;

/// The diffraction candidates of one transmitter, ready to be solved for many receivers. A
/// receiver is tried against every candidate and the diffraction point turns almost all of them
/// away; what that first test reads (the source image, the edge, the mirrors after it as one
/// affine map) is kept in one flat array, so a candidate is turned away without reading its
/// lists or the scene's triangles.
pub(super) struct DiffractionCandidates {
    list: Vec<DiffractionSequence>,
    probes: Vec<Probe>,
}

/// A candidate's first test: where the edge's diffraction point lies for a receiver.
struct Probe {
    source: DVec3,
    a: DVec3,
    e: DVec3,
    length: f64,
    /// The receiver's image in the surfaces after the edge: `mirror * rx + shift`.
    mirror: DMat3,
    shift: DVec3,
}

impl Probe {
    fn new(scene: &RfScene, c: &DiffractionSequence, tx: DVec3) -> Probe {
        let (mut mirror, mut shift) = (DMat3::IDENTITY, DVec3::ZERO);
        // Mirrored in the last surface first, as `diffracted_path` folds: p - 2 ((p - q).n) n.
        for &t in c.post.iter().rev() {
            let (n, q) = (scene.normals[t as usize], scene.tris[t as usize][0]);
            let m = DMat3::IDENTITY - 2.0 * DMat3::from_cols(n * n.x, n * n.y, n * n.z);
            (mirror, shift) = (m * mirror, m * shift + 2.0 * q.dot(n) * n);
        }
        Probe {
            source: c.pre_images.last().copied().unwrap_or(tx),
            a: c.wedge.a,
            e: c.wedge.e,
            length: c.wedge.length,
            mirror,
            shift,
        }
    }

    /// False only when the diffraction point for `rx` lies off the edge by more than the
    /// rounding that separates this sink from `diffracted_path`'s (1 mm, and 1e-6 of the
    /// span the point moves over). Ends less than 1 cm off the edge's line, where the point's
    /// ratio is ill-conditioned, always pass: past that, a nanometre of rounding in the two
    /// distances (coordinates of millions of metres) moves the ratio by under 2e-7.
    #[inline]
    fn may_diffract(&self, rx: DVec3) -> bool {
        let sink = self.mirror * rx + self.shift;
        let (u1, u2) = (
            (self.source - self.a).dot(self.e),
            (sink - self.a).dot(self.e),
        );
        let r1 = (self.source - self.a - self.e * u1).length();
        let r2 = (sink - self.a - self.e * u2).length();
        if r1 + r2 < 1e-2 {
            return true;
        }
        let u = u1 + (u2 - u1) * r1 / (r1 + r2);
        let slack = 1e-3 + 1e-6 * (u2 - u1).abs();
        u > 1e-6 - slack && u < self.length - 1e-6 + slack
    }
}

impl DiffractionCandidates {
    /// The candidates of `tx`'s search.
    pub(super) fn new(scene: &RfScene, tx: DVec3, list: Vec<DiffractionSequence>) -> Self {
        let probes = list.iter().map(|c| Probe::new(scene, c, tx)).collect();
        DiffractionCandidates { list, probes }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// The diffracted paths from `tx` (at foliage depth `at_tx`) to `rx`: those whose diffraction
    /// point lies on the edge, whose reflection points lie on their triangles and whose every leg
    /// is clear of surfaces (diffracted paths are not transmitted; foliage attenuates them, ITU-R
    /// P.833), with the UTD field of `diffraction` between the reflections' (ITU-R P.2040 §2.2.2.2,
    /// scaled by √(1 − S²) as specular paths are). In the candidates' order.
    pub(super) fn paths(&self, t: &Tracer, tx: DVec3, rx: DVec3, at_tx: FoliageDepth) -> Vec<Path> {
        self.list
            .iter()
            .zip(&self.probes)
            .filter(|(_, probe)| probe.may_diffract(rx))
            .filter_map(|(c, _)| diffracted_path(t, c, tx, rx, at_tx))
            .collect()
    }
}

fn diffracted_path(
    t: &Tracer,
    c: &DiffractionSequence,
    tx: DVec3,
    rx: DVec3,
    at_tx: FoliageDepth,
) -> Option<Path> {
    let scene = t.scene;
    let w = &c.wedge;
    let source = c.pre_images.last().copied().unwrap_or(tx);
    // The receiver mirrored in the surfaces after the edge, the last one first.
    let sink = c
        .post
        .iter()
        .rev()
        .fold(rx, |p, &tri| mirrored(scene, p, tri));
    let q = w.a + w.e * diffraction_point(w, source, sink)?;
    let before = if c.pre.is_empty() {
        vec![tx, q]
    } else {
        image_points(scene, tx, q, &c.pre, &c.pre_images)?
    };
    let after = if c.post.is_empty() {
        vec![q, rx]
    } else {
        image_points(scene, q, rx, &c.post, &images_of(scene, q, &c.post))?
    };
    // Every leg clear of surfaces (one any-hit query each without foliage), with the foliage
    // along it.
    let (mut foliage_m, mut foliage) = (0.0, at_tx);
    for leg in before.windows(2).chain(after.windows(2)) {
        let (a, b) = (leg[0], leg[1]);
        let eps = if a == q || b == q { EDGE_EPS } else { EPS };
        if !scene.has_foliage() {
            if scene.blocked(a, b, eps) {
                return None;
            }
            continue;
        }
        let hits = scene.hits_between_until(a, b, eps, 0);
        if hits.iter().any(|h| !scene.is_foliage(h.triangle)) {
            return None;
        }
        let (inside, at_b) = foliage_length(scene, a, b, &hits, foliage);
        foliage_m += inside;
        foliage = at_b;
    }
    let mut interactions = Vec::with_capacity(c.pre.len() + 1 + c.post.len());
    let k0 = (before[1] - before[0]).normalize();
    let e_tx = field::real(DVec3::from(t.tx_antenna.field(k0.to_array())));
    let e = reflections(t, &before, &c.pre, e_tx, &mut interactions);
    // The wave reaches the edge as if from the source image, and leaves it towards the sink
    // image: the UTD over the unfolded lengths.
    let e = diffracted_field(scene, w, q, source, sink, &e)?;
    interactions.push(Interaction {
        kind: InteractionKind::Diffraction,
        point: q.to_array(),
        triangle: w.tri0,
    });
    let e = reflections(t, &after, &c.post, e, &mut interactions);
    let k_last = (rx - after[after.len() - 2]).normalize();
    let rx_pattern = DVec3::from(t.rx_antenna.field((-k_last).to_array()));
    let a = field::dot(&e, rx_pattern)
        * (scene.wavelength / (4.0 * std::f64::consts::PI))
        * t.foliage.amplitude(foliage_m);
    if a.norm_sqr() == 0.0 {
        return None;
    }
    let length = (q - source).length() + (sink - q).length();
    Some(Path::new(interactions, length, a, foliage_m))
}

/// The field `e` after the reflections at the inner points of `points` off the surfaces `seq`,
/// each recorded in `interactions`.
fn reflections(
    t: &Tracer,
    points: &[DVec3],
    seq: &[u32],
    mut e: CVec,
    interactions: &mut Vec<Interaction>,
) -> CVec {
    for (j, &tri) in seq.iter().enumerate() {
        let d = (points[j + 1] - points[j]).normalize();
        let (e2, at) = specular(t, tri, d, points[j + 1], &e);
        e = e2;
        interactions.push(at);
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rf::antenna::Antenna;
    use crate::rf::diffraction::wedges;
    use crate::rf::diffraction_search::diffraction_sequences;
    use crate::rf::path::TraceOptions;
    use crate::rf::sequences::reflection_sequences;
    use crate::rf::test_scenes::{STREET_TX, street_grid};

    /// The probe turns receivers away, never a path: over a street grid, every receiver gets
    /// exactly the paths of `diffracted_path` over every candidate, in order and to the bit,
    /// while most candidates are never solved.
    #[test]
    fn candidates_give_the_paths_of_every_candidate_solved() {
        let scene = street_grid();
        let tx = STREET_TX;
        let opt = TraceOptions {
            max_depth: 2,
            rays: 20_000,
            diffraction: true,
            ..Default::default()
        };
        let all = wedges(&scene, 0.0, true, true);
        let seqs = reflection_sequences(&scene, tx, &opt);
        let list = diffraction_sequences(&scene, &all, tx, &seqs, &opt);
        assert!(list.len() > 300, "{}", list.len());
        let candidates = DiffractionCandidates::new(&scene, tx, list);
        let antenna = Antenna::default();
        let tracer = Tracer {
            scene: &scene,
            tx_antenna: &antenna,
            rx_antenna: &antenna,
            opt: &opt,
            foliage: crate::rf::foliage::FoliageLaw::Linear.at(3.5e9, 0.0),
        };
        let at_tx = FoliageDepth::at(&scene, tx);
        let bits = |p: &Path| (p.delay_s.to_bits(), p.a.map(f64::to_bits));
        let (mut paths, mut solved, mut tried) = (0, 0, 0);
        for k in 0..120 {
            let rx = DVec3::new(
                (k % 12) as f64 * 13.7 - 80.0,
                (k / 12) as f64 * 16.1 - 72.0,
                1.5,
            );
            let exact: Vec<_> = candidates
                .list
                .iter()
                .filter_map(|c| diffracted_path(&tracer, c, tx, rx, at_tx))
                .map(|p| bits(&p))
                .collect();
            let fast: Vec<_> = candidates
                .paths(&tracer, tx, rx, at_tx)
                .iter()
                .map(bits)
                .collect();
            assert_eq!(fast, exact, "rx {rx}");
            paths += exact.len();
            solved += candidates
                .probes
                .iter()
                .filter(|p| p.may_diffract(rx))
                .count();
            tried += candidates.list.len();
        }
        assert!(paths > 500, "{paths}");
        // 52 %: this grid's blocks are few and their edges long; the demo's truth has thousands
        // of short ones.
        assert!(solved * 3 < tried * 2, "{solved} of {tried} solved");
    }
}
