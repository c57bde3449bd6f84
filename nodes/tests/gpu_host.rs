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

use glam::DVec3;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::gpu::{MapInputs, host_radio_map};
use kodama_nodes::rf::map_plane::{MapPlane, default_plane};
use kodama_nodes::rf::path::TraceOptions;
use kodama_nodes::rf::radiomap::radio_map;
use kodama_nodes::rf::scene::RfScene;
use kodama_nodes::rf::test_scenes::street_plane;

/// The host twin's map against `radio_map`; returns the comparison and prints it. Tolerance:
/// the launch directions (closed form here, a rotation on the CPU: 1e-8 apart), the slab table's
/// sampling and libm's last bits differ, so a ray grazing an edge may land elsewhere; the cells
/// must be the same but for a handful, and the median cell within 0.01 dB.
fn check_map(name: &str, scene: &RfScene, tx: DVec3, plane: &MapPlane, rays: u32) {
    let opt = TraceOptions {
        rays,
        max_depth: 3,
        ..Default::default()
    };
    check_map_with(name, scene, tx, plane, &opt);
}

/// Diffuse reflection as the paper traces it: roughness 0.3, Lambertian, with reflection and
/// transmission, depth 3.
fn diffuse(rays: u32) -> TraceOptions {
    TraceOptions {
        rays,
        max_depth: 3,
        diffuse: true,
        scattering_coefficient: 0.3,
        ..Default::default()
    }
}

fn check_map_with(name: &str, scene: &RfScene, tx: DVec3, plane: &MapPlane, opt: &TraceOptions) {
    check_map_from(name, scene, (tx, &Antenna::default()), plane, opt);
}

/// [`check_map_with`] from a transmitter with its own antenna.
fn check_map_from(
    name: &str,
    scene: &RfScene,
    (tx, antenna): (DVec3, &Antenna),
    plane: &MapPlane,
    opt: &TraceOptions,
) {
    let (rays, opt) = (opt.rays, opt.clone());
    let cpu = radio_map(scene, tx, antenna, plane, &opt, 3.5e9);
    let inputs = MapInputs::new(scene, tx, antenna, plane, &opt, 3.5e9).unwrap();
    let host = host_radio_map(&inputs);
    let again = host_radio_map(&inputs);
    assert_eq!(host.data.0, again.data.0, "{name}: two host maps differ");
    let (both, only, median, p99, max) = gpu_common::compare_maps(&host.data.0, &cpu.data.0);
    println!(
        "{name}: {rays} rays, depth {}: {both} cells both reach, {only} one only; |dB| median \
         {median:.2e}, p99 {p99:.2e}, max {max:.2e}",
        opt.max_depth
    );
    assert!(both > 100, "{name}: only {both} cells reached");
    assert!(
        only * 1000 <= both,
        "{name}: {only} cells reached by one map only"
    );
    assert!(median <= 0.01, "{name}: median |difference| {median} dB");
}

#[test]
fn host_kernel_maps_street_grid_as_the_cpu() {
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let plane = street_plane();
    check_map(
        "street grid",
        &scene,
        DVec3::new(-60.0, -56.0, 12.0),
        &plane,
        100_000,
    );
}

#[test]
fn host_kernel_maps_diffuse_reflection_as_the_cpu() {
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let plane = street_plane();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    check_map_with(
        "street grid, diffuse",
        &scene,
        tx,
        &plane,
        &diffuse(100_000),
    );
    let Some(xml) = munich_xml() else { return };
    let scene = gpu_common::munich_rf(&xml);
    let plane = default_plane(&scene, 5.0, 1.5);
    let tx = DVec3::new(8.5, 21.0, 27.0);
    check_map_with("munich, diffuse", &scene, tx, &plane, &diffuse(100_000));
}

/// The street grid with canopies: one round the transmitter (its rays start inside), two that
/// overlap (a ray in both counts its metres once), and a crown over a street.
fn street_grid_with_canopies() -> RfScene {
    use kodama_nodes::artifact::{Material, ObjectClass, SceneObject};
    use kodama_nodes::geom::mesh_build::cuboid;
    let mut scene = street_grid();
    let crowns = [
        ([-60.0, -56.0], [12.0, 10.0, 8.0], 6.0),
        ([-45.0, -30.0], [14.0, 10.0, 10.0], 2.0),
        ([-38.0, -26.0], [12.0, 12.0, 9.0], 4.0),
        ([0.0, -42.0], [30.0, 6.0, 6.0], 5.0),
    ];
    for (k, (c, size, z0)) in crowns.into_iter().enumerate() {
        scene.objects.push(SceneObject {
            id: format!("canopy{k}"),
            class: ObjectClass::Vegetation,
            mesh: cuboid(c, size, 0.0, z0, Material::Foliage),
        });
    }
    RfScene::new(&scene, 3.5e9, false).unwrap()
}

/// Foliage on the GPU as on the CPU: the linear law and P.833's saturating one, with diffuse
/// reflection, rays starting inside a canopy.
#[test]
fn host_kernel_maps_foliage_as_the_cpu() {
    use kodama_nodes::rf::foliage::FoliageLaw;
    let scene = street_grid_with_canopies();
    assert!(scene.has_foliage());
    let plane = street_plane();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let bare = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let without = radio_map(
        &bare,
        tx,
        &Antenna::default(),
        &plane,
        &diffuse(100_000),
        3.5e9,
    );
    for (name, law) in [("linear", FoliageLaw::Linear), ("P.833", FoliageLaw::P833)] {
        let opt = TraceOptions {
            foliage_law: law,
            ..diffuse(100_000)
        };
        let name = format!("street grid, canopies ({name})");
        check_map_with(&name, &scene, tx, &plane, &opt);
        // The canopies must cost something for the comparison to test them.
        let with = radio_map(&scene, tx, &Antenna::default(), &plane, &opt, 3.5e9);
        let mut loss: Vec<f64> = (with.data.0.iter().zip(&without.data.0))
            .filter(|(a, b)| **a > 0.0 && **b > 0.0)
            .map(|(a, b)| 10.0 * (*b as f64 / *a as f64).log10())
            .collect();
        loss.sort_by(f64::total_cmp);
        let median = loss[loss.len() / 2];
        println!("{name}: the canopies take a median {median:.2} dB from a cell");
        assert!(median > 1.0, "{name}: canopies cost only {median} dB");
    }
}

/// A map on a surface following rolling terrain (tilted patches, rays crossing it more than
/// once) as on the CPU, with diffuse reflection.
#[test]
fn host_kernel_maps_a_terrain_following_surface_as_the_cpu() {
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let plane = gpu_common::rolling_surface();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    check_map_with(
        "street grid, rolling surface",
        &scene,
        tx,
        &plane,
        &diffuse(100_000),
    );
}

/// A directive diffuse lobe (Sionna's ((1 + cos ψ) / 2)^α_R, α_R 4) on the GPU as on the CPU,
/// and unlike the Lambertian map (else this would test nothing).
#[test]
fn host_kernel_maps_a_directive_pattern_as_the_cpu() {
    use kodama_nodes::rf::scattering::ScatteringPattern;
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let plane = street_plane();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let opt = TraceOptions {
        scattering_pattern: ScatteringPattern::Directive { alpha_r: 4 },
        ..diffuse(100_000)
    };
    check_map_with("street grid, directive lobe", &scene, tx, &plane, &opt);
    let map = |o: &TraceOptions| {
        host_radio_map(&MapInputs::new(&scene, tx, &Antenna::default(), &plane, o, 3.5e9).unwrap())
    };
    let (directive, lambert) = (map(&opt), map(&diffuse(100_000)));
    let (_, _, median, _, max) = gpu_common::compare_maps(&directive.data.0, &lambert.data.0);
    println!("directive against Lambertian: |dB| median {median:.3}, max {max:.2}");
    assert!(max > 1.0, "the directive lobe changed no cell by 1 dB");
}

#[test]
fn host_kernel_maps_munich_as_the_cpu() {
    let Some(xml) = munich_xml() else { return };
    let scene = gpu_common::munich_rf(&xml);
    let plane = default_plane(&scene, 5.0, 1.5);
    check_map(
        "munich",
        &scene,
        DVec3::new(8.5, 21.0, 27.0),
        &plane,
        100_000,
    );
}

use kodama_nodes::rf::fibonacci::patch_order;
use kodama_nodes::rf::gpu::{ORDER_CHUNK, host_patch_order};

/// The order kernel's host twin is `patch_order`, ray for ray: whole chunks at the start, middle
/// and end of lattices of several sizes, the last partial chunk, chunks shorter than a patch,
/// the chunk lengths `radio_map` uses, and every chunk of one lattice.
#[test]
fn host_order_is_patch_order() {
    let mut cases = Vec::new();
    for n in [
        0u32, 1, 2, 64, 65, 1000, 65_536, 65_537, 100_000, 1_000_000, 10_000_000, 12_345_678,
    ] {
        let last = n.saturating_sub(1) / ORDER_CHUNK * ORDER_CHUNK;
        for start in [0, n / 2 / ORDER_CHUNK * ORDER_CHUNK, last] {
            cases.push((n, start, ORDER_CHUNK));
        }
    }
    for (n, len) in [
        (1_000_000u32, 14_208u32),
        (10_000_000, 44_864),
        (100_000, 8192),
    ] {
        for start in [0, n / 3, n / 2 - len / 2, n - len, n - 100] {
            cases.push((n, start, len));
        }
    }
    let n = 1_000_000u32;
    for start in (0..n).step_by(ORDER_CHUNK as usize) {
        cases.push((n, start, ORDER_CHUNK));
    }
    for &(n, start, len) in &cases {
        let want = patch_order(n, start, len);
        let got = host_patch_order(n, start, len);
        assert_eq!(got, want, "n {n} start {start} len {len}");
    }
    println!("{} chunks: host order = patch_order", cases.len());
}

use kodama_nodes::rf::gpu::{MapScene, SearchParams, host_reflection_sequences};
use kodama_nodes::rf::sequences::reflection_sequences;

/// The search kernel's host twin against the CPU's sequence search: the same sorted set of
/// sequences, which the image method then solves alike.
fn check_sequences(name: &str, scene: &RfScene, tx: DVec3, opt: &TraceOptions) -> usize {
    let want = reflection_sequences(scene, tx, opt);
    let inputs = MapScene::new(scene).unwrap();
    let params = SearchParams::new(tx, opt).unwrap();
    let got = host_reflection_sequences(&inputs, &params).unwrap();
    let longest = want.iter().map(Vec::len).max().unwrap_or(0);
    println!(
        "{name}: {} sequences (longest {longest}) from {} rays, depth {}",
        want.len(),
        opt.rays,
        opt.max_depth
    );
    assert_eq!(got.len(), want.len(), "{name}: how many sequences");
    assert!(got == want, "{name}: the sequences differ");
    want.len()
}

#[test]
fn host_kernel_finds_the_cpus_sequences() {
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let deep = TraceOptions {
        rays: 20_000,
        max_depth: 6,
        ..TraceOptions::default()
    };
    // Reflection and transmission both branch: the set is far larger than the rays.
    let n = check_sequences("street grid, depth 6", &scene, tx, &deep);
    assert!(n > 20_000, "only {n} sequences");
    let reflect_only = TraceOptions {
        transmission: false,
        ..deep.clone()
    };
    check_sequences("street grid, reflection only", &scene, tx, &reflect_only);
    // Canopies are passed through, round the transmitter too.
    check_sequences(
        "street grid, canopies",
        &street_grid_with_canopies(),
        tx,
        &deep,
    );
    let none = TraceOptions {
        reflection: false,
        ..deep
    };
    assert_eq!(check_sequences("no reflection", &scene, tx, &none), 0);
    let Some(xml) = munich_xml() else { return };
    let scene = gpu_common::munich_rf(&xml);
    let opt = TraceOptions {
        rays: 50_000,
        max_depth: 5,
        ..TraceOptions::default()
    };
    check_sequences("munich, depth 5", &scene, DVec3::new(8.5, 21.0, 27.0), &opt);
}

/// A set far smaller than what one chunk finds grows until it holds them all: here the first
/// guess (twice the rays, at least 4,096) is passed by a deep search of few rays.
#[test]
fn a_search_that_outgrows_its_set_runs_again() {
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let opt = TraceOptions {
        rays: 300,
        max_depth: 9,
        ..TraceOptions::default()
    };
    let n = check_sequences(
        "300 rays, depth 9",
        &scene,
        DVec3::new(-60.0, -56.0, 12.0),
        &opt,
    );
    // More than the first set holds, and all of them: the set grew.
    assert!(n > 4096, "only {n} sequences: the set never had to grow");
}

/// Past the kernel's 32 interactions the search is refused by name.
#[test]
fn the_search_kernel_refuses_more_than_32_interactions() {
    let opt = TraceOptions {
        max_depth: 33,
        ..TraceOptions::default()
    };
    let err = SearchParams::new(DVec3::ZERO, &opt)
        .err()
        .expect("depth 33 accepted");
    assert!(err.contains("at most 32"), "{err}");
}

/// First-order edge diffraction on the GPU as on the CPU, on the flat plane and a surface
/// following rolling terrain, with reflection and transmission: the diffracted samples must
/// reach cells the rays alone do not (else this would test nothing), and the maps agree as the
/// others do (the UTD's face factors come from the slab table here, exact on the CPU).
#[test]
fn host_kernel_maps_edge_diffraction_as_the_cpu() {
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let opt = TraceOptions {
        rays: 100_000,
        max_depth: 3,
        diffraction: true,
        ..Default::default()
    };
    let plane = street_plane();
    check_map_with("street grid, diffraction", &scene, tx, &plane, &opt);
    let without = TraceOptions {
        diffraction: false,
        ..opt.clone()
    };
    let antenna = Antenna::default();
    let run = |o: &TraceOptions| {
        host_radio_map(&MapInputs::new(&scene, tx, &antenna, &plane, o, 3.5e9).unwrap())
    };
    let (with, bare) = (run(&opt), run(&without));
    let gained = (with.data.0.iter().zip(&bare.data.0))
        .filter(|(a, b)| **a > 0.0 && **b == 0.0)
        .count();
    println!("street grid: diffraction reaches {gained} cells the rays do not");
    assert!(gained > 20, "diffraction reached only {gained} new cells");
    check_map_with(
        "street grid, rolling surface, diffraction",
        &scene,
        tx,
        &gpu_common::rolling_surface(),
        &opt,
    );
    let Some(xml) = munich_xml() else { return };
    let scene = gpu_common::munich_rf(&xml);
    let plane = default_plane(&scene, 5.0, 1.5);
    check_map_with(
        "munich, diffraction",
        &scene,
        DVec3::new(8.5, 21.0, 27.0),
        &plane,
        &opt,
    );
}

/// Diffraction with foliage is refused by name, not traced without the canopies' loss.
#[test]
fn the_map_kernel_refuses_diffraction_with_foliage() {
    let scene = street_grid_with_canopies();
    let opt = TraceOptions {
        diffraction: true,
        ..diffuse(1000)
    };
    let err = MapInputs::new(
        &scene,
        DVec3::new(-60.0, -56.0, 12.0),
        &Antenna::default(),
        &street_plane(),
        &opt,
        3.5e9,
    )
    .err()
    .expect("diffraction with foliage was accepted");
    assert!(
        err.contains("edge diffraction in a scene with foliage"),
        "{err}"
    );
}

use kodama_nodes::rf::gpu::host_occluded;

/// The any-hit kernel's host twin against `SceneRays::occluded`, ray for ray, on the cast test's
/// rays with finite ends (shadow rays: from the launch point to points across the scene) and
/// infinite ones.
#[test]
fn host_kernel_answers_any_hit_as_the_cpu() {
    let check = |name: &str, scene: &Scene, tx: [f32; 3], centre: [f32; 3], span: f32| {
        let v = vertices(scene);
        let mut rays = rays(tx, centre, span, 50_000, &v);
        // Every other ray ends part of the way: a shadow ray to a point before or past a wall.
        let mut s = 11u64;
        for (k, r) in rays.iter_mut().enumerate() {
            if k % 2 == 0 {
                s = kodama_nodes::rng::mix(s);
                r[7] = 1.0 + 150.0 * kodama_nodes::rng::unit(s) as f32;
            }
        }
        let cpu = SceneRays::new(scene);
        let tree = Tree::new(cpu.wide_bvh()).unwrap();
        let got = host_occluded(&tree, &rays);
        let mut blocked = 0;
        for (k, (r, g)) in rays.iter().zip(&got).enumerate() {
            let want = cpu.occluded([r[0], r[1], r[2]], [r[3], r[4], r[5]], r[6], r[7]);
            assert_eq!(*g, want, "{name}, ray {k}: {r:?}");
            blocked += want as usize;
        }
        println!(
            "{name}: {} rays, {blocked} blocked, all as the CPU",
            rays.len()
        );
        assert!(blocked > rays.len() / 10 && blocked < rays.len() * 9 / 10);
    };
    check(
        "street grid",
        &street_grid(),
        [-60.0, -56.0, 12.0],
        [0.0, 0.0, 10.0],
        200.0,
    );
    let Some(xml) = munich_xml() else { return };
    let scene = read_scene(&xml).unwrap();
    check("munich", &scene, [8.5, 21.0, 27.0], [0.0, 0.0, 20.0], 400.0);
}

/// Every antenna on the GPU as on the CPU: the TR 38.901 sector turned and tilted (with
/// diffraction, whose edges it lights too) and a horizontally polarised dipole; the sector
/// must shape the map for the comparison to test it.
#[test]
fn host_kernel_maps_antenna_patterns_as_the_cpu() {
    use kodama_nodes::rf::antenna::{Pattern, Polarization};
    let scene = RfScene::new(&street_grid(), 3.5e9, false).unwrap();
    let tx = DVec3::new(-60.0, -56.0, 12.0);
    let plane = street_plane();
    let sector = Antenna {
        pattern: Pattern::Tr38901,
        polarization: Polarization::V,
        azimuth_deg: 130.0,
        tilt_deg: 6.0,
    };
    let opt = TraceOptions {
        rays: 100_000,
        max_depth: 3,
        diffraction: true,
        ..Default::default()
    };
    check_map_from("street grid, sector", &scene, (tx, &sector), &plane, &opt);
    let dipole = Antenna {
        pattern: Pattern::Dipole,
        polarization: Polarization::H,
        ..Antenna::default()
    };
    check_map_from(
        "street grid, H dipole",
        &scene,
        (tx, &dipole),
        &plane,
        &diffuse(100_000),
    );
    // The sector's back lobe is 30 dB down: cells behind it lose power against the iso map.
    let map =
        |a: &Antenna| host_radio_map(&MapInputs::new(&scene, tx, a, &plane, &opt, 3.5e9).unwrap());
    let (s, iso) = (map(&sector), map(&Antenna::default()));
    let spread: Vec<f64> = (s.data.0.iter().zip(&iso.data.0))
        .filter(|(a, b)| **a > 0.0 && **b > 0.0)
        .map(|(a, b)| 10.0 * (*a as f64 / *b as f64).log10())
        .collect();
    let (lo, hi) = spread
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    println!("sector against iso: cells from {lo:.1} to {hi:.1} dB");
    assert!(
        hi - lo > 20.0,
        "the sector shapes the map by only {} dB",
        hi - lo
    );
}
