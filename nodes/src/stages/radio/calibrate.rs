//! Calibrate: the measurements as a training signal (the paper's future work, Sec. 7). The
//! links are traced once, as the Trace stage traces them; the training half of a
//! spatial split fits a factor on each material's permittivity and conductivity (and, if asked,
//! the foliage rate and each cell's antenna tilt, bearing and height) with one offset per cell
//! (`rf::calibration`), tracing again only where a height moved past a tolerance; the held-out
//! half is scored with offsets alone and calibrated. The factors and offsets are the output: a
//! Trace given them as its `calibration` input traces the calibrated twin.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use crate::artifact::{
    ArtifactType, Half, Material, Measurements, Metrics, Raster, Scene, block_half, measured_loss,
};
use crate::rf::calibration::{
    self, Calibration, LinkModel, Observation, Parameter, Prior, Setting, State, TraceSetup, fit,
    fit_from, fit_offsets, rmse_db,
};
use crate::rf::path::InteractionKind;
use crate::rf::traced_links::{TraceParams, trace_groups};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`Calibrate`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrateParams {
    /// How the links are traced: a Trace node's params (options, antennas, reach). Default
    /// Trace's defaults.
    pub trace: TraceParams,
    /// The materials whose permittivity and conductivity move, by ITU name (`concrete`,
    /// `medium_dry_ground`, ...). Default: every material a traced reflection or transmission
    /// meets, but metal (a conductor to the tracer at any σ it could fit).
    pub materials: Option<Vec<String>>,
    /// Fit the permittivity ε'. Default true.
    pub permittivity: bool,
    /// Fit the conductivity σ. Default true.
    pub conductivity: bool,
    /// Fit the foliage loss rate. Default false.
    pub foliage: bool,
    /// Fit the scattering coefficient S (effective roughness: specular reflections keep
    /// √(1 − S²) of the field, the diffuse power grows as S²), as a factor within ×/÷2 at one
    /// standard deviation, S at most 0.95. Needs `trace.options.diffuse` with a
    /// `scattering_coefficient` above 0 (the diffuse power the factor moves). Default false.
    pub scattering: bool,
    /// Fit each cell's transmit antenna tilt, as an offset within ±10° (prior 3°). Default
    /// false.
    pub tilt: bool,
    /// Fit each cell's transmit antenna bearing, as an offset within ±20° (prior 5°). Default
    /// false.
    pub azimuth: bool,
    /// Fit each cell's transmit antenna height, as an offset within ±6 m (prior 3 m). A height
    /// moves the paths, and a few metres can lift an antenna over a roof: the links are first
    /// traced at each step of a scan (`height_scan_m`) and each cell starts from its best; the
    /// fit then replays the paths by the image method over their reflecting faces, within a
    /// trust radius of half a step, and where a cell's antenna moved further than
    /// `height_tolerance_m` its links are traced again from there: the move is kept where they
    /// fit that cell's training links better, else the radius is halved; then the fit again
    /// (at most `max_retraces` times). A height is reported only where a trace put it.
    /// Default false.
    pub height: bool,
    /// How far a fitted height may move from where the paths were traced before they are
    /// traced again, metres, in [0.1, 10]. Default 0.25: a few tenths of a metre can take a
    /// path over a roof's edge or under it.
    pub height_tolerance_m: f64,
    /// Most retraces for a moved height, in [0, 5]. Default 3.
    pub max_retraces: u32,
    /// The step of the height scan that comes before the fit, metres, in [0.5, 6]: each cell's
    /// links are traced at every multiple of it within the bounds (±6 m) and each cell starts
    /// the fit from its best, within half a step. Default 3 (five traces).
    pub height_scan_m: f64,
    /// The measurements' noise, dB: the residuals' scale against the priors (shadowing and
    /// measurement error together). Default 6.
    pub noise_db: f64,
    /// The training half: a checkerboard of `block_m` squares in the site's CRS, the even blocks
    /// training, the odd held out, receivers within `guard_m` of a block's edge in neither (the
    /// rule of Evaluate's `split`, so an Evaluate with the same split scores the calibrated
    /// twin on links the fit never saw). Default 100 m blocks, 5 m guard.
    pub block_m: f64,
    /// The guard band, metres, in [0, block_m / 2). Default 5.
    pub guard_m: f64,
}

impl Default for CalibrateParams {
    fn default() -> Self {
        CalibrateParams {
            trace: TraceParams::default(),
            materials: None,
            permittivity: true,
            conductivity: true,
            foliage: false,
            scattering: false,
            tilt: false,
            azimuth: false,
            height: false,
            height_tolerance_m: 0.25,
            max_retraces: 3,
            height_scan_m: 3.0,
            noise_db: 6.0,
            block_m: 100.0,
            guard_m: 5.0,
        }
    }
}

/// Factors on the twin's materials (and foliage rate) fitted to the training half of the
/// measurements, with the fit's figures and the held-out half's scores.
pub struct Calibrate;

impl Stage for Calibrate {
    const KIND: &'static str = "Calibrate";
    const VERSION: u32 = 3;
    const DOC: &'static str = "per-material permittivity and conductivity factors (and foliage rate, scattering coefficient, antenna tilt, bearing and height) fitted to measured links over traced paths, with per-cell offsets; held-out scores";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one("scene", ArtifactType::Scene, "the twin to calibrate"),
        InputSpec::one(
            "links",
            ArtifactType::Measurements,
            "the measured links (path loss, or received power with a per-cell offset)",
        ),
        InputSpec::optional(
            "terrain",
            ArtifactType::Raster,
            "the terrain, for heights given above ground",
        ),
    ];
    type Params = CalibrateParams;
    type Output = Metrics;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::rf::antenna::check_antenna("trace.tx_antenna", &p.trace.tx_antenna)?;
        crate::rf::antenna::check_antenna("trace.rx_antenna", &p.trace.rx_antenna)?;
        super::check_reach(p.trace.reach_m)?;
        p.trace
            .options
            .trace_options()
            .check()
            .map_err(|(field, m)| ParamError::new("trace", format!("options.{field}: {m}")))?;
        if p.trace.coherent {
            return Err(ParamError::new(
                "trace",
                "coherent: a calibration fits the paths' summed power Σ |a|², not their coherent \
                 sum; leave coherent false",
            ));
        }
        if !(p.noise_db > 0.0 && p.noise_db <= 100.0) {
            return Err(ParamError::new(
                "noise_db",
                format!("expected a noise in (0, 100] dB, found {}", p.noise_db),
            ));
        }
        if !(p.block_m.is_finite() && p.block_m > 0.0) {
            return Err(ParamError::new(
                "block_m",
                format!(
                    "expected a positive, finite block in metres; found {}",
                    p.block_m
                ),
            ));
        }
        if !(p.guard_m >= 0.0 && p.guard_m < p.block_m / 2.0) {
            return Err(ParamError::new(
                "guard_m",
                format!(
                    "expected guard_m in [0, block_m / 2) = [0, {}) metres; found {}",
                    p.block_m / 2.0,
                    p.guard_m
                ),
            ));
        }
        for name in p.materials.iter().flatten() {
            if Material::from_name(name).is_none_or(|m| m == Material::Foliage) {
                return Err(ParamError::new(
                    "materials",
                    format!("no ITU material is called {name:?} (concrete, brick, glass, ...)"),
                ));
            }
        }
        if !(p.height_tolerance_m >= 0.1 && p.height_tolerance_m <= 10.0) {
            return Err(ParamError::new(
                "height_tolerance_m",
                format!(
                    "expected a tolerance in [0.1, 10] metres, found {}",
                    p.height_tolerance_m
                ),
            ));
        }
        if !(p.height_scan_m >= 0.5 && p.height_scan_m <= 6.0) {
            return Err(ParamError::new(
                "height_scan_m",
                format!(
                    "expected a scan step in [0.5, 6] metres, found {}",
                    p.height_scan_m
                ),
            ));
        }
        if p.max_retraces > MAX_RETRACES {
            return Err(ParamError::new(
                "max_retraces",
                format!(
                    "expected at most {MAX_RETRACES} retraces, found {}",
                    p.max_retraces
                ),
            ));
        }
        if p.scattering
            && !(p.trace.options.diffuse && p.trace.options.scattering_coefficient > 0.0)
        {
            return Err(ParamError::new(
                "scattering",
                "fitting the scattering coefficient needs diffuse power to move: set \
                 trace.options.diffuse true and a scattering_coefficient above 0",
            ));
        }
        if !(p.permittivity
            || p.conductivity
            || p.foliage
            || p.scattering
            || p.tilt
            || p.azimuth
            || p.height)
        {
            return Err(ParamError::new(
                "permittivity",
                "nothing to fit: set permittivity, conductivity, foliage, scattering, tilt, \
                 azimuth or height",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Metrics, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let links: &Measurements = inputs.one("links")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        let mut cells: BTreeMap<String, usize> = BTreeMap::new();
        for l in &links.links {
            let next = cells.len();
            cells.entry(l.tx.id.clone()).or_insert(next);
        }
        let ids: Vec<String> = {
            let mut v = vec![String::new(); cells.len()];
            for (id, &c) in &cells {
                v[c] = id.clone();
            }
            v
        };
        let setup = FitSetup {
            p,
            scene,
            links,
            terrain,
            cells: &cells,
        };
        // The antennas as the twin mounts them: the baseline every figure is scored against.
        let mut t = setup.trace(&Calibration::default(), None, ctx)?;
        let params = fitted_parameters(p, &t.met, cells.len());
        if params.is_empty() {
            return Err(StageError::Failed(
                "no traced reflection or transmission meets a material to calibrate".into(),
            ));
        }
        if t.train.is_empty() {
            return Err(StageError::Failed(format!(
                "no measured link some path reaches lies in the training half ({} m blocks)",
                p.block_m
            )));
        }
        let plain = Setting::of(&t.states);
        let offsets_only = fit_offsets(&t.train, cells.len(), plain);
        let baseline = Baseline {
            train: rmse_db(&t.train, plain, &offsets_only).0,
            held_out: rmse_db(&t.held_out, plain, &offsets_only),
            per_cell: (0..cells.len())
                .map(|c| {
                    rmse_db(
                        t.held_out.iter().filter(|o| o.cell == c),
                        plain,
                        &offsets_only,
                    )
                })
                .collect(),
            offsets: offsets_only,
        };
        // Heights first by a scan (a move of a few metres can lift an antenna over a roof,
        // which no replay sees), then every parameter by the fit, each height within its trust
        // radius of where its paths were traced. Where the fit moved a cell's antenna past the
        // tolerance, that cell's links are traced again from there, and the move kept only if
        // the traced paths fit its training links better than those before (the fit's other
        // values held), else the cell's radius is halved: a trust region whose test is a trace.
        // A cell's links see only its own antenna, so cells are kept or refused one by one. A
        // height is only ever reported where a trace put it: a last move under the tolerance
        // is not applied.
        let mut placed = Calibration::default();
        let mut scan = vec![0.0; cells.len()];
        if p.height {
            scan = setup.scan_heights(&t, &ids, ctx)?;
            for (id, &h) in ids.iter().zip(&scan) {
                if h != 0.0 {
                    placed.mounts.entry(id.clone()).or_default().height_m = h;
                }
            }
            if !placed.mounts.is_empty() {
                t = setup.trace(&placed, None, ctx)?;
            }
        }
        // Each cell's trust radius: half a scan step, halved at each refused move.
        let mut radius = vec![p.height_scan_m / 2.0; cells.len()];
        let (mut retraces, mut refused) = (0, vec![0u32; cells.len()]);
        let mut last: Option<Vec<(Parameter, f64)>> = None;
        let (priors, fitted) = loop {
            let priors: Vec<Prior> = params
                .iter()
                .map(|&q| raised_prior(q, p, &placed, &ids, &radius))
                .collect();
            // After a retrace, on from where the last fit ended (the heights where it traced).
            let fitted = match &last {
                None => fit(&t.train, cells.len(), &t.states, &priors, p.noise_db),
                Some(values) => fit_from(
                    &t.train,
                    cells.len(),
                    &t.states,
                    &priors,
                    p.noise_db,
                    values,
                ),
            };
            let proposed: Vec<(usize, f64)> = fitted
                .values
                .iter()
                .filter_map(|&(q, v)| match q {
                    Parameter::Height(c) if v.abs() > p.height_tolerance_m => Some((c as usize, v)),
                    _ => None,
                })
                .collect();
            if proposed.is_empty() || retraces >= p.max_retraces {
                break (priors, fitted);
            }
            retraces += 1;
            let mut next = placed.clone();
            for &(c, v) in &proposed {
                next.mounts.entry(ids[c].clone()).or_default().height_m += v;
            }
            let moving: BTreeSet<&str> = proposed.iter().map(|&(c, _)| ids[c].as_str()).collect();
            let retraced = setup.trace(&next, Some(&moving), ctx)?;
            let held = held_heights(&fitted.values);
            last = Some(held.clone());
            let before = train_rmse_by_cell(&t, &held, cells.len());
            let after = train_rmse_by_cell(&retraced, &held, cells.len());
            let mut kept = BTreeSet::new();
            for &(c, _) in &proposed {
                if after[c].0 < before[c].0 {
                    kept.insert(c);
                    placed.mounts.insert(ids[c].clone(), next.mounts[&ids[c]]);
                } else {
                    refused[c] += 1;
                    radius[c] /= 2.0;
                }
            }
            t = t.with_cells_from(retraced, &kept);
        };
        // The calibration as a Trace will apply it: heights where the last trace put them.
        let applied = held_heights(&fitted.values);
        let calibrated: Vec<State> = t.states.iter().map(|s| s.scaled(&applied)).collect();
        let mounted = calibration::mounts(&applied, cells.len());
        let mut m = Metrics::default();
        for ((q, k), (spread, prior)) in applied.iter().zip(fitted.spread.iter().zip(&priors)) {
            // A height is reported from where the twin mounts the antenna.
            let from_twin = -prior.centre;
            let name = calibration::metric_name(*q, &ids);
            m.set(name.clone(), *k + from_twin);
            // The fit's detail beside each factor, under fit/ (a Trace reads calibration/).
            let detail = name.replacen("calibration/", "fit/", 1);
            m.set(format!("{detail}/spread_ln"), *spread);
            m.set(format!("{detail}/prior_width_ln"), prior.width);
            m.set(format!("{detail}/lo"), prior.lo + from_twin);
            m.set(format!("{detail}/hi"), prior.hi + from_twin);
            if let Some(v) = t.states.first().and_then(|s| s.get(*q)) {
                m.set(format!("{detail}/itu_at_first_carrier"), v);
            }
        }
        m.set("fit/iterations", fitted.iterations as f64);
        m.set("fit/retraces", retraces as f64);
        if p.height {
            for ((id, h), no) in ids.iter().zip(&scan).zip(&refused) {
                m.set(format!("fit/height_m/{id}/scanned"), *h);
                m.set(format!("fit/height_m/{id}/moves_refused"), *no as f64);
            }
        }
        m.set("fit/noise_db", p.noise_db);
        m.set("train/links", t.train.len() as f64);
        m.set("train/rmse_offsets_only_db", baseline.train);
        // Held out: the twin as mounted with offsets alone against the calibrated twin (each
        // with its own training offsets), over all cells and per cell.
        let tuned = Setting {
            states: &calibrated,
            mounts: &mounted,
        };
        // Each cell's offset again for the antennas as applied (the fit's went with its last
        // height moves).
        let offsets = fit_offsets(&t.train, cells.len(), tuned);
        m.set(
            "train/rmse_calibrated_db",
            rmse_db(&t.train, tuned, &offsets).0,
        );
        let (after, n) = rmse_db(&t.held_out, tuned, &offsets);
        m.set("held_out/links", baseline.held_out.1 as f64);
        m.set("held_out/rmse_offsets_only_db", baseline.held_out.0);
        m.set("held_out/rmse_calibrated_db", after);
        m.set("held_out/links_calibrated", n as f64);
        for (id, &c) in &cells {
            let (a, _) = rmse_db(t.held_out.iter().filter(|o| o.cell == c), tuned, &offsets);
            let (b, n) = baseline.per_cell[c];
            m.set(format!("held_out/{id}/links"), n as f64);
            m.set(format!("held_out/{id}/rmse_offsets_only_db"), b);
            m.set(format!("held_out/{id}/rmse_calibrated_db"), a);
            m.set(format!("offset/{id}/offsets_only_db"), baseline.offsets[c]);
            m.set(format!("offset/{id}/calibrated_db"), offsets[c]);
        }
        m.set("split/block_m", p.block_m);
        m.set("split/guard_m", p.guard_m);
        Ok(m)
    }
}

/// The most retraces a Calibrate node may ask for.
const MAX_RETRACES: u32 = 5;

/// The scores of the twin as mounted, offsets alone (each cell's fitted on the training half).
struct Baseline {
    train: f64,
    held_out: (f64, usize),
    per_cell: Vec<(f64, usize)>,
    offsets: Vec<f64>,
}

/// What a fit's trace needs: the node's params and inputs, and the cells by id.
struct FitSetup<'a> {
    p: &'a CalibrateParams,
    scene: &'a Scene,
    links: &'a Measurements,
    terrain: Option<&'a Raster>,
    cells: &'a BTreeMap<String, usize>,
}

/// The measured links traced for a fit: each as its replayable paths in its carrier's state,
/// split into the training and held-out halves, and how often the paths met each material.
struct Traced {
    train: Vec<Observation>,
    held_out: Vec<Observation>,
    states: Vec<State>,
    met: BTreeMap<Material, usize>,
}

impl Traced {
    /// These links with those of the cells `kept` taken from `other` (a trace of theirs from
    /// elsewhere): a link's paths depend on its own cell's antenna only.
    fn with_cells_from(self, other: Traced, kept: &BTreeSet<usize>) -> Traced {
        let shift = self.states.len();
        let moved = |o: Observation| Observation {
            group: o.group + shift,
            ..o
        };
        let take = |mine: Vec<Observation>, theirs: Vec<Observation>| -> Vec<Observation> {
            (mine.into_iter().filter(|o| !kept.contains(&o.cell)))
                .chain((theirs.into_iter().filter(|o| kept.contains(&o.cell))).map(moved))
                .collect()
        };
        let mut met = self.met;
        for (m, n) in other.met {
            *met.entry(m).or_default() += n;
        }
        Traced {
            train: take(self.train, other.train),
            held_out: take(self.held_out, other.held_out),
            states: self.states.into_iter().chain(other.states).collect(),
            met,
        }
    }
}

/// `values` with every height offset at 0: the antennas where the paths were traced.
fn held_heights(values: &[(Parameter, f64)]) -> Vec<(Parameter, f64)> {
    values
        .iter()
        .map(|&(q, v)| match q {
            Parameter::Height(_) => (q, 0.0),
            _ => (q, v),
        })
        .collect()
}

/// Each cell's training RMSE over `t`'s paths with the fitted `values` (none: the twin's),
/// each cell with its own best offset, and the links some path reaches.
fn train_rmse_by_cell(t: &Traced, values: &[(Parameter, f64)], cells: usize) -> Vec<(f64, usize)> {
    let states: Vec<State> = t.states.iter().map(|s| s.scaled(values)).collect();
    let mounts = calibration::mounts(values, cells);
    let at = Setting {
        states: &states,
        mounts: &mounts,
    };
    let offsets = fit_offsets(&t.train, cells, at);
    (0..cells)
        .map(|c| rmse_db(t.train.iter().filter(|o| o.cell == c), at, &offsets))
        .collect()
}

impl FitSetup<'_> {
    /// Each cell's height offset from a scan: the links traced with every antenna raised by each
    /// multiple of `height_scan_m` within the prior's bounds (`as_mounted` holds the twin's
    /// own), each cell scored on its training links with its own offset (the twin's materials,
    /// the published angles) as n₀ · mean squared residual / noise² + (offset / prior width)²,
    /// n₀ its training links as mounted (so reaching fewer links gains nothing); the lowest
    /// kept, a tie to the smaller move. A cell's links see only its own antenna, so one trace
    /// per step serves every cell.
    fn scan_heights(
        &self,
        as_mounted: &Traced,
        ids: &[String],
        ctx: &Ctx,
    ) -> Result<Vec<f64>, StageError> {
        let (p, cells) = (self.p, ids.len());
        let prior = Prior::default_for(Parameter::Height(0));
        let mean_squares = |t: &Traced| -> Vec<Option<f64>> {
            (train_rmse_by_cell(t, &[], cells).into_iter())
                .map(|(r, n)| (n > 0).then_some(r * r))
                .collect()
        };
        let n0: Vec<f64> = (0..cells)
            .map(|c| as_mounted.train.iter().filter(|o| o.cell == c).count() as f64)
            .collect();
        let cost = |h: f64, c: usize, ms: Option<f64>| {
            ms.map(|m| n0[c] * m / p.noise_db.powi(2) + (h / prior.width).powi(2))
        };
        let mut best: Vec<(f64, Option<f64>)> = mean_squares(as_mounted)
            .into_iter()
            .enumerate()
            .map(|(c, ms)| (0.0, cost(0.0, c, ms)))
            .collect();
        let k = (prior.hi.max(-prior.lo) / p.height_scan_m).floor() as i32;
        // Nearer moves first, so a tie keeps the smaller.
        let mut steps: Vec<i32> = (-k..=k).filter(|&i| i != 0).collect();
        steps.sort_by_key(|&i| (i.abs(), i));
        for i in steps {
            let h = i as f64 * p.height_scan_m;
            if h < prior.lo || h > prior.hi {
                continue;
            }
            let mut raised = Calibration::default();
            for id in ids {
                raised.mounts.entry(id.clone()).or_default().height_m = h;
            }
            let scored = mean_squares(&self.trace(&raised, None, ctx)?);
            for (c, ms) in scored.into_iter().enumerate() {
                if let Some(v) = cost(h, c, ms)
                    && best[c].1.is_none_or(|b| v < b)
                {
                    best[c] = (h, Some(v));
                }
            }
        }
        Ok(best.into_iter().map(|(h, _)| h).collect())
    }

    /// Traces the links as the Trace stage does (those of the cells in `only`, or all), each
    /// cell's antenna at its mount in `placed`.
    fn trace(
        &self,
        placed: &Calibration,
        only: Option<&BTreeSet<&str>>,
        ctx: &Ctx,
    ) -> Result<Traced, StageError> {
        let p = self.p;
        let some;
        let links = match only {
            Some(cells) => {
                some = Measurements {
                    links: (self.links.links.iter())
                        .filter(|l| cells.contains(l.tx.id.as_str()))
                        .cloned()
                        .collect(),
                };
                &some
            }
            None => self.links,
        };
        let (x0, y0) = ctx.site.origin;
        let mut t = Traced {
            train: Vec::new(),
            held_out: Vec::new(),
            states: Vec::new(),
            met: BTreeMap::new(),
        };
        trace_groups(
            &p.trace,
            self.scene,
            links,
            self.terrain,
            placed,
            ctx,
            |g| {
                let group = t.states.len();
                t.states.push(State::of_scene(&g.rf, g.freq_hz, &g.options));
                let setup = TraceSetup {
                    scene: &g.rf,
                    tx_antenna: &g.tx_antenna,
                    rx_antenna: &p.trace.rx_antenna,
                    opt: &g.options,
                };
                for ((&i, (tx, rx)), traced) in g.links.iter().zip(&g.ends).zip(&g.paths) {
                    let l = &links.links[i];
                    let Some(loss_db) = measured_loss(l) else {
                        continue;
                    };
                    for path in &traced.paths {
                        for it in &path.interactions {
                            if it.kind != InteractionKind::Diffraction {
                                *t.met
                                    .entry(g.rf.material[it.triangle as usize])
                                    .or_default() += 1;
                            }
                        }
                    }
                    let o = Observation {
                        model: LinkModel::new(&setup, (*tx).into(), (*rx).into(), traced),
                        cell: self.cells[&l.tx.id],
                        group,
                        loss_db,
                    };
                    match block_half(l.rx.x + x0, l.rx.y + y0, p.block_m, p.guard_m) {
                        Half::Train => t.train.push(o),
                        Half::HeldOut => t.held_out.push(o),
                        Half::Guard => {}
                    }
                }
                Ok(())
            },
        )?;
        Ok(t)
    }
}

/// The prior of `q` for paths traced with the antennas at `placed` (`p`'s trace): a height's
/// prior stays where the twin mounts the antenna (minus what was retraced), and its bounds are
/// the prior's within the cell's trust `radius` of where its paths were traced; the scattering
/// coefficient's keeps S at most 0.95.
fn raised_prior(
    q: Parameter,
    p: &CalibrateParams,
    placed: &Calibration,
    ids: &[String],
    radius: &[f64],
) -> Prior {
    let prior = Prior::default_for(q);
    let Parameter::Height(c) = q else {
        return match q {
            Parameter::Scattering => Prior::for_scattering(p.trace.options.scattering_coefficient),
            _ => prior,
        };
    };
    let (c, id) = (c as usize, &ids[c as usize]);
    let h = placed.mounts.get(id).map_or(0.0, |m| m.height_m);
    Prior {
        centre: prior.centre - h,
        lo: (prior.lo - h).max(-radius[c]),
        hi: (prior.hi - h).min(radius[c]),
        ..prior
    }
}

/// The parameters a fit moves: those `p` asks for, of the materials it names or (by default)
/// every material the traced paths met but metal, and each of `cells` cells' antenna tilt,
/// bearing and height.
fn fitted_parameters(
    p: &CalibrateParams,
    met: &BTreeMap<Material, usize>,
    cells: usize,
) -> Vec<Parameter> {
    let materials: Vec<Material> = match &p.materials {
        Some(names) => names
            .iter()
            .filter_map(|n| Material::from_name(n))
            .collect(),
        None => met
            .keys()
            .copied()
            .filter(|m| *m != Material::Metal && *m != Material::Foliage)
            .collect(),
    };
    let mut out = Vec::new();
    for m in materials.into_iter().filter(|m| met.contains_key(m)) {
        if p.permittivity {
            out.push(Parameter::Permittivity(m));
        }
        if p.conductivity {
            out.push(Parameter::Conductivity(m));
        }
    }
    if p.foliage {
        out.push(Parameter::FoliageDbPerM);
    }
    if p.scattering {
        out.push(Parameter::Scattering);
    }
    for c in 0..cells as u32 {
        if p.tilt {
            out.push(Parameter::Tilt(c));
        }
        if p.azimuth {
            out.push(Parameter::Azimuth(c));
        }
        if p.height {
            out.push(Parameter::Height(c));
        }
    }
    out
}
