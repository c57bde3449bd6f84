//! The OSM baseline scene (paper Sec. 5): footprints extruded flat to their tagged height, or
//! levels x 3 m, or a default, standing on coarse terrain. This is the construction Geo2SigMap,
//! OpenGERT and Blosm use, built here so KODAMA's scenes can be scored against it on equal terms.

use serde::{Deserialize, Serialize};

use crate::artifact::{
    ArtifactType, Footprint, Footprints, Mesh, Metrics, ObjectClass, Polygon, Raster, Scene,
    SceneObject, Typed,
};
use crate::artifact::{Material, default_material};
use crate::geom::mesh_build::prism;
use crate::geom::mesh_check::{OnInvalid, check_solid};
use crate::geom::polygon::{convex_hull, simplify_polygon};
use crate::geom::terrain_mesh::terrain_object;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, ReportSpec, Reported, Stage, StageError};

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
    /// Whether the scene carries the terrain as a mesh (object `terrain`, one vertex per terrain
    /// cell), so that tracing this scene alone keeps the ground reflection. Default `Include`;
    /// AssembleScene replaces it with its own terrain either way.
    pub ground: Ground,
    /// Material of the ground. Default the terrain class's: medium dry ground.
    pub terrain_material: Material,
    /// A footprint whose prism is not a valid solid: `Repair` (default) tries, in order, the
    /// footprint's polygons as separate objects `<id>/<k>` (touching parts of one relation), the
    /// polygon simplified at 1 cm (spikes, repeated or collinear vertices), then its convex hull;
    /// what none of these mends is dropped. `Drop` drops at once; `Fail` stops the run. Every
    /// repair and drop is counted in the report `counts`.
    pub on_invalid: OnInvalid,
}

/// Whether a baseline scene carries its ground.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Ground {
    /// The terrain's mesh is the scene's first object.
    Include,
    /// Buildings only.
    Omit,
}

impl Default for OsmBaselineParams {
    fn default() -> Self {
        OsmBaselineParams {
            level_height_m: 3.0,
            default_height_m: 10.0,
            embed_m: 0.5,
            material: default_material(ObjectClass::Building),
            ground: Ground::Include,
            terrain_material: default_material(ObjectClass::Terrain),
            on_invalid: OnInvalid::Repair,
        }
    }
}

/// One flat-topped prism per footprint polygon, `building-<id>`, in footprint order, on the
/// terrain's mesh.
pub struct OsmBaseline;

impl Stage for OsmBaseline {
    const KIND: &'static str = "OsmBaseline";
    // 2: the ground in the scene (`ground`), invalid solids repaired or dropped (`on_invalid`) and
    // a building's polygons checked together, counts in the report `counts`.
    const VERSION: u32 = 2;
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
            "the terrain the prisms stand on (e.g. Coarsen to 30 m, or FlatGround)",
        ),
    ];
    type Params = OsmBaselineParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v) in [
            ("level_height_m", p.level_height_m),
            ("default_height_m", p.default_height_m),
        ] {
            if !(v > 0.0 && v.is_finite() && v <= 1000.0) {
                return Err(ParamError::new(
                    name,
                    format!("expected a positive height up to 1000 m, found {v}"),
                ));
            }
        }
        if !(p.embed_m >= 0.01 && p.embed_m.is_finite() && p.embed_m <= 1000.0) {
            return Err(ParamError::new(
                "embed_m",
                "expected at least 0.01 m and at most 1000 m",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        Ok(baseline_scene(p, inputs, ctx)?.0)
    }

    const REPORTS: &'static [ReportSpec] = &[ReportSpec {
        name: "counts",
        ty: ArtifactType::Metrics,
        doc: "footprints read and built, where each height came from (tag, levels, default), polygons outside the terrain, and invalid solids repaired (split, simplified, hull) or dropped",
    }];

    fn run_reported(
        p: &Self::Params,
        inputs: &Inputs,
        ctx: &Ctx,
    ) -> Result<Reported<Scene>, StageError> {
        let (scene, counts) = baseline_scene(p, inputs, ctx)?;
        Ok(Reported {
            output: scene,
            reports: vec![("counts", counts.metrics(p).into_artifact())],
        })
    }
}

/// What [`baseline_scene`] did, for the report.
#[derive(Default)]
struct Counts {
    footprints: usize,
    buildings: usize,
    polygons: usize,
    outside_terrain: usize,
    height_from_tag: usize,
    height_from_levels: usize,
    height_default: usize,
    split: usize,
    simplified: usize,
    hull: usize,
    dropped: usize,
    /// The first few dropped polygons with the check they failed, for the warning.
    dropped_why: Vec<String>,
}

impl Counts {
    fn metrics(&self, p: &OsmBaselineParams) -> Metrics {
        let mut m = Metrics::default();
        for (k, v) in [
            ("footprints", self.footprints),
            ("buildings", self.buildings),
            ("polygons", self.polygons),
            ("polygons_outside_terrain", self.outside_terrain),
            ("height_from_tag", self.height_from_tag),
            ("height_from_levels", self.height_from_levels),
            ("height_default", self.height_default),
            ("repaired_split", self.split),
            ("repaired_simplified", self.simplified),
            ("repaired_hull", self.hull),
            ("polygons_dropped", self.dropped),
        ] {
            m.set(k, v as f64);
        }
        m.set("default_height_m", p.default_height_m);
        m.set("level_height_m", p.level_height_m);
        m
    }
}

/// How a polygon's prism became a valid solid.
enum Mend {
    AsIs,
    Simplified,
    Hull,
}

/// The scene and what was counted on the way.
fn baseline_scene(
    p: &OsmBaselineParams,
    inputs: &Inputs,
    ctx: &Ctx,
) -> Result<(Scene, Counts), StageError> {
    let footprints: &Footprints = inputs.one("footprints")?;
    let terrain: &Raster = inputs.one("terrain")?;
    let g = terrain.grid;
    let on_site = |q: &[f64; 2]| g.cell_of(q[0], q[1]).is_some();
    let mut c = Counts {
        footprints: footprints.items.len(),
        ..Counts::default()
    };
    let mut objects = Vec::new();
    if p.ground == Ground::Include {
        objects.push(
            terrain_object(terrain, g.cell_m, p.terrain_material).map_err(StageError::Failed)?,
        );
    }
    for f in &footprints.items {
        let (height, source) = height_and_source(f, p);
        let id = if f.id.starts_with("building") {
            f.id.clone()
        } else {
            format!("building-{}", f.id)
        };
        let mut parts: Vec<Mesh> = Vec::new();
        for poly in &f.polygons {
            if !poly.exterior.iter().any(on_site) {
                c.outside_terrain += 1;
                continue;
            }
            let ground: Vec<f64> = poly
                .exterior
                .iter()
                .filter_map(|q| terrain.bilinear(q[0], q[1]))
                .collect();
            if ground.is_empty() {
                c.outside_terrain += 1;
                continue;
            }
            c.polygons += 1;
            let base = ground.iter().sum::<f64>() / ground.len() as f64;
            let floor = ground.iter().copied().fold(f64::INFINITY, f64::min) - p.embed_m;
            match valid_prism(poly, floor, base + height, p) {
                Ok((m, mend)) => {
                    match mend {
                        Mend::AsIs => {}
                        Mend::Simplified => c.simplified += 1,
                        Mend::Hull => c.hull += 1,
                    }
                    parts.push(m);
                }
                Err(e) if p.on_invalid == OnInvalid::Fail => {
                    return Err(StageError::Failed(format!(
                        "footprint {}: {e} (on_invalid: Repair or Drop leaves such buildings out, counted)",
                        f.id
                    )));
                }
                Err(e) => {
                    c.dropped += 1;
                    if c.dropped_why.len() < 3 {
                        c.dropped_why.push(format!("{}: {e}", f.id));
                    }
                }
            }
        }
        if parts.is_empty() {
            continue;
        }
        match source {
            HeightSource::Tag => c.height_from_tag += 1,
            HeightSource::Levels => c.height_from_levels += 1,
            HeightSource::Default => c.height_default += 1,
        }
        let mut mesh = Mesh::default();
        for m in &parts {
            mesh.append(m);
        }
        // Each part is a valid solid; together they may touch or overlap (the polygons of one
        // relation), which the scene's check refuses.
        let whole = if parts.len() > 1 {
            check_solid(&mesh).map(|_| ())
        } else {
            Ok(())
        };
        match (whole, p.on_invalid) {
            (Ok(()), _) => {
                c.buildings += 1;
                objects.push(SceneObject {
                    id,
                    class: ObjectClass::Building,
                    mesh,
                });
            }
            (Err(e), OnInvalid::Fail) => {
                return Err(StageError::Failed(format!(
                    "footprint {}: its {} polygons together: {e} (on_invalid: Repair makes each its own object)",
                    f.id,
                    parts.len()
                )));
            }
            (Err(e), OnInvalid::Drop) => {
                c.dropped += parts.len();
                if c.dropped_why.len() < 3 {
                    c.dropped_why.push(format!("{}: {e}", f.id));
                }
            }
            (Err(_), OnInvalid::Repair) => {
                c.split += 1;
                c.buildings += 1;
                for (k, mesh) in parts.into_iter().enumerate() {
                    objects.push(SceneObject {
                        id: format!("{id}/{k}"),
                        class: ObjectClass::Building,
                        mesh,
                    });
                }
            }
        }
    }
    warn_counts(&c, ctx);
    Ok((Scene { objects }, c))
}

/// The warnings a user reads in the run's log; the counts go to the report.
fn warn_counts(c: &Counts, ctx: &Ctx) {
    if c.outside_terrain > 0 {
        ctx.progress.warn(&format!(
            "{} footprint polygons lie outside the terrain and were left out",
            c.outside_terrain
        ));
    }
    if c.height_default > 0 {
        ctx.progress.warn(&format!(
            "{} of {} buildings have neither a height nor a levels tag and stand at the default height",
            c.height_default, c.buildings
        ));
    }
    if c.dropped > 0 {
        ctx.progress.warn(&format!(
            "{} footprint polygons are not valid solids and were left out (first: {})",
            c.dropped,
            c.dropped_why.join("; ")
        ));
    }
    let mended = c.split + c.simplified + c.hull;
    if mended > 0 {
        ctx.progress.warn(&format!(
            "{mended} invalid solids were repaired: {} buildings split into their polygons, {} \
             polygons simplified, {} replaced by their convex hull",
            c.split, c.simplified, c.hull
        ));
    }
}

/// The prism of `poly` from `z0` to `z1` as a checked solid, mended as `p.on_invalid` allows.
fn valid_prism(
    poly: &Polygon,
    z0: f64,
    z1: f64,
    p: &OsmBaselineParams,
) -> Result<(Mesh, Mend), String> {
    let solid = |q: &Polygon| {
        prism(q, z0, z1, p.material, p.material).and_then(|m| check_solid(&m).map(|_| m))
    };
    let first = match solid(poly) {
        Ok(m) => return Ok((m, Mend::AsIs)),
        Err(e) => e,
    };
    if p.on_invalid != OnInvalid::Repair {
        return Err(first);
    }
    /// Tolerance of the simplification: 1 cm, below any wall OSM maps.
    const SIMPLIFY_M: f64 = 0.01;
    let simplified = simplify_polygon(poly.clone(), SIMPLIFY_M);
    if let Some(q) = Polygon::normalized(simplified.exterior, simplified.holes)
        && let Ok(m) = solid(&q)
    {
        return Ok((m, Mend::Simplified));
    }
    if let Some(q) = Polygon::normalized(convex_hull(poly.exterior.clone()), Vec::new())
        && let Ok(m) = solid(&q)
    {
        return Ok((m, Mend::Hull));
    }
    Err(first)
}

/// Where a baseline height came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum HeightSource {
    Tag,
    Levels,
    Default,
}

/// [`baseline_height`] and which rule gave it.
fn height_and_source(f: &Footprint, p: &OsmBaselineParams) -> (f64, HeightSource) {
    if let Some(h) = f.height_m.filter(|h| *h > 0.0 && h.is_finite()) {
        (h, HeightSource::Tag)
    } else if let Some(l) = f.levels.filter(|l| *l > 0.0 && l.is_finite()) {
        (l * p.level_height_m, HeightSource::Levels)
    } else {
        (p.default_height_m, HeightSource::Default)
    }
}

/// The height the peers extrude a footprint to: its tag, else levels x storey height, else the
/// default.
pub fn baseline_height(f: &Footprint, p: &OsmBaselineParams) -> f64 {
    height_and_source(f, p).0
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
