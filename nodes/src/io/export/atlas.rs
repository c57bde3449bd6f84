//! Texel layers as an atlas a person can open: every chart's grid packed into one image per
//! layer (`w_exp.exr` and `hits.exr` as floats, `w_exp.png` in viridis, `label.png` false-coloured
//! by winning class), with `atlas.json` saying where each chart sits and what the colours mean.

use image::{ImageBuffer, Rgba, RgbaImage};
use serde_json::json;

use crate::artifact::{ChartLayers, TexelLayers};
use crate::io::exr_io::write_exr;

/// Class colours for `label.png`: distinct hues, cycled.
const PALETTE: [[u8; 3]; 12] = [
    [166, 206, 227],
    [31, 120, 180],
    [178, 223, 138],
    [51, 160, 44],
    [251, 154, 153],
    [227, 26, 28],
    [253, 191, 111],
    [255, 127, 0],
    [202, 178, 214],
    [106, 61, 154],
    [255, 255, 153],
    [177, 89, 40],
];

/// Shelf packing, tallest first (ties by chart order), one texel of gap: each chart's corner in
/// the atlas, and the atlas size.
pub(super) fn pack(sizes: &[(u32, u32)]) -> (Vec<(u32, u32)>, u32, u32) {
    let area: f64 = sizes
        .iter()
        .map(|&(w, h)| (w as f64 + 1.0) * (h as f64 + 1.0))
        .sum();
    let widest = sizes.iter().map(|s| s.0 + 1).max().unwrap_or(1);
    let width = widest.max(area.sqrt().ceil() as u32);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&k| (std::cmp::Reverse(sizes[k].1), k));
    let mut at = vec![(0, 0); sizes.len()];
    let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
    for k in order {
        let (w, h) = sizes[k];
        if x + w + 1 > width {
            (x, y) = (0, y + shelf);
            shelf = 0;
        }
        at[k] = (x, y);
        x += w + 1;
        shelf = shelf.max(h + 1);
    }
    (at, width.max(1), (y + shelf).max(1))
}

/// The winning class of every texel of a chart, `None` where nothing voted.
fn labels(c: &ChartLayers) -> Vec<Option<u16>> {
    (0..c.w_exp.len()).map(|k| c.winner(k)).collect()
}

/// Where every chart sits in the packed atlas.
pub(super) struct AtlasLayout {
    /// Each chart's top-left corner, atlas pixels.
    pub at: Vec<(u32, u32)>,
    /// Atlas width, pixels.
    pub width: u32,
    /// Atlas height, pixels.
    pub height: u32,
}

impl AtlasLayout {
    /// Packs the charts of `t`; refuses atlases over 2^30 texels.
    pub fn of(t: &TexelLayers) -> Result<AtlasLayout, String> {
        let sizes: Vec<(u32, u32)> = t.charts.iter().map(|c| (c.width, c.height)).collect();
        AtlasLayout::of_sizes(&sizes)
    }

    /// Packs grids of `sizes` (width, height); refuses atlases over 2^30 texels.
    pub fn of_sizes(sizes: &[(u32, u32)]) -> Result<AtlasLayout, String> {
        let (at, width, height) = pack(sizes);
        if width as u64 * height as u64 > 1 << 30 {
            return Err(format!(
                "the atlas would be {width} x {height} texels; too large to write"
            ));
        }
        Ok(AtlasLayout { at, width, height })
    }

    /// Atlas pixel of chart `c`'s texel (i, j): atlas rows run down, chart `v` runs up, so the
    /// grid is flipped and walls stand upright.
    pub fn pixel(&self, c: usize, height: u32, i: u32, j: u32) -> (u32, u32) {
        let (x0, y0) = self.at[c];
        (x0 + i, y0 + height - 1 - j)
    }

    /// One RGBA image over the atlas: `colour(chart, texel)` for texels on the surface
    /// (transparent off it; every texel counts as on the surface when `t` has no frames).
    pub fn paint(&self, t: &TexelLayers, colour: impl Fn(usize, usize) -> [u8; 4]) -> RgbaImage {
        let mut img: RgbaImage = ImageBuffer::from_pixel(self.width, self.height, Rgba([0; 4]));
        for (ci, c) in t.charts.iter().enumerate() {
            let frame = t.frames.get(ci);
            for j in 0..c.height {
                for i in 0..c.width {
                    let k = (j * c.width + i) as usize;
                    if frame.is_some_and(|f| !f.is_covered(k)) {
                        continue;
                    }
                    let (x, y) = self.pixel(ci, c.height, i, j);
                    img.put_pixel(x, y, Rgba(colour(ci, k)));
                }
            }
        }
        img
    }
}

/// Colour of a texel no view saw, in the draped layers.
const UNSEEN: [u8; 4] = [200, 200, 200, 255];

/// The draped layers, each an RGBA atlas: the winning class (palette), log10 W_exp and the hit
/// count (viridis between their 2nd and 98th percentiles); unseen texels grey, off-surface
/// transparent. Returns (name, image, legend).
pub(super) fn layer_images(
    t: &TexelLayers,
    layout: &AtlasLayout,
) -> Vec<(&'static str, RgbaImage, serde_json::Value)> {
    let won: Vec<Vec<Option<u16>>> = t.charts.iter().map(labels).collect();
    let label = layout.paint(t, |c, k| match won[c][k] {
        Some(cl) => {
            let [r, g, b] = PALETTE[cl as usize % PALETTE.len()];
            [r, g, b, 255]
        }
        None => UNSEEN,
    });
    let legend = json!(
        t.classes
            .iter()
            .enumerate()
            .map(|(k, name)| json!({
                "class": name, "colour": PALETTE[k % PALETTE.len()],
            }))
            .collect::<Vec<_>>()
    );
    let mut out = vec![("label", label, legend)];
    let ramp = |name: &'static str, value: &dyn Fn(usize, usize) -> Option<f64>| {
        let mut all: Vec<f64> = Vec::new();
        for (c, ch) in t.charts.iter().enumerate() {
            all.extend((0..ch.w_exp.len()).filter_map(|k| value(c, k)));
        }
        all.sort_by(f64::total_cmp);
        let q = |p: f64| all[((all.len() - 1) as f64 * p).round() as usize];
        let (lo, hi) = if all.is_empty() {
            (0.0, 1.0)
        } else {
            (q(0.02), q(0.98))
        };
        let span = if hi > lo { hi - lo } else { 1.0 };
        let img = layout.paint(t, |c, k| match value(c, k) {
            Some(v) => {
                let [r, g, b] = super::colormap::viridis((v - lo) / span);
                [r, g, b, 255]
            }
            None => UNSEEN,
        });
        (
            name,
            img,
            json!({"colormap": "viridis", "low": lo, "high": hi}),
        )
    };
    out.push(ramp("exposure", &|c, k| {
        let w = t.charts[c].w_exp[k];
        (w > 0.0).then(|| (w as f64).log10())
    }));
    out.push(ramp("hits", &|c, k| {
        let n = t.charts[c].hits[k];
        (n > 0).then_some(n as f64)
    }));
    out
}

/// PNG bytes of an image.
pub(super) fn png(img: &RgbaImage) -> Result<Vec<u8>, String> {
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(buf.into_inner())
}

/// The atlas folder of `t` (the export adds `charts.glb` beside it: `super::texel_atlas`).
pub fn write_atlas(t: &TexelLayers) -> Result<Vec<(String, Vec<u8>)>, String> {
    let layout = AtlasLayout::of(t)?;
    let (w, h) = (layout.width, layout.height);
    let n = (w * h) as usize;
    let (mut w_exp, mut hits) = (vec![0f32; n], vec![0f32; n]);
    for (ci, c) in t.charts.iter().enumerate() {
        for j in 0..c.height {
            for i in 0..c.width {
                let k = (j * c.width + i) as usize;
                let (x, y) = layout.pixel(ci, c.height, i, j);
                let a = (y * w + x) as usize;
                w_exp[a] = c.w_exp[k];
                hits[a] = c.hits[k] as f32;
            }
        }
    }
    let won: Vec<Vec<Option<u16>>> = t.charts.iter().map(labels).collect();
    // The flat label image keeps unvoted texels transparent, so it overlays other pictures.
    let label = layout.paint(t, |c, k| match won[c][k] {
        Some(cl) => {
            let [r, g, b] = PALETTE[cl as usize % PALETTE.len()];
            [r, g, b, 255]
        }
        None => [0; 4],
    });
    let exposure_png = {
        let r = crate::artifact::Raster {
            grid: crate::artifact::Grid {
                x0: 0.0,
                y0: h as f64,
                cell_m: 1.0,
                width: w,
                height: h,
            },
            data: crate::artifact::PodVec(
                w_exp
                    .iter()
                    .map(|&v| if v > 0.0 { v.log10() } else { f32::NAN })
                    .collect(),
            ),
        };
        super::colormap::raster_png(&r)?
    };
    let index = json!({
        "width": w,
        "height": h,
        "note": "chart k's texel (i, j) is at atlas pixel (x + i, y + height - 1 - j); w_exp.png shows log10 W_exp; charts.glb drapes the layers over the buildings (material variants label, exposure, hits)",
        "classes": t.classes.iter().enumerate().map(|(k, name)| json!({
            "class": name,
            "colour": PALETTE[k % PALETTE.len()],
        })).collect::<Vec<_>>(),
        "charts": t.charts.iter().zip(&layout.at).map(|(c, &(x, y))| json!({
            "x": x, "y": y, "width": c.width, "height": c.height,
        })).collect::<Vec<_>>(),
        "stats": {
            "views": t.stats.views,
            "rays": t.stats.rays,
            "chart_hits": t.stats.chart_hits,
            "accepted": t.stats.accepted,
            "masked": t.stats.masked,
        },
    });
    let files = vec![
        (
            "atlas.json".into(),
            serde_json::to_vec_pretty(&index).map_err(|e| e.to_string())?,
        ),
        (
            "w_exp.exr".into(),
            write_exr(w as usize, h as usize, vec![("Y", w_exp)])?,
        ),
        (
            "hits.exr".into(),
            write_exr(w as usize, h as usize, vec![("Y", hits)])?,
        ),
        ("w_exp.png".into(), exposure_png),
        ("label.png".into(), png(&label)?),
    ];
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_never_overlaps() {
        let sizes = [(40, 30), (5, 50), (12, 12), (1, 1), (60, 2), (33, 30)];
        let (at, w, h) = pack(&sizes);
        for (k, &(x, y)) in at.iter().enumerate() {
            assert!(x + sizes[k].0 <= w && y + sizes[k].1 <= h);
            for (l, &(x2, y2)) in at.iter().enumerate().skip(k + 1) {
                let apart = x + sizes[k].0 <= x2
                    || x2 + sizes[l].0 <= x
                    || y + sizes[k].1 <= y2
                    || y2 + sizes[l].1 <= y;
                assert!(apart, "{k} and {l} overlap");
            }
        }
    }
}
