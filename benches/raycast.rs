//! Ray casting and radio-map throughput: closest-hit and any-hit rays/s per core on munich and on
//! a 1 km² synthetic city, and the munich radio map at 10^6 / 10^7 rays, depth 3 / 5, on 1 and 2
//! threads. Every figure is the best of `--n` runs (default 5): the machine is shared.
//!
//! `links` times the link tracer on munich: the sequence search alone
//! (`rf::sequences::reflection_sequences`, the part the GPU takes) and the whole trace of 21
//! links from the transmitter (receivers 1.5 m up on a spiral 30-190 m out), at `--rays` and
//! `--depth`, with transmission.
//!
//! `cargo bench --bench raycast -- [cast] [map] [links] [--n N] [--threads 1,2] [--rays 1e6,1e7]
//! [--depth 3,5] [--no-city] [--shuffle] [--patch-order] [--dump-rays FILE]` (both parts by
//! default; `--no-city` casts on munich only; `--shuffle` casts the closest-hit rays in a random
//! order, where consecutive rays share no path through the tree; `--patch-order` takes the
//! primary rays in the radio map's order, patches of neighbours on the lattice, each bounce's
//! rays in their parents' order, and casts them also as the map does, as packets where they run
//! side by side; `--dump-rays` writes munich's closest-hit rays, in the order cast, as
//! little-endian f32 rows of origin, direction and tmin, for `scripts/embree_rays_bench.py` to
//! cast with Embree). Needs ../shared/data (munich). Figures go in BENCHMARKS.md.

use std::path::PathBuf;
use std::time::Instant;

use glam::DVec3;
use kodama_nodes::artifact::Scene;
use kodama_nodes::artifact::TerrainModel;
use kodama_nodes::geom::raycast::SceneRays;
use kodama_nodes::io::sionna_xml::read_scene_with_thickness;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::fibonacci::{fibonacci_sphere, patch_order};
use kodama_nodes::rf::map_plane::default_plane;
use kodama_nodes::rf::path::TraceOptions;
use kodama_nodes::rf::paths::trace_links;
use kodama_nodes::rf::radiomap::radio_map;
use kodama_nodes::rf::scene::RfScene;
use kodama_nodes::rf::sequences::reflection_sequences;
use kodama_nodes::stage::Slot;
use kodama_nodes::synth::synth_city::{SynthCityParams, generate};
use kodama_nodes::synth::truth_scene::{TruthScene, TruthSceneParams};
use kodama_nodes::{Artifact, Ctx, Inputs, Site, Stage};
use rayon::prelude::*;

const TX: [f64; 3] = [8.5, 21.0, 27.0];

struct Args {
    cast: bool,
    map: bool,
    links: bool,
    n: usize,
    threads: Vec<usize>,
    rays: Vec<u32>,
    depth: Vec<u32>,
    city: bool,
    shuffle: bool,
    patch_order: bool,
    dump_rays: Option<PathBuf>,
}

fn list<T: std::str::FromStr>(s: &str) -> Vec<T> {
    s.split(',')
        .filter_map(|v| v.parse::<f64>().ok())
        .filter_map(|v| format!("{}", v as u64).parse().ok())
        .collect()
}

fn args() -> Args {
    let mut a = Args {
        cast: false,
        map: false,
        links: false,
        n: 5,
        threads: vec![1, 2],
        rays: vec![1_000_000, 10_000_000],
        depth: vec![3, 5],
        city: true,
        shuffle: false,
        patch_order: false,
        dump_rays: None,
    };
    let v: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < v.len() {
        let next = v.get(i + 1).cloned().unwrap_or_default();
        match v[i].as_str() {
            "cast" => a.cast = true,
            "map" => a.map = true,
            "links" => a.links = true,
            "--n" => (a.n, i) = (next.parse().unwrap_or(5), i + 1),
            "--threads" => (a.threads, i) = (list(&next), i + 1),
            "--rays" => (a.rays, i) = (list(&next), i + 1),
            "--depth" => (a.depth, i) = (list(&next), i + 1),
            "--no-city" => a.city = false,
            "--shuffle" => a.shuffle = true,
            "--patch-order" => a.patch_order = true,
            "--dump-rays" => (a.dump_rays, i) = (Some(PathBuf::from(&next)), i + 1),
            _ => {}
        }
        i += 1;
    }
    if !a.cast && !a.map && !a.links {
        (a.cast, a.map) = (true, true);
    }
    a
}

fn munich() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/sionna-scenes/munich/munich.xml")
}

fn best_of(n: usize, threads: usize, mut f: impl FnMut() + Send) -> f64 {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool");
    (0..n)
        .map(|_| {
            let t = Instant::now();
            pool.install(&mut f);
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// A ray to cast: origin, unit direction, tmin.
type Ray = ([f32; 3], [f32; 3], f32);

/// The radio map's kind of rays: a Fibonacci sphere from `tx` and its specular continuations
/// to `depth` bounces (about half the primary rays go to the sky), and shadow rays from every
/// first hit to a street-level point.
/// `patch` takes the primary rays in patches of neighbours ([`patch_order`]), as the radio map
/// does. Also returns where each bounce's rays start in the closest-hit list.
fn bounce_rays(
    rays: &SceneRays,
    tx: [f32; 3],
    n: u32,
    depth: u32,
    patch: bool,
) -> (Vec<Ray>, Vec<Ray>, Vec<usize>) {
    let mut all = Vec::new();
    let mut starts = Vec::new();
    let dirs: Vec<DVec3> = fibonacci_sphere(n).collect();
    let order = if patch {
        patch_order(n, 0, n)
    } else {
        (0..n).collect()
    };
    let mut live: Vec<Ray> = order
        .iter()
        .map(|&k| (tx, dirs[k as usize].as_vec3().to_array(), 0.0))
        .collect();
    let mut shadow = Vec::new();
    for level in 0..depth {
        starts.push(all.len());
        all.extend_from_slice(&live);
        let next: Vec<(Ray, Option<Ray>)> = live
            .par_iter()
            .filter_map(|&(o, d, tmin)| {
                let h = rays.cast(o, d, tmin, f32::INFINITY)?;
                let p = [0, 1, 2].map(|k| o[k] + d[k] * h.t);
                let n = h.normal;
                let dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
                let r = [0, 1, 2].map(|k| d[k] - 2.0 * dn * n[k]);
                let s = (level == 0).then(|| {
                    let to = [tx[0] + 60.0, tx[1] - 40.0, 1.5];
                    let v = [0, 1, 2].map(|k| to[k] - p[k]);
                    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                    (p, v.map(|c| c / l), l)
                });
                Some(((p, r, 1e-3), s))
            })
            .collect();
        live = next.iter().map(|r| r.0).collect();
        shadow.extend(next.iter().filter_map(|r| r.1));
    }
    (all, shadow, starts)
}

/// How many of `rs` hit something, each cast alone, in chunks over the thread pool.
fn hits_alone(rays: &SceneRays, rs: &[Ray]) -> usize {
    rs.par_chunks(4096)
        .map(|c| {
            c.iter()
                .filter(|(o, d, tmin)| rays.cast(*o, *d, *tmin, f32::INFINITY).is_some())
                .count()
        })
        .sum()
}

fn cast_case(name: &str, scene: &Scene, tx: [f32; 3], a: &Args) {
    let t = Instant::now();
    let rays = SceneRays::new(scene);
    let build = t.elapsed().as_secs_f64();
    let (mut closest, shadow, starts) = bounce_rays(&rays, tx, 1_000_000, 3, a.patch_order);
    println!(
        "{name}: {} triangles, wide BVH built in {:.0} ms ({}), {} closest-hit rays (10^6 \
         from the tx + specular to depth 3{}), {} shadow rays",
        rays.len(),
        build * 1e3,
        if rays.uses_simd() { "AVX2" } else { "scalar" },
        closest.len(),
        if a.patch_order {
            ", in patch order"
        } else {
            ""
        },
        shadow.len()
    );
    if let Some(path) = a.dump_rays.as_ref().filter(|_| name == "munich") {
        let bytes: Vec<u8> = closest
            .iter()
            .flat_map(|(o, d, tmin)| {
                o.iter()
                    .chain(d)
                    .chain([tmin])
                    .flat_map(|v| v.to_le_bytes())
            })
            .collect();
        if let Err(e) = std::fs::write(path, bytes) {
            eprintln!("error: writing the rays to {}: {e}", path.display());
            std::process::exit(2);
        }
        println!("  {} rays written to {}", closest.len(), path.display());
    }
    if a.shuffle {
        // Fisher-Yates from a fixed xorshift: the same order every run.
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for i in (1..closest.len()).rev() {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            closest.swap(i, (x % (i as u64 + 1)) as usize);
        }
        println!("  closest-hit rays cast in a random order");
    }
    for &threads in &a.threads {
        let secs = best_of(a.n, threads, || {
            std::hint::black_box(hits_alone(&rays, &closest));
        });
        let any = best_of(a.n, threads, || {
            let hits: usize = shadow
                .par_chunks(4096)
                .map(|c| {
                    c.iter()
                        .filter(|(o, d, l)| rays.occluded(*o, *d, 1e-3, *l - 1e-3))
                        .count()
                })
                .sum();
            std::hint::black_box(hits);
        });
        let per_core = |n: usize, s: f64| n as f64 / s / 1e6 / threads as f64;
        if a.patch_order && !a.shuffle {
            // As the map casts: each bounce's rays together (one tmin), packets where narrow.
            let levels: Vec<(usize, usize)> = starts
                .iter()
                .zip(starts.iter().skip(1).chain([&closest.len()]))
                .map(|(&s, &e)| (s, e))
                .collect();
            // Each level's rays as the coherent caster takes them, built once, outside the timing.
            let level_rays: Vec<(Vec<([f32; 3], [f32; 3])>, f32)> = levels
                .iter()
                .map(|&(s, e)| {
                    (
                        closest[s..e].iter().map(|r| (r.0, r.1)).collect(),
                        closest[s].2,
                    )
                })
                .collect();
            let cast_level = |(level, tmin): &(Vec<([f32; 3], [f32; 3])>, f32)| -> usize {
                level
                    .par_chunks(4096)
                    .map(|c| {
                        let mut hits = 0;
                        rays.cast_coherent_each(c, *tmin, f32::INFINITY, |_, h| {
                            hits += h.is_some() as usize
                        });
                        hits
                    })
                    .sum()
            };
            let secs: Vec<f64> = level_rays
                .iter()
                .map(|l| {
                    best_of(a.n, threads, || {
                        std::hint::black_box(cast_level(l));
                    })
                })
                .collect();
            let hits: usize = level_rays.iter().map(cast_level).sum();
            assert_eq!(
                hits,
                hits_alone(&rays, &closest),
                "packets and lone rays hit differently"
            );
            let total: f64 = secs.iter().sum();
            let bounces = closest.len() - levels[0].1;
            let lone = |range: &[Ray]| {
                best_of(a.n, threads, || {
                    std::hint::black_box(hits_alone(&rays, range));
                })
            };
            let (lone_primary, lone_bounces) =
                (lone(&closest[..levels[0].1]), lone(&closest[levels[0].1..]));
            println!(
                "  {threads} thread(s): closest-hit as packets where narrow {total:.3} s = {:.1} M \
                 rays/s per core ({hits} hits, as one by one); the primary rays {:.1} (one by \
                 one {:.1}), the bounces' {:.1} (one by one {:.1})",
                per_core(closest.len(), total),
                per_core(levels[0].1, secs[0]),
                per_core(levels[0].1, lone_primary),
                per_core(bounces, total - secs[0]),
                per_core(bounces, lone_bounces),
            );
        }
        println!(
            "  {threads} thread(s): closest-hit {:.3} s = {:.1} M rays/s per core; any-hit {:.3} s \
             = {:.1} M rays/s per core",
            secs,
            per_core(closest.len(), secs),
            any,
            per_core(shadow.len(), any)
        );
    }
    camera_case(&rays, tx, a);
}

/// A camera's rays: the six faces of a cube panorama of `size` x `size` pixels from `at`, each
/// face's pixels in 8 x 8 tiles (the order views, orthophotos and the fusion cast in).
fn panorama_rays(at: [f32; 3], size: u32) -> Vec<([f32; 3], [f32; 3])> {
    let order = kodama_nodes::geom::raycast::tile_order(size, size);
    let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
        ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
        ([-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]),
        ([0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        ([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
    ];
    let mut out = Vec::with_capacity(6 * order.len());
    for (f, r, u) in faces {
        for &p in &order {
            let x = ((p % size) as f32 + 0.5) / size as f32 * 2.0 - 1.0;
            let y = 1.0 - ((p / size) as f32 + 0.5) / size as f32 * 2.0;
            let d = [0, 1, 2].map(|k| f[k] + x * r[k] + y * u[k]);
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            out.push((at, d.map(|c| c / l)));
        }
    }
    out
}

/// Closest hits of camera rays one by one and as packets ([`SceneRays::cast_coherent`]).
fn camera_case(rays: &SceneRays, at: [f32; 3], a: &Args) {
    for size in [512, 128, 32] {
        camera_size_case(rays, at, size, a);
    }
}

fn camera_size_case(rays: &SceneRays, at: [f32; 3], size: u32, a: &Args) {
    let mut camera = panorama_rays(at, size);
    // About 1.5 M rays whatever the size.
    let copies = (1_572_864 / camera.len()).max(1);
    camera = camera.repeat(copies);
    for &threads in &a.threads {
        // Alternated run by run: this machine's speed drifts for seconds at a time, and the
        // ratio is what matters.
        let (mut single, mut packets) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..a.n {
            single = single.min(best_of(1, threads, || {
                let hits: usize = camera
                    .par_chunks(4096)
                    .map(|c| {
                        c.iter()
                            .filter(|(o, d)| rays.cast(*o, *d, 1e-3, f32::INFINITY).is_some())
                            .count()
                    })
                    .sum();
                std::hint::black_box(hits);
            }));
            packets = packets.min(best_of(1, threads, || {
                let hits: usize = camera
                    .par_chunks(4096)
                    .map(|c| {
                        rays.cast_coherent(c, 1e-3, f32::INFINITY)
                            .iter()
                            .filter(|h| h.is_some())
                            .count()
                    })
                    .sum();
                std::hint::black_box(hits);
            }));
        }
        let per_core = |s: f64| camera.len() as f64 / s / 1e6 / threads as f64;
        println!(
            "  {threads} thread(s), camera rays ({} from a cube panorama of {size} x {size} per face \
             at {at:?}, 8 x 8 tiles of {:.1} degrees): one by one {:.1}, packets {:.1} M rays/s \
             per core",
            camera.len(),
            8.0 * 90.0 / size as f64,
            per_core(single),
            per_core(packets)
        );
    }
}

fn synthetic_city() -> Scene {
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let ctx = Ctx::new(&site, &[]);
    let size = (1000.0, 1000.0);
    let city = generate(&SynthCityParams {
        size_m: size,
        blocks: (10, 10),
        terrain: TerrainModel {
            seed: 7,
            size_m: size,
            ..Default::default()
        },
        ..Default::default()
    });
    let out = TruthScene::run(
        &TruthSceneParams::default(),
        &Inputs::new().with("city", Slot::One(std::sync::Arc::new(Artifact::City(city)))),
        &ctx,
    )
    .expect("truth scene");
    out
}

fn main() {
    let a = args();
    let xml = munich();
    let (scene, thickness) = read_scene_with_thickness(&xml).expect("munich (../shared/data)");
    let tx = TX.map(|c| c as f32);
    // The scene as Sionna RT traces it: its materials at 3.5 GHz, each with the file's thickness.
    let radio_scene = || {
        thickness.iter().fold(
            RfScene::new(&scene, 3.5e9, false).expect("munich materials"),
            |rf, (&m, &d)| rf.with_thickness(m, d),
        )
    };
    if a.cast {
        cast_case("munich", &scene, tx, &a);
    }
    if a.cast && a.city {
        let city = synthetic_city();
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for o in &city.objects {
            for p in o.mesh.positions.iter() {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        let tx = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, lo[2] + 45.0];
        cast_case("synthetic city 1 km x 1 km", &city, tx, &a);
    }
    if a.map {
        let rf = radio_scene();
        let plane = default_plane(&rf, 5.0, 1.5);
        println!(
            "munich radio map: tx {TX:?}, 3.5 GHz, {} x {} cells of 5 m at 1.5 m, LOS + specular + \
             transmission",
            plane.grid.width, plane.grid.height
        );
        for &rays in &a.rays {
            for &depth in &a.depth {
                let opt = TraceOptions {
                    max_depth: depth,
                    rays,
                    ..Default::default()
                };
                let mut line = format!("  {rays:>9} rays, depth {depth}:");
                for &threads in &a.threads {
                    let secs = best_of(a.n, threads, || {
                        let map = radio_map(
                            &rf,
                            DVec3::from(TX),
                            &Antenna::default(),
                            &plane,
                            &opt,
                            3.5e9,
                        );
                        std::hint::black_box(map);
                    });
                    line += &format!(
                        "  {threads} thread(s) {secs:.3} s ({:.2} M rays/s)",
                        rays as f64 / secs / 1e6
                    );
                }
                println!("{line}");
            }
        }
    }
    if a.links {
        let rf = radio_scene();
        links_case(&rf, &a);
    }
}

/// The sequence search and the whole link trace, best of `a.n` each, at every thread count.
fn links_case(rf: &RfScene, a: &Args) {
    let links: Vec<([f64; 3], [f64; 3])> = (0..21)
        .map(|i| {
            let angle = std::f64::consts::TAU * i as f64 / 21.0;
            let r = 30.0 + 8.0 * i as f64;
            (TX, [TX[0] + r * angle.cos(), TX[1] + r * angle.sin(), 1.5])
        })
        .collect();
    println!("munich links: tx {TX:?}, 3.5 GHz, 21 receivers, LOS + specular + transmission");
    let iso = Antenna::default();
    for &rays in &a.rays {
        for &depth in &a.depth {
            let opt = TraceOptions {
                max_depth: depth,
                rays,
                ..Default::default()
            };
            let found = reflection_sequences(rf, DVec3::from(TX), &opt).len();
            let mut line = format!("  {rays:>9} rays, depth {depth}, {found} sequences:");
            for &threads in &a.threads {
                let search = best_of(a.n, threads, || {
                    std::hint::black_box(reflection_sequences(rf, DVec3::from(TX), &opt));
                });
                let trace = best_of(a.n, threads, || {
                    std::hint::black_box(trace_links(rf, &links, &iso, &iso, &opt, 3.5e9));
                });
                line += &format!(
                    "  {threads} thread(s): search {search:.3} s of the trace's {trace:.3} s"
                );
            }
            println!("{line}");
        }
    }
}
