//! Summary statistics of a point set: a quick check, and numbers tests assert on.

use crate::artifact::{ArtifactType, Metrics, PointSet};
use crate::params::NoParams;
use crate::stage::{Ctx, InputSpec, Inputs, Stage, StageError};

/// Point count, extent and the ASPRS class histogram (`class_<n>`).
pub struct PointStats;

impl Stage for PointStats {
    const KIND: &'static str = "PointStats";
    const VERSION: u32 = 1;
    const DOC: &'static str = "point set summary: count, extent, class histogram";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "points",
        ArtifactType::Points,
        "the point set",
    )];
    type Params = NoParams;
    type Output = Metrics;

    fn run(_: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Metrics, StageError> {
        let p: &PointSet = inputs.one("points")?;
        let mut m = Metrics::default();
        m.set("count", p.len() as f64);
        if let Some((lo, hi)) = p.bounds() {
            for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                m.set(format!("{axis}_min"), lo[k] as f64);
                m.set(format!("{axis}_max"), hi[k] as f64);
            }
        }
        let mut hist = [0u64; 256];
        for &c in p.class.iter() {
            hist[c as usize] += 1;
        }
        for (c, &k) in hist.iter().enumerate().filter(|(_, k)| **k > 0) {
            m.set(format!("class_{c}"), k as f64);
        }
        Ok(m)
    }
}
