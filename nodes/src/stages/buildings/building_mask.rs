//! Building masks F_b (paper Sec. 4.1): which cells of the site belong to which building, from
//! an external mask or footprints when given (the paper runs a footprint network on the
//! orthophoto), else the LiDAR's building class where the data has one, else geometric cues on the
//! above-ground field A, so that trees do not become buildings.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Footprints, PodVec, PointSet, Raster};
use crate::raster::label::{label_components, label_regions};
use crate::raster::morph::{dilate, erode};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`BuildingMask`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuildingMaskParams {
    /// Cells lower than this above ground are not building. Default 2.5 m.
    pub min_height_m: f64,
    /// Use the points' ASPRS building class (6) when they have it. Default true.
    pub use_classes: bool,
    /// Without classes: the largest local roughness (mean |Laplacian| of A over 5 x 5 cells, m)
    /// of a roof; tree crowns are rougher. Default 1.0 (on the synthetic site roofs have a median
    /// of 0.2, tree crowns 6.4: returns scatter through foliage).
    pub roughness_max: f64,
    /// Without classes: how far building cores (high and smooth) grow back into adjacent high
    /// cells, recovering the roof rims the roughness window marks rough, metres. Default 1.5.
    pub grow_m: f64,
    /// Closing radius (fills small gaps: roof units, missed returns), metres. Default 1.0.
    pub close_m: f64,
    /// Opening radius (drops thin fringes: tree edges, poles, wall returns), metres. Default 1.0.
    pub open_m: f64,
    /// Smaller components are dropped, m². Default 25.
    pub min_area_m2: f64,
}

impl Default for BuildingMaskParams {
    fn default() -> Self {
        BuildingMaskParams {
            min_height_m: 2.5,
            use_classes: true,
            roughness_max: 1.0,
            grow_m: 1.5,
            close_m: 1.0,
            open_m: 1.0,
            min_area_m2: 25.0,
        }
    }
}

/// Labels building cells of A's grid 1, 2, ... (one id per connected building, in raster order),
/// 0 elsewhere, NaN where A has no data.
pub struct BuildingMask;

impl Stage for BuildingMask {
    const KIND: &'static str = "BuildingMask";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "building masks F_b as a label raster, from LiDAR classes or geometric cues on A, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("above", ArtifactType::Raster, "the above-ground field A"),
        InputSpec::optional(
            "points",
            ArtifactType::Points,
            "classified LiDAR points (class 6 = building)",
        ),
        InputSpec::optional(
            "mask",
            ArtifactType::Raster,
            "an external building mask (> 0.5 = building), e.g. a footprint network's output",
        ),
        InputSpec::optional(
            "footprints",
            ArtifactType::Footprints,
            "external footprint polygons: one label per footprint, used as they are",
        ),
    ];
    type Params = BuildingMaskParams;
    type Output = Raster;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v) in [
            ("min_height_m", p.min_height_m),
            ("roughness_max", p.roughness_max),
            ("grow_m", p.grow_m),
            ("close_m", p.close_m),
            ("open_m", p.open_m),
            ("min_area_m2", p.min_area_m2),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ParamError::new(name, "expected a non-negative number"));
            }
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let a: &Raster = inputs.one("above")?;
        let points: Option<&PointSet> = inputs.optional("points")?;
        let g = a.grid;
        let high: Vec<bool> = a
            .data
            .iter()
            .map(|&v| v.is_finite() && v as f64 >= p.min_height_m)
            .collect();
        let external: Option<&Raster> = inputs.optional("mask")?;
        let footprints: Option<&Footprints> = inputs.optional("footprints")?;
        let min_cells = (p.min_area_m2 / (g.cell_m * g.cell_m)).ceil() as usize;
        if let Some(f) = footprints {
            // Trusted outlines: each footprint is its own building, even where two touch.
            let key: Vec<u32> = f
                .rasterize(&g)
                .into_iter()
                .zip(a.data.iter())
                .map(|(k, v)| if v.is_finite() { k } else { 0 })
                .collect();
            let labels = label_regions(&key, g.width, g.height, min_cells);
            return Ok(label_raster(&labels, a));
        }
        let classes = points.filter(|pts| p.use_classes && pts.class.contains(&6));
        let mut mask = match (external, classes) {
            (Some(m), _) => (0..g.len())
                .map(|i| {
                    let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
                    m.grid.cell_of(x, y).is_some_and(|(c, r)| m.at(c, r) > 0.5)
                })
                .collect(),
            (None, Some(pts)) => {
                let mut building = vec![false; g.len()];
                for (q, &c) in pts.xyz.iter().zip(pts.class.iter()) {
                    if c == 6
                        && let Some((col, row)) = g.cell_of(q[0] as f64, q[1] as f64)
                    {
                        building[(row * g.width + col) as usize] = true;
                    }
                }
                building
                    .iter()
                    .zip(&high)
                    .map(|(b, h)| *b && *h)
                    .collect::<Vec<bool>>()
            }
            (None, None) => {
                let rough = roughness(a);
                let core: Vec<bool> = high
                    .iter()
                    .zip(&rough)
                    .map(|(h, r)| *h && *r <= p.roughness_max as f32)
                    .collect();
                // Seeded growth: cores (minus specks) spread into adjacent high cells.
                let core = dilate(&erode(&core, g.width, g.height, 1), g.width, g.height, 1);
                let reach = dilate(
                    &core,
                    g.width,
                    g.height,
                    (p.grow_m / g.cell_m).round() as i64,
                );
                reach.iter().zip(&high).map(|(r, h)| *r && *h).collect()
            }
        };
        let radius = |m: f64| (m / g.cell_m).round() as i64;
        mask = erode(
            &dilate(&mask, g.width, g.height, radius(p.close_m)),
            g.width,
            g.height,
            radius(p.close_m),
        );
        mask = dilate(
            &erode(&mask, g.width, g.height, radius(p.open_m)),
            g.width,
            g.height,
            radius(p.open_m),
        );
        let labels = label_components(&mask, g.width, g.height, min_cells);
        ctx.progress.set_total(1);
        ctx.progress.advance(1);
        Ok(label_raster(&labels, a))
    }
}

/// Labels on A's grid: NaN where A has no data and no building.
fn label_raster(labels: &[u32], a: &Raster) -> Raster {
    let data = labels
        .iter()
        .zip(a.data.iter())
        .map(|(&l, &v)| {
            if v.is_finite() || l > 0 {
                l as f32
            } else {
                f32::NAN
            }
        })
        .collect();
    Raster {
        grid: a.grid,
        data: PodVec(data),
    }
}

/// Mean |Laplacian| of A over a 5 x 5 window: about zero on any plane (flat or sloped roofs),
/// large on tree crowns. Missing neighbours make a cell rough.
pub fn roughness(a: &Raster) -> Vec<f32> {
    let (w, h) = (a.grid.width as i64, a.grid.height as i64);
    let at = |c: i64, r: i64| {
        if c < 0 || r < 0 || c >= w || r >= h {
            f32::NAN
        } else {
            a.data[(r * w + c) as usize]
        }
    };
    let lap: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (c, r) = (i % w, i / w);
            let l = at(c - 1, r) + at(c + 1, r) + at(c, r - 1) + at(c, r + 1) - 4.0 * at(c, r);
            if l.is_finite() { l.abs() } else { 10.0 }
        })
        .collect();
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (c, r) = (i % w, i / w);
            let (mut s, mut n) = (0.0f32, 0u32);
            for dr in -2..=2 {
                for dc in -2..=2 {
                    let (cc, rr) = (c + dc, r + dr);
                    if cc >= 0 && rr >= 0 && cc < w && rr < h {
                        s += lap[(rr * w + cc) as usize];
                        n += 1;
                    }
                }
            }
            s / n as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Footprint, Grid, Polygon};
    use crate::stage::Slot;
    use crate::{Artifact, Site};
    use std::sync::Arc;

    fn square(id: &str, x: f64, s: f64) -> Footprint {
        Footprint {
            id: id.into(),
            polygons: vec![Polygon {
                exterior: vec![[x, 2.0], [x + s, 2.0], [x + s, 2.0 + s], [x, 2.0 + s]],
                holes: vec![],
            }],
            height_m: None,
            min_height_m: None,
            levels: None,
            min_level: None,
        }
    }

    fn run(inputs: Inputs) -> Raster {
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 0.5,
        };
        BuildingMask::run(&Default::default(), &inputs, &Ctx::new(&site, &[])).unwrap()
    }

    #[test]
    fn external_footprints_keep_touching_buildings_apart_and_masks_are_used() {
        let grid = Grid {
            x0: 0.0,
            y0: 20.0,
            cell_m: 0.5,
            width: 60,
            height: 40,
        };
        let above = Raster {
            grid,
            data: PodVec(vec![0.3; grid.len()]),
        };
        let one = |a: Artifact| Slot::One(Arc::new(a));
        let some = |a: Artifact| Slot::Optional(Some(Arc::new(a)));
        // Two 8 m houses sharing a wall: two labels, though A is flat (the footprints decide).
        let fps = Footprints {
            items: vec![square("a", 2.0, 8.0), square("b", 10.0, 8.0)],
        };
        let labels = run(Inputs::new()
            .with("above", one(Artifact::Raster(above.clone())))
            .with("footprints", some(Artifact::Footprints(fps))));
        let count = |l: f32| labels.data.iter().filter(|&&v| v == l).count();
        assert_eq!((count(1.0), count(2.0), count(3.0)), (256, 256, 0));
        // A network's mask: one blob, one label, cleaned like any mask.
        let mask = Raster {
            grid,
            data: PodVec(
                (0..grid.len())
                    .map(|i| {
                        let (c, r) = (i % 60, i / 60);
                        if (10..30).contains(&c) && (10..30).contains(&r) {
                            0.9
                        } else {
                            0.1
                        }
                    })
                    .collect(),
            ),
        };
        let labels = run(Inputs::new()
            .with("above", one(Artifact::Raster(above)))
            .with("mask", some(Artifact::Raster(mask))));
        let count = |l: f32| labels.data.iter().filter(|&&v| v == l).count();
        // 20 x 20 cells, less the 3 cells at each corner the 1 m opening disk cannot reach.
        assert_eq!((count(1.0), count(2.0)), (400 - 4 * 3, 0));
    }
}
