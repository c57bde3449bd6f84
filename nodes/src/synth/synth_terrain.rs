//! Seeded synthetic terrain: a sloped plane plus fractal value noise.

use rayon::prelude::*;

use crate::artifact::{Grid, PodVec, Raster, TerrainModel, height_at};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// A seeded terrain height field: the ground truth that synthetic sensors sample.
pub struct SynthTerrain;

impl Stage for SynthTerrain {
    const KIND: &'static str = "SynthTerrain";
    const VERSION: u32 = 1;
    const DOC: &'static str = "seeded synthetic terrain: sloped plane plus fractal value noise";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = TerrainModel;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("m")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.size_m.0 > 0.0 && p.size_m.1 > 0.0) {
            return Err(ParamError::new(
                "size_m",
                "expected a positive extent in metres",
            ));
        }
        crate::params::check_cell(p.cell_m)?;
        if !(p.wavelength_m > 0.0) {
            return Err(ParamError::new(
                "wavelength_m",
                "expected a positive wavelength in metres",
            ));
        }
        if p.octaves > 16 {
            return Err(ParamError::new("octaves", "expected at most 16 octaves"));
        }
        Ok(())
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let cell = p.cell_m.unwrap_or(ctx.site.cell_m);
        let (w, h) = ((p.size_m.0 / cell).ceil(), (p.size_m.1 / cell).ceil());
        if w * h > 400e6 {
            return Err(StageError::Param(ParamError::new(
                "size_m",
                format!("{w} x {h} cells is too many; use a coarser cell"),
            )));
        }
        // The extent starts at the site origin (south-west corner) and runs east and north.
        let grid = Grid {
            x0: 0.0,
            y0: h * cell,
            cell_m: cell,
            width: w as u32,
            height: h as u32,
        };
        let cells = grid.len();
        ctx.progress.set_total(grid.height as u64);
        let mut data = vec![0f32; cells];
        data.par_chunks_mut(grid.width as usize)
            .enumerate()
            .for_each(|(row, out)| {
                for (col, z) in out.iter_mut().enumerate() {
                    let (x, y) = grid.center(col as u32, row as u32);
                    *z = height_at(p, x, y) as f32;
                }
                ctx.progress.advance(1);
            });
        Ok(Raster {
            grid,
            data: PodVec(data),
        })
    }
}
