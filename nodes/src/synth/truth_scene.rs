//! The synthetic city's ground truth as a scene: closed building solids with their roof shapes,
//! tree crowns as foliage volumes, clutter, on a terrain surface.

use serde::{Deserialize, Serialize};

use crate::artifact::RECESS_M;
use crate::artifact::height_at;
use crate::artifact::{
    ArtifactType, BuildingSpec, City, FacadeFeature, FeatureKind, Mesh, ObjectClass, Polygon, Rect,
    Roof, Scene, SceneObject,
};
use crate::geom::mesh_build::{cuboid, dome, ellipsoid, gabled, height_surface, hipped, prism};
use crate::rf::materials::Material;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`TruthScene`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TruthSceneParams {
    /// Terrain mesh spacing, metres. Default 2.
    pub terrain_step_m: f64,
    /// Ground material. Default MediumDryGround.
    pub ground: Material,
}

impl Default for TruthSceneParams {
    fn default() -> Self {
        TruthSceneParams {
            terrain_step_m: 2.0,
            ground: Material::MediumDryGround,
        }
    }
}

/// Meshes a [`City`].
pub struct TruthScene;

impl Stage for TruthScene {
    const KIND: &'static str = "TruthScene";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "ground-truth scene of a synthetic city: terrain, closed buildings, foliage, clutter";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "city",
        ArtifactType::City,
        "the synthetic city",
    )];
    type Params = TruthSceneParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.terrain_step_m >= 0.25) {
            return Err(ParamError::new(
                "terrain_step_m",
                "expected at least 0.25 m",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        let city: &City = inputs.one("city")?;
        ctx.progress.set_total(city.buildings.len() as u64 + 1);
        let mut scene = Scene::default();
        let nx = (city.size_m.0 / p.terrain_step_m).ceil() as u32 + 1;
        let ny = (city.size_m.1 / p.terrain_step_m).ceil() as u32 + 1;
        let terrain = height_surface(
            [0.0, 0.0],
            nx,
            ny,
            p.terrain_step_m,
            |x, y| height_at(&city.terrain, x, y),
            p.ground,
        );
        scene.objects.push(SceneObject {
            id: "terrain".into(),
            class: ObjectClass::Terrain,
            mesh: terrain,
        });
        ctx.progress.advance(1);
        for b in &city.buildings {
            let mesh =
                building_mesh(b).map_err(|m| StageError::Failed(format!("{}: {m}", b.id)))?;
            scene.objects.push(SceneObject {
                id: b.id.clone(),
                class: ObjectClass::Building,
                mesh,
            });
            ctx.progress.advance(1);
        }
        for t in &city.trees {
            let mut mesh = cuboid(
                t.pos,
                [0.35, 0.35, t.trunk_m + 0.5],
                0.0,
                t.ground_z - 0.5,
                Material::Wood,
            );
            let cz = t.ground_z + t.trunk_m + t.crown_m / 2.0;
            mesh.append(&ellipsoid(
                [t.pos[0], t.pos[1], cz],
                [t.crown_radius_m, t.crown_radius_m, t.crown_m / 2.0],
                16,
                Material::Foliage,
            ));
            scene.objects.push(SceneObject {
                id: t.id.clone(),
                class: ObjectClass::Vegetation,
                mesh,
            });
        }
        for c in &city.clutter {
            // Bodies sink 0.2 m into the ground so sloped terrain leaves no gap underneath.
            let z0 = c.ground_z + c.lift_m - if c.lift_m > 0.0 { 0.0 } else { 0.2 };
            let size = [
                c.size[0],
                c.size[1],
                c.size[2] + if c.lift_m > 0.0 { 0.0 } else { 0.2 },
            ];
            scene.objects.push(SceneObject {
                id: c.id.clone(),
                class: ObjectClass::Clutter,
                mesh: cuboid(c.center, size, c.heading, z0, c.material),
            });
        }
        Ok(scene)
    }
}

/// The truth's terrain and every building's outline extruded from its base to the eave: the
/// walls the street views look at, without relief, roof shapes or clutter. What fusion is scored
/// on, so the score is the operator's and not the building reconstruction's.
pub fn wall_prisms(city: &City, truth: &Scene) -> Result<Scene, String> {
    let mut objects: Vec<SceneObject> = truth
        .objects
        .iter()
        .filter(|o| o.class == ObjectClass::Terrain)
        .cloned()
        .collect();
    for b in &city.buildings {
        objects.push(SceneObject {
            id: b.id.clone(),
            class: ObjectClass::Building,
            mesh: prism(
                &b.footprint,
                b.base_z,
                b.ground_z + b.eave_m,
                b.facade,
                b.roof_material,
            )
            .map_err(|e| format!("{}: {e}", b.id))?,
        });
    }
    Ok(Scene { objects })
}

/// The closed shells of one building: the main body with its roof, a stepped tier or dome, roof
/// furniture and façade relief. Parts that touch start 0.05 m inside each other so no two shells
/// share a face.
pub fn building_mesh(b: &BuildingSpec) -> Result<Mesh, String> {
    let eave = b.ground_z + b.eave_m;
    const EMBED: f64 = 0.05;
    let relief = !b.features.is_empty();
    // With façade relief the body is a core set back by the recess depth, glazed: windows and
    // doors are the core showing through openings in the outer wall layer built around it.
    let d = if relief { RECESS_M } else { 0.0 };
    let walls = if relief { Material::Glass } else { b.facade };
    let mut mesh = match &b.roof {
        Roof::Gabled { rect, ridge_m } | Roof::Hipped { rect, ridge_m } => {
            let r = inset_rect(rect, d);
            let roof = if matches!(b.roof, Roof::Gabled { .. }) {
                gabled
            } else {
                hipped
            };
            let mut m = roof(
                &r,
                eave - EMBED,
                eave,
                eave + ridge_m,
                b.facade,
                b.roof_material,
            );
            m.append(&prism(
                &Polygon::normalized(r.corners(), vec![]).ok_or("degenerate roof rectangle")?,
                b.base_z,
                eave,
                walls,
                b.roof_material,
            )?);
            m
        }
        _ => prism(
            &inset(&b.footprint, d)?,
            b.base_z,
            eave,
            walls,
            b.roof_material,
        )?,
    };
    match &b.roof {
        Roof::Stepped { upper, upper_m } => mesh.append(&prism(
            upper,
            eave - EMBED,
            eave + upper_m,
            b.facade,
            b.roof_material,
        )?),
        Roof::Domed {
            center,
            radius_m,
            height_m,
        } => mesh.append(&dome(
            *center,
            *radius_m,
            height_m + EMBED,
            eave - EMBED,
            32,
            Material::Metal,
        )),
        _ => {}
    }
    for f in &b.furniture {
        mesh.append(&cuboid(
            f.center,
            [f.size[0], f.size[1], f.size[2] + EMBED],
            0.0,
            eave - EMBED,
            Material::Metal,
        ));
    }
    if relief {
        facade_relief(b, eave, &mut mesh);
    }
    Ok(mesh)
}

/// A closed box on edge (`a`, `t`, `nl` = unit direction and inward normal): `along` metres from
/// `a`, `inward` metres from the outline into the building (negative: outside), `z` in height.
fn edge_box(
    a: [f64; 2],
    t: [f64; 2],
    nl: [f64; 2],
    along: (f64, f64),
    inward: (f64, f64),
    z: (f64, f64),
    m: Material,
) -> Mesh {
    let (s, n) = ((along.0 + along.1) / 2.0, (inward.0 + inward.1) / 2.0);
    let center = [a[0] + t[0] * s + nl[0] * n, a[1] + t[1] * s + nl[1] * n];
    cuboid(
        center,
        [along.1 - along.0, inward.1 - inward.0, z.1 - z.0],
        t[1].atan2(t[0]),
        z.0,
        m,
    )
}

fn facade_relief(b: &BuildingSpec, eave: f64, mesh: &mut Mesh) {
    const EMBED: f64 = 0.05;
    let rings: Vec<&Vec<[f64; 2]>> = std::iter::once(&b.footprint.exterior)
        .chain(&b.footprint.holes)
        .collect();
    for (ri, ring) in rings.iter().enumerate() {
        for e in 0..ring.len() {
            let (a, c) = (ring[e], ring[(e + 1) % ring.len()]);
            let len = (c[0] - a[0]).hypot(c[1] - a[1]);
            let t = [(c[0] - a[0]) / len, (c[1] - a[1]) / len];
            // The solid is left of every ring edge (exterior counter-clockwise, holes clockwise).
            let nl = [-t[1], t[0]];
            let here: Vec<&FacadeFeature> = b
                .features
                .iter()
                .filter(|f| f.ring == ri && f.edge == e)
                .collect();
            let openings: Vec<&&FacadeFeature> = here.iter().filter(|f| f.depth_m < 0.0).collect();
            // The outer wall layer, base to eave, minus the openings: sweep the height breakpoints
            // and cut each band at the openings spanning it.
            let mut zs: Vec<f64> = vec![b.base_z, eave];
            zs.extend(
                openings
                    .iter()
                    .flat_map(|o| [o.z.0, o.z.1])
                    .filter(|z| *z > b.base_z && *z < eave),
            );
            zs.sort_by(f64::total_cmp);
            zs.dedup_by(|x, y| (*x - *y).abs() < 1e-6);
            for band in zs.windows(2) {
                let (z0, z1) = (band[0], band[1]);
                let mut cuts: Vec<(f64, f64)> = openings
                    .iter()
                    .filter(|o| o.z.0 <= z0 + 1e-6 && o.z.1 >= z1 - 1e-6)
                    .map(|o| o.along)
                    .collect();
                cuts.sort_by(|p, q| p.0.total_cmp(&q.0));
                let mut s = 0.0;
                for (c0, c1) in cuts.into_iter().chain(std::iter::once((len, len))) {
                    if c0 - s > 1e-6 {
                        mesh.append(&edge_box(
                            a,
                            t,
                            nl,
                            (s, c0),
                            (0.0, RECESS_M + EMBED),
                            (z0, z1),
                            b.facade,
                        ));
                    }
                    s = s.max(c1);
                }
            }
            for f in here {
                match f.kind {
                    FeatureKind::Door => mesh.append(&edge_box(
                        a,
                        t,
                        nl,
                        f.along,
                        (RECESS_M - 0.05, RECESS_M + EMBED),
                        f.z,
                        Material::Wood,
                    )),
                    FeatureKind::Balcony => {
                        let slab = (f.z.0, f.z.0 + 0.15);
                        mesh.append(&edge_box(
                            a,
                            t,
                            nl,
                            f.along,
                            (-f.depth_m, EMBED),
                            slab,
                            Material::Concrete,
                        ));
                        mesh.append(&edge_box(
                            a,
                            t,
                            nl,
                            f.along,
                            (-f.depth_m, -f.depth_m + 0.05),
                            (slab.1 - EMBED, f.z.1),
                            Material::Metal,
                        ));
                    }
                    FeatureKind::Drainpipe => mesh.append(&edge_box(
                        a,
                        t,
                        nl,
                        f.along,
                        (-f.depth_m, EMBED),
                        f.z,
                        Material::Metal,
                    )),
                    FeatureKind::Window => {}
                }
            }
        }
    }
}

/// The rectangle shrunk by `d` on every side.
fn inset_rect(r: &Rect, d: f64) -> Rect {
    let (s, c) = r.heading.sin_cos();
    Rect {
        corner: [r.corner[0] + c * d - s * d, r.corner[1] + s * d + c * d],
        length: r.length - 2.0 * d,
        width: r.width - 2.0 * d,
        heading: r.heading,
    }
}

/// The polygon shrunk by `d` (every edge moved `d` into the solid, mitred corners).
fn inset(p: &Polygon, d: f64) -> Result<Polygon, String> {
    if d == 0.0 {
        return Ok(p.clone());
    }
    let ring = |r: &Vec<[f64; 2]>| -> Vec<[f64; 2]> {
        let n = r.len();
        (0..n)
            .map(|i| {
                let (p0, p1, p2) = (r[(i + n - 1) % n], r[i], r[(i + 1) % n]);
                let unit = |a: [f64; 2], b: [f64; 2]| {
                    let l = (b[0] - a[0]).hypot(b[1] - a[1]);
                    [(b[0] - a[0]) / l, (b[1] - a[1]) / l]
                };
                let (t0, t1) = (unit(p0, p1), unit(p1, p2));
                let (n0, n1) = ([-t0[1], t0[0]], [-t1[1], t1[0]]);
                // Intersection of the two offset lines: p1 + d * (n0 + n1) / (1 + n0 . n1).
                let k = d / (1.0 + n0[0] * n1[0] + n0[1] * n1[1]);
                [p1[0] + k * (n0[0] + n1[0]), p1[1] + k * (n0[1] + n1[1])]
            })
            .collect()
    };
    Polygon::normalized(ring(&p.exterior), p.holes.iter().map(ring).collect())
        .ok_or_else(|| "the outline is too small for its façade".into())
}
