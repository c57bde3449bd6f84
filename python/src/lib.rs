//! `kodama_dag._core`: the engine and the stages in the Python process. The typed API lives in
//! the Python package beside it (`python/kodama_dag`); this module hands it plain values: JSON
//! text for records, and artifacts as dicts of NumPy arrays built from the decoded vectors
//! themselves (no copy past the decode).
//!
//! Long calls (`run`) release the GIL, so other Python threads go on while a graph runs. Errors
//! that the CLI reports with exit code 2 (a graph, a flag or an input file the user got wrong)
//! arrive as `UserError`, with the CLI's message, file and place; the others as `EngineError`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use kodama_dag::cache::{Blob, Cache, Digest, NotACache};
use kodama_dag::exec::{RunError, RunOptions, run as run_graph};
use kodama_dag::graph::{Graph, LoadOptions, TileOverrides, load};
use kodama_dag::progress::{Mode, Reporter};
use kodama_dag::registry;
use kodama_nodes::artifact::{Footprints, Measurements, PointSet, Raster, Scene};
use kodama_nodes::stage::Arity;
use kodama_nodes::{Artifact, Site};
use numpy::{IntoPyArray, PyArray1, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

mod raster_view;
mod rf;

create_exception!(
    _core,
    UserError,
    PyException,
    "What the CLI reports with exit code 2: a graph, a parameter or an input file that is not what was expected. The message names the file, the place and what was expected."
);
create_exception!(
    _core,
    EngineError,
    PyException,
    "What the CLI reports with exit code 1: the cache or the output folder failed."
);

fn user(m: impl Into<String>) -> PyErr {
    UserError::new_err(m.into())
}

fn engine(m: impl Into<String>) -> PyErr {
    EngineError::new_err(m.into())
}

fn run_error(e: RunError) -> PyErr {
    match e {
        RunError::Usage(m) => user(m),
        RunError::Io(m) => engine(m),
    }
}

/// Worker threads as the CLI's `--jobs` takes them: 0 is refused; too many are clamped by the
/// engine, with a warning.
fn check_jobs(jobs: Option<usize>) -> PyResult<()> {
    if jobs == Some(0) {
        return Err(user("jobs: expected at least 1 worker thread, got 0"));
    }
    Ok(())
}

/// Loads the graph file `path` as `kodama-dag run` does (`sets` as `--set NODE.KEY=VALUE`).
fn load_graph(
    path: &str,
    sets: Vec<String>,
    data: Option<PathBuf>,
    allow_outside: bool,
    tile_m: Option<f64>,
    halo_m: Option<f64>,
) -> PyResult<Graph> {
    if let Some(d) = &data
        && !d.is_dir()
    {
        return Err(user(format!("data {}: not a directory", d.display())));
    }
    for (name, v) in [("tile_m", tile_m), ("halo_m", halo_m)] {
        if let Some(v) = v
            && !(v.is_finite() && v > 0.0)
        {
            return Err(user(format!(
                "{name}: expected a finite number of metres above 0, got {v}"
            )));
        }
    }
    let opts = LoadOptions {
        data_dir: data,
        sets,
        allow_outside,
        tiles: TileOverrides { tile_m, halo_m },
    };
    load(Path::new(path), &opts).map_err(|e| user(e.to_string()))
}

/// A cache that could not be opened: a folder that is not a cache is the user's.
fn cache_error(dir: &Path, e: std::io::Error) -> PyErr {
    match NotACache::of(&e) {
        Some(n) => user(n.to_string()),
        None => engine(format!("cannot open the cache at {}: {e}", dir.display())),
    }
}

/// Opens (creating if needed) the cache folder `dir`.
fn open_cache(dir: &Path) -> PyResult<Cache> {
    Cache::open(dir).map_err(|e| cache_error(dir, e))
}

/// The site of a loaded graph, as a dict.
fn site_dict<'py>(py: Python<'py>, g: &Graph) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("crs", &g.site.crs)?;
    d.set_item("origin", (g.site.origin.0, g.site.origin.1))?;
    d.set_item("cell_m", g.site.cell_m)?;
    Ok(d)
}

/// The reporter of a run from Python: with `progress` (a callable taking one line), every line
/// goes through it, so a notebook shows them under the cell (the package passes
/// `sys.stderr.write` there); without, the CLI's (bars on a terminal, lines elsewhere).
fn reporter(quiet: bool, total: usize, progress: Option<Py<PyAny>>) -> Reporter {
    match progress {
        None => Reporter::new(Mode::detect(quiet), total),
        Some(callback) => Reporter::with_sink(
            quiet,
            total,
            std::sync::Arc::new(move |text: &str| {
                Python::attach(|py| {
                    // A failing callback must not stop the run: its lines are lost, no more.
                    let _ = callback.call1(py, (format!("{text}\n"),));
                });
            }),
        ),
    }
}

/// Runs a graph; returns (the run record as JSON, the graph's site, its output names by node).
#[pyfunction]
#[pyo3(signature = (graph, sets, cache, out, targets, jobs, data, allow_outside, tile_m, halo_m, quiet, progress=None))]
#[allow(clippy::too_many_arguments)]
fn run<'py>(
    py: Python<'py>,
    graph: &str,
    sets: Vec<String>,
    cache: PathBuf,
    out: Option<PathBuf>,
    targets: Vec<String>,
    jobs: Option<usize>,
    data: Option<PathBuf>,
    allow_outside: bool,
    tile_m: Option<f64>,
    halo_m: Option<f64>,
    quiet: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<(String, Bound<'py, PyDict>)> {
    check_jobs(jobs)?;
    let g = load_graph(graph, sets, data, allow_outside, tile_m, halo_m)?;
    let mut cache = open_cache(&cache)?;
    if let Some(out) = &out {
        cache.writes_outputs_to(out);
    }
    let total = g
        .needed(&kodama_dag::exec::target_indices(&g, &targets).map_err(run_error)?)
        .iter()
        .filter(|x| **x)
        .count();
    let opts = RunOptions {
        jobs,
        targets,
        out_dir: out,
    };
    let record = py.detach(|| {
        let reporter = reporter(quiet, total, progress);
        run_graph(&g, &cache, &opts, &reporter)
    });
    let record = record.map_err(run_error)?;
    let json = serde_json::to_string(&record).map_err(|e| engine(e.to_string()))?;
    Ok((json, site_dict(py, &g)?))
}

/// Runs a sweep file as `kodama-dag sweep` does (every variant through one cache, the table
/// written in `out`); returns its name, axes, metric names, output folder, and per variant its
/// (axis, label) pairs, metrics (NaN where missing) and run record as JSON.
#[pyfunction]
#[pyo3(signature = (file, sets, cache, out, jobs, data, allow_outside, quiet, progress=None))]
#[allow(clippy::too_many_arguments)]
fn sweep<'py>(
    py: Python<'py>,
    file: PathBuf,
    sets: Vec<String>,
    cache: PathBuf,
    out: Option<PathBuf>,
    jobs: Option<usize>,
    data: Option<PathBuf>,
    allow_outside: bool,
    quiet: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use kodama_dag::sweep::{SweepError, SweepOptions, load_sweep, run_sweep};
    check_jobs(jobs)?;
    let sw = load_sweep(&file, allow_outside).map_err(user)?;
    // The base graph's site: a variant's overrides set params, never the site.
    let base = load_graph(
        &sw.graph.to_string_lossy(),
        sets.clone(),
        data.clone(),
        allow_outside,
        None,
        None,
    )?;
    let mut cache = open_cache(&cache)?;
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(&sw.name));
    cache.writes_outputs_to(&out_dir);
    let opts = SweepOptions {
        data_dir: data,
        sets,
        out_dir: out_dir.clone(),
        jobs,
        allow_outside,
    };
    let results = py.detach(|| {
        let reporter = reporter(quiet, 0, progress);
        run_sweep(&sw, &cache, &opts, &reporter, |i, n, v| {
            reporter.say(&format!("variant {}/{n}: {}", i + 1, v.name()));
        })
    });
    let results = results.map_err(|e| match e {
        SweepError::Graph(m) => user(m),
        SweepError::Run(e) => run_error(e),
        SweepError::Failed(m) => engine(m),
    })?;
    let d = PyDict::new(py);
    d.set_item("name", &sw.name)?;
    d.set_item(
        "axes",
        sw.axes.iter().map(|(a, _)| a.as_str()).collect::<Vec<_>>(),
    )?;
    d.set_item("metrics", &sw.metrics)?;
    d.set_item("out", &out_dir)?;
    d.set_item("site", site_dict(py, &base)?)?;
    let variants = PyList::empty(py);
    for r in &results {
        let v = PyDict::new(py);
        v.set_item("labels", &r.variant.labels)?;
        v.set_item("metrics", &r.metrics)?;
        let json = serde_json::to_string(&r.record).map_err(|e| engine(e.to_string()))?;
        v.set_item("record", json)?;
        variants.append(v)?;
    }
    d.set_item("variants", variants)?;
    Ok(d)
}

/// What `run` would do for each node and why, as JSON (`kodama-dag explain --json`'s nodes).
#[pyfunction]
#[pyo3(signature = (graph, sets, cache, targets, data, allow_outside))]
fn explain(
    py: Python<'_>,
    graph: &str,
    sets: Vec<String>,
    cache: PathBuf,
    targets: Vec<String>,
    data: Option<PathBuf>,
    allow_outside: bool,
) -> PyResult<String> {
    let g = load_graph(graph, sets, data, allow_outside, None, None)?;
    let cache = open_cache(&cache)?;
    let plan = py
        .detach(|| kodama_dag::explain::explain(&g, &cache, &targets))
        .map_err(run_error)?;
    serde_json::to_string(&plan).map_err(|e| engine(e.to_string()))
}

/// Every node kind a graph may name: name, version, doc, inputs, output type and reports.
#[pyfunction]
fn kinds(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for k in registry::kinds() {
        let d = PyDict::new(py);
        d.set_item("name", k.name)?;
        d.set_item("version", k.version)?;
        d.set_item("doc", k.doc)?;
        d.set_item("output", k.output.to_string())?;
        let inputs = PyList::empty(py);
        for i in k.inputs {
            let arity = match i.arity {
                Arity::One => "one",
                Arity::Optional => "optional",
                Arity::Many => "many",
            };
            inputs.append((i.name, i.ty.to_string(), arity, i.doc))?;
        }
        d.set_item("inputs", inputs)?;
        let reports = PyList::empty(py);
        for r in k.reports {
            reports.append((r.name, r.ty.to_string(), r.doc))?;
        }
        d.set_item("reports", reports)?;
        // Every param with its type, default (JSON text, None when required or not readable)
        // and doc, as `kodama-dag kinds KIND` prints them; and that text.
        let params = PyList::empty(py);
        if let Some(t) = kodama_nodes::params::reference::of_path((k.params_type)()) {
            let defaults = kodama_dag::cli::kinds::defaults_of(k, t).unwrap_or_default();
            for f in t.fields {
                let default = defaults.get(f.name).map(|v| v.to_string());
                params.append((f.name, f.ty, !f.optional, default, f.doc))?;
            }
        }
        d.set_item("params", params)?;
        d.set_item("reference", kodama_dag::cli::kinds::kind_reference(k))?;
        out.append(d)?;
    }
    Ok(out)
}

/// A vector of `[T; N]` as an (n, N) array: the vector's own buffer, reinterpreted.
fn rows<'py, T, const N: usize>(py: Python<'py>, v: Vec<[T; N]>) -> PyResult<Bound<'py, PyAny>>
where
    T: numpy::Element + bytemuck::Pod,
    [T; N]: bytemuck::Pod,
{
    let n = v.len();
    let flat: Vec<T> = bytemuck::allocation::try_cast_vec(v)
        .map_err(|(e, _)| engine(format!("cannot view the rows as one array: {e}")))?;
    Ok(flat.into_pyarray(py).reshape([n, N])?.into_any())
}

fn raster<'py>(py: Python<'py>, r: Raster) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let g = r.grid;
    d.set_item("type", "Raster")?;
    d.set_item("x0", g.x0)?;
    d.set_item("y0", g.y0)?;
    d.set_item("cell_m", g.cell_m)?;
    d.set_item(
        "data",
        r.data
            .0
            .into_pyarray(py)
            .reshape([g.height as usize, g.width as usize])?,
    )?;
    Ok(d)
}

fn points<'py>(py: Python<'py>, p: PointSet) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("type", "Points")?;
    d.set_item("xyz", rows(py, p.xyz.0)?)?;
    d.set_item("classification", p.class.0.into_pyarray(py))?;
    d.set_item("intensity", p.intensity.0.into_pyarray(py))?;
    d.set_item("return_number", p.return_number.0.into_pyarray(py))?;
    d.set_item("number_of_returns", p.number_of_returns.0.into_pyarray(py))?;
    if !p.rgb.is_empty() {
        d.set_item("rgb", rows(py, p.rgb.0)?)?;
    }
    Ok(d)
}

fn scene<'py>(py: Python<'py>, s: Scene) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("type", "Scene")?;
    let objects = PyList::empty(py);
    for o in s.objects {
        let od = PyDict::new(py);
        od.set_item("id", o.id)?;
        od.set_item("class", format!("{:?}", o.class))?;
        od.set_item("vertices", rows(py, o.mesh.positions.0)?)?;
        od.set_item("triangles", rows(py, o.mesh.triangles.0)?)?;
        od.set_item("materials", o.mesh.materials.0.into_pyarray(py))?;
        objects.append(od)?;
    }
    d.set_item("objects", objects)?;
    let names = PyDict::new(py);
    for m in kodama_nodes::artifact::Material::ALL {
        names.set_item(m as u8, m.itu_type().unwrap_or("foliage"))?;
    }
    d.set_item("material_names", names)?;
    // The slab thickness the tracer (and the Sionna export) gives each class's transmission.
    let thickness = PyDict::new(py);
    for m in kodama_nodes::artifact::Material::ALL {
        thickness.set_item(m as u8, m.slab_thickness_m())?;
    }
    d.set_item("material_thickness_m", thickness)?;
    Ok(d)
}

fn footprints<'py>(py: Python<'py>, f: Footprints) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("type", "Footprints")?;
    let items = PyList::empty(py);
    for fp in f.items {
        let fd = PyDict::new(py);
        fd.set_item("id", fp.id)?;
        let polys = PyList::empty(py);
        for p in fp.polygons {
            let rings = PyList::empty(py);
            rings.append(rows(py, p.exterior)?)?;
            for h in p.holes {
                rings.append(rows(py, h)?)?;
            }
            polys.append(rings)?;
        }
        fd.set_item("polygons", polys)?;
        fd.set_item("height_m", fp.height_m)?;
        fd.set_item("min_height_m", fp.min_height_m)?;
        fd.set_item("levels", fp.levels)?;
        fd.set_item("min_level", fp.min_level)?;
        items.append(fd)?;
    }
    d.set_item("items", items)?;
    Ok(d)
}

/// Measurements as columns: one list or array per field, one entry per link.
fn measurements<'py>(py: Python<'py>, m: Measurements) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("type", "Measurements")?;
    let mut strings: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    let mut numbers: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    let mut los: Vec<Option<bool>> = Vec::new();
    let opt = |v: Option<f64>| v.unwrap_or(f64::NAN);
    for l in &m.links {
        strings.entry("tx_id").or_default().push(l.tx.id.clone());
        strings.entry("rx_id").or_default().push(l.rx.id.clone());
        for (name, v) in [
            ("tx_x", l.tx.x),
            ("tx_y", l.tx.y),
            ("rx_x", l.rx.x),
            ("rx_y", l.rx.y),
            ("freq_hz", l.freq_hz),
            ("path_loss_db", opt(l.path_loss_db)),
            ("rx_power_dbm", opt(l.rx_power_dbm)),
            ("tx_eirp_dbm", opt(l.tx_eirp_dbm)),
        ] {
            numbers.entry(name).or_default().push(v);
        }
        los.push(l.los);
    }
    if m.links.is_empty() {
        for name in ["tx_id", "rx_id"] {
            strings.insert(name, Vec::new());
        }
    }
    for (k, v) in strings {
        d.set_item(k, v)?;
    }
    for (k, v) in numbers {
        d.set_item(k, v.into_pyarray(py))?;
    }
    d.set_item("los", los)?;
    d.set_item(
        "heights",
        m.links
            .iter()
            .map(|l| (format!("{:?}", l.tx.z), format!("{:?}", l.rx.z)))
            .collect::<Vec<_>>(),
    )?;
    Ok(d)
}

/// The blob stored under `digest` (hex) in the cache at `cache`, mapped and verified (without
/// the GIL).
fn blob_of(py: Python<'_>, cache: &Path, digest: &str) -> PyResult<Blob> {
    let d = Digest::from_hex(digest)
        .map_err(|_| user(format!("digest: expected 64 hex digits, got {digest:?}")))?;
    let c = Cache::open_existing(cache).map_err(|e| cache_error(cache, e))?;
    py.detach(|| c.get_blob(&d))
        .map_err(|e| unreadable(cache, digest, e.to_string()))
}

/// The artifact in `blob`, decoded (without the GIL).
fn decode(py: Python<'_>, blob: Blob, cache: &Path, digest: &str) -> PyResult<Artifact> {
    py.detach(|| rmp_serde::from_slice::<Artifact>(&blob))
        .map_err(|e| unreadable(cache, digest, format!("undecodable ({e})")))
}

fn unreadable(cache: &Path, digest: &str, why: String) -> PyErr {
    engine(format!(
        "the artifact {} in {}: {why}; run the graph again to rebuild it",
        &digest[..12.min(digest.len())],
        cache.display()
    ))
}

/// The artifact stored under `digest` (hex) in the cache at `cache`, decoded.
fn artifact_of(py: Python<'_>, cache: &Path, digest: &str) -> PyResult<Artifact> {
    let blob = blob_of(py, cache, digest)?;
    decode(py, blob, cache, digest)
}

/// The artifact stored under `digest` (hex) in the cache at `cache`, as a dict whose `type` names
/// it. Rasters, point sets, scenes, footprints, measurements and metrics are read; the other
/// types say what they are and how to get at them.
#[pyfunction]
fn artifact<'py>(py: Python<'py>, cache: PathBuf, digest: &str) -> PyResult<Bound<'py, PyDict>> {
    // A raster's cells are viewed in the mapped file; anything else is decoded.
    let blob = match raster_view::raster_view(py, blob_of(py, &cache, digest)?)? {
        Ok(raster) => return Ok(raster),
        Err(blob) => blob,
    };
    match decode(py, blob, &cache, digest)? {
        Artifact::Raster(r) => raster(py, r),
        Artifact::Points(p) => points(py, p),
        Artifact::Scene(s) => scene(py, s),
        Artifact::Footprints(f) => footprints(py, f),
        Artifact::Measurements(m) => measurements(py, m),
        Artifact::Metrics(m) => {
            let d = PyDict::new(py);
            d.set_item("type", "Metrics")?;
            d.set_item("values", m.values)?;
            Ok(d)
        }
        other => {
            let d = PyDict::new(py);
            d.set_item("type", other.ty().to_string())?;
            Ok(d)
        }
    }
}

/// Writes the artifact `digest` to `dest` in the format its name's extension gives, as a
/// graph's output of that name would be written (`x.tif`, `scene.glb`, `twin.sionna`,
/// `tiles.3dtiles`, ...; `site` is the run's (crs, origin, cell_m)); returns the files written,
/// relative to `dest`'s folder. An existing `dest` is refused unless `overwrite` and it is a
/// file: a folder is never removed from here.
#[pyfunction]
#[pyo3(signature = (cache, digest, site, dest, overwrite, band=(None, None)))]
fn export(
    py: Python<'_>,
    cache: PathBuf,
    digest: &str,
    site: (String, (f64, f64), f64),
    dest: PathBuf,
    overwrite: bool,
    band: (Option<String>, Option<String>),
) -> PyResult<Vec<String>> {
    use kodama_nodes::io::cog::Band;
    use kodama_nodes::io::export::{encode_with_band, output_file};
    let name = dest
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| {
            user(format!(
                "dest {}: expected a file or folder name",
                dest.display()
            ))
        })?
        .to_string();
    if let Ok(meta) = std::fs::symlink_metadata(&dest)
        && !(overwrite && meta.is_file())
    {
        return Err(user(format!(
            "dest {}: already exists{}; remove it or choose another name",
            dest.display(),
            if meta.is_file() {
                " (overwrite=True replaces a file)"
            } else {
                ""
            }
        )));
    }
    let a = artifact_of(py, &cache, digest)?;
    let (_, format) = output_file(&name, a.ty()).map_err(|m| user(format!("dest {name}: {m}")))?;
    let site = Site {
        crs: site.0,
        origin: site.1,
        cell_m: site.2,
    };
    let band = Band {
        unit: band.0,
        description: band.1,
    };
    let parts = kodama_nodes::stage::process_parts();
    let encoded = py
        .detach(|| encode_with_band(&a, &site, format, parts, &band))
        .map_err(|m| user(format!("dest {name}: {m}")))?;
    let dir = match dest.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir)
        .map_err(|e| engine(format!("cannot create {}: {e}", dir.display())))?;
    kodama_dag::exec::write_encoded(&dir, &name, encoded)
        .map_err(|e| engine(format!("cannot write {}: {e}", dest.display())))
}

/// Two NumPy columns of the same length.
type Columns<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// WGS 84 longitudes and latitudes (degrees) of site-frame points (`xs`, `ys`, metres) of the
/// site `(crs, origin)`: the reprojection the exported CSVs use.
#[pyfunction]
fn lon_lat<'py>(
    py: Python<'py>,
    crs: String,
    origin: (f64, f64),
    xs: Vec<f64>,
    ys: Vec<f64>,
) -> PyResult<Columns<'py>> {
    use kodama_nodes::io::crs::{Crs, ToSite};
    if xs.len() != ys.len() {
        return Err(user(format!(
            "lon_lat: {} x values against {} y values",
            xs.len(),
            ys.len()
        )));
    }
    let site = Site {
        crs,
        origin,
        cell_m: 1.0,
    };
    let wgs84 = Crs::from_epsg(4326)
        .and_then(|c| ToSite::new(&c, &site))
        .map_err(user)?;
    let mut lon = Vec::with_capacity(xs.len());
    let mut lat = Vec::with_capacity(xs.len());
    for (&x, &y) in xs.iter().zip(&ys) {
        let (a, b) = if x.is_finite() && y.is_finite() {
            wgs84.inverse(x, y).map_err(user)?
        } else {
            (f64::NAN, f64::NAN)
        };
        lon.push(a);
        lat.push(b);
    }
    Ok((lon.into_pyarray(py), lat.into_pyarray(py)))
}

/// The `kodama-dag` command line, run in this process: `argv` as the binary's (its name first);
/// returns the exit code. The GIL is released while it runs.
#[pyfunction]
fn cli(py: Python<'_>, argv: Vec<String>) -> u8 {
    py.detach(|| kodama_dag::cli::main(argv))
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("UserError", m.py().get_type::<UserError>())?;
    m.add("EngineError", m.py().get_type::<EngineError>())?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(explain, m)?)?;
    m.add_function(wrap_pyfunction!(kinds, m)?)?;
    m.add_function(wrap_pyfunction!(artifact, m)?)?;
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    m.add_function(wrap_pyfunction!(sweep, m)?)?;
    m.add_function(wrap_pyfunction!(export, m)?)?;
    m.add_function(wrap_pyfunction!(lon_lat, m)?)?;
    m.add_function(wrap_pyfunction!(rf::trace, m)?)?;
    m.add_function(wrap_pyfunction!(rf::radio_map_at, m)?)?;
    m.add_function(wrap_pyfunction!(rf::foliage_lengths, m)?)?;
    m.add_function(wrap_pyfunction!(rf::foliage_loss_db, m)?)?;
    Ok(())
}
