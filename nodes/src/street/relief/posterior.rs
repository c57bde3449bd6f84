//! The discrete Bayesian posterior of eq. (4): the conditional probability table, the mesh
//! discrepancy Delta and Pr(d | Delta), the evidence levels, and the posterior per texel.

use std::collections::BTreeSet;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{ChartKind, ChartSet, Scene};
use crate::geom::raycast::SceneRays;

/// The displacement classes Y, in the order every probability triple uses.
pub const RELIEF_CLASSES: [&str; 3] = ["recessed", "neutral", "protruding"];

/// The conditional probability table of eq. (4), stored as the two small tables it is built
/// from (see [`Cpt::expand`]) plus optional explicit rows that replace derived ones.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Cpt {
    /// Pr(Y | R, P) from the images alone (the latent mesh state unknown): 9 triples (recessed,
    /// neutral, protruding), R level major (R = 0, P = 0..2; R = 1, ...).
    pub image: Vec<(f64, f64, f64)>,
    /// Pr(d | Y): for Y = recessed, neutral, protruding (rows) the probability that a source
    /// mesh shows the façade behind (d = in), at (flush) or in front of (out) ours.
    pub mesh: Vec<(f64, f64, f64)>,
    /// Pr(Y) where no view observed the texel (used with a mesh only).
    pub prior: (f64, f64, f64),
    /// Rows that replace derived ones: Pr(Y | d, R, P) given outright.
    pub rows: Vec<CptRow>,
}

/// One explicit row of the CPT.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CptRow {
    /// The latent mesh state.
    pub d: MeshState,
    /// Recessed evidence level (0, 1, 2).
    pub r: u8,
    /// Protruding evidence level (0, 1, 2).
    pub p: u8,
    /// Pr(Y = recessed, neutral, protruding).
    pub y: (f64, f64, f64),
}

/// The latent mesh-discrepancy state d of eq. (4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum MeshState {
    /// The source mesh lies behind our façade.
    In,
    /// It agrees with our façade.
    Flush,
    /// It stands in front of our façade.
    Out,
    /// No information (no source mesh, or none found along the normal).
    Unknown,
}

impl Default for Cpt {
    /// The defaults, and why:
    /// - `image`: a texel most of whose exposure voted recessed (R = 2, share >= the upper level)
    ///   is recessed with 0.85; some votes (R = 1) give 0.35, not enough alone (a view whose
    ///   region spilled over, or one view among many), but enough with a mesh that agrees; no
    ///   votes either way is flat with 0.94 (the wall was seen and looked flat). Conflicting
    ///   strong votes (R = P = 2, e.g. a window behind a balcony railing) split evenly between
    ///   the two relief classes. The table is symmetric in R and P.
    /// - `mesh`: a photogrammetry mesh is right about a recess 70 % of the time (it smooths
    ///   shallow relief: 25 % flush), and shows spurious relief on a flat wall 10 % of the time.
    /// - `prior`: 10 % of façade area is recessed, 10 % protruding (the synthetic city's windows
    ///   cover about 15 % of its walls), 80 % flat.
    fn default() -> Self {
        Cpt {
            image: vec![
                (0.03, 0.94, 0.03),
                (0.03, 0.62, 0.35),
                (0.03, 0.12, 0.85),
                (0.35, 0.62, 0.03),
                (0.25, 0.50, 0.25),
                (0.15, 0.25, 0.60),
                (0.85, 0.12, 0.03),
                (0.60, 0.25, 0.15),
                (0.45, 0.10, 0.45),
            ],
            mesh: vec![(0.70, 0.25, 0.05), (0.05, 0.90, 0.05), (0.05, 0.25, 0.70)],
            prior: (0.1, 0.8, 0.1),
            rows: Vec::new(),
        }
    }
}

/// The CPT expanded to every (d, R, P): Pr(Y | d, R, P), and Pr(Y | d) where unobserved.
#[derive(Clone, Debug, PartialEq)]
pub struct ExpandedCpt {
    /// `[d][r][p]` -> (recessed, neutral, protruding); d in the order In, Flush, Out, Unknown.
    pub observed: [[[[f64; 3]; 3]; 3]; 4],
    /// `[d]` -> Pr(Y | d, unobserved); `None` for Unknown (no evidence at all).
    pub unobserved: [Option<[f64; 3]>; 4],
}

fn tri(t: (f64, f64, f64)) -> [f64; 3] {
    [t.0, t.1, t.2]
}

fn normalised(y: [f64; 3]) -> [f64; 3] {
    let s: f64 = y.iter().sum();
    if s > 0.0 {
        y.map(|v| v / s)
    } else {
        [0.0, 1.0, 0.0]
    }
}

fn check_triple(t: (f64, f64, f64), what: &str) -> Result<(), String> {
    let y = tri(t);
    if y.iter().any(|v| !v.is_finite() || *v < 0.0) || (y.iter().sum::<f64>() - 1.0).abs() > 1e-6 {
        return Err(format!(
            "{what}: expected three probabilities summing to 1, got {t:?}"
        ));
    }
    Ok(())
}

fn state_index(d: MeshState) -> usize {
    match d {
        MeshState::In => 0,
        MeshState::Flush => 1,
        MeshState::Out => 2,
        MeshState::Unknown => 3,
    }
}

impl Cpt {
    /// Checks shapes and that every row is a distribution.
    pub fn validate(&self) -> Result<(), String> {
        if self.image.len() != 9 {
            return Err(format!(
                "cpt.image: expected 9 rows (R 0..2 x P 0..2), got {}",
                self.image.len()
            ));
        }
        if self.mesh.len() != 3 {
            return Err(format!(
                "cpt.mesh: expected 3 rows (Y = recessed, neutral, protruding), got {}",
                self.mesh.len()
            ));
        }
        for (k, t) in self.image.iter().enumerate() {
            check_triple(*t, &format!("cpt.image[{k}]"))?;
        }
        for (k, t) in self.mesh.iter().enumerate() {
            check_triple(*t, &format!("cpt.mesh[{k}]"))?;
        }
        check_triple(self.prior, "cpt.prior")?;
        let mut seen = BTreeSet::new();
        for (k, row) in self.rows.iter().enumerate() {
            if row.r > 2 || row.p > 2 {
                return Err(format!("cpt.rows[{k}]: levels are 0, 1 or 2"));
            }
            check_triple(row.y, &format!("cpt.rows[{k}].y"))?;
            if !seen.insert((state_index(row.d), row.r, row.p)) {
                return Err(format!(
                    "cpt.rows[{k}]: ({:?}, {}, {}) given twice",
                    row.d, row.r, row.p
                ));
            }
        }
        Ok(())
    }

    /// The full table: Pr(Y | Unknown, R, P) is `image`; for a mesh state d,
    /// Pr(Y | d, R, P) ∝ Pr(Y | R, P) Pr(d | Y) (the mesh and the views err independently given
    /// the true class); unobserved, Pr(Y | d) ∝ Pr(Y) Pr(d | Y). Explicit `rows` then replace
    /// derived entries.
    pub fn expand(&self) -> ExpandedCpt {
        let mut observed = [[[[0.0; 3]; 3]; 3]; 4];
        let mut unobserved = [None; 4];
        for (d, by_r) in observed.iter_mut().enumerate() {
            for (r, by_p) in by_r.iter_mut().enumerate() {
                for (p, row) in by_p.iter_mut().enumerate() {
                    let img = tri(self.image[r * 3 + p]);
                    *row = if d == 3 {
                        img
                    } else {
                        normalised(std::array::from_fn(|y| img[y] * tri(self.mesh[y])[d]))
                    };
                }
            }
            if d < 3 {
                let prior = tri(self.prior);
                unobserved[d] = Some(normalised(std::array::from_fn(|y| {
                    prior[y] * tri(self.mesh[y])[d]
                })));
            }
        }
        for row in &self.rows {
            observed[state_index(row.d)][row.r as usize][row.p as usize] = tri(row.y);
        }
        ExpandedCpt {
            observed,
            unobserved,
        }
    }
}

/// How the source mesh's discrepancy Delta becomes Pr(d | Delta).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeltaParams {
    /// |Delta| at which in (or out) and flush are equally likely, metres.
    pub tau_m: f64,
    /// Width of the logistic transition, metres (the mesh's noise).
    pub scale_m: f64,
    /// Weight of the mesh: Pr(d = Unknown | Delta) = 1 - trust.
    pub trust: f64,
    /// How far along the normal to look for the mesh, each way, metres.
    pub search_m: f64,
}

impl Default for DeltaParams {
    fn default() -> Self {
        DeltaParams {
            tau_m: 0.1,
            scale_m: 0.03,
            trust: 0.8,
            search_m: 1.0,
        }
    }
}

/// Pr(d | Delta) over (In, Flush, Out, Unknown): logistic in Delta around ±tau, scaled by the
/// mesh's trust; all Unknown when Delta is not finite (no mesh there).
pub fn mesh_state_probabilities(delta: f64, p: &DeltaParams) -> [f64; 4] {
    if !delta.is_finite() {
        return [0.0, 0.0, 0.0, 1.0];
    }
    let s = |x: f64| 1.0 / (1.0 + (-x / p.scale_m).exp());
    let pin = s(-delta - p.tau_m);
    let pout = s(delta - p.tau_m);
    let flush = (1.0 - pin - pout).max(0.0);
    let t = p.trust;
    [t * pin, t * flush, t * pout, 1.0 - t]
}

/// Eq. (4), discrete Bayesian fusion of the evidence e_q = (R_q, P_q, Delta_q):
///
/// Pr(Y_q = y | e_q) = Σ_d Pr(Y_q = y | d, R_q, P_q) Pr(d | Delta_q),
///
/// with `levels` the discretised (R, P), `None` where the texel is unobserved, and `pd` =
/// Pr(d | Delta) over (In, Flush, Out, Unknown). Returns (recessed, neutral, protruding), or
/// `None` where there is no evidence at all (unobserved and no mesh): an unobserved texel is
/// never evidence for a flat wall.
pub fn relief_posterior(
    cpt: &ExpandedCpt,
    levels: Option<(u8, u8)>,
    pd: [f64; 4],
) -> Option<[f64; 3]> {
    let mut y = [0.0; 3];
    let mut mass = 0.0;
    for (d, w) in pd.iter().enumerate() {
        if *w <= 0.0 {
            continue;
        }
        let row = match levels {
            Some((r, p)) => cpt.observed[d][r.min(2) as usize][p.min(2) as usize],
            None => match cpt.unobserved[d] {
                Some(row) => row,
                None => continue,
            },
        };
        for k in 0..3 {
            y[k] += w * row[k];
        }
        mass += w;
    }
    // Unobserved, the Unknown state carries no row: what remains is conditioned on the mesh.
    (mass > 0.0).then(|| y.map(|v| v / mass))
}

/// Discretises an evidence share into levels 0, 1, 2 at the two thresholds.
pub fn level(share: f64, levels: (f64, f64)) -> u8 {
    if share >= levels.1 {
        2
    } else if share >= levels.0 {
        1
    } else {
        0
    }
}

/// Delta_q on every wall texel: the signed distance from our façade to the source mesh along
/// the outward normal (positive: the mesh stands in front), found by casting from `search_m` in
/// front of the texel back through it to the first mesh face that faces the same way (within
/// 45 degrees: the ground and the sides of openings are passed through); NaN where there is none
/// within `search_m` either way.
pub fn mesh_delta(charts: &ChartSet, mesh: &Scene, search_m: f64) -> Vec<Vec<f32>> {
    let rays = SceneRays::new(mesh);
    charts
        .charts
        .par_iter()
        .with_max_len(1)
        .map(|c| {
            if c.kind != ChartKind::Wall {
                return Vec::new();
            }
            let mut out = vec![f32::NAN; c.len()];
            let dir = c.normal.map(|v| -v as f32);
            for j in 0..c.height {
                for i in 0..c.width {
                    let k = (j * c.width + i) as usize;
                    if c.triangle_at[k] == u32::MAX {
                        continue;
                    }
                    let x = c.texel_center(i, j);
                    let o: [f32; 3] =
                        std::array::from_fn(|a| (x[a] + c.normal[a] * search_m) as f32);
                    // The first surface facing the way the wall does (not the ground, not a
                    // side face): up to four tries past what is not.
                    let mut tmin = 0.0f32;
                    for _ in 0..4 {
                        let Some(hit) = rays.cast(o, dir, tmin, (2.0 * search_m) as f32) else {
                            break;
                        };
                        let facing: f64 = (0..3).map(|a| hit.normal[a] as f64 * c.normal[a]).sum();
                        if facing >= 0.7 {
                            out[k] = (search_m - hit.t as f64) as f32;
                            break;
                        }
                        tmin = hit.t + 1e-3;
                    }
                }
            }
            out
        })
        .collect()
}
