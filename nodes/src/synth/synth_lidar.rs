//! A simulated airborne LiDAR survey of a scene: the classified point cloud a real site's LAS tile
//! would be, with the occlusion, multiple returns and noise that make reconstruction hard.
//!
//! The scanner flies parallel lines along x at a fixed altitude, sweeping across track within
//! ±`scan_angle_deg` (a line scanner, as most airborne systems). Each pulse is cast through the
//! scene's BVH: walls and roofs stop it (so the ground behind a building is shadowed off-nadir),
//! tree crowns are semi-transparent volumes (a pulse may echo inside a crown, pass through it, or
//! end there), and every return is classified from the object it hit (ASPRS 2 ground, 6
//! building, 5 high vegetation, 1 unclassified clutter), with optional labelling errors.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::{ArtifactType, ObjectClass, PointSet, Scene};
use crate::geom::raycast::SceneRays;
use crate::rng::{gaussian, mix, unit};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`SynthLidar`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthLidarParams {
    /// Target density of first returns on open ground, pulses per m². Default 12.
    pub density_per_m2: f64,
    /// Flying height above the highest terrain, metres. Default 500.
    pub altitude_m: f64,
    /// Half scan angle, degrees. Default 20.
    pub scan_angle_deg: f64,
    /// Side overlap between neighbouring strips, fraction. Default 0.3.
    pub overlap: f64,
    /// Standard deviation of the position noise, metres. Default 0.05.
    pub noise_m: f64,
    /// Probability that a pulse ends inside a tree crown it enters. Default 0.35.
    pub foliage_stop: f64,
    /// Probability of an intermediate echo from a crown the pulse passes through. Default 0.5.
    pub foliage_echo: f64,
    /// Probability that a hard return is misclassified: one in vegetation, on clutter, on a wall
    /// or steep roof (the surface's normal more than 50 degrees off vertical), or a pulse's
    /// return that is not its last. A building return becomes vegetation (5), a vegetation
    /// return building (6) or unclassified (1), ground unclassified, clutter ground or
    /// vegetation. Default 0.1 (with `class_error_open`, about 2 % of the demo's returns).
    pub class_error: f64,
    /// Probability that any other return (open ground, flat roofs) is misclassified, the same
    /// way. Default 0.005.
    pub class_error_open: f64,
    /// Returns per pulse at most. Default 4.
    pub max_returns: u8,
    /// Seed. Default 7.
    pub seed: u64,
}

impl Default for SynthLidarParams {
    fn default() -> Self {
        SynthLidarParams {
            density_per_m2: 12.0,
            altitude_m: 500.0,
            scan_angle_deg: 20.0,
            overlap: 0.3,
            noise_m: 0.05,
            foliage_stop: 0.35,
            foliage_echo: 0.5,
            class_error: 0.1,
            class_error_open: 0.005,
            max_returns: 4,
            seed: 7,
        }
    }
}

/// Simulates an airborne LiDAR survey of a scene.
pub struct SynthLidar;

impl Stage for SynthLidar {
    const KIND: &'static str = "SynthLidar";
    // 2: classification error on by default, concentrated on hard returns (issue 51).
    const VERSION: u32 = 2;
    const DOC: &'static str =
        "simulated airborne LiDAR survey: occlusion, multiple returns in foliage, classes, noise";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "scene",
        ArtifactType::Scene,
        "the ground-truth scene",
    )];
    type Params = SynthLidarParams;
    type Output = PointSet;
    // In a tiled run the survey is planned over the whole scene, as untiled, and only the pulses
    // aimed into the window are fired: tiles get exactly the untiled returns that fall in them.
    const WINDOWED: bool = true;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        let prob = |v: f64| (0.0..=1.0).contains(&v);
        if !(p.density_per_m2 > 0.0 && p.density_per_m2 <= 200.0) {
            return Err(ParamError::new(
                "density_per_m2",
                "expected a density in (0, 200] per m²",
            ));
        }
        if !(p.altitude_m >= 20.0) {
            return Err(ParamError::new("altitude_m", "expected at least 20 m"));
        }
        if !(p.scan_angle_deg > 0.0 && p.scan_angle_deg < 60.0) {
            return Err(ParamError::new(
                "scan_angle_deg",
                "expected a half angle in (0, 60) degrees",
            ));
        }
        if !(0.0..0.9).contains(&p.overlap) {
            return Err(ParamError::new(
                "overlap",
                "expected an overlap in [0, 0.9)",
            ));
        }
        for (name, v) in [
            ("foliage_stop", p.foliage_stop),
            ("foliage_echo", p.foliage_echo),
            ("class_error", p.class_error),
            ("class_error_open", p.class_error_open),
        ] {
            if !prob(v) {
                return Err(ParamError::new(name, "expected a probability in [0, 1]"));
            }
        }
        if p.max_returns == 0 {
            return Err(ParamError::new("max_returns", "expected at least 1"));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<PointSet, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        survey(scene, p, ctx)
    }
}

/// Near-infrared reflectance used for intensities.
fn reflectance(m: Option<Material>) -> f64 {
    match m {
        Some(Material::Glass) => 0.08,
        Some(Material::Metal) => 0.25,
        Some(Material::Brick) => 0.35,
        Some(Material::Wood) => 0.35,
        Some(Material::Marble) => 0.6,
        Some(Material::Foliage) => 0.5,
        Some(Material::Concrete) => 0.45,
        _ => 0.3,
    }
}

fn asprs_class(c: ObjectClass) -> u8 {
    match c {
        ObjectClass::Terrain => 2,
        ObjectClass::Building => 6,
        ObjectClass::Vegetation => 5,
        ObjectClass::Clutter | ObjectClass::Unsegmented => 1,
    }
}

/// The class a labeller gives a return of true class `class`, wrong with probability `rate`
/// (one hash `h` decides whether and to what): building to vegetation, vegetation to building
/// or unclassified, ground to unclassified, unclassified to ground or vegetation.
fn misclassified(class: u8, rate: f64, h: u64) -> u8 {
    if unit(h) >= rate {
        return class;
    }
    let either = unit(mix(h)) < 0.5;
    match class {
        6 => 5,
        5 => {
            if either {
                6
            } else {
                1
            }
        }
        2 => 1,
        _ => {
            if either {
                2
            } else {
                5
            }
        }
    }
}

struct Return {
    xyz: [f32; 3],
    class: u8,
    intensity: u16,
}

/// Flies the survey over the extent of the scene's terrain object (or all objects if none).
pub fn survey(scene: &Scene, p: &SynthLidarParams, ctx: &Ctx) -> Result<PointSet, StageError> {
    let extent_of = |pred: &dyn Fn(&ObjectClass) -> bool| {
        scene
            .objects
            .iter()
            .filter(|o| pred(&o.class))
            .flat_map(|o| o.mesh.positions.iter())
            .fold(
                ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
                |(mut lo, mut hi), q| {
                    for k in 0..3 {
                        lo[k] = lo[k].min(q[k] as f64);
                        hi[k] = hi[k].max(q[k] as f64);
                    }
                    (lo, hi)
                },
            )
    };
    let (mut lo, mut hi) = extent_of(&|c| *c == ObjectClass::Terrain);
    if !lo[0].is_finite() {
        (lo, hi) = extent_of(&|_| true);
    }
    if !lo[0].is_finite() {
        return Err(StageError::Failed(
            "the scene is empty: nothing to survey".into(),
        ));
    }
    let z_sensor = hi[2] + p.altitude_m;
    let z_ref = (lo[2] + hi[2]) / 2.0;
    let half_swath = (z_sensor - z_ref) * p.scan_angle_deg.to_radians().tan();
    let spacing = 2.0 * half_swath * (1.0 - p.overlap);
    // Strips centred on the site, as few as cover it; the per-strip density is the target divided
    // by how many strips see an average point of the site, so the site's mean density is the target.
    let span = hi[1] - lo[1];
    let n_lines = (((span - 2.0 * half_swath) / spacing).ceil().max(0.0) as u64) + 1;
    let first_line = (lo[1] + hi[1]) / 2.0 - (n_lines - 1) as f64 * spacing / 2.0;
    let covered: f64 = (0..n_lines)
        .map(|l| {
            let y = first_line + l as f64 * spacing;
            ((y + half_swath).min(hi[1]) - (y - half_swath).max(lo[1])).max(0.0)
        })
        .sum();
    let multiplicity = (covered / span.max(1e-9)).max(1.0);
    let step = 1.0 / (p.density_per_m2 / multiplicity).sqrt();
    let n_along = ((hi[0] - lo[0]) / step).ceil() as u64 + 1;
    let n_across = (2.0 * half_swath / step).ceil() as u64;
    // A pulse aimed at (x, y) leaves the sensor at most half a swath away across track (a little
    // more where it goes on below the reference height): what lies farther from the window can
    // neither be hit nor shadow a pulse into it.
    let window = ctx.window;
    let cropped;
    let scene = match window {
        Some(w) => {
            let near = w.grown(1.5 * half_swath + step);
            // Cut to the triangles: the pulses aimed into the window reach nothing cut away.
            cropped = scene.near(near.min, near.max, |_| false);
            &cropped
        }
        None => scene,
    };
    let rays = SceneRays::new(scene);
    let row_meets_window = |line: u64, i: u64| {
        window.is_none_or(|w| {
            let y_line = first_line + line as f64 * spacing;
            let x = lo[0] + i as f64 * step;
            w.meets((x, y_line - half_swath), (x + step, y_line + half_swath))
        })
    };
    let rows_fired: Vec<u64> = (0..n_lines * n_along)
        .filter(|row| row_meets_window(row / n_along, row % n_along))
        .collect();
    ctx.progress.set_total(rows_fired.len() as u64);
    let rows: Vec<Vec<(u64, Return)>> = rows_fired
        .into_par_iter()
        .map(|row| {
            let (line, i) = (row / n_along, row % n_along);
            let y_line = first_line + line as f64 * spacing;
            let mut out = Vec::new();
            for k in 0..n_across {
                let pulse = row * n_across + k;
                let h = mix(p.seed ^ mix(pulse));
                let x = lo[0] + (i as f64 + unit(h)) * step;
                let y = y_line - half_swath + (k as f64 + unit(mix(h))) * step;
                if x > hi[0] || y < lo[1] || y > hi[1] {
                    continue;
                }
                if window.is_some_and(|w| !w.contains(x, y)) {
                    continue;
                }
                let (sx, sy, sz) = (x, y_line, z_sensor);
                let d = [x - sx, y - sy, z_ref - sz];
                let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let dir = [(d[0] / n) as f32, (d[1] / n) as f32, (d[2] / n) as f32];
                for r in trace_pulse(&rays, scene, p, [sx as f32, sy as f32, sz as f32], dir, h) {
                    out.push((pulse, r));
                }
            }
            ctx.progress.advance(1);
            out
        })
        .collect();
    let mut ps = PointSet::default();
    for row in rows {
        let mut start = 0;
        while start < row.len() {
            let pulse = row[start].0;
            let end = row[start..]
                .iter()
                .position(|r| r.0 != pulse)
                .map_or(row.len(), |e| start + e);
            for (j, (_, r)) in row[start..end].iter().enumerate() {
                ps.xyz.push(r.xyz);
                ps.class.push(r.class);
                ps.intensity.push(r.intensity);
                ps.return_number.push(j as u8 + 1);
                ps.number_of_returns.push((end - start) as u8);
            }
            start = end;
        }
    }
    Ok(ps)
}

fn trace_pulse(
    rays: &SceneRays,
    scene: &Scene,
    p: &SynthLidarParams,
    origin: [f32; 3],
    dir: [f32; 3],
    seed: u64,
) -> Vec<Return> {
    let mut returns = Vec::new();
    let mut o = origin;
    let mut draw = 0u64;
    let mut next = || {
        draw += 1;
        mix(seed ^ draw.wrapping_mul(0xD6E8_FEB8_6659_FD93))
    };
    let at = |o: [f32; 3], t: f32| [o[0] + dir[0] * t, o[1] + dir[1] * t, o[2] + dir[2] * t];
    while returns.len() < p.max_returns as usize {
        let Some(hit) = rays.cast(o, dir, 1e-3, f32::INFINITY) else {
            break;
        };
        let obj = &scene.objects[hit.object];
        let material = obj
            .mesh
            .materials
            .get(hit.triangle)
            .copied()
            .and_then(Material::from_u8);
        let cos =
            (hit.normal[0] * dir[0] + hit.normal[1] * dir[1] + hit.normal[2] * dir[2]).abs() as f64;
        let steep = (hit.normal[2] as f64).abs() < 0.64;
        let mut emit = |pt: [f32; 3], last: bool, next: &mut dyn FnMut() -> u64| {
            let hn = next();
            let noise = |k: u64| (p.noise_m * gaussian(mix(hn ^ k))) as f32;
            let hard = !last
                || steep
                || matches!(obj.class, ObjectClass::Vegetation | ObjectClass::Clutter)
                || material == Some(Material::Foliage);
            let rate = if hard {
                p.class_error
            } else {
                p.class_error_open
            };
            let class = misclassified(asprs_class(obj.class), rate, next());
            let intensity = (65535.0 * reflectance(material) * cos.max(0.05)).min(65535.0) as u16;
            returns.push(Return {
                xyz: [pt[0] + noise(1), pt[1] + noise(2), pt[2] + noise(3)],
                class,
                intensity,
            });
        };
        if material == Some(Material::Foliage) {
            // Entering a crown: find where the pulse would leave it.
            let entry = at(o, hit.t);
            let exit_t = rays
                .cast(entry, dir, 1e-3, f32::INFINITY)
                .filter(|e| e.object == hit.object)
                .map(|e| e.t);
            let Some(depth) = exit_t else {
                emit(entry, true, &mut next);
                break;
            };
            let inside = at(entry, depth * unit(next()) as f32);
            if unit(next()) < p.foliage_stop {
                emit(inside, true, &mut next);
                break;
            }
            if unit(next()) < p.foliage_echo {
                emit(inside, false, &mut next);
            }
            o = at(entry, depth);
            continue;
        }
        emit(at(o, hit.t), true, &mut next);
        break;
    }
    returns
}
