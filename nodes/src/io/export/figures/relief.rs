//! Relief instances per façade (eq. (4)'s decisions): the walls with the most instances, each as
//! an elevation in metres along and up the wall, recesses filled and protrusions outlined, one
//! colour per class.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{Draw, FONT, PALETTE, plot_err, rgb};
use crate::artifact::{ChartKind, ChartSet, ReliefSet};

/// At most this many façades are drawn.
pub const PANELS: usize = 6;

/// The figure: up to [`PANELS`] walls, most instances first.
pub struct ReliefFigure<'a> {
    relief: &'a ReliefSet,
    charts: &'a ChartSet,
    walls: Vec<usize>,
    classes: Vec<String>,
}

impl<'a> ReliefFigure<'a> {
    /// The walls of `charts` with the most instances of `relief`.
    pub fn new(relief: &'a ReliefSet, charts: &'a ChartSet) -> Self {
        let mut count = vec![0usize; charts.charts.len()];
        for i in &relief.instances {
            if let Some(c) = count.get_mut(i.chart as usize) {
                *c += 1;
            }
        }
        let mut walls: Vec<usize> = (0..charts.charts.len())
            .filter(|&c| count[c] > 0 && charts.charts[c].kind == ChartKind::Wall)
            .collect();
        // Most instances first; the chart index breaks ties so the choice is stable.
        walls.sort_by(|&a, &b| count[b].cmp(&count[a]).then(a.cmp(&b)));
        walls.truncate(PANELS);
        let mut classes: Vec<String> = relief
            .instances
            .iter()
            .filter(|i| walls.contains(&(i.chart as usize)))
            .map(|i| i.class.clone())
            .collect();
        classes.sort();
        classes.dedup();
        ReliefFigure {
            relief,
            charts,
            walls,
            classes,
        }
    }

    fn colour(&self, class: &str) -> RGBColor {
        let k = self.classes.iter().position(|c| c == class).unwrap_or(0);
        rgb(PALETTE[k % PALETTE.len()])
    }
}

impl Draw for ReliefFigure<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let (body, legend) = root.split_vertically(900);
        let body = body
            .titled(
                &format!(
                    "Relief instances on the {} façades with the most (filled: recessed, outlined: protruding)",
                    self.walls.len()
                ),
                (FONT, 30),
            )
            .map_err(plot_err)?;
        if self.walls.is_empty() {
            return body
                .draw(&Text::new("no relief instances", (600, 400), (FONT, 30)))
                .map_err(plot_err);
        }
        let panels = body.split_evenly((2, 3));
        for (&c, area) in self.walls.iter().zip(&panels) {
            let ch = &self.charts.charts[c];
            let (w, h) = (ch.width as f64 * ch.texel_m, ch.height as f64 * ch.texel_m);
            let mut chart = ChartBuilder::on(area)
                .caption(format!("{} wall {c}", ch.building), (FONT, 22))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(50)
                .build_cartesian_2d(0.0..w.max(1.0), 0.0..h.max(1.0))
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .label_style((FONT, 16))
                .x_labels(5)
                .y_labels(5)
                .draw()
                .map_err(plot_err)?;
            // Covered texels as a grey silhouette, one rectangle per run along a row.
            let grey = RGBColor(215, 215, 215).filled();
            for v in 0..ch.height {
                let row = &ch.triangle_at[(v * ch.width) as usize..((v + 1) * ch.width) as usize];
                let mut u = 0;
                while u < ch.width {
                    if row[u as usize] == u32::MAX {
                        u += 1;
                        continue;
                    }
                    let start = u;
                    while u < ch.width && row[u as usize] != u32::MAX {
                        u += 1;
                    }
                    let t = ch.texel_m;
                    chart
                        .draw_series([Rectangle::new(
                            [
                                (start as f64 * t, v as f64 * t),
                                (u as f64 * t, (v + 1) as f64 * t),
                            ],
                            grey,
                        )])
                        .map_err(plot_err)?;
                }
            }
            for i in self
                .relief
                .instances
                .iter()
                .filter(|i| i.chart as usize == c)
            {
                let t = ch.texel_m;
                let r = [
                    (i.rect[0] * t, i.rect[1] * t),
                    (i.rect[2] * t, i.rect[3] * t),
                ];
                let col = self.colour(&i.class);
                let style = if i.sign < 0 {
                    col.mix(0.8).filled()
                } else {
                    col.stroke_width(3)
                };
                chart
                    .draw_series([Rectangle::new(r, style)])
                    .map_err(plot_err)?;
            }
        }
        let mut x = 40;
        for class in &self.classes {
            let c = self.colour(class);
            legend
                .draw(&Rectangle::new([(x, 30), (x + 28, 50)], c.filled()))
                .map_err(plot_err)?;
            legend
                .draw(&Text::new(class.clone(), (x + 36, 30), (FONT, 22)))
                .map_err(plot_err)?;
            x += 60 + 13 * class.chars().count() as i32;
        }
        Ok(())
    }
}
