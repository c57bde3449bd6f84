//! Material layers as an atlas a person can open: every chart's grid packed into one image per
//! layer: `material.png` false-coloured by ITU class (the glb's colours), `source.png` (observed,
//! extended from the chart, from the building, default), `w_exp.exr` and `hits.exr`, and
//! `materials.json` with where each chart sits, the colours, the weights and the counts.

use image::{ImageBuffer, Rgba, RgbaImage};
use serde_json::json;

use super::atlas::png;
use crate::artifact::Material;
use crate::artifact::{MaterialLayers, MaterialSource, NO_MATERIAL};
use crate::io::export::material_color;
use crate::io::exr_io::write_exr;

/// Colours of `source.png`, by [`MaterialSource`] discriminant.
const SOURCE_COLOURS: [[u8; 4]; 5] = [
    [0, 0, 0, 0],
    [30, 160, 60, 255],
    [240, 200, 40, 255],
    [240, 120, 30, 255],
    [200, 40, 40, 255],
];

/// The atlas folder of `m`.
pub fn write_material_atlas(m: &MaterialLayers) -> Result<Vec<(String, Vec<u8>)>, String> {
    let layers = &m.fused.charts;
    if layers.len() != m.charts.len() {
        return Err("material layers and fused layers disagree on the chart count".into());
    }
    let sizes: Vec<(u32, u32)> = layers.iter().map(|c| (c.width, c.height)).collect();
    let layout = super::atlas::AtlasLayout::of_sizes(&sizes)?;
    let (at, w, h) = (&layout.at, layout.width, layout.height);
    let n = (w * h) as usize;
    let (mut w_exp, mut hits) = (vec![0f32; n], vec![0f32; n]);
    let mut material: RgbaImage = ImageBuffer::from_pixel(w, h, Rgba([0, 0, 0, 0]));
    let mut source: RgbaImage = ImageBuffer::from_pixel(w, h, Rgba([0, 0, 0, 0]));
    for ((l, c), &(x0, y0)) in layers.iter().zip(&m.charts).zip(at) {
        for j in 0..l.height {
            for i in 0..l.width {
                let k = (j * l.width + i) as usize;
                // Atlas rows run down; chart v runs up: flip so walls stand upright.
                let (x, y) = (x0 + i, y0 + l.height - 1 - j);
                let a = (y * w + x) as usize;
                w_exp[a] = l.w_exp.get(k).copied().unwrap_or(0.0);
                hits[a] = l.hits.get(k).copied().unwrap_or(0) as f32;
                let mat = c.material.get(k).copied().unwrap_or(NO_MATERIAL);
                if let Some(mm) = Material::from_u8(mat) {
                    let [r, g, b] = material_color(mm).map(|v| (v * 255.0).round() as u8);
                    material.put_pixel(x, y, Rgba([r, g, b, 255]));
                }
                let s = c.source.get(k).copied().unwrap_or(0) as usize;
                source.put_pixel(x, y, Rgba(SOURCE_COLOURS[s.min(4)]));
            }
        }
    }
    let s = &m.stats;
    let index = json!({
        "width": w,
        "height": h,
        "note": "chart k's texel (i, j) is at atlas pixel (x + i, y + height - 1 - j)",
        "materials": Material::ALL.iter().filter(|x| x.itu_type().is_some()).map(|x| json!({
            "material": x.itu_type(),
            "colour": material_color(*x).map(|v| (v * 255.0).round() as u8),
            "weight": m.weights.get(*x as usize),
            "texels": s.by_material.get(*x as usize),
            "area_m2": s.area_m2.get(*x as usize),
        })).collect::<Vec<_>>(),
        "sources": MaterialSource::ALL.iter().map(|x| json!({
            "source": format!("{x:?}"),
            "colour": SOURCE_COLOURS[*x as usize],
            "texels": s.by_source[*x as usize],
        })).collect::<Vec<_>>(),
        "charts": layers.iter().zip(&m.charts).zip(at).map(|((l, c), &(x, y))| json!({
            "x": x, "y": y, "width": l.width, "height": l.height,
            "dominant": c.dominant.and_then(Material::from_u8).and_then(|m| m.itu_type()),
        })).collect::<Vec<_>>(),
        "stats": {
            "surface_texels": s.texels,
            "refined_pixels": s.refined_pixels,
            "refined_instances": s.refined_instances,
            "masked_rays": s.masked_rays,
            "views": m.fused.stats.views,
            "rays": m.fused.stats.rays,
            "chart_hits": m.fused.stats.chart_hits,
            "accepted": m.fused.stats.accepted,
        },
    });
    Ok(vec![
        (
            "materials.json".into(),
            serde_json::to_vec_pretty(&index).map_err(|e| e.to_string())?,
        ),
        ("material.png".into(), png(&material)?),
        ("source.png".into(), png(&source)?),
        (
            "w_exp.exr".into(),
            write_exr(w as usize, h as usize, vec![("Y", w_exp)])?,
        ),
        (
            "hits.exr".into(),
            write_exr(w as usize, h as usize, vec![("Y", hits)])?,
        ),
    ])
}
