//! What stands above the ground but is not a building (paper Sec. 4.1: "setting unassigned
//! above-ground regions aside so we can extract foliage from them later"): trees, hedges, cars,
//! shelters. Kept as a height field for the foliage and clutter stages.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, PodVec, Raster};
use crate::raster::label::label_ids;
use crate::raster::morph::dilate;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// Params of [`UnassignedAbove`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UnassignedAboveParams {
    /// Cells lower than this above ground are ground, metres. Default 1.0.
    pub min_height_m: f64,
    /// Cells this close to a building are its walls' fringe, not candidates, metres. Default 1.0.
    pub building_gap_m: f64,
}

impl Default for UnassignedAboveParams {
    fn default() -> Self {
        UnassignedAboveParams {
            min_height_m: 1.0,
            building_gap_m: 1.0,
        }
    }
}

/// A on above-ground cells that no building claims (with a gap around buildings), NaN elsewhere.
pub struct UnassignedAbove;

impl Stage for UnassignedAbove {
    const KIND: &'static str = "UnassignedAbove";
    const VERSION: u32 = 1;
    const DOC: &'static str =
        "above-ground cells no building claims: foliage and clutter candidates, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("above", ArtifactType::Raster, "the above-ground field A"),
        InputSpec::one(
            "labels",
            ArtifactType::Raster,
            "building labels F_b on A's grid",
        ),
    ];
    type Params = UnassignedAboveParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::SameAs("above")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v) in [
            ("min_height_m", p.min_height_m),
            ("building_gap_m", p.building_gap_m),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ParamError::new(
                    name,
                    "expected a non-negative length in metres",
                ));
            }
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        let a: &Raster = inputs.one("above")?;
        let labels: &Raster = inputs.one("labels")?;
        if a.grid != labels.grid {
            return Err(StageError::Failed(
                "above and labels must share one grid".into(),
            ));
        }
        let g = a.grid;
        let building: Vec<bool> = label_ids(labels).iter().map(|&l| l > 0).collect();
        let near = dilate(
            &building,
            g.width,
            g.height,
            (p.building_gap_m / g.cell_m).round() as i64,
        );
        let data = (0..g.len())
            .map(|i| {
                let v = a.data[i];
                if !near[i] && v.is_finite() && v as f64 >= p.min_height_m {
                    v
                } else {
                    f32::NAN
                }
            })
            .collect();
        Ok(Raster {
            grid: g,
            data: PodVec(data),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Grid;
    use crate::stage::Slot;
    use crate::{Artifact, Site};
    use std::sync::Arc;

    #[test]
    fn trees_are_kept_and_buildings_with_their_fringe_are_not() {
        let grid = Grid {
            x0: 0.0,
            y0: 5.0,
            cell_m: 0.5,
            width: 10,
            height: 10,
        };
        // A building in columns 0..4, a tree at column 8, low ground elsewhere.
        let above = Raster {
            grid,
            data: PodVec(
                (0..100)
                    .map(|i| match i % 10 {
                        0..4 => 9.0,
                        4 => 9.0,
                        8 => 6.0,
                        _ => 0.2,
                    })
                    .collect(),
            ),
        };
        let labels = Raster {
            grid,
            data: PodVec(
                (0..100)
                    .map(|i| if i % 10 < 4 { 1.0 } else { 0.0 })
                    .collect(),
            ),
        };
        let inputs = Inputs::new()
            .with("above", Slot::One(Arc::new(Artifact::Raster(above))))
            .with("labels", Slot::One(Arc::new(Artifact::Raster(labels))));
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 0.5,
        };
        let out =
            UnassignedAbove::run(&Default::default(), &inputs, &Ctx::new(&site, &[])).unwrap();
        let kept: Vec<usize> = (0..10).filter(|&c| out.data[c].is_finite()).collect();
        assert_eq!(
            kept,
            vec![8],
            "the wall fringe at column 4 is left out, the tree is kept"
        );
    }
}
