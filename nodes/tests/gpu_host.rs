//! The GPU kernels' source compiled for the host (feature `cuda`, nodes/build.rs) against the
//! Rust tracer: every ray's closest hit must be the same triangle at the same distance, to the
//! bit. This is what lets CI without a GPU vouch for the kernel the GPU runs (`rf::gpu`).

mod gpu_common;

use gpu_common::{munich_xml, rays, street_grid, vertices};
use kodama_nodes::artifact::Scene;
use kodama_nodes::geom::raycast::SceneRays;
use kodama_nodes::io::sionna_xml::read_scene;
use kodama_nodes::rf::gpu::{GpuRay, Tree, host_cast};

/// Casts `rays` with the Rust tracer and with the kernel's host build; asserts every hit equal
/// to the bit; returns (rays, hits).
fn compare(scene: &Scene, rays: &[GpuRay]) -> (usize, usize) {
    let cpu = SceneRays::new(scene);
    let tree = Tree::new(cpu.wide_bvh()).unwrap();
    let got = host_cast(&tree, rays);
    let mut hits = 0;
    for (k, (r, g)) in rays.iter().zip(&got).enumerate() {
        let want = cpu.cast_index([r[0], r[1], r[2]], [r[3], r[4], r[5]], r[6], r[7]);
        let bits = |h: Option<(f32, u32)>| h.map(|(t, p)| (t.to_bits(), p));
        assert_eq!(bits(*g), bits(want), "ray {k}: {r:?}");
        hits += want.is_some() as usize;
    }
    (rays.len(), hits)
}

#[test]
fn host_kernel_casts_street_grid_as_the_cpu() {
    let scene = street_grid();
    let v = vertices(&scene);
    let rays = rays([-60.0, -56.0, 12.0], [0.0, 0.0, 10.0], 200.0, 100_000, &v);
    let (n, hits) = compare(&scene, &rays);
    println!("street grid: {n} rays, {hits} hits, all bit-equal");
    assert!(hits > n / 4, "{hits} hits of {n}: too few to test much");
}

#[test]
fn host_kernel_casts_munich_as_the_cpu() {
    let Some(xml) = munich_xml() else { return };
    let scene = read_scene(&xml).unwrap();
    let v = vertices(&scene);
    let rays = rays([8.5, 21.0, 27.0], [0.0, 0.0, 30.0], 400.0, 200_000, &v);
    let (n, hits) = compare(&scene, &rays);
    println!("munich: {n} rays, {hits} hits, all bit-equal");
    assert!(hits > n / 4, "{hits} hits of {n}: too few to test much");
}
