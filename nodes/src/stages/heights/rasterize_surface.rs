//! Point sets onto the site grid as a height field H_s (paper Sec. 4: one field per source, ⊥ where
//! the source observed nothing).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Grid, PodVec, PointSet, Raster};
use crate::raster::gap_fill::fill_gaps;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// How the points falling into one cell become its value.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum CellMode {
    /// Highest z: a digital surface model.
    Max,
    /// Lowest z: a first ground estimate.
    Min,
    /// Mean z.
    Mean,
    /// Number of points (0 where empty, never no-data).
    Count,
    /// The given percentile (0-100) of z, linearly interpolated between ranks.
    Percentile(f64),
}

/// Params of [`RasterizeSurface`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RasterizeSurfaceParams {
    /// How the points in a cell are combined.
    pub mode: CellMode,
    /// Cell size in metres; default: the site's.
    #[serde(default)]
    pub cell_m: Option<f64>,
    /// Only points of these ASPRS classes; default: all.
    #[serde(default)]
    pub classes: Option<Vec<u8>>,
    /// Points of these classes are dropped. Default: [7, 18] (low and high noise).
    #[serde(default = "noise_classes")]
    pub exclude_classes: Vec<u8>,
    /// Fill no-data cells up to this distance from observed ones, metres. Default 0 (no fill).
    #[serde(default)]
    pub max_gap_m: f64,
}

fn noise_classes() -> Vec<u8> {
    vec![7, 18]
}

/// Rasterizes points onto a grid aligned with the site origin, covering the points' extent.
pub struct RasterizeSurface;

impl Stage for RasterizeSurface {
    const KIND: &'static str = "RasterizeSurface";
    const VERSION: u32 = 1;
    const DOC: &'static str = "points -> height field H_s on the site grid (max/min/mean/percentile/count per cell, class filter, bounded gap fill), Sec. 4";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "points",
        ArtifactType::Points,
        "the point set",
    )];
    type Params = RasterizeSurfaceParams;
    type Output = Raster;

    fn unit(p: &Self::Params) -> Unit {
        if p.mode == CellMode::Count {
            Unit::None
        } else {
            Unit::Is("m")
        }
    }

    /// The widest gap filled from its rim.
    fn reach_m(p: &Self::Params) -> f64 {
        p.max_gap_m
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::params::check_cell(p.cell_m)?;
        if let CellMode::Percentile(q) = p.mode
            && !(0.0..=100.0).contains(&q)
        {
            return Err(ParamError::new(
                "mode",
                format!("expected a percentile in [0, 100], found {q}"),
            ));
        }
        if !(p.max_gap_m >= 0.0 && p.max_gap_m.is_finite()) {
            return Err(ParamError::new(
                "max_gap_m",
                "expected a non-negative distance in metres",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let all: &PointSet = inputs.one("points")?;
        let cell = p.cell_m.unwrap_or(ctx.site.cell_m);
        let keep = |c: u8| {
            p.classes.as_ref().is_none_or(|k| k.contains(&c)) && !p.exclude_classes.contains(&c)
        };
        let filtered;
        let points = if all.class.is_empty() || all.class.iter().all(|&c| keep(c)) {
            all
        } else {
            filtered = select(all, |i| keep(all.class[i]));
            &filtered
        };
        let (lo, hi) = points.bounds().ok_or_else(|| {
            StageError::Failed(
                "no points to rasterize (the set is empty, or every point was filtered out by class)".into(),
            )
        })?;
        let grid = Grid::covering_checked(
            (lo[0] as f64, lo[1] as f64),
            (hi[0] as f64, hi[1] as f64),
            cell,
        )
        .map_err(|m| {
            StageError::Param(ParamError::new(
                "cell_m",
                format!("{m}; use a coarser cell"),
            ))
        })?;
        let mut r = rasterize(points, grid, p.mode);
        let steps = (p.max_gap_m / cell).floor() as u32;
        if steps > 0 && p.mode != CellMode::Count {
            fill_gaps(&mut r, steps);
        }
        Ok(r)
    }
}

/// The points for which `keep(index)` holds, with all their attributes.
pub fn select(p: &PointSet, keep: impl Fn(usize) -> bool) -> PointSet {
    let idx: Vec<usize> = (0..p.len()).filter(|&i| keep(i)).collect();
    fn pick<T: bytemuck::Pod>(v: &[T], idx: &[usize]) -> crate::artifact::PodVec<T> {
        if v.is_empty() {
            Default::default()
        } else {
            crate::artifact::PodVec(idx.iter().map(|&i| v[i]).collect())
        }
    }
    PointSet {
        xyz: pick(&p.xyz, &idx),
        class: pick(&p.class, &idx),
        intensity: pick(&p.intensity, &idx),
        return_number: pick(&p.return_number, &idx),
        number_of_returns: pick(&p.number_of_returns, &idx),
        rgb: pick(&p.rgb, &idx),
    }
}

/// Combines the points of each cell of `grid` with `mode`; cells without points are NaN
/// (0 for `Count`). Points outside the grid are ignored.
pub fn rasterize(points: &PointSet, grid: Grid, mode: CellMode) -> Raster {
    if let CellMode::Percentile(q) = mode {
        return rasterize_percentile(points, grid, q);
    }
    let n = grid.len();
    let mut acc = vec![0f64; n];
    let mut count = vec![0u32; n];
    for q in points.xyz.iter() {
        let Some((c, r)) = grid.cell_of(q[0] as f64, q[1] as f64) else {
            continue;
        };
        let i = r as usize * grid.width as usize + c as usize;
        let z = q[2] as f64;
        acc[i] = match (mode, count[i]) {
            (CellMode::Count, _) => 0.0,
            (_, 0) => z,
            (CellMode::Max, _) => acc[i].max(z),
            (CellMode::Min, _) => acc[i].min(z),
            (CellMode::Mean, _) => acc[i] + z,
            (CellMode::Percentile(_), _) => unreachable!("handled by rasterize_percentile"),
        };
        count[i] += 1;
    }
    let data = acc
        .iter()
        .zip(&count)
        .map(|(&a, &k)| match (mode, k) {
            (CellMode::Count, k) => k as f32,
            (_, 0) => f32::NAN,
            (CellMode::Mean, k) => (a / k as f64) as f32,
            _ => a as f32,
        })
        .collect();
    Raster {
        grid,
        data: PodVec(data),
    }
}

/// Per-cell percentile `q` of z (linear between closest ranks, as numpy's default): points are
/// sorted by (cell, z) once, then each cell's run is read off.
fn rasterize_percentile(points: &PointSet, grid: Grid, q: f64) -> Raster {
    let mut keyed: Vec<(u32, f32)> = points
        .xyz
        .iter()
        .filter_map(|p| {
            grid.cell_of(p[0] as f64, p[1] as f64)
                .map(|(c, r)| (r * grid.width + c, p[2]))
        })
        .collect();
    keyed.par_sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut data = vec![f32::NAN; grid.len()];
    for run in keyed.chunk_by(|a, b| a.0 == b.0) {
        let pos = q / 100.0 * (run.len() - 1) as f64;
        let (lo, t) = (pos.floor() as usize, pos.fract());
        let hi = (lo + 1).min(run.len() - 1);
        data[run[0].0 as usize] = (run[lo].1 as f64 * (1.0 - t) + run[hi].1 as f64 * t) as f32;
    }
    Raster {
        grid,
        data: PodVec(data),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_min_mean_count_on_known_points() {
        let pts = PointSet {
            xyz: PodVec(vec![[0.2, 0.2, 1.0], [0.7, 0.3, 3.0], [1.5, 0.5, 5.0]]),
            ..Default::default()
        };
        let g = Grid::covering((0.2, 0.2), (1.5, 0.5), 1.0);
        assert_eq!((g.x0, g.y0, g.width, g.height), (0.0, 1.0, 2, 1));
        assert_eq!(rasterize(&pts, g, CellMode::Max).data.0, vec![3.0, 5.0]);
        assert_eq!(rasterize(&pts, g, CellMode::Min).data.0, vec![1.0, 5.0]);
        assert_eq!(rasterize(&pts, g, CellMode::Mean).data.0, vec![2.0, 5.0]);
        assert_eq!(rasterize(&pts, g, CellMode::Count).data.0, vec![2.0, 1.0]);
        assert_eq!(
            rasterize(&pts, g, CellMode::Percentile(50.0)).data.0,
            vec![2.0, 5.0]
        );
        assert_eq!(
            rasterize(&pts, g, CellMode::Percentile(25.0)).data.0,
            vec![1.5, 5.0]
        );
    }

    #[test]
    fn class_filter_keeps_only_the_chosen_classes_and_drops_noise() {
        use crate::site::Site;
        use crate::stage::Slot;
        let pts = PointSet {
            xyz: PodVec(vec![
                [0.5, 0.5, 1.0],
                [0.6, 0.5, 30.0],
                [0.7, 0.5, -50.0],
                [1.5, 0.5, 2.0],
            ]),
            class: PodVec(vec![2, 6, 7, 2]),
            ..Default::default()
        };
        let inputs = Inputs::new().with(
            "points",
            Slot::One(std::sync::Arc::new(crate::Artifact::Points(pts))),
        );
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        let run = |classes: Option<Vec<u8>>, mode| {
            let p = RasterizeSurfaceParams {
                mode,
                cell_m: None,
                classes,
                exclude_classes: vec![7, 18],
                max_gap_m: 0.0,
            };
            RasterizeSurface::run(&p, &inputs, &Ctx::new(&site, &[]))
                .unwrap()
                .data
                .0
        };
        assert_eq!(
            run(Some(vec![2]), CellMode::Max),
            vec![1.0, 2.0],
            "ground only"
        );
        assert_eq!(run(None, CellMode::Max), vec![30.0, 2.0], "all but noise");
        assert_eq!(
            run(None, CellMode::Min),
            vec![1.0, 2.0],
            "the noise point at -50 m is dropped"
        );
    }

    #[test]
    fn out_of_range_values_are_rejected() {
        let p = |mode, max_gap_m| RasterizeSurfaceParams {
            mode,
            cell_m: None,
            classes: None,
            exclude_classes: vec![],
            max_gap_m,
        };
        assert_eq!(
            RasterizeSurface::validate(&p(CellMode::Percentile(120.0), 0.0))
                .unwrap_err()
                .field,
            "mode"
        );
        assert_eq!(
            RasterizeSurface::validate(&p(CellMode::Max, -1.0))
                .unwrap_err()
                .field,
            "max_gap_m"
        );
        assert!(RasterizeSurface::validate(&p(CellMode::Percentile(5.0), 2.0)).is_ok());
    }

    #[test]
    fn gaps_fill_only_up_to_the_bound() {
        let grid = Grid {
            x0: 0.0,
            y0: 1.0,
            cell_m: 1.0,
            width: 7,
            height: 1,
        };
        let mut r = Raster {
            grid,
            data: PodVec(vec![
                1.0,
                f32::NAN,
                f32::NAN,
                f32::NAN,
                f32::NAN,
                f32::NAN,
                3.0,
            ]),
        };
        fill_gaps(&mut r, 2);
        assert_eq!(&r.data[..3], &[1.0, 1.0, 1.0]);
        assert!(
            r.data[3].is_nan(),
            "the middle of a 5-cell gap is 3 cells from data"
        );
        assert_eq!(&r.data[4..], &[3.0, 3.0, 3.0]);
    }
}
