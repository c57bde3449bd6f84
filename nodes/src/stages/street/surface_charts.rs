//! SurfaceCharts: the texel grids Sec. 4.2 writes into, one planar chart per wall segment and roof
//! facet of every building of a scene.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, ChartSet, Scene};
use crate::geom::charts::{ChartSpec, building_charts};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`SurfaceCharts`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurfaceChartsParams {
    /// Texel edge on façades, metres. Default 0.1 (windows and their frames resolve).
    pub wall_texel_m: f64,
    /// Texel edge on roofs, in plan, metres. Default 0.25.
    pub roof_texel_m: f64,
    /// Faces sharing an edge join one chart when their normals differ by less than this, degrees.
    /// Default 1.
    pub max_bend_deg: f64,
    /// The most texels over all charts. Default 2 x 10^8 (about 1.6 GB of layers per f64 layer
    /// during fusion): a texel size typed too small fails here, not in the allocator.
    pub max_texels: u64,
}

impl Default for SurfaceChartsParams {
    fn default() -> Self {
        let s = ChartSpec::default();
        SurfaceChartsParams {
            wall_texel_m: s.wall_texel_m,
            roof_texel_m: s.roof_texel_m,
            max_bend_deg: s.max_bend_deg,
            max_texels: s.max_texels,
        }
    }
}

/// Planar charts with texel grids on every building of a scene.
pub struct SurfaceCharts;

impl Stage for SurfaceCharts {
    const KIND: &'static str = "SurfaceCharts";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "planar charts (wall segments, roof facets) with texel grids on every building, Sec. 4.2";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "scene",
        ArtifactType::Scene,
        "the scene whose Building objects get charts",
    )];
    type Params = SurfaceChartsParams;
    type Output = ChartSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v) in [
            ("wall_texel_m", p.wall_texel_m),
            ("roof_texel_m", p.roof_texel_m),
        ] {
            if !(v >= 0.01 && v <= 10.0) {
                return Err(ParamError::new(
                    name,
                    "expected a texel size in [0.01, 10] metres",
                ));
            }
        }
        if !(p.max_bend_deg >= 0.0 && p.max_bend_deg < 45.0) {
            return Err(ParamError::new(
                "max_bend_deg",
                "expected an angle in [0, 45) degrees",
            ));
        }
        // Texels are indexed by u32 in the fusion and in every stored layer.
        if p.max_texels == 0 || p.max_texels > u32::MAX as u64 {
            return Err(ParamError::new(
                "max_texels",
                "expected a positive count of at most 4294967295",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<ChartSet, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let spec = ChartSpec {
            wall_texel_m: p.wall_texel_m,
            roof_texel_m: p.roof_texel_m,
            max_bend_deg: p.max_bend_deg,
            max_texels: p.max_texels,
            ..ChartSpec::default()
        };
        building_charts(scene, &spec)
            .map_err(|m| StageError::Param(ParamError::new("wall_texel_m", m)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_texels_is_refused_past_what_a_texel_index_holds() {
        let with = |max_texels| SurfaceChartsParams {
            max_texels,
            ..Default::default()
        };
        assert!(SurfaceCharts::validate(&with(u32::MAX as u64)).is_ok());
        for bad in [0, u32::MAX as u64 + 1, u64::MAX] {
            assert!(SurfaceCharts::validate(&with(bad)).is_err(), "{bad}");
        }
    }
}
