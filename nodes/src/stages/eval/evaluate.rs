//! Scoring predicted path loss against measurements (rf.md §6): point-to-point error (mean, RMSE,
//! standard deviation), and the power-distance (floating intercept) and close-in trend lines fitted
//! to a model's predictions, with the RMSE of the measurements about each line. When the
//! transmitters' EIRP is unknown one offset per transmitter is fitted first. LOS and NLOS links
//! are also scored apart when the predictions say which is which.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Measurements, Metrics, Raster};
use crate::artifact::{link_distance, measured_loss};
use crate::rf::em::fspl_db;
use crate::rf::pathloss_fit::{fit_close_in, fit_power_distance};
use crate::stage::{Ctx, InputSpec, Inputs, Stage, StageError};

/// Params of [`Evaluate`].
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvaluateParams {
    /// Fit one offset per transmitter (EIRP unknown). Default: when the measurements are received
    /// powers without EIRP.
    pub fit_offsets: Option<bool>,
    /// The model's predictions are its own trend line (3GPP), rather than a line fitted to them.
    /// Default false.
    pub model_is_trend: bool,
    /// The receiver's floor as a path loss, dB: a prediction beyond it (or no path at all) is
    /// scored as the floor, the most loss the measurements could have shown, so every model is
    /// scored on the same links. Default none: predictions are taken as they are and links a
    /// model finds no path for are left out of its scores (`links_no_path`).
    pub floor_db: Option<f64>,
}

/// Point-to-point statistics of errors e_i = predicted − measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct P2p {
    /// Mean error, dB.
    pub me: f64,
    /// Root mean square error, dB.
    pub rmse: f64,
    /// Standard deviation, sqrt(RMSE² − ME²), dB.
    pub std: f64,
}

/// ME, RMSE and σ of `errors`.
pub fn p2p(errors: &[f64]) -> P2p {
    let n = errors.len() as f64;
    let me = errors.iter().sum::<f64>() / n;
    let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    P2p {
        me,
        rmse,
        std: (rmse * rmse - me * me).max(0.0).sqrt(),
    }
}

/// Scores one model's predictions against the measurements of the same links.
pub struct Evaluate;

impl Stage for Evaluate {
    const KIND: &'static str = "Evaluate";
    const VERSION: u32 = 2;
    const DOC: &'static str = "P2P error, power-distance and close-in trend RMSE of predictions against measurements (per-tx offsets when EIRP is unknown; LOS/NLOS)";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "predictions",
            ArtifactType::Measurements,
            "predicted path loss per link (Trace, Tr38901)",
        ),
        InputSpec::one(
            "measurements",
            ArtifactType::Measurements,
            "the measured links, in the same order",
        ),
        InputSpec::optional(
            "terrain",
            ArtifactType::Raster,
            "the terrain, for heights above ground in distances",
        ),
    ];
    type Params = EvaluateParams;
    type Output = Metrics;

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Metrics, StageError> {
        let pred: &Measurements = inputs.one("predictions")?;
        let meas: &Measurements = inputs.one("measurements")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        if pred.links.len() != meas.links.len() {
            return Err(StageError::Failed(format!(
                "{} predictions for {} measured links: predict the measurements' own links",
                pred.links.len(),
                meas.links.len()
            )));
        }
        let fit_offsets = p.fit_offsets.unwrap_or_else(|| {
            meas.links
                .iter()
                .any(|l| l.path_loss_db.is_none() && l.tx_eirp_dbm.is_none())
        });
        let mut links = scored_links(p, pred, meas, terrain);
        let mut m = Metrics::default();
        set_link_counts(&mut m, p, pred, meas, links.len());
        if links.is_empty() {
            return Ok(m);
        }
        if fit_offsets {
            take_out_tx_offsets(&mut m, &mut links);
        }
        set_per_tx_p2p(&mut m, &links);
        // All links, then those the predictions call LOS, then NLOS.
        for (prefix, want) in [("", None), ("los/", Some(true)), ("nlos/", Some(false))] {
            let group: Vec<&ScoredLink> = links
                .iter()
                .filter(|l| want.is_none() || l.los == want)
                .collect();
            if !group.is_empty() {
                set_group_metrics(&mut m, p, prefix, &group);
            }
        }
        Ok(m)
    }
}

/// A link both the model and the measurements give a path loss for.
struct ScoredLink {
    /// The transmitter's id.
    tx: String,
    /// Link distance, metres.
    distance_m: f64,
    /// Carrier frequency, Hz.
    freq_hz: f64,
    /// Predicted path loss, dB (no more than the floor, when there is one).
    predicted_db: f64,
    /// Measured path loss, dB: up to the transmitter's offset while the EIRP is unknown.
    measured_db: f64,
    /// Line of sight, by the prediction, else by the measurement.
    los: Option<bool>,
}

/// The links, in order, with a usable prediction and measurement; a prediction beyond the floor
/// is taken as the floor.
fn scored_links(
    p: &EvaluateParams,
    pred: &Measurements,
    meas: &Measurements,
    terrain: Option<&Raster>,
) -> Vec<ScoredLink> {
    let mut links = Vec::new();
    for (pl, ml) in pred.links.iter().zip(&meas.links) {
        let Some(predicted) =
            pl.path_loss_db
                .filter(|v| !v.is_nan())
                .and_then(|v| match p.floor_db {
                    Some(f) => Some(v.min(f)),
                    None => v.is_finite().then_some(v),
                })
        else {
            continue;
        };
        let Some(measured) = measured_loss(ml) else {
            continue;
        };
        links.push(ScoredLink {
            tx: ml.tx.id.clone(),
            distance_m: link_distance(ml, terrain),
            freq_hz: ml.freq_hz,
            predicted_db: predicted,
            measured_db: measured,
            los: pl.los.or(ml.los),
        });
    }
    links
}

fn set_link_counts(
    m: &mut Metrics,
    p: &EvaluateParams,
    pred: &Measurements,
    meas: &Measurements,
    scored: usize,
) {
    if let Some(f) = p.floor_db {
        m.set("floor_db", f);
    } else {
        let no_path = pred
            .links
            .iter()
            .filter(|l| l.path_loss_db.is_some_and(f64::is_infinite))
            .count();
        m.set("links_no_path", no_path as f64);
    }
    m.set("links", meas.links.len() as f64);
    m.set("links_scored", scored as f64);
}

/// Per-transmitter offsets: the mean of measured − predicted, taken out of the measurements.
fn take_out_tx_offsets(m: &mut Metrics, links: &mut [ScoredLink]) {
    let mut by_tx: BTreeMap<String, (f64, usize)> = BTreeMap::new();
    for l in links.iter() {
        let e = by_tx.entry(l.tx.clone()).or_default();
        e.0 += l.measured_db - l.predicted_db;
        e.1 += 1;
    }
    for (tx, (sum, n)) in &by_tx {
        let off = sum / *n as f64;
        m.set(format!("offset_db/{tx}"), off);
        for l in links.iter_mut().filter(|l| &l.tx == tx) {
            l.measured_db -= off;
        }
    }
}

/// Per transmitter (a cell of a drive test): P2P after its offset.
fn set_per_tx_p2p(m: &mut Metrics, links: &[ScoredLink]) {
    let mut per_tx: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for l in links {
        per_tx
            .entry(l.tx.as_str())
            .or_default()
            .push(l.predicted_db - l.measured_db);
    }
    if per_tx.len() > 1 {
        for (tx, e) in &per_tx {
            let s = p2p(e);
            m.set(format!("tx/{tx}/n"), e.len() as f64);
            m.set(format!("tx/{tx}/p2p_rmse_db"), s.rmse);
            m.set(format!("tx/{tx}/p2p_std_db"), s.std);
        }
    }
}

/// P2P and trend-line metrics of one group of links, named `<prefix><metric>`.
fn set_group_metrics(m: &mut Metrics, p: &EvaluateParams, prefix: &str, group: &[&ScoredLink]) {
    let d: Vec<f64> = group.iter().map(|l| l.distance_m).collect();
    let f: Vec<f64> = group.iter().map(|l| l.freq_hz).collect();
    let pr: Vec<f64> = group.iter().map(|l| l.predicted_db).collect();
    let ms: Vec<f64> = group.iter().map(|l| l.measured_db).collect();
    let errors: Vec<f64> = pr.iter().zip(&ms).map(|(p, m)| p - m).collect();
    let s = p2p(&errors);
    m.set(format!("{prefix}n"), group.len() as f64);
    m.set(format!("{prefix}p2p_me_db"), s.me);
    m.set(format!("{prefix}p2p_rmse_db"), s.rmse);
    m.set(format!("{prefix}p2p_std_db"), s.std);
    if p.model_is_trend {
        m.set(format!("{prefix}pd_rmse_db"), s.rmse);
        m.set(format!("{prefix}ci_rmse_db"), s.rmse);
    } else {
        set_fitted_trends(m, prefix, &d, &f, &pr, &ms);
    }
}

/// The power-distance and close-in lines fitted to the predictions `pr`, and the RMSE of the
/// measurements `ms` about each.
fn set_fitted_trends(m: &mut Metrics, prefix: &str, d: &[f64], f: &[f64], pr: &[f64], ms: &[f64]) {
    let (alpha, beta) = fit_power_distance(d, pr);
    m.set(format!("{prefix}pd_alpha_db"), alpha);
    m.set(format!("{prefix}pd_beta"), beta);
    m.set(
        format!("{prefix}pd_rmse_db"),
        rms_about(ms, |i| alpha + 10.0 * beta * d[i].log10()),
    );
    let n = fit_close_in(d, pr, f);
    m.set(format!("{prefix}ci_n"), n);
    m.set(
        format!("{prefix}ci_rmse_db"),
        rms_about(ms, |i| fspl_db(1.0, f[i]) + 10.0 * n * d[i].log10()),
    );
}

/// The RMS of `values` about `line`, which gives the value at each index.
fn rms_about(values: &[f64], line: impl Fn(usize) -> f64) -> f64 {
    (values
        .iter()
        .enumerate()
        .map(|(i, v)| (v - line(i)).powi(2))
        .sum::<f64>()
        / values.len() as f64)
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-computed: errors 1, -1, 3 -> ME 1, RMSE sqrt(11/3), std sqrt(11/3 - 1).
    #[test]
    fn p2p_by_hand() {
        let s = p2p(&[1.0, -1.0, 3.0]);
        assert!((s.me - 1.0).abs() < 1e-12);
        assert!((s.rmse - (11.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((s.std - (8.0f64 / 3.0).sqrt()).abs() < 1e-12);
    }

    /// Points exactly on PL = 40 + 10 * 3 log10 d are fitted back; the close-in exponent of
    /// exact free-space points is 2.
    #[test]
    fn trend_fits_recover_their_lines() {
        let d = [10.0, 30.0, 100.0, 400.0];
        let pl: Vec<f64> = d.iter().map(|d: &f64| 40.0 + 30.0 * d.log10()).collect();
        let (a, b) = fit_power_distance(&d, &pl);
        assert!(
            (a - 40.0).abs() < 1e-9 && (b - 3.0).abs() < 1e-12,
            "{a} {b}"
        );
        let f = [3.5e9; 4];
        let fs: Vec<f64> = d.iter().map(|d| fspl_db(*d, 3.5e9)).collect();
        assert!((fit_close_in(&d, &fs, &f) - 2.0).abs() < 1e-9);
        // By hand: A = (1, 3), D = (10, 20) -> n = (10 + 60) / (100 + 400) = 0.14.
        let pl2 = [fspl_db(1.0, 3.5e9) + 1.0, fspl_db(1.0, 3.5e9) + 3.0];
        assert!((fit_close_in(&[10.0, 100.0], &pl2, &[3.5e9; 2]) - 0.14).abs() < 1e-12);
    }
}
