//! The relief's parameters: per-class rules, the cue weights of g(v), and every knob with its
//! default and its check.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use super::posterior::{Cpt, DeltaParams};

/// Per semantic class: its prior sign, the depths it may be carved at, and whether it runs up
/// the wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassRule {
    /// The architectural class name the views use.
    pub name: String,
    /// The semantic cue v_semantic: -1 recessed, 0 none, +1 protruding.
    pub prior: i8,
    /// Depth range, metres (min, max): an instance's measured depth is clamped into it.
    pub depth_m: (f64, f64),
    /// The feature runs the wall's height (a downpipe, from its gutter at the eave to the
    /// ground): an instance reaches up to the wall's top and down to the terrain through texels
    /// the views did not observe or that hold some of its evidence, and through flat wall the
    /// views saw well enough to have resolved it (with `width_m`, the exposure of a view that
    /// sees its widest across as one pixel) for less than `run_stop_m`; pieces of it that then
    /// overlap are one instance. Default false.
    #[serde(default, alias = "runs_up")]
    pub runs_full_height: bool,
    /// Width range across the wall, metres (min, max), for a class whose width the evidence
    /// cannot tell: a feature not much wider than a texel reads as wide as the fusion's kernel
    /// plus the views' registration scatter (a 0.12 m drainpipe reads 0.2-0.3 m), so its
    /// rectangle keeps the evidence's centre and takes a width within this range. None (the
    /// default): the evidence's width.
    #[serde(default)]
    pub width_m: Option<(f64, f64)>,
}

/// Weights of the cues in g(v).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CueWeights {
    /// The class prior.
    pub semantic: f64,
    /// The depth step against the surrounding wall plane.
    pub depth: f64,
    /// The normal flow.
    pub normal: f64,
}

/// Everything the relief needs, named as in the paper where it has a name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReliefParams {
    /// gamma_fac: the stage exponent on the Jacobian, high (close, head-on views dominate).
    /// Default 2.
    pub gamma: f64,
    /// Angle gate theta_max, degrees. Default 70.
    pub theta_max_deg: f64,
    /// Kernel sigma, texels. Default 0.5 (a drainpipe is about one texel wide).
    pub sigma_texels: f64,
    /// One fusion ray every `stride` pixels each way. Default 1.
    pub stride: u32,
    /// Clutter pixels neither vote nor count as exposure. Default true.
    pub mask_clutter: bool,
    /// The architectural class of the walls regions must sit in. Default "wall".
    pub wall_class: String,
    /// Classes that never form regions (roofs). Default ["roof"].
    pub ignore_classes: Vec<String>,
    /// Per class: prior sign, depth range, and whether it runs up the wall. Default: windows
    /// and doors recessed 0.1-0.3 m, balconies protruding 0.3-1.5 m, drainpipes protruding
    /// 0.05-0.3 m and running up to the eave.
    pub classes: Vec<ClassRule>,
    /// Depth range of recesses of no known class, metres. Default (0.05, 0.5).
    pub unknown_recess_m: (f64, f64),
    /// Depth range of protrusions of no known class, metres. Default (0.05, 1.5).
    pub unknown_protrusion_m: (f64, f64),
    /// Smallest region, pixels. Default 6.
    pub min_region_px: u32,
    /// Width of the ring around a region where its enclosing wall is looked for, pixels.
    /// Default 3.
    pub ring_px: u32,
    /// Share of the ring (clutter and sky aside) walls must hold. Default 0.5.
    pub enclosure_min: f64,
    /// Unlabelled ring pixels whose calibrated depth puts them this close to the region's chart
    /// plane count as wall (a wall the segmentation missed), metres. Default 0.3.
    pub plane_tol_m: f64,
    /// Smallest depth step that counts, metres. Default 0.05. A protruding instance needs its
    /// views to have measured it standing out at least this far: the class in the image alone
    /// does not say which wall a protrusion stands on (a drainpipe round the corner, seen
    /// past it, lands on the near wall's last texels).
    pub min_step_m: f64,
    /// And its significance: step over its standard error. Default 3.
    pub step_z_min: f64,
    /// A pixel whose normal is further than this from the wall's is a side face, degrees.
    /// Default 30.
    pub side_angle_deg: f64,
    /// Share of side-face pixels needed for the normal cue. Default 0.05.
    pub min_side_share: f64,
    /// Agreement of the side faces' flow needed for the normal cue, in [0, 1]. Default 0.3.
    pub flow_min: f64,
    /// Cue weights in g(v).
    pub weights: CueWeights,
    /// |score| needed for a non-neutral region label. Default 1.
    pub score_min: f64,
    /// Exposure unit: one head-on view from this far, metres. Default 30.
    pub ref_distance_m: f64,
    /// Texels with less exposure (in those units) stay unobserved. Default 1.
    pub exposure_min: f64,
    /// Thresholds discretising R and P into levels 0, 1, 2. Default (0.2, 0.5).
    pub levels: (f64, f64),
    /// The CPT of eq. (4).
    pub cpt: Cpt,
    /// Pr(d | Delta).
    pub delta: DeltaParams,
    /// Posterior an instance's texels need. Default 0.5.
    pub threshold: f64,
    /// Lower posterior through which texels over `threshold` join into one instance
    /// (hysteresis); the instance's extent is still its texels over `threshold`. Default 0.3:
    /// a texel with some votes (R or P at level 1 gives 0.35 in the default CPT), not a texel
    /// that looked flat (0.03).
    pub grow_threshold: f64,
    /// Morphological opening radius for recesses and protrusions, texels. Default (1, 0): a
    /// drainpipe is one texel wide.
    pub open_texels: (u32, u32),
    /// Closing radius, texels. Default 1.
    pub close_texels: u32,
    /// Smallest instance, texels. Default 6.
    pub min_texels: u32,
    /// Widest stretch of unobserved texels (or texels with some evidence) across which two
    /// pieces of one feature join, texels. Default 5: a balcony slab's shadow on a drainpipe.
    pub bridge_texels: u32,
    /// The stretch of flat wall, seen well enough to have resolved it, that stops a feature
    /// running the wall's height (`ClassRule::runs_full_height`), metres. Default 3, a storey:
    /// a pipe the one close view's segmentation missed, or far views read flat, over part of
    /// its run goes on; one that ends stops.
    pub run_stop_m: f64,
}

impl Default for ReliefParams {
    fn default() -> Self {
        let rule = |name: &str, prior, depth_m, runs_full_height, width_m| ClassRule {
            name: name.into(),
            prior,
            depth_m,
            runs_full_height,
            width_m,
        };
        ReliefParams {
            gamma: 2.0,
            theta_max_deg: 70.0,
            sigma_texels: 0.5,
            stride: 1,
            mask_clutter: true,
            wall_class: "wall".into(),
            ignore_classes: vec!["roof".into()],
            classes: vec![
                // Reveals from a window flush in a thin rendered wall to one set in a 0.5 m
                // masonry wall.
                rule("window", -1, (0.05, 0.5), false, None),
                rule("door", -1, (0.05, 0.5), false, None),
                rule("balcony", 1, (0.3, 1.5), false, None),
                // Views see a drainpipe between balconies and parked cars, in pieces, and rarely
                // up to the eave from the street: it runs there all the same. Downpipes are
                // made 50 to 150 mm across (EN 12200's nominal sizes).
                rule("drainpipe", 1, (0.05, 0.3), true, Some((0.05, 0.15))),
            ],
            unknown_recess_m: (0.05, 0.5),
            unknown_protrusion_m: (0.05, 1.5),
            min_region_px: 6,
            ring_px: 3,
            enclosure_min: 0.5,
            plane_tol_m: 0.3,
            min_step_m: 0.05,
            step_z_min: 3.0,
            side_angle_deg: 30.0,
            min_side_share: 0.05,
            flow_min: 0.3,
            weights: CueWeights {
                semantic: 1.0,
                depth: 2.0,
                normal: 1.0,
            },
            score_min: 1.0,
            ref_distance_m: 30.0,
            exposure_min: 1.0,
            levels: (0.2, 0.5),
            cpt: Cpt::default(),
            delta: DeltaParams::default(),
            threshold: 0.5,
            grow_threshold: 0.3,
            open_texels: (1, 0),
            close_texels: 1,
            min_texels: 6,
            bridge_texels: 5,
            run_stop_m: 3.0,
        }
    }
}

impl ReliefParams {
    /// Checks every knob: (field, message) of the first bad one.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let range = crate::params::check_in;
        range("gamma", self.gamma, 0.0, 8.0)?;
        range("theta_max_deg", self.theta_max_deg, 1.0, 90.0)?;
        range("sigma_texels", self.sigma_texels, 0.0, 8.0)?;
        if !(1..=64).contains(&self.stride) {
            return Err(("stride", "expected 1 to 64 pixels".into()));
        }
        let depth_range = |name: &'static str, r: (f64, f64)| {
            if r.0.is_finite() && r.1.is_finite() && r.0 >= 0.0 && r.0 <= r.1 && r.1 <= 10.0 {
                Ok(())
            } else {
                Err((name, format!("expected 0 <= min <= max <= 10 m, got {r:?}")))
            }
        };
        for c in &self.classes {
            depth_range("classes", c.depth_m)?;
            if let Some(w) = c.width_m {
                depth_range("classes", w)?;
            }
            if !(-1..=1).contains(&c.prior) {
                return Err(("classes", format!("{}: prior is -1, 0 or 1", c.name)));
            }
        }
        let names: BTreeSet<&str> = self.classes.iter().map(|c| c.name.as_str()).collect();
        if names.len() != self.classes.len() {
            return Err(("classes", "a class is listed twice".into()));
        }
        depth_range("unknown_recess_m", self.unknown_recess_m)?;
        depth_range("unknown_protrusion_m", self.unknown_protrusion_m)?;
        if !(1..=100_000).contains(&self.min_region_px) {
            return Err(("min_region_px", "expected 1 to 100000 pixels".into()));
        }
        if !(1..=32).contains(&self.ring_px) {
            return Err(("ring_px", "expected 1 to 32 pixels".into()));
        }
        range("enclosure_min", self.enclosure_min, 0.0, 1.0)?;
        range("plane_tol_m", self.plane_tol_m, 0.0, 10.0)?;
        range("min_step_m", self.min_step_m, 0.0, 5.0)?;
        range("step_z_min", self.step_z_min, 0.0, 100.0)?;
        range("side_angle_deg", self.side_angle_deg, 1.0, 89.0)?;
        range("min_side_share", self.min_side_share, 0.0, 1.0)?;
        range("flow_min", self.flow_min, 0.0, 1.0)?;
        range("weights.semantic", self.weights.semantic, 0.0, 100.0)?;
        range("weights.depth", self.weights.depth, 0.0, 100.0)?;
        range("weights.normal", self.weights.normal, 0.0, 100.0)?;
        range("score_min", self.score_min, 0.0, 1000.0)?;
        range("ref_distance_m", self.ref_distance_m, 0.1, 10_000.0)?;
        range("exposure_min", self.exposure_min, 0.0, 1e9)?;
        range("levels", self.levels.0, 0.0, 1.0)?;
        range("levels", self.levels.1, self.levels.0, 1.0)?;
        self.cpt.validate().map_err(|m| ("cpt", m))?;
        range("delta.tau_m", self.delta.tau_m, 0.0, 10.0)?;
        range("delta.scale_m", self.delta.scale_m, 1e-4, 10.0)?;
        range("delta.trust", self.delta.trust, 0.0, 1.0)?;
        range("delta.search_m", self.delta.search_m, 0.01, 50.0)?;
        range("threshold", self.threshold, 0.0, 1.0)?;
        range("grow_threshold", self.grow_threshold, 0.0, self.threshold)?;
        if self.open_texels.0 > 16 || self.open_texels.1 > 16 || self.close_texels > 16 {
            return Err(("open_texels", "expected radii of at most 16 texels".into()));
        }
        if !(1..=1_000_000).contains(&self.min_texels) {
            return Err(("min_texels", "expected 1 to 10^6 texels".into()));
        }
        if self.bridge_texels > 1000 {
            return Err(("bridge_texels", "expected 0 to 1000 texels".into()));
        }
        range("run_stop_m", self.run_stop_m, 0.0, 1000.0)?;
        Ok(())
    }

    /// The depth range of an instance of `class` and `sign`.
    pub fn depth_range(&self, class: &str, sign: i8) -> (f64, f64) {
        match self.classes.iter().find(|c| c.name == class) {
            // A class's range is for its usual sign: a bay window stands out as far as any
            // protrusion may, not as deep as windows are set in.
            Some(c) if c.prior == 0 || c.prior.signum() == sign.signum() => c.depth_m,
            _ if sign < 0 => self.unknown_recess_m,
            _ => self.unknown_protrusion_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_class_width_range_is_refused_out_of_order_or_not_finite() {
        for bad in [
            (0.2, 0.1),
            (f64::NAN, 0.1),
            (0.05, f64::INFINITY),
            (-0.1, 0.1),
        ] {
            let mut p = ReliefParams::default();
            p.classes[3].width_m = Some(bad);
            assert_eq!(p.validate().map_err(|e| e.0), Err("classes"), "{bad:?}");
        }
    }

    #[test]
    fn grow_threshold_is_refused_above_the_threshold_or_not_finite() {
        for g in [0.6, f64::NAN, -0.1] {
            let p = ReliefParams {
                grow_threshold: g,
                ..Default::default()
            };
            assert_eq!(p.validate().map_err(|e| e.0), Err("grow_threshold"), "{g}");
        }
        assert!(ReliefParams::default().validate().is_ok());
    }

    #[test]
    fn plane_tolerance_bridge_width_and_run_stop_are_refused_out_of_range() {
        for t in [f64::NAN, f64::INFINITY, -0.1, 11.0] {
            let p = ReliefParams {
                plane_tol_m: t,
                ..Default::default()
            };
            assert_eq!(p.validate().map_err(|e| e.0), Err("plane_tol_m"), "{t}");
        }
        let p = ReliefParams {
            bridge_texels: 1001,
            ..Default::default()
        };
        assert_eq!(p.validate().map_err(|e| e.0), Err("bridge_texels"));
        for m in [f64::NAN, f64::NEG_INFINITY, -1.0, 1001.0] {
            let p = ReliefParams {
                run_stop_m: m,
                ..Default::default()
            };
            assert_eq!(p.validate().map_err(|e| e.0), Err("run_stop_m"), "{m}");
        }
    }
}
