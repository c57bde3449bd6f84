//! A raster as a PNG picture: viridis colours between the 2nd and 98th percentile of its values,
//! no-data transparent, and a colour bar with the range printed beside it (the 3 x 5 pixel font
//! of `pixel_font`, scaled), so a radio map reads without GIS software.

use image::{ImageBuffer, Rgba, RgbaImage};

use crate::artifact::Raster;

/// Viridis at 9 stops (matplotlib's), interpolated linearly.
const VIRIDIS: [[f32; 3]; 9] = [
    [68.0, 1.0, 84.0],
    [71.0, 44.0, 122.0],
    [59.0, 81.0, 139.0],
    [44.0, 113.0, 142.0],
    [33.0, 144.0, 141.0],
    [39.0, 173.0, 129.0],
    [92.0, 200.0, 99.0],
    [170.0, 220.0, 50.0],
    [253.0, 231.0, 37.0],
];

pub(crate) fn viridis(t: f64) -> [u8; 3] {
    let x = t.clamp(0.0, 1.0) * (VIRIDIS.len() - 1) as f64;
    let (i, f) = (x.floor() as usize, (x - x.floor()) as f32);
    let (a, b) = (VIRIDIS[i], VIRIDIS[(i + 1).min(VIRIDIS.len() - 1)]);
    [0, 1, 2].map(|k| (a[k] + (b[k] - a[k]) * f).round() as u8)
}

fn text(img: &mut RgbaImage, x: u32, y: u32, s: &str, scale: u32) {
    super::pixel_font::text_px(img, x as i64, y as i64, s, scale, Rgba([0, 0, 0, 255]));
}

/// The PNG bytes of `r` with a colour bar.
pub fn raster_png(r: &Raster) -> Result<Vec<u8>, String> {
    let g = r.grid;
    let mut v: Vec<f32> = r.data.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f32::total_cmp);
    let (lo, hi) = if v.is_empty() {
        (0.0, 1.0)
    } else {
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize] as f64;
        let (a, b) = (q(0.02), q(0.98));
        if b > a { (a, b) } else { (a - 0.5, a + 0.5) }
    };
    let scale = (g.height / 100).clamp(1, 4);
    let bar_w = 16 * scale;
    let label_w = 4 * 8 * scale;
    let (w, h) = (
        g.width + 10 * scale + bar_w + 4 * scale + label_w,
        g.height.max(60),
    );
    let mut img: RgbaImage = ImageBuffer::from_pixel(w, h, Rgba([255, 255, 255, 255]));
    for row in 0..g.height {
        for col in 0..g.width {
            let x = r.at(col, row);
            let px = if x.is_finite() {
                let c = viridis((x as f64 - lo) / (hi - lo));
                Rgba([c[0], c[1], c[2], 255])
            } else {
                Rgba([0, 0, 0, 0])
            };
            img.put_pixel(col, row, px);
        }
    }
    let bx = g.width + 10 * scale;
    for y in 0..h {
        let c = viridis(1.0 - y as f64 / (h - 1).max(1) as f64);
        for x in bx..bx + bar_w {
            img.put_pixel(x, y, Rgba([c[0], c[1], c[2], 255]));
        }
    }
    let lx = bx + bar_w + 4 * scale;
    text(&mut img, lx, 0, &format!("{hi:.1}"), scale);
    text(
        &mut img,
        lx,
        h / 2 - 3 * scale,
        &format!("{:.1}", (lo + hi) / 2.0),
        scale,
    );
    text(&mut img, lx, h - 6 * scale, &format!("{lo:.1}"), scale);
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| format!("PNG encoding failed: {e}"))?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Grid, PodVec};

    #[test]
    fn a_map_decodes_with_its_colours_and_a_bar() {
        let r = Raster {
            grid: Grid {
                x0: 0.0,
                y0: 10.0,
                cell_m: 1.0,
                width: 50,
                height: 40,
            },
            data: PodVec(
                (0..2000)
                    .map(|i| if i == 0 { f32::NAN } else { -(i as f32) / 20.0 })
                    .collect(),
            ),
        };
        let png = raster_png(&r).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgba8();
        assert!(img.width() > 50 && img.height() == 60);
        assert_eq!(img.get_pixel(0, 0)[3], 0, "no data is transparent");
        // Highest values (top-left rows) are yellow, lowest dark purple.
        let top = img.get_pixel(1, 0);
        let bottom = img.get_pixel(49, 39);
        assert!(top[0] > 200 && top[1] > 200, "{top:?}");
        assert!(bottom[0] < 80 && bottom[2] > 70, "{bottom:?}");
    }
}
