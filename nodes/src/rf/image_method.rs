//! The image method: a sequence of reflecting surfaces solved exactly for one receiver. The
//! transmitter is mirrored in each surface in turn; walking back from the receiver towards each
//! image gives the reflection points, kept only when each lies on its triangle and sends the path
//! back to the side it came from.

use glam::DVec3;

use super::scene::RfScene;

/// The transmitter mirrored in each surface of `seq` in turn: the images of the image method.
pub fn images_of(scene: &RfScene, tx: DVec3, seq: &[u32]) -> Vec<DVec3> {
    let mut images = Vec::with_capacity(seq.len());
    let mut img = tx;
    for &t in seq {
        img = mirrored(scene, img, t);
        images.push(img);
    }
    images
}

/// `p` mirrored in the plane of triangle `t`.
pub fn mirrored(scene: &RfScene, p: DVec3, t: u32) -> DVec3 {
    let (n, q) = (scene.normals[t as usize], scene.tris[t as usize][0]);
    p - 2.0 * (p - q).dot(n) * n
}

/// The sequences a transmitter's rays found, with their images, ready to be solved for many
/// receivers. A receiver is tried against every sequence and the last surface turns almost all
/// of them away, so each sequence also keeps, in one flat array, a sphere around its last
/// surface: a receiver whose line from the last image passes wide of it cannot be reached, and
/// is turned away before the exact walk reads the sequence, its images or the scene's triangles.
pub struct Candidates {
    sequences: Vec<(Vec<u32>, Vec<DVec3>)>,
    reach: Vec<Reach>,
}

/// The last image of a sequence and a sphere holding its last surface, grown by more than the
/// rounding of the test in [`Reach::may_reach`] and the tolerance of [`inside_triangle`].
struct Reach {
    image: DVec3,
    centre: DVec3,
    radius2: f64,
}

impl Reach {
    fn new(scene: &RfScene, t: u32, image: DVec3) -> Reach {
        let tri = &scene.tris[t as usize];
        let centre = (tri[0] + tri[1] + tri[2]) / 3.0;
        let r = tri.iter().map(|v| v.distance(centre)).fold(0.0, f64::max);
        // 1 mm and 1e-6 of the radius, far above the 1e-9 m tolerance of the exact test, and a
        // term for the cancellation in `may_reach`, whose terms grow as |centre - image|².
        let w2 = (centre - image).length_squared();
        let grown = r * (1.0 + 1e-6) + 1e-3;
        Reach {
            image,
            centre,
            radius2: grown * grown + 1e-12 * w2,
        }
    }

    /// False only when the line from the image through `rx` passes outside the sphere: no
    /// point of the last surface lies on it. |w × v|² / |v|² is the squared distance of the
    /// centre from the line, written without a division or a root. A receiver on the image
    /// itself has no line: it passes (and the exact walk decides).
    #[inline]
    fn may_reach(&self, rx: DVec3) -> bool {
        let (v, w) = (rx - self.image, self.centre - self.image);
        let (vv, wv) = (v.length_squared(), w.dot(v));
        vv == 0.0 || w.length_squared() * vv - wv * wv <= self.radius2 * vv
    }
}

impl Candidates {
    /// `seqs` from `tx`: each with its images ([`images_of`]).
    pub fn new(scene: &RfScene, tx: DVec3, seqs: Vec<Vec<u32>>) -> Candidates {
        let sequences: Vec<(Vec<u32>, Vec<DVec3>)> = seqs
            .into_iter()
            .map(|seq| {
                let images = images_of(scene, tx, &seq);
                (seq, images)
            })
            .collect();
        let reach = sequences
            .iter()
            .map(|(seq, images)| match (seq.last(), images.last()) {
                (Some(&t), Some(&image)) => Reach::new(scene, t, image),
                // An empty sequence is the direct path: every receiver.
                _ => Reach {
                    image: tx,
                    centre: tx,
                    radius2: f64::INFINITY,
                },
            })
            .collect();
        Candidates { sequences, reach }
    }

    /// Each sequence that reaches `rx`, with its path ([`image_points`]), in the sequences'
    /// order.
    pub fn solve<'a>(
        &'a self,
        scene: &'a RfScene,
        tx: DVec3,
        rx: DVec3,
    ) -> impl Iterator<Item = (&'a [u32], Vec<DVec3>)> + 'a {
        self.reach
            .iter()
            .zip(&self.sequences)
            .filter(move |(reach, _)| reach.may_reach(rx))
            .filter_map(move |(_, (seq, images))| {
                image_points(scene, tx, rx, seq, images).map(|p| (seq.as_slice(), p))
            })
    }
}

/// The path `tx`, reflection points, `rx`: with the transmitter's `images` in the surfaces of
/// `seq`, walk back from the receiver, intersecting each surface's plane. `None` when a point
/// misses its triangle or falls outside its segment, or a reflection would cross its surface.
pub fn image_points(
    scene: &RfScene,
    tx: DVec3,
    rx: DVec3,
    seq: &[u32],
    images: &[DVec3],
) -> Option<Vec<DVec3>> {
    let Some(last) = seq.len().checked_sub(1) else {
        return Some(vec![tx, rx]);
    };
    // A receiver is tried against every sequence its transmitter's rays found, and the last
    // surface rejects almost all of them: decide that before allocating the path.
    let mut target = reflection_point(scene, seq[last], images[last], rx)?;
    let mut points = vec![DVec3::ZERO; seq.len() + 2];
    points[0] = tx;
    points[seq.len() + 1] = rx;
    points[last + 1] = target;
    for j in (0..last).rev() {
        target = reflection_point(scene, seq[j], images[j], target)?;
        points[j + 1] = target;
    }
    // Each reflection must send the path back to the side it came from.
    for j in 1..=seq.len() {
        let n = scene.normals[seq[j - 1] as usize];
        let (a, b) = (
            (points[j - 1] - points[j]).dot(n),
            (points[j + 1] - points[j]).dot(n),
        );
        if a * b <= 0.0 {
            return None;
        }
    }
    Some(points)
}

/// Where the segment from `image` to `target` crosses triangle `t`: `None` when it misses the
/// triangle or crosses its plane outside the segment.
#[inline]
fn reflection_point(scene: &RfScene, t: u32, image: DVec3, target: DVec3) -> Option<DVec3> {
    let t = t as usize;
    let (n, q) = (scene.normals[t], scene.tris[t][0]);
    let d = target - image;
    let denom = n.dot(d);
    if denom.abs() < 1e-12 {
        return None;
    }
    let s = n.dot(q - image) / denom;
    if !(s > 1e-9 && s < 1.0 - 1e-9) {
        return None;
    }
    let p = image + d * s;
    inside_triangle(&scene.tris[t], n, p).then_some(p)
}

/// Whether `p`, on the plane of `t` (normal `n`), lies inside it (edges included).
fn inside_triangle(t: &[DVec3; 3], n: DVec3, p: DVec3) -> bool {
    let tol = -1e-9;
    (0..3).all(|k| {
        let edge = t[(k + 1) % 3] - t[k];
        let side = edge.cross(p - t[k]).dot(n);
        // The edge's length only matters within its tolerance of the edge: skip the root inside.
        side >= 0.0 || side >= tol * edge.length()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rf::path::TraceOptions;
    use crate::rf::sequences::reflection_sequences;
    use crate::rf::test_scenes::{STREET_TX, street_grid};

    /// An empty sequence is the direct path, for every receiver: the transmitter's own point
    /// included, where the line from the image has no direction.
    #[test]
    fn an_empty_sequence_reaches_every_receiver() {
        let scene = street_grid();
        let tx = STREET_TX;
        let candidates = Candidates::new(&scene, tx, vec![Vec::new()]);
        for rx in [tx, DVec3::new(10.0, 3.0, 1.5)] {
            let got: Vec<(&[u32], Vec<DVec3>)> = candidates.solve(&scene, tx, rx).collect();
            assert_eq!(got, vec![(&[][..], vec![tx, rx])], "rx {rx}");
        }
    }

    /// The sphere test turns receivers away, never a path: over a street grid with its ground,
    /// every receiver gets exactly the paths of the exact walk over every sequence, in order
    /// and to the bit, while most sequences never reach the walk.
    #[test]
    fn candidates_solve_as_the_exact_walk_over_every_sequence() {
        let scene = street_grid();
        let tx = STREET_TX;
        let opt = TraceOptions {
            max_depth: 3,
            rays: 20_000,
            ..Default::default()
        };
        let seqs = reflection_sequences(&scene, tx, &opt);
        assert!(seqs.len() > 1000, "{}", seqs.len());
        let candidates = Candidates::new(&scene, tx, seqs);
        let (mut paths, mut walked, mut tried) = (0usize, 0usize, 0usize);
        for k in 0..150 {
            let rx = DVec3::new(
                (k % 15) as f64 * 10.3 - 80.0,
                (k / 15) as f64 * 13.1 - 65.0,
                1.5,
            );
            let exact: Vec<(&[u32], Vec<[u64; 3]>)> = candidates
                .sequences
                .iter()
                .filter_map(|(seq, images)| {
                    image_points(&scene, tx, rx, seq, images).map(|p| (seq.as_slice(), p))
                })
                .map(|(seq, p)| {
                    (
                        seq,
                        p.iter().map(|v| v.to_array().map(f64::to_bits)).collect(),
                    )
                })
                .collect();
            let fast: Vec<(&[u32], Vec<[u64; 3]>)> = candidates
                .solve(&scene, tx, rx)
                .map(|(seq, p)| {
                    (
                        seq,
                        p.iter().map(|v| v.to_array().map(f64::to_bits)).collect(),
                    )
                })
                .collect();
            assert_eq!(fast, exact, "rx {rx}");
            paths += exact.len();
            walked += candidates.reach.iter().filter(|r| r.may_reach(rx)).count();
            tried += candidates.sequences.len();
        }
        assert!(paths > 300, "{paths}");
        // 24 %: the ground's two big triangles let almost every receiver through.
        assert!(walked * 3 < tried, "{walked} of {tried} walked");
    }
}
