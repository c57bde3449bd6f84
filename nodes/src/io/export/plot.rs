//! Small PNG charts without a plotting library: axes with ticks, points, lines, a legend, and a
//! 3 x 5 pixel font (digits, capitals, a little punctuation) scaled up. Enough for a report's
//! scatter, CDF and trend plots to read on their own.

use image::{Rgb, RgbImage};

/// 3 x 5 glyphs, one row per u8 (three low bits, left to right); lower case prints as capitals.
pub fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        '=' => [0, 7, 0, 7, 0],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '%' => [5, 1, 2, 4, 5],
        '/' => [1, 1, 2, 4, 4],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        '|' => [2, 2, 2, 2, 2],
        '_' => [0, 0, 0, 0, 7],
        ' ' => [0, 0, 0, 0, 0],
        _ => return None,
    })
}

/// Draws `s` with its top-left corner at (x, y), `scale` pixels per font pixel, in `color`.
pub fn text_px<P: image::Pixel>(
    img: &mut image::ImageBuffer<P, Vec<P::Subpixel>>,
    x: i64,
    y: i64,
    s: &str,
    scale: u32,
    color: P,
) {
    for (k, c) in s.chars().enumerate() {
        let Some(g) = glyph(c) else { continue };
        for (row, bits) in g.iter().enumerate() {
            for col in 0..3u32 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        let px = x + ((k as u32 * 4 + col) * scale + dx) as i64;
                        let py = y + (row as u32 * scale + dy) as i64;
                        if px >= 0
                            && py >= 0
                            && (px as u32) < img.width()
                            && (py as u32) < img.height()
                        {
                            img.put_pixel(px as u32, py as u32, color);
                        }
                    }
                }
            }
        }
    }
}

/// [`text_px`] in an RGB colour.
pub fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, scale: u32, color: [u8; 3]) {
    text_px(img, x, y, s, scale, Rgb(color));
}

/// Width in pixels of `s` at `scale`.
pub fn text_width(s: &str, scale: u32) -> i64 {
    (s.chars().count() as u32 * 4 * scale) as i64
}

/// Colours for series, in order.
pub const PALETTE: [[u8; 3]; 6] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
];

/// One chart: a white canvas with a plot area mapped to `x` x `y` data ranges.
pub struct Chart {
    img: RgbImage,
    left: i64,
    top: i64,
    w: i64,
    h: i64,
    x: (f64, f64),
    y: (f64, f64),
    scale: u32,
    legend: Vec<(String, [u8; 3])>,
}

fn nice_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(1e-9);
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= 6.0)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-9 * span {
        out.push(if t.abs() < 1e-12 { 0.0 } else { t });
        t += step;
    }
    out
}

impl Chart {
    /// A `width` x `height` chart over the given data ranges, with a title and axis labels.
    pub fn new(
        width: u32,
        height: u32,
        x: (f64, f64),
        y: (f64, f64),
        title: &str,
        xlabel: &str,
        ylabel: &str,
    ) -> Chart {
        let scale = 2;
        let mut c = Chart {
            img: RgbImage::from_pixel(width, height, Rgb([255, 255, 255])),
            left: 70,
            top: 30,
            w: width as i64 - 90,
            h: height as i64 - 80,
            x,
            y,
            scale,
            legend: Vec::new(),
        };
        let black = [0, 0, 0];
        // Title centred over the plot area; the y label sits top-left, clear of it.
        let tx = c.left + c.w / 2 - text_width(title, scale) / 2;
        text(&mut c.img, tx.max(c.left + 130), 8, title, scale, black);
        let (l, t, w, h) = (c.left, c.top, c.w, c.h);
        for i in 0..=w {
            c.dot(l + i, t + h, [0, 0, 0]);
            c.dot(l + i, t, [200, 200, 200]);
        }
        for j in 0..=h {
            c.dot(l, t + j, [0, 0, 0]);
            c.dot(l + w, t + j, [200, 200, 200]);
        }
        for v in nice_ticks(x.0, x.1) {
            let px = c.px(v);
            for j in 0..h {
                if j % 4 == 0 {
                    c.dot(px, t + j, [225, 225, 225]);
                }
            }
            let s = fmt_tick(v);
            text(
                &mut c.img,
                px - text_width(&s, scale) / 2,
                t + h + 6,
                &s,
                scale,
                black,
            );
        }
        for v in nice_ticks(y.0, y.1) {
            let py = c.py(v);
            for i in 0..w {
                if i % 4 == 0 {
                    c.dot(l + i, py, [225, 225, 225]);
                }
            }
            let s = fmt_tick(v);
            text(
                &mut c.img,
                l - 6 - text_width(&s, scale),
                py - 5,
                &s,
                scale,
                black,
            );
        }
        text(
            &mut c.img,
            l + w / 2 - text_width(xlabel, scale) / 2,
            t + h + 24,
            xlabel,
            scale,
            black,
        );
        text(&mut c.img, 4, t - 22, ylabel, scale, black);
        c
    }

    fn dot(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.img.width() && (y as u32) < self.img.height() {
            self.img.put_pixel(x as u32, y as u32, Rgb(c));
        }
    }

    fn px(&self, v: f64) -> i64 {
        self.left + ((v - self.x.0) / (self.x.1 - self.x.0) * self.w as f64).round() as i64
    }

    fn py(&self, v: f64) -> i64 {
        self.top + self.h - ((v - self.y.0) / (self.y.1 - self.y.0) * self.h as f64).round() as i64
    }

    fn inside(&self, x: i64, y: i64) -> bool {
        x >= self.left && x <= self.left + self.w && y >= self.top && y <= self.top + self.h
    }

    /// Small filled squares at each point.
    pub fn points(&mut self, pts: &[(f64, f64)], color: [u8; 3], label: &str) {
        for &(x, y) in pts {
            let (px, py) = (self.px(x), self.py(y));
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if self.inside(px + dx, py + dy) {
                        self.dot(px + dx, py + dy, color);
                    }
                }
            }
        }
        self.legend.push((label.to_string(), color));
    }

    /// A polyline through `pts` (in order), two pixels wide.
    pub fn line(&mut self, pts: &[(f64, f64)], color: [u8; 3], label: &str) {
        for w in pts.windows(2) {
            let (x0, y0, x1, y1) = (
                self.px(w[0].0),
                self.py(w[0].1),
                self.px(w[1].0),
                self.py(w[1].1),
            );
            let n = (x1 - x0).abs().max((y1 - y0).abs()).max(1);
            for k in 0..=n {
                let x = x0 + (x1 - x0) * k / n;
                let y = y0 + (y1 - y0) * k / n;
                for d in 0..2 {
                    if self.inside(x, y + d) {
                        self.dot(x, y + d, color);
                    }
                }
            }
        }
        if !label.is_empty() {
            self.legend.push((label.to_string(), color));
        }
    }

    /// The PNG bytes, legend in the top-left corner of the plot area.
    pub fn png(mut self) -> Result<Vec<u8>, String> {
        let legend = std::mem::take(&mut self.legend);
        let (mut y, x) = (self.top + 6, self.left + 8);
        for (label, color) in legend.iter().filter(|(l, _)| !l.is_empty()) {
            for dy in 0..8 {
                for dx in 0..8 {
                    self.dot(x + dx, y + dy, *color);
                }
            }
            text(&mut self.img, x + 12, y - 1, label, self.scale, [0, 0, 0]);
            y += 14;
        }
        let mut out = std::io::Cursor::new(Vec::new());
        self.img
            .write_to(&mut out, image::ImageFormat::Png)
            .map_err(|e| format!("PNG encoding failed: {e}"))?;
        Ok(out.into_inner())
    }
}

fn fmt_tick(v: f64) -> String {
    if v.fract().abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

/// A range covering `values` with a margin, for an axis.
pub fn range(values: impl IntoIterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let m = ((hi - lo) * 0.05).max(1e-6);
    (lo - m, hi + m)
}
