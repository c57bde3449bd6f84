//! ApplyMaterials: the per-texel materials of FuseMaterials written into the scene as
//! per-triangle materials (paper Sec. 4.2.3): chart triangles split along material boundaries,
//! every building checked closed and manifold afterwards. A building whose split fails the check
//! keeps its unsplit solid, each triangle painted, and is warned about and counted in the report
//! `counts`: one building must not cost the whole twin.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, ChartSet, MaterialLayers, Metrics, Scene, Typed};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, ReportSpec, Reported, Stage, StageError};
use crate::street::materials::apply::{ApplySpec, ApplyStats, apply_materials};

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
    // 2: a building whose split fails the solid check is kept whole and counted, not fatal; the
    // report `counts`.
    const VERSION: u32 = 2;
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

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        Ok(apply(p, inputs, ctx)?.0)
    }

    const REPORTS: &'static [ReportSpec] = &[ReportSpec {
        name: "counts",
        ty: ArtifactType::Metrics,
        doc: "objects split along their materials, objects kept whole because their split failed the solid check, triangles, cut lines",
    }];

    fn run_reported(
        p: &Self::Params,
        inputs: &Inputs,
        ctx: &Ctx,
    ) -> Result<Reported<Scene>, StageError> {
        let (scene, s) = apply(p, inputs, ctx)?;
        let mut m = Metrics::default();
        m.set("objects_split", s.objects_split as f64);
        m.set("objects_kept_whole", s.kept_whole.len() as f64);
        m.set("triangles_before", s.triangles_before as f64);
        m.set("triangles_after", s.triangles_after as f64);
        m.set("charts_split", s.charts_split as f64);
        m.set("cut_lines", s.cut_lines as f64);
        Ok(Reported {
            output: scene,
            reports: vec![("counts", m.into_artifact())],
        })
    }
}

/// The painted scene and what the painting did; warns about every building kept whole.
fn apply(
    p: &ApplyMaterialsParams,
    inputs: &Inputs,
    ctx: &Ctx,
) -> Result<(Scene, ApplyStats), StageError> {
    let scene: &Scene = inputs.one("scene")?;
    let charts: &ChartSet = inputs.one("charts")?;
    let mats: &MaterialLayers = inputs.one("materials")?;
    let spec = ApplySpec {
        min_region_m2: p.min_region_m2,
        snap_m: p.snap_m,
    };
    let (out, stats) =
        apply_materials(scene, charts, &mats.charts, &spec).map_err(StageError::Failed)?;
    let whole = &stats.kept_whole;
    if !whole.is_empty() {
        ctx.progress.warn(&format!(
            "{} buildings kept whole, each triangle painted, because their split along the material boundaries failed (first: {})",
            whole.len(),
            whole[..whole.len().min(3)].join("; ")
        ));
    }
    Ok((out, stats))
}
