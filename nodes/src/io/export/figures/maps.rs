//! Map figures: a raster layer (radio map, error map) colour-mapped over the orthophoto at native
//! resolution, with vector overlays (outlines, markers), a colour bar, a scale bar and a north
//! arrow. North is up; one pixel is one `px_m` square of the site frame.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{Background, Draw, FONT, MAX_SIDE, nice_step, plot_err, rgb};
use crate::artifact::{Grid, Ortho, Raster};
use crate::io::export::colormap::viridis;

/// How raster values become colours.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Palette {
    /// Viridis between the range's ends (signal levels).
    Viridis,
    /// Blue through white to red, symmetric about zero (signed errors).
    Diverging,
    /// One distinct colour per whole value 0, 1, 2, ... (a best-server map's transmitter
    /// index), cycling after ten; other values are not drawn. The colour bar becomes a legend of
    /// the categories.
    Categorical,
}

/// Ten distinct colours (matplotlib's tab10), for [`Palette::Categorical`].
pub const CATEGORICAL: [[u8; 3]; 10] = super::TAB10;

/// The most categories a categorical legend lists.
pub const MAX_CATEGORIES: usize = 64;

/// The category of a categorical value: a whole number in [0, [`MAX_CATEGORIES`]).
pub fn category(v: f64) -> Option<usize> {
    (v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v < MAX_CATEGORIES as f64)
        .then_some(v as usize)
}

impl Palette {
    /// The colour of `t` in [0, 1]; for `Categorical`, `t` is the category (0, 1, 2, ...).
    pub fn at(self, t: f64) -> [u8; 3] {
        match self {
            Palette::Viridis => viridis(t),
            Palette::Categorical => CATEGORICAL[category(t).unwrap_or(0) % CATEGORICAL.len()],
            Palette::Diverging => {
                let t = t.clamp(0.0, 1.0);
                let (lo, mid, hi) = (
                    [33.0, 102.0, 172.0],
                    [247.0, 247.0, 247.0],
                    [178.0, 24.0, 43.0],
                );
                let (a, b, f) = if t < 0.5 {
                    (lo, mid, t * 2.0)
                } else {
                    (mid, hi, t * 2.0 - 1.0)
                };
                [0, 1, 2].map(|k| (a[k] + (b[k] - a[k]) * f).round() as u8)
            }
        }
    }
}

/// A colour-mapped raster layer.
pub struct Layer<'a> {
    /// The values; non-finite cells are not drawn.
    pub raster: &'a Raster,
    /// Colours.
    pub palette: Palette,
    /// Values at the palette's ends.
    pub range: (f64, f64),
    /// Opacity over the orthophoto (1 without one).
    pub alpha: f64,
    /// The colour bar's caption, e.g. "path gain (dB)".
    pub units: String,
}

/// The range a layer is drawn over: 2nd to 98th percentile, symmetric about 0 for `Diverging`.
pub fn robust_range(r: &Raster, palette: Palette) -> (f64, f64) {
    let mut v: Vec<f32> = r.data.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (0.0, 1.0);
    }
    v.sort_by(f32::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize] as f64;
    let (lo, hi) = (q(0.02), q(0.98));
    match palette {
        Palette::Diverging => {
            let m = lo.abs().max(hi.abs()).max(1e-3);
            (-m, m)
        }
        Palette::Viridis if hi > lo => (lo, hi),
        Palette::Viridis => (lo - 0.5, lo + 0.5),
        Palette::Categorical => (0.0, v[v.len() - 1].max(1.0) as f64),
    }
}

/// A polyline or polygon ring in site metres.
pub struct Path {
    /// Vertices.
    pub points: Vec<[f64; 2]>,
    /// Closed ring.
    pub closed: bool,
    /// Colour.
    pub color: [u8; 3],
    /// Stroke width, pixels.
    pub width: u32,
}

/// Point markers of one kind.
pub struct Markers {
    /// Positions, site metres.
    pub points: Vec<[f64; 2]>,
    /// Colour.
    pub color: [u8; 3],
    /// Filled disc (else a ring).
    pub filled: bool,
    /// Radius, pixels.
    pub radius: u32,
    /// Legend text (empty: none).
    pub label: String,
}

/// A transmitter site: a filled triangle at `at` with a short line along each antenna's
/// bearing, and a label.
pub struct SiteMarker {
    /// Position, site metres.
    pub at: [f64; 2],
    /// Compass bearings of its antennas, degrees clockwise from grid north (+y).
    pub bearings_deg: Vec<f64>,
    /// The label beside it (its transmitters' ids).
    pub label: String,
}

/// A map figure.
pub struct MapFigure<'a> {
    /// Title above the map.
    pub title: String,
    /// The area shown and its pixel size.
    pub view: Grid,
    /// Colour bar and legend entries of the paths, (text, colour).
    pub legend: Vec<(String, [u8; 3])>,
    /// Drawn over the background.
    pub paths: Vec<Path>,
    /// Drawn over the paths.
    pub markers: Vec<Markers>,
    /// Transmitter sites, drawn over the markers.
    pub sites: Vec<SiteMarker>,
    /// The names of a categorical layer's categories, by value (the value itself where none).
    pub categories: Vec<String>,
    layer: Option<Layer<'a>>,
    background: Background,
}

const LEFT: u32 = 40;
const TOP: u32 = 80;
const RIGHT: u32 = 330;
const BOTTOM: u32 = 40;

/// The pixel grid a map of `extent` is drawn on: the finest of `cells` (native resolution),
/// coarsened past [`MAX_SIDE`] and refined by a whole factor under about 1200 pixels so it prints.
pub fn view_grid(extent: &Grid, cells: &[f64]) -> Grid {
    let (w_m, h_m) = (
        extent.width as f64 * extent.cell_m,
        extent.height as f64 * extent.cell_m,
    );
    let mut px = cells
        .iter()
        .copied()
        .filter(|c| c.is_finite() && *c > 0.0)
        .fold(extent.cell_m, f64::min);
    let long = |px: f64| (w_m.max(h_m) / px).ceil();
    if long(px) > MAX_SIDE as f64 {
        px = w_m.max(h_m) / MAX_SIDE as f64;
    }
    let k = (1200.0 / long(px)).ceil().max(1.0);
    px /= k;
    Grid {
        x0: extent.x0,
        y0: extent.y0,
        cell_m: px,
        width: ((w_m / px).round() as u32).clamp(1, MAX_SIDE),
        height: ((h_m / px).round() as u32).clamp(1, MAX_SIDE),
    }
}

impl<'a> MapFigure<'a> {
    /// A map of `view` over `ortho` (light grey where there is none) with `layer` on top.
    pub fn new(title: String, view: Grid, ortho: Option<&Ortho>, layer: Option<Layer<'a>>) -> Self {
        let mut rgb = Vec::with_capacity(view.len());
        for row in 0..view.height {
            for col in 0..view.width {
                let (x, y) = view.center(col, row);
                let under = ortho
                    .and_then(|o| {
                        let (c, r) = o.grid.cell_of(x, y)?;
                        let i = (r * o.grid.width + c) as usize;
                        (o.valid.get(i).copied().unwrap_or(1) != 0).then(|| o.rgb[i])
                    })
                    .unwrap_or([235, 235, 235]);
                let over = layer.as_ref().and_then(|l| {
                    let (c, r) = l.raster.grid.cell_of(x, y)?;
                    let v = l.raster.at(c, r) as f64;
                    if l.palette == Palette::Categorical {
                        return category(v).map(|k| (l.palette.at(k as f64), l.alpha));
                    }
                    v.is_finite().then(|| {
                        let (lo, hi) = l.range;
                        (l.palette.at((v - lo) / (hi - lo)), l.alpha)
                    })
                });
                rgb.push(match over {
                    Some((c, a)) => [0, 1, 2]
                        .map(|k| (c[k] as f64 * a + under[k] as f64 * (1.0 - a)).round() as u8),
                    None => under,
                });
            }
        }
        MapFigure {
            title,
            legend: Vec::new(),
            paths: Vec::new(),
            markers: Vec::new(),
            sites: Vec::new(),
            categories: Vec::new(),
            background: Background {
                at: (LEFT, TOP),
                width: view.width,
                height: view.height,
                rgb,
            },
            view,
            layer,
        }
    }

    fn px(&self, p: [f64; 2]) -> (i32, i32) {
        (
            LEFT as i32 + ((p[0] - self.view.x0) / self.view.cell_m).round() as i32,
            TOP as i32 + ((self.view.y0 - p[1]) / self.view.cell_m).round() as i32,
        )
    }

    fn colour_bar<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        l: &Layer,
    ) -> Result<(), String> {
        let x = (LEFT + self.view.width + 40) as i32;
        let top = TOP as i32 + 40;
        let h = (self.view.height as i32 - 80).clamp(120, 700);
        root.draw(&Text::new(l.units.clone(), (x, TOP as i32), (FONT, 24)))
            .map_err(plot_err)?;
        if l.palette == Palette::Categorical {
            return self.category_legend(root, l, x, top);
        }
        // One band per pixel row would make thousands of SVG elements: 128 bands read smooth.
        let bands = 128;
        for b in 0..bands {
            let y0 = top + h * b / bands;
            let y1 = top + h * (b + 1) / bands;
            let c = rgb(l.palette.at(1.0 - (b as f64 + 0.5) / bands as f64));
            root.draw(&Rectangle::new([(x, y0), (x + 36, y1)], c.filled()))
                .map_err(plot_err)?;
        }
        root.draw(&Rectangle::new(
            [(x, top), (x + 36, top + h)],
            BLACK.stroke_width(1),
        ))
        .map_err(plot_err)?;
        let (lo, hi) = l.range;
        let step = nice_step(hi - lo, 6);
        let mut v = (lo / step).ceil() * step;
        while v <= hi + step * 1e-6 {
            let y = top + ((hi - v) / (hi - lo) * h as f64).round() as i32;
            root.draw(&PathElement::new(
                [(x + 36, y), (x + 46, y)],
                BLACK.stroke_width(2),
            ))
            .map_err(plot_err)?;
            let text = if step >= 1.0 {
                format!("{v:.0}")
            } else {
                format!("{v:.1}")
            };
            root.draw(&Text::new(
                text,
                (x + 52, y),
                TextStyle::from((FONT, 22)).pos(Pos::new(HPos::Left, VPos::Center)),
            ))
            .map_err(plot_err)?;
            v += step;
        }
        Ok(())
    }

    /// The categories present in a categorical layer, or named, as swatches with their names.
    fn category_legend<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        l: &Layer,
        x: i32,
        top: i32,
    ) -> Result<(), String> {
        let mut present = [false; MAX_CATEGORIES];
        for &v in l.raster.data.iter() {
            if let Some(k) = category(v as f64) {
                present[k] = true;
            }
        }
        let n = (present.iter().rposition(|&p| p).map_or(0, |k| k + 1))
            .max(self.categories.len())
            .min(MAX_CATEGORIES);
        let h = (self.view.height as i32 - 80).clamp(120, 700);
        let row = (h / n.max(1) as i32).clamp(14, 32);
        for k in 0..n {
            let y = top + row * k as i32;
            root.draw(&Rectangle::new(
                [(x, y), (x + 36, y + row - 4)],
                rgb(l.palette.at(k as f64)).filled(),
            ))
            .map_err(plot_err)?;
            let name = self
                .categories
                .get(k)
                .cloned()
                .unwrap_or_else(|| k.to_string());
            root.draw(&Text::new(
                name,
                (x + 46, y + (row - 4) / 2),
                TextStyle::from((FONT, 22)).pos(Pos::new(HPos::Left, VPos::Center)),
            ))
            .map_err(plot_err)?;
        }
        Ok(())
    }

    /// Each site's bearing lines, its triangle and its label on a light box.
    fn draw_sites<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        const LINE_PX: f64 = 55.0;
        const SIDE_PX: i32 = 14;
        for s in &self.sites {
            // A site off the map would be drawn over the margins: left out.
            if self.view.cell_of(s.at[0], s.at[1]).is_none() {
                continue;
            }
            let (x, y) = self.px(s.at);
            for b in &s.bearings_deg {
                // Clockwise from grid north; pixel rows grow southwards.
                let (sin, cos) = b.to_radians().sin_cos();
                let end = (
                    x + (LINE_PX * sin).round() as i32,
                    y - (LINE_PX * cos).round() as i32,
                );
                root.draw(&PathElement::new([(x, y), end], WHITE.stroke_width(6)))
                    .map_err(plot_err)?;
                root.draw(&PathElement::new([(x, y), end], BLACK.stroke_width(3)))
                    .map_err(plot_err)?;
            }
            let tri = [
                (x, y - SIDE_PX),
                (x - SIDE_PX, y + SIDE_PX * 2 / 3),
                (x + SIDE_PX, y + SIDE_PX * 2 / 3),
            ];
            root.draw(&Polygon::new(tri, BLACK.filled()))
                .map_err(plot_err)?;
            root.draw(&PathElement::new(
                [tri[0], tri[1], tri[2], tri[0]],
                WHITE.stroke_width(2),
            ))
            .map_err(plot_err)?;
            if !s.label.is_empty() {
                let (lx, ly) = (x + SIDE_PX + 4, y + SIDE_PX);
                let w = 13 * s.label.chars().count() as i32 + 8;
                root.draw(&Rectangle::new(
                    [(lx, ly - 4), (lx + w, ly + 28)],
                    WHITE.mix(0.8).filled(),
                ))
                .map_err(plot_err)?;
                root.draw(&Text::new(s.label.clone(), (lx + 4, ly + 2), (FONT, 22)))
                    .map_err(plot_err)?;
            }
        }
        Ok(())
    }

    fn scale_bar<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let width_m = self.view.width as f64 * self.view.cell_m;
        let len_m = nice_step(width_m / 5.0, 1);
        let len_px = (len_m / self.view.cell_m).round() as i32;
        let x = LEFT as i32 + 20;
        let y = (TOP + self.view.height) as i32 - 30;
        root.draw(&Rectangle::new(
            [(x - 10, y - 36), (x + len_px + 10, y + 14)],
            WHITE.mix(0.8).filled(),
        ))
        .map_err(plot_err)?;
        // Two halves, black and white, as survey maps draw them.
        let half = len_px / 2;
        root.draw(&Rectangle::new([(x, y), (x + half, y + 8)], BLACK.filled()))
            .map_err(plot_err)?;
        root.draw(&Rectangle::new(
            [(x, y), (x + len_px, y + 8)],
            BLACK.stroke_width(2),
        ))
        .map_err(plot_err)?;
        let text = if len_m >= 1000.0 {
            format!("{} km", len_m / 1000.0)
        } else {
            format!("{len_m} m")
        };
        root.draw(&Text::new(text, (x, y - 32), (FONT, 22)))
            .map_err(plot_err)
    }

    fn north_arrow<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let x = (LEFT + self.view.width) as i32 - 40;
        let y = TOP as i32 + 20;
        root.draw(&Polygon::new(
            [(x, y), (x - 12, y + 34), (x, y + 26), (x + 12, y + 34)],
            BLACK.filled(),
        ))
        .map_err(plot_err)?;
        root.draw(&Text::new(
            "N",
            (x, y + 40),
            TextStyle::from((FONT, 22)).pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(plot_err)
    }
}

impl Draw for MapFigure<'_> {
    fn size(&self) -> (u32, u32) {
        (
            LEFT + self.view.width + RIGHT,
            (TOP + self.view.height + BOTTOM).max(TOP + 600),
        )
    }

    fn background(&self) -> Option<&Background> {
        Some(&self.background)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        root.draw(&Text::new(
            self.title.clone(),
            (LEFT as i32, 24),
            (FONT, 34),
        ))
        .map_err(plot_err)?;
        for p in &self.paths {
            let mut pts: Vec<(i32, i32)> = p.points.iter().map(|&q| self.px(q)).collect();
            if p.closed
                && let Some(&f) = pts.first()
            {
                pts.push(f);
            }
            root.draw(&PathElement::new(pts, rgb(p.color).stroke_width(p.width)))
                .map_err(plot_err)?;
        }
        for m in &self.markers {
            let style = if m.filled {
                rgb(m.color).filled()
            } else {
                rgb(m.color).stroke_width(2)
            };
            for &q in &m.points {
                root.draw(&Circle::new(self.px(q), m.radius, style))
                    .map_err(plot_err)?;
            }
        }
        self.draw_sites(root)?;
        root.draw(&Rectangle::new(
            [
                (LEFT as i32, TOP as i32),
                (
                    (LEFT + self.view.width) as i32,
                    (TOP + self.view.height) as i32,
                ),
            ],
            BLACK.stroke_width(2),
        ))
        .map_err(plot_err)?;
        self.scale_bar(root)?;
        self.north_arrow(root)?;
        let mut y = TOP as i32;
        if let Some(l) = &self.layer {
            self.colour_bar(root, l)?;
            y += (self.view.height as i32 - 80).clamp(120, 700) + 80;
        }
        let x = (LEFT + self.view.width + 40) as i32;
        let entries = self.legend.iter().cloned().chain(
            self.markers
                .iter()
                .filter(|m| !m.label.is_empty())
                .map(|m| (m.label.clone(), m.color)),
        );
        for (text, c) in entries {
            root.draw(&Rectangle::new([(x, y), (x + 28, y + 20)], rgb(c).filled()))
                .map_err(plot_err)?;
            root.draw(&Text::new(text, (x + 38, y), (FONT, 22)))
                .map_err(plot_err)?;
            y += 32;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::PodVec;
    use crate::io::export::figures::render;

    fn pixel(png: &[u8], x: u32, y: u32) -> [u8; 3] {
        image::load_from_memory(png)
            .unwrap()
            .to_rgb8()
            .get_pixel(x, y)
            .0
    }

    /// Overlays land where their site coordinates say, north up: a marker in the north-east of
    /// the raster is drawn top-right, over the raster cell it sits on (a flipped axis fails).
    #[test]
    fn overlays_are_georeferenced() {
        let grid = Grid {
            x0: 100.0,
            y0: 500.0,
            cell_m: 2.0,
            width: 50,
            height: 40,
        };
        // Values grow eastwards: the west edge is dark purple, the east edge yellow.
        let data: Vec<f32> = (0..grid.len())
            .map(|i| (i as u32 % grid.width) as f32)
            .collect();
        let raster = Raster {
            grid,
            data: PodVec(data),
        };
        let layer = Layer {
            raster: &raster,
            palette: Palette::Viridis,
            range: (0.0, 49.0),
            alpha: 1.0,
            units: "u".into(),
        };
        let view = view_grid(&grid, &[grid.cell_m]);
        assert!(view.width >= 1200 && view.cell_m <= 2.0, "{view:?}");
        let mut fig = MapFigure::new("t".into(), view, None, Some(layer));
        let at = [100.0 + 90.0, 500.0 - 10.0];
        fig.markers.push(Markers {
            points: vec![at],
            color: [255, 0, 0],
            filled: true,
            radius: 5,
            label: String::new(),
        });
        let f = render(&fig).unwrap();
        let px = |p: [f64; 2]| {
            (
                LEFT + ((p[0] - view.x0) / view.cell_m) as u32,
                TOP + ((view.y0 - p[1]) / view.cell_m) as u32,
            )
        };
        let (mx, my) = px(at);
        assert_eq!(pixel(&f.png, mx, my), [255, 0, 0]);
        // 20 m west of the marker the raster shows its column's colour, not the marker.
        let (wx, wy) = px([at[0] - 20.0, at[1]]);
        let col = ((at[0] - 20.0 - grid.x0) / grid.cell_m).floor();
        assert_eq!(pixel(&f.png, wx, wy), Palette::Viridis.at(col / 49.0));
        // The SVG carries the same marker at the same place over the embedded raster.
        assert!(f.svg.contains("data:image/png;base64,"));
        assert!(
            f.svg.contains(&format!("cx=\"{mx}\" cy=\"{my}\"")),
            "marker not at ({mx}, {my})"
        );
    }
}
