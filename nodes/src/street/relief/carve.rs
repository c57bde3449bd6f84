//! Booleans for façade relief (paper Sec. 4.2.2): every relief instance becomes a prism on its
//! wall; recesses are subtracted from the building solid and protrusions added (exact Booleans,
//! materials kept per face: `geom::boolean`).
//!
//! Every carved solid must pass [`check_solid`](crate::geom::mesh_check::check_solid); where the
//! batch result does not, the building's instances are applied one at a time and each one whose
//! result fails is dropped, its reason kept.

use manifold_rust::manifold::Manifold;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::{
    Chart, ChartSet, Mesh, Metrics, ObjectClass, ReliefInstance, ReliefSet, Scene, SceneObject,
};
use crate::geom::boolean::{subtract_then_add as apply, to_manifold};
use crate::geom::mesh_build::quad_prism;

/// The material a carved face of a class takes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaceMaterial {
    /// The instance class (`window`, `door`, ...).
    pub class: String,
    /// For a recess, its back face (the glazing, the door leaf); for a protrusion, every face.
    pub material: Material,
}

/// Carving knobs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CarveParams {
    /// Carved-face materials per class.
    pub materials: Vec<FaceMaterial>,
    /// Back face of a recess of no known class. Default Glass (most unlabelled recesses on a
    /// façade are windows the segmentation missed).
    pub unknown_recess: Material,
    /// Faces of a protrusion of no known class. Default Concrete.
    pub unknown_protrusion: Material,
    /// How far a prism reaches past the wall plane into the solid (protrusions) or out of it
    /// (recesses), so the Boolean cuts cleanly rather than meeting the wall face to face, metres.
    /// Default 0.05.
    pub overshoot_m: f64,
    /// An instance must stay this far inside its wall's outline, metres. Default 0.05.
    pub margin_m: f64,
    /// Instances narrower than this (either side) are dropped, metres. Default 0.05.
    pub min_size_m: f64,
}

impl Default for CarveParams {
    fn default() -> Self {
        let m = |class: &str, material| FaceMaterial {
            class: class.into(),
            material,
        };
        CarveParams {
            materials: vec![
                m("window", Material::Glass),
                m("door", Material::Wood),
                m("balcony", Material::Concrete),
                m("drainpipe", Material::Metal),
            ],
            unknown_recess: Material::Glass,
            unknown_protrusion: Material::Concrete,
            overshoot_m: 0.05,
            margin_m: 0.05,
            min_size_m: 0.05,
        }
    }
}

impl CarveParams {
    /// (field, message) of the first bad knob.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        for (name, v, hi) in [
            ("overshoot_m", self.overshoot_m, 1.0),
            ("margin_m", self.margin_m, 10.0),
            ("min_size_m", self.min_size_m, 10.0),
        ] {
            if !(v.is_finite() && v >= 0.0 && v <= hi) {
                return Err((name, format!("expected a length in [0, {hi}] m, got {v}")));
            }
        }
        if self.overshoot_m < 1e-3 {
            return Err((
                "overshoot_m",
                "expected at least 1 mm: a prism flush with the wall leaves faces to decide".into(),
            ));
        }
        Ok(())
    }

    fn face_material(&self, class: &str, sign: i8) -> Material {
        match self.materials.iter().find(|m| m.class == class) {
            Some(m) => m.material,
            None if sign < 0 => self.unknown_recess,
            None => self.unknown_protrusion,
        }
    }
}

/// What happened to one instance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum CarveOutcome {
    /// Carved into (or added to) its building.
    Carved,
    /// Left out: the step that refused it, and why.
    Dropped(DropKind, String),
}

/// The step of the carve that left an instance out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum DropKind {
    /// Fitting it to its wall: off the wall, or trimmed under the minimum size.
    Fit,
    /// Its building is not in the scene.
    Scene,
    /// The building solid itself is not one the Booleans take.
    Solid,
    /// Its prism is not a solid the Booleans take.
    Prism,
    /// The carved building failed the solid check (intersecting or degenerate triangles).
    Check,
}

impl DropKind {
    /// Every kind, in order.
    pub const ALL: [DropKind; 5] = [
        DropKind::Fit,
        DropKind::Scene,
        DropKind::Solid,
        DropKind::Prism,
        DropKind::Check,
    ];

    /// The kind's name in metrics.
    pub fn name(self) -> &'static str {
        match self {
            DropKind::Fit => "fit",
            DropKind::Scene => "scene",
            DropKind::Solid => "solid",
            DropKind::Prism => "prism",
            DropKind::Check => "check",
        }
    }
}

/// Per building: triangles before and after.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CarvedBuilding {
    /// Object id.
    pub id: String,
    /// Triangles before carving.
    pub triangles_before: usize,
    /// Triangles after.
    pub triangles_after: usize,
    /// Instances carved.
    pub carved: usize,
    /// Instances dropped.
    pub dropped: usize,
}

/// What a carve did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CarveReport {
    /// One per relief instance, in the relief's order.
    pub outcomes: Vec<CarveOutcome>,
    /// One per building with at least one instance.
    pub buildings: Vec<CarvedBuilding>,
}

impl CarveReport {
    /// The report as metrics, `relief` being the instances it reports on: `instances`, `carved`,
    /// `dropped` and `dropped/<kind>` for every [`DropKind`]; per relief class `instances/<class>`
    /// and `carved/<class>`; `buildings` carved into and their `triangles_before` and
    /// `triangles_after`.
    pub fn metrics(&self, relief: &ReliefSet) -> Metrics {
        let mut m = Metrics::default();
        let carved = |o: &CarveOutcome| *o == CarveOutcome::Carved;
        m.set("instances", self.outcomes.len() as f64);
        let n_carved = self.outcomes.iter().filter(|o| carved(o)).count();
        m.set("carved", n_carved as f64);
        m.set("dropped", (self.outcomes.len() - n_carved) as f64);
        for kind in DropKind::ALL {
            let n = self
                .outcomes
                .iter()
                .filter(|o| matches!(o, CarveOutcome::Dropped(k, _) if *k == kind))
                .count();
            m.set(format!("dropped/{}", kind.name()), n as f64);
        }
        let mut per_class = std::collections::BTreeMap::<&str, (usize, usize)>::new();
        for (inst, o) in relief.instances.iter().zip(&self.outcomes) {
            let e = per_class.entry(inst.class.as_str()).or_default();
            e.0 += 1;
            e.1 += carved(o) as usize;
        }
        for (class, (n, c)) in per_class {
            m.set(format!("instances/{class}"), n as f64);
            m.set(format!("carved/{class}"), c as f64);
        }
        m.set("buildings", self.buildings.len() as f64);
        let sum = |f: fn(&CarvedBuilding) -> usize| self.buildings.iter().map(f).sum::<usize>();
        m.set("triangles_before", sum(|b| b.triangles_before) as f64);
        m.set("triangles_after", sum(|b| b.triangles_after) as f64);
        m
    }
}

/// The prism of one instance as a closed, outward-oriented box mesh, its faces' materials set:
/// a recess reaches from `overshoot` outside the wall to its depth inside (back face: the class
/// material; sides: the wall's); a protrusion from `overshoot` inside to its depth outside (every
/// face the class material).
pub fn instance_prism(
    inst: &ReliefInstance,
    normal: [f64; 3],
    wall: Material,
    p: &CarveParams,
) -> Mesh {
    let (back, front) = if inst.sign < 0 {
        (-inst.depth_m, p.overshoot_m)
    } else {
        (-p.overshoot_m, inst.depth_m)
    };
    let face = p.face_material(&inst.class, inst.sign);
    let (back_m, side_m, front_m) = if inst.sign < 0 {
        (face, wall, wall)
    } else {
        (face, face, face)
    };
    quad_prism(
        inst.corners,
        normal,
        (back, front),
        [back_m, side_m, front_m],
    )
}

/// The instance as it can become a prism on its wall, or why it cannot. A rectangle reaching
/// past the wall's outline, or within `margin_m` of it, is trimmed to fit rather than dropped:
/// a downpipe the relief runs up to the eave and down to the ground ends exactly where the wall
/// does, and the Boolean needs the prism a margin inside that edge, not the pipe left out.
fn fit_to_wall(
    inst: &ReliefInstance,
    charts: &ChartSet,
    p: &CarveParams,
) -> Result<ReliefInstance, String> {
    let Some(c) = charts.charts.get(inst.chart as usize) else {
        return Err(format!("chart {} is not in the chart set", inst.chart));
    };
    if c.building != inst.building {
        return Err(format!(
            "chart {} is on {}, not {}",
            inst.chart, c.building, inst.building
        ));
    }
    if !(inst.depth_m > 0.0 && inst.depth_m.is_finite()) {
        return Err(format!("depth {} m", inst.depth_m));
    }
    let too_small = |rect: [f64; 4]| {
        let (wu, wv) = (
            (rect[2] - rect[0]) * c.texel_m,
            (rect[3] - rect[1]) * c.texel_m,
        );
        (!(wu >= p.min_size_m && wv >= p.min_size_m)).then(|| {
            format!(
                "{wu:.3} x {wv:.3} m is under the {} m minimum",
                p.min_size_m
            )
        })
    };
    if let Some(why) = too_small(inst.rect) {
        return Err(why);
    }
    // Every texel under the rectangle widened by the margin must be covered by the wall.
    let m = p.margin_m / c.texel_m;
    let (w, h) = (c.width as i64, c.height as i64);
    let covered = |i: i64, j: i64| {
        (0..w).contains(&i)
            && (0..h).contains(&j)
            && c.triangle_at[(j * w + i) as usize] != u32::MAX
    };
    let span = |lo: f64, hi: f64| ((lo - m).floor() as i64, (hi + m).ceil() as i64);
    let [u0, v0, u1, v1] = inst.rect;
    let (u0, u1) = (u0.max(m), u1.min(w as f64 - m));
    let (v0, v1) = (v0.max(m), v1.min(h as f64 - m));
    if !(u0 < u1 && v0 < v1) {
        return Err("it lies within the margin of its wall's edge".into());
    }
    // Lines (rows, then columns over the rows kept; or the other way round, whichever keeps
    // more) whose texels across the rectangle are all covered: the run of good lines that
    // overlaps the rectangle most, less the margin.
    let trim = |[u0, v0, u1, v1]: [f64; 4], rows_first: bool| -> Option<[f64; 4]> {
        let ((a0, a1), (b0, b1)) = if rows_first {
            ((v0, v1), (u0, u1))
        } else {
            ((u0, u1), (v0, v1))
        };
        let at = |along: i64, across: i64| {
            if rows_first {
                covered(across, along)
            } else {
                covered(along, across)
            }
        };
        let (i0, i1) = span(b0, b1);
        let (j0, j1) = span(a0, a1);
        let (lo, hi) = best_run(j0, j1, |j| (i0..i1).all(|i| at(j, i)))?;
        let (a0, a1) = (a0.max(lo as f64 + m), a1.min(hi as f64 - m));
        let (j0, j1) = span(a0, a1);
        let (lo, hi) = best_run(i0, i1, |i| (j0..j1).all(|j| at(j, i)))?;
        let (b0, b1) = (b0.max(lo as f64 + m), b1.min(hi as f64 - m));
        Some(if rows_first {
            [b0, a0, b1, a1]
        } else {
            [a0, b0, a1, b1]
        })
    };
    let area = |r: &[f64; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let Some([u0, v0, u1, v1]) = [true, false]
        .into_iter()
        .filter_map(|rows_first| trim([u0, v0, u1, v1], rows_first))
        .max_by(|a, b| area(a).total_cmp(&area(b)))
    else {
        return Err("no part of it lies on the wall".into());
    };
    let rect = [u0, v0, u1, v1];
    if let Some(why) = too_small(rect) {
        return Err(format!("trimmed to its wall, {why}"));
    }
    let mut fitted = inst.clone();
    if rect != inst.rect {
        fitted.rect = rect;
        fitted.corners = [
            c.world_of(u0, v0),
            c.world_of(u1, v0),
            c.world_of(u1, v1),
            c.world_of(u0, v1),
        ];
    }
    Ok(fitted)
}

/// How far, metres, an instance whose carve fails the solid check is drawn in (its rectangle on
/// the wall on every side, its overshoot through the wall) before it is dropped, in turn.
const NUDGES_M: [f64; 2] = [0.003, 0.01];

/// `inst` drawn in by `d` metres on every side of its rectangle, or None when that leaves it
/// under the minimum size.
fn drawn_in(inst: &ReliefInstance, c: &Chart, d: f64, p: &CarveParams) -> Option<ReliefInstance> {
    let t = d / c.texel_m;
    let [u0, v0, u1, v1] = inst.rect;
    let rect = [u0 + t, v0 + t, u1 - t, v1 - t];
    let min = p.min_size_m / c.texel_m;
    if !(rect[2] - rect[0] >= min && rect[3] - rect[1] >= min) {
        return None;
    }
    let mut out = inst.clone();
    out.rect = rect;
    out.corners = [
        c.world_of(rect[0], rect[1]),
        c.world_of(rect[2], rect[1]),
        c.world_of(rect[2], rect[3]),
        c.world_of(rect[0], rect[3]),
    ];
    Some(out)
}

/// Of the lines `lo..hi` where `good` holds, the run `[a, b)` longest (ties to the first).
fn best_run(lo: i64, hi: i64, good: impl Fn(i64) -> bool) -> Option<(i64, i64)> {
    let mut best: Option<(i64, i64)> = None;
    let mut start = None;
    for k in lo..=hi {
        match (k < hi && good(k), start) {
            (true, None) => start = Some(k),
            (false, Some(a)) => {
                if best.is_none_or(|(x, y)| k - a > y - x) {
                    best = Some((a, k));
                }
                start = None;
            }
            _ => {}
        }
    }
    best
}

/// Carves every relief instance into its building of `scene`: the carved scene and what happened
/// to each instance. Buildings without instances are passed through untouched. Deterministic:
/// buildings are carved independently (in parallel) and instances applied in the relief's order.
pub fn carve_scene(
    scene: &Scene,
    charts: &ChartSet,
    relief: &ReliefSet,
    p: &CarveParams,
) -> Result<(Scene, CarveReport), String> {
    let (mut outcomes, per_object, fitted) = route_instances(scene, charts, relief, p);
    let ctx = CarveCtx {
        charts,
        fitted: &fitted,
        p,
    };
    let done: Vec<Result<Option<Done>, String>> = per_object
        .par_iter()
        .with_max_len(1)
        .enumerate()
        .map(|(oi, ks)| carve_building(&ctx, &scene.objects[oi], oi, ks))
        .collect();
    let mut out = scene.clone();
    let mut report = CarveReport::default();
    for d in done {
        let Some((oi, mesh, results, b)) = d? else {
            continue;
        };
        out.objects[oi].mesh = mesh;
        for (k, o) in results {
            outcomes[k] = o;
        }
        report.buildings.push(b);
    }
    report.outcomes = outcomes;
    Ok((out, report))
}

/// One carved building: its object index, its mesh, each of its instances' outcome, its report.
type Done = (usize, Mesh, Vec<(usize, CarveOutcome)>, CarvedBuilding);

/// What every building's carving reads: the charts, the fitted instances (by relief index) and
/// the parameters.
struct CarveCtx<'a> {
    charts: &'a ChartSet,
    fitted: &'a [Option<ReliefInstance>],
    p: &'a CarveParams,
}

/// The routing step, before any carving: fits each instance to its wall and files it under the
/// scene object its chart was made from. Returns the outcomes so far (instances that failed to
/// fit or whose building is not in the scene are dropped here), the instances of each object and
/// the fitted instances. A step of its own as it is serial and decides which buildings carve.
#[allow(clippy::type_complexity)]
fn route_instances(
    scene: &Scene,
    charts: &ChartSet,
    relief: &ReliefSet,
    p: &CarveParams,
) -> (
    Vec<CarveOutcome>,
    Vec<Vec<usize>>,
    Vec<Option<ReliefInstance>>,
) {
    let mut outcomes: Vec<CarveOutcome> = vec![CarveOutcome::Carved; relief.instances.len()];
    let mut per_object: Vec<Vec<usize>> = vec![Vec::new(); scene.objects.len()];
    let mut fitted: Vec<Option<ReliefInstance>> = vec![None; relief.instances.len()];
    for (k, inst) in relief.instances.iter().enumerate() {
        match fit_to_wall(inst, charts, p) {
            Ok(f) => fitted[k] = Some(f),
            Err(why) => {
                outcomes[k] = CarveOutcome::Dropped(DropKind::Fit, why);
                continue;
            }
        }
        let c = &charts.charts[inst.chart as usize];
        match scene.objects.get(c.object as usize) {
            Some(o) if o.id == c.building && o.class == ObjectClass::Building => {
                per_object[c.object as usize].push(k)
            }
            _ => {
                outcomes[k] = CarveOutcome::Dropped(
                    DropKind::Scene,
                    format!(
                        "the scene has no building {} at object {}: give CarveRelief the scene its charts were made from",
                        c.building, c.object
                    ),
                )
            }
        }
    }
    (outcomes, per_object, fitted)
}

/// Carves the instances `ks` into building `obj` (object `oi`): None when it has none. The
/// per-building step that runs in parallel: makes the solid, the prisms, then applies them all
/// at once or, when that fails, one at a time.
fn carve_building(
    ctx: &CarveCtx,
    obj: &SceneObject,
    oi: usize,
    ks: &[usize],
) -> Result<Option<Done>, String> {
    if ks.is_empty() {
        return Ok(None);
    }
    let wall_default = Material::Concrete;
    let base = match to_manifold(&obj.mesh) {
        Ok(b) => b,
        Err(e) => return Ok(Some(unsolid_building(obj, oi, ks, e))),
    };
    let (prisms, mut results) = building_prisms(ctx, obj, ks);
    let recess: Vec<&Manifold> = prisms.iter().filter(|p| p.1 < 0).map(|p| &p.2).collect();
    let protr: Vec<&Manifold> = prisms.iter().filter(|p| p.1 > 0).map(|p| &p.2).collect();
    let mesh = match apply(&base, &recess, &protr, wall_default) {
        Ok(m) => {
            results.extend(prisms.iter().map(|p| (p.0, CarveOutcome::Carved)));
            m
        }
        Err(_) => carve_one_at_a_time(ctx, obj, base, &prisms, &mut results)?,
    };
    let carved = results
        .iter()
        .filter(|r| r.1 == CarveOutcome::Carved)
        .count();
    let b = CarvedBuilding {
        id: obj.id.clone(),
        triangles_before: obj.mesh.len(),
        triangles_after: mesh.len(),
        carved,
        dropped: results.len() - carved,
    };
    Ok(Some((oi, mesh, results, b)))
}

/// The building whose mesh is not a solid Manifold takes (`e` why not): it stays as it is and
/// all its instances `ks` are dropped. A step of its own: the early way out of carving.
fn unsolid_building(obj: &SceneObject, oi: usize, ks: &[usize], e: String) -> Done {
    // Not a solid Manifold takes: the building stays as it is.
    let why = format!("{}: the building solid: {e}", obj.id);
    let results = ks
        .iter()
        .map(|&k| (k, CarveOutcome::Dropped(DropKind::Solid, why.clone())))
        .collect();
    let b = CarvedBuilding {
        id: obj.id.clone(),
        triangles_before: obj.mesh.len(),
        triangles_after: obj.mesh.len(),
        carved: 0,
        dropped: ks.len(),
    };
    (oi, obj.mesh.clone(), results, b)
}

/// A carved prism: the instance's relief index, its sign (< 0 recess, > 0 protrusion), its solid
/// and the wall material it takes.
type Prism = (usize, i8, Manifold, Material);

/// The prisms of building `obj`'s fitted instances `ks`, in their order, and the instances
/// dropped as their prism is no solid. The step that turns instances into solids.
fn building_prisms(
    ctx: &CarveCtx,
    obj: &SceneObject,
    ks: &[usize],
) -> (Vec<Prism>, Vec<(usize, CarveOutcome)>) {
    let mut prisms: Vec<Prism> = Vec::new();
    let mut results: Vec<(usize, CarveOutcome)> = Vec::new();
    for &k in ks {
        let Some(inst) = ctx.fitted[k].as_ref() else {
            continue;
        };
        let c = &ctx.charts.charts[inst.chart as usize];
        let wall = wall_material(inst, c, obj);
        let prism = instance_prism(inst, c.normal, wall, ctx.p);
        match to_manifold(&prism) {
            Ok(m) => prisms.push((k, inst.sign, m, wall)),
            Err(e) => results.push((
                k,
                CarveOutcome::Dropped(DropKind::Prism, format!("prism: {e}")),
            )),
        }
    }
    (prisms, results)
}

/// The wall's material: that of the chart's triangle under the instance's centre (concrete when
/// there is none). A step of its own: the only texel look-up of carving.
fn wall_material(inst: &ReliefInstance, c: &Chart, obj: &SceneObject) -> Material {
    let wall_default = Material::Concrete;
    // The wall's material: that of the chart's triangle under the instance's centre.
    let (cu, cv) = (
        ((inst.rect[0] + inst.rect[2]) / 2.0) as u32,
        ((inst.rect[1] + inst.rect[3]) / 2.0) as u32,
    );
    c.triangle_at
        .get(
            (cv.min(c.height.saturating_sub(1)) * c.width + cu.min(c.width.saturating_sub(1)))
                as usize,
        )
        .and_then(|&t| obj.mesh.materials.get(t as usize))
        .and_then(|&m| Material::from_u8(m))
        .unwrap_or(wall_default)
}

/// The fallback when all prisms at once fail the check: applies them one at a time to `base`,
/// keeping each whose result still checks (pushing every prism's outcome to `results`), and
/// returns the mesh. A step of its own: the slow, forgiving path.
fn carve_one_at_a_time(
    ctx: &CarveCtx,
    obj: &SceneObject,
    base: Manifold,
    prisms: &[Prism],
    results: &mut Vec<(usize, CarveOutcome)>,
) -> Result<Mesh, String> {
    // One at a time: keep each instance whose result still checks.
    let mut cur = base;
    let mut mesh = obj.mesh.clone();
    for (k, sign, pm, wall) in prisms {
        match apply_nudged(ctx, &cur, *k, *sign, pm, *wall) {
            Ok(m) => {
                cur = to_manifold(&m).map_err(|e| format!("{}: {e}", obj.id))?;
                mesh = m;
                results.push((*k, CarveOutcome::Carved));
            }
            Err(e) => results.push((*k, CarveOutcome::Dropped(DropKind::Check, e))),
        }
    }
    Ok(mesh)
}

/// Applies the single prism `pm` of instance `k` (sign `sign`, wall `wall`) to `cur`; when the
/// result fails the check, retries with the prism drawn in by each of NUDGES_M in turn. The step
/// that applies one instance in the fallback.
fn apply_nudged(
    ctx: &CarveCtx,
    cur: &Manifold,
    k: usize,
    sign: i8,
    pm: &Manifold,
    wall: Material,
) -> Result<Mesh, String> {
    let wall_default = Material::Concrete;
    let p = ctx.p;
    let one = |pm: &Manifold| {
        let (r, pr): (Vec<&Manifold>, Vec<&Manifold>) = if sign < 0 {
            (vec![pm], vec![])
        } else {
            (vec![], vec![pm])
        };
        apply(cur, &r, &pr, wall_default)
    };
    // A result that fails the check mostly does so where f32 rounding
    // lets a corner through a face another feature left a hair away:
    // the prism drawn in by a few millimetres misses that coincidence.
    let mut tried = one(pm);
    for nudge in NUDGES_M {
        if tried.is_ok() {
            break;
        }
        // Prisms are made of fitted instances only.
        let Some(inst) = ctx.fitted[k].as_ref() else {
            break;
        };
        let c = &ctx.charts.charts[inst.chart as usize];
        let Some(inset) = drawn_in(inst, c, nudge, p) else {
            break;
        };
        let q = CarveParams {
            overshoot_m: p.overshoot_m + nudge,
            ..p.clone()
        };
        let prism = instance_prism(&inset, c.normal, wall, &q);
        if let Ok(m) = to_manifold(&prism)
            && let Ok(r) = one(&m)
        {
            tried = Ok(r);
        }
    }
    tried
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Chart;

    /// A 2 m x 3 m wall of 0.1 m texels, its top right corner off the wall (under a gable's
    /// slope, say): columns 15 and up from row 25 up.
    fn wall() -> ChartSet {
        let mut c = Chart::flat_wall(20, 30);
        for (k, t) in c.triangle_at.0.iter_mut().enumerate() {
            if k % 20 >= 15 && k / 20 >= 25 {
                *t = u32::MAX;
            }
        }
        ChartSet { charts: vec![c] }
    }

    fn instance(rect: [f64; 4]) -> ReliefInstance {
        let c = &wall().charts[0];
        ReliefInstance {
            chart: 0,
            building: "building-0".into(),
            sign: 1,
            class: "drainpipe".into(),
            rect,
            corners: [
                c.world_of(rect[0], rect[1]),
                c.world_of(rect[2], rect[1]),
                c.world_of(rect[2], rect[3]),
                c.world_of(rect[0], rect[3]),
            ],
            depth_m: 0.12,
            measured_depth_m: Some(0.12),
            posterior: 0.8,
            exposure: 5.0,
            texels: 300,
            views: 2,
            delta_agreement: None,
        }
    }

    #[test]
    fn an_instance_past_its_wall_is_trimmed_to_it_not_dropped() {
        let (charts, p) = (wall(), CarveParams::default());
        // A downpipe the relief runs from the ground to the eave: the margin off each end.
        let f = fit_to_wall(&instance([5.0, 0.0, 6.2, 30.0]), &charts, &p).unwrap();
        assert_eq!(f.rect, [5.0, 0.5, 6.2, 29.5]);
        let top = f.corners[2];
        assert!((top[0] - 0.62).abs() < 1e-12 && (top[2] - 2.95).abs() < 1e-12);
        // Into the corner off the wall: cut below it (4 x 4.5 texels) rather than beside it
        // (0.5 x 9.5).
        let f = fit_to_wall(&instance([14.0, 20.0, 18.0, 30.0]), &charts, &p).unwrap();
        assert_eq!(f.rect, [14.0, 20.0, 18.0, 24.5]);
        // Inside the wall: untouched.
        let inside = instance([3.0, 3.0, 8.0, 9.0]);
        assert_eq!(fit_to_wall(&inside, &charts, &p).unwrap(), inside);
        // Wholly off it, or trimmed under the minimum size: dropped.
        assert!(fit_to_wall(&instance([16.0, 26.0, 19.0, 29.0]), &charts, &p).is_err());
        let sliver = fit_to_wall(&instance([0.0, 5.0, 0.8, 9.0]), &charts, &p);
        assert!(sliver.is_err_and(|e| e.contains("under the 0.05 m minimum")));
    }

    #[test]
    fn drawn_in_keeps_the_centre_and_the_wall_and_stops_at_the_minimum() {
        let (charts, p) = (wall(), CarveParams::default());
        let c = &charts.charts[0];
        let inst = instance([3.0, 3.0, 8.0, 9.0]);
        let d = drawn_in(&inst, c, 0.01, &p).unwrap();
        // 0.01 m is a tenth of a 0.1 m texel on every side.
        let want = [3.1, 3.1, 7.9, 8.9];
        assert!(d.rect.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12));
        for (got, (u, v)) in d
            .corners
            .iter()
            .zip([(3.1, 3.1), (7.9, 3.1), (7.9, 8.9), (3.1, 8.9)])
        {
            let w = c.world_of(u, v);
            assert!(
                (0..3).all(|a| (got[a] - w[a]).abs() < 1e-12),
                "{got:?} {w:?}"
            );
        }
        // A 0.06 m wide instance drawn in by 0.01 m a side is under the 0.05 m minimum.
        assert!(drawn_in(&instance([3.0, 3.0, 3.6, 9.0]), c, 0.01, &p).is_none());
        assert!(drawn_in(&instance([3.0, 3.0, 3.8, 9.0]), c, 0.01, &p).is_some());
    }

    #[test]
    fn the_report_counts_each_outcome_by_kind_and_class() {
        let mut window = instance([3.0, 3.0, 8.0, 9.0]);
        (window.class, window.sign) = ("window".into(), -1);
        let relief = ReliefSet {
            instances: vec![
                instance([5.0, 0.0, 6.2, 30.0]),
                window,
                instance([16.0, 26.0, 19.0, 29.0]),
            ],
            ..ReliefSet::default()
        };
        let report = CarveReport {
            outcomes: vec![
                CarveOutcome::Carved,
                CarveOutcome::Dropped(DropKind::Check, "intersecting triangles".into()),
                CarveOutcome::Dropped(DropKind::Fit, "no part of it lies on the wall".into()),
            ],
            buildings: vec![CarvedBuilding {
                id: "building-0".into(),
                triangles_before: 12,
                triangles_after: 40,
                carved: 1,
                dropped: 1,
            }],
        };
        let m = report.metrics(&relief);
        let get = |k: &str| m.get(k).unwrap_or_else(|| panic!("{k} missing: {m:?}"));
        assert_eq!(
            [get("instances"), get("carved"), get("dropped")],
            [3.0, 1.0, 2.0]
        );
        assert_eq!(
            DropKind::ALL.map(|k| get(&format!("dropped/{}", k.name()))),
            [1.0, 0.0, 0.0, 0.0, 1.0]
        );
        assert_eq!(
            [get("instances/drainpipe"), get("carved/drainpipe")],
            [2.0, 1.0]
        );
        assert_eq!([get("instances/window"), get("carved/window")], [1.0, 0.0]);
        assert_eq!(
            [
                get("buildings"),
                get("triangles_before"),
                get("triangles_after")
            ],
            [1.0, 12.0, 40.0]
        );
    }
}
