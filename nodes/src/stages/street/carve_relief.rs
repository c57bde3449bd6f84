//! CarveRelief: the relief instances carved into the building solids by Booleans (paper Sec.
//! 4.2.2): recesses subtracted, protrusions added, carved faces given their materials; every
//! carved solid passes the solid check or its instance is dropped.

use crate::artifact::{ArtifactType, ChartSet, ReliefSet, Scene};
use crate::geom::carve::{CarveParams, carve_scene};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Relief instances carved into the scene's buildings.
pub struct CarveRelief;

impl Stage for CarveRelief {
    const KIND: &'static str = "CarveRelief";
    // 2: unions merged in a balanced tree (geom::boolean): the same solids, other triangles.
    // 3: an instance reaching past its wall's outline (a downpipe run to the eave) is trimmed
    // to the wall, no longer dropped.
    // 4: slivers the Boolean leaves at T-junctions are mended (geom::boolean), not a reason to
    // drop the instance.
    const VERSION: u32 = 4;
    const DOC: &'static str = "façade relief carved into the building solids by Booleans (recesses subtracted, protrusions added), every result a checked solid";
    const INPUTS: &'static [InputSpec] = &[
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
    type Params = CarveParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.validate().map_err(|(f, m)| ParamError::new(f, m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Scene, StageError> {
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
        let (carved, _report) =
            carve_scene(scene, charts, relief, p).map_err(StageError::Failed)?;
        Ok(carved)
    }
}
