//! Summary statistics of a raster: a quick check, and the numbers tests assert on (the RMSE of a
//! difference raster).

use crate::artifact::{ArtifactType, Metrics, Raster};
use crate::params::NoParams;
use crate::stage::{Ctx, InputSpec, Inputs, Stage, StageError};

/// Cell count, valid count, min, max, mean, standard deviation and root mean square of the valid
/// cells.
pub struct RasterStats;

impl Stage for RasterStats {
    const KIND: &'static str = "RasterStats";
    const VERSION: u32 = 2;
    const DOC: &'static str = "raster summary: cells, valid cells, min, max, mean, std, rms";
    const INPUTS: &'static [InputSpec] =
        &[InputSpec::one("raster", ArtifactType::Raster, "the raster")];
    type Params = NoParams;
    type Output = Metrics;

    fn run(_: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Metrics, StageError> {
        let r: &Raster = inputs.one("raster")?;
        Ok(raster_stats(r))
    }
}

/// The statistics [`RasterStats`] reports. Sums run sequentially in f64 so the result does not
/// depend on thread count.
pub fn raster_stats(r: &Raster) -> Metrics {
    let (mut n, mut sum, mut sum2) = (0u64, 0f64, 0f64);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in r.data.iter().filter(|v| v.is_finite()) {
        let v = v as f64;
        n += 1;
        sum += v;
        sum2 += v * v;
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let mut m = Metrics::default();
    m.set("cells", r.data.len() as f64);
    m.set("width", r.grid.width as f64);
    m.set("height", r.grid.height as f64);
    m.set("cell_m", r.grid.cell_m);
    m.set("valid", n as f64);
    if n > 0 {
        let mean = sum / n as f64;
        m.set("min", lo);
        m.set("max", hi);
        m.set("mean", mean);
        m.set("std", (sum2 / n as f64 - mean * mean).max(0.0).sqrt());
        // Of a difference raster, the RMSE.
        m.set("rms", (sum2 / n as f64).sqrt());
    }
    m
}
