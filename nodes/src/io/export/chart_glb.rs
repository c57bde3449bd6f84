//! Texel layers draped over the buildings as a glb: every chart a textured quad lifted 2 cm off
//! its surface (so it can be opened over the scene's glb without z-fighting), textured from the
//! packed atlas. The layers are material variants (`KHR_materials_variants`): `label` (the
//! winning class, the default), `exposure` (log10 W_exp) and `hits`; viewers that know the
//! extension (three.js, Blender, the glTF sample viewer) switch between them, others show the
//! labels. Texels are unlit and sampled nearest, so one texel reads as one square.

use serde_json::{Value, json};

use super::atlas::{AtlasLayout, layer_images, png};
use super::glb::glb_container;
use crate::artifact::{ChartFrame, TexelLayers};

/// How far the quads float off the surface, metres.
const LIFT_M: f64 = 0.02;

/// Browsers refuse textures wider than this (WebGL's common `MAX_TEXTURE_SIZE`).
const MAX_TEXTURE: u32 = 16384;

/// Encodes the draped layers of `t` (which must carry its charts' frames) as a GLB file.
pub fn write_chart_glb(t: &TexelLayers) -> Result<Vec<u8>, String> {
    let layout = atlas_layout(t)?;
    let quads = DrapedQuads::of(t, &layout);
    let mut chunk = BinaryChunk::default();
    let accessors = quads.accessors(&mut chunk);
    let variants = LayerVariants::of(&layer_images(t, &layout), &mut chunk)?;
    let BinaryChunk { bin, views } = chunk;
    let doc = json!({
        "asset": {"version": "2.0", "generator": concat!("kodama-dag ", env!("CARGO_PKG_VERSION"))},
        "extensionsUsed": ["KHR_materials_variants", "KHR_materials_unlit"],
        "extensions": {"KHR_materials_variants": {"variants": variants.variants}},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "texel-layers", "mesh": 0}],
        "meshes": [{"name": "charts", "primitives": [{
            "attributes": {"POSITION": 0, "TEXCOORD_0": 1},
            "indices": 2,
            "material": 0,
            "extensions": {"KHR_materials_variants": {"mappings": variants.mappings}},
        }]}],
        "materials": variants.materials,
        "textures": variants.textures,
        // Nearest filtering and clamping: a texel is a square, and no chart bleeds into the next.
        "samplers": [{"magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071}],
        "images": variants.images,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    glb_container(&doc, bin)
}

/// The atlas the layers are packed in, refused when the layers lack their charts' frames (no
/// quad could be placed) or the atlas is wider than a viewer's texture holds.
fn atlas_layout(t: &TexelLayers) -> Result<AtlasLayout, String> {
    if t.frames.len() != t.charts.len() {
        return Err(format!(
            "the texel layers carry {} chart frames for {} charts; rerun the fusion that made them",
            t.frames.len(),
            t.charts.len()
        ));
    }
    let layout = AtlasLayout::of(t)?;
    if layout.width.max(layout.height) > MAX_TEXTURE {
        return Err(format!(
            "the texel atlas is {} x {} texels, over the {MAX_TEXTURE} a viewer's texture holds; coarsen the charts' texels",
            layout.width, layout.height
        ));
    }
    Ok(layout)
}

/// The glb's binary chunk as it is filled, and the buffer views that cut it.
#[derive(Default)]
struct BinaryChunk {
    bin: Vec<u8>,
    views: Vec<Value>,
}

impl BinaryChunk {
    /// Appends `bytes` at the next 4-byte boundary as a new buffer view (of `target`, if given);
    /// returns the view's index.
    fn push_view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        let bin = &mut self.bin;
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.views.push(v);
        bin.extend_from_slice(bytes);
        self.views.len() - 1
    }
}

/// Every chart's quad: its corners (glTF's y-up frame), their atlas coordinates, its triangles.
struct DrapedQuads {
    pos: Vec<[f32; 3]>,
    uv: Vec<[f32; 2]>,
    idx: Vec<u32>,
}

impl DrapedQuads {
    /// The quads of the charts of `t` with a size, textured from their places in `layout`.
    fn of(t: &TexelLayers, layout: &AtlasLayout) -> DrapedQuads {
        let mut quads = DrapedQuads {
            pos: Vec::new(),
            uv: Vec::new(),
            idx: Vec::new(),
        };
        for (f, &at) in t.frames.iter().zip(&layout.at) {
            if f.width == 0 || f.height == 0 {
                continue;
            }
            quads.push_chart(f, at, (layout.width as f64, layout.height as f64));
        }
        quads
    }

    /// The quad of the chart with frame `f`, lifted `LIFT_M` off its surface, its texels at
    /// (`x0`, `y0`) in an atlas of `aw` x `ah` texels, wound counter-clockwise seen from outside.
    fn push_chart(&mut self, f: &ChartFrame, (x0, y0): (u32, u32), (aw, ah): (f64, f64)) {
        let (w, h) = (f.width as f64, f.height as f64);
        let corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)];
        let base = self.pos.len() as u32;
        let mut world = [[0.0; 3]; 4];
        for (c, &(u, v)) in corners.iter().enumerate() {
            let p = f.world_of(u, v);
            world[c] = std::array::from_fn(|k| p[k] + LIFT_M * f.normal[k]);
            // glTF is y-up: site (x, y, z) is written (x, z, -y).
            self.pos
                .push([world[c][0] as f32, world[c][2] as f32, -world[c][1] as f32]);
            // Texel (i, j) sits at atlas pixel (x0 + i, y0 + height - 1 - j); image v runs down.
            self.uv.push([
                ((x0 as f64 + u) / aw) as f32,
                ((y0 as f64 + h - v) / ah) as f32,
            ]);
        }
        // Wind counter-clockwise seen from outside.
        let e1: [f64; 3] = std::array::from_fn(|k| world[1][k] - world[0][k]);
        let e3: [f64; 3] = std::array::from_fn(|k| world[3][k] - world[0][k]);
        let cross = [
            e1[1] * e3[2] - e1[2] * e3[1],
            e1[2] * e3[0] - e1[0] * e3[2],
            e1[0] * e3[1] - e1[1] * e3[0],
        ];
        let outward = (0..3).map(|k| cross[k] * f.normal[k]).sum::<f64>() > 0.0;
        let quad = if outward {
            [0, 1, 2, 0, 2, 3]
        } else {
            [0, 2, 1, 0, 3, 2]
        };
        self.idx.extend(quad.iter().map(|&q| base + q));
    }

    /// The quads' positions, texture coordinates and indices written into `chunk`, and their
    /// accessors (0, 1, 2), positions with the bounds glTF requires.
    fn accessors(&self, chunk: &mut BinaryChunk) -> Value {
        let (pos, uv, idx) = (&self.pos, &self.uv, &self.idx);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in pos {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if pos.is_empty() {
            (lo, hi) = ([0.0; 3], [0.0; 3]);
        }
        let pv = chunk.push_view(bytemuck::cast_slice(pos), Some(34962));
        let tv = chunk.push_view(bytemuck::cast_slice(uv), Some(34962));
        let iv = chunk.push_view(bytemuck::cast_slice(idx), Some(34963));
        json!([
            {"bufferView": pv, "componentType": 5126, "count": pos.len(), "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": tv, "componentType": 5126, "count": uv.len(), "type": "VEC2"},
            {"bufferView": iv, "componentType": 5125, "count": idx.len(), "type": "SCALAR"},
        ])
    }
}

/// One material variant per texel layer: its image, texture, unlit material, variant name and
/// the mapping that picks it.
struct LayerVariants {
    images: Vec<Value>,
    textures: Vec<Value>,
    materials: Vec<Value>,
    variants: Vec<Value>,
    mappings: Vec<Value>,
}

impl LayerVariants {
    /// The variants of `layers` (name, atlas image, legend), their PNGs written into `chunk`.
    fn of(
        layers: &[(&str, image::RgbaImage, Value)],
        chunk: &mut BinaryChunk,
    ) -> Result<LayerVariants, String> {
        let (mut images, mut textures, mut materials, mut variants, mut mappings) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (k, (name, img, legend)) in layers.iter().enumerate() {
            let v = chunk.push_view(&png(img)?, None);
            images.push(json!({"bufferView": v, "mimeType": "image/png", "name": name}));
            textures.push(json!({"source": k, "sampler": 0}));
            materials.push(json!({
                "name": name,
                "pbrMetallicRoughness": {"baseColorTexture": {"index": k}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
                "alphaMode": "MASK",
                "alphaCutoff": 0.5,
                "doubleSided": true,
                "extensions": {"KHR_materials_unlit": {}},
                "extras": {"legend": legend},
            }));
            variants.push(json!({"name": name}));
            mappings.push(json!({"material": k, "variants": [k]}));
        }
        Ok(LayerVariants {
            images,
            textures,
            materials,
            variants,
            mappings,
        })
    }
}
