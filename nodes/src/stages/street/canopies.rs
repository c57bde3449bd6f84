//! Canopies (paper Sec. 4.2.4): foliage volumes from the unassigned above-ground field: large,
//! elevated, irregular regions (height roughness, or the share of multiple returns where points
//! are given) as closed envelopes of `Material::Foliage`, which the tracer attenuates through with
//! ITU-R P.833's specific attenuation (rf/foliage.rs).

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PointSet, Raster, Scene};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};
use crate::street::canopy::{CanopyConfig, canopies};

/// Params of [`Canopies`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CanopiesParams {
    /// Cells lower than this above ground are not canopy, metres. Default 1.5.
    pub min_height_m: f64,
    /// Regions smaller than this are not canopy, m². Default 8.
    pub min_area_m2: f64,
    /// Regions lower than this at their highest are not canopy, metres. Default 4.
    pub min_top_m: f64,
    /// Height standard deviation that makes a region irregular, metres. Default 0.3.
    pub min_roughness_m: f64,
    /// Share of multiple-return points that makes a region irregular. Default 0.2.
    pub min_multi_share: f64,
    /// Height slices per envelope. Default 8.
    pub slices: u32,
    /// Outline simplification tolerance, metres. Default 0.3.
    pub simplify_m: f64,
    /// Lowest crown bottom above ground, metres. Default 1.
    pub min_clearance_m: f64,
    /// Quantile of the field on a region's outline taken as the crown's widest level when no
    /// points are given (with points the returns tell it). Default 0.4.
    pub edge_quantile: f64,
    /// Radius of the morphological closing of each crown's cells, in cells: fills the notches at
    /// the rim where a cell's few pulses all missed the crown. Default 1.
    pub close_cells: u32,
    /// How far, in cells, a crown grows into the cells `unassigned` leaves out beside it (the
    /// fringe UnassignedAbove keeps from buildings), through cells with vegetation returns; with
    /// points only. Default 2 (UnassignedAbove's 1 m at 0.5 m cells).
    pub fringe_cells: u32,
}

impl Default for CanopiesParams {
    fn default() -> Self {
        let c = CanopyConfig::default();
        CanopiesParams {
            min_height_m: c.min_height_m,
            min_area_m2: c.min_area_m2,
            min_top_m: c.min_top_m,
            min_roughness_m: c.min_roughness_m,
            min_multi_share: c.min_multi_share,
            slices: c.slices,
            simplify_m: c.simplify_m,
            min_clearance_m: c.min_clearance_m,
            edge_quantile: c.edge_quantile,
            close_cells: c.close_cells,
            fringe_cells: c.fringe_cells,
        }
    }
}

impl CanopiesParams {
    /// The extraction's configuration.
    pub fn config(&self) -> CanopyConfig {
        CanopyConfig {
            min_height_m: self.min_height_m,
            min_area_m2: self.min_area_m2,
            min_top_m: self.min_top_m,
            min_roughness_m: self.min_roughness_m,
            min_multi_share: self.min_multi_share,
            slices: self.slices,
            simplify_m: self.simplify_m,
            min_clearance_m: self.min_clearance_m,
            edge_quantile: self.edge_quantile,
            close_cells: self.close_cells,
            fringe_cells: self.fringe_cells,
        }
    }
}

/// Canopy envelopes from the unassigned above-ground field.
pub struct Canopies;

impl Stage for Canopies {
    const KIND: &'static str = "Canopies";
    // 3: the widest level and the lower surface from the LiDAR returns; the crown's cells closed;
    // crowns grown into the fringe through cells with vegetation returns.
    const VERSION: u32 = 3;
    const DOC: &'static str = "canopy envelopes (closed foliage volumes) from large, elevated, irregular unassigned above-ground regions, Sec. 4.2.4";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "unassigned",
            ArtifactType::Raster,
            "above-ground heights no building claims (UnassignedAbove)",
        ),
        InputSpec::one("terrain", ArtifactType::Raster, "the terrain T"),
        InputSpec::optional(
            "points",
            ArtifactType::Points,
            "the LiDAR returns: the share of multiple returns, the crowns' widest level and lower surface",
        ),
    ];
    type Params = CanopiesParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v, lo, hi) in [
            ("min_height_m", p.min_height_m, 0.0, 100.0),
            ("min_area_m2", p.min_area_m2, 0.0, 1e6),
            ("min_top_m", p.min_top_m, 0.0, 200.0),
            ("min_roughness_m", p.min_roughness_m, 0.0, 100.0),
            ("min_multi_share", p.min_multi_share, 0.0, 1.0),
            ("simplify_m", p.simplify_m, 0.0, 10.0),
            ("min_clearance_m", p.min_clearance_m, 0.0, 100.0),
            ("edge_quantile", p.edge_quantile, 0.0, 1.0),
        ] {
            if !(v >= lo && v <= hi) {
                return Err(ParamError::new(
                    name,
                    format!("expected a finite value in [{lo}, {hi}]"),
                ));
            }
        }
        if p.close_cells > 8 {
            return Err(ParamError::new("close_cells", "expected 0 to 8 cells"));
        }
        if p.fringe_cells > 16 {
            return Err(ParamError::new("fringe_cells", "expected 0 to 16 cells"));
        }
        if !(1..=64).contains(&p.slices) {
            return Err(ParamError::new("slices", "expected 1 to 64 slices"));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Scene, StageError> {
        let unassigned: &Raster = inputs.one("unassigned")?;
        let terrain: &Raster = inputs.one("terrain")?;
        let points: Option<&PointSet> = inputs.optional("points")?;
        if terrain.grid.is_empty() {
            return Err(StageError::Failed("the terrain raster is empty".into()));
        }
        Ok(canopies(unassigned, terrain, points, &p.config()).0)
    }
}
