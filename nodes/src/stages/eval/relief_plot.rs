//! The façade relief figure for the report: the walls with the most relief instances, each an
//! elevation with its instances by class (recessed filled, protruding outlined).

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, ChartSet, ReliefSet, ReportFiles};
use crate::io::export::figures::relief::ReliefFigure;
use crate::io::export::figures::render;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReliefPlot`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReliefPlotParams {
    /// The figure's file stem in the report. Default "relief".
    #[serde(default = "name")]
    pub name: String,
}

fn name() -> String {
    "relief".into()
}

/// The relief figure as `<name>.svg` and `<name>.png` (give it to Report's `figures`).
pub struct ReliefPlot;

impl Stage for ReliefPlot {
    const KIND: &'static str = "ReliefPlot";
    const VERSION: u32 = 1;
    const DOC: &'static str = "Relief instances per façade (SVG and PNG): the walls with the most instances, recessed filled, protruding outlined";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("relief", ArtifactType::Relief, "Relief's instances"),
        InputSpec::one(
            "charts",
            ArtifactType::Charts,
            "the charts the relief was fused on",
        ),
    ];
    type Params = ReliefPlotParams;
    type Output = ReportFiles;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::safe_name::check_file_name(&p.name).map_err(|m| ParamError::new("name", m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<ReportFiles, StageError> {
        let relief: &ReliefSet = inputs.one("relief")?;
        let charts: &ChartSet = inputs.one("charts")?;
        if relief.layers.len() != charts.charts.len() {
            return Err(StageError::Failed(format!(
                "the relief has layers for {} charts, the chart set {}: give the charts it was fused on",
                relief.layers.len(),
                charts.charts.len()
            )));
        }
        let f = render(&ReliefFigure::new(relief, charts)).map_err(StageError::Failed)?;
        Ok(ReportFiles {
            files: vec![
                (format!("{}.svg", p.name), f.svg.into_bytes()),
                (format!("{}.png", p.name), f.png),
            ],
        })
    }
}
