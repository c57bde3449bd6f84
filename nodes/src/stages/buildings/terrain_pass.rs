//! Terrain estimation by iterative low-elevation sampling (paper Sec. 4.1, eq. (1)), and the
//! above-ground field A = max(H - T, 0).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Grid, PodVec, Raster};
use crate::raster::blur::gaussian_blur;
use crate::raster::gap_fill::fill_gaps;
use crate::raster::normal::normal_z;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError, Unit};

/// Params of [`TerrainPass`] (the symbols of eq. (1)).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TerrainPassParams {
    /// Coarse cell size of this pass, metres.
    pub coarse_m: f64,
    /// q_k: the percentile of each coarse cell's samples taken as its ground level.
    pub percentile: f64,
    /// n_min: samples whose surface normal has a smaller vertical component are discarded.
    pub n_min: f64,
    /// tau_k: a fine hit within this height of the interpolated estimate is accepted, metres.
    pub tau_m: f64,
    /// sigma_k: the final Gaussian smoothing, metres.
    pub sigma_m: f64,
    /// Coarse cells with fewer samples take the previous estimate (or their neighbours'). Default 4.
    #[serde(default = "default_min_samples")]
    pub min_samples: u32,
}

fn default_min_samples() -> u32 {
    4
}

/// One pass k of eq. (1): T_k = G_sigma_k * [chi_k h_k + (1 - chi_k) U(T̄_k)].
pub struct TerrainPass;

impl Stage for TerrainPass {
    const KIND: &'static str = "TerrainPass";
    // 2: coarse cells on the site frame's lattice of coarse_m, not the surface raster's corner,
    // so tiles of a tiled run (and any crop) see the same coarse cells.
    const VERSION: u32 = 2;
    const DOC: &'static str = "terrain pass k: percentile of low, level samples per coarse cell, acceptance within tau, Gaussian, eq. (1)";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("surface", ArtifactType::Raster, "the height field H"),
        InputSpec::optional(
            "previous",
            ArtifactType::Raster,
            "the previous pass's terrain T_(k-1)",
        ),
    ];
    type Params = TerrainPassParams;
    type Output = Raster;

    fn unit(_p: &Self::Params) -> Unit {
        Unit::Is("m")
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.coarse_m > 0.0) {
            return Err(ParamError::new(
                "coarse_m",
                "expected a positive cell size in metres",
            ));
        }
        if !(0.0..=100.0).contains(&p.percentile) {
            return Err(ParamError::new(
                "percentile",
                "expected a percentile in [0, 100]",
            ));
        }
        if !(0.0..=1.0).contains(&p.n_min) {
            return Err(ParamError::new(
                "n_min",
                "expected a normal component in [0, 1]",
            ));
        }
        if !(p.tau_m >= 0.0) {
            return Err(ParamError::new(
                "tau_m",
                "expected a non-negative tolerance in metres",
            ));
        }
        if !(p.sigma_m >= 0.0) {
            return Err(ParamError::new(
                "sigma_m",
                "expected a non-negative sigma in metres",
            ));
        }
        Ok(())
    }

    /// Two coarse cells (a percentile's cell and the bilinear interpolation reaching into its
    /// neighbour) plus the final Gaussian's 3 sigma.
    fn reach_m(p: &Self::Params) -> f64 {
        2.0 * p.coarse_m + 3.0 * p.sigma_m
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Raster, StageError> {
        let h: &Raster = inputs.one("surface")?;
        let previous: Option<&Raster> = inputs.optional("previous")?;
        ctx.progress.set_total(3);
        let coarse = coarse_estimate(h, previous, p).ok_or_else(|| {
            StageError::Failed("the surface has no level samples to estimate terrain from".into())
        })?;
        ctx.progress.advance(1);
        let combined = combine(h, &coarse, p.tau_m);
        ctx.progress.advance(1);
        let t = gaussian_blur(&combined, p.sigma_m, false);
        ctx.progress.advance(1);
        Ok(t)
    }
}

/// T̄_k on the coarse grid: the q_k-th percentile of each coarse cell's level samples (those with
/// n_z >= n_min and, when there is a previous pass, no higher than T_(k-1) + tau_k). Cells with too
/// few samples (under large buildings) are interpolated harmonically from the cells around them:
/// finer evidence nearby beats the coarser previous pass, which is only used when no cell has any.
fn coarse_estimate(h: &Raster, previous: Option<&Raster>, p: &TerrainPassParams) -> Option<Raster> {
    let g = h.grid;
    let k = (p.coarse_m / g.cell_m).round().max(1.0) as u32;
    // Coarse cells on the site frame's lattice of k fine cells: (off_c, off_r) fine cells of
    // padding west and north of the raster, so a crop of the surface sees the same coarse cells.
    let ck = g.cell_m * k as f64;
    let fine_index = |v: f64| (v / g.cell_m).round() as i64;
    let off_c = fine_index(g.x0).rem_euclid(k as i64) as u32;
    let off_r = (-fine_index(g.y0)).rem_euclid(k as i64) as u32;
    let cg = Grid {
        x0: g.x0 - off_c as f64 * g.cell_m,
        y0: g.y0 + off_r as f64 * g.cell_m,
        cell_m: ck,
        width: (g.width + off_c).div_ceil(k),
        height: (g.height + off_r).div_ceil(k),
    };
    let nz = normal_z(h);
    let prev_at = |x: f64, y: f64| {
        previous
            .and_then(|t| t.grid.cell_of(x, y).map(|(c, r)| t.at(c, r)))
            .filter(|v| v.is_finite())
    };
    let data: Vec<f32> = (0..cg.len())
        .into_par_iter()
        .map(|ci| {
            let (cc, cr) = (ci as u32 % cg.width, ci as u32 / cg.width);
            let mut z = Vec::new();
            let fine = |cell: u32, off: u32, n: u32| {
                (cell * k).saturating_sub(off)..((cell + 1) * k).saturating_sub(off).min(n)
            };
            for r in fine(cr, off_r, g.height) {
                for c in fine(cc, off_c, g.width) {
                    let i = (r * g.width + c) as usize;
                    let v = h.data[i];
                    let (x, y) = g.center(c, r);
                    let prev = prev_at(x, y);
                    let level = nz[i] >= p.n_min as f32;
                    let low = prev.is_none_or(|t| v <= t + p.tau_m as f32);
                    if v.is_finite() && level && low {
                        z.push(v);
                    }
                }
            }
            if z.len() >= p.min_samples as usize {
                z.sort_unstable_by(f32::total_cmp);
                let pos = p.percentile / 100.0 * (z.len() - 1) as f64;
                let (lo, t) = (pos.floor() as usize, pos.fract());
                let hi = (lo + 1).min(z.len() - 1);
                (z[lo] as f64 * (1.0 - t) + z[hi] as f64 * t) as f32
            } else {
                f32::NAN
            }
        })
        .collect();
    let mut coarse = Raster {
        grid: cg,
        data: PodVec(data),
    };
    if coarse.data.iter().all(|v| !v.is_finite()) {
        // Nothing level and low enough anywhere: keep the previous estimate, if there is one.
        let prev = previous?;
        for (i, v) in coarse.data.iter_mut().enumerate() {
            let (x, y) = cg.center(i as u32 % cg.width, i as u32 / cg.width);
            *v = prev.bilinear(x, y).unwrap_or(f64::NAN) as f32;
        }
        if coarse.data.iter().all(|v| !v.is_finite()) {
            return None;
        }
    }
    let unknown: Vec<bool> = coarse.data.iter().map(|v| !v.is_finite()).collect();
    // A first guess grown in from the rim, then harmonic interpolation of the empty cells (under
    // large buildings): the Laplace equation reproduces a sloping plane exactly, where averaging
    // inward from the rim would leave terraces of slope x distance.
    while coarse.data.iter().any(|v| !v.is_finite()) {
        fill_gaps(&mut coarse, cg.width.max(cg.height));
    }
    harmonic_fill(&mut coarse, &unknown);
    Some(coarse)
}

/// Jacobi relaxation of the Laplace equation over the cells marked `unknown`, the others held
/// fixed; neighbours outside the grid are left out (a free boundary).
fn harmonic_fill(r: &mut Raster, unknown: &[bool]) {
    let (w, h) = (r.grid.width as i64, r.grid.height as i64);
    if !unknown.iter().any(|u| *u) {
        return;
    }
    for _ in 0..5000 {
        let src = r.data.clone();
        let mut change = 0f32;
        for i in (0..src.len()).filter(|&i| unknown[i]) {
            let (c, row) = (i as i64 % w, i as i64 / w);
            let (mut sum, mut n) = (0.0f64, 0u32);
            for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let (cc, rr) = (c + dc, row + dr);
                if cc >= 0 && rr >= 0 && cc < w && rr < h {
                    sum += src[(rr * w + cc) as usize] as f64;
                    n += 1;
                }
            }
            let v = (sum / n as f64) as f32;
            change = change.max((v - src[i]).abs());
            r.data[i] = v;
        }
        if change < 1e-4 {
            break;
        }
    }
}

/// chi_k h_k + (1 - chi_k) U(T̄_k): the fine hit where it lies within tau_k of the upsampled
/// estimate, the estimate elsewhere (and wherever nothing was observed).
fn combine(h: &Raster, coarse: &Raster, tau_m: f64) -> Raster {
    let g = h.grid;
    let data = (0..g.len())
        .into_par_iter()
        .map(|i| {
            let (c, r) = (i as u32 % g.width, i as u32 / g.width);
            let (x, y) = g.center(c, r);
            let u = coarse.bilinear(x, y).unwrap_or(f64::NAN);
            let v = h.data[i] as f64;
            if v.is_finite() && v <= u + tau_m {
                v as f32
            } else {
                u as f32
            }
        })
        .collect();
    Raster {
        grid: g,
        data: PodVec(data),
    }
}
