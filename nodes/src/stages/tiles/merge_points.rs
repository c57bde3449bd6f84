//! A tiled run's point sets into one: each point from the tile whose core holds it.

use crate::artifact::{ArtifactType, PointSet};
use crate::site::MergeTilesParams;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Keeps each tile's points that lie in its core, tile by tile in the params' order.
pub struct MergePoints;

impl Stage for MergePoints {
    const KIND: &'static str = "MergePoints";
    const VERSION: u32 = 1;
    const DOC: &'static str = "a tiled run's point sets into one, each point from the tile whose core holds it (added by the engine)";
    const INPUTS: &'static [InputSpec] = &[InputSpec::many(
        "tiles",
        ArtifactType::Points,
        "each tile's points, in the order of `tiles`",
    )];
    type Params = MergeTilesParams;
    type Output = PointSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.validate().map_err(|(f, m)| ParamError::new(f, m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, _ctx: &Ctx) -> Result<PointSet, StageError> {
        let parts: Vec<&PointSet> = inputs.many("tiles")?;
        p.check_inputs(parts.len()).map_err(StageError::Failed)?;
        let mut out = PointSet::default();
        for (tile, ps) in p.tiles.iter().zip(parts) {
            let keep: Vec<usize> = (0..ps.len())
                .filter(|&i| {
                    let [x, y, _] = ps.xyz[i];
                    tile.core.contains(x as f64, y as f64)
                })
                .collect();
            out.append_selected(ps, &keep)
                .map_err(|m| StageError::Failed(format!("tile {}: {m}", tile.name)))?;
        }
        Ok(out)
    }
}
