//! `kodama-dag trace` and `kodama-dag radiomap`: the tracer on a Sionna scene without writing a
//! graph. Thin wrappers over `kodama_nodes::rf` (the same code the graph nodes run); the engine
//! library itself stays free of radio.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use glam::DVec3;

use kodama_nodes::io::export::{Encoded, encode};
use kodama_nodes::io::sionna_xml::read_scene_with_thickness;
use kodama_nodes::rf::antenna::Antenna;
use kodama_nodes::rf::gpu::{Device, device_unavailable, radio_map_on};
use kodama_nodes::rf::links_csv::{read_links, write_results};
use kodama_nodes::rf::map_plane::default_plane;
use kodama_nodes::rf::path::{LinkEnds, LinkPaths, TraceOptions};
use kodama_nodes::rf::paths::trace_links_on;
use kodama_nodes::rf::scene::RfScene;
use kodama_nodes::{Artifact, Site, StageError};

use crate::progress::{Mode, Task};

/// Interaction switches shared by both commands.
#[derive(Args, Debug)]
pub struct Interactions {
    /// Carrier frequency, Hz.
    #[arg(long)]
    freq_hz: f64,
    /// Most interactions along a path.
    #[arg(long, default_value_t = 3)]
    max_depth: u32,
    /// Rays shot from each transmitter.
    #[arg(long, default_value_t = 1_000_000)]
    rays: u32,
    /// No line-of-sight paths.
    #[arg(long)]
    no_los: bool,
    /// No specular reflection.
    #[arg(long)]
    no_reflection: bool,
    /// No transmission through surfaces.
    #[arg(long)]
    no_transmission: bool,
    /// UTD edge diffraction, one edge a path: in links chained with reflections before and after
    /// it up to the depth, in radio maps first order (off by default, as in Sionna RT).
    #[arg(long)]
    diffraction: bool,
    /// No diffraction (the default; accepted for Sionna-style command lines).
    #[arg(long)]
    no_diffraction: bool,
    /// Diffract only at edges where the faces turn by at least this many degrees (0-90).
    #[arg(long, default_value_t = 0.0)]
    min_wedge_deg: f64,
    /// Diffract only at edges within one shape of the scene file, as Sionna RT 2.2 does (by
    /// default also where two shapes meet, e.g. a wall's top against a separate roof).
    #[arg(long)]
    wedges_within_shapes: bool,
    /// Take every wedge's faces as unbounded, as the UTD and Sionna RT 2.2 do (by default a
    /// face's reflection term is no stronger than a face of its width can reflect: a post's
    /// narrow facets do not shine like a wall).
    #[arg(long)]
    infinite_faces: bool,
    /// Diffuse reflection (effective roughness, Lambertian; last bounce only for links).
    #[arg(long)]
    diffuse: bool,
    /// No diffuse reflection (the default; accepted for Sionna-style command lines).
    #[arg(long)]
    no_diffuse: bool,
    /// Scattering coefficient S of every surface, in [0, 1] (specular keeps √(1 − S²)).
    #[arg(long, default_value_t = 0.0)]
    scattering_coefficient: f64,
    /// Use P.2040 material laws outside their frequency ranges (ground above 10 GHz needs none:
    /// it is ITU-R P.527 soil there).
    #[arg(long)]
    extrapolate: bool,
}

impl Interactions {
    fn options(&self) -> TraceOptions {
        TraceOptions {
            max_depth: self.max_depth,
            los: !self.no_los,
            reflection: !self.no_reflection,
            transmission: !self.no_transmission,
            diffraction: self.diffraction && !self.no_diffraction,
            diffuse: self.diffuse && !self.no_diffuse,
            scattering_coefficient: self.scattering_coefficient,
            rays: self.rays,
            min_wedge_deg: self.min_wedge_deg,
            wedges_across_objects: !self.wedges_within_shapes,
            finite_faces: !self.infinite_faces,
            ..Default::default()
        }
    }
}

/// `trace` arguments.
#[derive(Args, Debug)]
pub struct TraceArgs {
    /// A Sionna RT scene (Mitsuba XML + PLY).
    #[arg(long)]
    scene: PathBuf,
    /// Links CSV with columns tx_x,tx_y,tx_z,rx_x,rx_y,rx_z.
    #[arg(long)]
    links: PathBuf,
    #[command(flatten)]
    interactions: Interactions,
    /// Transmit antenna: `iso`, `dipole` or `tr38901:BEARING_DEG:TILT_DEG` (the TR 38.901 sector,
    /// boresight at a compass bearing clockwise from the scene's +y, downtilt below the horizon).
    /// The receivers stay isotropic.
    #[arg(long, value_parser = Antenna::parse, default_value = "iso")]
    tx_antenna: Antenna,
    /// Where to write the links with path_gain_db (CSV).
    #[arg(long)]
    out: PathBuf,
    /// Also write every path of every link (its interactions, points, triangles, length, delay
    /// and complex gain) as JSON: what to read when one link's figure needs explaining.
    #[arg(long)]
    paths: Option<PathBuf>,
    /// Where the rays of the links' sequence search run: `cpu`, or `cuda` (an NVIDIA GPU; a
    /// build with `--features cuda` and the NVIDIA driver; README, "GPU backend (optional)").
    /// The paths are the same bits on either.
    #[arg(long, value_parser = Device::parse, default_value = "cpu")]
    device: Device,
}

/// `radiomap` arguments.
#[derive(Args, Debug)]
pub struct RadiomapArgs {
    /// A Sionna RT scene (Mitsuba XML + PLY).
    #[arg(long)]
    scene: PathBuf,
    /// Transmitter position X,Y,Z in the scene's frame, metres.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    tx: [f64; 3],
    #[command(flatten)]
    interactions: Interactions,
    /// Cell size, metres.
    #[arg(long, default_value_t = 10.0)]
    cell_m: f64,
    /// Height of the measurement plane, metres.
    #[arg(long, default_value_t = 1.5)]
    height_m: f64,
    /// Transmit antenna: `iso`, `dipole` or `tr38901:BEARING_DEG:TILT_DEG` (the TR 38.901 sector,
    /// boresight at a compass bearing clockwise from the scene's +y, downtilt below the horizon).
    #[arg(long, value_parser = Antenna::parse, default_value = "iso")]
    tx_antenna: Antenna,
    /// The map: .tif (GeoTIFF, scene frame), .exr or .png (with a colour bar); path gain in dB.
    #[arg(long)]
    out: PathBuf,
    /// Where to trace: `cpu`, or `cuda` (an NVIDIA GPU; a build with `--features cuda` and the
    /// NVIDIA driver; README, "GPU backend (optional)").
    #[arg(long, value_parser = Device::parse, default_value = "cpu")]
    device: Device,
}

fn parse_point(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|c| {
            c.trim()
                .parse::<f64>()
                .map_err(|_| format!("{c:?} is not a number"))
        })
        .collect::<Result<_, _>>()?;
    let p = <[f64; 3]>::try_from(v).map_err(|_| "expected X,Y,Z".to_string())?;
    kodama_nodes::params::check_point(p).map_err(|m| format!("expected {m}"))?;
    Ok(p)
}

type Fail = (u8, String);

fn stage_fail(e: StageError) -> Fail {
    (if e.is_user_error() { 2 } else { 1 }, format!("error: {e}"))
}

/// A file named on the command line must be a regular file: a FIFO or device would block the
/// reader, a folder gives a confusing error later.
fn regular_file(flag: &str, path: &Path) -> Result<(), Fail> {
    let meta = std::fs::metadata(path)
        .map_err(|e| (2, format!("error: {flag} {}: {e}", path.display())))?;
    if meta.is_file() {
        return Ok(());
    }
    let what = if meta.is_dir() {
        "a folder"
    } else {
        crate::cache::describe_file_type(&meta.file_type())
    };
    Err((
        2,
        format!(
            "error: {flag} {}: expected a regular file, found {what}",
            path.display()
        ),
    ))
}

fn load(scene: &Path, i: &Interactions) -> Result<RfScene, Fail> {
    regular_file("--scene", scene)?;
    if let Err((field, m)) = i.options().check() {
        let flag = field.replace('_', "-");
        return Err((2, format!("error: --{flag}: {m}")));
    }
    if !(i.freq_hz > 0.0 && i.freq_hz.is_finite()) {
        return Err((
            2,
            format!("error: --freq-hz {} is not a positive frequency", i.freq_hz),
        ));
    }
    let (s, thickness) = read_scene_with_thickness(scene).map_err(stage_fail)?;
    // Traced as Sionna traces the file: with the slab thickness it gives each material.
    let rf = RfScene::new(&s, i.freq_hz, i.extrapolate)
        .map_err(|e| (2, format!("error: {}: {e}", scene.display())))?;
    Ok(thickness
        .into_iter()
        .fold(rf, |rf, (m, d)| rf.with_thickness(m, d)))
}

/// Writes `bytes` to `dest` through a temporary file in the same folder, so a failure never
/// leaves half a file.
fn write_file(dest: &Path, bytes: &[u8]) -> Result<(), Fail> {
    let dir = dest
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)
        .map_err(|e| (2, format!("error: cannot create {}: {e}", dir.display())))?;
    let tmp = dir.join(format!(
        ".{}.tmp",
        dest.file_name().unwrap_or_default().to_string_lossy()
    ));
    std::fs::write(&tmp, bytes)
        .and_then(|()| std::fs::rename(&tmp, dest))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            (2, format!("error: cannot write {}: {e}", dest.display()))
        })
}

fn note_unmodelled(i: &Interactions) {
    if i.diffuse && i.scattering_coefficient <= 0.0 {
        eprintln!("note: --diffuse with a scattering coefficient of 0 scatters nothing");
    }
}

/// At most this many calls into the tracer per `trace` command: steps of the progress bar. Each
/// call repeats some per-scene work (diffraction wedges), so they stay few.
const TRACE_STEPS: usize = 20;

/// `kodama-dag trace`.
pub fn trace(a: TraceArgs) -> Result<u8, Fail> {
    // Before the scene is read: a GPU that cannot be had is the user's to fix (exit 2).
    if let Some(why) = device_unavailable(a.device) {
        return Err((2, format!("error: {why}")));
    }
    let task = Task::new(Mode::detect(false), "reading the scene", None);
    let scene = load(&a.scene, &a.interactions)?;
    regular_file("--links", &a.links)?;
    let links = read_links(&a.links).map_err(stage_fail)?;
    drop(task);
    note_unmodelled(&a.interactions);
    let t = Instant::now();
    let rx_ant = Antenna::default();
    // Links sharing a transmitter share its ray search, so the steps split by transmitter.
    let mut txs: Vec<[u64; 3]> = links.iter().map(|l| l.0.map(f64::to_bits)).collect();
    txs.sort_unstable();
    txs.dedup();
    let per_step = txs.len().div_ceil(TRACE_STEPS).max(1);
    let task = Task::new(
        Mode::detect(false),
        &format!(
            "tracing {} links from {} transmitters",
            links.len(),
            txs.len()
        ),
        Some(txs.len() as u64),
    );
    let mut results = vec![None; links.len()];
    for batch in txs.chunks(per_step) {
        let idx: Vec<usize> = (0..links.len())
            .filter(|&i| batch.binary_search(&links[i].0.map(f64::to_bits)).is_ok())
            .collect();
        let pairs: Vec<_> = idx.iter().map(|&i| links[i]).collect();
        let traced = trace_links_on(
            a.device,
            &scene,
            &pairs,
            (&a.tx_antenna, &rx_ant),
            &a.interactions.options(),
            a.interactions.freq_hz,
        )
        .map_err(|e| (1, format!("error: {e}")))?;
        for (i, r) in idx.into_iter().zip(traced) {
            results[i] = Some(r);
        }
        task.advance(batch.len() as u64);
    }
    drop(task);
    let results: Vec<_> = results
        .into_iter()
        .map(|r| r.expect("every link is in one batch"))
        .collect();
    write_file(&a.out, write_results(&links, &results).as_bytes())?;
    if let Some(dest) = &a.paths {
        write_file(dest, paths_json(&links, &results).as_bytes())?;
    }
    eprintln!(
        "traced {} links in {:.2} s -> {}",
        links.len(),
        t.elapsed().as_secs_f64(),
        a.out.display()
    );
    Ok(0)
}

/// The links and their paths as a JSON array, one object per link in the links file's order;
/// each path's power in dB beside its complex gain (a gain of -inf dB is written as null).
fn paths_json(links: &[LinkEnds], results: &[LinkPaths]) -> String {
    let db = |x: f64| x.is_finite().then_some(x);
    let rows: Vec<serde_json::Value> = links
        .iter()
        .zip(results)
        .map(|((tx, rx), r)| {
            let paths: Vec<serde_json::Value> = r
                .paths
                .iter()
                .map(|p| {
                    serde_json::json!({
                        "gain_db": db(10.0 * (p.a[0] * p.a[0] + p.a[1] * p.a[1]).log10()),
                        "a": p.a,
                        "length_m": p.length_m,
                        "delay_s": p.delay_s,
                        "foliage_m": p.foliage_m,
                        "interactions": p.interactions,
                    })
                })
                .collect();
            serde_json::json!({
                "tx": tx,
                "rx": rx,
                "path_gain_db": db(r.gain_db),
                "diffuse_gain_db": db(r.diffuse_gain_db),
                "paths": paths,
            })
        })
        .collect();
    serde_json::to_string_pretty(&rows).expect("plain values serialize")
}

/// `kodama-dag radiomap`.
pub fn radiomap(a: RadiomapArgs) -> Result<u8, Fail> {
    let format = a
        .out
        .extension()
        .and_then(|e| e.to_str())
        .filter(|e| ["tif", "exr", "png"].contains(e))
        .ok_or_else(|| {
            (
                2,
                format!(
                    "error: {}: expected a .tif, .exr or .png file name",
                    a.out.display()
                ),
            )
        })?
        .to_string();
    if !(a.cell_m > 0.0 && a.cell_m.is_finite()) {
        return Err((
            2,
            format!("error: --cell-m {} is not a positive size", a.cell_m),
        ));
    }
    if !a.height_m.is_finite() {
        return Err((
            2,
            format!("error: --height-m {} is not a finite height", a.height_m),
        ));
    }
    // Before the scene is read: a GPU that cannot be had is the user's to fix (exit 2).
    if let Some(why) = device_unavailable(a.device) {
        return Err((2, format!("error: {why}")));
    }
    let task = Task::new(Mode::detect(false), "reading the scene", None);
    let scene = load(&a.scene, &a.interactions)?;
    note_unmodelled(&a.interactions);
    let plane = default_plane(&scene, a.cell_m, a.height_m);
    // The map's cells are as many as the scene's extent over the cell size: bounded as a
    // graph's RadioMap bounds them (its accumulators take 16 bytes a cell), before anything is
    // allocated.
    let (w, h) = (plane.grid.width as f64, plane.grid.height as f64);
    kodama_nodes::params::check_cells(w, h, 16).map_err(|m| {
        (
            2,
            format!("error: --cell-m {}: {m}; use a coarser cell", a.cell_m),
        )
    })?;
    task.step(&format!(
        "radio map: {} rays over {} x {} cells",
        a.interactions.rays, plane.grid.width, plane.grid.height
    ));
    let t = Instant::now();
    let map = radio_map_on(
        a.device,
        &scene,
        DVec3::from(a.tx),
        &a.tx_antenna,
        &plane,
        &a.interactions.options(),
        a.interactions.freq_hz,
    )
    .map_err(|e| (2, format!("error: {e}")))?;
    let secs = t.elapsed().as_secs_f64();
    drop(task);
    let db = kodama_nodes::rf::radiomap::to_db(&map);
    let site = Site {
        crs: String::new(),
        origin: (0.0, 0.0),
        cell_m: a.cell_m,
    };
    let Encoded::File(bytes) =
        encode(&Artifact::Raster(db), &site, &format).map_err(|e| (1, format!("error: {e}")))?
    else {
        return Err((1, "error: a raster encodes as one file".into()));
    };
    write_file(&a.out, &bytes)?;
    eprintln!(
        "radio map {} x {} cells of {} m from {} rays in {secs:.3} s ({:.2} M rays/s) -> {}",
        map.grid.width,
        map.grid.height,
        a.cell_m,
        a.interactions.rays,
        a.interactions.rays as f64 / secs / 1e6,
        a.out.display()
    );
    Ok(0)
}
