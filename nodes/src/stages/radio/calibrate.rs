//! Calibrate: the measurements as a training signal (the paper's future work, Sec. 7). The
//! links are traced once, as the Trace stage traces them; the training half of a
//! spatial split fits a factor on each material's permittivity and conductivity (and, if asked,
//! the foliage rate) with one offset per cell (`rf::calibration`); the held-out half is scored
//! with offsets alone and calibrated. The factors are the output: a Trace given them as its
//! `calibration` input traces the calibrated twin.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{
    ArtifactType, Half, Material, Measurements, Metrics, Raster, Scene, block_half, measured_loss,
};
use crate::rf::calibration::{
    self, LinkModel, Observation, Parameter, Prior, Setting, State, TraceSetup, fit, fit_offsets,
    rmse_db,
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
    /// Fit each cell's transmit antenna tilt, as an offset within ±10° (prior 3°). Default
    /// false.
    pub tilt: bool,
    /// Fit each cell's transmit antenna bearing, as an offset within ±20° (prior 5°). Default
    /// false.
    pub azimuth: bool,
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
            tilt: false,
            azimuth: false,
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
    const VERSION: u32 = 1;
    const DOC: &'static str = "per-material permittivity and conductivity factors (and foliage rate) fitted to measured links over traced paths, with per-cell offsets; held-out scores";
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
        if !(p.permittivity || p.conductivity || p.foliage || p.tilt || p.azimuth) {
            return Err(ParamError::new(
                "permittivity",
                "nothing to fit: set permittivity, conductivity, foliage, tilt or azimuth",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Metrics, StageError> {
        let scene: &Scene = inputs.one("scene")?;
        let links: &Measurements = inputs.one("links")?;
        let terrain: Option<&Raster> = inputs.optional("terrain")?;
        let (x0, y0) = ctx.site.origin;
        let mut cells: BTreeMap<String, usize> = BTreeMap::new();
        for l in &links.links {
            let next = cells.len();
            cells.entry(l.tx.id.clone()).or_insert(next);
        }
        // Trace once; keep each link as its replayable paths, in the state of its carrier.
        let (mut train, mut held_out) = (Vec::new(), Vec::new());
        let mut states: Vec<State> = Vec::new();
        let mut met: BTreeMap<Material, usize> = BTreeMap::new();
        trace_groups(
            &p.trace,
            scene,
            links,
            terrain,
            &calibration::Calibration::default(),
            ctx,
            |g| {
                let group = states.len();
                states.push(State::of_scene(
                    &g.rf,
                    g.freq_hz,
                    g.options.foliage_loss(g.freq_hz),
                ));
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
                                *met.entry(g.rf.material[it.triangle as usize]).or_default() += 1;
                            }
                        }
                    }
                    let o = Observation {
                        model: LinkModel::new(&setup, (*tx).into(), (*rx).into(), traced),
                        cell: cells[&l.tx.id],
                        group,
                        loss_db,
                    };
                    match block_half(l.rx.x + x0, l.rx.y + y0, p.block_m, p.guard_m) {
                        Half::Train => train.push(o),
                        Half::HeldOut => held_out.push(o),
                        Half::Guard => {}
                    }
                }
                Ok(())
            },
        )?;
        let params = fitted_parameters(p, &met, cells.len());
        let ids: Vec<String> = {
            let mut v = vec![String::new(); cells.len()];
            for (id, &c) in &cells {
                v[c] = id.clone();
            }
            v
        };
        if params.is_empty() {
            return Err(StageError::Failed(
                "no traced reflection or transmission meets a material to calibrate".into(),
            ));
        }
        if train.is_empty() {
            return Err(StageError::Failed(format!(
                "no measured link some path reaches lies in the training half ({} m blocks)",
                p.block_m
            )));
        }
        let priors: Vec<Prior> = params.iter().map(|&q| Prior::default_for(q)).collect();
        let fitted = fit(&train, cells.len(), &states, &priors, p.noise_db);
        let calibrated: Vec<State> = states.iter().map(|s| s.scaled(&fitted.values)).collect();
        let turned = calibration::turns(&fitted.values, cells.len());
        let mut m = Metrics::default();
        for ((q, k), (spread, prior)) in fitted.values.iter().zip(fitted.spread.iter().zip(&priors))
        {
            let name = calibration::metric_name(*q, &ids);
            m.set(name.clone(), *k);
            // The fit's detail beside each factor, under fit/ (a Trace reads calibration/).
            let detail = name.replacen("calibration/", "fit/", 1);
            m.set(format!("{detail}/spread_ln"), *spread);
            m.set(format!("{detail}/prior_width_ln"), prior.width);
            m.set(format!("{detail}/lo"), prior.lo);
            m.set(format!("{detail}/hi"), prior.hi);
            if let Some(v) = states.first().and_then(|s| s.get(*q)) {
                m.set(format!("{detail}/itu_at_first_carrier"), v);
            }
        }
        m.set("fit/iterations", fitted.iterations as f64);
        m.set("fit/noise_db", p.noise_db);
        m.set("train/links", train.len() as f64);
        m.set("train/rmse_offsets_only_db", fitted.rmse_db.0);
        m.set("train/rmse_calibrated_db", fitted.rmse_db.1);
        // Held out: each state with its own training offsets, over all cells and per cell.
        let (plain, tuned) = (
            Setting::of(&states),
            Setting {
                states: &calibrated,
                turns: &turned,
            },
        );
        let offsets_only = fit_offsets(&train, cells.len(), plain);
        let (before, n) = rmse_db(&held_out, plain, &offsets_only);
        let (after, _) = rmse_db(&held_out, tuned, &fitted.offsets);
        m.set("held_out/links", n as f64);
        m.set("held_out/rmse_offsets_only_db", before);
        m.set("held_out/rmse_calibrated_db", after);
        for (id, &c) in &cells {
            let of_cell = || held_out.iter().filter(|o| o.cell == c);
            let (b, n) = rmse_db(of_cell(), plain, &offsets_only);
            let (a, _) = rmse_db(of_cell(), tuned, &fitted.offsets);
            m.set(format!("held_out/{id}/links"), n as f64);
            m.set(format!("held_out/{id}/rmse_offsets_only_db"), b);
            m.set(format!("held_out/{id}/rmse_calibrated_db"), a);
            m.set(format!("offset/{id}/offsets_only_db"), offsets_only[c]);
            m.set(format!("offset/{id}/calibrated_db"), fitted.offsets[c]);
        }
        m.set("split/block_m", p.block_m);
        m.set("split/guard_m", p.guard_m);
        Ok(m)
    }
}

/// The parameters a fit moves: those `p` asks for, of the materials it names or (by default)
/// every material the traced paths met but metal, and each of `cells` cells' antenna angles.
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
    for c in 0..cells as u32 {
        if p.tilt {
            out.push(Parameter::Tilt(c));
        }
        if p.azimuth {
            out.push(Parameter::Azimuth(c));
        }
    }
    out
}
