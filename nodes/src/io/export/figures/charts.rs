//! The report's scoring charts: predicted vs measured, the CDF of the absolute error, and path
//! loss vs distance with each model's power-distance and close-in trend lines (the lines are
//! defined, with their sources, on `stages::eval::evaluate::carrier_trends`); with received power
//! and no EIRP (a drive test's RSRP), received power vs distance instead.

use plotters::coord::Shift;
use plotters::coord::combinators::LogCoord;
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::{Draw, FONT, PALETTE, padded_range, plot_err, rgb};

/// One model's links: (distance m, measured loss dB with the offset taken out, predicted dB).
#[derive(Clone)]
pub struct ModelSeries<'a> {
    /// Legend name.
    pub name: &'a str,
    /// Its links.
    pub links: &'a [(f64, f64, f64)],
    /// Its power-distance fit PL = a + 10 b log10(d), when it has one.
    pub trend: Option<(f64, f64)>,
    /// Its close-in fit PL = FSPL(f, 1 m) + 10 n log10(d) as (FSPL(f, 1 m) dB, n), drawn at one
    /// frequency (the links' median), when it has one.
    pub close_in: Option<(f64, f64)>,
}

fn colour(k: usize) -> RGBColor {
    rgb(PALETTE[k % PALETTE.len()])
}

const TITLE: u32 = 40;
const LABEL: u32 = 28;
const TICK: u32 = 22;

/// Axes of log link distance (metres) against `y_desc`, over the positive distances `ds` (padded
/// by 10 %; 1-1000 m when there are none) and the range `yr`, with the figures' mesh: what both
/// distance plots stand on.
fn log_distance_chart<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    caption: &str,
    y_desc: &str,
    ds: impl Iterator<Item = f64>,
    yr: (f64, f64),
) -> Result<ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, RangedCoordf64>>, String> {
    let (dmin, dmax) = ds
        .filter(|d| *d > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(a, b), d| (a.min(d), b.max(d)));
    let (dmin, dmax) = if dmin < dmax {
        (dmin * 0.9, dmax * 1.1)
    } else {
        (1.0, 1000.0)
    };
    let mut chart = ChartBuilder::on(root)
        .caption(caption, (FONT, TITLE))
        .margin(30)
        .x_label_area_size(80)
        .y_label_area_size(100)
        .build_cartesian_2d((dmin..dmax).log_scale(), yr.0..yr.1)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("link distance (m, log scale)")
        .x_labels(12)
        .x_label_formatter(&|d| format!("{d:.0}"))
        .y_desc(y_desc)
        .axis_desc_style((FONT, LABEL))
        .label_style((FONT, TICK))
        .light_line_style(BLACK.mix(0.05))
        .draw()
        .map_err(plot_err)?;
    Ok(chart)
}

fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    at: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(at)
        .label_font((FONT, LABEL))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.5))
        .margin(12)
        .draw()
        .map_err(plot_err)
}

/// Predicted against measured path loss, one colour per model, the 1:1 line.
pub struct Scatter<'a>(pub &'a [ModelSeries<'a>]);

impl Draw for Scatter<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let r = padded_range(
            self.0
                .iter()
                .flat_map(|m| m.links.iter().flat_map(|l| [l.1, l.2])),
        );
        let mut chart = ChartBuilder::on(root)
            .caption("Predicted vs measured path loss", (FONT, TITLE))
            .margin(30)
            .x_label_area_size(80)
            .y_label_area_size(100)
            .build_cartesian_2d(r.0..r.1, r.0..r.1)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("measured path loss (dB)")
            .y_desc("predicted path loss (dB)")
            .axis_desc_style((FONT, LABEL))
            .label_style((FONT, TICK))
            .light_line_style(BLACK.mix(0.05))
            .draw()
            .map_err(plot_err)?;
        chart
            .draw_series(LineSeries::new(
                [(r.0, r.0), (r.1, r.1)],
                BLACK.mix(0.4).stroke_width(2),
            ))
            .map_err(plot_err)?
            .label("1:1")
            .legend(|(x, y)| {
                PathElement::new([(x, y), (x + 30, y)], BLACK.mix(0.4).stroke_width(2))
            });
        for (k, m) in self.0.iter().enumerate() {
            let c = colour(k);
            chart
                .draw_series(
                    m.links
                        .iter()
                        .map(|l| Circle::new((l.1, l.2), 4, c.mix(0.7).filled())),
                )
                .map_err(plot_err)?
                .label(m.name)
                .legend(move |(x, y)| Circle::new((x + 15, y), 7, c.filled()));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    }
}

/// The CDF of |predicted − measured| per model.
pub struct ErrorCdf<'a>(pub &'a [ModelSeries<'a>]);

impl Draw for ErrorCdf<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let errs: Vec<Vec<f64>> = self
            .0
            .iter()
            .map(|m| {
                let mut e: Vec<f64> = m.links.iter().map(|l| (l.2 - l.1).abs()).collect();
                e.sort_by(f64::total_cmp);
                e
            })
            .collect();
        let xmax = errs.iter().flatten().fold(1.0f64, |a, &v| a.max(v)) * 1.02;
        let mut chart = ChartBuilder::on(root)
            .caption("CDF of the absolute prediction error", (FONT, TITLE))
            .margin(30)
            .x_label_area_size(80)
            .y_label_area_size(100)
            .build_cartesian_2d(0.0..xmax, 0.0..1.0)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("|predicted − measured| (dB)")
            .y_desc("share of links")
            .axis_desc_style((FONT, LABEL))
            .label_style((FONT, TICK))
            .light_line_style(BLACK.mix(0.05))
            .draw()
            .map_err(plot_err)?;
        for (k, (m, e)) in self.0.iter().zip(&errs).enumerate() {
            let c = colour(k);
            let n = e.len().max(1) as f64;
            // A step function: each link raises the curve by 1/n at its error.
            let mut pts = vec![(0.0, 0.0)];
            for (i, &v) in e.iter().enumerate() {
                pts.push((v, i as f64 / n));
                pts.push((v, (i + 1) as f64 / n));
            }
            chart
                .draw_series(LineSeries::new(pts, c.stroke_width(3)))
                .map_err(plot_err)?
                .label(m.name)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 30, y)], c.stroke_width(3)));
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    }
}

/// Path loss against distance (log axis): the measurements and each model's trend line.
pub struct PathLossDistance<'a>(pub &'a [ModelSeries<'a>]);

impl Draw for PathLossDistance<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let ds = || {
            self.0
                .iter()
                .flat_map(|m| m.links.iter().map(|l| l.0))
                .filter(|d| *d > 0.0)
        };
        let yr = padded_range(
            self.0
                .iter()
                .flat_map(|m| m.links.iter().flat_map(|l| [l.1, l.2])),
        );
        let mut chart = log_distance_chart(
            root,
            "Path loss vs distance: power-distance (solid) and close-in (dashed) lines",
            "path loss (dB)",
            ds(),
            yr,
        )?;
        let (dmin, dmax) = {
            let r = chart.x_range();
            (r.start, r.end)
        };
        if let Some(first) = self.0.first() {
            let grey = RGBColor(90, 90, 90);
            chart
                .draw_series(
                    first
                        .links
                        .iter()
                        .filter(|l| l.0 > 0.0)
                        .map(|l| Circle::new((l.0, l.1), 3, grey.mix(0.5).filled())),
                )
                .map_err(plot_err)?
                .label("measured")
                .legend(move |(x, y)| Circle::new((x + 15, y), 6, grey.filled()));
        }
        // Only inside the axes: plotters would flatten the part outside onto the frame.
        let line = |a: f64, b: f64| {
            (0..=200)
                .map(move |i| {
                    let d = dmin * (dmax / dmin).powf(i as f64 / 200.0);
                    (d, a + 10.0 * b * d.log10())
                })
                .filter(move |p| (yr.0..=yr.1).contains(&p.1))
        };
        for (k, m) in self.0.iter().enumerate() {
            let c = colour(k);
            if let Some((a, b)) = m.trend {
                chart
                    .draw_series(LineSeries::new(line(a, b), c.stroke_width(3)))
                    .map_err(plot_err)?
                    .label(format!("{} PD (β = {b:.2})", m.name))
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 30, y)], c.stroke_width(3))
                    });
            }
            if let Some((fspl_1m, n)) = m.close_in {
                chart
                    .draw_series(DashedLineSeries::new(
                        line(fspl_1m, n),
                        12,
                        8,
                        c.stroke_width(2),
                    ))
                    .map_err(plot_err)?
                    .label(format!("{} CI (n = {n:.2})", m.name))
                    .legend(move |(x, y)| {
                        DashedPathElement::new([(x, y), (x + 30, y)], 8, 5, c.stroke_width(2))
                    });
            }
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    }
}

/// The received-power chart's values, when the measurements are received power without the
/// transmitters' EIRP (a drive test's RSRP): what [`ReceivedPowerDistance`] draws.
#[derive(Clone, Debug, PartialEq)]
pub struct PowerDistance {
    /// Each measured reading as (distance m, received power dBm), as read.
    pub measured: Vec<(f64, f64)>,
    /// Per model, its name and each scored link as (distance m, EIRP_fit − predicted path loss
    /// dBm), EIRP_fit the model's own fitted EIRP for the link's transmitter.
    pub models: Vec<(String, Vec<(f64, f64)>)>,
    /// The free-space lines, one per transmitter: (transmitter, EIRP dBm, carrier Hz).
    pub free_space: Vec<(String, f64, f64)>,
    /// Whose fitted EIRP the free-space lines are drawn at (the legend says so).
    pub free_space_from: String,
}

/// Received power against distance (log axis): the measured readings as read, each model's
/// prediction at its fitted EIRP, and free space at each transmitter's fitted EIRP, one dashed
/// line per transmitter under one legend entry.
pub struct ReceivedPowerDistance<'a>(pub &'a PowerDistance);

impl Draw for ReceivedPowerDistance<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let pd = self.0;
        let all = || {
            pd.measured
                .iter()
                .chain(pd.models.iter().flat_map(|m| m.1.iter()))
                .filter(|p| p.0 > 0.0 && p.1.is_finite())
        };
        let yr = padded_range(all().map(|p| p.1));
        let mut chart = log_distance_chart(
            root,
            "Received power vs distance: measured RSRP, models at their fitted EIRP",
            "received power, RSRP (dBm)",
            all().map(|p| p.0),
            yr,
        )?;
        let (dmin, dmax) = {
            let r = chart.x_range();
            (r.start, r.end)
        };
        let grey = RGBColor(90, 90, 90);
        chart
            .draw_series(
                pd.measured
                    .iter()
                    .filter(|p| p.0 > 0.0)
                    .map(|p| Circle::new(*p, 3, grey.mix(0.5).filled())),
            )
            .map_err(plot_err)?
            .label("measured RSRP (as read)")
            .legend(move |(x, y)| Circle::new((x + 15, y), 6, grey.filled()));
        for (k, (name, pts)) in pd.models.iter().enumerate() {
            let c = colour(k);
            chart
                .draw_series(
                    pts.iter()
                        .filter(|p| p.0 > 0.0)
                        .map(|p| Circle::new(*p, 2, c.mix(0.5).filled())),
                )
                .map_err(plot_err)?
                .label(format!("{name}: its EIRP_fit − PL_pred"))
                .legend(move |(x, y)| Circle::new((x + 15, y), 6, c.filled()));
        }
        // Only inside the axes: plotters would flatten the part outside onto the frame.
        let line = |eirp: f64, f: f64| {
            (0..=200)
                .map(move |i| {
                    let d = dmin * (dmax / dmin).powf(i as f64 / 200.0);
                    (d, eirp - crate::rf::em::fspl_db(d, f))
                })
                .filter(move |p| (yr.0..=yr.1).contains(&p.1))
        };
        for (k, (_, eirp, f)) in pd.free_space.iter().enumerate() {
            let s = chart
                .draw_series(DashedLineSeries::new(
                    line(*eirp, *f),
                    12,
                    8,
                    BLACK.stroke_width(2),
                ))
                .map_err(plot_err)?;
            if k == 0 {
                s.label(format!(
                    "free space at each cell's EIRP fitted for {} (one line per cell)",
                    pd.free_space_from
                ))
                .legend(|(x, y)| {
                    DashedPathElement::new([(x, y), (x + 30, y)], 8, 5, BLACK.stroke_width(2))
                });
            }
        }
        legend(&mut chart, SeriesLabelPosition::LowerLeft)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::export::figures::render;
    use crate::rf::em::fspl_db;
    use crate::rf::pathloss_fit::{fit_close_in, fit_power_distance};

    /// Predictions exactly on a close-in line of exponent 3: both fits find n = 3, and the chart
    /// draws the power-distance line solid and the close-in line dashed, each named with its n.
    #[test]
    fn the_path_loss_chart_draws_both_trend_lines_with_their_exponents() {
        let f = 3.5e9;
        let fspl_1m = fspl_db(1.0, f);
        let links: Vec<(f64, f64, f64)> = (1..60)
            .map(|k| {
                let d = 8.0 * k as f64;
                let pl = fspl_1m + 30.0 * d.log10();
                (d, pl + if k % 2 == 0 { 4.0 } else { -4.0 }, pl)
            })
            .collect();
        let d: Vec<f64> = links.iter().map(|l| l.0).collect();
        let pl: Vec<f64> = links.iter().map(|l| l.2).collect();
        let n = fit_close_in(&d, &pl, &vec![f; d.len()]);
        let (a, b) = fit_power_distance(&d, &pl);
        assert!((n - 3.0).abs() < 1e-9 && (b - 3.0).abs() < 1e-9 && (a - fspl_1m).abs() < 1e-6);
        let model = ModelSeries {
            name: "twin",
            links: &links,
            trend: Some((a, b)),
            close_in: Some((fspl_1m, n)),
        };
        let fig = render(&PathLossDistance(&[model])).unwrap();
        for label in ["twin PD (β = 3.00)", "twin CI (n = 3.00)", "measured"] {
            assert!(fig.svg.contains(label), "no {label:?} in the SVG");
        }
        // The dashed line is drawn as many short segments, the solid one as one polyline.
        let solid = fig.svg.matches("<polyline").count();
        let segments = fig.svg.matches("<line").count() + solid;
        assert!(
            segments > solid + 20,
            "{segments} segments, {solid} polylines"
        );
    }
}
