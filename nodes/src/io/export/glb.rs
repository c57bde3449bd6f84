//! glTF 2.0 binary (`.glb`) export of scenes: one node per object, one primitive per material,
//! materials named after their ITU class (`itu_concrete`, ...) and false-coloured by it.
//!
//! glTF is y-up; the site frame is z-up. Positions are written as (x, z, -y) so that Blender,
//! three.js and other viewers show the scene upright, and the node carries the site id.

use serde_json::{Value, json};

use crate::artifact::Material;
use crate::artifact::{Scene, SceneObject};

/// A display colour per material (linear RGB), so classes are told apart at a glance.
pub fn material_color(m: Material) -> [f32; 3] {
    match m {
        Material::Concrete => [0.60, 0.60, 0.58],
        Material::Brick => [0.65, 0.25, 0.15],
        Material::Plasterboard => [0.90, 0.88, 0.80],
        Material::Wood => [0.55, 0.35, 0.15],
        Material::Glass => [0.35, 0.65, 0.85],
        Material::CeilingBoard => [0.95, 0.95, 0.90],
        Material::Chipboard => [0.75, 0.60, 0.40],
        Material::Plywood => [0.80, 0.65, 0.45],
        Material::Marble => [0.92, 0.90, 0.86],
        Material::Floorboard => [0.60, 0.45, 0.30],
        Material::Metal => [0.30, 0.32, 0.38],
        Material::VeryDryGround => [0.80, 0.72, 0.50],
        Material::MediumDryGround => [0.50, 0.45, 0.30],
        Material::WetGround => [0.30, 0.28, 0.20],
        Material::Foliage => [0.15, 0.50, 0.15],
    }
}

fn material_name(m: Material) -> String {
    m.itu_type()
        .map(|t| format!("itu_{t}"))
        .unwrap_or_else(|| "foliage".into())
}

/// Encodes `scene` as a GLB file, z-up site coordinates written y-up.
pub fn write_glb(scene: &Scene) -> Result<Vec<u8>, String> {
    let objects: Vec<&SceneObject> = scene.objects.iter().collect();
    write_glb_objects(&objects, |p| [p[0], p[2], -p[1]], false)
}

/// Encodes `objects` as a GLB file, each vertex mapped by `to_gltf` into glTF's y-up space. With
/// `features`, each object is a feature: its vertices carry its row (`_FEATURE_ID_0`,
/// `EXT_mesh_features`) in a property table of the objects' properties (`EXT_structural_metadata`,
/// [`super::object_properties::property_table`]), as 3D Tiles 1.1 viewers read them.
pub fn write_glb_objects(
    objects: &[&SceneObject],
    to_gltf: impl Fn([f32; 3]) -> [f32; 3],
    features: bool,
) -> Result<Vec<u8>, String> {
    let mut bin: Vec<u8> = Vec::new();
    let (mut accessors, mut views, mut meshes, mut nodes) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let used: std::collections::BTreeSet<u8> = objects
        .iter()
        .flat_map(|o| o.mesh.materials.iter().copied())
        .collect();
    let material_index: std::collections::BTreeMap<u8, usize> =
        used.iter().enumerate().map(|(i, &m)| (m, i)).collect();
    let materials: Vec<Value> = used
        .iter()
        .map(|&m| {
            let mat = Material::from_u8(m).ok_or_else(|| format!("unknown material id {m}"))?;
            let c = material_color(mat);
            Ok(json!({"name": material_name(mat), "pbrMetallicRoughness": {"baseColorFactor": [c[0], c[1], c[2], 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.9}}))
        })
        .collect::<Result<_, String>>()?;
    // Vertex data starts on 4 bytes (glTF); property-table columns (no target) on 8.
    let mut push_view = |bin: &mut Vec<u8>, bytes: &[u8], target: Option<u32>| {
        let align = if target.is_some() { 4 } else { 8 };
        while !bin.len().is_multiple_of(align) {
            bin.push(0);
        }
        let mut view = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        views.push(view);
        bin.extend_from_slice(bytes);
        views.len() - 1
    };
    let kept: Vec<&SceneObject> = objects
        .iter()
        .copied()
        .filter(|o| !o.mesh.is_empty())
        .collect();
    for (row, obj) in kept.iter().enumerate() {
        let m = &obj.mesh;
        let pos: Vec<[f32; 3]> = m.positions.iter().map(|p| to_gltf(*p)).collect();
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in &pos {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let v = push_view(&mut bin, bytemuck::cast_slice(&pos), Some(34962));
        accessors.push(json!({"bufferView": v, "componentType": 5126, "count": pos.len(), "type": "VEC3", "min": lo, "max": hi}));
        let mut attributes = json!({"POSITION": accessors.len() - 1});
        let mut extensions = json!({});
        if features {
            // Float feature IDs: exact below 2^24 rows, and 4-byte aligned as vertex data must be.
            let ids = vec![row as f32; pos.len()];
            let v = push_view(&mut bin, bytemuck::cast_slice(&ids), Some(34962));
            accessors.push(json!({"bufferView": v, "componentType": 5126, "count": ids.len(), "type": "SCALAR"}));
            attributes["_FEATURE_ID_0"] = json!(accessors.len() - 1);
            extensions = json!({"EXT_mesh_features": {"featureIds": [{"featureCount": 1, "attribute": 0, "propertyTable": 0}]}});
        }
        let mut primitives = Vec::new();
        for (&mat, &mi) in &material_index {
            let idx: Vec<u32> = m
                .triangles
                .iter()
                .zip(m.materials.iter())
                .filter(|(_, mm)| **mm == mat)
                .flat_map(|(t, _)| *t)
                .collect();
            if idx.is_empty() {
                continue;
            }
            let v = push_view(&mut bin, bytemuck::cast_slice(&idx), Some(34963));
            accessors.push(json!({"bufferView": v, "componentType": 5125, "count": idx.len(), "type": "SCALAR"}));
            let mut primitive =
                json!({"attributes": attributes, "indices": accessors.len() - 1, "material": mi});
            if features {
                primitive["extensions"] = extensions.clone();
            }
            primitives.push(primitive);
        }
        meshes.push(json!({"name": obj.id, "primitives": primitives}));
        nodes.push(json!({"name": obj.id, "mesh": meshes.len() - 1, "extras": {"class": format!("{:?}", obj.class)}}));
    }
    let metadata = if features {
        Some(super::object_properties::property_table(
            &kept,
            &mut |bytes| push_view(&mut bin, bytes, None),
        )?)
    } else {
        None
    };
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": concat!("kodama-dag ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    if let Some(m) = metadata {
        doc["extensionsUsed"] = json!(["EXT_mesh_features", "EXT_structural_metadata"]);
        doc["extensions"] = json!({"EXT_structural_metadata": m});
    }
    glb_container(&doc, bin)
}

/// The binary glTF container: a 12-byte header, the JSON chunk and the binary chunk, each padded
/// to four bytes.
pub(super) fn glb_container(doc: &Value, mut bin: Vec<u8>) -> Result<Vec<u8>, String> {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut json_bytes = serde_json::to_vec(doc).map_err(|e| e.to_string())?;
    while json_bytes.len() % 4 != 0 {
        json_bytes.push(b' ');
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    if total > u32::MAX as usize {
        return Err(format!(
            "the glb would be {total} bytes; the format holds at most 4 GiB"
        ));
    }
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}
