//! Scene assembly: the terrain as a mesh plus the objects of the other stages (building solids,
//! later vegetation and clutter), each with a stable id, a semantic class and per-triangle ITU
//! materials, ready for tracing and export.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Metrics, ObjectClass, Raster, Scene, Typed};
use crate::artifact::{Material, default_material};
use crate::geom::mesh_check::{OnInvalid, check_solid};
use crate::geom::terrain_mesh::terrain_object;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, ReportSpec, Reported, Stage, StageError};

/// Params of [`AssembleScene`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AssembleSceneParams {
    /// Spacing of the terrain mesh's vertices, metres; `None` uses the terrain raster's cell.
    /// Default 2 (0.5 m terrain rasters would give millions of triangles for little RF effect).
    pub terrain_step_m: Option<f64>,
    /// Material of the terrain. Default the terrain class's: medium dry ground.
    pub terrain_material: Material,
    /// A building that fails the solid check: `Fail` (default: a bad solid from our own stages
    /// is a bug to see) or `Drop` (left out, counted in the report `counts` and warned about).
    /// Repairs belong to the stage that made the solid (OsmBaseline's `on_invalid`).
    pub on_invalid: OnInvalid,
}

impl Default for AssembleSceneParams {
    fn default() -> Self {
        AssembleSceneParams {
            terrain_step_m: Some(2.0),
            terrain_material: default_material(ObjectClass::Terrain),
            on_invalid: OnInvalid::Fail,
        }
    }
}

/// `terrain` first, then every object of every input scene in order; building solids are checked
/// again, ids must be unique.
pub struct AssembleScene;

impl Stage for AssembleScene {
    const KIND: &'static str = "AssembleScene";
    // 2: `on_invalid` (Fail or Drop) and the report `counts`.
    const VERSION: u32 = 2;
    const DOC: &'static str = "the RF scene: terrain mesh + objects (buildings, vegetation, clutter) with ids, classes and ITU materials";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("terrain", ArtifactType::Raster, "the terrain T"),
        InputSpec::many(
            "objects",
            ArtifactType::Scene,
            "scenes whose objects join the terrain (building solids, clutter, canopies; a terrain among them is replaced)",
        ),
    ];
    type Params = AssembleSceneParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        match p.terrain_step_m {
            Some(s) if !(s > 0.0 && s.is_finite()) => Err(ParamError::new(
                "terrain_step_m",
                "expected a positive spacing in metres",
            )),
            _ => Ok(()),
        }
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        Ok(assemble(p, inputs, ctx)?.0)
    }

    const REPORTS: &'static [ReportSpec] = &[ReportSpec {
        name: "counts",
        ty: ArtifactType::Metrics,
        doc: "objects in the scene by class, and buildings dropped for failing the solid check",
    }];

    fn run_reported(
        p: &Self::Params,
        inputs: &Inputs,
        ctx: &Ctx,
    ) -> Result<Reported<Scene>, StageError> {
        let (scene, dropped) = assemble(p, inputs, ctx)?;
        let mut m = Metrics::default();
        m.set("objects", scene.objects.len() as f64);
        for class in [
            ObjectClass::Terrain,
            ObjectClass::Building,
            ObjectClass::Vegetation,
            ObjectClass::Clutter,
            ObjectClass::Unsegmented,
        ] {
            let n = scene.objects.iter().filter(|o| o.class == class).count();
            m.set(format!("objects/{}", class_name(class)), n as f64);
        }
        m.set("buildings_dropped", dropped as f64);
        Ok(Reported {
            output: scene,
            reports: vec![("counts", m.into_artifact())],
        })
    }
}

/// The lower-case name of a class, for metric names.
fn class_name(c: ObjectClass) -> String {
    format!("{c:?}").to_lowercase()
}

/// The scene and how many buildings were dropped.
fn assemble(
    p: &AssembleSceneParams,
    inputs: &Inputs,
    ctx: &Ctx,
) -> Result<(Scene, usize), StageError> {
    let terrain: &Raster = inputs.one("terrain")?;
    let scenes: Vec<&Scene> = inputs.many("objects")?;
    let ground = terrain_object(
        terrain,
        p.terrain_step_m.unwrap_or(terrain.grid.cell_m),
        p.terrain_material,
    )
    .map_err(StageError::Failed)?;
    let mut ids: BTreeSet<String> = BTreeSet::from([ground.id.clone()]);
    let mut objects = vec![ground];
    let total: usize = scenes.iter().map(|s| s.objects.len()).sum();
    ctx.progress.set_total(total as u64);
    let mut dropped: Vec<String> = Vec::new();
    // A terrain inside an input scene (one carved or painted from a whole scene) gives way
    // to the mesh of `terrain`.
    for o in scenes
        .iter()
        .flat_map(|s| &s.objects)
        .filter(|o| o.class != ObjectClass::Terrain)
    {
        ctx.progress.advance(1);
        if !ids.insert(o.id.clone()) {
            return Err(StageError::Failed(format!(
                "two objects are called {:?}: give each input scene distinct ids",
                o.id
            )));
        }
        if o.class == ObjectClass::Building
            && let Err(e) = check_solid(&o.mesh)
        {
            let why = format!("{}: {e}", o.id);
            if p.on_invalid == OnInvalid::Fail {
                return Err(StageError::Failed(format!(
                    "{why} (on_invalid: Drop leaves such buildings out, counted)"
                )));
            }
            dropped.push(why);
            continue;
        }
        objects.push(o.clone());
    }
    if !dropped.is_empty() {
        ctx.progress.warn(&format!(
            "{} buildings are not valid solids and were left out (first: {})",
            dropped.len(),
            dropped[..dropped.len().min(3)].join("; ")
        ));
    }
    Ok((Scene { objects }, dropped.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Grid, PodVec};
    use crate::geom::terrain_mesh::terrain_mesh;

    #[test]
    fn the_terrain_mesh_covers_the_raster_and_follows_it() {
        let g = Grid {
            x0: 10.0,
            y0: 50.0,
            cell_m: 1.0,
            width: 7,
            height: 5,
        };
        let mut data: Vec<f32> = (0..35).map(|i| (i % 7) as f32 * 0.5).collect();
        data[12] = f32::NAN;
        let r = Raster {
            grid: g,
            data: PodVec(data),
        };
        let m = terrain_mesh(&r, 2.0, Material::WetGround).unwrap();
        let (lo, hi) = m
            .positions
            .iter()
            .fold(([f32::MAX; 3], [f32::MIN; 3]), |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1]), lo[2].min(p[2])],
                    [hi[0].max(p[0]), hi[1].max(p[1]), hi[2].max(p[2])],
                )
            });
        assert_eq!((lo[0], lo[1], hi[0], hi[1]), (10.0, 45.0, 17.0, 50.0));
        assert!(lo[2] >= 0.0 && hi[2] <= 3.0, "{lo:?} {hi:?}");
        assert!(m.materials.iter().all(|&k| k == Material::WetGround as u8));
    }
}
