//! FlatGround: a level terrain at a stated height, for sites with no open DEM (the Duke campus):
//! the ground a scene needs for its ground reflection, said out loud rather than left out.

use serde::{Deserialize, Serialize};

use crate::artifact::{Grid, PodVec, Raster};
use crate::io::crs::LonLatBox;
use crate::params::check_window;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// Params of [`FlatGround`]: the extent as `window` (site metres) or `lonlat` (degrees), one of
/// the two.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlatGroundParams {
    /// (x_min, y_min, x_max, y_max) in site metres.
    #[serde(default)]
    pub window: Option<(f64, f64, f64, f64)>,
    /// A box in WGS 84 degrees, `(west: .., south: .., east: .., north: ..)`; the ground covers the
    /// site-frame rectangle holding it.
    #[serde(default)]
    pub lonlat: Option<LonLatBox>,
    /// Cell size, metres. Default 10 (a flat ground needs no finer cell; the scene's terrain mesh
    /// has two triangles per cell).
    #[serde(default = "ten")]
    pub cell_m: f64,
    /// Height of the ground, metres in the site's vertical datum. Default 0.
    #[serde(default)]
    pub z_m: f64,
}

fn ten() -> f64 {
    10.0
}

/// A raster of one height over the box, on the site-aligned grid of `cell_m` cells covering it.
pub struct FlatGround;

impl Stage for FlatGround {
    const KIND: &'static str = "FlatGround";
    const VERSION: u32 = 1;
    const DOC: &'static str = "a level terrain at a stated height over a box (site metres or lat/lon), for sites without an open DEM";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = FlatGroundParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("m")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        check_window(p.window)?;
        if let Some(b) = &p.lonlat {
            b.check().map_err(|m| ParamError::new("lonlat", m))?;
        }
        if p.window.is_some() == p.lonlat.is_some() {
            return Err(ParamError::new(
                "window",
                "expected the extent as `window: (x_min, y_min, x_max, y_max)` in site metres or \
                 as `lonlat: (west: .., south: .., east: .., north: ..)`, one of the two",
            ));
        }
        if !(p.cell_m > 0.0 && p.cell_m.is_finite()) {
            return Err(ParamError::new(
                "cell_m",
                "expected a positive, finite cell size in metres",
            ));
        }
        if !(p.z_m.is_finite() && p.z_m.abs() <= 1e4) {
            return Err(ParamError::new(
                "z_m",
                format!("expected a height within ±10 km, found {}", p.z_m),
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let window = match (p.window, &p.lonlat) {
            (Some(w), _) => w,
            (None, Some(b)) => b.site_window(ctx.site).map_err(StageError::Failed)?,
            (None, None) => unreachable!("validate asks for one of window and lonlat"),
        };
        flat_ground(window, p.cell_m, p.z_m).map_err(StageError::Failed)
    }
}

/// `z` everywhere on the grid of `cell_m` cells covering `window`.
pub fn flat_ground(window: (f64, f64, f64, f64), cell_m: f64, z: f64) -> Result<Raster, String> {
    let grid: Grid = Grid::covering_checked((window.0, window.1), (window.2, window.3), cell_m)?;
    Ok(Raster {
        grid,
        data: PodVec(vec![z as f32; grid.len()]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::Site;

    fn params(window: Option<(f64, f64, f64, f64)>, lonlat: Option<LonLatBox>) -> FlatGroundParams {
        FlatGroundParams {
            window,
            lonlat,
            cell_m: 10.0,
            z_m: 2.5,
        }
    }

    #[test]
    fn the_ground_covers_the_window_at_its_height() {
        let r = flat_ground((-95.0, 0.0, 100.0, 50.0), 10.0, 2.5).unwrap();
        let g = r.grid;
        assert!(
            g.x0 <= -95.0 && g.x0 + g.width as f64 * 10.0 >= 100.0,
            "{g:?}"
        );
        assert!(
            g.y0 >= 50.0 && g.y0 - g.height as f64 * 10.0 <= 0.0,
            "{g:?}"
        );
        assert!(r.data.0.iter().all(|&z| z == 2.5));
    }

    #[test]
    fn one_extent_exactly() {
        let b = LonLatBox {
            west: -78.95,
            south: 35.99,
            east: -78.93,
            north: 36.01,
        };
        assert!(FlatGround::validate(&params(Some((0.0, 0.0, 1.0, 1.0)), None)).is_ok());
        assert!(FlatGround::validate(&params(None, Some(b))).is_ok());
        assert!(FlatGround::validate(&params(None, None)).is_err());
        assert!(FlatGround::validate(&params(Some((0.0, 0.0, 1.0, 1.0)), Some(b))).is_err());
        let swapped = LonLatBox {
            south: 36.01,
            north: 35.99,
            ..b
        };
        assert!(FlatGround::validate(&params(None, Some(swapped))).is_err());
        let mut p = params(Some((0.0, 0.0, 1.0, 1.0)), None);
        p.z_m = f64::NAN;
        assert!(FlatGround::validate(&p).is_err());
    }

    /// The Duke pci_EF box, its OSM `<bounds>` projected: pyproj 3.7 (edges sampled as here) gives
    /// (-1328.23, 507.94, -307.23, 1528.90) from the site origin (687000, 3985000), EPSG:32617.
    #[test]
    fn a_lonlat_box_lands_where_pyproj_puts_it() {
        let site = Site {
            crs: "EPSG:32617".into(),
            origin: (687000.0, 3985000.0),
            cell_m: 1.0,
        };
        let b = LonLatBox {
            west: -78.9399,
            south: 35.996366,
            east: -78.928809,
            north: 36.005378,
        };
        let (x0, y0, x1, y1) = b.site_window(&site).unwrap();
        for (got, want) in [(x0, -1328.23), (y0, 507.94), (x1, -307.23), (y1, 1528.90)] {
            assert!(
                (got - want).abs() < 0.01,
                "{:?} vs {want}",
                (x0, y0, x1, y1)
            );
        }
    }
}
