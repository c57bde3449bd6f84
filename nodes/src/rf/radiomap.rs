//! Radio maps by shooting and bouncing rays, with Sionna RT's estimator (its radio map solver):
//! rays leave the transmitter on a Fibonacci sphere, each carrying the solid angle Ω = 4π/N and a
//! polarised field; every crossing of the measurement plane adds |E|² Ω / |cos θ| to its cell, and
//! the map is scaled by (λ/4π)² / A_cell at the end: the mean path gain over each cell for an
//! isotropic receiver. At a surface the ray reflects, or goes through (slab transmission); with
//! both enabled one is drawn with probability in proportion to its power and the field divided by
//! √p, as Sionna does, from a hash of the ray and depth, so maps are deterministic.

use glam::DVec3;
use rayon::prelude::*;

use crate::artifact::{PodVec, Raster};
use crate::rng::{mix, unit};

use super::antenna::Antenna;
use super::antenna::spherical_basis;
use super::diffraction::wedges_for;
use super::fibonacci::{PATCH, fibonacci_run, patch_order};
use super::field::{self, CVec};
use super::foliage::{FoliageDepth, FoliageLoss};
use super::map_plane::{Crossing, MapPlane};
use super::path::TraceOptions;
use super::radiomap_diffraction::{EdgeSampler, lit_wedges};
use super::scattering::pattern;
use super::scene::{EPS, RfScene, SurfaceHit};
use super::slab_table::SlabTable;

/// The mean path gain (linear) of every cell of `plane` from a transmitter at `tx`; 0 where no
/// ray arrived. `opt.rays` rays, interactions as `opt` enables them, foliage crossed at
/// `opt.foliage_loss_db_per_m` (ITU-R P.833). Diffraction adds first-order edge-diffracted power
/// from as many samples as rays, over the edges of the surfaces the rays first land on
/// (`radiomap_diffraction`).
pub fn radio_map(
    scene: &RfScene,
    tx: DVec3,
    antenna: &Antenna,
    plane: &MapPlane,
    opt: &TraceOptions,
    freq_hz: f64,
) -> Raster {
    let g = plane.grid;
    let omega = 4.0 * std::f64::consts::PI / opt.rays.max(1) as f64;
    let foliage = Foliage {
        at_tx: FoliageDepth::at(scene, tx),
        loss: opt.foliage_loss(freq_hz),
    };
    let shooter = Shooter {
        scene,
        tx,
        antenna,
        plane,
        opt,
        omega,
        foliage,
        slabs: SlabTable::new(scene),
    };
    // Fixed chunks, summed in chunk order and within a chunk in an order the rays alone fix:
    // the same bytes at any thread count. The sums run in f64, and the order's last bits do
    // not reach the f32 map: it is the bytes of summing ray after ray (tested below).
    let chunk = chunk_len(opt.rays);
    let diffraction = opt.diffraction && opt.max_depth > 0;
    let shoot = || -> Vec<(Vec<CellPower>, Vec<u32>)> {
        (0..opt.rays.div_ceil(chunk))
            .into_par_iter()
            .map(|k| {
                let (mut hits, mut crossings) = (Vec::new(), Vec::new());
                let mut first = diffraction.then(Vec::new);
                let start = k * chunk;
                // Every first bounce leaves the transmitter, and the lattice's neighbours lie side by
                // side: cast as packets of a patch each, these rays cost a fraction of a lone ray
                // (BENCHMARKS.md, "Tracer speed"). The map is the same to the bit.
                let order = patch_order(opt.rays, start, chunk);
                // Put in patch order once: every later pass reads them in sequence, where
                // the lattice's order would scatter each patch over the chunk.
                let lattice: Vec<DVec3> = fibonacci_run(opt.rays, start, chunk).collect();
                let dirs: Vec<DVec3> = order.iter().map(|&i| lattice[i as usize]).collect();
                drop(lattice);
                let landed = scene.cast_fan(tx, &dirs, EPS, f64::INFINITY);
                let bufs = (&mut hits, &mut crossings);
                shooter.shoot_batches(&dirs, start as u64, &order, &landed, bufs, first.as_mut());
                let mut first = first.unwrap_or_default();
                first.sort_unstable();
                first.dedup();
                (hits, first)
            })
            .collect()
    };
    // The scene's wedges do not depend on the rays: built on one thread while the rest shoot.
    let (chunks, all) = rayon::join(shoot, || diffraction.then(|| wedges_for(scene, opt)));
    let mut acc = vec![0.0f64; g.len()];
    let mut seen = Vec::new();
    for (hits, first) in chunks {
        for (cell, v) in hits {
            acc[cell as usize] += v;
        }
        seen.extend(first);
    }
    if let Some(all) = all {
        seen.sort_unstable();
        seen.dedup();
        let wedges = lit_wedges(&all, &seen, tx);
        let sampler = EdgeSampler {
            scene,
            tx,
            antenna,
            plane,
            foliage: (shooter.foliage.at_tx, shooter.foliage.loss),
        };
        for (cell, v) in sampler.contributions(&wedges, opt.rays) {
            acc[cell as usize] += v;
        }
    }
    let scale = (scene.wavelength / (4.0 * std::f64::consts::PI)).powi(2);
    Raster {
        grid: g,
        data: PodVec(acc.into_iter().map(|v| (v * scale) as f32).collect()),
    }
}

/// Rays a chunk of a map traces together: about a band of the lattice [`PATCH`] rays high
/// (`patch_order` then makes square patches), at least 8,192 so that a chunk's set-up stays
/// small, at most 65,536, which bounds its buffers (directions, first hits, order: a few MB).
fn chunk_len(rays: u32) -> u32 {
    let band = 8.0 * (std::f64::consts::PI * rays as f64).sqrt();
    ((band / PATCH as f64).ceil() as u32 * PATCH).clamp(8192, 65_536)
}

/// The foliage a map's rays start in, and its loss.
struct Foliage {
    at_tx: FoliageDepth,
    loss: FoliageLoss,
}

/// A crossing's cell and the power it adds there.
type CellPower = (u32, f64);

/// Rays shot together, segment by segment: their state (about 130 bytes a ray) stays in the
/// cache. Batches of 128 to 8,192 rays made the munich map equally fast.
const BATCH: usize = 512;

/// What every ray of one map shares.
struct Shooter<'a> {
    scene: &'a RfScene,
    tx: DVec3,
    antenna: &'a Antenna,
    plane: &'a MapPlane,
    opt: &'a TraceOptions,
    /// The solid angle each ray stands for, sr.
    omega: f64,
    foliage: Foliage,
    slabs: SlabTable,
}

/// A ray between two segments: what it carries into the next one, which starts at `o` and runs
/// along `d`.
#[derive(Clone, Copy)]
struct Flight {
    e: CVec,
    o: DVec3,
    d: DVec3,
    /// The solid angle its tube spans, sr.
    omega: f64,
    /// Its index on the Fibonacci sphere: the seed of its event draws.
    index: u64,
    /// Interactions so far.
    depth: u32,
    foliage: FoliageDepth,
    /// Metres run in foliage so far (P.833's law saturates on the whole path's).
    in_foliage: f64,
}

impl Shooter<'_> {
    /// A ray leaving the transmitter along `d0`, the `index`-th of the lattice.
    fn launch(&self, d0: DVec3, index: u64) -> Flight {
        Flight {
            e: field::real(DVec3::from(self.antenna.field(d0.to_array()))),
            o: self.tx,
            d: d0,
            omega: self.omega,
            index,
            depth: 0,
            foliage: self.foliage.at_tx,
            in_foliage: 0.0,
        }
    }

    /// The rays `dirs`, the lattice's `start + order[i]`-th, each from its launch to the end of
    /// its bounces, `landed[i]` being where it first lands. Taken in batches of [`BATCH`]
    /// that go one segment at a time, each segment's casts together: neighbours on the lattice
    /// that reflect off one plane still travel side by side and go as packets
    /// ([`RfScene::cast_coherent`], the same hits as one by one). The crossings come out
    /// segment by segment, ray by ray within one: the map sums them in an order fixed by the
    /// rays alone.
    fn shoot_batches(
        &self,
        dirs: &[DVec3],
        start: u64,
        order: &[u32],
        landed: &[Option<SurfaceHit>],
        (out, crossings): (&mut Vec<CellPower>, &mut Vec<Crossing>),
        mut first: Option<&mut Vec<u32>>,
    ) {
        let mut flights = Vec::with_capacity(BATCH);
        let mut next = Vec::with_capacity(BATCH);
        let batches = order.chunks(BATCH).zip(dirs.chunks(BATCH));
        for ((batch, dirs), landed) in batches.zip(landed.chunks(BATCH)) {
            flights.clear();
            flights
                .extend((batch.iter().zip(dirs)).map(|(&k, &d)| self.launch(d, start + k as u64)));
            let mut hits = landed.to_vec();
            loop {
                let mut live = 0;
                next.clear();
                for (r, hit) in hits.into_iter().enumerate() {
                    let mut f = flights[r];
                    if self.segment(&mut f, hit, (out, crossings), first.as_deref_mut()) {
                        next.push((f.o, f.d));
                        flights[live] = f;
                        live += 1;
                    }
                }
                flights.truncate(live);
                if flights.is_empty() {
                    break;
                }
                hits = self.scene.cast_coherent(&next, EPS, f64::INFINITY);
            }
        }
    }

    /// One segment of a ray, from `f.o` along `f.d` to `hit` (or out of the scene): every crossing
    /// of the plane adds the power it carries to its cell (as Sionna RT's solver does), foliage
    /// passed through attenuates it (ITU-R P.833), and at the surface hit it reflects, scatters or
    /// goes through. True when the ray goes on, `f` then holding its next segment's start. `out`
    /// takes (cell, power) per crossing; the second buffer is scratch. `first`, if given, takes
    /// the surface the ray first lands on (foliage aside): the faces whose edges can diffract.
    #[inline(always)]
    fn segment(
        &self,
        f: &mut Flight,
        hit: Option<SurfaceHit>,
        (out, crossings): (&mut Vec<CellPower>, &mut Vec<Crossing>),
        first: Option<&mut Vec<u32>>,
    ) -> bool {
        let Shooter {
            scene,
            plane,
            opt,
            ref foliage,
            ref slabs,
            ..
        } = *self;
        let (o, d) = (f.o, f.d);
        let t_end = hit.map_or(f64::INFINITY, |h| h.t);
        let inside = f.foliage.inside();
        let before = f.in_foliage;
        let foliage_amp = |len: f64| {
            if inside {
                foliage.loss.step_amplitude(before, len)
            } else {
                1.0
            }
        };
        if f.depth > 0 || opt.los {
            crossings.clear();
            plane.crossings(o, d, t_end, crossings);
            for c in crossings.iter() {
                let a = foliage_amp(c.t);
                let cos = d.dot(c.normal).abs().max(1e-6);
                let weight = 1.0 / (cos * plane.patch_area(c.normal));
                out.push((c.cell, field::norm_sqr(&f.e) * a * a * f.omega * weight));
            }
        }
        let Some(h) = hit else { return false };
        let a = foliage_amp(h.t);
        f.e = f.e.map(|c| c * a);
        if inside {
            f.in_foliage += h.t;
        }
        let p = o + d * h.t;
        f.o = p;
        if f.foliage.cross(scene, h.triangle, d) {
            return true;
        }
        let n = scene.normals[h.triangle as usize];
        if f.depth == 0
            && let Some(first) = first
        {
            first.push(h.triangle);
        }
        f.depth += 1;
        if f.depth > opt.max_depth {
            return false;
        }
        let (r, t) = slabs.get(scene, h.triangle, d.dot(n));
        // Sionna's event probabilities: specular r (1 - S²), diffuse r S², transmission t.
        let (pr, pt) = (
            r.0.norm_sqr() + r.1.norm_sqr(),
            t.0.norm_sqr() + t.1.norm_sqr(),
        );
        let s2 = opt.scattering_coefficient.powi(2);
        let p_spec = if opt.reflection { pr * (1.0 - s2) } else { 0.0 };
        let p_diff = if opt.diffuse { pr * s2 } else { 0.0 };
        let p_tran = if opt.transmission { pt } else { 0.0 };
        let total = p_spec + p_diff + p_tran;
        if total <= 0.0 {
            return false;
        }
        let seed = mix(f.index.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ f.depth as u64);
        let u = unit(seed) * total;
        let e = &f.e;
        if u < p_spec {
            let (e2, k) = field::reflect(e, d, n, r);
            let w = ((1.0 - s2) * total / p_spec).sqrt();
            f.e = e2.map(|c| c * w);
            f.d = k;
        } else if u < p_spec + p_diff {
            // Uniform on the hemisphere the wave came from; the new tube spans 2π.
            let side = if d.dot(n) < 0.0 { n } else { -n };
            let (u1, u2) = (unit(mix(seed ^ 1)), unit(mix(seed ^ 2)));
            let ko = hemisphere(side, u1, u2);
            let (e_spec, _) = field::reflect(e, d, n, r);
            let gamma = (field::norm_sqr(&e_spec) / field::norm_sqr(e).max(1e-300)).sqrt();
            let fp = pattern(opt.scattering_pattern, d, ko, side);
            let (th_i, ph_i) = spherical_basis(d.to_array());
            let (th_o, ph_o) = spherical_basis(ko.to_array());
            let (e_th, e_ph) = (
                field::dot(e, DVec3::from(th_i)),
                field::dot(e, DVec3::from(ph_i)),
            );
            let w = opt.scattering_coefficient * gamma * (fp * f.omega * total / p_diff).sqrt();
            f.e = [0, 1, 2].map(|c| (e_th * th_o[c] + e_ph * ph_o[c]) * w);
            f.d = ko;
            f.omega = 2.0 * std::f64::consts::PI;
        } else {
            f.e = field::transmit(e, d, n, t).map(|c| c * (total / p_tran).sqrt());
        }
        true
    }
}

/// A path-gain map in dB: NaN where no ray arrived.
pub fn to_db(map: &Raster) -> Raster {
    Raster {
        grid: map.grid,
        data: PodVec(
            map.data
                .iter()
                .map(|&g| if g > 0.0 { 10.0 * g.log10() } else { f32::NAN })
                .collect(),
        ),
    }
}

/// A direction on the hemisphere round `n`, uniform in solid angle, from two uniforms.
fn hemisphere(n: DVec3, u1: f64, u2: f64) -> DVec3 {
    let z = u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * std::f64::consts::PI * u2;
    let (a, b) = n.any_orthonormal_pair();
    (a * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Grid, Scene};
    use crate::rf::test_scenes::{STREET_TX, street_grid, street_plane};

    /// Casting in packets, in patch order and segment by segment changes nothing: the map is the
    /// bytes of tracing ray after ray, each cast alone, summed in ray order (the map sums in
    /// f64 segment by segment: the order's last bits stay below f32). In a street grid,
    /// with every event (specular, diffuse, transmitted) drawn and a lattice dense enough for
    /// packets (1e6 rays: patches of 1.4 degrees).
    #[test]
    fn the_map_is_ray_after_ray_to_the_bit() {
        let scene = street_grid();
        let plane = street_plane();
        let tx = STREET_TX;
        let opt = TraceOptions {
            rays: 1_000_000,
            diffuse: true,
            scattering_coefficient: 0.4,
            ..Default::default()
        };
        let antenna = Antenna::default();
        let map = radio_map(&scene, tx, &antenna, &plane, &opt, 3.5e9);
        let shooter = Shooter {
            scene: &scene,
            tx,
            antenna: &antenna,
            plane: &plane,
            opt: &opt,
            omega: 4.0 * std::f64::consts::PI / opt.rays as f64,
            foliage: Foliage {
                at_tx: FoliageDepth::at(&scene, tx),
                loss: opt.foliage_loss(3.5e9),
            },
            slabs: SlabTable::new(&scene),
        };
        let (mut hits, mut crossings) = (Vec::new(), Vec::new());
        for (i, d0) in fibonacci_run(opt.rays, 0, opt.rays).enumerate() {
            let mut f = shooter.launch(d0, i as u64);
            let mut hit = scene.cast(tx, d0, EPS, f64::INFINITY);
            while shooter.segment(&mut f, hit, (&mut hits, &mut crossings), None) {
                hit = scene.cast(f.o, f.d, EPS, f64::INFINITY);
            }
        }
        let mut acc = vec![0.0f64; plane.grid.len()];
        for (cell, v) in hits {
            acc[cell as usize] += v;
        }
        let scale = (scene.wavelength / (4.0 * std::f64::consts::PI)).powi(2);
        let alone: Vec<u32> = acc.iter().map(|v| ((v * scale) as f32).to_bits()).collect();
        let got: Vec<u32> = map.data.0.iter().map(|v| v.to_bits()).collect();
        assert_eq!(got, alone);
        let reached = acc.iter().filter(|v| **v > 0.0).count();
        assert!(reached > 800, "{reached} cells reached");
    }

    /// In free space the map is Friis averaged over each cell: check cells away from the
    /// transmitter, where the average is close to the value at the centre.
    #[test]
    fn free_space_map_follows_friis() {
        let scene = RfScene::new(&Scene::default(), 3.5e9, false).unwrap();
        let plane = MapPlane::plane(
            Grid {
                x0: -200.0,
                y0: 200.0,
                cell_m: 10.0,
                width: 40,
                height: 40,
            },
            0.0,
        );
        let tx = DVec3::new(0.0, 0.0, 30.0);
        let opt = TraceOptions {
            rays: 2_000_000,
            ..Default::default()
        };
        let map = radio_map(&scene, tx, &Antenna::default(), &plane, &opt, 3.5e9);
        let lam = scene.wavelength;
        let mut worst: f64 = 0.0;
        for (c, r) in [(30u32, 20u32), (35, 5), (5, 30), (20, 38)] {
            let (x, y) = plane.grid.center(c, r);
            let d2 = x * x + y * y + 900.0;
            // Vertical polarisation, isotropic: |θ̂|² = 1 everywhere.
            let friis = (lam / (4.0 * std::f64::consts::PI)).powi(2) / d2;
            let got = map.at(c, r) as f64;
            worst = worst.max((10.0 * (got / friis).log10()).abs());
        }
        assert!(worst < 0.25, "worst cell off Friis by {worst} dB");
    }
}
