//! Scenes as CityJSON 2.0 (<https://www.cityjson.org/specs/2.0.1/>): what GIS and city-model
//! tools (QGIS's CityJSON loader, ninja, cjio, FME) open buildings in.
//!
//! One city object per scene object: a `Building` (LoD 2: roofs from the survey, walls to the
//! ground), a `TINRelief` for the terrain, a `SolitaryVegetationObject` per tree, `CityFurniture`
//! for clutter, a `GenericCityObject` for an unsegmented surface; each with the area share of
//! its ITU-R P.2040 materials (`itu_material_area_share`). Each triangle is one surface; on a
//! building (the only one of these types CityJSON gives semantic surfaces) its semantic surface
//! names its material (`itu_material`) and what it is by its normal: `RoofSurface` facing up, `GroundSurface` facing down at the
//! building's foot, `OuterCeilingSurface` facing down above it, `WallSurface` otherwise.
//! A building whose shells are all closed is a `Solid`, or, of several shells, a `Building` whose
//! `BuildingPart` children are one `Solid` each (CityJSON has no multi-solid building); an open
//! one a `MultiSurface`. Vertices are in the site's CRS at millimetre resolution (the `transform`),
//! deduplicated; triangles that millimetres collapse are dropped.

use std::collections::{BTreeMap, HashMap};

use glam::DVec3;
use serde_json::{Value, json};

use super::object_properties::{material_area_shares, z_range};
use crate::artifact::{Material, ObjectClass, Scene, SceneObject};
use crate::site::Site;

/// The vertices' resolution, metres.
const SCALE_M: f64 = 0.001;

/// The sine of the slope from the horizontal below which a face is a wall (10 degrees).
const WALL_SIN: f64 = 0.173_648;

/// How far above a building's lowest point a downward face still counts as its ground, metres.
const FOOT_M: f64 = 0.25;

/// The document's shared vertex list, quantized and deduplicated.
struct Vertices {
    translate: [f64; 3],
    index: HashMap<[i64; 3], u32>,
    list: Vec<[i64; 3]>,
}

impl Vertices {
    /// The index of site-frame point `p` (quantized, `origin` added to x and y).
    fn of(&mut self, p: [f32; 3], origin: (f64, f64)) -> Result<u32, String> {
        let world = [p[0] as f64 + origin.0, p[1] as f64 + origin.1, p[2] as f64];
        let mut q = [0i64; 3];
        for k in 0..3 {
            let v = ((world[k] - self.translate[k]) / SCALE_M).round();
            if !v.is_finite() || v.abs() > 2f64.powi(53) {
                return Err(format!("a vertex at {p:?} is not a finite coordinate"));
            }
            q[k] = v as i64;
        }
        let next = self.list.len() as u32;
        Ok(*self.index.entry(q).or_insert_with(|| {
            self.list.push(q);
            next
        }))
    }
}

/// What a building triangle is by its normal and height (module docs).
fn building_surface(n: DVec3, top_z: f64, foot_z: f64) -> &'static str {
    let nz = n.normalize_or_zero().z;
    if nz > WALL_SIN {
        "RoofSurface"
    } else if nz < -WALL_SIN {
        if top_z <= foot_z + FOOT_M {
            "GroundSurface"
        } else {
            "OuterCeilingSurface"
        }
    } else {
        "WallSurface"
    }
}

/// The CityJSON type of a scene object's class.
fn city_type(class: ObjectClass) -> &'static str {
    match class {
        ObjectClass::Building => "Building",
        ObjectClass::Terrain => "TINRelief",
        ObjectClass::Vegetation => "SolitaryVegetationObject",
        ObjectClass::Clutter => "CityFurniture",
        ObjectClass::Unsegmented => "GenericCityObject",
    }
}

/// The connected groups of `tris` (sharing a vertex), each in first-triangle order, and whether
/// every group is closed: each directed edge once, its reverse once.
fn shells(tris: &[[u32; 3]]) -> (Vec<Vec<usize>>, bool) {
    let mut parent: HashMap<u32, u32> = HashMap::new();
    fn root(parent: &mut HashMap<u32, u32>, v: u32) -> u32 {
        let mut r = v;
        while let Some(&p) = parent.get(&r)
            && p != r
        {
            r = p;
        }
        parent.insert(v, r);
        r
    }
    for t in tris {
        for &v in t {
            parent.entry(v).or_insert(v);
        }
        let a = root(&mut parent, t[0]);
        for &v in &t[1..] {
            let b = root(&mut parent, v);
            if a != b {
                parent.insert(b, a);
            }
        }
    }
    let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    let mut first_of: HashMap<u32, usize> = HashMap::new();
    for (k, t) in tris.iter().enumerate() {
        let r = root(&mut parent, t[0]);
        let first = *first_of.entry(r).or_insert(k);
        groups.entry(first).or_default().push(k);
    }
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for t in tris {
        for (p, q) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *directed.entry((p, q)).or_default() += 1;
        }
    }
    let closed = directed
        .iter()
        .all(|(&(p, q), &n)| n == 1 && directed.get(&(q, p)) == Some(&1));
    (groups.into_values().collect(), closed)
}

/// One scene object as city objects (a building of several shells is a building and its parts),
/// by id, its vertices added to `verts`; none when millimetres leave it no triangle.
fn city_objects(
    obj: &SceneObject,
    verts: &mut Vertices,
    origin: (f64, f64),
) -> Result<Vec<(String, Value)>, String> {
    let mesh = &obj.mesh;
    let (foot_z, top_z) = z_range(mesh);
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(mesh.triangles.len());
    let mut kinds: Vec<usize> = Vec::with_capacity(mesh.triangles.len());
    let mut surfaces: Vec<(&'static str, &'static str)> = Vec::new();
    for (k, t) in mesh.triangles.iter().enumerate() {
        let corners = t.map(|i| mesh.positions[i as usize]);
        let q = [
            verts.of(corners[0], origin)?,
            verts.of(corners[1], origin)?,
            verts.of(corners[2], origin)?,
        ];
        if q[0] == q[1] || q[1] == q[2] || q[0] == q[2] {
            continue;
        }
        let [a, b, c] = corners.map(|p| DVec3::from(p.map(|v| v as f64)));
        let n = (b - a).cross(c - a);
        let code = mesh.materials[k];
        let material = Material::from_u8(code)
            .ok_or_else(|| format!("{}: unknown material id {code}", obj.id))?;
        let name = material.itu_type().unwrap_or("foliage");
        let kind = match obj.class {
            ObjectClass::Building => building_surface(n, a.z.max(b.z).max(c.z), foot_z),
            _ => "",
        };
        let s = match surfaces.iter().position(|&s| s == (kind, name)) {
            Some(s) => s,
            None => {
                surfaces.push((kind, name));
                surfaces.len() - 1
            }
        };
        tris.push(q);
        kinds.push(s);
    }
    if tris.is_empty() {
        return Ok(Vec::new());
    }
    let surface = |k: usize| json!([[tris[k][0], tris[k][1], tris[k][2]]]);
    let semantic_surfaces: Vec<Value> = surfaces
        .iter()
        .map(|&(kind, material)| json!({ "type": kind, "itu_material": material }))
        .collect();
    let shares = material_area_shares(mesh).map_err(|e| format!("{}: {e}", obj.id))?;
    let mut attributes = json!({ "itu_material_area_share": shares });
    let mut out = Vec::new();
    if obj.class != ObjectClass::Building {
        let ty = if obj.class == ObjectClass::Terrain {
            "CompositeSurface"
        } else {
            "MultiSurface"
        };
        let geometry = json!({
            "type": ty,
            "lod": "1",
            "boundaries": (0..tris.len()).map(surface).collect::<Vec<_>>(),
        });
        out.push((
            obj.id.clone(),
            json!({ "type": city_type(obj.class), "attributes": attributes, "geometry": [geometry] }),
        ));
        return Ok(out);
    }
    attributes["measuredHeight"] = json!(((top_z - foot_z) * 100.0).round() / 100.0);
    let with_semantics = |ty: &str, boundaries: Value, values: Value| {
        json!({
            "type": ty,
            "lod": "2",
            "boundaries": boundaries,
            "semantics": { "surfaces": semantic_surfaces, "values": values },
        })
    };
    let (groups, closed) = shells(&tris);
    let solid = |g: &Vec<usize>| {
        with_semantics(
            "Solid",
            json!([g.iter().map(|&k| surface(k)).collect::<Vec<_>>()]),
            json!([g.iter().map(|&k| kinds[k]).collect::<Vec<_>>()]),
        )
    };
    if !closed {
        let geometry = with_semantics(
            "MultiSurface",
            Value::Array((0..tris.len()).map(surface).collect()),
            json!(kinds),
        );
        out.push((
            obj.id.clone(),
            json!({ "type": "Building", "attributes": attributes, "geometry": [geometry] }),
        ));
    } else if groups.len() == 1 {
        out.push((
            obj.id.clone(),
            json!({ "type": "Building", "attributes": attributes, "geometry": [solid(&groups[0])] }),
        ));
    } else {
        // CityJSON has no multi-solid building: each closed shell is a part of it, as CityGML's
        // BuildingPart.
        let parts: Vec<String> = (1..=groups.len())
            .map(|k| format!("{}/part-{k}", obj.id))
            .collect();
        out.push((
            obj.id.clone(),
            json!({ "type": "Building", "attributes": attributes, "children": parts }),
        ));
        for (part, g) in parts.iter().zip(&groups) {
            let (lo, hi) = g
                .iter()
                .flat_map(|&k| tris[k])
                .map(|v| verts.list[v as usize][2] as f64 * SCALE_M)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
                    (lo.min(z), hi.max(z))
                });
            out.push((
                part.clone(),
                json!({
                    "type": "BuildingPart",
                    "parents": [obj.id],
                    "attributes": { "measuredHeight": ((hi - lo) * 100.0).round() / 100.0 },
                    "geometry": [solid(g)],
                }),
            ));
        }
    }
    Ok(out)
}

/// `scene` as a CityJSON 2.0 document in the site's CRS (module docs).
pub fn write_cityjson(scene: &Scene, site: &Site) -> Result<Vec<u8>, String> {
    let epsg = site.epsg()?;
    let (lo, hi) = scene
        .objects
        .iter()
        .flat_map(|o| o.mesh.positions.iter())
        .fold(
            ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
            |(lo, hi), p| {
                (
                    [0, 1, 2].map(|k| lo[k].min(p[k] as f64)),
                    [0, 1, 2].map(|k| hi[k].max(p[k] as f64)),
                )
            },
        );
    if !lo.iter().chain(&hi).all(|v| v.is_finite()) {
        return Err("a scene without vertices has no CityJSON".into());
    }
    let origin = site.origin;
    let mut verts = Vertices {
        translate: [
            (lo[0] + origin.0).floor(),
            (lo[1] + origin.1).floor(),
            lo[2].floor(),
        ],
        index: HashMap::new(),
        list: Vec::new(),
    };
    let mut objects = serde_json::Map::new();
    for obj in &scene.objects {
        for (id, o) in city_objects(obj, &mut verts, origin)? {
            if objects.insert(id.clone(), o).is_some() {
                return Err(format!("two city objects are named {id:?}"));
            }
        }
    }
    let doc = json!({
        "type": "CityJSON",
        "version": "2.0",
        "transform": { "scale": [SCALE_M, SCALE_M, SCALE_M], "translate": verts.translate },
        "metadata": {
            "referenceSystem": format!("https://www.opengis.net/def/crs/EPSG/0/{epsg}"),
            "geographicalExtent": [
                lo[0] + origin.0, lo[1] + origin.1, lo[2],
                hi[0] + origin.0, hi[1] + origin.1, hi[2],
            ],
        },
        "CityObjects": objects,
        "vertices": verts.list,
    });
    let mut out = serde_json::to_vec(&doc).map_err(|e| e.to_string())?;
    out.push(b'\n');
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Mesh, PodVec};
    use crate::geom::mesh_build::cuboid;
    use crate::rf::test_scenes::street_grid_scene;

    fn site() -> Site {
        Site {
            crs: "EPSG:32618".into(),
            origin: (583_200.0, 4_506_600.0),
            cell_m: 0.5,
        }
    }

    /// The street grid (36 closed concrete blocks and a ground) with a building of two separate
    /// blocks, a building left open (a block without its roof), and a tree of foliage.
    fn scene() -> Scene {
        let mut s = street_grid_scene();
        let mut two = cuboid([120.0, 0.0], [10.0, 10.0, 9.0], 0.0, 0.0, Material::Brick);
        two.append(&cuboid(
            [140.0, 0.0],
            [6.0, 6.0, 5.0],
            0.3,
            0.0,
            Material::Glass,
        ));
        s.objects.push(SceneObject {
            id: "two blocks".into(),
            class: ObjectClass::Building,
            mesh: two,
        });
        let mut open = cuboid([120.0, 40.0], [10.0, 10.0, 9.0], 0.0, 0.0, Material::Metal);
        let keep: Vec<usize> = (0..open.triangles.len())
            .filter(|&k| {
                let t = open.triangles[k];
                !t.iter().all(|&i| open.positions[i as usize][2] > 8.0)
            })
            .collect();
        open = Mesh {
            positions: open.positions.clone(),
            triangles: PodVec(keep.iter().map(|&k| open.triangles[k]).collect()),
            materials: PodVec(keep.iter().map(|&k| open.materials[k]).collect()),
        };
        s.objects.push(SceneObject {
            id: "open".into(),
            class: ObjectClass::Building,
            mesh: open,
        });
        s.objects.push(SceneObject {
            id: "tree-1".into(),
            class: ObjectClass::Vegetation,
            mesh: cuboid([150.0, 40.0], [4.0, 4.0, 4.0], 0.0, 3.0, Material::Foliage),
        });
        s
    }

    #[test]
    fn the_official_validator_finds_nothing_wrong() {
        let text = String::from_utf8(write_cityjson(&scene(), &site()).unwrap()).unwrap();
        let v = cjval::CJValidator::from_str(&text);
        let report = v.validate();
        let failed: Vec<String> = report
            .iter()
            .filter(|(_, s)| s.has_errors())
            .map(|(check, s)| format!("{check}: {s}"))
            .collect();
        assert!(failed.is_empty(), "{failed:#?}");
        assert!(v.is_valid());
    }

    #[test]
    fn buildings_are_solids_with_roofs_walls_and_ground_and_their_materials() {
        let doc: Value =
            serde_json::from_slice(&write_cityjson(&scene(), &site()).unwrap()).unwrap();
        let objects = doc["CityObjects"].as_object().unwrap();
        assert_eq!(objects.len(), 42);
        assert_eq!(objects["ground"]["type"], "TINRelief");
        assert_eq!(objects["tree-1"]["type"], "SolitaryVegetationObject");
        assert_eq!(
            objects["tree-1"]["attributes"]["itu_material_area_share"]["foliage"],
            1.0
        );

        // A block: one closed shell of 12 triangles, 2 up, 2 down at the foot, 8 walls.
        let b0 = &objects["b0"];
        assert_eq!(b0["type"], "Building");
        assert_eq!(b0["attributes"]["measuredHeight"], 8.0);
        let g = &b0["geometry"][0];
        assert_eq!(g["type"], "Solid");
        assert_eq!(g["boundaries"][0].as_array().unwrap().len(), 12);
        let surfaces = g["semantics"]["surfaces"].as_array().unwrap();
        let mut count: BTreeMap<String, usize> = BTreeMap::new();
        for v in g["semantics"]["values"][0].as_array().unwrap() {
            let s = &surfaces[v.as_u64().unwrap() as usize];
            assert_eq!(s["itu_material"], "concrete");
            *count.entry(s["type"].as_str().unwrap().into()).or_default() += 1;
        }
        let want: BTreeMap<String, usize> = [
            ("GroundSurface".to_string(), 2),
            ("RoofSurface".to_string(), 2),
            ("WallSurface".to_string(), 8),
        ]
        .into();
        assert_eq!(count, want);

        let two = &objects["two blocks"];
        assert_eq!(
            two["children"],
            json!(["two blocks/part-1", "two blocks/part-2"])
        );
        let part = &objects["two blocks/part-2"];
        assert_eq!(part["type"], "BuildingPart");
        assert_eq!(part["parents"], json!(["two blocks"]));
        assert_eq!(part["geometry"][0]["type"], "Solid");
        assert_eq!(part["attributes"]["measuredHeight"], 5.0);
        let shares = &objects["two blocks"]["attributes"]["itu_material_area_share"];
        // 10 x 10 x 9 of brick, 6 x 6 x 5 of glass: 560 and 192 m² of surface.
        assert_eq!(
            shares["brick"],
            (560.0f64 / 752.0 * 1000.0).round() / 1000.0
        );
        assert_eq!(objects["open"]["geometry"][0]["type"], "MultiSurface");
    }

    #[test]
    fn vertices_read_back_in_the_crs_to_the_millimetre() {
        let s = scene();
        let site = site();
        let doc: Value = serde_json::from_slice(&write_cityjson(&s, &site).unwrap()).unwrap();
        let t = &doc["transform"];
        let at = |i: u64| -> [f64; 3] {
            let v = &doc["vertices"][i as usize];
            [0, 1, 2].map(|k| {
                v[k].as_i64().unwrap() as f64 * t["scale"][k].as_f64().unwrap()
                    + t["translate"][k].as_f64().unwrap()
            })
        };
        let b0 = &s.objects[0];
        let first = &doc["CityObjects"]["b0"]["geometry"][0]["boundaries"][0][0][0];
        for (k, idx) in first.as_array().unwrap().iter().enumerate() {
            let p = b0.mesh.positions[b0.mesh.triangles[0][k] as usize];
            let want = [
                p[0] as f64 + site.origin.0,
                p[1] as f64 + site.origin.1,
                p[2] as f64,
            ];
            let got = at(idx.as_u64().unwrap());
            for c in 0..3 {
                assert!((got[c] - want[c]).abs() <= 0.0005, "{got:?} {want:?}");
            }
        }
        assert_eq!(
            doc["metadata"]["referenceSystem"],
            "https://www.opengis.net/def/crs/EPSG/0/32618"
        );
    }

    #[test]
    fn the_output_name_picks_the_format() {
        use crate::artifact::ArtifactType;
        use crate::io::export::output_file;
        assert_eq!(
            output_file("twin.city.json", ArtifactType::Scene).unwrap(),
            ("twin.city.json".to_string(), "city.json")
        );
        let e = output_file("twin.json", ArtifactType::Scene).unwrap_err();
        assert!(e.contains("city.json") && e.contains("not .json"), "{e}");
        assert!(output_file(".city.json", ArtifactType::Scene).is_err());
    }
}
