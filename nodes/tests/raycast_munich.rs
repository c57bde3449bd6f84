//! The ray caster's SIMD and scalar paths, one by one and in packets, on a real scene: Sionna
//! RT's munich (from the shared data; the engine's own unit tests cover synthetic triangles).

use glam::Vec3A;
use kodama_nodes::geom::raycast::{SceneRays, tile_order};
use kodama_nodes::io::sionna_xml::read_scene;
use kodama_nodes::rng::{mix, unit};

/// `n` rays from points spread over a cube `span` wide, in directions uniform on the sphere.
fn random_rays(n: usize, span: f32) -> Vec<(Vec3A, Vec3A)> {
    let mut s = 11u64;
    let mut next = || {
        s = mix(s);
        unit(s) as f32
    };
    (0..n)
        .map(|_| {
            let o = Vec3A::new(next(), next(), next()) * span - Vec3A::splat(span / 2.0);
            let z = 2.0 * next() - 1.0;
            let phi = std::f32::consts::TAU * next();
            let r = (1.0 - z * z).max(0.0).sqrt();
            (o, Vec3A::new(r * phi.cos(), r * phi.sin(), z))
        })
        .collect()
}

/// On the munich scene (when the shared data is at hand): the AVX2 and scalar paths give the
/// same hits for rays from a transmitter and from random points, and any-hit agrees.
#[test]
fn simd_and_scalar_agree_on_munich() {
    let xml = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/sionna-scenes/munich/munich.xml");
    if !xml.exists() {
        eprintln!("skipped: {} not found", xml.display());
        return;
    }
    let scene = read_scene(&xml).unwrap();
    let fast = SceneRays::new(&scene);
    let mut slow = SceneRays::new(&scene);
    slow.force_scalar();
    let mut hits = 0;
    for (k, (o, d)) in random_rays(50_000, 400.0).into_iter().enumerate() {
        let o = if k % 2 == 0 {
            Vec3A::new(8.5, 21.0, 27.0)
        } else {
            o
        };
        let (o, d) = (o.to_array(), d.to_array());
        let a = fast.cast(o, d, 1e-3, f32::INFINITY);
        assert_eq!(a, slow.cast(o, d, 1e-3, f32::INFINITY));
        assert_eq!(fast.occluded(o, d, 1e-3, f32::INFINITY), a.is_some());
        assert_eq!(
            slow.occluded(o, d, 1e-3, 50.0),
            a.is_some_and(|h| h.t < 50.0)
        );
        hits += a.is_some() as usize;
    }
    assert!(hits > 10_000, "{hits} hits");

    // A camera at the transmitter, its pixels cast in tiles, and a grid of rays looking
    // down: the packets' hits are the single rays'.
    let (w, h) = (96u32, 64u32);
    let origin = [8.5f32, 21.0, 27.0];
    let mut rays = Vec::new();
    for p in tile_order(w, h) {
        let (u, v) = ((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
        // A narrow lens: tiles of about 1.4 degrees, within what `cast_coherent` packs.
        let d = Vec3A::new((u / w as f32 - 0.5) * 0.3, 1.0, 0.1 - v / h as f32 * 0.2);
        rays.push((origin, d.normalize().to_array()));
    }
    for p in tile_order(w, h) {
        let (x, y) = ((p % w) as f32 * 3.1 - 150.0, (p / w) as f32 * 3.1 - 100.0);
        rays.push(([x, y, 200.0], [0.0, 0.0, -1.0]));
    }
    for b in [&fast, &slow] {
        let got = b.cast_coherent(&rays, 1e-3, f32::INFINITY);
        for ((o, d), g) in rays.iter().zip(&got) {
            assert_eq!(*g, b.cast(*o, *d, 1e-3, f32::INFINITY));
        }
        assert!(got.iter().filter(|h| h.is_some()).count() > 5_000);
    }
}
