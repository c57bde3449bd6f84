//! The synthetic city's ground truth as a scene: one closed solid per building (roof shape, roof
//! furniture and façade relief merged by Booleans), tree crowns as foliage volumes, clutter, on a
//! terrain surface.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::height_at;
use crate::artifact::{
    ArtifactType, BuildingSpec, City, CrownShape, FeatureKind, Mesh, ObjectClass, Rect, Roof,
    Scene, SceneObject,
};
use crate::geom::boolean::{subtract_then_add, to_manifold};
use crate::geom::mesh_build::{
    cone, cuboid, dome, ellipsoid, gabled, height_surface, hipped, prism, quad_prism,
};
use crate::geom::mesh_check::check_solid;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`TruthScene`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TruthSceneParams {
    /// Terrain mesh spacing, metres. Default 2.
    pub terrain_step_m: f64,
    /// Ground material. Default MediumDryGround.
    pub ground: Material,
}

impl Default for TruthSceneParams {
    fn default() -> Self {
        TruthSceneParams {
            terrain_step_m: 2.0,
            ground: Material::MediumDryGround,
        }
    }
}

/// Meshes a [`City`].
pub struct TruthScene;

impl Stage for TruthScene {
    const KIND: &'static str = "TruthScene";
    // 2: one solid per building, merged by Booleans (no stacked shells). 3: bay windows (a
    // window standing out of its wall) and the roof's inset from each building's own recesses;
    // conical crowns.
    const VERSION: u32 = 3;
    const DOC: &'static str =
        "ground-truth scene of a synthetic city: terrain, closed buildings, foliage, clutter";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "city",
        ArtifactType::City,
        "the synthetic city",
    )];
    type Params = TruthSceneParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.terrain_step_m >= 0.25) {
            return Err(ParamError::new(
                "terrain_step_m",
                "expected at least 0.25 m",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        let city: &City = inputs.one("city")?;
        ctx.progress.set_total(city.buildings.len() as u64 + 1);
        let mut scene = Scene::default();
        let nx = (city.size_m.0 / p.terrain_step_m).ceil() as u32 + 1;
        let ny = (city.size_m.1 / p.terrain_step_m).ceil() as u32 + 1;
        let terrain = height_surface(
            [0.0, 0.0],
            nx,
            ny,
            p.terrain_step_m,
            |x, y| height_at(&city.terrain, x, y),
            p.ground,
        );
        scene.objects.push(SceneObject {
            id: "terrain".into(),
            class: ObjectClass::Terrain,
            mesh: terrain,
        });
        ctx.progress.advance(1);
        // Each building's Booleans are its own: in parallel, collected in the city's order.
        let meshes: Vec<(Mesh, Relief)> = city
            .buildings
            .par_iter()
            .with_max_len(1)
            .map(|b| {
                let mesh =
                    building_solid(b).map_err(|m| StageError::Failed(format!("{}: {m}", b.id)));
                ctx.progress.advance(1);
                mesh
            })
            .collect::<Result<_, _>>()?;
        for (kept, what) in [
            (
                Relief::PlainWalls,
                "kept plain walls (their façade relief's Booleans failed the solid check)",
            ),
            (
                Relief::PlainBody,
                "kept their plain body (their roof parts' Booleans failed the solid check too)",
            ),
        ] {
            let ids: Vec<&str> = city
                .buildings
                .iter()
                .zip(&meshes)
                .filter(|(_, (_, r))| *r == kept)
                .map(|(b, _)| b.id.as_str())
                .collect();
            if !ids.is_empty() {
                ctx.progress.warn(&format!(
                    "{} of {} buildings {what}: {}",
                    ids.len(),
                    city.buildings.len(),
                    crate::stage::named_few(&ids)
                ));
            }
        }
        for (b, (mesh, _)) in city.buildings.iter().zip(meshes) {
            scene.objects.push(SceneObject {
                id: b.id.clone(),
                class: ObjectClass::Building,
                mesh,
            });
        }
        for t in &city.trees {
            let mut mesh = cuboid(
                t.pos,
                [0.35, 0.35, t.trunk_m + 0.5],
                0.0,
                t.ground_z - 0.5,
                Material::Wood,
            );
            let base = t.ground_z + t.trunk_m;
            mesh.append(&match t.crown {
                CrownShape::Ellipsoid => ellipsoid(
                    [t.pos[0], t.pos[1], base + t.crown_m / 2.0],
                    [t.crown_radius_m, t.crown_radius_m, t.crown_m / 2.0],
                    16,
                    Material::Foliage,
                ),
                CrownShape::Cone => cone(
                    t.pos,
                    t.crown_radius_m,
                    base,
                    t.crown_m,
                    16,
                    Material::Foliage,
                ),
            });
            scene.objects.push(SceneObject {
                id: t.id.clone(),
                class: ObjectClass::Vegetation,
                mesh,
            });
        }
        for c in &city.clutter {
            // Bodies sink 0.2 m into the ground so sloped terrain leaves no gap underneath.
            let z0 = c.ground_z + c.lift_m - if c.lift_m > 0.0 { 0.0 } else { 0.2 };
            let size = [
                c.size[0],
                c.size[1],
                c.size[2] + if c.lift_m > 0.0 { 0.0 } else { 0.2 },
            ];
            scene.objects.push(SceneObject {
                id: c.id.clone(),
                class: ObjectClass::Clutter,
                mesh: cuboid(c.center, size, c.heading, z0, c.material),
            });
        }
        Ok(scene)
    }
}

/// The truth's terrain and every building's outline extruded from its base to the eave: the
/// walls the street views look at, without relief, roof shapes or clutter. What fusion is scored
/// on, so the score is the operator's and not the building reconstruction's.
pub fn wall_prisms(city: &City, truth: &Scene) -> Result<Scene, String> {
    let mut objects: Vec<SceneObject> = truth
        .objects
        .iter()
        .filter(|o| o.class == ObjectClass::Terrain)
        .cloned()
        .collect();
    for b in &city.buildings {
        objects.push(SceneObject {
            id: b.id.clone(),
            class: ObjectClass::Building,
            mesh: prism(
                &b.footprint,
                b.base_z,
                b.ground_z + b.eave_m,
                b.facade,
                b.roof_material,
            )
            .map_err(|e| format!("{}: {e}", b.id))?,
        });
    }
    Ok(Scene { objects })
}

/// How far parts that touch start inside each other, metres, so the Booleans cut cleanly.
const EMBED: f64 = 0.05;

/// One building as one closed solid: the body with its roof, a stepped tier or dome, roof
/// furniture and façade relief, merged by exact Booleans (`geom::boolean`). One envelope, as a
/// real building has: a wave crossing a wall crosses one slab, and a flat façade has no edge
/// where two parts happen to meet. Parts that touch overlap by [`EMBED`].
pub fn building_mesh(b: &BuildingSpec) -> Result<Mesh, String> {
    building_solid(b).map(|(mesh, _)| mesh)
}

/// What of a building's relief its solid kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Relief {
    /// Everything: the façade relief and the roof parts.
    Whole,
    /// The roof parts but not the façade relief.
    PlainWalls,
    /// Neither: the plain body.
    PlainBody,
}

/// [`building_mesh`], and what of the relief it kept.
pub fn building_solid(b: &BuildingSpec) -> Result<(Mesh, Relief), String> {
    let eave = b.ground_z + b.eave_m;
    let mut parts: Vec<Mesh> = Vec::new();
    match &b.roof {
        Roof::Gabled { rect, ridge_m } | Roof::Hipped { rect, ridge_m } => {
            // With façade relief the roof sits back by the recess depth: the walls' outer layer
            // (the depth of the openings) stops at the eave around it.
            let d = b.recess_depth_m();
            let r = inset_rect(rect, d);
            let roof = if matches!(b.roof, Roof::Gabled { .. }) {
                gabled
            } else {
                hipped
            };
            parts.push(roof(
                &r,
                eave - EMBED,
                eave,
                eave + ridge_m,
                b.facade,
                b.roof_material,
            ));
        }
        Roof::Stepped { upper, upper_m } => parts.push(prism(
            upper,
            eave - EMBED,
            eave + upper_m,
            b.facade,
            b.roof_material,
        )?),
        Roof::Domed {
            center,
            radius_m,
            height_m,
        } => parts.push(dome(
            *center,
            *radius_m,
            height_m + EMBED,
            eave - EMBED,
            32,
            Material::Metal,
        )),
        Roof::Flat => {}
    }
    for f in &b.furniture {
        parts.push(cuboid(
            f.center,
            [f.size[0], f.size[1], f.size[2] + EMBED],
            0.0,
            eave - EMBED,
            Material::Metal,
        ));
    }
    let body = prism(&b.footprint, b.base_z, eave, b.facade, b.roof_material)?;
    let (recesses, protrusions) = facade_relief(b);
    let with_relief = |relief: bool| {
        let mut all = parts.clone();
        let mut cut: &[Mesh] = &[];
        if relief {
            all.extend(protrusions.iter().cloned());
            cut = &recesses;
        }
        join(&body, cut, &all, b.facade)
    };
    // Rarely (a building in several thousand), the Booleans leave an edge or a crossing the
    // solid check refuses; the truth then keeps that building's plain walls, and failing that
    // its plain body, rather than a bad solid.
    with_relief(true)
        .map(|m| (m, Relief::Whole))
        .or_else(|e| {
            with_relief(false)
                .map(|m| (m, Relief::PlainWalls))
                .map_err(|_| e)
        })
        .or_else(|e| {
            check_solid(&body)
                .map(|_| (body.clone(), Relief::PlainBody))
                .map_err(|_| e)
        })
}

/// `body` less `recesses`, plus `parts`, by exact Booleans; `body` itself when there is nothing
/// to join.
fn join(
    body: &Mesh,
    recesses: &[Mesh],
    parts: &[Mesh],
    fallback: Material,
) -> Result<Mesh, String> {
    if parts.is_empty() && recesses.is_empty() {
        return Ok(body.clone());
    }
    let base = to_manifold(body)?;
    let recesses = recesses
        .iter()
        .map(to_manifold)
        .collect::<Result<Vec<_>, _>>()?;
    let parts = parts
        .iter()
        .map(to_manifold)
        .collect::<Result<Vec<_>, _>>()?;
    subtract_then_add(
        &base,
        &recesses.iter().collect::<Vec<_>>(),
        &parts.iter().collect::<Vec<_>>(),
        fallback,
    )
}

/// The façade relief of `b` as prisms on its walls: the recesses (windows glazed and doors hung
/// at their backs, reveals of the façade material) and the protrusions (balconies with their
/// railings, drainpipes).
fn facade_relief(b: &BuildingSpec) -> (Vec<Mesh>, Vec<Mesh>) {
    const DOOR_SET_BACK_M: f64 = 0.05;
    let (mut recesses, mut protrusions) = (Vec::new(), Vec::new());
    let rings: Vec<&Vec<[f64; 2]>> = std::iter::once(&b.footprint.exterior)
        .chain(&b.footprint.holes)
        .collect();
    for f in &b.features {
        let Some(ring) = rings.get(f.ring) else {
            continue;
        };
        let n = ring.len();
        if n < 2 {
            continue;
        }
        let (a, c) = (ring[f.edge % n], ring[(f.edge + 1) % n]);
        let len = (c[0] - a[0]).hypot(c[1] - a[1]);
        if !(len > 0.0) {
            continue;
        }
        let t = [(c[0] - a[0]) / len, (c[1] - a[1]) / len];
        // The solid is left of every ring edge (exterior counter-clockwise, holes clockwise):
        // the wall's outward normal is t turned clockwise.
        let out = [t[1], -t[0], 0.0];
        // Counter-clockwise seen from outside: along the edge, then up.
        let on_wall = |z: (f64, f64)| -> [[f64; 3]; 4] {
            let p = |s: f64, z: f64| [a[0] + t[0] * s, a[1] + t[1] * s, z];
            [
                p(f.along.0, z.0),
                p(f.along.1, z.0),
                p(f.along.1, z.1),
                p(f.along.0, z.1),
            ]
        };
        let box_on = |z: (f64, f64), reach: (f64, f64), m: [Material; 3]| {
            quad_prism(on_wall(z), out, reach, m)
        };
        match f.kind {
            // A bay window stands out of the wall, glazed at its front.
            FeatureKind::Window if f.depth_m > 0.0 => protrusions.push(box_on(
                f.z,
                (-EMBED, f.depth_m),
                [b.facade, b.facade, Material::Glass],
            )),
            FeatureKind::Window => recesses.push(box_on(
                f.z,
                (f.depth_m.min(-EMBED), EMBED),
                [Material::Glass, b.facade, b.facade],
            )),
            FeatureKind::Door => recesses.push(box_on(
                f.z,
                ((f.depth_m + DOOR_SET_BACK_M).min(-EMBED), EMBED),
                [Material::Wood, b.facade, b.facade],
            )),
            FeatureKind::Balcony => {
                let slab = (f.z.0, f.z.0 + 0.15);
                protrusions.push(box_on(slab, (-EMBED, f.depth_m), [Material::Concrete; 3]));
                protrusions.push(box_on(
                    (slab.1 - EMBED, f.z.1),
                    (f.depth_m - 0.05, f.depth_m),
                    [Material::Metal; 3],
                ));
            }
            FeatureKind::Drainpipe => {
                protrusions.push(box_on(f.z, (-EMBED, f.depth_m), [Material::Metal; 3]))
            }
        }
    }
    (recesses, protrusions)
}

/// The rectangle shrunk by `d` on every side.
fn inset_rect(r: &Rect, d: f64) -> Rect {
    let (s, c) = r.heading.sin_cos();
    Rect {
        corner: [r.corner[0] + c * d - s * d, r.corner[1] + s * d + c * d],
        length: r.length - 2.0 * d,
        width: r.width - 2.0 * d,
        heading: r.heading,
    }
}
