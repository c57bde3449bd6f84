//! Ingest of OGC 3D Tiles (photogrammetry meshes, paper Sec. 4): `tileset.json` with glTF (`.glb`)
//! or batched-3D-model (`.b3dm`) content, every transform applied, into one scene in the site frame.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::artifact::Material;
use crate::artifact::{Mesh, ObjectClass, Scene, SceneObject};
use crate::io::crs::{Crs, ToSite};
use crate::io::ecef::from_ecef;
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadTileset`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadTilesetParams {
    /// The `tileset.json`. Its whole folder is the node's input (content files live beside it).
    pub path: String,
    /// The CRS of tile coordinates; default ECEF (EPSG:4978), as 3D Tiles specify.
    #[serde(default)]
    pub crs: Option<String>,
}

/// Reads a 3D Tiles tileset into a scene: one object per glTF node with a mesh, surfaces marked
/// [`ObjectClass::Unsegmented`]; materials from their names when they are ITU classes, else
/// concrete (photogrammetry carries no radio materials; a later stage assigns them).
pub struct ReadTileset;

impl Stage for ReadTileset {
    const KIND: &'static str = "ReadTileset";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "OGC 3D Tiles (glb/b3dm content) into a scene in the site frame, Sec. 4";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadTilesetParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::crs::check_crs_param(&p.crs)?;
        if !p.path.ends_with(".json") {
            return Err(ParamError::new("path", "expected the tileset's .json file"));
        }
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        let folder = crate::params::folder_of(&p.path);
        vec![FileRef {
            field: "path",
            path: folder,
        }]
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        let folder = ctx.file(0)?;
        let json = folder.join(Path::new(&p.path).file_name().unwrap_or_default());
        let place: Box<Placer> = match &p.crs {
            None => {
                let wgs84 =
                    ToSite::new(&Crs::from_epsg(4326).expect("EPSG:4326 is known"), ctx.site)
                        .map_err(StageError::Failed)?;
                Box::new(move |e: [f64; 3]| {
                    let (lon, lat, h) = from_ecef(e);
                    let (x, y, _) = wgs84.apply(lon, lat, 0.0)?;
                    Ok([x, y, h])
                })
            }
            Some(c) => {
                let crs =
                    Crs::from_user(c).map_err(|m| StageError::Param(ParamError::new("crs", m)))?;
                let t = ToSite::new(&crs, ctx.site).map_err(StageError::Failed)?;
                Box::new(move |e: [f64; 3]| t.apply(e[0], e[1], e[2]).map(|(x, y, z)| [x, y, z]))
            }
        };
        let mut scene = Scene::default();
        let tiles = Tiles {
            root: folder,
            place: &*place,
            budget: crate::params::ReadBudget::default(),
            tiles: std::cell::Cell::new(0),
        };
        read_tileset_file(&json, IDENTITY, None, &tiles, &mut scene, 0)?;
        if scene.objects.is_empty() {
            return Err(StageError::bad_input(
                &json,
                "content",
                "the tileset has no glb or b3dm content",
            ));
        }
        Ok(scene)
    }
}

type Mat4 = [f64; 16];
const IDENTITY: Mat4 = [
    1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
];

/// Column-major product a * b.
fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut out = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            out[c * 4 + r] = (0..4).map(|k| a[k * 4 + r] * b[c * 4 + k]).sum();
        }
    }
    out
}

fn apply(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r])
}

/// glTF content is y-up; 3D Tiles rotate it to z-up before the tile transform.
const Y_UP_TO_Z_UP: Mat4 = [
    1., 0., 0., 0., 0., 0., 1., 0., 0., -1., 0., 0., 0., 0., 0., 1.,
];

type Placer = dyn Fn([f64; 3]) -> Result<[f64; 3], String> + Sync;

/// What every file of a tileset is read with: the folder the node declared, which every URI must
/// stay inside, and the transform from the tileset's frame to the site's.
struct Tiles<'a> {
    root: &'a Path,
    place: &'a Placer,
    /// Every file read (tileset JSON, content, buffers), however often it is named.
    budget: crate::params::ReadBudget,
    /// Tiles visited so far, external tilesets' included: depth is bounded, and this bounds
    /// the width (a tileset of a thousand external tilesets of a thousand each...).
    tiles: std::cell::Cell<u64>,
}

/// The most tiles one tileset may have, external tilesets' included: far past any city's
/// photogrammetry, and a bound on the walk when references fan out.
const MAX_TILES: u64 = 1 << 20;

impl Tiles<'_> {
    /// Counts `file` against the read budget before it is read.
    fn read(&self, json: &Path, field: &str, file: &Path) -> Result<(), StageError> {
        self.budget
            .take(file)
            .map_err(|m| StageError::bad_input(json, field, m))
    }

    /// The file `uri` names, relative to `base` (the folder of the file naming it); refused when
    /// it is remote or leads outside the declared folder.
    fn resolve(
        &self,
        json: &Path,
        field: &str,
        base: &Path,
        uri: &str,
    ) -> Result<PathBuf, StageError> {
        if uri.contains("://") || uri.starts_with("data:") {
            return Err(StageError::bad_input(
                json,
                field,
                format!(
                    "a file inside the tileset's folder, found the URI {uri:?} (download remote content first)"
                ),
            ));
        }
        crate::io::safe_name::resolve_inside(self.root, base, uri)
            .map_err(|m| StageError::bad_input(json, field, m))
    }
}

fn read_tileset_file(
    json: &Path,
    parent: Mat4,
    refine: Option<&str>,
    tiles: &Tiles,
    scene: &mut Scene,
    depth: u32,
) -> Result<(), StageError> {
    if depth > 16 {
        return Err(StageError::bad_input(
            json,
            "external tilesets",
            "nested more than 16 deep (a cycle?)",
        ));
    }
    tiles.read(json, "open", json)?;
    let text = crate::io::open::read_regular_to_string(json)
        .map_err(|e| StageError::bad_input(json, "open", e.to_string()))?;
    let doc: Value = serde_json::from_str(&text).map_err(|e| {
        StageError::bad_input(
            json,
            format!("line {}, column {}", e.line(), e.column()),
            format!("expected JSON: {e}"),
        )
    })?;
    let root = doc
        .get("root")
        .ok_or_else(|| StageError::bad_input(json, "top level", "expected a `root` tile"))?;
    let base = json.parent().unwrap_or(Path::new("."));
    visit_tile(
        root,
        base,
        json,
        parent,
        refine.unwrap_or("REPLACE"),
        tiles,
        scene,
        depth,
        "root".into(),
    )
}

#[allow(clippy::too_many_arguments)]
fn visit_tile(
    tile: &Value,
    base: &Path,
    json: &Path,
    parent: Mat4,
    refine: &str,
    tiles: &Tiles,
    scene: &mut Scene,
    depth: u32,
    path: String,
) -> Result<(), StageError> {
    tiles.tiles.set(tiles.tiles.get() + 1);
    if tiles.tiles.get() > MAX_TILES {
        return Err(StageError::bad_input(
            json,
            path,
            format!("a tileset of at most {MAX_TILES} tiles, external tilesets' included"),
        ));
    }
    let transform = match tile.get("transform").and_then(Value::as_array) {
        Some(t) if t.len() == 16 => {
            let mut m = [0.0; 16];
            for (i, v) in t.iter().enumerate() {
                m[i] = v.as_f64().ok_or_else(|| {
                    StageError::bad_input(json, format!("{path}.transform"), "expected 16 numbers")
                })?;
            }
            mul(&parent, &m)
        }
        Some(_) => {
            return Err(StageError::bad_input(
                json,
                format!("{path}.transform"),
                "expected 16 numbers",
            ));
        }
        None => parent,
    };
    let refine = tile.get("refine").and_then(Value::as_str).unwrap_or(refine);
    let children = tile
        .get("children")
        .and_then(Value::as_array)
        .map(Vec::as_slice)
        .unwrap_or(&[]);
    // With REPLACE refinement a parent's content is a coarser copy of its children's: read leaves.
    let read_content = refine.eq_ignore_ascii_case("ADD") || children.is_empty();
    if read_content {
        let contents: Vec<&Value> = match (
            tile.get("content"),
            tile.get("contents").and_then(Value::as_array),
        ) {
            (Some(c), _) => vec![c],
            (None, Some(cs)) => cs.iter().collect(),
            _ => vec![],
        };
        for c in contents {
            let Some(uri) = c
                .get("uri")
                .or_else(|| c.get("url"))
                .and_then(Value::as_str)
            else {
                continue;
            };
            let field = format!("{path}.content.uri");
            let file = tiles.resolve(json, &field, base, uri)?;
            if uri.ends_with(".json") {
                read_tileset_file(&file, transform, Some(refine), tiles, scene, depth + 1)?;
            } else {
                tiles.read(json, &field, &file)?;
                read_content_file(&file, uri, &transform, tiles, scene)?;
            }
        }
    }
    for (i, child) in children.iter().enumerate() {
        visit_tile(
            child,
            base,
            json,
            transform,
            refine,
            tiles,
            scene,
            depth,
            format!("{path}.children[{i}]"),
        )?;
    }
    Ok(())
}

/// Reads one content file (b3dm or glb) of a tile whose transform is `tile`: each glTF node with
/// a mesh becomes an object `<uri>#<node name>` of `scene`, placed in the site frame.
fn read_content_file(
    file: &Path,
    uri: &str,
    tile: &Mat4,
    tiles: &Tiles,
    scene: &mut Scene,
) -> Result<(), StageError> {
    let bytes = crate::io::open::read_regular(file)
        .map_err(|e| StageError::bad_input(file, "open", e.to_string()))?;
    let (glb, rtc) = if bytes.starts_with(b"b3dm") {
        split_b3dm(file, &bytes)?
    } else {
        (bytes.as_slice(), [0.0; 3])
    };
    check_glb_container(file, glb)?;
    let gltf = parse_gltf(file, glb)?;
    let buffers = gltf_buffers(file, &gltf, tiles)?;
    let rtc_m: Mat4 = [
        1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., rtc[0], rtc[1], rtc[2], 1.,
    ];
    let to_tile = mul(tile, &mul(&rtc_m, &Y_UP_TO_Z_UP));
    let Some(s) = gltf.default_scene().or_else(|| gltf.scenes().next()) else {
        return Ok(());
    };
    let content = Content {
        file,
        tiles,
        buffers: &buffers,
    };
    let mut stack: Vec<(gltf::Node, Mat4)> = s.nodes().map(|n| (n, to_tile)).collect();
    // glTF's nodes form a forest: a node reached twice is a cycle (its own child) or a shared
    // child, either of which would make the walk endless or exponential.
    let mut seen = vec![false; gltf.nodes().len()];
    while let Some((node, parent)) = stack.pop() {
        if seen
            .get_mut(node.index())
            .is_none_or(|s| std::mem::replace(s, true))
        {
            return Err(StageError::bad_input(
                file,
                format!("node {}", node.index()),
                "glTF nodes that form a tree (this node is reached twice: it is its own \
                 ancestor, or the child of two nodes)",
            ));
        }
        let local = node.transform().matrix();
        let m: Mat4 = std::array::from_fn(|i| local[i / 4][i % 4] as f64);
        let world = mul(&parent, &m);
        if let Some(mesh) = node.mesh() {
            let out = content.mesh(&mesh, &world)?;
            let name = node
                .name()
                .map(str::to_owned)
                .unwrap_or_else(|| node.index().to_string());
            // Non-finite or far-off vertices (NaN in the file, an overflowing transform) are named
            // here, before any ray tracer builds a BVH over them.
            out.check().map_err(|(place, expected)| {
                StageError::bad_input(file, format!("node {name:?}, {place}"), expected)
            })?;
            scene.objects.push(SceneObject {
                id: format!("{uri}#{name}"),
                class: ObjectClass::Unsegmented,
                mesh: out,
            });
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    Ok(())
}

/// The glTF document of `glb`. gltf-json's validation indexes some lists unchecked (a POSITION
/// accessor past the accessors panics, gltf-json 1.4.1): a panic there is this file's fault,
/// reported as such.
fn parse_gltf(file: &Path, glb: &[u8]) -> Result<gltf::Gltf, StageError> {
    let parsed = StageError::catch_decoder_panic(
        file,
        "glTF",
        "expected a well-formed glTF binary (its parser failed",
        || gltf::Gltf::from_slice(glb),
    )?;
    parsed.map_err(|e| StageError::bad_input(file, "glTF", format!("expected a glTF binary: {e}")))
}

/// The bytes of each buffer of `gltf`: the GLB's BIN chunk, or a file beside `file` inside the
/// declared folder.
fn gltf_buffers(file: &Path, gltf: &gltf::Gltf, tiles: &Tiles) -> Result<Vec<Vec<u8>>, StageError> {
    gltf.buffers()
        .map(|b| match b.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| StageError::bad_input(file, "glTF", "the BIN chunk is missing")),
            gltf::buffer::Source::Uri(u) => {
                let base = file.parent().unwrap_or(Path::new("."));
                let buffer = tiles.resolve(file, &format!("buffer {u}"), base, u)?;
                tiles.read(file, &format!("buffer {u}"), &buffer)?;
                crate::io::open::read_regular(&buffer)
                    .map_err(|e| StageError::bad_input(file, format!("buffer {u}"), e.to_string()))
            }
        })
        .collect()
}

/// One content file's glTF being read into meshes: the file (for errors), the tileset (to place
/// vertices) and the glTF's buffers.
struct Content<'a> {
    file: &'a Path,
    tiles: &'a Tiles<'a>,
    buffers: &'a [Vec<u8>],
}

impl Content<'_> {
    /// The triangles of `mesh`'s primitives, placed by the node's transform `world`.
    /// Primitives often share one POSITION accessor (one per material): each is read once.
    fn mesh(&self, mesh: &gltf::Mesh, world: &Mat4) -> Result<Mesh, StageError> {
        let mut out = Mesh::default();
        let mut bases: std::collections::HashMap<usize, (u32, u32)> = Default::default();
        for prim in mesh.primitives() {
            self.append_primitive(&mut out, &mut bases, &prim, world)?;
        }
        Ok(out)
    }

    /// Appends the triangles of `prim` to `out` (its vertices too, unless `bases` says where its
    /// POSITION accessor's already are), each with the material its glTF material names.
    /// Primitives other than triangle lists, or without positions, add nothing.
    fn append_primitive(
        &self,
        out: &mut Mesh,
        bases: &mut std::collections::HashMap<usize, (u32, u32)>,
        prim: &gltf::Primitive,
        world: &Mat4,
    ) -> Result<(), StageError> {
        let (file, buffers) = (self.file, self.buffers);
        if prim.mode() != gltf::mesh::Mode::Triangles {
            return Ok(());
        }
        let material = prim
            .material()
            .name()
            .and_then(Material::from_name)
            .unwrap_or(Material::Concrete);
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let Some(accessor) = prim.get(&gltf::Semantic::Positions) else {
            return Ok(());
        };
        if !check_accessor(file, "POSITION", &accessor, buffers)? {
            return Ok(());
        }
        if let Some(ix) = prim.indices() {
            check_accessor(file, "indices", &ix, buffers)?;
        }
        let (base, n) = match bases.get(&accessor.index()) {
            Some(&b) => b,
            None => {
                let Some(positions) = reader.read_positions() else {
                    return Ok(());
                };
                let b = self.append_positions(out, positions, world)?;
                bases.insert(accessor.index(), b);
                b
            }
        };
        let indices: Vec<u32> = match reader.read_indices() {
            Some(ix) => ix.into_u32().collect(),
            None => (0..n).collect(),
        };
        for t in indices.chunks_exact(3) {
            if t.iter().any(|&i| i >= n) {
                return Err(StageError::bad_input(
                    file,
                    "indices",
                    "an index points past the vertices",
                ));
            }
            out.triangles.push([base + t[0], base + t[1], base + t[2]]);
            out.materials.push(material as u8);
        }
        Ok(())
    }

    /// Appends `positions`, transformed by `world` and placed in the site frame, to `out`;
    /// returns where they start and how many there are.
    fn append_positions(
        &self,
        out: &mut Mesh,
        positions: impl Iterator<Item = [f32; 3]>,
        world: &Mat4,
    ) -> Result<(u32, u32), StageError> {
        let base = out.positions.len() as u32;
        for p in positions {
            let e = apply(world, [p[0] as f64, p[1] as f64, p[2] as f64]);
            let q =
                (self.tiles.place)(e).map_err(|m| StageError::bad_input(self.file, "vertex", m))?;
            out.positions.push([q[0] as f32, q[1] as f32, q[2] as f32]);
        }
        Ok((base, out.positions.len() as u32 - base))
    }
}

/// The GLB container's lengths, checked before the gltf crate subtracts and slices by them
/// unchecked: the header's total, then each chunk's, within the bytes there are.
fn check_glb_container(file: &Path, b: &[u8]) -> Result<(), StageError> {
    if !b.starts_with(b"glTF") {
        return Ok(()); // glTF JSON: parsed as such.
    }
    let u32_at = |o: usize| {
        b.get(o..o + 4)
            .map(|s| u32::from_le_bytes(s.try_into().expect("4 bytes")) as usize)
    };
    let bad = |place: &str, m: String| StageError::bad_input(file, format!("GLB {place}"), m);
    let total = u32_at(8).ok_or_else(|| bad("header", "a 12-byte header".into()))?;
    if !(20..=b.len()).contains(&total) {
        return Err(bad(
            "header",
            format!(
                "a length from 20 to the file's {} bytes, found {total}",
                b.len()
            ),
        ));
    }
    let mut at = 12;
    while at < total {
        let len = u32_at(at).filter(|_| at + 8 <= total).ok_or_else(|| {
            bad(
                &format!("chunk at byte {at}"),
                "an 8-byte chunk header".into(),
            )
        })?;
        if len > total - at - 8 {
            return Err(bad(
                &format!("chunk at byte {at}"),
                format!("a length within the file's {total} bytes, found {len}"),
            ));
        }
        at += 8 + len;
    }
    Ok(())
}

/// Checks that an accessor reads only bytes its buffer has, with a type the reader takes, so the
/// gltf crate's readers (which compute the extent unchecked, and panic on unexpected index types)
/// never see one that does not: false when it is empty.
fn check_accessor(
    file: &Path,
    what: &str,
    a: &gltf::Accessor,
    buffers: &[Vec<u8>],
) -> Result<bool, StageError> {
    use gltf::accessor::{DataType, Dimensions};
    let bad =
        |m: String| StageError::bad_input(file, format!("accessor {} ({what})", a.index()), m);
    if a.sparse().is_some() {
        return Err(bad(
            "a plain accessor (sparse accessors are not supported)".into()
        ));
    }
    let ok_type = match what {
        "POSITION" => a.data_type() == DataType::F32 && a.dimensions() == Dimensions::Vec3,
        _ => {
            matches!(a.data_type(), DataType::U8 | DataType::U16 | DataType::U32)
                && a.dimensions() == Dimensions::Scalar
        }
    };
    if !ok_type {
        return Err(bad(format!(
            "{} (found {:?} {:?})",
            if what == "POSITION" {
                "float VEC3 positions"
            } else {
                "unsigned SCALAR indices"
            },
            a.data_type(),
            a.dimensions()
        )));
    }
    if a.count() == 0 {
        return Ok(false);
    }
    let view = a
        .view()
        .ok_or_else(|| bad("a buffer view (accessors without one are not supported)".into()))?;
    let buffer_len = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    let elem = a.size();
    let stride = view.stride().unwrap_or(elem);
    let view_end = view.offset().checked_add(view.length());
    if view_end.is_none_or(|e| e > buffer_len) {
        return Err(bad(format!(
            "buffer view {} within its buffer's {buffer_len} bytes (offset {}, length {})",
            view.index(),
            view.offset(),
            view.length()
        )));
    }
    let end = stride
        .checked_mul(a.count() - 1)
        .and_then(|n| n.checked_add(a.offset()))
        .and_then(|n| n.checked_add(elem));
    if end.is_none_or(|e| e > view.length()) {
        return Err(bad(format!(
            "{} elements of {elem} bytes (stride {stride}) within buffer view {}'s {} bytes",
            a.count(),
            view.index(),
            view.length()
        )));
    }
    Ok(true)
}

/// The glTF inside a b3dm, and its feature table's RTC_CENTER.
fn split_b3dm<'a>(file: &Path, b: &'a [u8]) -> Result<(&'a [u8], [f64; 3]), StageError> {
    let u32_at = |o: usize| {
        b.get(o..o + 4)
            .map(|s| u32::from_le_bytes(s.try_into().expect("4 bytes")) as usize)
    };
    let bad = |m: &str| StageError::bad_input(file, "b3dm header", m.to_owned());
    let (Some(ft_json), Some(ft_bin), Some(bt_json), Some(bt_bin)) =
        (u32_at(12), u32_at(16), u32_at(20), u32_at(24))
    else {
        return Err(bad("expected a 28-byte header"));
    };
    let glb_start = 28 + ft_json + ft_bin + bt_json + bt_bin;
    let glb = b
        .get(glb_start..)
        .ok_or_else(|| bad("the table lengths run past the end of the file"))?;
    let mut rtc = [0.0; 3];
    if ft_json > 0 {
        let ft: Value = serde_json::from_slice(&b[28..28 + ft_json])
            .map_err(|e| bad(&format!("feature table: {e}")))?;
        if let Some(c) = ft.get("RTC_CENTER").and_then(Value::as_array) {
            for (k, v) in c.iter().take(3).enumerate() {
                rtc[k] = v.as_f64().unwrap_or(0.0);
            }
        }
    }
    Ok((glb, rtc))
}
