//! Scoring predicted path loss against measurements (rf.md §6): point-to-point error (mean, RMSE,
//! standard deviation), and the power-distance (floating intercept) and close-in trend lines fitted
//! to a model's predictions, with the RMSE of the measurements about each line; and the same lines
//! fitted to the measurements, with the RMSE between the model's line and the measured one. When
//! the transmitters' EIRP is unknown one offset per transmitter is fitted first.
//!
//! LOS and NLOS rows group the links the same way for every model: by the measurement's own LOS
//! flag where it has one, else by a stated reference trace (`los_reference`), never by the model
//! being scored. Predictions clamped at the floor count in P2P (as the floor) but not in the trend
//! fits, where they would drag the line towards the floor; they are counted.

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
    // 3: LOS/NLOS from the measurements or a reference, never the model; floor-clamped links out
    // of the trend fits; lines fitted to the measurements too.
    // 4: links_unpredicted counts measured links the model gave no number for (NaN or none).
    const VERSION: u32 = 4;
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
        InputSpec::optional(
            "los_reference",
            ArtifactType::Measurements,
            "a trace of the same links through one stated reference scene: its LOS flags group \
             the links whose measurement has none (give every model's Evaluate the same one)",
        ),
    ];
    type Params = EvaluateParams;
    type Output = Metrics;

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Metrics, StageError> {
        let pred: &Measurements = inputs.one("predictions")?;
        let meas: &Measurements = inputs.one("measurements")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        let reference: Option<&Measurements> = inputs.optional("los_reference")?;
        for (what, m) in [("predictions", Some(pred)), ("los_reference", reference)] {
            if let Some(m) = m
                && m.links.len() != meas.links.len()
            {
                return Err(StageError::Failed(format!(
                    "{} {what} links for {} measured links: trace the measurements' own links",
                    m.links.len(),
                    meas.links.len()
                )));
            }
        }
        let fit_offsets = p.fit_offsets.unwrap_or_else(|| {
            meas.links
                .iter()
                .any(|l| l.path_loss_db.is_none() && l.tx_eirp_dbm.is_none())
        });
        let mut links = scored_links(p, pred, meas, reference, terrain);
        let mut m = Metrics::default();
        set_link_counts(&mut m, p, pred, meas, links.len());
        set_los_sources(&mut m, meas, reference);
        if links.is_empty() {
            return Ok(m);
        }
        if fit_offsets {
            take_out_tx_offsets(&mut m, &mut links);
        }
        set_per_tx_p2p(&mut m, &links);
        // All links, then LOS, then NLOS.
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
    /// The prediction was beyond the floor (or no path) and is scored as the floor.
    at_floor: bool,
    /// Measured path loss, dB: up to the transmitter's offset while the EIRP is unknown.
    measured_db: f64,
    /// Line of sight, by the measurement, else by the reference trace.
    los: Option<bool>,
}

/// The links, in order, with a usable prediction and measurement; a prediction beyond the floor
/// is taken as the floor.
fn scored_links(
    p: &EvaluateParams,
    pred: &Measurements,
    meas: &Measurements,
    reference: Option<&Measurements>,
    terrain: Option<&Raster>,
) -> Vec<ScoredLink> {
    let mut links = Vec::new();
    for (i, (pl, ml)) in pred.links.iter().zip(&meas.links).enumerate() {
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
        let at_floor = p
            .floor_db
            .is_some_and(|f| pl.path_loss_db.is_some_and(|v| v >= f));
        links.push(ScoredLink {
            tx: ml.tx.id.clone(),
            distance_m: link_distance(ml, terrain),
            freq_hz: ml.freq_hz,
            predicted_db: predicted,
            at_floor,
            measured_db: measured,
            los: ml.los.or_else(|| reference.and_then(|r| r.links[i].los)),
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
    // Measured links the model says nothing about (no value, or NaN) are left out of every score;
    // counted, so a model that fails where it is hard cannot look better for it.
    let unpredicted = pred
        .links
        .iter()
        .zip(&meas.links)
        .filter(|(pl, ml)| {
            measured_loss(ml).is_some() && !pl.path_loss_db.is_some_and(|v| !v.is_nan())
        })
        .count();
    m.set("links_unpredicted", unpredicted as f64);
}

/// Where the LOS/NLOS grouping came from: how many links the measurements label, how many the
/// reference trace, how many neither (those count only in the all-links rows).
fn set_los_sources(m: &mut Metrics, meas: &Measurements, reference: Option<&Measurements>) {
    let (mut own, mut by_reference) = (0usize, 0usize);
    for (i, l) in meas.links.iter().enumerate() {
        if l.los.is_some() {
            own += 1;
        } else if reference.is_some_and(|r| r.links[i].los.is_some()) {
            by_reference += 1;
        }
    }
    m.set("los_source/measurements", own as f64);
    m.set("los_source/reference", by_reference as f64);
    m.set(
        "los_source/unknown",
        (meas.links.len() - own - by_reference) as f64,
    );
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
    // Trend lines from the links whose prediction is a prediction, not the floor.
    let fit: Vec<usize> = (0..group.len()).filter(|&i| !group[i].at_floor).collect();
    m.set(
        format!("{prefix}floor_clamped"),
        (group.len() - fit.len()) as f64,
    );
    let pick = |v: &[f64]| -> Vec<f64> { fit.iter().map(|&i| v[i]).collect() };
    let (d, f, pr, ms) = (pick(&d), pick(&f), pick(&pr), pick(&ms));
    let distinct = d
        .iter()
        .any(|x| (x - d[0]).abs() > 1e-9 * d[0].abs().max(1.0));
    if d.len() < 2 || !distinct {
        return;
    }
    m.set(format!("{prefix}trend_links"), d.len() as f64);
    set_trends(m, prefix, &d, &f, &pr, &ms, p.model_is_trend);
}

/// The two trend lines of rf.md §6 for one group, both ways the literature compares them:
/// `*_rmse_db`, the RMS of the measurements about the line fitted to the predictions `pr` (the
/// paper's PD and CI RMSE); `*_lines_rmse_db`, the RMS difference, over the links' distances,
/// between that line and the same line fitted to the measurements `ms`. A model that is its own
/// trend line (3GPP) is that line: its predictions stand in for the fitted one.
///
/// PD: PL = α + 10 β log10 d, least squares in (α, β). CI: PL = FSPL(f, 1 m) + 10 n log10 d,
/// least squares in n.
fn set_trends(
    m: &mut Metrics,
    prefix: &str,
    d: &[f64],
    f: &[f64],
    pr: &[f64],
    ms: &[f64],
    model_is_trend: bool,
) {
    let pd = |(a, b): (f64, f64)| move |i: usize| a + 10.0 * b * d[i].log10();
    let ci = |n: f64| move |i: usize| fspl_db(1.0, f[i]) + 10.0 * n * d[i].log10();
    let (pd_meas, ci_meas) = (fit_power_distance(d, ms), fit_close_in(d, ms, f));
    m.set(format!("{prefix}pd_beta_measured"), pd_meas.1);
    m.set(format!("{prefix}ci_n_measured"), ci_meas);
    let (model_pd, model_ci): (Box<dyn Fn(usize) -> f64>, Box<dyn Fn(usize) -> f64>) =
        if model_is_trend {
            (Box::new(|i| pr[i]), Box::new(|i| pr[i]))
        } else {
            let (alpha, beta) = fit_power_distance(d, pr);
            let n = fit_close_in(d, pr, f);
            m.set(format!("{prefix}pd_alpha_db"), alpha);
            m.set(format!("{prefix}pd_beta"), beta);
            m.set(format!("{prefix}ci_n"), n);
            (Box::new(pd((alpha, beta))), Box::new(ci(n)))
        };
    let (pd_m, ci_m) = (pd(pd_meas), ci(ci_meas));
    m.set(format!("{prefix}pd_rmse_db"), rms_about(ms, &model_pd));
    m.set(format!("{prefix}ci_rmse_db"), rms_about(ms, &model_ci));
    let lines = |a: &dyn Fn(usize) -> f64, b: &dyn Fn(usize) -> f64| {
        let diff: Vec<f64> = (0..d.len()).map(|i| a(i) - b(i)).collect();
        rms_about(&diff, |_| 0.0)
    };
    m.set(format!("{prefix}pd_lines_rmse_db"), lines(&model_pd, &pd_m));
    m.set(format!("{prefix}ci_lines_rmse_db"), lines(&model_ci, &ci_m));
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

    use crate::artifact::{Artifact, Endpoint, Height, Link};
    use crate::stage::Slot;
    use crate::{Ctx, Site};
    use std::sync::Arc;

    /// Links along x at the given distances (tx at 0, both ends at z = 0), with the given path
    /// losses and LOS flags.
    fn links(d: &[f64], pl: &[Option<f64>], los: &[Option<bool>]) -> Measurements {
        let end = |id: &str, x: f64| Endpoint {
            id: id.into(),
            x,
            y: 0.0,
            z: Height::Absolute(0.0),
            azimuth_deg: None,
        };
        Measurements {
            links: (0..d.len())
                .map(|i| Link {
                    tx: end("tx", 0.0),
                    rx: end("", d[i]),
                    freq_hz: 3.5e9,
                    path_loss_db: pl[i],
                    rx_power_dbm: None,
                    tx_eirp_dbm: None,
                    los: los[i],
                })
                .collect(),
        }
    }

    fn evaluate(
        p: &EvaluateParams,
        pred: Measurements,
        meas: Measurements,
        reference: Option<Measurements>,
    ) -> Metrics {
        let mut inputs = Inputs::new()
            .with(
                "predictions",
                Slot::One(Arc::new(Artifact::Measurements(pred))),
            )
            .with(
                "measurements",
                Slot::One(Arc::new(Artifact::Measurements(meas))),
            );
        if let Some(r) = reference {
            inputs = inputs.with(
                "los_reference",
                Slot::Optional(Some(Arc::new(Artifact::Measurements(r)))),
            );
        }
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        Evaluate::run(p, &inputs, &Ctx::new(&site, &[])).unwrap()
    }

    /// The rows group links by the measurement's flag, then the reference's; the model's own
    /// flags (here all wrong) are never used.
    #[test]
    fn los_rows_follow_the_measurements_then_the_reference() {
        let d = [10.0, 20.0, 40.0, 80.0];
        let meas = links(
            &d,
            &[Some(80.0), Some(90.0), Some(100.0), Some(110.0)],
            &[Some(true), None, Some(false), None],
        );
        let pred = links(
            &d,
            &[Some(81.0), Some(91.0), Some(101.0), Some(111.0)],
            &[Some(false), Some(false), Some(true), Some(true)],
        );
        let reference = links(&d, &[None; 4], &[Some(false), Some(true), Some(true), None]);
        let m = evaluate(
            &EvaluateParams::default(),
            pred.clone(),
            meas.clone(),
            Some(reference),
        );
        // LOS: link 0 (measured), link 1 (reference); NLOS: link 2 (measured); link 3 unknown.
        assert_eq!(
            (m.get("los/n"), m.get("nlos/n"), m.get("n")),
            (Some(2.0), Some(1.0), Some(4.0))
        );
        assert_eq!(m.get("los_source/measurements"), Some(2.0));
        assert_eq!(m.get("los_source/reference"), Some(1.0));
        assert_eq!(m.get("los_source/unknown"), Some(1.0));
        let m = evaluate(&EvaluateParams::default(), pred, meas, None);
        assert_eq!((m.get("los/n"), m.get("nlos/n")), (Some(1.0), Some(1.0)));
    }

    /// Predictions at the floor count in P2P as the floor, but the trend lines are fitted to the
    /// others: a model exactly 3 dB above the measurements keeps both lines 3 dB apart.
    #[test]
    fn floor_clamped_links_stay_out_of_the_trend_fits() {
        let d = [10.0, 20.0, 40.0, 80.0, 160.0, 320.0];
        let truth: Vec<f64> = d.iter().map(|d: &f64| 50.0 + 32.0 * d.log10()).collect();
        let meas = links(
            &d,
            &truth.iter().map(|v| Some(*v)).collect::<Vec<_>>(),
            &[None; 6],
        );
        // The last two links: no path (infinite loss) and a loss past the floor.
        let mut pl: Vec<Option<f64>> = truth.iter().map(|v| Some(v + 3.0)).collect();
        pl[4] = Some(f64::INFINITY);
        pl[5] = Some(200.0);
        let p = EvaluateParams {
            floor_db: Some(140.0),
            ..Default::default()
        };
        let m = evaluate(&p, links(&d, &pl, &[None; 6]), meas.clone(), None);
        assert_eq!(m.get("links_scored"), Some(6.0));
        assert_eq!(m.get("links_unpredicted"), Some(0.0));
        // A NaN prediction is no prediction: out of the scores, and counted.
        let mut nan = pl.clone();
        nan[0] = Some(f64::NAN);
        let m_nan = evaluate(&p, links(&d, &nan, &[None; 6]), meas.clone(), None);
        assert_eq!(m_nan.get("links_scored"), Some(5.0));
        assert_eq!(m_nan.get("links_unpredicted"), Some(1.0));
        assert_eq!(m.get("floor_clamped"), Some(2.0));
        assert_eq!(m.get("trend_links"), Some(4.0));
        let close = |k: &str, want: f64| {
            let v = m.get(k).unwrap();
            assert!((v - want).abs() < 1e-9, "{k} = {v}, want {want}");
        };
        close("pd_beta", 3.2);
        close("pd_beta_measured", 3.2);
        close("pd_rmse_db", 3.0);
        close("pd_lines_rmse_db", 3.0);
        // P2P takes the clamped links at the floor: 140 against the truth there.
        let e: Vec<f64> = (0..6)
            .map(|i| if i < 4 { 3.0 } else { 140.0 - truth[i] })
            .collect();
        close("p2p_rmse_db", p2p(&e).rmse);
    }
}
