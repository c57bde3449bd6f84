//! A tiled run's rasters into one mosaic: each cell from the tile whose core holds its centre.

use crate::artifact::{ArtifactType, Grid, PodVec, Raster};
use crate::site::MergeTilesParams;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// The mosaic over the union of the tiles' cores, on the tiles' cell lattice; a cell no tile
/// covers is no-data.
pub struct MergeRasters;

impl Stage for MergeRasters {
    const KIND: &'static str = "MergeRasters";
    const VERSION: u32 = 1;
    const DOC: &'static str = "a tiled run's rasters into one mosaic, each cell from the tile whose core holds its centre (added by the engine)";
    const INPUTS: &'static [InputSpec] = &[InputSpec::many(
        "tiles",
        ArtifactType::Raster,
        "each tile's raster, in the order of `tiles`",
    )];
    type Params = MergeTilesParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::SameAs("tiles")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.validate().map_err(|(f, m)| ParamError::new(f, m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let parts: Vec<&Raster> = inputs.many("tiles")?;
        p.check_inputs(parts.len()).map_err(StageError::Failed)?;
        let Some(first) = parts.first() else {
            return Err(StageError::Failed("no tiles to merge".into()));
        };
        let cell = first.grid.cell_m;
        if let Some((t, r)) = p
            .tiles
            .iter()
            .zip(&parts)
            .find(|(_, r)| r.grid.cell_m != cell)
        {
            return Err(StageError::Failed(format!(
                "tile {} has cells of {} m where the others have {cell} m",
                t.name, r.grid.cell_m
            )));
        }
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for t in &p.tiles {
            lo = (lo.0.min(t.core.min.0), lo.1.min(t.core.min.1));
            hi = (hi.0.max(t.core.max.0), hi.1.max(t.core.max.1));
        }
        // Cells whose centres lie in the union's bounds: the cores' edges are on the lattice when
        // the tiling's are (the engine checks it), so no cell is split between two tiles.
        let grid = Grid::covering_checked(
            (lo.0 + cell / 2.0, lo.1 + cell / 2.0),
            (hi.0 - cell / 2.0, hi.1 - cell / 2.0),
            cell,
        )
        .map_err(StageError::Failed)?;
        ctx.progress.set_total(grid.height as u64);
        let mut data = vec![f32::NAN; grid.len()];
        for (row, out) in data.chunks_mut(grid.width as usize).enumerate() {
            for (col, v) in out.iter_mut().enumerate() {
                let (x, y) = grid.center(col as u32, row as u32);
                if let Some(t) = p.owner(x, y)
                    && let Some((c, r)) = parts[t].grid.cell_of(x, y)
                {
                    *v = parts[t].at(c, r);
                }
            }
            ctx.progress.advance(1);
        }
        Ok(Raster {
            grid,
            data: PodVec(data),
        })
    }
}
