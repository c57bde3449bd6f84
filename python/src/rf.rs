//! The tracer from Python: `trace` (path gains and paths of tx/rx links) and `radio_map` (one
//! transmitter over a horizontal plane), on a Sionna RT scene file or a run's scene artifact.
//! The same code as `kodama-dag trace` and `radiomap` and the graph's radio nodes; results as
//! arrays shaped as Sionna RT's, padded where links differ in their number of paths.

use std::path::PathBuf;

use glam::DVec3;
use kodama_nodes::Artifact;
use kodama_nodes::artifact::Scene;
use kodama_nodes::io::sionna_xml::read_scene_with_thickness;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::map_plane::default_plane;
use kodama_nodes::rf::path::{InteractionKind, LinkEnds, LinkPaths, TraceOptions};
use kodama_nodes::rf::paths::trace_links;
use kodama_nodes::rf::radiomap::{radio_map, to_db};
use kodama_nodes::rf::scene::RfScene;
use num_complex::Complex64;
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{artifact_of, raster, user};

/// The most links one `trace` call takes, and the most cells of a radio map: bounds on what a
/// caller's arguments can make this process allocate.
const MAX_LINKS: usize = 10_000_000;
const MAX_CELLS: u64 = 100_000_000;

/// Where the scene comes from: a Sionna RT XML file, or a Scene artifact in a cache.
#[derive(FromPyObject)]
pub(crate) enum SceneSource {
    /// (cache folder, digest hex) of a run's scene node.
    Cached(PathBuf, String),
    /// A Sionna RT scene file (Mitsuba XML + PLY).
    File(PathBuf),
}

/// The physics switches of both calls, as the CLI's flags name them.
#[derive(FromPyObject)]
pub(crate) struct Physics {
    #[pyo3(item)]
    max_depth: u32,
    #[pyo3(item)]
    los: bool,
    #[pyo3(item)]
    reflection: bool,
    #[pyo3(item)]
    transmission: bool,
    #[pyo3(item)]
    diffraction: bool,
    #[pyo3(item)]
    diffuse: bool,
    #[pyo3(item)]
    scattering_coefficient: f64,
    #[pyo3(item)]
    rays: u32,
    #[pyo3(item)]
    tx_antenna: String,
    #[pyo3(item)]
    extrapolate: bool,
}

impl Physics {
    fn options(&self) -> PyResult<TraceOptions> {
        let opt = TraceOptions {
            max_depth: self.max_depth,
            los: self.los,
            reflection: self.reflection,
            transmission: self.transmission,
            diffraction: self.diffraction,
            diffuse: self.diffuse,
            scattering_coefficient: self.scattering_coefficient,
            rays: self.rays,
            ..Default::default()
        };
        opt.check()
            .map_err(|(field, m)| user(format!("{field}: {m}")))?;
        Ok(opt)
    }

    fn antenna(&self) -> PyResult<Antenna> {
        Antenna::parse(&self.tx_antenna).map_err(|m| user(format!("tx_antenna: {m}")))
    }
}

/// The scene at `freq_hz`, as the tracer sees it: a file keeps the slab thickness each of its
/// materials gives, as Sionna RT traces it.
fn rf_scene(
    py: Python<'_>,
    src: &SceneSource,
    freq_hz: f64,
    extrapolate: bool,
) -> PyResult<RfScene> {
    if !(freq_hz > 0.0 && freq_hz.is_finite()) {
        return Err(user(format!(
            "freq_hz: expected a positive, finite frequency in Hz, got {freq_hz}"
        )));
    }
    let (scene, thickness, name): (Scene, Vec<_>, String) = match src {
        SceneSource::File(path) => {
            if !path.is_file() {
                return Err(user(format!(
                    "scene {}: expected a Sionna RT scene file (XML)",
                    path.display()
                )));
            }
            let (s, t) = py
                .detach(|| read_scene_with_thickness(path))
                .map_err(|e| user(e.to_string()))?;
            (s, t.into_iter().collect(), path.display().to_string())
        }
        SceneSource::Cached(cache, digest) => match artifact_of(py, cache, digest)? {
            Artifact::Scene(s) => (s, Vec::new(), format!("the scene {}", &digest[..12])),
            other => {
                return Err(user(format!(
                    "the artifact {} is a {}, not a Scene",
                    &digest[..12.min(digest.len())],
                    other.ty()
                )));
            }
        },
    };
    let rf =
        RfScene::new(&scene, freq_hz, extrapolate).map_err(|e| user(format!("{name}: {e}")))?;
    Ok(thickness
        .into_iter()
        .fold(rf, |rf, (m, d)| rf.with_thickness(m, d)))
}

/// Sionna RT's `InteractionType` codes: NONE 0, SPECULAR 1, DIFFUSE 2 (never a listed path
/// here: diffuse power is summed, not listed), REFRACTION 4 (transmission through a slab),
/// DIFFRACTION 8.
fn sionna_code(k: InteractionKind) -> u8 {
    match k {
        InteractionKind::Reflection => 1,
        InteractionKind::Transmission => 4,
        InteractionKind::Diffraction => 8,
    }
}

/// Path gains and paths of the links `links` ((N, 6): tx x, y, z, rx x, y, z in the scene's
/// frame) at `freq_hz`. Per link: `gain_db` (Σ|a|², dB), `coherent_gain_db`, `diffuse_gain_db`;
/// per link and path (padded to the most paths of any link): `a` (complex, Sionna's `a`
/// without the phase of the delay), `tau` (s; -1 where no path, as Sionna RT pads), `valid`;
/// per link, path and interaction (padded to `max_depth`): `interactions` (Sionna RT's codes, 0
/// none), `vertices` (the points, 0 past the last), `triangles` (-1 past the last).
#[pyfunction]
#[pyo3(signature = (scene, links, freq_hz, physics))]
pub(crate) fn trace<'py>(
    py: Python<'py>,
    scene: SceneSource,
    links: PyReadonlyArray2<'py, f64>,
    freq_hz: f64,
    physics: Physics,
) -> PyResult<Bound<'py, PyDict>> {
    let flat = links.as_array();
    let shape = flat.shape();
    if shape[1] != 6 {
        return Err(user(format!(
            "links: expected an array of shape (N, 6) (tx x, y, z, rx x, y, z), got {shape:?}"
        )));
    }
    if shape[0] > MAX_LINKS {
        return Err(user(format!(
            "links: {} links, at most {MAX_LINKS} a call",
            shape[0]
        )));
    }
    let ends: Vec<LinkEnds> = flat
        .rows()
        .into_iter()
        .map(|r| ([r[0], r[1], r[2]], [r[3], r[4], r[5]]))
        .collect();
    if let Some(k) = ends
        .iter()
        .position(|(t, r)| t.iter().chain(r).any(|v| !v.is_finite()))
    {
        return Err(user(format!(
            "links: row {k} holds a non-finite coordinate"
        )));
    }
    let opt = physics.options()?;
    let tx_antenna = physics.antenna()?;
    let rf = rf_scene(py, &scene, freq_hz, physics.extrapolate)?;
    let results: Vec<LinkPaths> =
        py.detach(|| trace_links(&rf, &ends, &tx_antenna, &Antenna::default(), &opt, freq_hz));
    paths_dict(py, &results, opt.max_depth as usize)
}

/// [`trace`]'s results as padded arrays.
fn paths_dict<'py>(
    py: Python<'py>,
    results: &[LinkPaths],
    depth: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let n = results.len();
    let most = results.iter().map(|r| r.paths.len()).max().unwrap_or(0);
    let depth = depth.max(
        results
            .iter()
            .flat_map(|r| &r.paths)
            .map(|p| p.interactions.len())
            .max()
            .unwrap_or(0),
    );
    let mut a = vec![Complex64::new(0.0, 0.0); n * most];
    let mut tau = vec![-1.0f64; n * most];
    let mut valid = vec![false; n * most];
    let mut kinds = vec![0u8; n * most * depth];
    let mut vertices = vec![0.0f64; n * most * depth * 3];
    let mut triangles = vec![-1i64; n * most * depth];
    for (i, r) in results.iter().enumerate() {
        for (j, p) in r.paths.iter().enumerate() {
            let k = i * most + j;
            a[k] = Complex64::new(p.a[0], p.a[1]);
            tau[k] = p.delay_s;
            valid[k] = true;
            for (d, it) in p.interactions.iter().enumerate() {
                let q = k * depth + d;
                kinds[q] = sionna_code(it.kind);
                vertices[q * 3..q * 3 + 3].copy_from_slice(&it.point);
                triangles[q] = it.triangle as i64;
            }
        }
    }
    let column = |f: fn(&LinkPaths) -> f64| results.iter().map(f).collect::<Vec<f64>>();
    let d = PyDict::new(py);
    d.set_item("gain_db", column(|r| r.gain_db).into_pyarray(py))?;
    d.set_item(
        "coherent_gain_db",
        column(|r| r.coherent_gain_db).into_pyarray(py),
    )?;
    d.set_item(
        "diffuse_gain_db",
        column(|r| r.diffuse_gain_db).into_pyarray(py),
    )?;
    d.set_item("a", a.into_pyarray(py).reshape([n, most])?)?;
    d.set_item("tau", tau.into_pyarray(py).reshape([n, most])?)?;
    d.set_item("valid", valid.into_pyarray(py).reshape([n, most])?)?;
    d.set_item(
        "interactions",
        kinds.into_pyarray(py).reshape([n, most, depth])?,
    )?;
    d.set_item(
        "vertices",
        vertices.into_pyarray(py).reshape([n, most, depth, 3])?,
    )?;
    d.set_item(
        "triangles",
        triangles.into_pyarray(py).reshape([n, most, depth])?,
    )?;
    Ok(d)
}

/// The path gain (linear, NaN where no ray arrived) from a transmitter at `tx` over Sionna RT's
/// default plane: the scene's horizontal extent in cells of `cell_m`, centred on it, `height_m`
/// up. A raster dict as `artifact` gives (x0, y0 the north-west corner, rows north to south),
/// with `data_db` beside `data`.
#[pyfunction]
#[pyo3(signature = (scene, tx, freq_hz, cell_m, height_m, physics))]
pub(crate) fn radio_map_at<'py>(
    py: Python<'py>,
    scene: SceneSource,
    tx: [f64; 3],
    freq_hz: f64,
    cell_m: f64,
    height_m: f64,
    physics: Physics,
) -> PyResult<Bound<'py, PyDict>> {
    if tx.iter().any(|v| !v.is_finite()) {
        return Err(user(format!("tx: expected finite coordinates, got {tx:?}")));
    }
    if !(cell_m > 0.0 && cell_m.is_finite()) {
        return Err(user(format!(
            "cell_m: expected a positive, finite size in metres, got {cell_m}"
        )));
    }
    if !height_m.is_finite() {
        return Err(user(format!(
            "height_m: expected a finite height, got {height_m}"
        )));
    }
    let opt = physics.options()?;
    let antenna = physics.antenna()?;
    let rf = rf_scene(py, &scene, freq_hz, physics.extrapolate)?;
    let plane = default_plane(&rf, cell_m, height_m);
    let cells = plane.grid.width as u64 * plane.grid.height as u64;
    if cells > MAX_CELLS {
        return Err(user(format!(
            "cell_m: {cell_m} m over this scene makes {cells} cells, at most {MAX_CELLS}"
        )));
    }
    let map = py.detach(|| radio_map(&rf, DVec3::from(tx), &antenna, &plane, &opt, freq_hz));
    let db = to_db(&map);
    let d = raster(py, map)?;
    let g = db.grid;
    d.set_item(
        "data_db",
        db.data
            .0
            .into_pyarray(py)
            .reshape([g.height as usize, g.width as usize])?,
    )?;
    Ok(d)
}

/// The most path vertices one `foliage_lengths` call takes.
const MAX_VERTICES: usize = 100_000_000;

/// The metres each path runs inside the foliage volumes of `plys` (closed meshes in the scene's
/// frame, as a Sionna export's `foliage/` holds them), measured as the tracer measures its own
/// paths' (`rf::foliage::foliage_length`; overlapping volumes counted once). The paths are
/// `points` (M, 3), taken `counts[i]` at a time (each at least 2: its ends and the interactions
/// between them).
#[pyfunction]
pub fn foliage_lengths<'py>(
    py: Python<'py>,
    plys: Vec<PathBuf>,
    points: PyReadonlyArray2<'py, f64>,
    counts: Vec<usize>,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    use kodama_nodes::artifact::{Material, ObjectClass, PodVec, SceneObject};
    use kodama_nodes::io::sionna_xml::read_ply;
    use kodama_nodes::rf::foliage::{FoliageDepth, foliage_length};
    use kodama_nodes::rf::scene::EPS;
    let pts = points.as_array();
    if pts.ncols() != 3 || pts.nrows() > MAX_VERTICES {
        return Err(user(format!(
            "points: expected shape (M, 3) with M at most {MAX_VERTICES}, got {:?}",
            pts.shape()
        )));
    }
    if counts.iter().any(|&c| c < 2) || counts.iter().sum::<usize>() != pts.nrows() {
        return Err(user(
            "counts: expected at least 2 points a path, summing to the rows of points".to_string(),
        ));
    }
    if !pts.iter().all(|v| v.is_finite()) {
        return Err(user("points: expected finite coordinates".to_string()));
    }
    let mut objects = Vec::new();
    for (k, ply) in plys.iter().enumerate() {
        let mut mesh = read_ply(ply).map_err(|e| user(e.to_string()))?;
        // A volume's faces must face out (entering is crossing against the normal), whichever
        // way the file winds them: Sionna's loader and ours read PLY files wound either way.
        if mesh.volume() < 0.0 {
            for t in mesh.triangles.iter_mut() {
                t.swap(1, 2);
            }
        }
        let n = mesh.triangles.len();
        objects.push(SceneObject {
            id: format!("foliage-{k}"),
            class: ObjectClass::Vegetation,
            mesh: kodama_nodes::artifact::Mesh {
                materials: PodVec(vec![Material::Foliage as u8; n]),
                ..mesh
            },
        });
    }
    let scene = RfScene::new(&Scene { objects }, 3.5e9, false).map_err(|e| user(e.to_string()))?;
    let paths: Vec<Vec<DVec3>> = {
        let mut at = 0;
        counts
            .iter()
            .map(|&c| {
                let p = (at..at + c)
                    .map(|r| DVec3::new(pts[[r, 0]], pts[[r, 1]], pts[[r, 2]]))
                    .collect();
                at += c;
                p
            })
            .collect()
    };
    let lengths: Vec<f64> = py.detach(|| {
        use rayon::prelude::*;
        paths
            .par_iter()
            .map(|p| {
                let mut depth = FoliageDepth::at(&scene, p[0]);
                let mut inside = 0.0;
                for w in p.windows(2) {
                    if (w[1] - w[0]).length() == 0.0 {
                        continue;
                    }
                    let hits = scene.hits_between(w[0], w[1], EPS);
                    let (len, at_b) = foliage_length(&scene, w[0], w[1], &hits, depth);
                    inside += len;
                    depth = at_b;
                }
                inside
            })
            .collect()
    });
    Ok(lengths.into_pyarray(py))
}

/// The foliage loss, dB, of each of `lengths` metres at `freq_hz`: `db_per_m` (default ITU-R
/// P.833 Figure 2 at the carrier) times the metres, or with `max_db` (`"p833"`: P.833's A_m at
/// the carrier; a number: that A_m) P.833's saturating law (`rf::foliage::FoliageLaw`).
#[pyfunction]
#[pyo3(signature = (lengths, freq_hz, db_per_m=None, max_db=None))]
pub fn foliage_loss_db<'py>(
    py: Python<'py>,
    lengths: Vec<f64>,
    freq_hz: f64,
    db_per_m: Option<f64>,
    max_db: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    use kodama_nodes::rf::foliage::{FoliageLaw, specific_attenuation_db_per_m};
    if !(freq_hz > 0.0 && freq_hz.is_finite()) {
        return Err(user(format!(
            "freq_hz: expected a positive frequency, got {freq_hz}"
        )));
    }
    let gamma = db_per_m.unwrap_or_else(|| specific_attenuation_db_per_m(freq_hz));
    if !(gamma >= 0.0 && gamma.is_finite()) {
        return Err(user(format!(
            "db_per_m: expected a non-negative loss, got {gamma}"
        )));
    }
    let law = match max_db {
        None => FoliageLaw::Linear,
        Some(v) if v.extract::<String>().is_ok_and(|s| s == "p833") => FoliageLaw::P833,
        Some(v) => FoliageLaw::P833Max(v.extract::<f64>().map_err(|_| {
            user("max_db: expected \"p833\" or a maximum attenuation in dB".to_string())
        })?),
    };
    law.check().map_err(|m| user(format!("max_db: {m}")))?;
    if lengths.iter().any(|l| !(*l >= 0.0 && l.is_finite())) {
        return Err(user("lengths: expected non-negative metres".to_string()));
    }
    let loss = law.at(freq_hz, gamma);
    Ok(lengths
        .iter()
        .map(|&l| loss.loss_db(l))
        .collect::<Vec<_>>()
        .into_pyarray(py))
}
