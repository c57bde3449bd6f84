//! The materials figure for the report: the scene seen obliquely in ITU-R P.2040 false colours,
//! so a reader sees which material each wall, roof and window got (eq. (5)'s result).

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, ReportFiles, Scene};
use crate::io::export::figures::render;
use crate::io::export::figures::render3d::MaterialRender;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`MaterialPlot`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialPlotParams {
    /// The figure's file stem in the report. Default "materials".
    #[serde(default = "name")]
    pub name: String,
    /// The title over the picture.
    #[serde(default = "title")]
    pub title: String,
    /// Viewing elevation above the horizon, degrees (looking north-east). Default 35.
    #[serde(default = "elevation")]
    pub elevation_deg: f64,
}

fn name() -> String {
    "materials".into()
}
fn title() -> String {
    "Materials of the twin (ITU-R P.2040 classes), seen from the south-west".into()
}
fn elevation() -> f64 {
    35.0
}

/// The scene in material false colours as `<name>.svg` and `<name>.png` (give it to Report's
/// `figures`).
pub struct MaterialPlot;

impl Stage for MaterialPlot {
    const KIND: &'static str = "MaterialPlot";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "The scene seen obliquely in ITU-R P.2040 false colours (SVG and PNG)";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "scene",
        ArtifactType::Scene,
        "the scene to show (e.g. the painted or carved twin)",
    )];
    type Params = MaterialPlotParams;
    type Output = ReportFiles;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::safe_name::check_file_name(&p.name).map_err(|m| ParamError::new("name", m))?;
        if !(p.elevation_deg.is_finite() && (5.0..=90.0).contains(&p.elevation_deg)) {
            return Err(ParamError::new(
                "elevation_deg",
                "expected degrees in [5, 90]",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<ReportFiles, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let f = render(&MaterialRender::new(
            p.title.clone(),
            scene,
            p.elevation_deg,
        ))
        .map_err(StageError::Failed)?;
        Ok(ReportFiles {
            files: vec![
                (format!("{}.svg", p.name), f.svg.into_bytes()),
                (format!("{}.png", p.name), f.png),
            ],
        })
    }
}
