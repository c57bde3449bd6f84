//! RegisterViews: each street view's reported position and heading refined against the twin's
//! building silhouettes (an addition to the paper's metadata-only registration of Sec. 4.2; see
//! `street::registration` for why and how). Every view keeps its images; only its pose moves,
//! and its `pose_source` says by how much and on what evidence.

use crate::artifact::{ArtifactType, Scene, ViewSet};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::street::registration::{RegistrationParams, register_views};

/// Street views with their poses refined against the twin.
pub struct RegisterViews;

impl Stage for RegisterViews {
    const KIND: &'static str = "RegisterViews";
    // 2: drainpipes and balconies say nothing about the pose; the pattern search goes on to
    // steps under 2.5 cm.
    // 3: camera height, pitch and focal length searched too (issue 51: the views' metadata errs in all six
    // degrees of freedom).
    // 4: roll can be searched too (`search_roll_deg`, off by default).
    // 5: the views' pixels are parts (one per view), the set holds their heads.
    // 6: on the finest lattice the search moves the camera in plan only (`PLAN_MOVES`), and
    // tries the other moves once more at the end (`settle_the_rest`).
    const VERSION: u32 = 6;
    const DOC: &'static str = "street views with position, height, heading, pitch and focal length (roll optionally) refined against the twin's building silhouettes (bounded search; a view is left alone when nothing beats its metadata)";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "views",
            ArtifactType::Views,
            "the street views, placed from their metadata",
        ),
        InputSpec::one(
            "scene",
            ArtifactType::Scene,
            "the twin whose Building and Terrain objects the views are matched to",
        ),
    ];
    type Params = RegistrationParams;
    type Output = ViewSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.validate().map_err(|(f, m)| ParamError::new(f, m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ViewSet, StageError> {
        let views: &ViewSet = inputs.one("views")?;
        let scene: &Scene = inputs.one("scene")?;
        if p.is_off() {
            return Ok(views.clone());
        }
        let refined = register_views(scene, views.with(ctx.parts), p, ctx.progress)?;
        let mut out = views.clone();
        for (v, (pose, r)) in out.views.iter_mut().zip(refined) {
            let was = v.pose_source.clone().unwrap_or_else(|| "metadata".into());
            v.pose_source = Some(if r.accepted {
                v.pose = pose;
                v.intrinsics.fx *= r.focal_scale;
                v.intrinsics.fy *= r.focal_scale;
                let by = if r.by_facades {
                    "the twin's silhouettes and the façades the other views agree on"
                } else {
                    "the twin's silhouettes"
                };
                format!(
                    "{was}; refined against {by}: moved ({:+.2}, {:+.2}, {:+.2}) m, turned {:+.2} deg, pitched {:+.2} deg, rolled {:+.2} deg, focal length x {:.3}, agreement {:.3} -> {:.3}",
                    r.shift_m[0],
                    r.shift_m[1],
                    r.dz_m,
                    r.yaw_deg,
                    r.pitch_deg,
                    r.roll_deg,
                    r.focal_scale,
                    r.before,
                    r.after
                )
            } else if r.before.is_finite() {
                format!(
                    "{was}; kept: nothing within {} m and {} deg beat it (agreement {:.3})",
                    p.search_m, p.search_deg, r.before
                )
            } else {
                format!("{was}; kept: no building labelled in the view to match the twin with")
            });
        }
        Ok(out)
    }
}
