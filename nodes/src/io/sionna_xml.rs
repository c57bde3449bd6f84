//! Sionna RT scenes: Mitsuba 3 XML naming one binary PLY mesh per shape, each with an ITU-R P.2040
//! radio material (Sionna RT's scene format). Read, so our tracer runs on Sionna's scenes; written,
//! so `sionna.rt.load_scene` loads ours.

use std::collections::BTreeMap;
use std::path::Path;

use crate::artifact::Material;
use crate::artifact::{Mesh, ObjectClass, PodVec, Scene, SceneObject};
use crate::site::Site;
use crate::stage::StageError;

/// Sionna's default slab thickness, metres. Our scenes write each material's thickness from
/// [`Material::slab_thickness_m`]; a scene read back accepts either.
pub const THICKNESS_M: f64 = 0.1;

/// Reads a Sionna/Mitsuba scene XML and the PLY files it names (relative to the XML's folder).
/// Each shape becomes one object (id without the `mesh-` prefix, class `Unsegmented`) whose
/// triangles carry the shape's material.
pub fn read_scene(path: &Path) -> Result<Scene, StageError> {
    read_scene_with_thickness(path).map(|(scene, _)| scene)
}

/// [`read_scene`], with each material's slab thickness as the file gives it (Sionna's default
/// [`THICKNESS_M`] where a material names none): what tracing the file as Sionna does needs.
pub fn read_scene_with_thickness(
    path: &Path,
) -> Result<(Scene, BTreeMap<Material, f64>), StageError> {
    let bad = |place: String, expected: &str| StageError::bad_input(path, place, expected);
    let text = crate::io::open::read_regular_to_string(path)
        .map_err(|e| bad("file".into(), &format!("a readable XML file ({e})")))?;
    check_depth(path, &text)?;
    let doc = roxmltree::Document::parse(&text).map_err(|e| {
        let (row, col) = match e {
            // roxmltree places this at 1:1; the file ends at its last character.
            roxmltree::Error::UnexpectedEndOfStream => {
                let last = text.rfind('\n').map_or(0, |k| k + 1);
                (
                    text.matches('\n').count() + 1,
                    text[last..].chars().count() + 1,
                )
            }
            _ => (e.pos().row as usize, e.pos().col as usize),
        };
        bad(
            format!("line {row}, column {col}"),
            &format!("well-formed XML ({e})"),
        )
    })?;
    let line = |n: roxmltree::Node| doc.text_pos_at(n.range().start).row;
    let mut materials: BTreeMap<String, Material> = BTreeMap::new();
    let mut thickness: BTreeMap<Material, f64> = BTreeMap::new();
    for b in doc
        .descendants()
        .filter(|n| n.has_tag_name("bsdf") && n.parent().is_some_and(|p| p.has_tag_name("scene")))
    {
        let id = b.attribute("id").unwrap_or_default().to_string();
        let kind = b.attribute("type").unwrap_or_default();
        let prop = |tag: &str, name: &str| {
            b.children()
                .find(|c| c.has_tag_name(tag) && c.attribute("name") == Some(name))
                .and_then(|c| c.attribute("value"))
        };
        let material = match kind {
            "itu-radio-material" => prop("string", "type").and_then(Material::from_name),
            // Blender/Sionna 0.x exports: the id names the ITU class (`mat-itu_concrete`).
            _ => Material::from_name(&id),
        }
        .filter(|m| m.itu_type().is_some())
        .ok_or_else(|| {
            bad(
                format!("line {}: bsdf \"{id}\"", line(b)),
                "an itu-radio-material, or an id naming an ITU class (custom radio-material \
                 permittivities are not supported)",
            )
        })?;
        let mut slab = THICKNESS_M;
        if let Some(t) = prop("float", "thickness") {
            let t: f64 = t.parse().map_err(|_| {
                bad(
                    format!("line {}: bsdf \"{id}\" thickness", line(b)),
                    "a number",
                )
            })?;
            let ours = material.slab_thickness_m();
            if (t - THICKNESS_M).abs() > 1e-9 && (t - ours).abs() > 1e-9 {
                return Err(bad(
                    format!("line {}: bsdf \"{id}\" thickness {t}", line(b)),
                    &format!(
                        "Sionna's default 0.1 m or our table's {ours} m for this material (other slab thicknesses are not supported yet)"
                    ),
                ));
            }
            slab = t;
        }
        if thickness.insert(material, slab).is_some_and(|d| d != slab) {
            return Err(bad(
                format!("line {}: bsdf \"{id}\" thickness {slab}", line(b)),
                "one thickness per ITU class (another bsdf of this class has another)",
            ));
        }
        materials.insert(id, material);
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    // Every shape's file resolved and counted first, so that a file named by thousands of
    // shapes is refused before the first byte of meshes is read.
    let budget = crate::params::ReadBudget::default();
    let mut shapes = Vec::new();
    for s in doc.descendants().filter(|n| n.has_tag_name("shape")) {
        let id = s.attribute("id").unwrap_or_default();
        let place = || format!("line {}: shape \"{id}\"", line(s));
        if s.attribute("type") != Some("ply") {
            return Err(bad(place(), "a shape of type \"ply\""));
        }
        let file = s
            .children()
            .find(|c| c.has_tag_name("string") && c.attribute("name") == Some("filename"))
            .and_then(|c| c.attribute("value"))
            .ok_or_else(|| bad(place(), "a <string name=\"filename\"> child"))?;
        let bsdf = s
            .children()
            .find(|c| c.has_tag_name("ref"))
            .and_then(|c| c.attribute("id"))
            .ok_or_else(|| bad(place(), "a <ref id=...> to a material"))?;
        let material = *materials.get(bsdf).ok_or_else(|| {
            bad(
                place(),
                &format!("a material defined in the file (no bsdf \"{bsdf}\")"),
            )
        })?;
        // The node declared (and the cache digested) the XML's folder: nothing outside it is read.
        let ply = crate::io::safe_name::resolve_inside(dir, dir, file)
            .map_err(|m| bad(format!("{}, filename", place()), &m))?;
        budget
            .take(&ply)
            .map_err(|m| bad(format!("{}, filename", place()), &m))?;
        shapes.push((id, ply, material));
    }
    let mut objects = Vec::with_capacity(shapes.len());
    for (id, ply, material) in shapes {
        let mut mesh = read_ply(&ply)?;
        mesh.materials = PodVec(vec![material as u8; mesh.triangles.len()]);
        mesh.check()
            .map_err(|(place, expected)| StageError::bad_input(&ply, place, expected))?;
        objects.push(SceneObject {
            id: id.strip_prefix("mesh-").unwrap_or(id).to_string(),
            class: ObjectClass::Unsegmented,
            mesh,
        });
    }
    Ok((Scene { objects }, thickness))
}

/// The deepest element nesting a scene file may have. Mitsuba scenes nest a few levels; the limit
/// keeps anything that walks the tree recursively (here or in a later tool) off the stack's end.
pub const MAX_XML_DEPTH: usize = 256;

/// Refuses a document nested deeper than [`MAX_XML_DEPTH`], naming the line and column where it
/// gets too deep. A scan of the text before parsing: the XML parser itself recurses per level and
/// overflows the stack some ten thousand levels down.
fn check_depth(path: &Path, text: &str) -> Result<(), StageError> {
    let b = text.as_bytes();
    let (mut depth, mut i) = (0usize, 0usize);
    let skip_past = |from: usize, end: &str| {
        text[from..]
            .find(end)
            .map_or(b.len(), |k| from + k + end.len())
    };
    while let Some(k) = text[i..].find('<') {
        let at = i + k;
        let rest = &text[at..];
        if rest.starts_with("<!--") {
            i = skip_past(at, "-->");
        } else if rest.starts_with("<![CDATA[") {
            i = skip_past(at, "]]>");
        } else if rest.starts_with("<?") {
            i = skip_past(at, "?>");
        } else if rest.starts_with("<!") {
            i = skip_past(at, ">");
        } else if rest.starts_with("</") {
            depth = depth.saturating_sub(1);
            i = skip_past(at, ">");
        } else {
            // A start tag: to its '>', outside quoted attribute values.
            let mut j = at + 1;
            let mut quote = None;
            while j < b.len() {
                match (quote, b[j]) {
                    (None, b'"' | b'\'') => quote = Some(b[j]),
                    (Some(q), c) if c == q => quote = None,
                    (None, b'>') => break,
                    _ => {}
                }
                j += 1;
            }
            if b.get(j.wrapping_sub(1)) != Some(&b'/') {
                depth += 1;
                if depth > MAX_XML_DEPTH {
                    let line = text[..at].matches('\n').count() + 1;
                    let col = at - text[..at].rfind('\n').map_or(0, |n| n + 1) + 1;
                    return Err(StageError::bad_input(
                        path,
                        format!("line {line}, column {col}"),
                        format!("elements nested at most {MAX_XML_DEPTH} deep"),
                    ));
                }
            }
            i = j + 1;
        }
        if i >= b.len() {
            break;
        }
    }
    Ok(())
}

/// Reads a binary little-endian PLY: vertex x, y, z (any other vertex properties skipped) and
/// polygon faces (fanned into triangles).
pub fn read_ply(path: &Path) -> Result<Mesh, StageError> {
    let bytes = crate::io::open::read_regular(path)
        .map_err(|e| ply_error(path, "file", &format!("a readable PLY file ({e})")))?;
    let (header, body) = split_header(path, &bytes)?;
    let header = parse_header(path, header)?;
    let (positions, faces) = read_positions(path, &header, body)?;
    let triangles = read_triangles(path, &header, faces)?;
    Ok(Mesh {
        positions: PodVec(positions),
        triangles: PodVec(triangles),
        materials: PodVec(vec![]),
    })
}

fn ply_error(path: &Path, place: &str, expected: &str) -> StageError {
    StageError::bad_input(path, place, expected)
}

/// The header text and the data after it, once the header says binary little-endian PLY.
fn split_header<'a>(path: &Path, bytes: &'a [u8]) -> Result<(&'a str, &'a [u8]), StageError> {
    let bad = |place: &str, expected: &str| ply_error(path, place, expected);
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or_else(|| bad("header", "a PLY header ending in end_header"))?;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| bad("header", "ASCII text"))?;
    if !header.starts_with("ply") {
        return Err(bad("header", "the magic word ply"));
    }
    if !header.contains("format binary_little_endian 1.0") {
        return Err(bad("header", "format binary_little_endian 1.0"));
    }
    Ok((header, &bytes[end + 11..]))
}

/// What a PLY header declares.
struct PlyHeader {
    n_vertex: usize,
    n_face: usize,
    /// (type, name) of each vertex property, in data order.
    vertex_props: Vec<(String, String)>,
    /// (count type, index type) of the face list.
    face_types: Option<(String, String)>,
}

fn parse_header(path: &Path, header: &str) -> Result<PlyHeader, StageError> {
    let mut h = PlyHeader {
        n_vertex: 0,
        n_face: 0,
        vertex_props: Vec::new(),
        face_types: None,
    };
    let mut element = "";
    for l in header.lines() {
        let w: Vec<&str> = l.split_whitespace().collect();
        match w.as_slice() {
            ["element", name, n] => {
                element = if *name == "vertex" {
                    "vertex"
                } else if *name == "face" {
                    "face"
                } else {
                    "other"
                };
                let n: usize = n
                    .parse()
                    .map_err(|_| ply_error(path, l, "an element count"))?;
                match element {
                    "vertex" => h.n_vertex = n,
                    "face" => h.n_face = n,
                    _ if n > 0 => return Err(ply_error(path, l, "only vertex and face elements")),
                    _ => {}
                }
            }
            ["property", "list", count, index, _] if element == "face" => {
                h.face_types = Some((count.to_string(), index.to_string()));
            }
            ["property", t, name] if element == "vertex" => {
                h.vertex_props.push((t.to_string(), name.to_string()));
            }
            _ => {}
        }
    }
    Ok(h)
}

/// Bytes of a PLY scalar type.
fn type_size(t: &str) -> Option<usize> {
    match t {
        "char" | "uchar" | "int8" | "uint8" => Some(1),
        "short" | "ushort" | "int16" | "uint16" => Some(2),
        "int" | "uint" | "float" | "int32" | "uint32" | "float32" => Some(4),
        "double" | "float64" => Some(8),
        _ => None,
    }
}

/// The vertex positions, and the data after the vertices.
fn read_positions<'a>(
    path: &Path,
    h: &PlyHeader,
    body: &'a [u8],
) -> Result<(Vec<[f32; 3]>, &'a [u8]), StageError> {
    let stride: usize = h
        .vertex_props
        .iter()
        .map(|(t, _)| {
            type_size(t).ok_or_else(|| ply_error(path, "vertex properties", "known property types"))
        })
        .sum::<Result<usize, _>>()?;
    let xyz = [
        vertex_offset(path, h, "x")?,
        vertex_offset(path, h, "y")?,
        vertex_offset(path, h, "z")?,
    ];
    if let Some(&(_, t)) = xyz
        .iter()
        .find(|(_, t)| !matches!(*t, "float" | "float32" | "double" | "float64"))
    {
        return Err(ply_error(
            path,
            "vertex properties",
            &format!("x, y and z of type float or double, found {t}"),
        ));
    }
    // The count comes from the header: checked against the data present before anything is
    // sized by it, so a header claiming 10^18 vertices is an error, not an abort.
    let n_vertex = h.n_vertex;
    let need = n_vertex.checked_mul(stride).filter(|&n| n <= body.len());
    let Some(need) = need else {
        return Err(ply_error(
            path,
            "vertex data",
            &format!(
                "{n_vertex} vertices of {stride} bytes as the header says, but the file has {} bytes of data",
                body.len()
            ),
        ));
    };
    let positions = (0..n_vertex)
        .map(|i| xyz.map(|(off, t)| read_float(&body[i * stride + off..], t)))
        .collect();
    Ok((positions, &body[need..]))
}

/// The byte offset within a vertex, and the type, of property `want`.
fn vertex_offset<'a>(
    path: &Path,
    h: &'a PlyHeader,
    want: &str,
) -> Result<(usize, &'a str), StageError> {
    let mut off = 0;
    for (t, n) in &h.vertex_props {
        if n == want {
            return Ok((off, t.as_str()));
        }
        off += type_size(t).unwrap_or(0);
    }
    Err(ply_error(
        path,
        "vertex properties",
        &format!("a vertex property {want}"),
    ))
}

fn read_float(b: &[u8], t: &str) -> f32 {
    match t {
        "double" | "float64" => f64::from_le_bytes(b[..8].try_into().expect("8 bytes")) as f32,
        _ => f32::from_le_bytes(b[..4].try_into().expect("4 bytes")),
    }
}

/// An unsigned integer of `n` bytes.
fn read_uint(b: &[u8], n: usize) -> u32 {
    match n {
        1 => b[0] as u32,
        2 => u16::from_le_bytes([b[0], b[1]]) as u32,
        _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
    }
}

/// The faces in `body`, each fanned into triangles about its first vertex.
fn read_triangles(path: &Path, h: &PlyHeader, body: &[u8]) -> Result<Vec<[u32; 3]>, StageError> {
    let bad = |place: &str, expected: &str| ply_error(path, place, expected);
    let (count_t, index_t) = h
        .face_types
        .as_ref()
        .ok_or_else(|| bad("header", "a face vertex_indices list"))?;
    let (cs, is) = (
        type_size(count_t).ok_or_else(|| bad("face list", "a known count type"))?,
        type_size(index_t).ok_or_else(|| bad("face list", "a known index type"))?,
    );
    let n_vertex = h.n_vertex;
    // Every face takes at least its count's bytes: a header announcing more faces than that
    // is refused before the triangle list is sized by it.
    if h.n_face > body.len() / cs {
        return Err(bad(
            "face data",
            &format!(
                "{} faces as the header says, but the file has {} bytes of face data (at most {} faces)",
                h.n_face,
                body.len(),
                body.len() / cs
            ),
        ));
    }
    let mut triangles = Vec::with_capacity(h.n_face);
    let mut at = 0usize;
    for f in 0..h.n_face {
        let truncated = || bad(&format!("face {f}"), "the face data the header announces");
        let k = read_uint(body.get(at..at + cs).ok_or_else(truncated)?, cs) as usize;
        at += cs;
        let idx: Vec<u32> = (0..k)
            .map(|j| {
                body.get(at + j * is..at + (j + 1) * is)
                    .map(|b| read_uint(b, is))
                    .ok_or_else(truncated)
            })
            .collect::<Result<_, _>>()?;
        at += k * is;
        if let Some(&bad_index) = idx.iter().find(|&&v| v as usize >= n_vertex) {
            return Err(bad(
                &format!("face {f}"),
                &format!("vertex indices below {n_vertex}, not {bad_index}"),
            ));
        }
        for j in 1..k.saturating_sub(1) {
            triangles.push([idx[0], idx[j], idx[j + 1]]);
        }
    }
    Ok(triangles)
}

/// Writes a binary little-endian PLY with float x, y, z and int triangle lists.
pub fn write_ply(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        positions.len(),
        triangles.len()
    )
    .into_bytes();
    for p in positions {
        for v in p {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    for t in triangles {
        out.push(3);
        for v in t {
            out.extend_from_slice(&(*v as i32).to_le_bytes());
        }
    }
    out
}

/// The files of a Sionna scene folder: `scene.xml` and `meshes/<object>-<material>.ply`, one
/// shape per object (one per building) and material, named by the object, so a user can edit one
/// building in Sionna; one `itu-radio-material` per class used, with the slab thickness the
/// tracer uses for it ([`Material::slab_thickness_m`]). Foliage has no P.2040 class and no place
/// in Sionna's scene (our tracer applies it as a volume loss): its volumes go beside it, as
/// `foliage/<object>.ply` listed in `foliage.json`, for the loss to be applied to Sionna's paths
/// after tracing, as the paper does (Sec. 4.2.4, Sec. 5; `kodama_dag.sionna_foliage_loss_db`).
pub fn write_scene(scene: &Scene) -> Result<Vec<(String, Vec<u8>)>, String> {
    let mut files = Vec::new();
    let mut used: std::collections::BTreeSet<Material> = Default::default();
    let mut shapes = String::new();
    let mut foliage: Vec<String> = Vec::new();
    for obj in &scene.objects {
        let by_material: BTreeMap<u8, Vec<usize>> =
            obj.mesh
                .materials
                .iter()
                .enumerate()
                .fold(BTreeMap::new(), |mut m, (k, &mat)| {
                    m.entry(mat).or_insert_with(Vec::new).push(k);
                    m
                });
        for (mat, tris) in by_material {
            let material = Material::from_u8(mat)
                .ok_or_else(|| format!("{}: unknown material id {mat}", obj.id))?;
            // Only the vertices these triangles use, renumbered.
            let mut remap: BTreeMap<u32, u32> = BTreeMap::new();
            let mut positions = Vec::new();
            let triangles: Vec<[u32; 3]> = tris
                .iter()
                .map(|&k| {
                    obj.mesh.triangles[k].map(|v| {
                        *remap.entry(v).or_insert_with(|| {
                            positions.push(obj.mesh.positions[v as usize]);
                            positions.len() as u32 - 1
                        })
                    })
                })
                .collect();
            let Some(itu) = material.itu_type() else {
                let file = format!("foliage/{}.ply", safe_name(&obj.id));
                files.push((file.clone(), write_ply(&positions, &triangles)));
                foliage.push(file);
                continue;
            };
            used.insert(material);
            let name = format!("{}-itu_{itu}", safe_name(&obj.id));
            files.push((
                format!("meshes/{name}.ply"),
                write_ply(&positions, &triangles),
            ));
            shapes.push_str(&format!(
                "\t<shape type=\"ply\" id=\"mesh-{name}\">\n\t\t<string name=\"filename\" value=\"meshes/{name}.ply\"/>\n\t\t<boolean name=\"face_normals\" value=\"true\"/>\n\t\t<ref id=\"itu_{itu}\" name=\"bsdf\"/>\n\t</shape>\n"
            ));
        }
    }
    let mut xml = String::from("<scene version=\"2.1.0\">\n\n<!-- Materials -->\n\n");
    for m in &used {
        let itu = m.itu_type().expect("only ITU classes are used");
        xml.push_str(&format!(
            "\t<bsdf type=\"itu-radio-material\" id=\"itu_{itu}\">\n\t\t<string name=\"type\" value=\"{itu}\"/>\n\t\t<float name=\"thickness\" value=\"{}\"/>\n\t</bsdf>\n",
            m.slab_thickness_m()
        ));
    }
    xml.push_str("\n<!-- Shapes -->\n\n");
    xml.push_str(&shapes);
    xml.push_str("</scene>\n");
    files.insert(0, ("scene.xml".to_string(), xml.into_bytes()));
    if !foliage.is_empty() {
        files.push(("foliage.json".into(), foliage_json(&foliage)?));
    }
    Ok(files)
}

/// `foliage.json`: the foliage volumes of a Sionna export and how their loss is applied.
fn foliage_json(volumes: &[String]) -> Result<Vec<u8>, String> {
    let doc = serde_json::json!({
        "about": "Foliage volumes (closed meshes in the scene's frame) that Sionna RT cannot \
                  represent: apply them to its paths after tracing, a loss for the metres each \
                  path runs inside them, as the KODAMA paper does. \
                  kodama_dag.sionna_foliage_loss_db(folder, paths, freq_hz) computes it.",
        "volumes": volumes,
        "specific_attenuation": "ITU-R P.833 Figure 2 (woodland), log-log between these points \
                                 (Hz, dB/m); held above the last",
        "p833_figure_2": crate::rf::foliage::P833_FIGURE_2,
        "law": "linear (dB/m x metres) by default; ITU-R P.833's A_m (1 - exp(-gamma d / A_m)) \
                on request",
    });
    let mut text = serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())?;
    text.push('\n');
    Ok(text.into_bytes())
}

/// `site.json`, beside a Sionna RT export: where its frame lies. The scene is in the site frame
/// (metres; x east, y north, z up), which Sionna RT cannot carry, so a user placing transmitters
/// from a GIS needs the CRS and the origin to subtract; and `merge_shapes=False`, without which
/// Sionna RT merges the buildings of one material into one shape.
pub fn site_json(site: &Site) -> Result<Vec<u8>, String> {
    use crate::io::crs::{Crs, ToSite};
    let wgs84 = ToSite::new(&Crs::from_epsg(4326)?, site)?;
    let (lon, lat) = wgs84.inverse(0.0, 0.0)?;
    let doc = serde_json::json!({
        "crs": site.crs,
        "origin": [site.origin.0, site.origin.1],
        "origin_lon_lat": [lon, lat],
        "units": "metre",
        "axes": "x east, y north, z up: easting = x + origin[0], northing = y + origin[1]; z as the input heights",
        "load": "sionna.rt.load_scene(\"scene.xml\", merge_shapes=False) keeps one shape per building and material",
    });
    let mut text = serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())?;
    text.push('\n');
    Ok(text.into_bytes())
}

/// Object ids as file names: letters, digits, `-` and `_` kept, anything else `_`.
fn safe_name(id: &str) -> String {
    id.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::mesh_build::cuboid;

    #[test]
    fn site_json_places_the_frame_on_the_earth() {
        // lon -75, lat 40 lies on UTM 18N's central meridian: E 500000, N 4427757.22 m (the
        // textbook point of crs.rs's tests).
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (500_000.0, 4_427_757.22),
            cell_m: 1.0,
        };
        let doc: serde_json::Value = serde_json::from_slice(&site_json(&site).unwrap()).unwrap();
        assert_eq!(doc["crs"], "EPSG:32618");
        assert_eq!(doc["origin"][0], 500_000.0);
        assert_eq!(doc["origin"][1], 4_427_757.22);
        let (lon, lat) = (
            doc["origin_lon_lat"][0].as_f64().unwrap(),
            doc["origin_lon_lat"][1].as_f64().unwrap(),
        );
        assert!(
            (lon + 75.0).abs() < 1e-7 && (lat - 40.0).abs() < 1e-6,
            "{lon} {lat}"
        );
        assert!(doc["load"].as_str().unwrap().contains("merge_shapes=False"));
    }

    #[test]
    fn a_written_scene_reads_back_the_same() {
        let mut mesh = cuboid([10.0, 5.0], [4.0, 3.0, 6.0], 0.3, 1.0, Material::Brick);
        mesh.materials[0] = Material::Glass as u8;
        let scene = Scene {
            objects: vec![SceneObject {
                id: "building-1".into(),
                class: ObjectClass::Building,
                mesh: mesh.clone(),
            }],
        };
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes) in write_scene(&scene).unwrap() {
            let p = dir.path().join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, bytes).unwrap();
        }
        let back = read_scene(&dir.path().join("scene.xml")).unwrap();
        assert_eq!(back.objects.len(), 2, "one shape per material");
        let tris: usize = back.objects.iter().map(|o| o.mesh.len()).sum();
        assert_eq!(tris, mesh.len());
        let volume: f64 = back.objects.iter().map(|o| o.mesh.volume()).sum();
        assert!((volume - mesh.volume()).abs() < 1e-3);
        assert_eq!(back.objects[0].id, "building-1-itu_brick");
        assert!(
            back.objects[1]
                .mesh
                .materials
                .iter()
                .all(|&m| m == Material::Glass as u8)
        );
    }
}
