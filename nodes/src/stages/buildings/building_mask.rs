//! Building masks F_b (paper Sec. 4.1): which cells of the site belong to which building, from
//! an external mask or footprints when given (the paper runs a footprint network on the
//! orthophoto), else the LiDAR's building class where the data has one, else geometric cues on the
//! above-ground field A, so that trees do not become buildings. With cues alone two more tests
//! run on each candidate: a roof stops the laser, a crown lets a share of it through to what lies
//! below (the "penetration" cue of building extraction from LiDAR without classes, e.g.
//! Rottensteiner et al. 2005, Awrangjeb and Fraser 2014); a deck a few metres wide (a footbridge
//! over a river bed) is narrower than any building; and a building stands on walls, where a bank
//! or a mound the terrain missed ramps down. What the cues drop is warned about.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Footprints, Grid, PodVec, PointSet, Raster};
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
    /// Without classes, with points: a candidate where more than this share of the returns
    /// inside it (its edge aside) reached the ground is vegetation, not a roof. Default 0.05.
    pub max_pass_through: f64,
    /// Without classes: a candidate with no part this wide (it vanishes when eroded by half of
    /// it) is a deck or a wall top, not a building, metres. Default 6 (house depths start there;
    /// Autzen's footbridge is 4.5-5 m wide).
    pub min_width_m: f64,
    /// Without classes: the least share of a candidate's edge where A drops by `min_height_m`
    /// or more within [`WALL_M`] outside it, a wall; a river bank or a mound the terrain missed
    /// ramps down instead. Default 0.3 (edges against a tree or a neighbour are not walls).
    pub min_walled: f64,
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
            max_pass_through: 0.05,
            min_width_m: 6.0,
            min_walled: 0.3,
        }
    }
}

/// Labels building cells of A's grid 1, 2, ... (one id per connected building, in raster order),
/// 0 elsewhere, NaN where A has no data.
pub struct BuildingMask;

impl Stage for BuildingMask {
    const KIND: &'static str = "BuildingMask";
    // 2: with cues alone, candidates the laser passes through, narrower than `min_width_m` or
    // without walls are dropped.
    const VERSION: u32 = 2;
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
            ("min_width_m", p.min_width_m),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ParamError::new(name, "expected a non-negative number"));
            }
        }
        for (name, v) in [
            ("max_pass_through", p.max_pass_through),
            ("min_walled", p.min_walled),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(ParamError::new(name, "expected a share in [0, 1]"));
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
        let cues = external.is_none() && classes.is_none();
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
        let mut labels = label_components(&mask, g.width, g.height, min_cells);
        if cues {
            labels = drop_non_buildings(p, labels, a, points, ctx);
        }
        ctx.progress.set_total(1);
        ctx.progress.advance(1);
        Ok(label_raster(&labels, a))
    }
}

/// The cue-made candidates `labels` less those the returns show to be vegetation or too narrow
/// to be a building, relabelled 1, 2, ... in raster order; warns with what it dropped and why.
fn drop_non_buildings(
    p: &BuildingMaskParams,
    labels: Vec<u32>,
    a: &Raster,
    points: Option<&PointSet>,
    ctx: &Ctx,
) -> Vec<u32> {
    let g = a.grid;
    let n = labels.iter().copied().max().unwrap_or(0) as usize;
    if n == 0 {
        return labels;
    }
    let pass = points.map(|pts| pass_through_shares(&labels, n, a, pts));
    let wide = reaches_width(&labels, n, &g, p.min_width_m);
    let walled = walled_shares(&labels, n, a, p.min_height_m);
    let (mut crowns, mut narrow, mut ramps) = (0, 0, 0);
    let keep: Vec<bool> = (1..=n)
        .map(|l| {
            if !wide[l] {
                narrow += 1;
                false
            } else if pass.as_ref().is_some_and(|s| s[l] > p.max_pass_through) {
                crowns += 1;
                false
            } else if walled[l] < p.min_walled {
                ramps += 1;
                false
            } else {
                true
            }
        })
        .collect();
    ctx.progress.warn(&format!(
        "no building class in the points and no mask or footprints: {n} building candidates \
         from geometric cues (high, smooth), {crowns} dropped as vegetation (more than {:.0} % \
         of the laser passed through), {narrow} as narrower than {} m (decks, wall tops), \
         {ramps} for want of walls (banks, mounds); bridges wider than that can still pass as \
         buildings: give the stage footprints or a mask where the site has them",
        100.0 * p.max_pass_through,
        p.min_width_m,
    ));
    let kept: Vec<bool> = labels
        .iter()
        .map(|&l| l > 0 && keep[l as usize - 1])
        .collect();
    label_components(&kept, g.width, g.height, 1)
}

/// A return this close to the ground (metres) reached it.
const GROUND_M: f64 = 1.0;

/// Per label (index 0 unused): the share of the returns in its inner cells (all four
/// neighbours in the same label: returns off a wall or the ground beside it aside) that reached
/// the ground: within [`GROUND_M`] of the terrain under them, which is the cell's highest return
/// less A there (A is that return's height above the terrain where both come from the same
/// returns on the same grid). A roof stops the laser, steps and roof units included; a crown lets
/// some of it through. 0 where a label has no returns.
fn pass_through_shares(labels: &[u32], n: usize, a: &Raster, pts: &PointSet) -> Vec<f64> {
    let g = a.grid;
    let w = g.width as usize;
    let mut top = vec![f32::NEG_INFINITY; g.len()];
    let cell = |q: &[f32; 3]| {
        g.cell_of(q[0] as f64, q[1] as f64)
            .map(|(c, r)| r as usize * w + c as usize)
    };
    for q in pts.xyz.iter() {
        if let Some(i) = cell(q) {
            top[i] = top[i].max(q[2]);
        }
    }
    let inner = |i: usize| {
        let (c, r) = (i % w, i / w);
        c > 0 && r > 0 && c + 1 < w && r + 1 < g.height as usize && {
            let l = labels[i];
            [i - 1, i + 1, i - w, i + w].iter().all(|&j| labels[j] == l)
        }
    };
    let (mut ground, mut all) = (vec![0u64; n + 1], vec![0u64; n + 1]);
    for q in pts.xyz.iter() {
        let Some(i) = cell(q) else { continue };
        let l = labels[i] as usize;
        if l == 0 || !inner(i) || !a.data[i].is_finite() {
            continue;
        }
        all[l] += 1;
        let above_ground = a.data[i] - (top[i] - q[2]);
        if (above_ground as f64) <= GROUND_M {
            ground[l] += 1;
        }
    }
    shares(&ground, &all, 0.0)
}

/// `part[l] / whole[l]` per label, `empty` where a label has no whole.
fn shares(part: &[u64], whole: &[u64], empty: f64) -> Vec<f64> {
    part.iter()
        .zip(whole)
        .map(|(&p, &w)| if w > 0 { p as f64 / w as f64 } else { empty })
        .collect()
}

/// How far outside a candidate's edge the wall test looks for the ground, metres.
const WALL_M: f64 = 1.5;

/// Per label (index 0 unused): the share of its edge cells (a 4-neighbour outside it) where A
/// drops by `drop_m` or more to the lowest cell within [`WALL_M`] outside the label; edge cells
/// with no data outside are not counted.
fn walled_shares(labels: &[u32], n: usize, a: &Raster, drop_m: f64) -> Vec<f64> {
    let g = a.grid;
    let (w, h) = (g.width as usize, g.height as usize);
    let reach = ((WALL_M / g.cell_m).ceil() as usize).max(1);
    let (mut walls, mut edges) = (vec![0u64; n + 1], vec![0u64; n + 1]);
    for i in 0..labels.len() {
        let l = labels[i];
        let (c, r) = (i % w, i / w);
        let on_edge = l > 0
            && ((c > 0 && labels[i - 1] != l)
                || (c + 1 < w && labels[i + 1] != l)
                || (r > 0 && labels[i - w] != l)
                || (r + 1 < h && labels[i + w] != l));
        if !on_edge || !a.data[i].is_finite() {
            continue;
        }
        let mut low = f32::INFINITY;
        for rr in r.saturating_sub(reach)..=(r + reach).min(h - 1) {
            for cc in c.saturating_sub(reach)..=(c + reach).min(w - 1) {
                let j = rr * w + cc;
                if labels[j] != l && a.data[j].is_finite() {
                    low = low.min(a.data[j]);
                }
            }
        }
        if low.is_finite() {
            edges[l as usize] += 1;
            if (a.data[i] - low) as f64 >= drop_m {
                walls[l as usize] += 1;
            }
        }
    }
    shares(&walls, &edges, 1.0)
}

/// Per label (index 0 unused): whether some of it is `width_m` wide, i.e. survives an erosion by
/// half of that.
fn reaches_width(labels: &[u32], n: usize, g: &Grid, width_m: f64) -> Vec<bool> {
    let radius = (width_m / 2.0 / g.cell_m).round() as i64;
    let mut wide = vec![false; n + 1];
    if radius <= 0 {
        return vec![true; n + 1];
    }
    let any: Vec<bool> = labels.iter().map(|&l| l > 0).collect();
    // Erode each label alone: one erosion of the union would let touching labels prop each
    // other up; erosion of the union with label borders cut keeps them apart.
    let apart: Vec<bool> = (0..labels.len())
        .map(|i| {
            let (w, c) = (g.width as usize, i % g.width as usize);
            let l = labels[i];
            any[i]
                && (c == 0 || labels[i - 1] == l)
                && (c + 1 == w || labels[i + 1] == l)
                && (i < w || labels[i - w] == l)
                && (i + w >= labels.len() || labels[i + w] == l)
        })
        .collect();
    let core = erode(&apart, g.width, g.height, radius);
    for (i, &k) in core.iter().enumerate() {
        if k {
            wide[labels[i] as usize] = true;
        }
    }
    wide
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

    /// Cues alone: a 12 m block on walls stays; a 4 m wide deck and a mound that ramps down
    /// (both high and smooth) go, and so does a block the laser passes through to the ground.
    #[test]
    fn cues_keep_walled_blocks_and_drop_decks_mounds_and_crowns() {
        let grid = Grid {
            x0: 0.0,
            y0: 50.0,
            cell_m: 0.5,
            width: 200,
            height: 100,
        };
        let a_at = |x: f64, y: f64| -> f32 {
            let block = |x0: f64| (x0..x0 + 12.0).contains(&x) && (10.0..22.0).contains(&y);
            if block(5.0) || block(65.0) {
                8.0
            } else if (30.0..34.0).contains(&x) && (5.0..45.0).contains(&y) {
                6.0 // the deck
            } else {
                // The mound: 9 m at its top, down to 0 over 12 m.
                let r = (x - 85.0).hypot(y - 35.0);
                (9.0 - 0.75 * r).max(0.0) as f32
            }
        };
        let data: Vec<f32> = (0..grid.len())
            .map(|i| {
                let (x, y) = grid.center(i as u32 % 200, i as u32 / 200);
                a_at(x, y)
            })
            .collect();
        // One return a cell at the top of A (terrain at 0); in the second block every third cell
        // has a second return from the ground, as under a crown.
        let mut xyz = Vec::new();
        for i in 0..grid.len() {
            let (x, y) = grid.center(i as u32 % 200, i as u32 / 200);
            xyz.push([x as f32, y as f32, a_at(x, y)]);
            if (65.0..77.0).contains(&x) && (10.0..22.0).contains(&y) && i % 3 == 0 {
                xyz.push([x as f32, y as f32, 0.2]);
            }
        }
        let n = xyz.len();
        let points = PointSet {
            xyz: PodVec(xyz),
            class: PodVec(vec![1; n]),
            ..Default::default()
        };
        let above = Raster {
            grid,
            data: PodVec(data),
        };
        let one = |a: Artifact| Slot::One(Arc::new(a));
        let some = |a: Artifact| Slot::Optional(Some(Arc::new(a)));
        let labels = run(Inputs::new()
            .with("above", one(Artifact::Raster(above)))
            .with("points", some(Artifact::Points(points))));
        let max = labels.data.iter().fold(0.0f32, |m, &l| m.max(l));
        assert_eq!(max, 1.0, "one building left");
        let (x, y) = grid.center(
            labels.data.iter().position(|&l| l == 1.0).unwrap() as u32 % 200,
            0,
        );
        assert!(
            (5.0..17.0).contains(&x),
            "the walled block at x {x} (y {y})"
        );
    }
}
