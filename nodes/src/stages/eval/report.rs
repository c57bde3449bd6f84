//! The report (paper Table 1 and its figures): every model's scores against the measurements in
//! one table (rows: site x metric; columns: models), as Markdown, CSV and JSON, with plots: predicted
//! vs measured, the CDF of the error, path loss against distance with each model's trend line, and
//! the radio map over the orthophoto.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{
    ArtifactType, Height, Link, Measurements, Metrics, Ortho, Raster, ReportFiles, Scene,
};
use crate::artifact::{Half, block_half, link_distance, measured_loss};
use crate::io::csv_text;
use crate::io::export::figures::charts::{
    ErrorCdf, ModelSeries, PathLossDistance, PowerDistance, ReceivedPowerDistance, Scatter,
};
use crate::io::export::figures::maps::{Layer, MapFigure, Palette, robust_range, view_grid};
use crate::io::export::figures::{Figure, render};
use crate::io::export::report_html::{LinkPoint, Page, TableRow, number, report_html};
use crate::rf::calibration;
use crate::rf::em::fspl_db;
use crate::rf::pathloss_fit::{fit_close_in, fit_power_distance};
use crate::site::Site;
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`Report`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReportParams {
    /// The models' names, in the order of `predictions` and `evaluations` (the table's columns).
    pub models: Vec<String>,
    /// The site's name (the table's row group). Default "site".
    #[serde(default = "site")]
    pub site: String,
    /// Names of the `scenes` in report.html's 3D view, in order. Default "scene 1", ...
    #[serde(default)]
    pub scene_names: Vec<String>,
    /// Names of the `evidence` reports, in order. Default the report's place, "evidence 1", ...
    #[serde(default)]
    pub evidence_names: Vec<String>,
    /// What the run assumes that the data does not say (antenna heights, terrain, default
    /// building heights), one sentence each, stated after the introduction. Default none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub assumptions: Vec<String>,
}

/// The most assumptions a report states, and the longest one, in characters.
const MAX_ASSUMPTIONS: usize = 64;
const MAX_ASSUMPTION_CHARS: usize = 1000;

fn site() -> String {
    "site".into()
}

/// The table's rows: (metric key in the evaluations, label). The rows of each carrier's PD and
/// CI follow the pooled ones when the links have more than one carrier ([`table_keys`]).
const ROWS: [(&str, &str); 21] = [
    ("p2p_rmse_db", "P2P RMSE (dB)"),
    ("p2p_me_db", "P2P mean error (dB)"),
    ("p2p_std_db", "P2P std (dB)"),
    ("pd_rmse_db", "PD RMSE (dB)"),
    ("ci_rmse_db", "CI RMSE (dB)"),
    (
        "pd_scatter_db",
        "PD: measured about the model's line, RMS (dB)",
    ),
    (
        "ci_scatter_db",
        "CI: measured about the model's line, RMS (dB)",
    ),
    (
        "pd_sigma_measured_db",
        "PD: measured about the measured line, σ (dB)",
    ),
    ("pd_beta", "PD slope β of the model's line"),
    ("pd_beta_measured", "PD slope β of the measured line"),
    ("ci_n", "CI exponent n of the model's line"),
    ("ci_n_measured", "CI exponent n of the measured line"),
    ("los/p2p_rmse_db", "LOS P2P RMSE (dB)"),
    ("nlos/p2p_rmse_db", "NLOS P2P RMSE (dB)"),
    ("los/pd_rmse_db", "LOS PD RMSE (dB)"),
    ("nlos/pd_rmse_db", "NLOS PD RMSE (dB)"),
    ("links_scored", "links scored"),
    (
        "links_unpredicted",
        "links the model gave no value (left out)",
    ),
    (
        "links_no_path",
        "links the model found no path for (left out)",
    ),
    (
        "floor_clamped",
        "links predicted past the floor (scored at the floor)",
    ),
    ("trend_links", "links in the PD/CI lines"),
];

/// Rows that count links, printed without decimals.
const COUNT_ROWS: [&str; 5] = [
    "links_scored",
    "links_unpredicted",
    "links_no_path",
    "floor_clamped",
    "trend_links",
];

/// Table 1's rows as (key, label): [`ROWS`], with each carrier's PD and CI RMSE after the pooled
/// CI row when some evaluation has more than one carrier (`f/<carrier>/…`), in order of
/// frequency.
fn table_keys(evals: &[&Metrics]) -> Vec<(String, String)> {
    let mut carriers: Vec<String> = Vec::new();
    for e in evals {
        for k in e.values.keys() {
            if let Some(c) = k
                .strip_prefix("f/")
                .and_then(|r| r.strip_suffix("/pd_rmse_db"))
                && !carriers.iter().any(|x| x == c)
            {
                carriers.push(c.to_string());
            }
        }
    }
    let ghz = |c: &str| {
        c.trim_end_matches("GHz")
            .parse::<f64>()
            .unwrap_or(f64::INFINITY)
    };
    carriers.sort_by(|a, b| ghz(a).total_cmp(&ghz(b)));
    let mut keys = Vec::new();
    for (key, label) in ROWS {
        keys.push((key.to_string(), label.to_string()));
        if key == "ci_rmse_db" {
            for c in &carriers {
                for (m, name) in [("pd", "PD"), ("ci", "CI")] {
                    keys.push((
                        format!("f/{c}/{m}_rmse_db"),
                        format!("{name} RMSE at {c} (dB)"),
                    ));
                }
            }
        }
    }
    keys
}

/// Table 1 and its plots as a folder: `report.md`, `table.csv`, `links.csv` (every link as
/// scored), `metrics.json`, `plots/*.png`, and `report.html` with all of it and the scenes in 3D.
pub struct Report;

impl Stage for Report {
    const KIND: &'static str = "Report";
    // 3: report.html with the 3D view; 4: scenes past the page's budget left out, named;
    // 5: plotters figures as SVG and PNG at print size, per-stage figures; 6: close-in lines in
    // the path-loss chart; 7: both trend-line variants, the floor count, the definitions;
    // 8: links.csv, every link as scored; 9: stages' reports (`evidence`) as tables;
    // 10: Evaluate 5's PD/CI (the gap between the model's and the measured lines), per-carrier
    // rows, the definitions under the table, the chart's lines from the evaluations with the
    // measured lines; 11: the PD/CI <= P2P sentence says "on those links"; 12: the links with no
    // path get their row (they were left out unseen beside "no value: 0"), links.csv's
    // offset_db and half columns, the table of links left out (Evaluate 6's split, windows,
    // footprints); 13: with received power and no EIRP (a drive test's RSRP), the
    // path-loss-distance chart in received power (measured as read, each model at its fitted
    // EIRP, free space at the first model's), the offsets applied said under it.
    // 14: the intro says the models were scored at different links when they were; the
    // `assumptions` stated after it. 15: a Calibrate node's evidence gets a table of its
    // calibrated parameters with their priors.
    const VERSION: u32 = 15;
    const DOC: &'static str = "Table 1 (site x metric by model) as Markdown/CSV/JSON with scatter, error CDF, path-loss-distance and radio map plots";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "measurements",
            ArtifactType::Measurements,
            "the measured links",
        ),
        InputSpec::many(
            "predictions",
            ArtifactType::Measurements,
            "each model's predictions, in `models` order",
        ),
        InputSpec::many(
            "evaluations",
            ArtifactType::Metrics,
            "each model's Evaluate metrics, in `models` order",
        ),
        InputSpec::optional(
            "radio_map",
            ArtifactType::Raster,
            "a radio map (dB) to show",
        ),
        InputSpec::optional(
            "ortho",
            ArtifactType::Ortho,
            "an orthophoto under the radio map",
        ),
        InputSpec::many(
            "figures",
            ArtifactType::Report,
            "per-stage figures (MapPlot, ReliefPlot, MaterialPlot) shown after the plots",
        ),
        InputSpec::many(
            "scenes",
            ArtifactType::Scene,
            "scenes for report.html's 3D view (the twin first: its terrain carries the map and points)",
        ),
        InputSpec::many(
            "evidence",
            ArtifactType::Metrics,
            "stages' reports (\"carved.outcomes\", \"clutter.counts\"), each a table after the plots",
        ),
    ];
    type Params = ReportParams;
    type Output = ReportFiles;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if p.models.is_empty() {
            return Err(ParamError::new("models", "expected the models' names"));
        }
        if p.scene_names.len() > 16 {
            return Err(ParamError::new("scene_names", "expected at most 16 scenes"));
        }
        if p.evidence_names.len() > 64 {
            return Err(ParamError::new(
                "evidence_names",
                "expected at most 64 reports",
            ));
        }
        if p.assumptions.len() > MAX_ASSUMPTIONS
            || p.assumptions
                .iter()
                .any(|a| a.chars().count() > MAX_ASSUMPTION_CHARS)
        {
            return Err(ParamError::new(
                "assumptions",
                format!(
                    "expected at most {MAX_ASSUMPTIONS} sentences of at most \
                     {MAX_ASSUMPTION_CHARS} characters each"
                ),
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<ReportFiles, StageError> {
        let meas: &Measurements = inputs.one("measurements")?;
        let preds: Vec<&Measurements> = inputs.many("predictions")?;
        let evals: Vec<&Metrics> = inputs.many("evaluations")?;
        if preds.len() != p.models.len() || evals.len() != p.models.len() {
            return Err(StageError::Failed(format!(
                "{} models named, {} predictions, {} evaluations: give one of each per model",
                p.models.len(),
                preds.len(),
                evals.len()
            )));
        }
        let radio_map: Option<&Raster> = inputs.optional("radio_map")?;
        let ortho: Option<&Ortho> = inputs.optional("ortho")?;
        let scenes: Vec<&Scene> = inputs.many("scenes")?;
        if !p.scene_names.is_empty() && p.scene_names.len() != scenes.len() {
            return Err(StageError::Failed(format!(
                "{} scene names for {} scenes: name each scene, or none",
                p.scene_names.len(),
                scenes.len()
            )));
        }
        let named = named_evidence(p, inputs.many("evidence")?)?;
        let evidence: Vec<(&str, &Metrics)> = named.iter().map(|(n, m)| (n.as_str(), *m)).collect();
        let fail = StageError::Failed;
        let mut files = Vec::new();
        let (md_table, csv) = tables(p, &evals);
        let figures = model_figures(p, meas, &preds, &evals, radio_map, ortho)?;
        let plots = plot_files(figures, &inputs.many::<ReportFiles>("figures")?)?;
        let intro = with_assumptions(intro(meas, &evals), &p.assumptions);
        let defs = definitions(&evals);
        let mut md = format!(
            "# KODAMA report: {}\n\n{intro}\n\n{md_table}\n{}\n{}",
            p.site,
            definitions_markdown(&defs),
            left_out_markdown(p, &evals)
        );
        let power_note = power_distance(&p.models, meas, &preds, &evals)
            .map(|pd| power_distance_note(&pd, &p.models, &evals));
        for (name, _) in plots.iter().filter(|(n, _)| n.ends_with(".png")) {
            md.push_str(&format!("![{name}]({name})\n\n"));
            if let Some(note) = power_note.as_ref()
                && name == "plots/path_loss_distance.png"
            {
                md.push_str(&format!("{note}\n\n"));
            }
        }
        md.push_str(&evidence_markdown(&evidence));
        files.push(("report.md".to_string(), md.into_bytes()));
        files.push(("table.csv".to_string(), csv.into_bytes()));
        files.push((
            "links.csv".to_string(),
            links_csv(&p.models, meas, &preds, &evals, ctx.site)
                .map_err(StageError::Failed)?
                .into_bytes(),
        ));
        files.push(("metrics.json".to_string(), metrics_json(p, &evals)?));
        let plot_notes: Vec<(&str, String)> = power_note
            .map(|n| ("plots/path_loss_distance.png", n))
            .into_iter()
            .collect();
        let page = PageInputs {
            p,
            plot_notes: &plot_notes,
            intro: &intro,
            definitions: &defs,
            meas,
            preds: &preds,
            evals: &evals,
            scenes: &scenes,
            radio_map,
            evidence: &evidence,
        };
        let html = page.html(&plots).map_err(fail)?;
        files.push(("report.html".to_string(), html.into_bytes()));
        files.extend(plots);
        Ok(ReportFiles { files })
    }
}

/// metrics.json: each model's evaluation by the model's name. A step of its own: the one file
/// written from the evaluations as they are.
fn metrics_json(p: &ReportParams, evals: &[&Metrics]) -> Result<Vec<u8>, StageError> {
    let mut json: BTreeMap<&str, &BTreeMap<String, f64>> = BTreeMap::new();
    for (name, e) in p.models.iter().zip(evals) {
        json.insert(name, &e.values);
    }
    Ok(
        (serde_json::to_string_pretty(&json).map_err(|e| StageError::Failed(e.to_string()))?
            + "\n")
            .into_bytes(),
    )
}

/// The report's own figures: predicted against measured, the CDF of the error, path loss
/// against distance, and the radio map over the orthophoto when there is one.
fn model_figures(
    p: &ReportParams,
    meas: &Measurements,
    preds: &[&Measurements],
    evals: &[&Metrics],
    radio_map: Option<&Raster>,
    ortho: Option<&Ortho>,
) -> Result<Vec<(String, Figure)>, StageError> {
    let fail = StageError::Failed;
    // Per model: (distance, measured with its offset taken out, predicted), and each link's
    // frequency.
    let (series, freqs): (Vec<Vec<(f64, f64, f64)>>, Vec<Vec<f64>>) = preds
        .iter()
        .zip(evals)
        .map(|(pr, ev)| pairs(meas, pr, ev).into_iter().unzip())
        .unzip();
    let models = model_series(p, &series, &freqs, evals);
    // The path-loss chart also draws the lines fitted to the measurements (the first model's
    // links): what Table 1's PD and CI compare each model's lines with.
    let mut with_measured: Vec<ModelSeries> = models.iter().map(ModelSeries::clone).collect();
    if let (Some(ev), Some(f)) = (evals.first(), freqs.first())
        && let Some((pd, ci)) = evaluated_lines(ev, "_measured", f)
    {
        with_measured.push(ModelSeries {
            name: "measured",
            links: &[],
            trend: Some(pd),
            close_in: Some(ci),
        });
    }
    let mut figures: Vec<(String, Figure)> = vec![
        ("scatter".into(), render(&Scatter(&models)).map_err(fail)?),
        (
            "error_cdf".into(),
            render(&ErrorCdf(&models)).map_err(fail)?,
        ),
        (
            "path_loss_distance".into(),
            match power_distance(&p.models, meas, preds, evals) {
                Some(pd) => render(&ReceivedPowerDistance(&pd)),
                None => render(&PathLossDistance(&with_measured)),
            }
            .map_err(fail)?,
        ),
    ];
    if let Some(map) = radio_map {
        figures.push(("radio_map".into(), map_figure(map, ortho).map_err(fail)?));
    }
    Ok(figures)
}

/// Every plot as plots/<name>.png (shown) and .svg (print); the per-stage figures' files
/// (`stage_figures`, the `figures` input) join them under their own names, each checked to be a
/// plain file name that no other figure writes.
fn plot_files(
    figures: Vec<(String, Figure)>,
    stage_figures: &[&ReportFiles],
) -> Result<Vec<(String, Vec<u8>)>, StageError> {
    let fail = StageError::Failed;
    let mut plots: Vec<(String, Vec<u8>)> = Vec::new();
    for (name, f) in figures {
        plots.push((format!("plots/{name}.png"), f.png));
        plots.push((format!("plots/{name}.svg"), f.svg.into_bytes()));
    }
    for (k, fig) in stage_figures.iter().enumerate() {
        for (name, bytes) in &fig.files {
            crate::io::safe_name::check_file_name(name)
                .map_err(|m| fail(format!("figure {} (input `figures` #{k}): {m}", name)))?;
            let path = format!("plots/{name}");
            if plots.iter().any(|(p, _)| *p == path) {
                return Err(fail(format!(
                    "two figures write {path}: give each MapPlot/ReliefPlot/MaterialPlot its own `name`"
                )));
            }
            plots.push((path, bytes.clone()));
        }
    }
    Ok(plots)
}

/// The introduction followed by the run's assumptions, when it states any.
fn with_assumptions(intro: String, assumptions: &[String]) -> String {
    if assumptions.is_empty() {
        return intro;
    }
    let list: Vec<String> = assumptions
        .iter()
        .map(|a| a.trim().trim_end_matches('.').to_string())
        .collect();
    format!(
        "{intro} Assumptions, none of them published: {}.",
        list.join("; ")
    )
}

/// The report's introduction: how many links, and where the definitions are.
/// The claim "every model is scored at the same links" is made only when it holds: a traced model
/// that finds no path for some links is scored on fewer, and then the intro says so.
fn intro(meas: &Measurements, evals: &[&Metrics]) -> String {
    let scored: Vec<Option<f64>> = evals.iter().map(|m| m.get("links_scored")).collect();
    let same = scored.windows(2).all(|w| w[0] == w[1]);
    let how = if same {
        "every model is scored at the same links (paper Sec. 5)"
    } else {
        "the models are scored at the links each gives a value for, so their counts differ \
         (\"links scored\" in Table 1, and where the others went in the table of links left out)"
    };
    format!(
        "{} measured links; {how}. How each figure of Table 1 is computed is stated under it.",
        meas.links.len()
    )
}

/// How each figure of Table 1 is computed, one paragraph each, with what the measurements' own
/// lines are on this site (from the first evaluation: every model scored on the same links is
/// compared with the same measured lines). The paper (Sec. 5, Table 1) names P2P, PD and CI but
/// gives no formulas; these are the standard forms, chosen as `Evaluate` documents.
fn definitions(evals: &[&Metrics]) -> Vec<String> {
    let first = evals.first().copied();
    let get = |k: &str| first.and_then(|e| e.get(k));
    let floor = evals.iter().find_map(|e| e.get("floor_db"));
    let offsets = evals
        .iter()
        .any(|e| e.values.keys().any(|k| k.starts_with("offset_db/")));
    let carriers = get("carriers").unwrap_or(1.0);
    let mut out = vec![
        format!(
            "P2P (point-to-point): e_i = PL_pred,i − PL_meas,i for every link both give a path \
             loss for; P2P RMSE = sqrt(mean e_i²), mean error = mean e_i, std = sqrt(RMSE² − \
             mean²). {}{}",
            match floor {
                Some(f) => format!(
                    "A prediction past the receiver's floor ({f:.0} dB), or no path at all, is \
                     scored as the floor (row \"links predicted past the floor\"). "
                ),
                None => "Links a model finds no path for are left out. ".to_string(),
            },
            if offsets {
                "The transmitters' EIRP is unknown: one offset per transmitter (the mean of \
                 measured − predicted) is taken out of the measurements first."
            } else {
                ""
            }
        )
        .trim_end()
        .to_string(),
        "Trend lines, each fitted by least squares to the path loss PL_i at the 3-D \
         transmitter-receiver distances d_i (metres, ground heights from the terrain): PD \
         (power-distance, floating intercept, the 3GPP TR 38.901 form) PL(d) = α + 10 β \
         log10(d / 1 m), in α and β; CI (close-in free-space reference distance; Sun, Rappaport \
         et al., IEEE Trans. Veh. Technol. 65(5), 2016, d0 = 1 m) PL(f, d) = FSPL(f, 1 m) + 10 \
         n log10(d / 1 m), FSPL(f, 1 m) = 20 log10(4π f / c), in n."
            .to_string(),
        "PD RMSE and CI RMSE (Table 1's PD and CI): the line is fitted separately to the \
         model's predictions and to the measurements of the same links (the same values as \
         P2P, a prediction past the floor at the floor), and the RMSE is sqrt(mean over the \
         links of (model's line(d_i) − measured line(d_i))²): how far the model's trend is \
         from the measured trend where the links are. 3GPP is its own line: its formula's \
         value at each link against the measured line. The gap between two least-squares \
         lines fitted to the same links is the least-squares line of the P2P errors, so a \
         fitted model's PD and CI RMSE are never above its P2P RMSE on those links."
            .to_string(),
    ];
    if carriers > 1.0 {
        out.push(
            "The links have more than one carrier: the lines are fitted per carrier (a PD \
             line's intercept holds the carrier's free-space loss), each carrier's PD and CI \
             RMSE has its own row, and the pooled PD and CI RMSE is the RMS over all links of \
             their own carrier's gap: sqrt(Σ n_f RMSE_f² / Σ n_f)."
                .to_string(),
        );
    } else {
        out.push(
            "One carrier: the lines are fitted to all the links together (with several \
             carriers they are fitted per carrier, each with its own row, and pooled as the \
             RMS over all links)."
                .to_string(),
        );
    }
    out.push(
        "Measured about the model's line: sqrt(mean (PL_meas,i − model's line(d_i))²), the \
         other way a trend-line RMSE is read. It is never below σ, the RMS of the measurements \
         about their own line (the shadow fading of Sun et al.), which is the same for every \
         model: it measures how far the site's path loss is from one line, more than the model."
            .to_string(),
    );
    if let (Some(b), Some(sigma)) = (get("pd_beta_measured"), get("pd_sigma_measured_db")) {
        let mut site = format!(
            "On this site the measured PD line has slope β = {b:.2} with σ = {sigma:.2} dB \
             about it"
        );
        if let (Some(bl), Some(bn), Some(nl), Some(nn)) = (
            get("los/pd_beta_measured"),
            get("nlos/pd_beta_measured"),
            get("los/n"),
            get("nlos/n"),
        ) {
            site.push_str(&format!(
                "; fitted apart, the {nl:.0} LOS links have β = {bl:.2} (σ = {:.2} dB) and the \
                 {nn:.0} NLOS links β = {bn:.2} (σ = {:.2} dB): one line through both spans the \
                 step from LOS near the transmitter to NLOS far from it, hence its slope and \
                 scatter",
                get("los/pd_sigma_measured_db").unwrap_or(f64::NAN),
                get("nlos/pd_sigma_measured_db").unwrap_or(f64::NAN),
            ));
        }
        site.push('.');
        out.push(site);
    }
    out.push(
        "LOS/NLOS rows group the links by the measurements' LOS flag where known, else by one \
         stated reference trace, the same for every model."
            .to_string(),
    );
    if let Some((b, g)) = evals
        .iter()
        .find_map(|e| Some((e.get("split/block_m")?, e.get("split/guard_m")?)))
    {
        out.push(format!(
            "Split: the receivers are divided by a checkerboard of {b} m blocks in the site's \
             CRS; the offsets are fitted on the even blocks (the training half) and every figure \
             of Table 1 is computed on the odd ones (held out); a receiver within {g} m of its \
             block's edge is in neither half. \"links scored\" counts the held-out links; the \
             table under this list says where the others went. The plots and links.csv show \
             every link, with its half in links.csv."
        ));
    }
    out
}

/// The definitions as Markdown under Table 1.
fn definitions_markdown(defs: &[String]) -> String {
    let mut md = String::from("How each figure is computed:\n\n");
    for d in defs {
        md.push_str(&format!("- {d}\n"));
    }
    md
}

/// What report.html is made of besides its plots.
struct PageInputs<'a> {
    p: &'a ReportParams,
    /// Text under a plot, by its file.
    plot_notes: &'a [(&'a str, String)],
    intro: &'a str,
    definitions: &'a [String],
    meas: &'a Measurements,
    preds: &'a [&'a Measurements],
    evals: &'a [&'a Metrics],
    scenes: &'a [&'a Scene],
    radio_map: Option<&'a Raster>,
    evidence: &'a [(&'a str, &'a Metrics)],
}

impl PageInputs<'_> {
    /// report.html: the table, the PNG plots among `plots`, and the 3D view of the scenes (named
    /// by `scene_names`, else "scene 1", ...) with the radio map and the links.
    fn html(&self, plots: &[(String, Vec<u8>)]) -> Result<String, String> {
        let p = self.p;
        let names: Vec<String> = (0..self.scenes.len())
            .map(|k| {
                p.scene_names
                    .get(k)
                    .cloned()
                    .unwrap_or_else(|| format!("scene {}", k + 1))
            })
            .collect();
        let named: Vec<(&str, &Scene)> = names
            .iter()
            .map(String::as_str)
            .zip(self.scenes.iter().copied())
            .collect();
        let points = link_points(self.meas, self.preds, self.evals);
        let plot_names: Vec<&str> = plots
            .iter()
            .map(|(n, _)| n.as_str())
            .filter(|n| n.ends_with(".png"))
            .collect();
        report_html(&Page {
            site: &p.site,
            intro: self.intro,
            definitions: self.definitions,
            models: &p.models,
            table: &table_rows(self.evals),
            left_out: &left_out_rows(self.evals),
            plots: &plot_names,
            plot_notes: self.plot_notes,
            scenes: &named,
            radio_map: self.radio_map,
            points: &points,
            evidence: self.evidence,
        })
    }
}

/// The `evidence` reports with their names (`evidence_names`, else "evidence 1", ...).
fn named_evidence<'a>(
    p: &ReportParams,
    evidence: Vec<&'a Metrics>,
) -> Result<Vec<(String, &'a Metrics)>, StageError> {
    if !p.evidence_names.is_empty() && p.evidence_names.len() != evidence.len() {
        return Err(StageError::Failed(format!(
            "{} evidence names for {} evidence reports: name each report, or none",
            p.evidence_names.len(),
            evidence.len()
        )));
    }
    Ok(evidence
        .into_iter()
        .enumerate()
        .map(|(k, m)| {
            let name = p.evidence_names.get(k).cloned();
            (name.unwrap_or_else(|| format!("evidence {}", k + 1)), m)
        })
        .collect())
}

/// report.md's "Stage evidence": one table per stage report; nothing without any.
fn evidence_markdown(evidence: &[(&str, &Metrics)]) -> String {
    let mut md = String::new();
    if evidence.is_empty() {
        return md;
    }
    md.push_str("## Stage evidence\n\nWhat each stage did, from its own reports.\n\n");
    for (name, m) in evidence {
        let fitted = calibration::report_rows(m);
        if !fitted.is_empty() {
            md.push_str(&format!(
                "### {name}: calibrated parameters\n\n| {} |\n|{}\n",
                calibration::REPORT_COLUMNS.join(" | "),
                "---|".repeat(calibration::REPORT_COLUMNS.len())
            ));
            for row in fitted {
                md.push_str(&format!("| {} |\n", row.join(" | ")));
            }
            md.push('\n');
        }
        md.push_str(&format!("### {name}\n\n| figure | value |\n|---|---:|\n"));
        for (k, v) in &m.values {
            md.push_str(&format!("| {k} | {} |\n", number(*v)));
        }
        md.push('\n');
    }
    md
}

/// Why links are not in a model's scores, as Evaluate counts them: (metric, label). Shown when
/// some evaluation has a split, windows or footprints (`left_out_rows`); together with the
/// scored links they account for every measured link that has a measurement.
const LEFT_OUT: [(&str, &str); 8] = [
    ("links_outside_window", "outside every window"),
    ("links_in_footprint", "inside a building footprint"),
    ("links_guard", "in a split's guard band"),
    ("links_train", "in the training half (fit the offsets)"),
    (
        "links_no_offset",
        "held out, but the cell has no training link",
    ),
    ("links_unpredicted", "no value from the model"),
    ("links_no_path", "no path found by the model"),
    ("links_scored", "scored"),
];

/// The "left out" table's rows: every [`LEFT_OUT`] count some model has, a dash where a model
/// has none; no rows when no evaluation has a split, windows or footprints (the table would
/// only repeat Table 1).
fn left_out_rows(evals: &[&Metrics]) -> Vec<TableRow> {
    let any = |k: &str| evals.iter().any(|e| e.get(k).is_some());
    if !["links_outside_window", "links_in_footprint", "links_guard"]
        .iter()
        .any(|k| any(k))
    {
        return Vec::new();
    }
    LEFT_OUT
        .iter()
        .filter(|(k, _)| any(k))
        .map(|(k, label)| TableRow {
            label: label.to_string(),
            values: evals
                .iter()
                .map(|e| e.get(k).map_or("–".into(), |v| format!("{v:.0}")))
                .collect(),
            best: None,
        })
        .collect()
}

/// report.md's table of links left out, per model; nothing without a split, windows or
/// footprints.
fn left_out_markdown(p: &ReportParams, evals: &[&Metrics]) -> String {
    let rows = left_out_rows(evals);
    if rows.is_empty() {
        return String::new();
    }
    let mut md = format!(
        "## Links left out of the scores

| links | {} |
|---|{}
",
        p.models.join(" | "),
        "---:|".repeat(p.models.len())
    );
    for r in rows {
        md.push_str(&format!(
            "| {} | {} |
",
            r.label,
            r.values.join(" | ")
        ));
    }
    md.push('\n');
    md
}

/// Table 1's rows for report.html: the rows some model has, the best RMSE of each marked.
fn table_rows(evals: &[&Metrics]) -> Vec<TableRow> {
    table_keys(evals)
        .into_iter()
        .filter_map(|(key, label)| {
            let key = key.as_str();
            let vals: Vec<Option<f64>> = evals.iter().map(|e| e.get(key)).collect();
            if vals.iter().all(Option::is_none) {
                return None;
            }
            let best = key.ends_with("rmse_db").then(|| {
                vals.iter()
                    .enumerate()
                    .filter_map(|(i, v)| v.map(|v| (i, v)))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|x| x.0)
            });
            Some(TableRow {
                label,
                values: vals
                    .iter()
                    .map(|v| match v {
                        Some(v) if COUNT_ROWS.contains(&key) => format!("{v:.0}"),
                        Some(v) => format!("{v:.2}"),
                        None => "–".into(),
                    })
                    .collect(),
                best: best.flatten(),
            })
        })
        .collect()
}

/// Every measured link at its receiver, with the measurement (the first model's offset taken
/// out) and each model's prediction, for the 3D view.
fn link_points(meas: &Measurements, preds: &[&Measurements], evals: &[&Metrics]) -> Vec<LinkPoint> {
    meas.links
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let offset = evals.first().map_or(0.0, |e| tx_offset(e, &m.tx.id));
            let z = match m.rx.z {
                Height::Absolute(z) => z,
                Height::AboveGround(_) => 0.0,
            };
            LinkPoint {
                at: [m.rx.x, m.rx.y, z],
                measured: measured_loss(m).map(|v| v - offset),
                predicted: preds
                    .iter()
                    .map(|pr| {
                        pr.links
                            .get(k)
                            .and_then(|l| l.path_loss_db)
                            .filter(|v| v.is_finite())
                    })
                    .collect(),
            }
        })
        .collect()
}

/// Table 1 as Markdown (the best RMSE of each row in bold) and CSV.
fn tables(p: &ReportParams, evals: &[&Metrics]) -> (String, String) {
    let mut md = format!(
        "| site | metric | {} |\n|---|---|{}\n",
        p.models.join(" | "),
        "---|".repeat(p.models.len())
    );
    let mut csv = format!("site,metric,{}\n", csv_text::row(&p.models));
    for row in table_rows(evals) {
        let shown: Vec<String> = row
            .values
            .iter()
            .enumerate()
            .map(|(i, v)| {
                if row.best == Some(i) {
                    format!("**{v}**")
                } else {
                    v.clone()
                }
            })
            .collect();
        md.push_str(&format!(
            "| {} | {} | {} |\n",
            p.site,
            row.label,
            shown.join(" | ")
        ));
        let cells = [p.site.clone(), row.label].into_iter().chain(row.values);
        csv.push_str(&csv_text::row(&cells.collect::<Vec<_>>()));
        csv.push('\n');
    }
    (md, csv)
}

/// Every measured link, one row each, as the evaluations scored it: where it is, the measured
/// path loss, its half of the split (the first evaluation's that has one, by the same rule;
/// empty without a split), and per model the prediction (at most the floor), the offset taken
/// out of its transmitter's measurements, and the error against the measurement with it taken
/// out; empty where a model was not scored there or fitted no offset for that transmitter.
/// Beside the site frame, each end's WGS 84 longitude and latitude (degrees, 8 decimals), for a
/// GIS. The split's blocks are in the site's CRS.
///
/// Links left out by Evaluate's `windows` or `exclude_footprints` are not marked (its metrics
/// only count them): their half is where the block rule puts them.
fn links_csv(
    models: &[String],
    meas: &Measurements,
    preds: &[&Measurements],
    evals: &[&Metrics],
    site: &Site,
) -> Result<String, String> {
    use crate::io::crs::{Crs, ToSite};
    let wgs84 = ToSite::new(&Crs::from_epsg(4326)?, site)?;
    let origin = site.origin;
    let mut header: Vec<String> = [
        "tx_id",
        "rx_id",
        "tx_x",
        "tx_y",
        "rx_x",
        "rx_y",
        "tx_lon",
        "tx_lat",
        "rx_lon",
        "rx_lat",
        "distance_m",
        "freq_hz",
        "los",
        "half",
        "measured_db",
    ]
    .map(String::from)
    .into();
    for m in models {
        header.push(format!("{m} predicted_db"));
        header.push(format!("{m} error_db"));
        header.push(format!("{m} offset_db"));
    }
    let split = evals
        .iter()
        .find_map(|e| Some((e.get("split/block_m")?, e.get("split/guard_m")?)));
    let mut out = csv_text::row(&header) + "\n";
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.3}"));
    for (k, m) in meas.links.iter().enumerate() {
        let measured = measured_loss(m);
        let (tx_lon, tx_lat) = wgs84.inverse(m.tx.x, m.tx.y)?;
        let (rx_lon, rx_lat) = wgs84.inverse(m.rx.x, m.rx.y)?;
        let mut row = vec![
            m.tx.id.clone(),
            m.rx.id.clone(),
            format!("{:.3}", m.tx.x),
            format!("{:.3}", m.tx.y),
            format!("{:.3}", m.rx.x),
            format!("{:.3}", m.rx.y),
            format!("{tx_lon:.8}"),
            format!("{tx_lat:.8}"),
            format!("{rx_lon:.8}"),
            format!("{rx_lat:.8}"),
            format!("{:.3}", link_distance(m, None)),
            format!("{}", m.freq_hz),
            m.los.map_or(String::new(), |l| u8::from(l).to_string()),
            split.map_or(String::new(), |(block_m, guard_m)| {
                half(m, origin, block_m, guard_m).name().to_string()
            }),
            opt(measured),
        ];
        for (pr, ev) in preds.iter().zip(evals) {
            let predicted = pr.links.get(k).and_then(|l| scored_prediction(l, ev));
            let offset = fitted_offset(ev, &m.tx.id);
            let error = predicted
                .zip(measured)
                .zip(offset)
                .map(|((p, q), o)| p - (q - o));
            row.push(opt(predicted));
            row.push(opt(error));
            row.push(opt(offset.filter(|_| fits_offsets(ev))));
        }
        out += &csv_text::row(&row);
        out.push('\n');
    }
    Ok(out)
}

/// A prediction as Evaluate scores it: beyond the floor (or no path) it is the floor; without a
/// floor, no path is no score; NaN is no score.
fn scored_prediction(l: &Link, ev: &Metrics) -> Option<f64> {
    l.path_loss_db
        .filter(|v| !v.is_nan())
        .and_then(|v| match ev.get("floor_db") {
            Some(f) => Some(v.min(f)),
            None => v.is_finite().then_some(v),
        })
}

/// The receiver's half of the split of `block_m` blocks and `guard_m` guard, in the site CRS.
fn half(l: &Link, origin: (f64, f64), block_m: f64, guard_m: f64) -> Half {
    block_half(l.rx.x + origin.0, l.rx.y + origin.1, block_m, guard_m)
}

/// Evaluate fitted offsets (the EIRP was unknown).
fn fits_offsets(ev: &Metrics) -> bool {
    ev.values.keys().any(|k| k.starts_with("offset_db/"))
}

/// The offset taken out of transmitter `tx`'s measurements: 0 when Evaluate fitted none at all,
/// `None` when it fitted some but none for `tx` (a split whose training half misses `tx`).
fn fitted_offset(ev: &Metrics, tx: &str) -> Option<f64> {
    match ev.get(&format!("offset_db/{tx}")) {
        Some(v) => Some(v),
        None if fits_offsets(ev) => None,
        None => Some(0.0),
    }
}

/// The offset taken out of transmitter `tx`'s measurements while its EIRP is unknown (0 when
/// Evaluate fitted none).
fn tx_offset(ev: &Metrics, tx: &str) -> f64 {
    ev.get(&format!("offset_db/{tx}")).unwrap_or(0.0)
}

/// Each scored link as ((distance, measured with the offset taken out, predicted), frequency).
fn pairs(meas: &Measurements, pred: &Measurements, ev: &Metrics) -> Vec<((f64, f64, f64), f64)> {
    meas.links
        .iter()
        .zip(&pred.links)
        .filter_map(|(m, p)| {
            let offset = tx_offset(ev, &m.tx.id);
            Some((
                (
                    link_distance(m, None),
                    measured_loss(m)? - offset,
                    scored_prediction(p, ev)?,
                ),
                m.freq_hz,
            ))
        })
        .collect()
}

/// The measurements are received power without the transmitters' EIRP (a drive test's RSRP:
/// no link gives a path loss or an EIRP) and the first evaluation fitted offsets: the
/// path-loss chart is then drawn in received power.
fn received_power_only(meas: &Measurements, evals: &[&Metrics]) -> bool {
    evals.first().is_some_and(|e| fits_offsets(e))
        && meas.links.iter().any(|l| l.rx_power_dbm.is_some())
        && meas
            .links
            .iter()
            .all(|l| l.path_loss_db.is_none() && l.tx_eirp_dbm.is_none())
}

/// The received-power chart's values, `None` unless [`received_power_only`]: every reading's
/// received power as read; per model each scored link at EIRP_fit − PL_pred, where EIRP_fit =
/// −offset_db/<tx> (Evaluate's offset is the mean of measured − predicted path loss, and the
/// measured path loss is −RSRP here), links of a transmitter the model fitted no offset for left
/// out; and one free-space line per transmitter at the first model's EIRP_fit, at the median
/// carrier of its links.
fn power_distance(
    models: &[String],
    meas: &Measurements,
    preds: &[&Measurements],
    evals: &[&Metrics],
) -> Option<PowerDistance> {
    if !received_power_only(meas, evals) {
        return None;
    }
    let rsrp = |l: &Link| l.rx_power_dbm.filter(|v| v.is_finite());
    let measured = meas
        .links
        .iter()
        .filter_map(|l| Some((link_distance(l, None), rsrp(l)?)))
        .collect();
    let series = models
        .iter()
        .zip(preds)
        .zip(evals)
        .map(|((name, pr), ev)| {
            let pts = meas
                .links
                .iter()
                .zip(&pr.links)
                .filter_map(|(m, l)| {
                    rsrp(m)?;
                    let eirp = -fitted_offset(ev, &m.tx.id)?;
                    Some((link_distance(m, None), eirp - scored_prediction(l, ev)?))
                })
                .collect();
            (name.clone(), pts)
        })
        .collect();
    let mut freqs: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for l in &meas.links {
        freqs.entry(&l.tx.id).or_default().push(l.freq_hz);
    }
    let first = evals[0];
    let free_space = freqs
        .into_iter()
        .filter_map(|(tx, f)| {
            let off = first.get(&format!("offset_db/{tx}"))?;
            Some((tx.to_string(), -off, median(&f)))
        })
        .collect();
    Some(PowerDistance {
        measured,
        models: series,
        free_space,
        free_space_from: models.first().cloned().unwrap_or_default(),
    })
}

/// The text under the received-power chart: what is drawn, and every offset applied.
fn power_distance_note(pd: &PowerDistance, models: &[String], evals: &[&Metrics]) -> String {
    let split = evals.iter().any(|e| e.get("split/block_m").is_some());
    let per_model: Vec<String> = models
        .iter()
        .zip(evals)
        .map(|(name, ev)| {
            let cells: Vec<String> = ev
                .values
                .iter()
                .filter_map(|(k, v)| {
                    let tx = k.strip_prefix("offset_db/")?;
                    Some(format!("{tx} {:.2}", -v))
                })
                .collect();
            if cells.is_empty() {
                format!("{name}: none fitted (EIRP 0 dBm)")
            } else {
                format!("{name}: {}", cells.join(", "))
            }
        })
        .collect();
    format!(
        "Received power against distance. The measurements are received power (RSRP) without \
         the transmitters' EIRP, so this chart is drawn in received power, not path loss: the \
         grey points are the {} readings as read (dBm, no offset applied); each model's points \
         are RSRP = EIRP_fit − PL_pred at the links it scored, EIRP_fit being that model's own \
         fitted EIRP per transmitter, EIRP_fit = −offset_db/<tx> (Evaluate's offset is the mean \
         of measured − predicted path loss{}, with measured path loss = −RSRP; with RSRP, EIRP_fit \
         is per resource element, like RSRP, and takes in antenna gains the model leaves out). \
         The dashed lines \
         are free space, EIRP_fit − FSPL(f, d), one per transmitter ({} lines, one legend entry: \
         per-cell labels would crowd the legend), at the EIRP fitted for {}, each at its \
         transmitter's carrier. EIRP_fit applied (dBm) — {}. The power-distance and close-in \
         lines are path-loss lines and are not drawn here: the cells' EIRPs differ; Table 1 \
         gives their RMSE.",
        pd.measured.len(),
        if split { ", on the training half" } else { "" },
        pd.free_space.len(),
        pd.free_space_from,
        per_model.join("; ")
    )
}

/// Each model's links and trend lines, for the charts: the lines Evaluate fitted to its
/// predictions (its metrics), with several carriers the lowest carrier's; a model that is its own
/// line (3GPP) gets the lines fitted to its values here, for the eye. The close-in line is drawn
/// at that carrier's frequency (else the links' median).
fn model_series<'a>(
    p: &'a ReportParams,
    series: &'a [Vec<(f64, f64, f64)>],
    freqs: &[Vec<f64>],
    evals: &[&Metrics],
) -> Vec<ModelSeries<'a>> {
    p.models
        .iter()
        .zip(series)
        .zip(freqs)
        .zip(evals)
        .map(|(((name, links), f), ev)| {
            let d: Vec<f64> = links.iter().map(|x| x.0).collect();
            let pl: Vec<f64> = links.iter().map(|x| x.2).collect();
            let (trend, close_in) = match evaluated_lines(ev, "", f) {
                Some((pd, ci)) => (Some(pd), Some(ci)),
                None => (
                    (links.len() >= 2).then(|| fit_power_distance(&d, &pl)),
                    (!links.is_empty())
                        .then(|| (fspl_db(1.0, median(f)), fit_close_in(&d, &pl, f))),
                ),
            };
            ModelSeries {
                name,
                links,
                trend,
                close_in,
            }
        })
        .collect()
}

/// The median of `v` (upper middle; 0 when empty).
fn median(v: &[f64]) -> f64 {
    let mut sorted = v.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.get(sorted.len() / 2).copied().unwrap_or(0.0)
}

/// The PD line (α, β) and the CI line (FSPL(f, 1 m), n) an evaluation gives, the model's
/// (`suffix` "") or the measurements' (`suffix` "_measured"): with one carrier its own, with
/// several the lowest carrier's; `None` when it gives none.
fn evaluated_lines(ev: &Metrics, suffix: &str, freqs: &[f64]) -> Option<((f64, f64), (f64, f64))> {
    let alpha = format!("pd_alpha{suffix}_db");
    let beta = format!("pd_beta{suffix}");
    let n = format!("ci_n{suffix}");
    if let (Some(a), Some(b), Some(n)) = (ev.get(&alpha), ev.get(&beta), ev.get(&n)) {
        return Some(((a, b), (fspl_db(1.0, median(freqs)), n)));
    }
    let lowest = freqs.iter().copied().fold(f64::INFINITY, f64::min);
    if !lowest.is_finite() {
        return None;
    }
    let at = format!("f/{}/", crate::artifact::carrier_label(lowest));
    let get = |k: &str| ev.get(&format!("{at}{k}"));
    Some((
        (get(&alpha)?, get(&beta)?),
        (fspl_db(1.0, lowest), get(&n)?),
    ))
}

/// The radio map colour-mapped over the orthophoto at the finer of the two resolutions, with a
/// colour bar and a scale bar.
fn map_figure(map: &Raster, ortho: Option<&Ortho>) -> Result<Figure, String> {
    let cells: Vec<f64> = std::iter::once(map.grid.cell_m)
        .chain(ortho.map(|o| o.grid.cell_m))
        .collect();
    let layer = Layer {
        raster: map,
        palette: Palette::Viridis,
        range: robust_range(map, Palette::Viridis),
        alpha: if ortho.is_some() { 0.65 } else { 1.0 },
        units: "path gain (dB)".into(),
    };
    render(&MapFigure::new(
        "Radio map".into(),
        view_grid(&map.grid, &cells),
        ortho,
        Some(layer),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With two carriers, each carrier's PD and CI rows follow the pooled CI row, lowest carrier
    /// first (16.95 sorts after 6.75 by frequency, not by text), and the definitions say how the
    /// pooled figure is made.
    #[test]
    fn carriers_get_their_own_rows_in_order_of_frequency() {
        let mut m = Metrics::default();
        for (k, v) in [
            ("pd_rmse_db", 3.0),
            ("ci_rmse_db", 3.5),
            ("carriers", 2.0),
            ("f/16.95GHz/pd_rmse_db", 4.0),
            ("f/16.95GHz/ci_rmse_db", 4.5),
            ("f/6.75GHz/pd_rmse_db", 2.0),
            ("f/6.75GHz/ci_rmse_db", 2.5),
        ] {
            m.set(k, v);
        }
        let keys: Vec<String> = table_keys(&[&m]).into_iter().map(|k| k.0).collect();
        let at = |k: &str| keys.iter().position(|x| x == k).unwrap();
        assert_eq!(at("f/6.75GHz/pd_rmse_db"), at("ci_rmse_db") + 1);
        assert_eq!(at("f/6.75GHz/ci_rmse_db"), at("ci_rmse_db") + 2);
        assert_eq!(at("f/16.95GHz/pd_rmse_db"), at("ci_rmse_db") + 3);
        let rows = table_rows(&[&m]);
        let row = rows
            .iter()
            .find(|r| r.label == "PD RMSE at 16.95GHz (dB)")
            .unwrap();
        assert_eq!(row.values, vec!["4.00".to_string()]);
        let defs = definitions(&[&m]).join("\n");
        assert!(defs.contains("fitted per carrier"), "{defs}");
        assert!(!defs.contains("rf.md"), "{defs}");
    }

    /// Received power without EIRP: the readings as read, each model at −its offset − its
    /// prediction, free space at the first model's EIRP per transmitter, by hand.
    #[test]
    fn received_power_chart_puts_each_model_at_its_fitted_eirp() {
        use crate::artifact::Endpoint;
        let end = |id: &str, x: f64, y: f64| Endpoint {
            id: id.into(),
            x,
            y,
            z: Height::Absolute(0.0),
            azimuth_deg: None,
        };
        let reading = |tx: &str, rx: (f64, f64), f: f64, rsrp: Option<f64>| Link {
            tx: end(tx, 0.0, 0.0),
            rx: end("", rx.0, rx.1),
            freq_hz: f,
            path_loss_db: None,
            rx_power_dbm: rsrp,
            tx_eirp_dbm: None,
            los: None,
        };
        let predicted = |l: &Link, pl: Option<f64>| Link {
            path_loss_db: pl,
            rx_power_dbm: None,
            ..l.clone()
        };
        let meas = Measurements {
            links: vec![
                reading("a", (100.0, 0.0), 3.5e9, Some(-80.0)),
                reading("b", (0.0, 200.0), 1.9e9, Some(-90.0)),
                reading("a", (300.0, 0.0), 3.5e9, None),
            ],
        };
        let pred = |pl: [Option<f64>; 3]| Measurements {
            links: meas
                .links
                .iter()
                .zip(pl)
                .map(|(l, v)| predicted(l, v))
                .collect(),
        };
        let (pm, pn) = (
            pred([Some(110.0), Some(120.0), Some(130.0)]),
            pred([Some(105.0), Some(100.0), Some(130.0)]),
        );
        // Evaluate's offsets are measured − predicted path loss, the measured loss −RSRP: an
        // offset of −30 dB is an EIRP of 30 dBm. N fitted none for b (its training half had none).
        let metrics = |kv: &[(&str, f64)]| {
            let mut m = Metrics::default();
            for (k, v) in kv {
                m.set(*k, *v);
            }
            m
        };
        let em = metrics(&[("offset_db/a", -30.0), ("offset_db/b", -28.0)]);
        let en = metrics(&[("offset_db/a", -25.0)]);
        let models = ["M".to_string(), "N".to_string()];
        let pd = power_distance(&models, &meas, &[&pm, &pn], &[&em, &en]).unwrap();
        // The readings as read; the third has no reading, so no point for any model.
        assert_eq!(pd.measured, [(100.0, -80.0), (200.0, -90.0)]);
        assert_eq!(
            pd.models[0],
            ("M".into(), vec![(100.0, -80.0), (200.0, -92.0)])
        );
        assert_eq!(pd.models[1], ("N".into(), vec![(100.0, -80.0)]));
        // Free space at the first model's EIRP per transmitter, at its carrier.
        assert_eq!(
            pd.free_space,
            [("a".into(), 30.0, 3.5e9), ("b".into(), 28.0, 1.9e9)]
        );
        assert_eq!(pd.free_space_from, "M");
        let note = power_distance_note(&pd, &models, &[&em, &en]);
        for want in ["M: a 30.00, b 28.00", "N: a 25.00", "2 readings as read"] {
            assert!(note.contains(want), "{want:?} not in {note}");
        }
        let fig = render(&ReceivedPowerDistance(&pd)).unwrap();
        for want in [
            "received power, RSRP (dBm)",
            "free space at each cell&apos;s EIRP fitted for M",
            "measured RSRP (as read)",
        ] {
            assert!(
                fig.svg.contains(want) || fig.svg.contains(&want.replace("&apos;", "'")),
                "no {want:?} in the SVG"
            );
        }
        // With the EIRP known, or with no offsets fitted, the path-loss chart as before.
        let mut known = meas.clone();
        known.links[0].tx_eirp_dbm = Some(30.0);
        assert!(power_distance(&models, &known, &[&pm, &pn], &[&em, &en]).is_none());
        let none = Metrics::default();
        assert!(power_distance(&models, &meas, &[&pm, &pn], &[&none, &en]).is_none());
    }

    /// links.csv: each model's offset next to its error, empty (and no error) for a transmitter
    /// the split gave no training link; the half by the block rule in the site CRS (origin
    /// (1000, -200): the receiver at the frame's (-950, 250) is at (50, 50), block (0, 0),
    /// training; at (-850, 250) it is at (150, 50), held out).
    #[test]
    fn links_csv_has_offsets_and_halves() {
        use crate::artifact::Endpoint;
        let end = |id: &str, x: f64, y: f64| Endpoint {
            id: id.into(),
            x,
            y,
            z: Height::Absolute(0.0),
            azimuth_deg: None,
        };
        let link = |tx: &str, x: f64, pl: f64| Link {
            tx: end(tx, -1000.0, 0.0),
            rx: end("", x, 250.0),
            freq_hz: 3.5e9,
            path_loss_db: Some(pl),
            rx_power_dbm: None,
            tx_eirp_dbm: None,
            los: None,
        };
        let meas = Measurements {
            links: vec![link("a", -950.0, 100.0), link("b", -850.0, 100.0)],
        };
        let pred = Measurements {
            links: vec![link("a", -950.0, 90.0), link("b", -850.0, 95.0)],
        };
        let mut ev = Metrics::default();
        for (k, v) in [
            ("offset_db/a", 12.0),
            ("split/block_m", 100.0),
            ("split/guard_m", 5.0),
            ("links_guard", 0.0),
            ("links_scored", 1.0),
        ] {
            ev.set(k, v);
        }
        let utm = |origin| Site {
            crs: "EPSG:32618".into(),
            origin,
            cell_m: 1.0,
        };
        let csv = links_csv(
            &["M".into()],
            &meas,
            &[&pred],
            &[&ev],
            &utm((1000.0, -200.0)),
        )
        .unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert!(
            lines[0].ends_with("los,half,measured_db,M predicted_db,M error_db,M offset_db"),
            "{}",
            lines[0]
        );
        assert!(
            lines[1].ends_with(",train,100.000,90.000,2.000,12.000"),
            "{}",
            lines[1]
        );
        assert!(
            lines[2].ends_with(",held_out,100.000,95.000,,"),
            "{}",
            lines[2]
        );
        // Without a split or offsets: no half, no offset, the error as before.
        let csv = links_csv(
            &["M".into()],
            &meas,
            &[&pred],
            &[&Metrics::default()],
            &utm((500_000.0, 4_427_757.22)),
        )
        .unwrap();
        // The transmitter at the frame's (-1000, 0) from an origin on UTM 18N's central meridian
        // at 40° N: 1 km west is 0.0117151° of longitude to first order (1000 m / (k0 N cos 40°),
        // k0 = 0.9996, N = 6386976 m the WGS 84 prime vertical radius there), the latitude
        // within a micro-degree.
        let row: Vec<&str> = csv.lines().nth(1).unwrap().split(',').collect();
        let (lon, lat): (f64, f64) = (row[6].parse().unwrap(), row[7].parse().unwrap());
        assert!((lon - (-75.0 - 0.0117151)).abs() < 1e-6, "{lon}");
        assert!((lat - 40.0).abs() < 1e-5, "{lat}");
        assert!(
            csv.lines()
                .nth(1)
                .unwrap()
                .ends_with(",,100.000,90.000,-10.000,"),
            "{csv}"
        );
        // The table of links left out: only with a split, windows or footprints; a dash where a
        // model has no such count.
        assert!(left_out_rows(&[&Metrics::default()]).is_empty());
        let rows = left_out_rows(&[&ev, &Metrics::default()]);
        let labels: Vec<&str> = rows.iter().map(|r| r.label.as_str()).collect();
        assert_eq!(labels, ["in a split's guard band", "scored"]);
        assert_eq!(rows[1].values, ["1", "–"]);
        let md = left_out_markdown(
            &ReportParams {
                models: vec!["M".into(), "N".into()],
                site: "s".into(),
                scene_names: vec![],
                evidence_names: vec![],
                assumptions: vec![],
            },
            &[&ev, &Metrics::default()],
        );
        assert!(md.contains("| scored | 1 | – |"), "{md}");
    }

    #[test]
    fn assumptions_follow_the_introduction() {
        let intro = "46655 measured links.".to_string();
        assert_eq!(with_assumptions(intro.clone(), &[]), intro);
        let a = [
            "ground flat at z = 0.".to_string(),
            " antennas 12 m".to_string(),
        ];
        assert_eq!(
            with_assumptions(intro, &a),
            "46655 measured links. Assumptions, none of them published: ground flat at z = 0; \
             antennas 12 m."
        );
    }
}
