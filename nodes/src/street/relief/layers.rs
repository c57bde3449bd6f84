//! One chart's relief layers: dense while they are made, sparse as stored.

use crate::artifact::{Chart, ChartLayers, PodVec, ReliefLayers, SparseLayer};

use super::params::ReliefParams;
use super::posterior::{ExpandedCpt, level, mesh_state_probabilities, relief_posterior};

/// The stored layers of a chart no view saw and no mesh reached (or not a wall).
pub(super) fn unobserved_layers(c: &Chart, with_mesh: bool) -> ReliefLayers {
    let n = c.len() as u32;
    let nan = SparseLayer::filled(f32::NAN, n);
    ReliefLayers {
        width: c.width,
        height: c.height,
        exposure: SparseLayer::filled(0.0, n),
        recessed: nan.clone(),
        protruding: nan.clone(),
        delta: if with_mesh {
            nan.clone()
        } else {
            SparseLayer::filled(f32::NAN, 0)
        },
        pr_recessed: nan.clone(),
        pr_protruding: nan,
    }
}

/// One chart's relief layers while they are made: dense, in raster order, with the meaning of
/// [`ReliefLayers`]' fields.
#[cfg_attr(test, derive(Clone))]
pub(super) struct DenseLayers {
    pub(super) exposure: Vec<f32>,
    pub(super) recessed: Vec<f32>,
    pub(super) protruding: Vec<f32>,
    /// Empty without a source mesh.
    pub(super) delta: Vec<f32>,
    pub(super) pr_recessed: Vec<f32>,
    pub(super) pr_protruding: Vec<f32>,
}

impl DenseLayers {
    /// `n` texels no view saw: no exposure, no evidence, no posterior.
    pub(super) fn unobserved(n: usize, with_mesh: bool) -> DenseLayers {
        DenseLayers {
            exposure: vec![0.0; n],
            recessed: vec![f32::NAN; n],
            protruding: vec![f32::NAN; n],
            // Without a source mesh the layer would be NaN throughout.
            delta: if with_mesh {
                vec![f32::NAN; n]
            } else {
                Vec::new()
            },
            pr_recessed: vec![f32::NAN; n],
            pr_protruding: vec![f32::NAN; n],
        }
    }

    /// The layers as stored: the texels that carry a value.
    pub(super) fn pack(&self, c: &Chart) -> ReliefLayers {
        let nan = |v: &[f32]| SparseLayer::from_dense(v, f32::NAN);
        ReliefLayers {
            width: c.width,
            height: c.height,
            exposure: SparseLayer::from_dense(&self.exposure, 0.0),
            recessed: nan(&self.recessed),
            protruding: nan(&self.protruding),
            delta: nan(&self.delta),
            pr_recessed: nan(&self.pr_recessed),
            pr_protruding: nan(&self.pr_protruding),
        }
    }
}

/// The posterior of eq. (4) as a pass uses it: the expanded CPT, and the one posterior of every
/// texel no view saw and the mesh did not reach.
pub(super) struct Posterior {
    cpt: ExpandedCpt,
    unseen: Option<[f64; 3]>,
}

impl Posterior {
    pub(super) fn new(p: &ReliefParams) -> Posterior {
        let cpt = p.cpt.expand();
        // Most texels of a seen chart are unseen and out of the mesh's reach: one posterior for
        // all.
        let unseen = relief_posterior(&cpt, None, mesh_state_probabilities(f64::NAN, &p.delta));
        Posterior { cpt, unseen }
    }
}

/// One wall chart's dense layers from its fused layers `l` (None: unseen but reached by the
/// mesh, Delta alone) and its Delta (`delta`, if a mesh reached it): per texel the exposure in
/// units of `w_ref`, the evidence shares R and P where observed, their levels, and the
/// posterior. With the count of observed texels.
pub(super) fn chart_layers(
    c: &Chart,
    l: Option<ChartLayers>,
    delta: Option<&Vec<f32>>,
    w_ref: f64,
    post: &Posterior,
    p: &ReliefParams,
) -> (DenseLayers, u64) {
    // Unseen but reached by the mesh: Delta alone.
    let l = l.unwrap_or_else(|| ChartLayers {
        width: c.width,
        height: c.height,
        w_exp: PodVec(vec![0.0; c.len()]),
        hits: PodVec::default(),
        votes: Vec::new(),
    });
    let votes = |k: u16| l.votes.iter().find(|(c, _)| *c == k).map(|(_, v)| v);
    let (em, ep) = (votes(0), votes(2));
    let n = c.len();
    let mut lay = DenseLayers::unobserved(n, delta.is_some());
    let mut observed = 0u64;
    for k in 0..n {
        if c.triangle_at[k] == u32::MAX {
            continue;
        }
        let wexp = l.w_exp[k] as f64;
        let e = wexp / w_ref;
        lay.exposure[k] = e as f32;
        let levels = if e >= p.exposure_min && wexp > 0.0 {
            observed += 1;
            let r = em.map_or(0.0, |v| v[k] as f64) / wexp;
            let pp = ep.map_or(0.0, |v| v[k] as f64) / wexp;
            lay.recessed[k] = r as f32;
            lay.protruding[k] = pp as f32;
            Some((level(r, p.levels), level(pp, p.levels)))
        } else {
            None
        };
        let dq = delta.map_or(f64::NAN, |d| d[k] as f64);
        if let Some(slot) = lay.delta.get_mut(k) {
            *slot = dq as f32;
        }
        let posterior = if levels.is_none() && dq.is_nan() {
            post.unseen
        } else {
            relief_posterior(&post.cpt, levels, mesh_state_probabilities(dq, &p.delta))
        };
        if let Some(y) = posterior {
            lay.pr_recessed[k] = y[0] as f32;
            lay.pr_protruding[k] = y[2] as f32;
        }
    }
    (lay, observed)
}
