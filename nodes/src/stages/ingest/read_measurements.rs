//! Ingest of drive-test measurements (paper Sec. 5, Table 1) into the site frame.
//!
//! Two layouts:
//! - `Links`: the project's CSV, one row per link. Transmitter `tx_x, tx_y, tx_z` (site frame) or
//!   `tx_lat, tx_lon, tx_height_m` (WGS84, height above ground); the same for `rx_`; `freq_hz`;
//!   `path_loss_db`, or `rx_power_dbm` with optional `tx_eirp_dbm`; optional `tx_id`, `rx_id`,
//!   `tx_azimuth_deg`, `los` (0/1). The azimuth is a compass bearing: true north beside
//!   `tx_lat, tx_lon` (turned to grid north here), grid north beside `tx_x, tx_y` (as Export
//!   writes it). A file with both (Export writes `tx_lon, tx_lat` too, for a GIS) is read by
//!   its site-frame columns.
//! - `DukeCbrs`: the Duke CBRS drive test (`PCI, latitude, longitude, device, rsrp`) with its cells
//!   file (`{"cells": [{"pci", "lat", "lon", "azimuth_deg", "freq_hz"}]}`): RSRP as received power,
//!   EIRP unknown, transmitter and receiver heights from the params (not published). The cells'
//!   azimuths are true bearings, turned to grid bearings here.
//!
//! Every `Endpoint::azimuth_deg` read is a grid bearing (clockwise from the site frame's +y):
//! a true bearing less the meridian convergence at the transmitter (`ToSite::convergence_deg`).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::artifact::{Endpoint, Height, Link, Measurements};
use crate::io::crs::{Crs, ToSite};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Which file layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Layout {
    /// The project's CSV layout (module docs).
    Links,
    /// The Duke CBRS drive test with its cells file.
    DukeCbrs {
        /// The cells JSON.
        cells: String,
        /// Antenna height above ground of every cell, metres (not published). Default 20.
        #[serde(default = "default_tx_height")]
        tx_height_m: f64,
        /// Heights of single cells by PCI, overriding `tx_height_m` for them, e.g. the antennas
        /// of two sites on roofs of different heights. Every key must be a cell of the file.
        #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
        tx_heights_m: BTreeMap<String, f64>,
        /// Phone height above ground, metres. Default 1.5.
        #[serde(default = "default_rx_height")]
        rx_height_m: f64,
    },
}

/// The highest antenna above ground a layout may state: above the tallest masts.
const MAX_ANTENNA_HEIGHT_M: f64 = 1000.0;

fn default_tx_height() -> f64 {
    20.0
}
fn default_rx_height() -> f64 {
    1.5
}

/// Params of [`ReadMeasurements`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadMeasurementsParams {
    /// The CSV file.
    pub path: String,
    /// Its layout. Default `Links`.
    #[serde(default = "links")]
    pub layout: Layout,
}

fn links() -> Layout {
    Layout::Links
}

/// Reads measured links into the site frame.
pub struct ReadMeasurements;

impl Stage for ReadMeasurements {
    const KIND: &'static str = "ReadMeasurements";
    // 2: DukeCbrs `tx_heights_m`, heights by cell; azimuths read as true bearings become grid
    // bearings (less the meridian convergence).
    // 3: the same, renumbered: the two changes were each numbered 2 on their own branches, so a
    // cache filled by either branch must not answer for both.
    const VERSION: u32 = 3;
    const DOC: &'static str =
        "drive-test measurements CSV (links, or the Duke CBRS layout) into the site frame, Sec. 5";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadMeasurementsParams;
    type Output = Measurements;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if let Layout::DukeCbrs {
            tx_height_m,
            tx_heights_m,
            rx_height_m,
            ..
        } = &p.layout
        {
            let heights = [*tx_height_m, *rx_height_m]
                .into_iter()
                .chain(tx_heights_m.values().copied());
            for h in heights {
                if !(0.0..=MAX_ANTENNA_HEIGHT_M).contains(&h) {
                    return Err(ParamError::new(
                        "layout",
                        format!(
                            "expected antenna heights from 0 to {MAX_ANTENNA_HEIGHT_M} m above \
                             ground, found {h}"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        let mut f = vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }];
        if let Layout::DukeCbrs { cells, .. } = &p.layout {
            f.push(FileRef {
                field: "layout",
                path: cells.clone(),
            });
        }
        f
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Measurements, StageError> {
        let path = ctx.file(0)?;
        let wgs84 = ToSite::new(&Crs::from_epsg(4326).expect("EPSG:4326 is known"), ctx.site)
            .map_err(StageError::Failed)?;
        match &p.layout {
            Layout::Links => read_links(path, &wgs84),
            Layout::DukeCbrs {
                tx_height_m,
                tx_heights_m,
                rx_height_m,
                ..
            } => {
                let heights = CellHeights {
                    all: *tx_height_m,
                    by_pci: tx_heights_m,
                };
                read_duke(path, ctx.file(1)?, &wgs84, &heights, *rx_height_m)
            }
        }
    }
}

/// A CSV file's header and records, with errors that name the file, line and column.
struct Table<'a> {
    path: &'a Path,
    columns: HashMap<String, usize>,
    names: Vec<String>,
}

impl<'a> Table<'a> {
    fn open(path: &'a Path) -> Result<(Table<'a>, csv::Reader<std::fs::File>), StageError> {
        let mut r = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_path(path)
            .map_err(|e| StageError::bad_input(path, "open", e.to_string()))?;
        let names: Vec<String> = r
            .headers()
            .map_err(|e| StageError::bad_input(path, "header", e.to_string()))?
            .iter()
            .map(str::to_owned)
            .collect();
        let mut columns = HashMap::new();
        for (i, n) in names.iter().enumerate() {
            if let Some(first) = columns.insert(n.clone(), i) {
                // Which of the two a later lookup would get is arbitrary: refuse rather than guess.
                return Err(StageError::bad_input(
                    path,
                    "header",
                    format!(
                        "expected each column once; `{n}` is columns {} and {}",
                        first + 1,
                        i + 1
                    ),
                ));
            }
        }
        Ok((
            Table {
                path,
                columns,
                names,
            },
            r,
        ))
    }
    fn has(&self, name: &str) -> bool {
        self.columns.contains_key(name)
    }
    fn require(&self, name: &str) -> Result<usize, StageError> {
        self.columns.get(name).copied().ok_or_else(|| {
            StageError::bad_input(
                self.path,
                "header",
                format!(
                    "expected a column `{name}`; found: {}",
                    self.names.join(", ")
                ),
            )
        })
    }
    fn number(&self, rec: &csv::StringRecord, line: u64, col: usize) -> Result<f64, StageError> {
        let s = rec.get(col).unwrap_or("");
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                StageError::bad_input(
                    self.path,
                    format!("line {line}, column `{}`", self.names[col]),
                    format!("expected a number, found {s:?}"),
                )
            })
    }
    fn optional_number(
        &self,
        rec: &csv::StringRecord,
        line: u64,
        col: Option<usize>,
    ) -> Result<Option<f64>, StageError> {
        match col {
            Some(c) if !rec.get(c).unwrap_or("").is_empty() => self.number(rec, line, c).map(Some),
            _ => Ok(None),
        }
    }
}

fn record(
    r: Result<csv::StringRecord, csv::Error>,
    path: &Path,
) -> Result<(csv::StringRecord, u64), StageError> {
    let rec = r.map_err(|e| {
        let place = e
            .position()
            .map(|p| format!("line {}", p.line()))
            .unwrap_or_else(|| "record".into());
        StageError::bad_input(path, place, e.to_string())
    })?;
    let line = rec.position().map(|p| p.line()).unwrap_or(0);
    Ok((rec, line))
}

/// Columns locating one endpoint (`tx` or `rx`).
enum Place {
    /// Site-frame x, y and, per row, either z or a height above ground.
    Site {
        x: usize,
        y: usize,
        z: Option<usize>,
        h: Option<usize>,
    },
    Geo {
        lat: usize,
        lon: usize,
        h: usize,
    },
}

fn place_columns(t: &Table, p: &str) -> Result<Place, StageError> {
    if t.has(&format!("{p}_x")) {
        let (z, h) = (
            t.columns.get(&format!("{p}_z")).copied(),
            t.columns.get(&format!("{p}_height_m")).copied(),
        );
        if z.is_none() && h.is_none() {
            return Err(StageError::bad_input(
                t.path,
                "header",
                format!(
                    "expected a column `{p}_z` or `{p}_height_m` beside `{p}_x`; found: {}",
                    t.names.join(", ")
                ),
            ));
        }
        Ok(Place::Site {
            x: t.require(&format!("{p}_x"))?,
            y: t.require(&format!("{p}_y"))?,
            z,
            h,
        })
    } else if t.has(&format!("{p}_lat")) {
        Ok(Place::Geo {
            lat: t.require(&format!("{p}_lat"))?,
            lon: t.require(&format!("{p}_lon"))?,
            h: t.require(&format!("{p}_height_m"))?,
        })
    } else {
        Err(StageError::bad_input(
            t.path,
            "header",
            format!(
                "expected columns {p}_x, {p}_y, {p}_z or {p}_lat, {p}_lon, {p}_height_m; found: {}",
                t.names.join(", ")
            ),
        ))
    }
}

fn endpoint(
    t: &Table,
    rec: &csv::StringRecord,
    line: u64,
    place: &Place,
    id: String,
    wgs84: &ToSite,
) -> Result<Endpoint, StageError> {
    let (x, y, z) = match *place {
        Place::Site { x, y, z, h } => {
            let height = match (
                t.optional_number(rec, line, z)?,
                t.optional_number(rec, line, h)?,
            ) {
                (Some(z), _) => Height::Absolute(z),
                (None, Some(h)) => Height::AboveGround(h),
                (None, None) => {
                    let col = z.or(h).expect("one of them exists");
                    return Err(StageError::bad_input(
                        t.path,
                        format!("line {line}, column `{}`", t.names[col]),
                        "expected a z or a height above ground",
                    ));
                }
            };
            (t.number(rec, line, x)?, t.number(rec, line, y)?, height)
        }
        Place::Geo { lat, lon, h } => {
            let (lat, lon) = (t.number(rec, line, lat)?, t.number(rec, line, lon)?);
            check_lat_lon(lat, lon)
                .map_err(|m| StageError::bad_input(t.path, format!("line {line}"), m))?;
            let (x, y, _) = wgs84
                .apply(lon, lat, 0.0)
                .map_err(|m| StageError::bad_input(t.path, format!("line {line}"), m))?;
            (x, y, Height::AboveGround(t.number(rec, line, h)?))
        }
    };
    Ok(Endpoint {
        id,
        x,
        y,
        z,
        azimuth_deg: None,
    })
}

fn read_links(path: &Path, wgs84: &ToSite) -> Result<Measurements, StageError> {
    let (t, mut r) = Table::open(path)?;
    let (tx, rx) = (place_columns(&t, "tx")?, place_columns(&t, "rx")?);
    let freq = t.require("freq_hz")?;
    let (pl, prx) = (
        t.columns.get("path_loss_db").copied(),
        t.columns.get("rx_power_dbm").copied(),
    );
    if pl.is_none() && prx.is_none() {
        return Err(StageError::bad_input(
            path,
            "header",
            format!(
                "expected a column `path_loss_db` or `rx_power_dbm`; found: {}",
                t.names.join(", ")
            ),
        ));
    }
    let (eirp, los, az) = (
        t.columns.get("tx_eirp_dbm").copied(),
        t.columns.get("los").copied(),
        t.columns.get("tx_azimuth_deg").copied(),
    );
    let id = |rec: &csv::StringRecord, name: &str| {
        t.columns
            .get(name)
            .and_then(|&c| rec.get(c))
            .unwrap_or("")
            .to_owned()
    };
    let mut out = Measurements::default();
    for row in r.records() {
        let (rec, line) = record(row, path)?;
        let mut tx_end = endpoint(&t, &rec, line, &tx, id(&rec, "tx_id"), wgs84)?;
        tx_end.azimuth_deg = match (t.optional_number(&rec, line, az)?, &tx) {
            (Some(b), Place::Geo { .. }) => Some(
                grid_bearing(b, wgs84, tx_end.x, tx_end.y)
                    .map_err(|m| StageError::bad_input(path, format!("line {line}"), m))?,
            ),
            (b, _) => b,
        };
        if tx_end.id.is_empty() {
            tx_end.id = format!("{:.1},{:.1}", tx_end.x, tx_end.y);
        }
        let link = Link {
            tx: tx_end,
            rx: endpoint(&t, &rec, line, &rx, id(&rec, "rx_id"), wgs84)?,
            freq_hz: positive_freq(&t, &rec, line, freq)?,
            path_loss_db: t.optional_number(&rec, line, pl)?,
            rx_power_dbm: t.optional_number(&rec, line, prx)?,
            tx_eirp_dbm: t.optional_number(&rec, line, eirp)?,
            los: t.optional_number(&rec, line, los)?.map(|v| v != 0.0),
        };
        if link.path_loss_db.is_none() && link.rx_power_dbm.is_none() {
            return Err(StageError::bad_input(
                path,
                format!("line {line}"),
                "expected a value in `path_loss_db` or `rx_power_dbm`",
            ));
        }
        out.links.push(link);
    }
    Ok(out)
}

/// A true bearing (degrees clockwise from true north) at a site-frame point as a grid bearing
/// (clockwise from the site frame's +y), in [0, 360).
fn grid_bearing(true_deg: f64, wgs84: &ToSite, x: f64, y: f64) -> Result<f64, String> {
    Ok((true_deg - wgs84.convergence_deg(x, y)?).rem_euclid(360.0))
}

/// A latitude and longitude a projection can take (proj gives garbage, not errors, past them).
fn check_lat_lon(lat: f64, lon: f64) -> Result<(), String> {
    if (-90.0..=90.0).contains(&lat) && (-180.0..=360.0).contains(&lon) {
        Ok(())
    } else {
        Err(format!(
            "expected a latitude in [-90, 90] and a longitude in [-180, 360] degrees, found {lat}, {lon}"
        ))
    }
}

/// The carrier of a row: every propagation law divides by the wavelength or takes its log.
fn positive_freq(
    t: &Table,
    rec: &csv::StringRecord,
    line: u64,
    col: usize,
) -> Result<f64, StageError> {
    let f = t.number(rec, line, col)?;
    if f > 0.0 {
        Ok(f)
    } else {
        Err(StageError::bad_input(
            t.path,
            format!("line {line}, column `{}`", t.names[col]),
            format!("expected a positive frequency in Hz, found {f}"),
        ))
    }
}

#[derive(Deserialize)]
struct DukeCells {
    cells: Vec<DukeCell>,
}

#[derive(Deserialize)]
struct DukeCell {
    pci: String,
    lat: f64,
    lon: f64,
    azimuth_deg: f64,
    freq_hz: f64,
}

/// The cells' antenna heights: one for all, some by PCI.
struct CellHeights<'a> {
    all: f64,
    by_pci: &'a BTreeMap<String, f64>,
}

fn read_duke(
    path: &Path,
    cells_path: &Path,
    wgs84: &ToSite,
    tx_h: &CellHeights,
    rx_h: f64,
) -> Result<Measurements, StageError> {
    let text = crate::io::open::read_regular_to_string(cells_path)
        .map_err(|e| StageError::bad_input(cells_path, "open", e.to_string()))?;
    let cells: DukeCells = serde_json::from_str(&text)
        .map_err(|e| StageError::bad_input(cells_path, format!("line {}, column {}", e.line(), e.column()), format!("expected {{\"cells\": [{{\"pci\", \"lat\", \"lon\", \"azimuth_deg\", \"freq_hz\"}}]}}: {e}")))?;
    let mut by_pci = HashMap::new();
    for (i, c) in cells.cells.iter().enumerate() {
        let place = || format!("cell {i} (pci {:?})", c.pci);
        check_lat_lon(c.lat, c.lon).map_err(|m| StageError::bad_input(cells_path, place(), m))?;
        if !(c.freq_hz > 0.0 && c.freq_hz.is_finite()) {
            return Err(StageError::bad_input(
                cells_path,
                place(),
                format!("expected a positive frequency in Hz, found {}", c.freq_hz),
            ));
        }
        let (x, y, _) = wgs84
            .apply(c.lon, c.lat, 0.0)
            .map_err(|m| StageError::bad_input(cells_path, format!("cell {}", c.pci), m))?;
        let tx = Endpoint {
            id: c.pci.clone(),
            x,
            y,
            z: Height::AboveGround(tx_h.by_pci.get(&c.pci).copied().unwrap_or(tx_h.all)),
            azimuth_deg: Some(
                grid_bearing(c.azimuth_deg, wgs84, x, y)
                    .map_err(|m| StageError::bad_input(cells_path, format!("cell {}", c.pci), m))?,
            ),
        };
        by_pci.insert(c.pci.clone(), (tx, c.freq_hz));
    }
    if let Some(pci) = tx_h.by_pci.keys().find(|k| !by_pci.contains_key(*k)) {
        let mut known: Vec<&String> = by_pci.keys().collect();
        known.sort();
        return Err(StageError::Failed(format!(
            "layout: tx_heights_m names cell {pci:?}, which {} does not list (its cells: {known:?})",
            cells_path.display()
        )));
    }
    let (t, mut r) = Table::open(path)?;
    let (pci, lat, lon, rsrp) = (
        t.require("PCI")?,
        t.require("latitude")?,
        t.require("longitude")?,
        t.require("rsrp")?,
    );
    let mut out = Measurements::default();
    for row in r.records() {
        let (rec, line) = record(row, path)?;
        let id = rec.get(pci).unwrap_or("");
        let (tx, freq_hz) = by_pci.get(id).ok_or_else(|| {
            StageError::bad_input(
                path,
                format!("line {line}, column `PCI`"),
                format!("cell {id:?} is not in {}", cells_path.display()),
            )
        })?;
        let (lat, lon) = (t.number(&rec, line, lat)?, t.number(&rec, line, lon)?);
        check_lat_lon(lat, lon)
            .map_err(|m| StageError::bad_input(path, format!("line {line}"), m))?;
        let (x, y, _) = wgs84
            .apply(lon, lat, 0.0)
            .map_err(|m| StageError::bad_input(path, format!("line {line}"), m))?;
        out.links.push(Link {
            tx: tx.clone(),
            rx: Endpoint {
                id: String::new(),
                x,
                y,
                z: Height::AboveGround(rx_h),
                azimuth_deg: None,
            },
            freq_hz: *freq_hz,
            path_loss_db: None,
            rx_power_dbm: Some(t.number(&rec, line, rsrp)?),
            tx_eirp_dbm: None,
            los: None,
        });
    }
    Ok(out)
}
