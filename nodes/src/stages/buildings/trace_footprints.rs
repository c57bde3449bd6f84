//! Footprint polygons from a building label raster (paper Sec. 4.1: "building masks F_b with
//! coherent boundaries"), output as GeoJSON in the site CRS.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Footprint, Footprints, Polygon, Raster};
use crate::buildings::regularize::{RegularizeConfig, regularize_polygon};
use crate::geom::polygon::{simplify_polygon, trace};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`TraceFootprints`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TraceFootprintsParams {
    /// Douglas-Peucker tolerance for the traced outlines, metres; 0 keeps the exact cell
    /// boundaries (collinear vertices are always merged). Default 0.
    pub simplify_m: f64,
    /// Outline regularization (`buildings::regularize`, after simplification at `simplify_m`, or one
    /// and a half cells when that is smaller): walls within this angle of the building's dominant orientation
    /// or its right angle are turned to it and meet square, degrees; 0 turns it off. The traced
    /// outline is kept where regularizing fails its checks. Default 0 (the traced outline, as
    /// evidence); BuildingSolids regularizes its own, against the roof returns.
    pub regularize_angle_deg: f64,
    /// The percentile of A within a building reported as its height. Default 90.
    pub height_percentile: f64,
}

impl Default for TraceFootprintsParams {
    fn default() -> Self {
        TraceFootprintsParams {
            simplify_m: 0.0,
            regularize_angle_deg: 0.0,
            height_percentile: 90.0,
        }
    }
}

/// One footprint per label: the outline and courtyards traced along cell boundaries.
pub struct TraceFootprints;

impl Stage for TraceFootprints {
    const KIND: &'static str = "TraceFootprints";
    // 3: a cut corner beside a spike, or a spike of several edges, is squared (buildings::regularize).
    const VERSION: u32 = 3;
    const DOC: &'static str = "footprint polygons (outlines and courtyards) traced from a building label raster, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "labels",
            ArtifactType::Raster,
            "building labels (1, 2, ...; 0 = none)",
        ),
        InputSpec::optional(
            "above",
            ArtifactType::Raster,
            "the above-ground field A, for heights",
        ),
    ];
    type Params = TraceFootprintsParams;
    type Output = Footprints;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.simplify_m >= 0.0) {
            return Err(ParamError::new(
                "simplify_m",
                "expected a non-negative tolerance in metres",
            ));
        }
        if !(0.0..=30.0).contains(&p.regularize_angle_deg) {
            return Err(ParamError::new(
                "regularize_angle_deg",
                "expected an angle from 0 (off) to 30 degrees",
            ));
        }
        if !(0.0..=100.0).contains(&p.height_percentile) {
            return Err(ParamError::new(
                "height_percentile",
                "expected a percentile in [0, 100]",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Footprints, StageError> {
        let labels: &Raster = inputs.one("labels")?;
        let above: Option<&Raster> = inputs.optional("above")?;
        let heights = above.map(|a| label_heights(labels, a));
        let cfg = RegularizeConfig {
            simplify_m: p.simplify_m.max(1.5 * labels.grid.cell_m),
            angle_tol_deg: p.regularize_angle_deg,
            ..RegularizeConfig::default()
        };
        let mut items = Vec::new();
        for (label, polygons) in trace(labels) {
            let polygons: Vec<Polygon> = polygons
                .into_iter()
                .map(|poly| {
                    let regular = (p.regularize_angle_deg > 0.0)
                        .then(|| regularize_polygon(&poly, &cfg, None))
                        .flatten();
                    regular.unwrap_or_else(|| simplify_polygon(poly, p.simplify_m))
                })
                .collect();
            let height_m = heights
                .as_ref()
                .and_then(|h| h.get(&label))
                .map(|v| percentile(v, p.height_percentile));
            items.push(Footprint {
                id: format!("building-{label}"),
                polygons,
                height_m,
                min_height_m: None,
                levels: None,
                min_level: None,
            });
        }
        Ok(Footprints { items })
    }
}

/// The finite values of `above` at the centre of each labelled cell, sorted, per label.
fn label_heights(labels: &Raster, above: &Raster) -> BTreeMap<u32, Vec<f32>> {
    let g = labels.grid;
    let mut out: BTreeMap<u32, Vec<f32>> = BTreeMap::new();
    for (i, &l) in labels.data.iter().enumerate() {
        if !(l.is_finite() && l > 0.0) {
            continue;
        }
        let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
        if let Some(a) = above
            .grid
            .cell_of(x, y)
            .map(|(c, r)| above.at(c, r))
            .filter(|a| a.is_finite())
        {
            out.entry(l as u32).or_default().push(a);
        }
    }
    for v in out.values_mut() {
        v.sort_by(f32::total_cmp);
    }
    out
}

/// The `q`-th percentile of sorted, non-empty `v`.
fn percentile(v: &[f32], q: f64) -> f64 {
    v[((v.len() - 1) as f64 * q / 100.0).round() as usize] as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Grid, PodVec};

    fn grid_of(rows: &[&str]) -> Raster {
        let (w, h) = (rows[0].len() as u32, rows.len() as u32);
        let data = rows
            .iter()
            .flat_map(|r| r.chars().map(|c| c.to_digit(10).unwrap() as f32))
            .collect();
        Raster {
            grid: Grid {
                x0: 0.0,
                y0: h as f64,
                cell_m: 1.0,
                width: w,
                height: h,
            },
            data: PodVec(data),
        }
    }

    #[test]
    fn a_courtyard_building_traces_to_an_outline_with_a_hole() {
        let r = grid_of(&["00000", "01110", "01010", "01110", "00000"]);
        let t = trace(&r);
        let p = &t[&1];
        assert_eq!(p.len(), 1);
        assert_eq!(
            p[0].exterior.len(),
            4,
            "collinear vertices merged: {:?}",
            p[0].exterior
        );
        assert_eq!(p[0].holes.len(), 1);
        assert!(
            (p[0].area() - 8.0).abs() < 1e-12,
            "9 cells minus the courtyard"
        );
    }

    #[test]
    fn simplifying_straightens_the_stairs_of_a_diagonal_outline() {
        // A band one cell wide running diagonally: stairs along both long sides.
        let rows: Vec<String> = (0..12)
            .map(|r| {
                (0..14)
                    .map(|c| if c == r || c == r + 1 { '1' } else { '0' })
                    .collect()
            })
            .collect();
        let r = grid_of(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        let exact = trace(&r)[&1][0].clone();
        assert!(exact.exterior.len() > 40, "{}", exact.exterior.len());
        let simple = simplify_polygon(exact.clone(), 1.0);
        assert!(simple.exterior.len() <= 6, "{:?}", simple.exterior);
        assert!((simple.area() - exact.area()).abs() < 0.2 * exact.area());
        assert_eq!(simplify_polygon(exact.clone(), 0.0), exact);
    }

    #[test]
    fn diagonal_touches_stay_separate_rings() {
        let r = grid_of(&["110", "110", "001"]);
        let t = trace(&r);
        let areas: Vec<f64> = t[&1].iter().map(Polygon::area).collect();
        assert_eq!(areas, vec![4.0, 1.0]);
    }

    #[test]
    fn a_regularize_angle_outside_0_to_30_degrees_is_refused() {
        for bad in [f64::NAN, f64::INFINITY, -1.0, 45.0] {
            let p = TraceFootprintsParams {
                regularize_angle_deg: bad,
                ..Default::default()
            };
            let e = TraceFootprints::validate(&p).unwrap_err();
            assert!(
                format!("{e:?}").contains("regularize_angle_deg"),
                "{bad}: {e:?}"
            );
        }
        for ok in [0.0, 12.0, 30.0] {
            let p = TraceFootprintsParams {
                regularize_angle_deg: ok,
                ..Default::default()
            };
            assert!(TraceFootprints::validate(&p).is_ok(), "{ok}");
        }
    }
}
