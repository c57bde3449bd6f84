//! The cast kernel on a real GPU (the checked-in PTX through the CUDA driver) against the Rust
//! tracer, to the bit; and, run with `--ignored` (scripts/gpu_device_check.sh), its speed on
//! munich against the CPU's. Skips, saying so, where no CUDA driver is present.

mod gpu_common;

use std::time::Instant;

use glam::Vec3A;
use gpu_common::{munich_xml, rays, street_grid, vertices};
use kodama_nodes::artifact::Scene;
use kodama_nodes::geom::raycast::SceneRays;
use kodama_nodes::io::sionna_xml::read_scene;
use kodama_nodes::rf::fibonacci::fibonacci_run;
use kodama_nodes::rf::gpu::{CastHit, Gpu, GpuRay, Tree, driver_present, host_cast};
use rayon::prelude::*;

fn gpu() -> Option<Gpu> {
    if !driver_present() {
        println!("skipped: no CUDA driver (libcuda.so.1) on this machine");
        return None;
    }
    let g = Gpu::new().expect("a CUDA driver is present, so a GPU should open");
    println!(
        "device: {} (driver CUDA {}.{})",
        g.name(),
        g.driver_version() / 1000,
        g.driver_version() % 1000 / 10
    );
    Some(g)
}

fn bits(h: &CastHit) -> Option<(u32, u32)> {
    h.map(|(t, p)| (t.to_bits(), p))
}

fn cpu_cast(cpu: &SceneRays, rays: &[GpuRay]) -> Vec<CastHit> {
    rays.par_iter()
        .map(|r| cpu.cast_index([r[0], r[1], r[2]], [r[3], r[4], r[5]], r[6], r[7]))
        .collect()
}

/// Device hits == host twin's == the Rust tracer's, for every ray; returns the hit count.
fn check(gpu: &Gpu, scene: &Scene, rays: &[GpuRay]) -> usize {
    let cpu = SceneRays::new(scene);
    let tree = Tree::new(cpu.wide_bvh()).unwrap();
    let dev = gpu.upload(&tree).unwrap();
    let got = gpu.cast(&dev, rays).unwrap();
    let host = host_cast(&tree, rays);
    let want = cpu_cast(&cpu, rays);
    for (k, r) in rays.iter().enumerate() {
        assert_eq!(
            bits(&got[k]),
            bits(&want[k]),
            "device vs CPU, ray {k}: {r:?}"
        );
        assert_eq!(
            bits(&host[k]),
            bits(&want[k]),
            "host twin vs CPU, ray {k}: {r:?}"
        );
    }
    want.iter().filter(|h| h.is_some()).count()
}

#[test]
fn device_casts_are_the_cpu_casts() {
    let Some(gpu) = gpu() else { return };
    let scene = street_grid();
    let r = rays(
        [-60.0, -56.0, 12.0],
        [0.0, 0.0, 10.0],
        200.0,
        100_000,
        &vertices(&scene),
    );
    let hits = check(&gpu, &scene, &r);
    println!(
        "street grid: {} rays, {hits} hits, device = CPU to the bit",
        r.len()
    );
    let Some(xml) = munich_xml() else { return };
    let scene = read_scene(&xml).unwrap();
    let r = rays(
        [8.5, 21.0, 27.0],
        [0.0, 0.0, 30.0],
        400.0,
        200_000,
        &vertices(&scene),
    );
    let hits = check(&gpu, &scene, &r);
    println!(
        "munich: {} rays, {hits} hits, device = CPU to the bit",
        r.len()
    );
}

/// The next segment of every ray that hit: specular reflection off the hit triangle, from the
/// hit point (what a map's bounce casts look like, without its physics).
fn bounce(tris: &[[Vec3A; 3]], rays: &[GpuRay], hits: &[CastHit]) -> Vec<GpuRay> {
    rays.par_iter()
        .zip(hits)
        .filter_map(|(r, h)| {
            let (t, p) = (*h)?;
            let [a, b, c] = tris[p as usize];
            let n = (b - a).cross(c - a).normalize_or_zero();
            let o = Vec3A::new(r[0], r[1], r[2]);
            let d = Vec3A::new(r[3], r[4], r[5]);
            let q = o + d * t;
            let d2 = (d - 2.0 * d.dot(n) * n).normalize_or_zero();
            (d2 != Vec3A::ZERO).then(|| [q.x, q.y, q.z, d2.x, d2.y, d2.z, 1e-3, f32::INFINITY])
        })
        .collect()
}

/// Munich casts per second on the device and on every CPU core, for a map-like load: the
/// lattice from the transmitter, then up to `depth - 1` specular bounces of the rays that hit.
/// Prints a markdown table; asserts device = CPU to the bit and two device runs identical.
#[test]
#[ignore = "timing on a GPU machine: scripts/gpu_device_check.sh"]
fn device_cast_speed_on_munich() {
    let Some(gpu) = gpu() else { return };
    let Some(xml) = munich_xml() else { return };
    let scene = read_scene(&xml).unwrap();
    let cpu = SceneRays::new(&scene);
    let tree = Tree::new(cpu.wide_bvh()).unwrap();
    let dev = gpu.upload(&tree).unwrap();
    let tris: Vec<[Vec3A; 3]> = scene
        .objects
        .iter()
        .flat_map(|o| {
            let p = &o.mesh.positions;
            o.mesh
                .triangles
                .iter()
                .map(move |t| t.map(|i| Vec3A::from(p[i as usize])))
        })
        .collect();
    println!(
        "\n| device | rays | depth | casts | GPU kernel s | GPU casts/s | GPU +upload+readback s | \
         CPU s ({} threads) | CPU casts/s | speed-up (kernel) | bit-equal | run-to-run |",
        rayon::current_num_threads()
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    // Warm the driver's JIT and the caches.
    let warm: Vec<GpuRay> = (0..1024)
        .map(|_| [8.5, 21.0, 27.0, 0.0, 0.0, -1.0, 1e-3, f32::INFINITY])
        .collect();
    gpu.cast(&dev, &warm).unwrap();
    for n in [1_000_000u32, 10_000_000] {
        for depth in [3u32, 5] {
            let mut seg: Vec<GpuRay> = fibonacci_run(n, 0, n)
                .map(|d| {
                    let d = d.as_vec3();
                    [8.5, 21.0, 27.0, d.x, d.y, d.z, 1e-3, f32::INFINITY]
                })
                .collect();
            let (mut casts, mut kernel, mut total, mut cpu_s) = (0usize, 0.0, 0.0, 0.0);
            let (mut equal, mut same) = (true, true);
            for _ in 0..depth {
                if seg.is_empty() {
                    break;
                }
                let (got, times) = gpu.cast_timed(&dev, &seg).unwrap();
                let again = gpu.cast(&dev, &seg).unwrap();
                let clock = Instant::now();
                let want = cpu_cast(&cpu, &seg);
                cpu_s += clock.elapsed().as_secs_f64();
                casts += seg.len();
                kernel += times.kernel;
                total += times.upload + times.kernel + times.readback;
                equal &= got.iter().zip(&want).all(|(a, b)| bits(a) == bits(b));
                same &= got.iter().zip(&again).all(|(a, b)| bits(a) == bits(b));
                seg = bounce(&tris, &seg, &want);
            }
            println!(
                "| {} | {n} | {depth} | {casts} | {kernel:.4} | {:.0} M | {total:.4} | {cpu_s:.4} | \
                 {:.0} M | {:.1}x | {equal} | {same} |",
                gpu.name(),
                casts as f64 / kernel / 1e6,
                casts as f64 / cpu_s / 1e6,
                cpu_s / kernel
            );
            assert!(equal, "device hits differ from the CPU's");
            assert!(same, "two device runs differ");
        }
    }
}
