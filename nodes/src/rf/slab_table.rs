//! Slab coefficients tabulated over the incidence cosine, per material, for the radio map's
//! inner loop. Evaluating [`em::slab`](super::em::slab) costs a complex square root, a complex
//! exponential and four complex divisions per bounce, about a tenth of a depth-3 map; a lookup
//! with linear interpolation costs two loads and a few multiplies.
//!
//! The table is dense enough that interpolation stays far below anything a Monte Carlo map can
//! resolve: the coefficients are smooth in cos θ except for the slab's round-trip phase, which
//! turns 2 d |Δ√(η - sin²θ)| / λ times over [0, 1]; every turn gets [`SAMPLES_PER_TURN`] samples, so
//! the relative error is at most (2π / 256)² / 8 ≈ 8e-5 (7e-4 dB). Links keep the exact
//! evaluation: their paths are deterministic and compared with Sionna RT path by path.

use num_complex::Complex64 as C64;

use super::em::slab;
use super::scene::RfScene;

/// Samples per turn of the slab's phase over the table's range.
const SAMPLES_PER_TURN: f64 = 256.0;
/// The fewest samples a table has (the Fresnel terms alone need about this many).
const MIN_SAMPLES: usize = 1024;
/// The most samples a table has: 64 turns of phase or more (a slab 30 wavelengths thick) are
/// sampled more coarsely than [`SAMPLES_PER_TURN`] rather than grow without bound.
const MAX_SAMPLES: usize = 1 << 14;

/// ((R_TE, R_TM), (T_TE, T_TM)), as [`em::slab`](super::em::slab) returns them.
pub type SlabCoefficients = ((C64, C64), (C64, C64));

/// Per material of a scene, its slab coefficients at evenly spaced incidence cosines in [0, 1].
pub struct SlabTable {
    /// Index = material discriminant; `None` for transparent materials (foliage) and materials
    /// no triangle has.
    tables: Vec<Option<Table>>,
}

/// One material's samples, evenly spaced in √cos θ from 0 to 1, and the cosine below which it
/// is evaluated exactly instead.
struct Table {
    samples: Vec<[C64; 4]>,
    exact_below: f64,
}

impl SlabTable {
    /// Tables for every material `scene` uses.
    pub fn new(scene: &RfScene) -> SlabTable {
        let mut used = vec![false; scene.material_count()];
        for &m in &scene.material {
            used[m as usize] = true;
        }
        let tables = used
            .iter()
            .enumerate()
            .map(|(m, &u)| {
                let (eta, d) = scene.slab_params(m)?;
                u.then(|| tabulate(eta, d, scene.wavelength))
            })
            .collect();
        SlabTable { tables }
    }

    /// The coefficients of triangle `tri` of `scene` at incidence cosine `cos_theta` (either
    /// sign), interpolated; foliage is transparent, as [`RfScene::slab`] has it.
    #[inline]
    pub fn get(&self, scene: &RfScene, tri: u32, cos_theta: f64) -> SlabCoefficients {
        let m = scene.material[tri as usize] as usize;
        let Some(table) = self.tables.get(m).and_then(Option::as_ref) else {
            return scene.slab(tri, cos_theta);
        };
        let c = cos_theta.abs().min(1.0);
        if c < table.exact_below {
            return scene.slab(tri, cos_theta);
        }
        let n = table.samples.len();
        let x = c.sqrt() * (n - 1) as f64;
        let i = (x as usize).min(n - 2);
        let f = x - i as f64;
        let (a, b) = (&table.samples[i], &table.samples[i + 1]);
        let lerp = |k: usize| a[k] + (b[k] - a[k]) * f;
        ((lerp(0), lerp(1)), (lerp(2), lerp(3)))
    }
}

/// The slab's coefficients at `n` points evenly spaced in √cos θ over [0, 1] (denser toward
/// grazing, where the coefficients bend fastest), `n` set by the phase's turns.
fn tabulate(eta: C64, d: f64, wavelength: f64) -> Table {
    // A slab's round trip turns its phase by 4π d / λ √(η - sin²θ); the change of that over
    // cos θ in [0, 1] bounds the turns.
    let root = |sin2: f64| (eta - sin2).sqrt();
    let turns = 2.0 * d / wavelength * (root(0.0) - root(1.0)).norm();
    // Spaced in √cos, the samples are up to twice as far apart in cos (near normal incidence).
    let n = ((2.0 * turns * SAMPLES_PER_TURN).ceil() as usize).clamp(MIN_SAMPLES, MAX_SAMPLES);
    let samples = (0..n)
        .map(|k| {
            let u = k as f64 / (n - 1) as f64;
            let ((r_te, r_tm), (t_te, t_tm)) = slab(u * u, eta, d, wavelength);
            [r_te, r_tm, t_te, t_tm]
        })
        .collect();
    // R_TM dips near grazing over a range of cosines about s = 1 / √|η| wide (the pseudo-Brewster
    // angle of a conductor). Spaced in √cos, the samples near cos = 8 s are 2 √(8 s) / n apart;
    // where that is coarser than s / 8 (|η| above about 10^5 at 1024 samples: metals) the dip is
    // evaluated exactly. Dielectrics (|η| < 100) never need it.
    let s = 1.0 / eta.norm().sqrt();
    let step = 2.0 * (8.0 * s).sqrt() / n as f64;
    let exact_below = if step > s / 8.0 { 8.0 * s } else { 0.0 };
    Table {
        samples,
        exact_below,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::artifact::{Mesh, ObjectClass, Scene, SceneObject};
    use crate::geom::mesh_build::cuboid;

    fn scene_of(materials: &[Material], freq_hz: f64) -> RfScene {
        let objects = materials
            .iter()
            .enumerate()
            .map(|(k, &m)| {
                let mesh: Mesh = cuboid([k as f64 * 10.0, 0.0], [2.0, 2.0, 5.0], 0.0, 0.0, m);
                SceneObject {
                    id: format!("b{k}"),
                    class: ObjectClass::Building,
                    mesh,
                }
            })
            .collect();
        RfScene::new(&Scene { objects }, freq_hz, true).unwrap()
    }

    /// Interpolated coefficients agree with the exact slab to 1e-3 dB in magnitude (above -20 dB)
    /// and 1e-4 in the complex plane over the whole range of incidence, at 3.5 and 28 GHz (where a 0.3 m
    /// concrete slab's phase turns many times), for every material the table holds.
    #[test]
    fn the_table_is_the_slab_within_its_interpolation_error() {
        let materials = [
            Material::Concrete,
            Material::Brick,
            Material::Glass,
            Material::Metal,
            Material::Wood,
            Material::Foliage,
        ];
        for freq in [3.5e9, 28e9] {
            let scene = scene_of(&materials, freq);
            let table = SlabTable::new(&scene);
            let mut worst = 0.0f64;
            for tri in (0..scene.material.len() as u32).step_by(12) {
                for k in 0..=4000 {
                    let c = k as f64 / 4000.0 * if k % 2 == 0 { 1.0 } else { -1.0 };
                    let exact = scene.slab(tri, c);
                    let got = table.get(&scene, tri, c);
                    let pairs = [
                        (exact.0.0, got.0.0),
                        (exact.0.1, got.0.1),
                        (exact.1.0, got.1.0),
                        (exact.1.1, got.1.1),
                    ];
                    for (e, g) in pairs {
                        worst = worst.max((e - g).norm());
                        if e.norm() > 0.1 {
                            let db = 20.0 * (g.norm() / e.norm()).log10();
                            assert!(
                                db.abs() < 1e-3,
                                "{:?} at {freq} Hz, cos {c}: {db} dB ({e} vs {g})",
                                scene.material[tri as usize]
                            );
                        }
                    }
                }
            }
            assert!(worst < 1e-4, "worst complex error {worst} at {freq} Hz");
        }
    }
}
