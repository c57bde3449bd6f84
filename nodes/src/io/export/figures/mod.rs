//! The report's figures, drawn with plotters once per backend: SVG for print and editing, PNG for
//! the page. PNG text is rasterised by ab_glyph from a vendored DejaVu Sans (assets/fonts), so the
//! figures look the same on every machine and need no system font library. Figures over a map
//! carry a raster background (orthophoto, radio map) painted under the drawing: in the PNG as
//! pixels, in the SVG as an embedded PNG `<image>`.

pub mod charts;
pub mod maps;
pub mod relief;
pub mod render3d;

use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

/// Print size: about 1600 x 1000 pixels, the figures' default.
pub const PRINT: (u32, u32) = (1600, 1000);

/// The largest figure side drawn, pixels: a map at native resolution is downsampled past it.
pub const MAX_SIDE: u32 = 6000;

/// matplotlib's tab10: ten distinct colours, for series and for categorical maps.
pub const TAB10: [[u8; 3]; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
];

/// Series colours: tab10's first six, in order.
pub const PALETTE: [[u8; 3]; 6] = [TAB10[0], TAB10[1], TAB10[2], TAB10[3], TAB10[4], TAB10[5]];

/// The font family every figure uses; registered with plotters under this name.
pub const FONT: &str = "sans-serif";

static DEJAVU_SANS: &[u8] = include_bytes!("../../../../assets/fonts/DejaVuSans.ttf");

/// One figure in both encodings.
#[derive(Clone, Debug)]
pub struct Figure {
    /// The SVG document.
    pub svg: String,
    /// The PNG bytes.
    pub png: Vec<u8>,
}

/// Pixels painted under a drawing (row-major RGB), placed at `at` in the figure.
pub struct Background {
    /// Top-left corner in the figure, pixels.
    pub at: (u32, u32),
    /// Size, pixels.
    pub width: u32,
    /// Size, pixels.
    pub height: u32,
    /// `width * height` colours, row by row from the top.
    pub rgb: Vec<[u8; 3]>,
}

/// Something drawn the same way on any plotters backend.
pub trait Draw {
    /// The figure's size in pixels.
    fn size(&self) -> (u32, u32) {
        PRINT
    }
    /// A raster painted under the drawing (the figure's background is white elsewhere).
    fn background(&self) -> Option<&Background> {
        None
    }
    /// Draws on `root` (already white, background painted).
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

/// A plotters error as text.
pub(crate) fn plot_err<E: std::fmt::Debug>(e: E) -> String {
    format!("drawing a figure failed: {e:?}")
}

fn register_font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        for style in [FontStyle::Normal, FontStyle::Bold] {
            plotters::style::register_font(FONT, style, DEJAVU_SANS)
                .map_err(|_| "the vendored DejaVu Sans is not a font".to_string())?;
        }
        Ok(())
    })
    .clone()
}

/// Draws `d` as SVG and as PNG.
pub fn render(d: &impl Draw) -> Result<Figure, String> {
    register_font()?;
    let (w, h) = d.size();
    if w == 0 || h == 0 || w > MAX_SIDE * 2 || h > MAX_SIDE * 2 {
        return Err(format!("a figure of {w} x {h} pixels cannot be drawn"));
    }
    let bg = d.background();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        d.draw(&root)?;
        root.present().map_err(plot_err)?;
    }
    if let Some(bg) = bg {
        svg = embed_background(&svg, bg)?;
    }
    let mut buf = vec![255u8; w as usize * h as usize * 3];
    if let Some(bg) = bg {
        paint(&mut buf, w, h, bg);
    }
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        d.draw(&root)?;
        root.present().map_err(plot_err)?;
    }
    Ok(Figure {
        svg,
        png: png_rgb(w, h, buf)?,
    })
}

fn paint(buf: &mut [u8], w: u32, h: u32, bg: &Background) {
    for row in 0..bg.height {
        let y = bg.at.1 + row;
        if y >= h {
            break;
        }
        for col in 0..bg.width {
            let x = bg.at.0 + col;
            if x >= w {
                break;
            }
            let at = (y as usize * w as usize + x as usize) * 3;
            buf[at..at + 3].copy_from_slice(&bg.rgb[(row * bg.width + col) as usize]);
        }
    }
}

/// PNG bytes of a row-major RGB buffer.
pub(crate) fn png_rgb(w: u32, h: u32, buf: Vec<u8>) -> Result<Vec<u8>, String> {
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| format!("{w} x {h} RGB buffer has the wrong length"))?;
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| format!("PNG encoding failed: {e}"))?;
    Ok(out.into_inner())
}

/// The SVG with `bg` as its first element, so everything drawn lies over it.
fn embed_background(svg: &str, bg: &Background) -> Result<String, String> {
    let flat: Vec<u8> = bg.rgb.iter().flatten().copied().collect();
    let png = png_rgb(bg.width, bg.height, flat)?;
    let open = svg
        .find("<svg")
        .and_then(|s| svg[s..].find('>').map(|e| s + e + 1))
        .ok_or("plotters wrote an SVG without an <svg> element")?;
    // plotters' white fill is the first element after <svg>: the image goes right after it.
    let after_fill = svg[open..].find("/>").map(|e| open + e + 2).unwrap_or(open);
    Ok(format!(
        "{}\n<image x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" style=\"image-rendering:pixelated\" href=\"data:image/png;base64,{}\"/>{}",
        &svg[..after_fill],
        bg.at.0,
        bg.at.1,
        bg.width,
        bg.height,
        super::report_html::base64(&png),
        &svg[after_fill..]
    ))
}

/// Round tick values: a step of 1, 2 or 5 times a power of ten giving about `n` ticks.
pub fn nice_step(span: f64, n: usize) -> f64 {
    let raw = (span / n.max(1) as f64).abs().max(1e-12);
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    mag * if f < 1.5 {
        1.0
    } else if f < 3.5 {
        2.0
    } else if f < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// A range with a little room at both ends; (0, 1) when `values` is empty.
pub fn padded_range(values: impl IntoIterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo > hi {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.04).max(0.5);
    (lo - pad, hi + pad)
}

/// A colour as plotters takes it.
pub fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Dot;
    impl Draw for Dot {
        fn size(&self) -> (u32, u32) {
            (200, 100)
        }
        fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
            root.draw(&Circle::new((100, 50), 10, RED.filled()))
                .map_err(plot_err)?;
            root.draw(&Text::new("dB", (10, 10), (FONT, 30)))
                .map_err(plot_err)
        }
    }

    #[test]
    fn both_encodings_carry_the_drawing() {
        let f = render(&Dot).unwrap();
        assert!(
            f.svg.contains("<circle") && f.svg.contains("<text") && f.svg.contains("dB"),
            "{}",
            f.svg
        );
        let img = image::load_from_memory(&f.png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (200, 100));
        assert_eq!(img.get_pixel(100, 50).0, [255, 0, 0]);
        // The text was rasterised: some dark pixels in its box, none in an empty corner.
        let dark = |x0: u32, y0: u32, x1: u32, y1: u32| {
            (x0..x1)
                .flat_map(|x| (y0..y1).map(move |y| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y).0[0] < 128)
                .count()
        };
        assert!(dark(10, 0, 50, 40) > 20);
        assert_eq!(dark(150, 0, 200, 30), 0);
    }

    #[test]
    fn ticks_are_round() {
        assert_eq!(nice_step(100.0, 5), 20.0);
        assert_eq!(nice_step(7.0, 5), 1.0);
        assert_eq!(nice_step(9.0, 5), 2.0);
        assert_eq!(nice_step(0.9, 4), 0.2);
    }
}
