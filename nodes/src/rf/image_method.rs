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
    let mut points = vec![DVec3::ZERO; seq.len() + 2];
    points[0] = tx;
    points[seq.len() + 1] = rx;
    let mut target = rx;
    for j in (0..seq.len()).rev() {
        let t = seq[j] as usize;
        let (n, q) = (scene.normals[t], scene.tris[t][0]);
        let d = target - images[j];
        let denom = n.dot(d);
        if denom.abs() < 1e-12 {
            return None;
        }
        let s = n.dot(q - images[j]) / denom;
        if !(s > 1e-9 && s < 1.0 - 1e-9) {
            return None;
        }
        let p = images[j] + d * s;
        if !inside_triangle(&scene.tris[t], n, p) {
            return None;
        }
        points[j + 1] = p;
        target = p;
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

/// Whether `p`, on the plane of `t` (normal `n`), lies inside it (edges included).
fn inside_triangle(t: &[DVec3; 3], n: DVec3, p: DVec3) -> bool {
    let tol = -1e-9;
    (0..3).all(|k| {
        (t[(k + 1) % 3] - t[k]).cross(p - t[k]).dot(n) >= tol * (t[(k + 1) % 3] - t[k]).length()
    })
}
