//! CarveRelief: the relief instances carved into the building solids by Booleans (paper Sec.
//! 4.2.2): recesses subtracted, protrusions added, carved faces given their materials; every
//! carved solid passes the solid check or its instance is dropped. Its report `outcomes` says,
//! as metrics, what the carve kept and dropped, and why.

use crate::artifact::{ArtifactType, ChartSet, ReliefSet, Scene, Typed};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, ReportSpec, Reported, Stage, StageError};
use crate::street::relief::carve::{CarveParams, CarveReport, carve_scene};

/// Relief instances carved into the scene's buildings.
pub struct CarveRelief;

impl Stage for CarveRelief {
    const KIND: &'static str = "CarveRelief";
    // 2: unions merged in a balanced tree (geom::boolean): the same solids, other triangles.
    // 3: an instance reaching past its wall's outline (a downpipe run to the eave) is trimmed
    // to the wall, no longer dropped.
    // 4: slivers the Boolean leaves at T-junctions are mended (geom::boolean), not a reason to
    // drop the instance.
    // 5: an instance whose carve fails the solid check is tried again drawn in by 3 mm, then
    // 10 mm, before it is dropped.
    // 6: a result failing the check has its slivers within 0.2 mm of a line mended too
    // (geom::boolean): the T-junction slivers the rounding folds over their neighbours.
    const VERSION: u32 = 6;
    const DOC: &'static str = "façade relief carved into the building solids by Booleans (recesses subtracted, protrusions added), every result a checked solid";
    const INPUTS: &'static [InputSpec] = INPUTS;
    type Params = CarveParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        validate(p)
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Scene, StageError> {
        Ok(carve(p, inputs)?.0)
    }

    const REPORTS: &'static [ReportSpec] = &[ReportSpec {
        name: "outcomes",
        ty: ArtifactType::Metrics,
        doc: "what the carve kept and dropped, by the step that dropped it and by relief class, and the carved buildings' triangles (CarveReport::metrics)",
    }];

    fn run_reported(
        p: &Self::Params,
        inputs: &Inputs,
        _: &Ctx,
    ) -> Result<Reported<Scene>, StageError> {
        let relief: &ReliefSet = inputs.one("relief")?;
        let (scene, report) = carve(p, inputs)?;
        Ok(Reported {
            output: scene,
            reports: vec![("outcomes", report.metrics(relief).into_artifact())],
        })
    }
}

/// The carve's inputs.
const INPUTS: &[InputSpec] = &[
    InputSpec::one(
        "scene",
        ArtifactType::Scene,
        "the scene to carve (the charts' scene)",
    ),
    InputSpec::one(
        "charts",
        ArtifactType::Charts,
        "the charts made from that scene",
    ),
    InputSpec::one(
        "relief",
        ArtifactType::Relief,
        "the relief instances on those charts",
    ),
];

/// The params' check.
fn validate(p: &CarveParams) -> Result<(), ParamError> {
    p.validate().map_err(|(f, m)| ParamError::new(f, m))
}

/// The carve of the inputs' scene by their relief.
fn carve(p: &CarveParams, inputs: &Inputs) -> Result<(Scene, CarveReport), StageError> {
    let scene: &Scene = inputs.one("scene")?;
    let charts: &ChartSet = inputs.one("charts")?;
    let relief: &ReliefSet = inputs.one("relief")?;
    if relief.layers.len() != charts.charts.len() {
        return Err(StageError::Failed(format!(
            "the relief has layers for {} charts, the chart set {}: give CarveRelief the charts its Relief node read",
            relief.layers.len(),
            charts.charts.len()
        )));
    }
    carve_scene(scene, charts, relief, p).map_err(StageError::Failed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bad knobs are refused, naming the field.
    #[test]
    fn bad_params_are_refused() {
        for (field, p) in [
            (
                "overshoot_m",
                CarveParams {
                    overshoot_m: -1.0,
                    ..CarveParams::default()
                },
            ),
            (
                "overshoot_m",
                CarveParams {
                    overshoot_m: 0.0,
                    ..CarveParams::default()
                },
            ),
            (
                "min_size_m",
                CarveParams {
                    min_size_m: f64::NAN,
                    ..CarveParams::default()
                },
            ),
            (
                "margin_m",
                CarveParams {
                    margin_m: 1e9,
                    ..CarveParams::default()
                },
            ),
        ] {
            let e = CarveRelief::validate(&p).expect_err(field);
            assert!(format!("{e:?}").contains(field), "{e:?}");
        }
        assert!(CarveRelief::validate(&CarveParams::default()).is_ok());
    }
}
