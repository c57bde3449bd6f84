//! Coverage: network-planning layers of several transmitters at once (RSRP per transmitter,
//! best-server RSRP, best server, SINR, coverage above a threshold) from their path-gain maps,
//! with a stated floor; its report `stats` counts what each cell became.
//!
//! # Equations
//!
//! Per cell, for transmitter k with path gain G_k (dB, the `RadioMap` of k) and EIRP per
//! resource element EIRP_k (dBm):
//!
//! - RSRP_k = EIRP_k + G_k (dBm), the reference-signal power of one resource element.
//! - The best server is s = argmax_k RSRP_k (the lowest index on a tie); the best-server RSRP is
//!   RSRP_s.
//! - SINR = S / (Σ_{k ∈ C(s)} I_k + N), in linear mW: S = 10^(RSRP_s / 10), I_k = 10^(RSRP_k /
//!   10) for every other transmitter k whose carrier is within `co_channel_hz` of the server's
//!   (C(s), the co-channel set; full load: every interferer sends on every resource element at
//!   its reference-signal power), N = 10^(`noise_dbm` / 10). Interferers count whether or not they
//!   are above the floor: a cell's interference does not stop where the UE stops reporting.
//! - The noise default is thermal noise in one LTE resource element plus a 7 dB noise figure:
//!   -174 dBm/Hz + 10 log10(15 kHz) + 7 dB = -125.24 dBm.
//!
//! # The floor
//!
//! `floor_dbm` (default -140 dBm, the lowest RSRP a UE reports, 3GPP TS 36.133's RSRP range) is
//! where a cell stops being served: a cell whose best RSRP is below it has no server, is NaN in
//! every RSRP, best-server and SINR layer, and is 0 in `Covered`; so is a cell no ray reached
//! (NaN in every map). Both are counted, never averaged in: `cells_no_ray`, `cells_below_floor`.
//!
//! # Matching Sionna RT
//!
//! `RadioMapSolver`'s path gain is our G_k; its RSS with a transmit power of EIRP_k per resource
//! element is our RSRP_k; its SINR is ours with every transmitter co-channel and its noise power.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Grid, Metrics, PodVec, Raster, Typed};
use crate::stage::{
    Ctx, InputSpec, Inputs, ParamError, ReportSpec, Reported, Stage, StageError, Unit,
};

/// The most transmitters one Coverage node takes.
pub const MAX_TRANSMITTERS: usize = 256;

/// One transmitter of [`CoverageParams`], in the order of the `maps` input.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoverageTx {
    /// Its id (unique; names the `Rsrp` layer and the `serving_fraction/<id>` metric).
    pub id: String,
    /// EIRP of one resource element (the reference signal), dBm, in [-100, 100]: the carrier's
    /// EIRP less 10 log10 of its subcarriers (46 dBm over 1200 subcarriers: 15.2 dBm). With the
    /// input `offsets`, what is added to the fitted EIRP (default 0).
    #[serde(default)]
    pub eirp_dbm: f64,
    /// Carrier frequency, Hz (> 0): which transmitters interfere (`co_channel_hz`).
    pub freq_hz: f64,
}

/// Which layer a [`Coverage`] node outputs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum CoverageLayer {
    /// The best server's RSRP, dBm; NaN below the floor or where no ray arrived.
    BestRsrp,
    /// The best server's index in `transmitters` (0..n-1, as f32); NaN where no server.
    BestServer,
    /// The best server's SINR, dB; NaN where no server.
    Sinr,
    /// 1 where the best RSRP is at least this threshold (dBm) and the floor, else 0.
    Covered(f64),
    /// The RSRP of the transmitter with this id, dBm; NaN where its own is below the floor or no
    /// ray of it arrived.
    Rsrp(String),
}

/// Params of [`Coverage`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoverageParams {
    /// The transmitters, one per map of `maps`, in the same order.
    pub transmitters: Vec<CoverageTx>,
    /// The layer to output.
    pub layer: CoverageLayer,
    /// Noise per resource element, dBm, in [-200, 0]. Default: -174 dBm/Hz + 10 log10(15 kHz) +
    /// 7 dB noise figure = -125.24 dBm.
    #[serde(default)]
    pub noise_dbm: Option<f64>,
    /// The UE's reporting floor, dBm, in [-250, 0]: a cell whose best RSRP is below it is not
    /// covered. Default -140.
    #[serde(default = "floor")]
    pub floor_dbm: f64,
    /// Interferers are the other transmitters whose carrier is within this of the server's, Hz,
    /// in [0, 1e10]. Default 10 MHz.
    #[serde(default = "co_channel")]
    pub co_channel_hz: f64,
}

fn floor() -> f64 {
    -140.0
}
fn co_channel() -> f64 {
    10e6
}

/// Thermal noise in one 15 kHz LTE resource element with a 7 dB noise figure, dBm.
pub fn default_noise_dbm() -> f64 {
    -174.0 + 10.0 * 15e3f64.log10() + 7.0
}

impl CoverageParams {
    /// The noise per resource element, dBm.
    pub fn noise(&self) -> f64 {
        self.noise_dbm.unwrap_or_else(default_noise_dbm)
    }
}

/// RSRP, best server, SINR or coverage over the maps of several transmitters.
pub struct Coverage;

impl Stage for Coverage {
    const KIND: &'static str = "Coverage";
    // 2: the optional input `offsets` (an Evaluate's fitted offsets as each transmitter's EIRP).
    const VERSION: u32 = 2;
    const DOC: &'static str = "network-planning layer of several transmitters' path-gain maps: RSRP per transmitter, best-server RSRP, best server, SINR or coverage above a threshold, with a stated floor";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::many(
            "maps",
            ArtifactType::Raster,
            "path gain (dB, NaN where no ray arrived) of each transmitter, on one lattice (one grid, or each cut to its transmitter's reach), in the order of `transmitters` (RadioMap)",
        ),
        InputSpec::optional(
            "offsets",
            ArtifactType::Metrics,
            "an Evaluate's metrics: each transmitter's EIRP is its eirp_dbm less the offset fitted for its id (offset_db/<id>), the EIRP the measurements imply",
        ),
    ];
    type Params = CoverageParams;
    type Output = Raster;

    fn unit(p: &Self::Params) -> Unit {
        match p.layer {
            CoverageLayer::BestRsrp | CoverageLayer::Rsrp(_) => Unit::Is("dBm"),
            CoverageLayer::Sinr => Unit::Is("dB"),
            CoverageLayer::BestServer | CoverageLayer::Covered(_) => Unit::None,
        }
    }

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        validate(p)
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Raster, StageError> {
        let p = with_offsets(p, inputs.optional("offsets")?)?;
        Ok(coverage(&p, &inputs.many("maps")?)?.0)
    }

    const REPORTS: &'static [ReportSpec] = &[ReportSpec {
        name: "stats",
        ty: ArtifactType::Metrics,
        doc: "cells, cells_no_ray, cells_below_floor, cells_covered, covered_fraction and covered_km2 at the floor, covered_fraction_above_threshold (Covered), serving_fraction/<id> (of the covered cells), sinr_median_db (over the covered cells), floor_dbm, noise_dbm",
    }];

    fn run_reported(
        p: &Self::Params,
        inputs: &Inputs,
        _: &Ctx,
    ) -> Result<Reported<Raster>, StageError> {
        let p = with_offsets(p, inputs.optional("offsets")?)?;
        let (output, mut stats) = coverage(&p, &inputs.many("maps")?)?;
        for t in &p.transmitters {
            stats.set(format!("eirp_dbm/{}", t.id), t.eirp_dbm);
        }
        Ok(Reported {
            output,
            reports: vec![("stats", stats.into_artifact())],
        })
    }
}

/// The params with each transmitter's EIRP taken from fitted offsets, when given: Evaluate fits,
/// per transmitter, the mean of measured minus predicted path loss, and for RSRP readings without
/// an EIRP the measured path loss is −RSRP, so the offset is −EIRP per resource element.
fn with_offsets(
    p: &CoverageParams,
    offsets: Option<&Metrics>,
) -> Result<CoverageParams, StageError> {
    let Some(m) = offsets else {
        return Ok(p.clone());
    };
    let mut p = p.clone();
    for t in &mut p.transmitters {
        let key = format!("offset_db/{}", t.id);
        let offset = m.get(&key).filter(|v| v.is_finite()).ok_or_else(|| {
            StageError::Failed(format!(
                "offsets: no finite {key}: the evaluation fitted no offset for transmitter {:?}",
                t.id
            ))
        })?;
        t.eirp_dbm -= offset;
    }
    validate(&p).map_err(StageError::Param)?;
    Ok(p)
}

/// The params' check: counts, values and ids.
fn validate(p: &CoverageParams) -> Result<(), ParamError> {
    let n = p.transmitters.len();
    if n == 0 || n > MAX_TRANSMITTERS {
        return Err(ParamError::new(
            "transmitters",
            format!("expected 1 to {MAX_TRANSMITTERS} transmitters, got {n}"),
        ));
    }
    for (k, t) in p.transmitters.iter().enumerate() {
        let bad = |m: String| ParamError::new("transmitters", format!("#{k} ({:?}): {m}", t.id));
        if t.id.trim().is_empty() {
            return Err(bad("expected a non-empty id".into()));
        }
        if p.transmitters[..k].iter().any(|u| u.id == t.id) {
            return Err(bad("the id is given twice; ids must be unique".into()));
        }
        crate::params::check_in("eirp_dbm", t.eirp_dbm, -100.0, 100.0)
            .map_err(|(f, m)| bad(format!("{f}: {m}")))?;
        crate::params::check_in("freq_hz", t.freq_hz, 1.0, 1e12)
            .map_err(|(f, m)| bad(format!("{f}: {m}")))?;
    }
    let field = |(f, m): (&'static str, String)| ParamError::new(f, m);
    if let Some(n) = p.noise_dbm {
        crate::params::check_in("noise_dbm", n, -200.0, 0.0).map_err(field)?;
    }
    crate::params::check_in("floor_dbm", p.floor_dbm, -250.0, 0.0).map_err(field)?;
    crate::params::check_in("co_channel_hz", p.co_channel_hz, 0.0, 1e10).map_err(field)?;
    match &p.layer {
        CoverageLayer::Covered(t) => {
            crate::params::check_in("layer", *t, -250.0, 100.0).map_err(field)?
        }
        CoverageLayer::Rsrp(id) if !p.transmitters.iter().any(|t| &t.id == id) => {
            return Err(ParamError::new(
                "layer",
                format!(
                    "Rsrp({id:?}): no transmitter has that id (ids: {})",
                    ids(&p.transmitters)
                ),
            ));
        }
        _ => {}
    }
    Ok(())
}

fn ids(t: &[CoverageTx]) -> String {
    t.iter()
        .map(|t| t.id.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// dBm to mW.
fn mw(dbm: f64) -> f64 {
    10f64.powf(dbm / 10.0)
}

/// The grid covering every map of `maps` and each map's offset in it (columns, rows): the maps
/// must lie on one lattice (the same cell size, corners whole cells apart), as the maps of one
/// terrain are whether or not a reach bounds them. Maps on one grid give that grid.
fn common_lattice(
    p: &CoverageParams,
    maps: &[&Raster],
) -> Result<(Grid, Vec<(i64, i64)>), StageError> {
    let first = maps[0].grid;
    let c = first.cell_m;
    let mut offsets = Vec::with_capacity(maps.len());
    for (k, m) in maps.iter().enumerate() {
        if m.data.len() != m.grid.len() {
            return Err(StageError::Failed(format!(
                "maps #{k} has {} values for {} cells",
                m.data.len(),
                m.grid.len()
            )));
        }
        let g = m.grid;
        let (dc, dr) = ((g.x0 - first.x0) / c, (first.y0 - g.y0) / c);
        let whole = |v: f64| v.is_finite() && (v - v.round()).abs() < 1e-6;
        if g.cell_m != c || !whole(dc) || !whole(dr) {
            return Err(StageError::Failed(format!(
                "maps #{k} ({}) is on grid {g:?}, maps #0 ({}) on {first:?}: every map must lie on one lattice (the same terrain or scene, cell_m and height; a reach may cut each to its own extent)",
                p.transmitters[k].id, p.transmitters[0].id
            )));
        }
        offsets.push((dc.round() as i64, dr.round() as i64));
    }
    let (c0, r0) = offsets
        .iter()
        .fold((i64::MAX, i64::MAX), |(a, b), &(c, r)| (a.min(c), b.min(r)));
    let (c1, r1) = maps
        .iter()
        .zip(&offsets)
        .fold((i64::MIN, i64::MIN), |(a, b), (m, &(c, r))| {
            (
                a.max(c + m.grid.width as i64),
                b.max(r + m.grid.height as i64),
            )
        });
    let (width, height) = ((c1 - c0) as f64, (r1 - r0) as f64);
    crate::params::check_cells(width, height, 4).map_err(StageError::Failed)?;
    let grid = Grid {
        x0: first.x0 + c0 as f64 * c,
        y0: first.y0 - r0 as f64 * c,
        cell_m: c,
        width: width as u32,
        height: height as u32,
    };
    let offsets = offsets.iter().map(|&(c, r)| (c - c0, r - r0)).collect();
    Ok((grid, offsets))
}

/// The layer `p` asks for over `maps` (one per transmitter, on one grid) and its stats.
pub fn coverage(p: &CoverageParams, maps: &[&Raster]) -> Result<(Raster, Metrics), StageError> {
    let n = p.transmitters.len();
    if maps.len() != n {
        return Err(StageError::Param(ParamError::new(
            "transmitters",
            format!(
                "{n} transmitters ({}) for {} maps: give one transmitter per map, in the order of `maps`",
                ids(&p.transmitters),
                maps.len()
            ),
        )));
    }
    let (grid, offsets) = common_lattice(p, maps)?;
    // Map k's path gain in cell i of the union, NaN where the cell lies outside its extent (a
    // transmitter bounded by its reach neither serves nor interferes beyond it).
    let gain = |k: usize, i: usize| -> f64 {
        let (col, row) = (
            (i % grid.width as usize) as i64,
            (i / grid.width as usize) as i64,
        );
        let (c, r) = (col - offsets[k].0, row - offsets[k].1);
        let g = maps[k].grid;
        if c < 0 || r < 0 || c >= g.width as i64 || r >= g.height as i64 {
            f64::NAN
        } else {
            maps[k].at(c as u32, r as u32) as f64
        }
    };
    let noise_mw = mw(p.noise());
    let rsrp_of = match &p.layer {
        CoverageLayer::Rsrp(id) => p.transmitters.iter().position(|t| &t.id == id),
        _ => None,
    };
    let mut out = vec![f32::NAN; grid.len()];
    let (mut no_ray, mut below, mut covered, mut above) = (0u64, 0u64, 0u64, 0u64);
    let mut serving = vec![0u64; n];
    let mut sinrs: Vec<f64> = Vec::new();
    let mut rsrp = vec![f64::NAN; n];
    for (i, v) in out.iter_mut().enumerate() {
        // RSRP_k = EIRP_k + G_k; the best server the largest (first on a tie).
        let mut best: Option<usize> = None;
        for (k, t) in p.transmitters.iter().enumerate() {
            let g = gain(k, i);
            rsrp[k] = if g.is_finite() {
                t.eirp_dbm + g
            } else {
                f64::NAN
            };
            if rsrp[k].is_finite() && best.is_none_or(|b| rsrp[k] > rsrp[b]) {
                best = Some(k);
            }
        }
        let Some(s) = best else {
            no_ray += 1;
            if let CoverageLayer::Covered(_) = p.layer {
                *v = 0.0;
            }
            continue;
        };
        if rsrp[s] < p.floor_dbm {
            below += 1;
            if let CoverageLayer::Covered(_) = p.layer {
                *v = 0.0;
            }
            continue;
        }
        covered += 1;
        serving[s] += 1;
        // SINR = S / (Σ co-channel I + N), linear mW.
        let f_s = p.transmitters[s].freq_hz;
        let interference: f64 = (0..n)
            .filter(|&k| {
                k != s
                    && rsrp[k].is_finite()
                    && (p.transmitters[k].freq_hz - f_s).abs() <= p.co_channel_hz
            })
            .map(|k| mw(rsrp[k]))
            .sum();
        let sinr_db = 10.0 * (mw(rsrp[s]) / (interference + noise_mw)).log10();
        sinrs.push(sinr_db);
        let is_above = match p.layer {
            CoverageLayer::Covered(t) => rsrp[s] >= t,
            _ => false,
        };
        above += u64::from(is_above);
        *v = match p.layer {
            CoverageLayer::BestRsrp => rsrp[s] as f32,
            CoverageLayer::BestServer => s as f32,
            CoverageLayer::Sinr => sinr_db as f32,
            CoverageLayer::Covered(_) => f32::from(u8::from(is_above)),
            CoverageLayer::Rsrp(_) => {
                let k = rsrp_of.expect("validated: the id is a transmitter's");
                if rsrp[k] >= p.floor_dbm {
                    rsrp[k] as f32
                } else {
                    f32::NAN
                }
            }
        };
    }
    let cells = grid.len() as f64;
    let frac = |c: u64| if cells > 0.0 { c as f64 / cells } else { 0.0 };
    let mut m = Metrics::default();
    m.set("cells", cells);
    m.set("cells_no_ray", no_ray as f64);
    m.set("cells_below_floor", below as f64);
    m.set("cells_covered", covered as f64);
    m.set("covered_fraction", frac(covered));
    m.set(
        "covered_km2",
        covered as f64 * grid.cell_m * grid.cell_m / 1e6,
    );
    if let CoverageLayer::Covered(_) = p.layer {
        m.set("covered_fraction_above_threshold", frac(above));
    }
    for (t, c) in p.transmitters.iter().zip(&serving) {
        let share = if covered > 0 {
            *c as f64 / covered as f64
        } else {
            0.0
        };
        m.set(format!("serving_fraction/{}", t.id), share);
    }
    if let Some(med) = median(&mut sinrs) {
        m.set("sinr_median_db", med);
    }
    m.set("floor_dbm", p.floor_dbm);
    m.set("noise_dbm", p.noise());
    Ok((
        Raster {
            grid,
            data: PodVec(out),
        },
        m,
    ))
}

/// The median (the mean of the middle two of an even count); None when empty.
fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let h = v.len() / 2;
    Some(if v.len() % 2 == 1 {
        v[h]
    } else {
        (v[h - 1] + v[h]) / 2.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stage::Slot;
    use crate::{Artifact, Site};
    use std::sync::Arc;

    const NAN: f32 = f32::NAN;

    fn grid() -> Grid {
        Grid {
            x0: 0.0,
            y0: 100.0,
            cell_m: 100.0,
            width: 5,
            height: 1,
        }
    }

    fn map(g: [f32; 5]) -> Raster {
        Raster {
            grid: grid(),
            data: PodVec(g.to_vec()),
        }
    }

    /// Path gains (dB) of A, B, C over five cells: A serves cell 0, B cell 1 (a tie with C, the
    /// first listed wins), no ray reaches cell 2, cell 3's best is below the floor, C serves cell
    /// 4.
    fn maps() -> [Raster; 3] {
        [
            map([-100.0, NAN, NAN, -155.0, -130.0]),
            map([-110.0, -125.0, NAN, NAN, -120.0]),
            map([-95.0, -115.0, NAN, -150.0, -100.0]),
        ]
    }

    /// A and B 5 MHz apart (co-channel), C on another carrier; noise -120 dBm for round numbers.
    fn params(layer: CoverageLayer) -> CoverageParams {
        let tx = |id: &str, eirp_dbm, freq_hz| CoverageTx {
            id: id.into(),
            eirp_dbm,
            freq_hz,
        };
        CoverageParams {
            transmitters: vec![
                tx("A", 10.0, 3.69e9),
                tx("B", 10.0, 3.695e9),
                tx("C", 0.0, 3.56e9),
            ],
            layer,
            noise_dbm: Some(-120.0),
            floor_dbm: -140.0,
            co_channel_hz: 10e6,
        }
    }

    /// Evaluate's offsets are −EIRP: A's offset 7.5 dB on eirp_dbm 10 gives 2.5 dBm; an id the
    /// evaluation did not fit is an error naming it.
    #[test]
    fn fitted_offsets_become_each_transmitters_eirp() {
        let p = params(CoverageLayer::BestRsrp);
        let mut m = Metrics::default();
        for (id, off) in [("A", 7.5), ("B", -3.0), ("C", 0.0)] {
            m.set(format!("offset_db/{id}"), off);
        }
        let q = with_offsets(&p, Some(&m)).unwrap();
        let eirp: Vec<f64> = q.transmitters.iter().map(|t| t.eirp_dbm).collect();
        assert_eq!(eirp, [2.5, 13.0, 0.0]);
        assert_eq!(with_offsets(&p, None).unwrap(), p);
        m.values.remove("offset_db/B");
        let e = with_offsets(&p, Some(&m)).unwrap_err();
        assert!(format!("{e}").contains("offset_db/B"), "{e}");
    }

    fn run(p: &CoverageParams) -> (Vec<f32>, Metrics) {
        let m = maps();
        let (r, s) = coverage(p, &m.iter().collect::<Vec<_>>()).unwrap();
        assert_eq!(r.grid, grid());
        (r.data.0, s)
    }

    fn same(got: &[f32], want: &[f32]) {
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(want) {
            assert!(
                (g.is_nan() && w.is_nan()) || (g - w).abs() < 1e-4,
                "{got:?} vs {want:?}"
            );
        }
    }

    #[test]
    fn the_noise_default_is_thermal_noise_in_one_resource_element() {
        assert!((default_noise_dbm() - -125.2391).abs() < 1e-4);
    }

    /// RSRP = EIRP + G: A at -90 dBm in cell 0, B and C tied at -115 in cell 1 (B listed first),
    /// C at -100 in cell 4; below the floor and without a ray nothing.
    #[test]
    fn best_server_and_its_rsrp_by_hand() {
        same(
            &run(&params(CoverageLayer::BestRsrp)).0,
            &[-90.0, -115.0, NAN, NAN, -100.0],
        );
        same(
            &run(&params(CoverageLayer::BestServer)).0,
            &[0.0, 1.0, NAN, NAN, 2.0],
        );
        // A's own RSRP: no ray in cells 1 and 2, -145 dBm (below the floor) in cell 3.
        same(
            &run(&params(CoverageLayer::Rsrp("A".into()))).0,
            &[-90.0, NAN, NAN, NAN, -120.0],
        );
        same(
            &run(&params(CoverageLayer::Rsrp("C".into()))).0,
            &[-95.0, -115.0, NAN, NAN, -100.0],
        );
    }

    /// SINR = S / (Σ co-channel I + N) in mW: cell 0 has A's -90 over B's -100 (5 MHz away)
    /// plus -120 of noise; C (130 MHz away) does not count. B in cell 1 and C in cell 4 have no
    /// co-channel interferer that arrived: S / N.
    #[test]
    fn sinr_counts_only_co_channel_interferers() {
        let cell0 = 10.0 * (1e-9f64 / (1e-10 + 1e-12)).log10();
        let (sinr, stats) = run(&params(CoverageLayer::Sinr));
        same(&sinr, &[cell0 as f32, 5.0, NAN, NAN, 20.0]);
        assert!((stats.get("sinr_median_db").unwrap() - cell0).abs() < 1e-9);
        // B 5 MHz from A is not co-channel within 1 MHz: cell 0 is S / N.
        let narrow = CoverageParams {
            co_channel_hz: 1e6,
            ..params(CoverageLayer::Sinr)
        };
        same(&run(&narrow).0, &[30.0, 5.0, NAN, NAN, 20.0]);
        // Everyone co-channel: C's -100 in cell 4 over A's -120 and B's -110 plus noise.
        let wide = CoverageParams {
            co_channel_hz: 1e9,
            ..params(CoverageLayer::Sinr)
        };
        let cell4 = 10.0 * (1e-10f64 / (1e-12 + 1e-11 + 1e-12)).log10();
        let cell1 = 10.0 * (10f64.powf(-11.5) / (10f64.powf(-11.5) + 1e-12)).log10();
        same(
            &run(&wide).0,
            &[
                (10.0 * (1e-9f64 / (1e-10 + 10f64.powf(-9.5) + 1e-12)).log10()) as f32,
                cell1 as f32,
                NAN,
                NAN,
                cell4 as f32,
            ],
        );
    }

    /// The floor and the threshold: three of five cells covered at the floor (0.03 km² of
    /// 100 m cells), two at -105 dBm; a cell without a ray or below the floor is 0, not NaN.
    #[test]
    fn covered_cells_and_their_stats() {
        let (cov, s) = run(&params(CoverageLayer::Covered(-105.0)));
        same(&cov, &[1.0, 0.0, 0.0, 0.0, 1.0]);
        let want = [
            ("cells", 5.0),
            ("cells_no_ray", 1.0),
            ("cells_below_floor", 1.0),
            ("cells_covered", 3.0),
            ("covered_fraction", 0.6),
            ("covered_km2", 0.03),
            ("covered_fraction_above_threshold", 0.4),
            ("serving_fraction/A", 1.0 / 3.0),
            ("serving_fraction/B", 1.0 / 3.0),
            ("serving_fraction/C", 1.0 / 3.0),
            ("floor_dbm", -140.0),
            ("noise_dbm", -120.0),
        ];
        for (k, v) in want {
            let got = s.get(k).unwrap_or_else(|| panic!("{k} missing: {s:?}"));
            assert!((got - v).abs() < 1e-12, "{k}: {got} vs {v}");
        }
        // Only a Covered layer has a threshold.
        let (_, s) = run(&params(CoverageLayer::BestRsrp));
        assert_eq!(s.get("covered_fraction_above_threshold"), None);
        // A floor of -100 dBm leaves cells 0 and 4.
        let high = CoverageParams {
            floor_dbm: -100.0,
            ..params(CoverageLayer::BestRsrp)
        };
        let (r, s) = run(&high);
        same(&r, &[-90.0, NAN, NAN, NAN, -100.0]);
        assert_eq!(s.get("cells_below_floor"), Some(2.0));
        assert_eq!(s.get("serving_fraction/B"), Some(0.0));
    }

    /// Through the stage: the list input in order, the report beside the raster.
    #[test]
    fn the_stage_reports_its_stats() {
        let inputs = Inputs::new().with(
            "maps",
            Slot::Many(
                maps()
                    .into_iter()
                    .map(|m| Arc::new(Artifact::Raster(m)))
                    .collect(),
            ),
        );
        let site = Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        let p = params(CoverageLayer::BestServer);
        assert!(Coverage::validate(&p).is_ok());
        let r = Coverage::run_reported(&p, &inputs, &Ctx::new(&site, &[])).unwrap();
        same(&r.output.data.0, &[0.0, 1.0, NAN, NAN, 2.0]);
        assert_eq!(r.reports.len(), 1);
        assert_eq!(r.reports[0].0, "stats");
        let Artifact::Metrics(m) = &r.reports[0].1 else {
            panic!("stats is not Metrics")
        };
        assert_eq!(m.get("cells_covered"), Some(3.0));
    }

    /// Maps each cut to its transmitter's reach (RadioMap's `reach_m`) on one lattice: the
    /// layer covers their union, and a transmitter neither serves nor interferes outside its
    /// map, exactly as if its map were NaN there.
    #[test]
    fn maps_cut_to_their_reach_cover_their_union() {
        let whole = maps();
        let cut = |m: &Raster, from: u32, to: u32| Raster {
            grid: Grid {
                x0: from as f64 * 100.0,
                width: to - from,
                ..grid()
            },
            data: PodVec(m.data[from as usize..to as usize].to_vec()),
        };
        // A reaches cells 0-1, B cells 0-4, C cells 3-4; the whole maps NaN where they are cut.
        let parts = [
            cut(&whole[0], 0, 2),
            cut(&whole[1], 0, 5),
            cut(&whole[2], 3, 5),
        ];
        let mut blanked = maps();
        for (m, range) in blanked.iter_mut().zip([2..5, 5..5, 0..3]) {
            for v in &mut m.data[range] {
                *v = NAN;
            }
        }
        for layer in [
            CoverageLayer::BestRsrp,
            CoverageLayer::BestServer,
            CoverageLayer::Sinr,
        ] {
            let p = params(layer);
            let (got, _) = coverage(&p, &parts.iter().collect::<Vec<_>>()).unwrap();
            let (want, _) = coverage(&p, &blanked.iter().collect::<Vec<_>>()).unwrap();
            assert_eq!(got.grid, grid());
            same(&got.data, &want.data);
        }
        // A map off the lattice by half a cell is refused.
        let mut off = parts.clone();
        off[2].grid.x0 += 50.0;
        let e = coverage(
            &params(CoverageLayer::BestRsrp),
            &off.iter().collect::<Vec<_>>(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("maps #2 (C)") && e.contains("one lattice"),
            "{e}"
        );
    }

    #[test]
    fn maps_on_different_grids_or_counts_are_refused() {
        let mut m = maps();
        m[2].grid.x0 = 50.0;
        let e = coverage(
            &params(CoverageLayer::BestRsrp),
            &m.iter().collect::<Vec<_>>(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("maps #2 (C)") && e.contains("x0: 50.0") && e.contains("x0: 0.0"),
            "{e}"
        );
        let m = maps();
        let e = coverage(&params(CoverageLayer::BestRsrp), &[&m[0], &m[1]])
            .unwrap_err()
            .to_string();
        assert!(e.contains("3 transmitters (A, B, C) for 2 maps"), "{e}");
    }

    #[test]
    fn bad_params_are_refused() {
        let ok = params(CoverageLayer::BestRsrp);
        assert!(Coverage::validate(&ok).is_ok());
        let with_tx = |k: usize, f: &dyn Fn(&mut CoverageTx)| {
            let mut p = ok.clone();
            f(&mut p.transmitters[k]);
            p
        };
        for (p, field, says) in [
            (
                with_tx(1, &|t| t.eirp_dbm = f64::NAN),
                "transmitters",
                "eirp_dbm",
            ),
            (
                with_tx(1, &|t| t.eirp_dbm = 500.0),
                "transmitters",
                "eirp_dbm",
            ),
            (with_tx(2, &|t| t.freq_hz = 0.0), "transmitters", "freq_hz"),
            (with_tx(2, &|t| t.id = "A".into()), "transmitters", "twice"),
            (
                with_tx(0, &|t| t.id = " ".into()),
                "transmitters",
                "non-empty",
            ),
            (
                CoverageParams {
                    transmitters: vec![],
                    ..ok.clone()
                },
                "transmitters",
                "1 to 256",
            ),
            (
                CoverageParams {
                    layer: CoverageLayer::Rsrp("Z".into()),
                    ..ok.clone()
                },
                "layer",
                "ids: A, B, C",
            ),
            (
                CoverageParams {
                    layer: CoverageLayer::Covered(f64::INFINITY),
                    ..ok.clone()
                },
                "layer",
                "expected",
            ),
            (
                CoverageParams {
                    noise_dbm: Some(f64::NAN),
                    ..ok.clone()
                },
                "noise_dbm",
                "expected",
            ),
            (
                CoverageParams {
                    floor_dbm: 10.0,
                    ..ok.clone()
                },
                "floor_dbm",
                "expected",
            ),
            (
                CoverageParams {
                    co_channel_hz: -1.0,
                    ..ok.clone()
                },
                "co_channel_hz",
                "expected",
            ),
        ] {
            let e = Coverage::validate(&p).unwrap_err();
            assert_eq!(e.field, field, "{e:?}");
            assert!(e.message.contains(says), "{e:?}");
        }
    }
}
