//! Relief: façade relief from street views (paper Sec. 4.2.2): per-view region votes (recessed,
//! neutral, protruding from semantic, depth-step and normal cues), fused onto the wall charts by
//! the exposure-weighted operator at a high gamma (eq. (2)-(3)), the per-texel posterior of
//! eq. (4) (with Delta from a source mesh where the graph gives one), and the instances
//! extracted from it, each with its evidence.

use crate::artifact::{ArtifactType, ChartSet, ReliefSet, Scene, ViewSet};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::street::relief::{ReliefParams, relief};

/// Façade relief instances with their evidence, eq. (4).
pub struct Relief;

impl Stage for Relief {
    const KIND: &'static str = "Relief";
    // 2: protrusions' side faces no longer vote; closing stays inside the chart; instances
    // grouped by hysteresis (grow_threshold).
    // 3: the fusion sums its deposits into dense grids in view and pixel order (other last
    // bits); neutral pixels deposit exposure only.
    // 4: no Delta layer without a mesh.
    // 5: instance rectangles where the evidence falls to half its peak; pieces joined across
    // unobserved stretches; sky left out of the enclosure ring, walls of any instance enclose.
    // 6: unlabelled ring pixels on the chart's plane enclose as wall (plane_tol_m).
    // 7: layers stored sparse (the texels that carry a value), 2.6 GB -> 0.6 GB on 1 km².
    // 8: thin features' rectangles without the fusion's blur; drainpipes run up to the eave;
    // protrusions no view measured standing out are dropped.
    // 9: a half-peak side toward the chart's end or unobserved texels extrapolated where the
    // evidence falls toward it; drainpipes 0.05-0.15 m wide (ClassRule::width_m).
    // 10: a drainpipe runs up through flat wall no view saw sharply enough to resolve it.
    // 11: a region's depth step measured on its faces parallel to the wall where that stands
    // farther out (balconies were read 0.15 m short, and deposited that far off).
    // 12: a labelled region a view could not judge neither votes nor counts as exposure; a
    // drainpipe runs down to the terrain as well as up, through less than a storey
    // (run_stop_m) of flat wall; a thin feature's centre from its whole blurred evidence.
    // 13: unlabelled pixels facing up (the ground) are a region apart from those facing sideways,
    // so a missed drainpipe or door that reaches the ground is judged on its own.
    // 14: a protruding feature a view sees past the twin's silhouette (a corner downpipe from
    // the street round the corner) votes, by its label, on the wall it stands by.
    // 15: a view's depth calibrated by Theil-Sen, as the clutter's lifting does, instead of
    // least squares trimmed at three MADs (one depth calibration in the tree).
    // 16: a class's depth range holds for its usual sign only (a window standing out, a bay,
    // takes the protrusions' range); windows and doors 0.05-0.5 m deep.
    const VERSION: u32 = 16;
    const DOC: &'static str = "façade relief from street views: region votes fused onto wall charts, the posterior of eq. (4), recessed and protruding instances with their evidence";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("views", ArtifactType::Views, "the street views"),
        InputSpec::one(
            "scene",
            ArtifactType::Scene,
            "the scene the rays are cast in (the charts' scene)",
        ),
        InputSpec::one(
            "charts",
            ArtifactType::Charts,
            "the charts made from that scene",
        ),
        InputSpec::optional(
            "mesh",
            ArtifactType::Scene,
            "a photogrammetry mesh (ReadTiles) giving Delta, the signed discrepancy along each wall's normal",
        ),
    ];
    type Params = ReliefParams;
    type Output = ReliefSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.validate().map_err(|(f, m)| ParamError::new(f, m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ReliefSet, StageError> {
        let views: &ViewSet = inputs.one("views")?;
        let scene: &Scene = inputs.one("scene")?;
        let charts: &ChartSet = inputs.one("charts")?;
        let mesh: Option<&Scene> = inputs.optional("mesh")?;
        charts.check_made_from(scene).map_err(|e| {
            StageError::Failed(format!(
                "{e}: give Relief the scene its SurfaceCharts node read"
            ))
        })?;
        relief(scene, charts, views.with(ctx.parts), mesh, p, ctx.progress)
    }
}
