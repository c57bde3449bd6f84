//! FuseViews: the per-pixel labels of a view set fused onto the building charts by
//! exposure-weighted projection (paper eq. (2)-(3)), keeping exposure, hit counts and votes per
//! class, and the winning class per texel.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, ChartSet, Scene, TexelLayers, View, ViewSet};
use crate::geom::raycast::SceneRays;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::street::fusion::{FusionParams, Vote, fuse_views};

/// Which per-pixel labels vote.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LabelSource {
    /// The architectural instances' classes (wall, window, door, balcony, ...).
    Architecture,
    /// The material classes of the view set's table.
    Material,
}

/// Params of [`FuseViews`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FuseViewsParams {
    /// The labels that vote. Default `Architecture`.
    pub labels: LabelSource,
    /// Stage exponent gamma on the projection Jacobian. Default 1.
    pub gamma: f64,
    /// Angle gate theta_max, degrees from the surface normal. Default 75.
    pub theta_max_deg: f64,
    /// Kernel sigma, texels. Default 1.
    pub sigma_texels: f64,
    /// One ray every `stride` pixels each way. Default 1 (every pixel).
    pub stride: u32,
    /// Pixels of clutter instances neither vote nor count as exposure. Default true.
    pub mask_clutter: bool,
}

impl Default for FuseViewsParams {
    fn default() -> Self {
        FuseViewsParams {
            labels: LabelSource::Architecture,
            gamma: 1.0,
            theta_max_deg: 75.0,
            sigma_texels: 1.0,
            stride: 1,
            mask_clutter: true,
        }
    }
}

/// Street-view labels fused onto building charts, eq. (2)-(3).
pub struct FuseViews;

impl Stage for FuseViews {
    const KIND: &'static str = "FuseViews";
    // 2: the output keeps the charts' frames; sums run slot by slot.
    // 3: deposits summed into dense grids in view and pixel order (other last bits).
    const VERSION: u32 = 3;
    const DOC: &'static str = "per-pixel labels of street views fused onto building charts by exposure-weighted projection, eq. (2)-(3)";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("views", ArtifactType::Views, "the street views"),
        InputSpec::one(
            "scene",
            ArtifactType::Scene,
            "the scene the rays are cast in (the charts' scene: terrain and buildings)",
        ),
        InputSpec::one(
            "charts",
            ArtifactType::Charts,
            "the charts made from that scene",
        ),
    ];
    type Params = FuseViewsParams;
    type Output = TexelLayers;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        FusionParams {
            gamma: p.gamma,
            theta_max_deg: p.theta_max_deg,
            sigma_texels: p.sigma_texels,
            stride: p.stride,
        }
        .check()
        .map_err(|(field, expected)| ParamError::new(field, expected))?;
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<TexelLayers, StageError> {
        let views: &ViewSet = inputs.one("views")?;
        let scene: &Scene = inputs.one("scene")?;
        let charts: &ChartSet = inputs.one("charts")?;
        charts.check_made_from(scene).map_err(|e| {
            StageError::Failed(format!(
                "{e}: give FuseViews the scene its SurfaceCharts node read"
            ))
        })?;
        let classes = class_table(views, p.labels)?;
        let vote = |_: &(), v: &View, px: usize| pixel_vote(v, px, p, &classes);
        let rays = SceneRays::new(scene);
        let fp = FusionParams {
            gamma: p.gamma,
            theta_max_deg: p.theta_max_deg,
            sigma_texels: p.sigma_texels,
            stride: p.stride,
        };
        fuse_views(
            scene,
            &rays,
            charts,
            views.with(ctx.parts),
            classes.clone(),
            &|_, _| (),
            &vote,
            &fp,
            ctx.progress,
        )
    }
}

/// The class names votes index: the material table, or every architectural class named by any
/// view, sorted.
fn class_table(views: &ViewSet, labels: LabelSource) -> Result<Vec<String>, StageError> {
    let mut names: Vec<String> = match labels {
        LabelSource::Material => return Ok(views.material_classes.clone()),
        LabelSource::Architecture => views
            .views
            .iter()
            .filter_map(|v| v.arch_classes.as_ref())
            .flat_map(|a| a.values().cloned())
            .collect(),
    };
    names.sort();
    names.dedup();
    if names.len() > u16::MAX as usize {
        return Err(StageError::Failed("more than 65535 classes".into()));
    }
    Ok(names)
}

fn pixel_vote(v: &View, px: usize, p: &FuseViewsParams, classes: &[String]) -> Vote {
    if p.mask_clutter
        && v.clutter
            .as_ref()
            .is_some_and(|c| c.ids.get(px).is_some_and(|&id| id != 0))
    {
        return Vote::Masked;
    }
    match p.labels {
        LabelSource::Architecture => {
            let Some(a) = &v.arch else { return Vote::Seen };
            let id = a.ids.get(px).copied().unwrap_or(0);
            a.classes
                .get(&id)
                .and_then(|name| classes.binary_search(name).ok())
                .map_or(Vote::Seen, |k| Vote::Class(k as u16))
        }
        LabelSource::Material => match v.material.as_ref().and_then(|m| m.get(px)) {
            Some(&m) if (m as usize) < classes.len() => Vote::Class(m as u16),
            _ => Vote::Seen,
        },
    }
}
