//! The OSM baseline scene (paper Sec. 5): footprints extruded flat to their tagged height, or
//! levels x 3 m, or a default, standing on coarse terrain. This is the construction Geo2SigMap,
//! OpenGERT and Blosm use, built here so KODAMA's scenes can be scored against it on equal terms.

use serde::{Deserialize, Serialize};

use crate::artifact::{
    ArtifactType, Footprint, Footprints, ObjectClass, Raster, Scene, SceneObject,
};
use crate::artifact::{Material, default_material};
use crate::geom::mesh_build::prism;
use crate::geom::mesh_check::check_solid;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`OsmBaseline`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OsmBaselineParams {
    /// Storey height for footprints tagged with levels only, metres. Default 3.
    pub level_height_m: f64,
    /// Height of footprints with neither height nor levels, metres. Default 10.
    pub default_height_m: f64,
    /// How far the floor goes below the lowest terrain under the footprint, metres. Default 0.5.
    pub embed_m: f64,
    /// Material of every face. Default the building class's: concrete.
    pub material: Material,
}

impl Default for OsmBaselineParams {
    fn default() -> Self {
        OsmBaselineParams {
            level_height_m: 3.0,
            default_height_m: 10.0,
            embed_m: 0.5,
            material: default_material(ObjectClass::Building),
        }
    }
}

/// One flat-topped prism per footprint polygon, `building-<id>`, in footprint order.
pub struct OsmBaseline;

impl Stage for OsmBaseline {
    const KIND: &'static str = "OsmBaseline";
    const VERSION: u32 = 1;
    const DOC: &'static str = "baseline scene: footprints extruded flat to tagged/levels/default heights on coarse terrain, as the peers build it, Sec. 5";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "footprints",
            ArtifactType::Footprints,
            "building footprints (OSM, GeoJSON)",
        ),
        InputSpec::one(
            "terrain",
            ArtifactType::Raster,
            "the terrain the prisms stand on (e.g. Coarsen to 30 m)",
        ),
    ];
    type Params = OsmBaselineParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v) in [
            ("level_height_m", p.level_height_m),
            ("default_height_m", p.default_height_m),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(ParamError::new(
                    name,
                    "expected a positive height in metres",
                ));
            }
        }
        if !(p.embed_m >= 0.01 && p.embed_m.is_finite()) {
            return Err(ParamError::new("embed_m", "expected at least 0.01 m"));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        let footprints: &Footprints = inputs.one("footprints")?;
        let terrain: &Raster = inputs.one("terrain")?;
        let g = terrain.grid;
        let on_site = |q: &[f64; 2]| g.cell_of(q[0], q[1]).is_some();
        let (mut outside, mut invalid) = (0usize, Vec::new());
        let mut objects = Vec::new();
        for f in &footprints.items {
            let height = baseline_height(f, p);
            let id = if f.id.starts_with("building") {
                f.id.clone()
            } else {
                format!("building-{}", f.id)
            };
            let mut mesh = crate::artifact::Mesh::default();
            for poly in &f.polygons {
                if !poly.exterior.iter().any(on_site) {
                    outside += 1;
                    continue;
                }
                let ground: Vec<f64> = poly
                    .exterior
                    .iter()
                    .filter_map(|q| terrain.bilinear(q[0], q[1]))
                    .collect();
                if ground.is_empty() {
                    outside += 1;
                    continue;
                }
                let base = ground.iter().sum::<f64>() / ground.len() as f64;
                let floor = ground.iter().copied().fold(f64::INFINITY, f64::min) - p.embed_m;
                match prism(poly, floor, base + height, p.material, p.material)
                    .and_then(|m| check_solid(&m).map(|_| m))
                {
                    Ok(m) => mesh.append(&m),
                    Err(e) => invalid.push(format!("{}: {e}", f.id)),
                }
            }
            if !mesh.is_empty() {
                objects.push(SceneObject {
                    id,
                    class: ObjectClass::Building,
                    mesh,
                });
            }
        }
        if outside > 0 {
            ctx.progress.warn(&format!(
                "{outside} footprint polygons lie outside the terrain and were left out"
            ));
        }
        if !invalid.is_empty() {
            ctx.progress.warn(&format!(
                "{} footprint polygons are not valid solids and were left out (first: {})",
                invalid.len(),
                invalid[0]
            ));
        }
        Ok(Scene { objects })
    }
}

/// The height the peers extrude a footprint to: its tag, else levels x storey height, else the
/// default.
pub fn baseline_height(f: &Footprint, p: &OsmBaselineParams) -> f64 {
    f.height_m
        .filter(|h| *h > 0.0)
        .or_else(|| f.levels.filter(|l| *l > 0.0).map(|l| l * p.level_height_m))
        .unwrap_or(p.default_height_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_come_from_tags_then_levels_then_the_default() {
        let p = OsmBaselineParams::default();
        let f = |height_m, levels| Footprint {
            id: "w1".into(),
            polygons: vec![],
            height_m,
            min_height_m: None,
            levels,
            min_level: None,
        };
        assert_eq!(baseline_height(&f(Some(17.5), Some(3.0)), &p), 17.5);
        assert_eq!(baseline_height(&f(None, Some(4.0)), &p), 12.0);
        assert_eq!(baseline_height(&f(None, None), &p), 10.0);
    }
}
