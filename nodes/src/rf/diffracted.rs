//! Diffracted paths of a link (rf.md §3.1): each candidate of `diffraction_search` (reflections,
//! one edge, reflections) solved exactly for one receiver. Unfolded in its mirrors, the path is a
//! first-order diffraction from the transmitter's image in the surfaces before the edge to the
//! receiver's image in those after it, so the diffraction point is Keller's for the two images,
//! and the reflection points follow by the image method on either side of it. The wedges and
//! the UTD field over them are `diffraction`'s.

use glam::DVec3;

use super::diffraction::{diffracted_field, diffraction_point};
use super::diffraction_search::DiffractionSequence;
use super::field::{self, CVec};
use super::foliage::{FoliageDepth, foliage_length, loss_amplitude};
use super::image_method::{image_points, images_of, mirrored};
use super::path_field::specular;
use super::paths::{Interaction, InteractionKind, Path, Tracer};
use super::scene::EPS;

/// Clearance kept at a diffraction point when testing its legs: the edge's own faces meet there.
const EDGE_EPS: f64 = 1e-2;

/// The diffracted paths from `tx` (at foliage depth `at_tx`) to `rx` among `candidates`: those
/// whose diffraction point lies on the edge, whose reflection points lie on their triangles and
/// whose every leg is clear of surfaces (diffracted paths are not transmitted; foliage attenuates
/// them, rf.md §5.1), with the UTD field of rf.md §3.1 between the reflections' (rf.md §2.2,
/// scaled by √(1 − S²) as specular paths are).
pub(super) fn diffracted_paths(
    t: &Tracer,
    candidates: &[DiffractionSequence],
    tx: DVec3,
    rx: DVec3,
    at_tx: FoliageDepth,
) -> Vec<Path> {
    candidates
        .iter()
        .filter_map(|c| diffracted_path(t, c, tx, rx, at_tx))
        .collect()
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
        let hits = scene.hits_between(a, b, eps);
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
        * loss_amplitude(t.foliage_db_per_m, foliage_m);
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
