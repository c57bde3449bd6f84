//! What the GPU tests share: the street grid, the rays that exercise every branch of a cast,
//! and where munich is.
#![allow(dead_code)]

use kodama_nodes::artifact::Scene;
use kodama_nodes::rf::fibonacci::fibonacci_run;
use kodama_nodes::rf::gpu::GpuRay;
use kodama_nodes::rng::{mix, unit};

/// Sionna RT's munich scene: `KODAMA_MUNICH_XML` when set (the device script's carried copy),
/// else the shared data beside the repository; `None` when absent, which fails under CI=true.
pub fn munich_xml() -> Option<std::path::PathBuf> {
    let xml = std::env::var_os("KODAMA_MUNICH_XML")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../shared/data/sionna-scenes/munich/munich.xml")
        });
    if xml.exists() {
        return Some(xml);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "{} not found (CI needs the shared data)",
        xml.display()
    );
    println!("skipped: {} not found", xml.display());
    None
}

pub use kodama_nodes::rf::test_scenes::street_grid_scene as street_grid;

/// Rays that exercise every branch of the cast: the launch lattice from `tx` (as a map's first
/// segment), random origins and directions over a cube `span` wide around `centre`, rays along
/// the axes and in axis planes (zero and -0.0 direction components: the inverse's 1e-20 guard),
/// rays aimed at vertices (the watertight test's f64 edge tie-break), and finite tmax.
pub fn rays(
    tx: [f32; 3],
    centre: [f32; 3],
    span: f32,
    n: u32,
    vertices: &[[f32; 3]],
) -> Vec<GpuRay> {
    let mut out = Vec::new();
    for d in fibonacci_run(n, 0, n) {
        let d = d.as_vec3().to_array();
        out.push([tx[0], tx[1], tx[2], d[0], d[1], d[2], 1e-3, f32::INFINITY]);
    }
    let mut s = 7u64;
    let mut next = || {
        s = mix(s);
        unit(s) as f32
    };
    for k in 0..n {
        let o: [f32; 3] = std::array::from_fn(|a| centre[a] + (next() - 0.5) * span);
        let z = 2.0 * next() - 1.0;
        let phi = std::f32::consts::TAU * next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        let mut d = [r * phi.cos(), r * phi.sin(), z];
        match k % 8 {
            // An axis: two components zero, one of them negative zero.
            0 => {
                let a = (k / 8 % 3) as usize;
                let sign = if next() < 0.5 { -1.0 } else { 1.0 };
                d = [0.0; 3];
                d[a] = sign;
                d[(a + 1) % 3] = -0.0;
            }
            // An axis plane.
            1 => {
                let a = (k / 8 % 3) as usize;
                d[a] = if k % 16 == 1 { 0.0 } else { -0.0 };
                let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                d = d.map(|c| c / l);
            }
            _ => {}
        }
        let tmax = if k % 5 == 0 { 20.0 } else { f32::INFINITY };
        out.push([o[0], o[1], o[2], d[0], d[1], d[2], 1e-3, tmax]);
    }
    // At vertices from the transmitter.
    for (k, v) in vertices.iter().enumerate().step_by(3) {
        let d = [v[0] - tx[0], v[1] - tx[1], v[2] - tx[2]];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if l > 0.0 && k / 3 < n as usize {
            out.push([
                tx[0],
                tx[1],
                tx[2],
                d[0] / l,
                d[1] / l,
                d[2] / l,
                1e-3,
                f32::INFINITY,
            ]);
        }
    }
    out
}

pub fn vertices(scene: &Scene) -> Vec<[f32; 3]> {
    scene
        .objects
        .iter()
        .flat_map(|o| o.mesh.positions.iter().copied())
        .collect()
}

/// A munich-like map set-up: `scene` at 3.5 GHz with its file's slab thicknesses (as the CLI
/// loads it), the default plane of `cell_m` cells at 1.5 m.
pub fn munich_rf(xml: &std::path::Path) -> kodama_nodes::rf::scene::RfScene {
    let (s, thickness) = kodama_nodes::io::sionna_xml::read_scene_with_thickness(xml).unwrap();
    let rf = kodama_nodes::rf::scene::RfScene::new(&s, 3.5e9, false).unwrap();
    thickness
        .into_iter()
        .fold(rf, |rf, (m, d)| rf.with_thickness(m, d))
}

/// Compares two path-gain maps (linear): (cells both reach, cells only one reaches, median,
/// 99th percentile and largest |difference| in dB over the cells both reach).
pub fn compare_maps(a: &[f32], b: &[f32]) -> (usize, usize, f64, f64, f64) {
    let mut diff = Vec::new();
    let mut only = 0;
    for (x, y) in a.iter().zip(b) {
        match (*x > 0.0, *y > 0.0) {
            (true, true) => diff.push((10.0 * (*x as f64 / *y as f64).log10()).abs()),
            (false, false) => {}
            _ => only += 1,
        }
    }
    diff.sort_by(f64::total_cmp);
    let at = |q: f64| diff[((diff.len() - 1) as f64 * q) as usize];
    (diff.len(), only, at(0.5), at(0.99), at(1.0))
}

/// The street grid's map cells (4 m, 50 x 50 over x, y in [-100, 100]) on a surface 1.5 m above
/// rolling terrain: a slope with hills 3 m high, so patches tilt and rays cross it more than
/// once.
pub fn rolling_surface() -> kodama_nodes::rf::map_plane::MapPlane {
    use kodama_nodes::artifact::{Grid, PodVec, Raster};
    let grid = kodama_nodes::rf::test_scenes::street_map_grid();
    let n = 110u32;
    let terrain = Raster {
        grid: Grid {
            x0: -110.0,
            y0: 110.0,
            cell_m: 2.0,
            width: n,
            height: n,
        },
        data: PodVec(
            (0..n * n)
                .map(|i| {
                    let x = (i % n) as f64 * 2.0 - 110.0;
                    let y = 110.0 - (i / n) as f64 * 2.0;
                    (0.04 * x + 3.0 * (x / 17.0).sin() * (y / 23.0).cos()) as f32
                })
                .collect(),
        ),
    };
    kodama_nodes::rf::map_plane::MapPlane::above_terrain(grid, &terrain, 1.5).unwrap()
}
