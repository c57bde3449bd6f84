//! The cast, map and link-search kernels on a real GPU (the checked-in PTX through the CUDA
//! driver) against the Rust tracer, to the bit; and, run with `--ignored`
//! (scripts/gpu_device_check.sh), their speed on munich against the CPU's: casts, maps, the
//! sequence search. Skips, saying so, where no CUDA driver is present.

mod gpu_common;

use std::time::Instant;

use glam::{DVec3, Vec3A};
use gpu_common::{munich_xml, rays, street_grid, vertices};
use kodama_nodes::artifact::Scene;
use kodama_nodes::geom::raycast::SceneRays;
use kodama_nodes::io::sionna_xml::read_scene;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::fibonacci::fibonacci_run;
use kodama_nodes::rf::fibonacci::patch_order;
use kodama_nodes::rf::gpu::{
    CastHit, Gpu, GpuRay, MapInputs, MapParams, MapScene, ORDER_CHUNK, Tree, driver_present,
    host_cast, host_occluded, host_radio_map,
};
use kodama_nodes::rf::map_plane::{MapPlane, default_plane};
use kodama_nodes::rf::path::TraceOptions;
use kodama_nodes::rf::radiomap::radio_map;
use kodama_nodes::rf::scene::RfScene;
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

/// Device hits == host twin's == the Rust tracer's, for every ray, closest and any; returns the
/// hit count.
fn check(gpu: &Gpu, scene: &Scene, rays: &[GpuRay]) -> usize {
    let cpu = SceneRays::new(scene);
    let tree = Tree::new(cpu.wide_bvh()).unwrap();
    let dev = gpu.upload(&tree).unwrap();
    let got = gpu.cast(&dev, rays).unwrap();
    let host = host_cast(&tree, rays);
    let want = cpu_cast(&cpu, rays);
    let any = gpu.occluded(&dev, rays).unwrap();
    let any_host = host_occluded(&tree, rays);
    for (k, r) in rays.iter().enumerate() {
        let want_any = cpu.occluded([r[0], r[1], r[2]], [r[3], r[4], r[5]], r[6], r[7]);
        assert_eq!(any[k], want_any, "device any-hit vs CPU, ray {k}: {r:?}");
        assert_eq!(any_host[k], want_any, "host any-hit vs CPU, ray {k}: {r:?}");
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

/// The device's patch order (`kodama_order`) is `patch_order`'s, chunk by chunk, to the ray.
#[test]
fn device_order_is_patch_order() {
    let Some(gpu) = gpu() else { return };
    for n in [1u32, 64, 65, 1000, 65_536, 100_000, 1_000_000, 3_000_001] {
        let got = gpu.patch_order(n).unwrap();
        let mut want = Vec::with_capacity(n as usize);
        for start in (0..n).step_by(ORDER_CHUNK as usize) {
            want.extend(
                patch_order(n, start, ORDER_CHUNK)
                    .iter()
                    .map(|&k| start + k),
            );
        }
        assert_eq!(got, want, "{n} rays: device order != patch_order");
    }
    println!("device order = patch_order, 1 to 3,000,001 rays");
}

fn map_inputs(scene: &RfScene, tx: DVec3, plane: &MapPlane, rays: u32, depth: u32) -> MapInputs {
    map_inputs_with(scene, tx, plane, &map_options(rays, depth, false))
}

fn map_inputs_with(scene: &RfScene, tx: DVec3, plane: &MapPlane, opt: &TraceOptions) -> MapInputs {
    MapInputs::new(scene, tx, &Antenna::default(), plane, opt, 3.5e9).unwrap()
}

/// LOS, specular reflection and transmission at `depth`; with `diffuse`, Lambertian diffuse
/// reflection at roughness 0.3 too (the paper's settings at depth 12).
fn map_options(rays: u32, depth: u32, diffuse: bool) -> TraceOptions {
    TraceOptions {
        rays,
        max_depth: depth,
        diffuse,
        scattering_coefficient: if diffuse { 0.3 } else { 0.0 },
        ..Default::default()
    }
}

/// With edge diffraction too: LOS, reflection, transmission and first-order diffraction.
fn diffraction_options(rays: u32, depth: u32) -> TraceOptions {
    TraceOptions {
        diffraction: true,
        ..map_options(rays, depth, false)
    }
}

/// The device map against the host twin's: to the bit (the same integer sums) where the rays
/// follow specular paths, whose only transcendental functions are the lattice's; within a
/// tolerance where diffuse directions or the UTD call the device's libm, whose last bits are
/// not glibc's. Each case three times, twice on a resident scene, the same bits each time.
#[test]
fn device_maps_are_the_host_maps() {
    let Some(gpu) = gpu() else { return };
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let plane = default_plane(&scene, 4.0, 1.5);
    let street_tx = DVec3::new(-60.0, -56.0, 12.0);
    let mut cases = vec![
        (
            "street grid",
            map_inputs(&scene, street_tx, &plane, 100_000, 3),
            true,
        ),
        (
            "street grid, diffuse",
            map_inputs_with(&scene, street_tx, &plane, &map_options(100_000, 3, true)),
            false,
        ),
        (
            "street grid, directive lobe",
            map_inputs_with(
                &scene,
                street_tx,
                &plane,
                &TraceOptions {
                    scattering_pattern:
                        kodama_nodes::rf::scattering::ScatteringPattern::Directive { alpha_r: 4 },
                    ..map_options(100_000, 3, true)
                },
            ),
            false,
        ),
        (
            "street grid, rolling surface",
            map_inputs_with(
                &scene,
                street_tx,
                &gpu_common::rolling_surface(),
                &map_options(100_000, 3, true),
            ),
            false,
        ),
        (
            "street grid, diffraction",
            map_inputs_with(&scene, street_tx, &plane, &diffraction_options(100_000, 3)),
            false,
        ),
        (
            "street grid, TR 38.901 sector, diffraction",
            MapInputs::new(
                &scene,
                street_tx,
                &kodama_nodes::rf::antenna::Antenna::parse("tr38901:130:6").unwrap(),
                &plane,
                &diffraction_options(100_000, 3),
                3.5e9,
            )
            .unwrap(),
            false,
        ),
        (
            "street grid, rolling surface, diffraction",
            map_inputs_with(
                &scene,
                street_tx,
                &gpu_common::rolling_surface(),
                &diffraction_options(100_000, 3),
            ),
            false,
        ),
    ];
    let munich = munich_xml().map(|xml| gpu_common::munich_rf(&xml));
    if let Some(m) = &munich {
        let plane = default_plane(m, 5.0, 1.5);
        let tx = DVec3::new(8.5, 21.0, 27.0);
        cases.push(("munich", map_inputs(m, tx, &plane, 100_000, 3), true));
        cases.push((
            "munich, diffuse, depth 12",
            map_inputs_with(m, tx, &plane, &map_options(100_000, 12, true)),
            false,
        ));
        cases.push((
            "munich, diffraction",
            map_inputs_with(m, tx, &plane, &diffraction_options(100_000, 3)),
            false,
        ));
    }
    let bits = |r: &[f32]| r.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for (name, inputs, exact) in cases {
        let host = host_radio_map(&inputs);
        let (a, _) = gpu.radio_map(&inputs).unwrap();
        // Twice more on one resident scene.
        let dev = gpu.upload_scene(&inputs.scene).unwrap();
        let (b, _) = gpu.map(&dev, &inputs.map).unwrap();
        let (c, _) = gpu.map(&dev, &inputs.map).unwrap();
        assert_eq!(
            bits(&a.data.0),
            bits(&b.data.0),
            "{name}: two device maps differ"
        );
        assert_eq!(
            bits(&b.data.0),
            bits(&c.data.0),
            "{name}: two maps of a resident scene differ"
        );
        let reached = a.data.0.iter().filter(|v| **v > 0.0).count();
        if exact {
            assert_eq!(
                bits(&a.data.0),
                bits(&host.data.0),
                "{name}: device map != host map"
            );
            println!(
                "{name}: device map = host map to the bit, thrice, twice on a resident scene \
                 ({reached} cells reached)"
            );
        } else {
            let (both, only, median, _, max) = gpu_common::compare_maps(&a.data.0, &host.data.0);
            let same = bits(&a.data.0) == bits(&host.data.0);
            println!(
                "{name}: device map against host map: {both} cells both, {only} one only, |dB| \
                 median {median:.2e}, max {max:.2e}, same bits {same}; thrice the same bits"
            );
            assert!(
                only * 1000 <= both,
                "{name}: {only} cells reached by one map only"
            );
            assert!(median <= 1e-3, "{name}: median |difference| {median} dB");
        }
    }
}

/// Munich maps on the device against `radio_map` on every CPU core: 10^6 and 10^7 rays at
/// depth 3 and 5, 5 m cells at 1.5 m, tx (8.5, 21, 27), 3.5 GHz. The scene is uploaded once
/// (its time printed first); each map is then a warm call on the resident scene (the PTX JIT
/// done before; the BVH built on the CPU, as Sionna RT is timed warm). Prints a markdown table.
#[test]
#[ignore = "timing on a GPU machine: scripts/gpu_device_check.sh"]
fn device_map_speed_on_munich() {
    let Some(gpu) = gpu() else { return };
    let Some(xml) = munich_xml() else { return };
    let scene = gpu_common::munich_rf(&xml);
    let plane = default_plane(&scene, 5.0, 1.5);
    let tx = DVec3::new(8.5, 21.0, 27.0);
    // Warm-up: the driver's JIT of the PTX, caches.
    gpu.radio_map(&map_inputs(&scene, tx, &plane, 10_000, 3))
        .unwrap();
    let map_scene = MapScene::new(&scene).unwrap();
    let clock = Instant::now();
    let dev = gpu.upload_scene(&map_scene).unwrap();
    let upload_s = clock.elapsed().as_secs_f64();
    println!(
        "\nscene upload (once; BVH nodes and packets, triangles, materials, slab table; {:.1} MB): \
         {upload_s:.4} s",
        map_scene.bytes() as f64 / 1e6
    );
    println!(
        "GPU call s: the whole warm call on the resident scene, from the call to the raster \
         back (scalars up, buffers allocated and zeroed, patch order on the device, kernel, \
         cells back, raster); GPU kernel+readback s: the map kernel, launch to completion, and \
         the cells back; both the faster of two runs. M rays/s and speed-up are by the call."
    );
    println!(
        "\n| device | rays | depth | GPU call s | GPU kernel+readback s | GPU M rays/s | \
         CPU map s ({} threads) | speed-up | cells both | cells one only | median abs dB diff | \
         max abs dB diff | GPU run-to-run |",
        rayon::current_num_threads()
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    // The rows, the paper's settings (depth 12 with diffuse reflection, S 0.3), then
    // first-order diffraction at depth 3 (Sionna RT CUDA: 0.042 s at 10^6 rays on an H100).
    // (rays, depth, diffuse, diffraction)
    let rows = [
        (1_000_000u32, 3u32, false, false),
        (1_000_000, 5, false, false),
        (10_000_000, 3, false, false),
        (10_000_000, 5, false, false),
        (1_000_000, 12, true, false),
        (10_000_000, 12, true, false),
        (1_000_000, 3, false, true),
        (10_000_000, 3, false, true),
    ];
    for (n, depth, diffuse, diffraction) in rows {
        let opt = TraceOptions {
            diffraction,
            ..map_options(n, depth, diffuse)
        };
        let params = MapParams::new(&scene, tx, &Antenna::default(), &plane, &opt, 3.5e9).unwrap();
        let (a, t) = gpu.map(&dev, &params).unwrap();
        let (b, t2) = gpu.map(&dev, &params).unwrap();
        let call_s = t.call.min(t2.call);
        let kernel_s = t.kernel.min(t2.kernel);
        let same = a
            .data
            .0
            .iter()
            .zip(&b.data.0)
            .all(|(x, y)| x.to_bits() == y.to_bits());
        let clock = Instant::now();
        let cpu = radio_map(&scene, tx, &Antenna::default(), &plane, &opt, 3.5e9);
        let cpu_s = clock.elapsed().as_secs_f64();
        let (both, only, median, _, max) = gpu_common::compare_maps(&a.data.0, &cpu.data.0);
        let depth = format!(
            "{depth}{}{}",
            if diffuse { " + diffuse" } else { "" },
            if diffraction { " + diffraction" } else { "" }
        );
        println!(
            "| {} | {n} | {depth} | {call_s:.4} | {kernel_s:.4} | {:.0} | {cpu_s:.4} | \
                 {:.1}x | {both} | {only} | {median:.2e} | {max:.2e} | {same} |",
            gpu.name(),
            n as f64 / call_s / 1e6,
            cpu_s / call_s
        );
        assert!(same, "two device maps differ");
    }
}

use kodama_nodes::rf::gpu::{SearchParams, host_reflection_sequences};
use kodama_nodes::rf::sequences::reflection_sequences;

/// The device's sequence search against the CPU's and the host twin's, as sets (sorted), twice on
/// one resident scene: the street grid deep with transmission, a search that outgrows its first
/// set, and munich.
#[test]
fn device_sequences_are_the_cpus() {
    let Some(gpu) = gpu() else { return };
    let grid = || RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let mut cases = vec![
        ("street grid, depth 6", grid(), tx, 20_000u32, 6u32),
        ("street grid, 300 rays, depth 9", grid(), tx, 300, 9),
    ];
    if let Some(xml) = munich_xml() {
        let munich = gpu_common::munich_rf(&xml);
        cases.push((
            "munich, depth 5",
            munich,
            DVec3::new(8.5, 21.0, 27.0),
            100_000,
            5,
        ));
    }
    for (name, scene, tx, rays, depth) in cases {
        let opt = TraceOptions {
            rays,
            max_depth: depth,
            ..TraceOptions::default()
        };
        let map_scene = MapScene::new(&scene).unwrap();
        let dev = gpu.upload_scene(&map_scene).unwrap();
        let params = SearchParams::new(tx, &opt).unwrap();
        let (a, t) = gpu.reflection_sequences(&dev, &params).unwrap();
        let (b, _) = gpu.reflection_sequences(&dev, &params).unwrap();
        let host = host_reflection_sequences(&map_scene, &params).unwrap();
        let cpu = reflection_sequences(&scene, tx, &opt);
        println!(
            "{name}: {} sequences, {} kernel run(s), device = host twin = CPU",
            a.len(),
            t.tries
        );
        assert!(a == cpu, "{name}: device and CPU sequences differ");
        assert!(b == a, "{name}: two device searches differ");
        assert!(host == cpu, "{name}: host twin and CPU sequences differ");
    }
}

/// The sequence search on munich from tx (8.5, 21, 27) on the device (warm, on a resident scene)
/// against `reflection_sequences` on every CPU core, with transmission: the part of a link
/// trace that grows with the rays and the depth (BENCHMARKS.md, "The paper's solver settings on
/// links"). Prints a markdown table.
#[test]
#[ignore = "timing on a GPU machine: scripts/gpu_device_check.sh"]
fn device_link_search_speed_on_munich() {
    let Some(gpu) = gpu() else { return };
    let Some(xml) = munich_xml() else { return };
    let scene = gpu_common::munich_rf(&xml);
    let tx = DVec3::new(8.5, 21.0, 27.0);
    let map_scene = MapScene::new(&scene).unwrap();
    let dev = gpu.upload_scene(&map_scene).unwrap();
    let warm = SearchParams::new(
        tx,
        &TraceOptions {
            rays: 10_000,
            ..TraceOptions::default()
        },
    );
    gpu.reflection_sequences(&dev, &warm.unwrap()).unwrap();
    println!(
        "\nGPU call s: the warm call on the resident scene (patch order, every kernel run, the \
         sequences back and sorted), the faster of two; CPU: reflection_sequences on {} threads, \
         one run (none where marked: too long for one device session).",
        rayon::current_num_threads()
    );
    println!(
        "\n| device | rays | depth | sequences | GPU call s | GPU kernel s | kernel runs | CPU s | \
         speed-up | same set |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let rows = [
        (100_000u32, 5u32, true),
        (100_000, 9, true),
        (100_000, 12, true),
        (1_000_000, 5, true),
        // Past this the host's copy and sort of the set (tens of millions of sequences) would
        // outlast a device session.
        (1_000_000, 9, false),
    ];
    for (rays, depth, with_cpu) in rows {
        let opt = TraceOptions {
            rays,
            max_depth: depth,
            ..TraceOptions::default()
        };
        let params = SearchParams::new(tx, &opt).unwrap();
        let (a, t) = match gpu.reflection_sequences(&dev, &params) {
            Ok(r) => r,
            Err(e) => {
                println!("| {} | {rays} | {depth} | {e} | | | | | | |", gpu.name());
                continue;
            }
        };
        let (b, t2) = gpu.reflection_sequences(&dev, &params).unwrap();
        assert!(a == b, "two device searches differ");
        let (cpu_s, same) = if with_cpu {
            let clock = Instant::now();
            let cpu = reflection_sequences(&scene, tx, &opt);
            (
                format!("{:.3}", clock.elapsed().as_secs_f64()),
                format!("{}", cpu == a),
            )
        } else {
            ("-".into(), "-".into())
        };
        let call = t.call.min(t2.call);
        let speedup = cpu_s
            .parse::<f64>()
            .map(|c| format!("{:.0}x", c / call))
            .unwrap_or_else(|_| "-".into());
        println!(
            "| {} | {rays} | {depth} | {} | {call:.4} | {:.4} | {} | {cpu_s} | {speedup} | {same} |",
            gpu.name(),
            a.len(),
            t.kernel.min(t2.kernel),
            t.tries
        );
        assert!(
            same != "false",
            "depth {depth}, {rays} rays: GPU and CPU sets differ"
        );
    }
}
