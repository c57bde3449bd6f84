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
fn pack(sizes: &[(u32, u32)]) -> (Vec<(u32, u32)>, u32, u32) {
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

/// The atlas folder of `t`.
pub fn write_atlas(t: &TexelLayers) -> Result<Vec<(String, Vec<u8>)>, String> {
    let sizes: Vec<(u32, u32)> = t.charts.iter().map(|c| (c.width, c.height)).collect();
    let (at, w, h) = pack(&sizes);
    if w as u64 * h as u64 > 1 << 30 {
        return Err(format!(
            "the atlas would be {w} x {h} texels; too large to write"
        ));
    }
    let n = (w * h) as usize;
    let (mut w_exp, mut hits) = (vec![0f32; n], vec![0f32; n]);
    let mut label: RgbaImage = ImageBuffer::from_pixel(w, h, Rgba([0, 0, 0, 0]));
    for (c, &(x0, y0)) in t.charts.iter().zip(&at) {
        let won = labels(c);
        for j in 0..c.height {
            for i in 0..c.width {
                let k = (j * c.width + i) as usize;
                // Atlas rows run down; chart v runs up: flip so walls stand upright.
                let (x, y) = (x0 + i, y0 + c.height - 1 - j);
                let a = (y * w + x) as usize;
                w_exp[a] = c.w_exp[k];
                hits[a] = c.hits[k] as f32;
                if let Some(cl) = won[k] {
                    let [r, g, b] = PALETTE[cl as usize % PALETTE.len()];
                    label.put_pixel(x, y, Rgba([r, g, b, 255]));
                }
            }
        }
    }
    let png = |img: &RgbaImage| -> Result<Vec<u8>, String> {
        let mut buf = std::io::Cursor::new(Vec::new());
        img.write_to(&mut buf, image::ImageFormat::Png)
            .map_err(|e| e.to_string())?;
        Ok(buf.into_inner())
    };
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
        "note": "chart k's texel (i, j) is at atlas pixel (x + i, y + height - 1 - j); w_exp.png shows log10 W_exp",
        "classes": t.classes.iter().enumerate().map(|(k, name)| json!({
            "class": name,
            "colour": PALETTE[k % PALETTE.len()],
        })).collect::<Vec<_>>(),
        "charts": t.charts.iter().zip(&at).map(|(c, &(x, y))| json!({
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
    Ok(vec![
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
    ])
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
