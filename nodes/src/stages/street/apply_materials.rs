//! ApplyMaterials: the per-texel materials of FuseMaterials written into the scene as
//! per-triangle materials (paper Sec. 4.2.3): chart triangles split along material boundaries,
//! every building checked closed and manifold afterwards.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, ChartSet, MaterialLayers, ObjectClass, Scene};
use crate::geom::mesh_check::check_solid;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::street::materials::apply::{ApplySpec, apply_materials};

/// Params of [`ApplyMaterials`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ApplyMaterialsParams {
    /// Material regions smaller than this (m²) join their most common neighbour. Default 0.16.
    pub min_region_m2: f64,
    /// Region boundaries closer than this (metres) merge into one cut. Default 0.2.
    pub snap_m: f64,
}

impl Default for ApplyMaterialsParams {
    fn default() -> Self {
        let s = ApplySpec::default();
        ApplyMaterialsParams {
            min_region_m2: s.min_region_m2,
            snap_m: s.snap_m,
        }
    }
}

/// Texel materials into per-triangle materials of the scene.
pub struct ApplyMaterials;

impl Stage for ApplyMaterials {
    const KIND: &'static str = "ApplyMaterials";
    const VERSION: u32 = 1;
    const DOC: &'static str = "per-texel P.2040 materials into per-triangle scene materials, chart triangles split along material boundaries, solids checked, Sec. 4.2.3";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "scene",
            ArtifactType::Scene,
            "the scene the charts were made from",
        ),
        InputSpec::one("charts", ArtifactType::Charts, "the charts of that scene"),
        InputSpec::one(
            "materials",
            ArtifactType::Materials,
            "the materials fused onto those charts",
        ),
    ];
    type Params = ApplyMaterialsParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.min_region_m2 >= 0.0 && p.min_region_m2 <= 1000.0) {
            return Err(ParamError::new(
                "min_region_m2",
                "expected an area in [0, 1000] m²",
            ));
        }
        if !(p.snap_m >= 0.0 && p.snap_m <= 10.0) {
            return Err(ParamError::new(
                "snap_m",
                "expected a distance in [0, 10] m",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Scene, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let charts: &ChartSet = inputs.one("charts")?;
        let mats: &MaterialLayers = inputs.one("materials")?;
        let spec = ApplySpec {
            min_region_m2: p.min_region_m2,
            snap_m: p.snap_m,
        };
        let (out, _) =
            apply_materials(scene, charts, &mats.charts, &spec).map_err(StageError::Failed)?;
        // Solids are checked where they are made.
        for (o, before) in out.objects.iter().zip(&scene.objects) {
            if o.class != ObjectClass::Building || o.mesh == before.mesh {
                continue;
            }
            if let Err(e) = check_solid(&o.mesh) {
                // A building that was no checked solid to begin with (a truth scene's unions of
                // shells) is not this stage's to fail.
                if check_solid(&before.mesh).is_ok() {
                    return Err(StageError::Failed(format!(
                        "{}: the solid split along its material boundaries is not closed and manifold: {e}",
                        o.id
                    )));
                }
            }
        }
        Ok(out)
    }
}
