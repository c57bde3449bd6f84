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

use crate::artifact::{ChartSet, Mesh, ObjectClass, ReliefInstance, ReliefSet, Scene};
use crate::geom::boolean::{subtract_then_add as apply, to_manifold};
use crate::geom::mesh_build::quad_prism;
use crate::rf::materials::Material;

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
    /// Left out, and why.
    Dropped(String),
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

/// Why an instance cannot become a prism on its wall, if it cannot.
fn precheck(inst: &ReliefInstance, charts: &ChartSet, p: &CarveParams) -> Option<String> {
    let Some(c) = charts.charts.get(inst.chart as usize) else {
        return Some(format!("chart {} is not in the chart set", inst.chart));
    };
    if c.building != inst.building {
        return Some(format!(
            "chart {} is on {}, not {}",
            inst.chart, c.building, inst.building
        ));
    }
    let [u0, v0, u1, v1] = inst.rect;
    let (wu, wv) = ((u1 - u0) * c.texel_m, (v1 - v0) * c.texel_m);
    if !(wu >= p.min_size_m && wv >= p.min_size_m) {
        return Some(format!(
            "{wu:.3} x {wv:.3} m is under the {} m minimum",
            p.min_size_m
        ));
    }
    if !(inst.depth_m > 0.0 && inst.depth_m.is_finite()) {
        return Some(format!("depth {} m", inst.depth_m));
    }
    // The rectangle, widened by the margin, must lie on the wall: every texel under it covered.
    let m = p.margin_m / c.texel_m;
    let (i0, j0) = ((u0 - m).floor(), (v0 - m).floor());
    let (i1, j1) = ((u1 + m).ceil(), (v1 + m).ceil());
    if i0 < 0.0 || j0 < 0.0 || i1 > c.width as f64 || j1 > c.height as f64 {
        return Some("within the margin of the wall's edge".into());
    }
    for j in j0 as u32..j1 as u32 {
        for i in i0 as u32..i1 as u32 {
            if c.triangle_at[(j * c.width + i) as usize] == u32::MAX {
                return Some("reaches off the wall (or within the margin of its edge)".into());
            }
        }
    }
    None
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
    let mut outcomes: Vec<CarveOutcome> = vec![CarveOutcome::Carved; relief.instances.len()];
    let mut per_object: Vec<Vec<usize>> = vec![Vec::new(); scene.objects.len()];
    for (k, inst) in relief.instances.iter().enumerate() {
        if let Some(why) = precheck(inst, charts, p) {
            outcomes[k] = CarveOutcome::Dropped(why);
            continue;
        }
        let c = &charts.charts[inst.chart as usize];
        match scene.objects.get(c.object as usize) {
            Some(o) if o.id == c.building && o.class == ObjectClass::Building => {
                per_object[c.object as usize].push(k)
            }
            _ => {
                outcomes[k] = CarveOutcome::Dropped(format!(
                    "the scene has no building {} at object {}: give CarveRelief the scene its charts were made from",
                    c.building, c.object
                ))
            }
        }
    }
    type Done = (usize, Mesh, Vec<(usize, CarveOutcome)>, CarvedBuilding);
    let done: Vec<Result<Option<Done>, String>> = per_object
        .par_iter()
        .enumerate()
        .map(|(oi, ks)| {
            if ks.is_empty() {
                return Ok(None);
            }
            let obj = &scene.objects[oi];
            let wall_default = Material::Concrete;
            let base = match to_manifold(&obj.mesh) {
                Ok(b) => b,
                Err(e) => {
                    // Not a solid Manifold takes: the building stays as it is.
                    let why = format!("{}: the building solid: {e}", obj.id);
                    let results = ks
                        .iter()
                        .map(|&k| (k, CarveOutcome::Dropped(why.clone())))
                        .collect();
                    let b = CarvedBuilding {
                        id: obj.id.clone(),
                        triangles_before: obj.mesh.len(),
                        triangles_after: obj.mesh.len(),
                        carved: 0,
                        dropped: ks.len(),
                    };
                    return Ok(Some((oi, obj.mesh.clone(), results, b)));
                }
            };
            let mut prisms: Vec<(usize, i8, Manifold)> = Vec::new();
            let mut results: Vec<(usize, CarveOutcome)> = Vec::new();
            for &k in ks {
                let inst = &relief.instances[k];
                let c = &charts.charts[inst.chart as usize];
                // The wall's material: that of the chart's triangle under the instance's centre.
                let (cu, cv) = (
                    ((inst.rect[0] + inst.rect[2]) / 2.0) as u32,
                    ((inst.rect[1] + inst.rect[3]) / 2.0) as u32,
                );
                let wall = c
                    .triangle_at
                    .get(
                        (cv.min(c.height.saturating_sub(1)) * c.width
                            + cu.min(c.width.saturating_sub(1))) as usize,
                    )
                    .and_then(|&t| obj.mesh.materials.get(t as usize))
                    .and_then(|&m| Material::from_u8(m))
                    .unwrap_or(wall_default);
                let prism = instance_prism(inst, c.normal, wall, p);
                match to_manifold(&prism) {
                    Ok(m) => prisms.push((k, inst.sign, m)),
                    Err(e) => results.push((k, CarveOutcome::Dropped(format!("prism: {e}")))),
                }
            }
            let recess: Vec<&Manifold> = prisms.iter().filter(|p| p.1 < 0).map(|p| &p.2).collect();
            let protr: Vec<&Manifold> = prisms.iter().filter(|p| p.1 > 0).map(|p| &p.2).collect();
            let mesh = match apply(&base, &recess, &protr, wall_default) {
                Ok(m) => {
                    results.extend(prisms.iter().map(|p| (p.0, CarveOutcome::Carved)));
                    m
                }
                Err(_) => {
                    // One at a time: keep each instance whose result still checks.
                    let mut cur = base.clone();
                    let mut mesh = obj.mesh.clone();
                    for (k, sign, pm) in &prisms {
                        let (r, pr): (Vec<&Manifold>, Vec<&Manifold>) = if *sign < 0 {
                            (vec![pm], vec![])
                        } else {
                            (vec![], vec![pm])
                        };
                        match apply(&cur, &r, &pr, wall_default) {
                            Ok(m) => {
                                cur = to_manifold(&m).map_err(|e| format!("{}: {e}", obj.id))?;
                                mesh = m;
                                results.push((*k, CarveOutcome::Carved));
                            }
                            Err(e) => results.push((*k, CarveOutcome::Dropped(e))),
                        }
                    }
                    mesh
                }
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
        })
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
