//! FuseMaterials: per-texel ITU-R P.2040 materials on the building charts from the street views'
//! material maps (paper Sec. 4.2.3): pixel classes mapped to P.2040, refined inside window and
//! door instances, clutter masked, fused by exposure-weighted projection with gamma_mat, chosen by
//! eq. (5) with the class weights mu_m, and extended onto what no view saw.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::{
    ArtifactType, ChartSet, MaterialLayers, MaterialStats, NO_MATERIAL, Scene, View, ViewSet,
};
use crate::geom::raycast::SceneRays;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::street::fusion::{FusionParams, Vote, fuse_views};
use crate::street::materials::fusion::{
    Extension, MASKED, SEEN, assign_materials, class_table, parse_target, refine_view, vote_classes,
};

/// Params of [`FuseMaterials`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FuseMaterialsParams {
    /// Stage exponent gamma_mat on the projection Jacobian: low, for coverage. Default 0.5.
    pub gamma: f64,
    /// Angle gate theta_max, degrees from the surface normal. Default 80.
    pub theta_max_deg: f64,
    /// Kernel sigma, texels. Default 0 (each hit deposited bilinearly): on the synthetic site
    /// sigma 1 blurs window edges and costs 4 points of observed accuracy (tests/materials.rs).
    pub sigma_texels: f64,
    /// One ray every `stride` pixels each way. Default 2.
    pub stride: u32,
    /// Class vote weights mu_m by P.2040 class name, e.g. `{"glass": 1.2}`; unnamed classes 1.
    pub weights: BTreeMap<String, f64>,
    /// Overrides of the pixel-class table: view class -> P.2040 class, `"foliage"` or `"none"`
    /// (defaults: shared/DESIGN.md, e.g. plaster -> concrete, leaf -> foliage, sky -> none).
    pub classes: BTreeMap<String, String>,
    /// Architectural instance classes whose mask takes the dominant compatible material, with
    /// the compatible P.2040 classes. Default window: glass, metal, wood; door: wood, glass,
    /// metal.
    pub refine: BTreeMap<String, Vec<String>>,
    /// Pixels of clutter instances neither vote nor count as exposure. Default true.
    pub mask_clutter: bool,
    /// Extend the dominant material onto unobserved texels. Default true.
    pub extend: bool,
    /// A texel is observed when its W_exp exceeds this. Default 0.
    pub min_exposure: f64,
    /// Walls of a building no view saw. Default concrete.
    pub wall_default: String,
    /// Roofs of a building whose roofs no view saw. Default concrete.
    pub roof_default: String,
}

impl Default for FuseMaterialsParams {
    fn default() -> Self {
        let list = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        FuseMaterialsParams {
            gamma: 0.5,
            theta_max_deg: 80.0,
            sigma_texels: 0.0,
            stride: 2,
            weights: BTreeMap::new(),
            classes: BTreeMap::new(),
            refine: BTreeMap::from([
                ("window".to_string(), list(&["glass", "metal", "wood"])),
                ("door".to_string(), list(&["wood", "glass", "metal"])),
            ]),
            mask_clutter: true,
            extend: true,
            min_exposure: 0.0,
            wall_default: "concrete".into(),
            roof_default: "concrete".into(),
        }
    }
}

/// A building-surface P.2040 class by name (not ground, not foliage).
fn surface_material(name: &str) -> Option<Material> {
    match parse_target(name)? {
        crate::street::materials::fusion::PixelTarget::Surface(m) => Some(m),
        _ => None,
    }
}

/// The P.2040 surface classes, for messages.
fn surface_names() -> String {
    vote_classes()
        .into_iter()
        .filter(|n| surface_material(n).is_some())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Per-texel ITU-R P.2040 materials, eq. (5).
pub struct FuseMaterials;

impl Stage for FuseMaterials {
    const KIND: &'static str = "FuseMaterials";
    // 2: the fusion sums its deposits into dense grids in view and pixel order (other last
    // bits).
    const VERSION: u32 = 2;
    const DOC: &'static str = "per-texel ITU-R P.2040 materials from street-view material maps: class table, instance refinement, eq. (5), extension, Sec. 4.2.3";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "views",
            ArtifactType::Views,
            "the street views with material maps",
        ),
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
    ];
    type Params = FuseMaterialsParams;
    type Output = MaterialLayers;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        FusionParams {
            gamma: p.gamma,
            theta_max_deg: p.theta_max_deg,
            sigma_texels: p.sigma_texels,
            stride: p.stride,
        }
        .check()
        .map_err(|(field, expected)| ParamError::new(field, expected))?;
        for (name, &w) in &p.weights {
            if surface_material(name).is_none() {
                return Err(ParamError::new(
                    "weights",
                    format!(
                        "{name:?} is not a P.2040 surface class; expected one of {}",
                        surface_names()
                    ),
                ));
            }
            if !(w > 0.0 && w <= 1000.0) {
                return Err(ParamError::new(
                    "weights",
                    format!("{name}: expected a weight in (0, 1000], not {w}"),
                ));
            }
        }
        for (class, target) in &p.classes {
            if parse_target(target).is_none() {
                return Err(ParamError::new(
                    "classes",
                    format!(
                        "{class:?} -> {target:?}: expected a P.2040 class ({}), \"foliage\" or \"none\"",
                        vote_classes().join(", ")
                    ),
                ));
            }
        }
        for (class, list) in &p.refine {
            for m in list {
                if surface_material(m).is_none() {
                    return Err(ParamError::new(
                        "refine",
                        format!(
                            "{class}: {m:?} is not a P.2040 surface class; expected one of {}",
                            surface_names()
                        ),
                    ));
                }
            }
        }
        if !(p.min_exposure >= 0.0 && p.min_exposure.is_finite()) {
            return Err(ParamError::new(
                "min_exposure",
                "expected a finite exposure >= 0",
            ));
        }
        for (field, name) in [
            ("wall_default", &p.wall_default),
            ("roof_default", &p.roof_default),
        ] {
            if surface_material(name).is_none() {
                return Err(ParamError::new(
                    field,
                    format!(
                        "{name:?} is not a P.2040 surface class; expected one of {}",
                        surface_names()
                    ),
                ));
            }
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<MaterialLayers, StageError> {
        let views: &ViewSet = inputs.one("views")?;
        let scene: &Scene = inputs.one("scene")?;
        let charts: &ChartSet = inputs.one("charts")?;
        charts.check_made_from(scene).map_err(|e| {
            StageError::Failed(format!(
                "{e}: give FuseMaterials the scene its SurfaceCharts node read"
            ))
        })?;
        let table = class_table(&views.material_classes, &p.classes)
            .map_err(|m| StageError::Param(ParamError::new("classes", m)))?;
        let refine: BTreeMap<String, Vec<Material>> = p
            .refine
            .iter()
            .map(|(k, v)| {
                (
                    k.clone(),
                    v.iter().filter_map(|n| surface_material(n)).collect(),
                )
            })
            .collect();
        // Each view's material map as refined votes, made as the fusion reads the view; the
        // counts are sums, the same in any order.
        let (refined_pixels, refined_instances) = (AtomicU64::new(0), AtomicU64::new(0));
        let prepare = |_: usize, v: &View| {
            let (votes, s) = refine_view(v, &table, &refine, p.mask_clutter);
            refined_pixels.fetch_add(s.pixels, Ordering::Relaxed);
            refined_instances.fetch_add(s.instances, Ordering::Relaxed);
            votes
        };
        let vote = |votes: &Vec<u8>, _: &View, px: usize| match votes.get(px).copied() {
            Some(MASKED) => Vote::Masked,
            Some(SEEN) | None => Vote::Seen,
            Some(m) => Vote::Class(m as u16),
        };
        let fp = FusionParams {
            gamma: p.gamma,
            theta_max_deg: p.theta_max_deg,
            sigma_texels: p.sigma_texels,
            stride: p.stride,
        };
        let rays = SceneRays::new(scene);
        let classes = vote_classes();
        let fused = fuse_views(
            scene,
            &rays,
            charts,
            views.with(ctx.parts),
            classes.clone(),
            &prepare,
            &vote,
            &fp,
            ctx.progress,
        )?;
        let mut weights = vec![1.0; classes.len()];
        for (name, &w) in &p.weights {
            if let Some(m) = surface_material(name) {
                weights[m as usize] = w;
            }
        }
        let ext = Extension {
            enabled: p.extend,
            min_exposure: p.min_exposure,
            wall_default: surface_material(&p.wall_default).unwrap_or(Material::Concrete),
            roof_default: surface_material(&p.roof_default).unwrap_or(Material::Concrete),
        };
        let chosen = assign_materials(charts, &fused.charts, &weights, &ext);
        let mut stats = MaterialStats {
            by_material: vec![0; Material::ALL.len()],
            area_m2: vec![0.0; Material::ALL.len()],
            ..Default::default()
        };
        for (c, m) in charts.charts.iter().zip(&chosen) {
            let area = c.texel_m * c.texel_m;
            for k in 0..c.len() {
                stats.by_source[m.source[k].min(4) as usize] += 1;
                if m.material[k] != NO_MATERIAL {
                    stats.texels += 1;
                    stats.by_material[m.material[k] as usize] += 1;
                    stats.area_m2[m.material[k] as usize] += area;
                }
            }
        }
        stats.refined_pixels = refined_pixels.into_inner();
        stats.refined_instances = refined_instances.into_inner();
        stats.masked_rays = fused.stats.masked;
        Ok(MaterialLayers {
            fused,
            weights,
            charts: chosen,
            stats,
        })
    }
}
