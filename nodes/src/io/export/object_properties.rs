//! What the vector exports say about each scene object beyond its geometry: its height and base,
//! and its ITU-R P.2040 materials by area. CityJSON carries them as attributes, 3D Tiles as a
//! property table (`EXT_structural_metadata`) whose rows the tiles' feature IDs point at
//! (`EXT_mesh_features`), so a viewer (CesiumJS, QGIS) shows them when a building is picked.

use std::collections::BTreeMap;

use glam::DVec3;
use serde_json::{Value, json};

use crate::artifact::{Material, Mesh, SceneObject};

/// Each material's share of `mesh`'s surface area, by P.2040 name ("foliage" for foliage), to
/// three decimals.
pub fn material_area_shares(mesh: &Mesh) -> Result<BTreeMap<&'static str, f64>, String> {
    let mut area: BTreeMap<&'static str, f64> = BTreeMap::new();
    for (t, &code) in mesh.triangles.iter().zip(mesh.materials.iter()) {
        let [a, b, c] = t.map(|i| DVec3::from(mesh.positions[i as usize].map(|v| v as f64)));
        let m = Material::from_u8(code).ok_or_else(|| format!("unknown material id {code}"))?;
        *area.entry(m.itu_type().unwrap_or("foliage")).or_default() +=
            0.5 * (b - a).cross(c - a).length();
    }
    let total: f64 = area.values().sum();
    Ok(area
        .into_iter()
        .map(|(m, a)| {
            let share = if total > 0.0 { a / total } else { 0.0 };
            (m, (share * 1000.0).round() / 1000.0)
        })
        .collect())
}

/// The lowest and highest vertex height of `mesh`, metres.
pub fn z_range(mesh: &Mesh) -> (f64, f64) {
    mesh.positions
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[2] as f64), hi.max(p[2] as f64))
        })
}

/// The shares as one string, largest first: `concrete=0.712;glass=0.288`.
fn shares_text(shares: &BTreeMap<&'static str, f64>) -> String {
    let mut v: Vec<(&str, f64)> = shares.iter().map(|(m, s)| (*m, *s)).collect();
    v.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(b.0)));
    v.iter()
        .map(|(m, s)| format!("{m}={s}"))
        .collect::<Vec<_>>()
        .join(";")
}

/// A string column of a property table: the UTF-8 bytes and the `count + 1` UINT32 offsets.
fn string_column(values: &[String]) -> (Vec<u8>, Vec<u32>) {
    let mut bytes = Vec::new();
    let mut offsets = vec![0u32];
    for v in values {
        bytes.extend_from_slice(v.as_bytes());
        offsets.push(bytes.len() as u32);
    }
    (bytes, offsets)
}

/// The glTF root's `EXT_structural_metadata`: a schema of one class, `object`, and one property
/// table with a row per object of `objects` (row k is the feature ID k the tile's vertices
/// carry). `push` stores a binary column and gives its buffer view (aligned to 8 bytes, as the
/// extension requires).
pub fn property_table(
    objects: &[&SceneObject],
    push: &mut dyn FnMut(&[u8]) -> usize,
) -> Result<Value, String> {
    let (mut ids, mut classes, mut materials, mut main) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut heights, mut bases) = (Vec::new(), Vec::new());
    for o in objects {
        let shares = material_area_shares(&o.mesh).map_err(|e| format!("{}: {e}", o.id))?;
        let (lo, hi) = z_range(&o.mesh);
        ids.push(o.id.clone());
        classes.push(format!("{:?}", o.class));
        main.push(
            shares
                .iter()
                .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(a.0)))
                .map(|(m, _)| m.to_string())
                .unwrap_or_default(),
        );
        materials.push(shares_text(&shares));
        heights.push((hi - lo) as f32);
        bases.push(lo as f32);
    }
    let mut properties = serde_json::Map::new();
    for (name, column) in [
        ("id", &ids),
        ("class", &classes),
        ("main_material", &main),
        ("materials", &materials),
    ] {
        let (bytes, offsets) = string_column(column);
        let values = push(&bytes);
        let offsets = push(bytemuck::cast_slice(&offsets));
        properties.insert(
            name.into(),
            json!({ "values": values, "stringOffsets": offsets, "stringOffsetType": "UINT32" }),
        );
    }
    for (name, column) in [("height_m", &heights), ("base_m", &bases)] {
        properties.insert(
            name.into(),
            json!({ "values": push(bytemuck::cast_slice(column)) }),
        );
    }
    let string = |d: &str| json!({ "type": "STRING", "description": d });
    let metres =
        |d: &str| json!({ "type": "SCALAR", "componentType": "FLOAT32", "description": d });
    Ok(json!({
        "schema": {
            "id": "kodama_dag",
            "classes": {
                "object": {
                    "name": "Scene object",
                    "properties": {
                        "id": string("the object's id in the scene (building-12)"),
                        "class": string("Building, Terrain, Vegetation, Clutter or Unsegmented"),
                        "main_material": string("the ITU-R P.2040 material covering most of its surface"),
                        "materials": string("each P.2040 material's share of its surface area, largest first: concrete=0.712;glass=0.288"),
                        "height_m": metres("from its lowest to its highest point, metres"),
                        "base_m": metres("its lowest point, metres, in the site's heights"),
                    },
                },
            },
        },
        "propertyTables": [{
            "name": "objects",
            "class": "object",
            "count": objects.len(),
            "properties": properties,
        }],
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::export::write_tileset;
    use crate::rf::test_scenes::street_grid_scene;
    use crate::site::Site;

    /// The JSON and binary chunks of a GLB.
    fn chunks(glb: &[u8]) -> (Value, &[u8]) {
        let u32_at = |o: usize| u32::from_le_bytes(glb[o..o + 4].try_into().unwrap()) as usize;
        assert_eq!(&glb[..4], b"glTF");
        let json_len = u32_at(12);
        let doc = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
        let bin_at = 20 + json_len;
        (doc, &glb[bin_at + 8..bin_at + 8 + u32_at(bin_at)])
    }

    fn view<'a>(doc: &Value, bin: &'a [u8], v: &Value) -> &'a [u8] {
        let bv = &doc["bufferViews"][v.as_u64().unwrap() as usize];
        let at = bv["byteOffset"].as_u64().unwrap() as usize;
        assert_eq!(at % 8, 0, "property columns start on 8 bytes");
        &bin[at..at + bv["byteLength"].as_u64().unwrap() as usize]
    }

    fn strings(doc: &Value, bin: &[u8], p: &Value) -> Vec<String> {
        let bytes = view(doc, bin, &p["values"]);
        let offsets: Vec<u32> = view(doc, bin, &p["stringOffsets"])
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        offsets
            .windows(2)
            .map(|w| String::from_utf8(bytes[w[0] as usize..w[1] as usize].to_vec()).unwrap())
            .collect()
    }

    /// Every tile's vertices point at the row of their object, and the row holds its id, class,
    /// height and materials, as the 3D Tiles metadata extensions lay them out.
    #[test]
    fn each_tiles_features_point_at_their_objects_rows() {
        let scene = street_grid_scene();
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (583_200.0, 4_506_600.0),
            cell_m: 1.0,
        };
        let files = write_tileset(&scene, &site, 100.0).unwrap();
        let mut seen = 0;
        for (name, glb) in files.iter().filter(|(n, _)| n.ends_with(".glb")) {
            let (doc, bin) = chunks(glb);
            assert_eq!(
                doc["extensionsUsed"],
                json!(["EXT_mesh_features", "EXT_structural_metadata"])
            );
            let meta = &doc["extensions"]["EXT_structural_metadata"];
            let table = &meta["propertyTables"][0];
            assert_eq!(table["class"], "object");
            assert!(meta["schema"]["classes"]["object"]["properties"]["height_m"].is_object());
            let props = &table["properties"];
            let ids = strings(&doc, bin, &props["id"]);
            let classes = strings(&doc, bin, &props["class"]);
            let main = strings(&doc, bin, &props["main_material"]);
            let heights: Vec<f32> = view(&doc, bin, &props["height_m"]["values"])
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect();
            assert_eq!(ids.len(), table["count"].as_u64().unwrap() as usize);
            for node in doc["nodes"].as_array().unwrap() {
                let mesh = &doc["meshes"][node["mesh"].as_u64().unwrap() as usize];
                for prim in mesh["primitives"].as_array().unwrap() {
                    let f = &prim["extensions"]["EXT_mesh_features"]["featureIds"][0];
                    assert_eq!(
                        (f["attribute"].as_u64(), f["propertyTable"].as_u64()),
                        (Some(0), Some(0))
                    );
                    let acc = &doc["accessors"]
                        [prim["attributes"]["_FEATURE_ID_0"].as_u64().unwrap() as usize];
                    assert_eq!(acc["componentType"], 5126);
                    let bv = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
                    let at = bv["byteOffset"].as_u64().unwrap() as usize;
                    let rows: Vec<f32> = bin[at..at + 4 * acc["count"].as_u64().unwrap() as usize]
                        .chunks_exact(4)
                        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                        .collect();
                    let row = rows[0] as usize;
                    assert!(rows.iter().all(|&r| r == rows[0]), "{name}");
                    // The row is the node's object.
                    assert_eq!(ids[row], node["name"].as_str().unwrap(), "{name}");
                    let obj = scene.objects.iter().find(|o| o.id == ids[row]).unwrap();
                    let (lo, hi) = z_range(&obj.mesh);
                    assert_eq!(heights[row], (hi - lo) as f32);
                    assert_eq!(classes[row], format!("{:?}", obj.class));
                    let want = if obj.id == "ground" {
                        "medium_dry_ground"
                    } else {
                        "concrete"
                    };
                    assert_eq!(main[row], want);
                    seen += 1;
                }
            }
        }
        assert_eq!(seen, scene.objects.len());
    }

    #[test]
    fn shares_sum_to_one_and_read_largest_first() {
        use crate::geom::mesh_build::cuboid;
        let mut m = cuboid([0.0, 0.0], [10.0, 10.0, 9.0], 0.0, 0.0, Material::Brick);
        m.append(&cuboid(
            [40.0, 0.0],
            [6.0, 6.0, 5.0],
            0.0,
            0.0,
            Material::Glass,
        ));
        let s = material_area_shares(&m).unwrap();
        assert_eq!(s["brick"], (560.0f64 / 752.0 * 1000.0).round() / 1000.0);
        assert!((s.values().sum::<f64>() - 1.0).abs() < 1e-3);
        assert_eq!(shares_text(&s), "brick=0.745;glass=0.255");
    }
}
