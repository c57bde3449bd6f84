//! Point sets onto the site grid as a height field H_s (paper Sec. 4: one field per source, ⊥ where
//! the source observed nothing).

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Grid, PodVec, PointSet, Raster};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// How the points falling into one cell become its value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum CellMode {
    /// Highest z: a digital surface model.
    Max,
    /// Lowest z: a first ground estimate.
    Min,
    /// Mean z.
    Mean,
    /// Number of points (0 where empty, never no-data).
    Count,
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
}

/// Rasterizes points onto a grid aligned with the site origin, covering the points' extent.
pub struct RasterizeSurface;

impl Stage for RasterizeSurface {
    const KIND: &'static str = "RasterizeSurface";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "points -> height field H_s on the site grid (max/min/mean/count per cell), Sec. 4";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "points",
        ArtifactType::Points,
        "the point set",
    )];
    type Params = RasterizeSurfaceParams;
    type Output = Raster;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        match p.cell_m {
            Some(c) if !(c > 0.0) => Err(ParamError::new(
                "cell_m",
                "expected a positive cell size in metres",
            )),
            _ => Ok(()),
        }
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let points: &PointSet = inputs.one("points")?;
        let cell = p.cell_m.unwrap_or(ctx.site.cell_m);
        let (lo, hi) = points.bounds().ok_or_else(|| {
            StageError::Failed("the point set is empty: nothing to rasterize".into())
        })?;
        let grid = Grid::covering(
            (lo[0] as f64, lo[1] as f64),
            (hi[0] as f64, hi[1] as f64),
            cell,
        );
        if grid.len() > 400_000_000 {
            return Err(StageError::Param(ParamError::new(
                "cell_m",
                format!(
                    "{} x {} cells at {cell} m is too many; use a coarser cell",
                    grid.width, grid.height
                ),
            )));
        }
        Ok(rasterize(points, grid, p.mode))
    }
}

/// Combines the points of each cell of `grid` with `mode`; cells without points are NaN
/// (0 for `Count`). Points outside the grid are ignored.
pub fn rasterize(points: &PointSet, grid: Grid, mode: CellMode) -> Raster {
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
    }
}
