//! The synthetic city's ground truth as a scene: closed building solids with their roof shapes,
//! tree crowns as foliage volumes, clutter, on a terrain surface.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, City, Mesh, ObjectClass, Roof, Scene, SceneObject};
use crate::materials::Material;
use crate::mesh_build::{cuboid, dome, ellipsoid, gabled, height_surface, hipped, prism};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::synth_terrain::height_at;

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
    const VERSION: u32 = 1;
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
        for b in &city.buildings {
            let mesh =
                building_mesh(b).map_err(|m| StageError::Failed(format!("{}: {m}", b.id)))?;
            scene.objects.push(SceneObject {
                id: b.id.clone(),
                class: ObjectClass::Building,
                mesh,
            });
            ctx.progress.advance(1);
        }
        for t in &city.trees {
            let mut mesh = cuboid(
                t.pos,
                [0.35, 0.35, t.trunk_m + 0.5],
                0.0,
                t.ground_z - 0.5,
                Material::Wood,
            );
            let cz = t.ground_z + t.trunk_m + t.crown_m / 2.0;
            mesh.append(&ellipsoid(
                [t.pos[0], t.pos[1], cz],
                [t.crown_radius_m, t.crown_radius_m, t.crown_m / 2.0],
                16,
                Material::Foliage,
            ));
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

/// The closed shells of one building: the main body with its roof, a stepped tier or dome, and
/// roof furniture. Upper parts start 0.05 m inside the body so no two shells share a face.
pub fn building_mesh(b: &crate::artifact::BuildingSpec) -> Result<Mesh, String> {
    let eave = b.ground_z + b.eave_m;
    const EMBED: f64 = 0.05;
    let mut mesh = match &b.roof {
        Roof::Gabled { rect, ridge_m } => gabled(
            rect.corner,
            rect.length,
            rect.width,
            rect.heading,
            b.base_z,
            eave,
            eave + ridge_m,
            b.facade,
            b.roof_material,
        ),
        Roof::Hipped { rect, ridge_m } => hipped(
            rect.corner,
            rect.length,
            rect.width,
            rect.heading,
            b.base_z,
            eave,
            eave + ridge_m,
            b.facade,
            b.roof_material,
        ),
        _ => prism(&b.footprint, b.base_z, eave, b.facade, b.roof_material)?,
    };
    match &b.roof {
        Roof::Stepped { upper, upper_m } => mesh.append(&prism(
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
        } => mesh.append(&dome(
            *center,
            *radius_m,
            height_m + EMBED,
            eave - EMBED,
            32,
            Material::Metal,
        )),
        _ => {}
    }
    for f in &b.furniture {
        mesh.append(&cuboid(
            f.center,
            [f.size[0], f.size[1], f.size[2] + EMBED],
            0.0,
            eave - EMBED,
            Material::Metal,
        ));
    }
    Ok(mesh)
}
