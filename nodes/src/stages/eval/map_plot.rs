//! A map figure for the report (a per-stage figure a reviewer asks for): over the orthophoto at
//! native resolution, any of a colour-mapped raster (terrain error, a radio map), footprint
//! outlines against reference outlines, and placed objects against the truth's clutter.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, City, Footprints, Ortho, Raster, ReportFiles, Scene};
use crate::io::export::figures::maps::{
    Layer, MapFigure, Markers, Palette, Path, robust_range, view_grid,
};
use crate::io::export::figures::{PALETTE, render};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Colour scale of the raster layer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub enum MapPalette {
    /// Viridis between the 2nd and 98th percentile (levels).
    #[default]
    Viridis,
    /// Blue-white-red symmetric about zero (signed errors).
    Diverging,
}

/// Params of [`MapPlot`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapPlotParams {
    /// The figure's file stem in the report (`<name>.png`, `<name>.svg`).
    pub name: String,
    /// The title over the map.
    pub title: String,
    /// The raster's colour scale.
    #[serde(default)]
    pub palette: MapPalette,
    /// The raster's value range; default the 2nd to 98th percentile (symmetric when diverging).
    #[serde(default)]
    pub range: Option<(f64, f64)>,
    /// The colour bar's caption.
    #[serde(default = "units")]
    pub units: String,
    /// Raster opacity over the orthophoto. Default 0.65.
    #[serde(default = "alpha")]
    pub alpha: f64,
}

fn units() -> String {
    "value".into()
}
fn alpha() -> f64 {
    0.65
}

/// The map figure, as `<name>.svg` and `<name>.png` in a report folder (give it to Report's
/// `figures`).
pub struct MapPlot;

/// The radius of the truth's rings, metres.
const MATCH_RADIUS_M: f64 = 1.5;
const OURS: [u8; 3] = [230, 30, 30];
const REFERENCE: [u8; 3] = [0, 200, 230];

impl Stage for MapPlot {
    const KIND: &'static str = "MapPlot";
    const VERSION: u32 = 1;
    const DOC: &'static str = "A map figure (SVG and PNG) over the orthophoto: a colour-mapped raster, outlines against reference outlines, objects against the truth's clutter";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::optional("ortho", ArtifactType::Ortho, "the orthophoto under the map"),
        InputSpec::optional("raster", ArtifactType::Raster, "a raster to colour-map"),
        InputSpec::optional(
            "outlines",
            ArtifactType::Footprints,
            "outlines drawn in red",
        ),
        InputSpec::optional(
            "reference",
            ArtifactType::Footprints,
            "reference outlines drawn in cyan",
        ),
        InputSpec::optional(
            "objects",
            ArtifactType::Scene,
            "placed objects (e.g. clutter) as discs by class",
        ),
        InputSpec::optional(
            "city",
            ArtifactType::City,
            "the synthetic truth: its clutter as rings by class",
        ),
    ];
    type Params = MapPlotParams;
    type Output = ReportFiles;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::safe_name::check_file_name(&p.name).map_err(|m| ParamError::new("name", m))?;
        if !(p.alpha.is_finite() && (0.0..=1.0).contains(&p.alpha)) {
            return Err(ParamError::new("alpha", "expected an opacity in [0, 1]"));
        }
        if let Some((lo, hi)) = p.range
            && !(lo.is_finite() && hi.is_finite() && lo < hi)
        {
            return Err(ParamError::new(
                "range",
                "expected finite (low, high) with low < high",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<ReportFiles, StageError> {
        let ortho: Option<&Ortho> = inputs.optional("ortho")?;
        let raster: Option<&Raster> = inputs.optional("raster")?;
        let extent = raster
            .map(|r| r.grid)
            .or(ortho.map(|o| o.grid))
            .ok_or_else(|| {
                StageError::Failed("a map needs a `raster` or an `ortho` to set its extent".into())
            })?;
        let cells: Vec<f64> = raster
            .iter()
            .map(|r| r.grid.cell_m)
            .chain(ortho.map(|o| o.grid.cell_m))
            .collect();
        let view = view_grid(&extent, &cells);
        let palette = match p.palette {
            MapPalette::Viridis => Palette::Viridis,
            MapPalette::Diverging => Palette::Diverging,
        };
        let layer = raster.map(|r| Layer {
            raster: r,
            palette,
            range: p.range.unwrap_or_else(|| robust_range(r, palette)),
            alpha: if ortho.is_some() { p.alpha } else { 1.0 },
            units: p.units.clone(),
        });
        let mut fig = MapFigure::new(p.title.clone(), view, ortho, layer);
        let rings = |f: &Footprints, color: [u8; 3], width: u32| -> Vec<Path> {
            f.items
                .iter()
                .flat_map(|b| &b.polygons)
                .flat_map(|poly| std::iter::once(&poly.exterior).chain(&poly.holes))
                .map(|ring| Path {
                    points: ring.clone(),
                    closed: true,
                    color,
                    width,
                })
                .collect()
        };
        if let Some(f) = inputs.optional::<Footprints>("reference")? {
            fig.paths.extend(rings(f, REFERENCE, 3));
            fig.legend.push(("reference outlines".into(), REFERENCE));
        }
        if let Some(f) = inputs.optional::<Footprints>("outlines")? {
            fig.paths.extend(rings(f, OURS, 2));
            fig.legend.push(("outlines".into(), OURS));
        }
        // One colour per class across the placed objects and the truth, so a disc inside a ring
        // of its colour is a hit.
        let mut placed: BTreeMap<String, Vec<[f64; 2]>> = BTreeMap::new();
        if let Some(s) = inputs.optional::<Scene>("objects")? {
            for (class, at) in object_centres(s) {
                placed.entry(class).or_default().push(at);
            }
        }
        let mut truth: BTreeMap<String, Vec<[f64; 2]>> = BTreeMap::new();
        if let Some(c) = inputs.optional::<City>("city")? {
            for k in &c.clutter {
                truth.entry(k.kind.clone()).or_default().push(k.center);
            }
        }
        let mut classes: Vec<&String> = placed.keys().chain(truth.keys()).collect();
        classes.sort();
        classes.dedup();
        let colour =
            |c: &str| PALETTE[classes.iter().position(|k| *k == c).unwrap_or(0) % PALETTE.len()];
        // Rings as wide as the 1.5 m within which a placed object counts as found (issue 15's
        // matching radius), so a reader can count hits by eye.
        let ring_px = (MATCH_RADIUS_M / view.cell_m).round().clamp(4.0, 60.0) as u32;
        for (class, pts) in &truth {
            fig.markers.push(Markers {
                points: pts.clone(),
                color: colour(class),
                filled: false,
                radius: ring_px,
                label: format!("{class} (truth, {MATCH_RADIUS_M} m ring)"),
            });
        }
        for (class, pts) in &placed {
            fig.markers.push(Markers {
                points: pts.clone(),
                color: colour(class),
                filled: true,
                radius: 6,
                label: format!("{class} (placed)"),
            });
        }
        let f = render(&fig).map_err(StageError::Failed)?;
        Ok(ReportFiles {
            files: vec![
                (format!("{}.svg", p.name), f.svg.into_bytes()),
                (format!("{}.png", p.name), f.png),
            ],
        })
    }
}

/// Each object's class (its id before the trailing `-<n>`, parts such as `-trunk` folded into
/// their object) and plan centre (the mean of its vertices), in object order.
fn object_centres(s: &Scene) -> Vec<(String, [f64; 2])> {
    let mut order: Vec<String> = Vec::new();
    let mut sums: BTreeMap<String, ([f64; 2], usize)> = BTreeMap::new();
    for o in &s.objects {
        let base = base_id(&o.id);
        let e = sums.entry(base.to_owned()).or_insert_with(|| {
            order.push(base.to_owned());
            ([0.0; 2], 0)
        });
        for v in o.mesh.positions.iter() {
            e.0[0] += v[0] as f64;
            e.0[1] += v[1] as f64;
            e.1 += 1;
        }
    }
    order
        .into_iter()
        .filter_map(|id| {
            let (s, n) = sums[&id];
            let class = id
                .rsplit_once('-')
                .map_or(id.as_str(), |(c, _)| c)
                .to_owned();
            (n > 0).then(|| (class, [s[0] / n as f64, s[1] / n as f64]))
        })
        .collect()
}

/// `car-3-trunk` -> `car-3`: the id up to and including its first numeric part.
fn base_id(id: &str) -> &str {
    let mut end = 0;
    for (k, part) in id.split('-').enumerate() {
        end += part.len() + usize::from(k > 0);
        if k > 0 && !part.is_empty() && part.bytes().all(|b| b.is_ascii_digit()) {
            return &id[..end];
        }
    }
    id
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_fold_into_their_object() {
        assert_eq!(base_id("car-3"), "car-3");
        assert_eq!(base_id("small_tree-12-trunk"), "small_tree-12");
        assert_eq!(base_id("bus"), "bus");
    }
}
