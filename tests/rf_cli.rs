//! `kodama-dag trace` and `radiomap` on a Sionna scene, and their input errors.

mod common;
use common::*;

use std::path::{Path, PathBuf};

fn canyon() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/sionna-scenes/simple_street_canyon/simple_street_canyon.xml");
    assert!(p.exists(), "real test data missing: {}", p.display());
    p
}

#[test]
fn trace_reproduces_sionna_on_the_street_canyon() {
    let env = Env::new();
    let fixture = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sionna_paths.csv"),
    )
    .unwrap();
    // The fixture's street-canyon rows as a links file (extra columns are ignored).
    let mut links = String::from(
        "scene,tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,freq_hz,max_depth,path_gain_db,num_paths\n",
    );
    let rows: Vec<&str> = fixture
        .lines()
        .filter(|l| l.starts_with("simple_street_canyon,"))
        .collect();
    for r in &rows {
        links.push_str(r);
        links.push('\n');
    }
    let links_file = env.write("links.csv", &links);
    let out = env.path("paths.csv");
    let r = env.cli(&[
        "trace",
        "--scene",
        canyon().to_str().unwrap(),
        "--links",
        links_file.to_str().unwrap(),
        "--freq-hz",
        "3.5e9",
        "--max-depth",
        "3",
        "--no-transmission",
        "--no-diffraction",
        "--no-diffuse",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let ours: Vec<f64> = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(6).unwrap().parse::<f64>().unwrap())
        .collect();
    assert_eq!(ours.len(), rows.len());
    let mut diffs: Vec<f64> = rows
        .iter()
        .zip(&ours)
        .filter_map(|(row, &g)| {
            let s: f64 = row
                .split(',')
                .nth(9)
                .unwrap()
                .parse()
                .unwrap_or(f64::NEG_INFINITY);
            assert_eq!(
                s.is_finite(),
                g.is_finite(),
                "paths on one side only: {row} vs {g}"
            );
            s.is_finite().then(|| (g - s).abs())
        })
        .collect();
    diffs.sort_by(f64::total_cmp);
    assert!(diffs[diffs.len() / 2] < 0.1, "{diffs:?}");
}

/// `kodama-dag radiomap` on the street canyon from its usual transmitter, with `options`, into
/// `out`.
fn canyon_map(env: &Env, options: &[&str], out: &Path) -> Run {
    let scene = canyon();
    let mut args = vec![
        "radiomap",
        "--scene",
        scene.to_str().unwrap(),
        "--tx",
        "-33,0,32",
        "--freq-hz",
        "3.5e9",
    ];
    args.extend_from_slice(options);
    args.extend_from_slice(&["--out", out.to_str().unwrap()]);
    env.cli(&args)
}

#[test]
fn radiomap_writes_each_format_and_rejects_others() {
    let env = Env::new();
    for ext in ["tif", "png", "exr"] {
        let out = env.path(&format!("map.{ext}"));
        let r = canyon_map(&env, &["--rays", "100000", "--cell-m", "2"], &out);
        assert_eq!(r.code, 0, "{}", r.stderr);
        let bytes = std::fs::read(&out).unwrap();
        let magic: &[u8] = match ext {
            "tif" => b"II*\0",
            "png" => b"\x89PNG",
            _ => b"\x76\x2f\x31\x01",
        };
        assert_eq!(&bytes[..4], magic, "{ext}");
    }
    let r = env.cli(&[
        "radiomap",
        "--scene",
        canyon().to_str().unwrap(),
        "--tx",
        "0,0,30",
        "--freq-hz",
        "3.5e9",
        "--out",
        env.path("map.jpg").to_str().unwrap(),
    ]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.contains("map.jpg") && r.stderr.contains(".tif, .exr or .png"),
        "{}",
        r.stderr
    );
    // Diffraction is drawn into the map, not ignored: behind the canyon's buildings it reaches
    // cells that rays alone leave dark, and adds power where they do not.
    let map_db = |flag: &str, name: &str| {
        let out = env.path(name);
        let options = [
            "--rays",
            "200000",
            "--cell-m",
            "4",
            "--max-depth",
            "1",
            "--no-transmission",
            flag,
        ];
        let r = canyon_map(&env, &options, &out);
        assert_eq!(r.code, 0, "{}", r.stderr);
        // The map's samples (f32, NaN where nothing arrived); its site-frame CRS is our own.
        let file = std::fs::File::open(&out).unwrap();
        match tiff::decoder::Decoder::new(file)
            .unwrap()
            .read_image()
            .unwrap()
        {
            tiff::decoder::DecodingResult::F32(v) => v,
            _ => panic!("the map is not f32"),
        }
    };
    let (plain, diffracted) = (
        map_db("--no-diffraction", "plain.tif"),
        map_db("--diffraction", "diffracted.tif"),
    );
    let reached = |m: &[f32]| m.iter().filter(|v| v.is_finite()).count();
    assert!(
        reached(&diffracted) > reached(&plain) + 10,
        "{} cells with diffraction, {} without",
        reached(&diffracted),
        reached(&plain)
    );
    assert!(
        plain
            .iter()
            .zip(&diffracted)
            .all(|(p, d)| !p.is_finite() || *d >= *p - 1e-3)
    );
}

#[test]
fn bad_links_exit_2_naming_the_file_and_write_nothing() {
    let env = Env::new();
    let links = env.write("links.csv", "tx_x,tx_y,tx_z,rx_x,rx_y\n0,0,10,50,0\n");
    let out = env.path("paths.csv");
    let r = env.cli(&[
        "trace",
        "--scene",
        canyon().to_str().unwrap(),
        "--links",
        links.to_str().unwrap(),
        "--freq-hz",
        "3.5e9",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.contains("links.csv") && r.stderr.contains("rx_z"),
        "{}",
        r.stderr
    );
    assert!(!out.exists());
    let links = env.write(
        "links2.csv",
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z\n0,0,10,50,0,abc\n",
    );
    let r = env.cli(&[
        "trace",
        "--scene",
        canyon().to_str().unwrap(),
        "--links",
        links.to_str().unwrap(),
        "--freq-hz",
        "3.5e9",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("line 2, column rx_z"), "{}", r.stderr);
    // A frequency outside the scene's materials' P.2040 ranges is refused unless extrapolating.
    let links = env.write(
        "links3.csv",
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z\n0,0,10,50,0,1.5\n",
    );
    let r = env.cli(&[
        "trace",
        "--scene",
        canyon().to_str().unwrap(),
        "--links",
        links.to_str().unwrap(),
        "--freq-hz",
        "60e9",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("GHz"), "{}", r.stderr);
}

/// The line-of-sight gain (dB) of one street-canyon link traced with `--tx-antenna antenna`.
fn los_gain(env: &Env, tx: [f64; 3], rx: [f64; 3], antenna: &str) -> Run {
    let links = env.write(
        "los.csv",
        &format!(
            "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z\n{},{},{},{},{},{}\n",
            tx[0], tx[1], tx[2], rx[0], rx[1], rx[2]
        ),
    );
    let out = env.path("los_out.csv");
    let _ = std::fs::remove_file(&out);
    env.cli(&[
        "trace",
        "--scene",
        canyon().to_str().unwrap(),
        "--links",
        links.to_str().unwrap(),
        "--freq-hz",
        "3.5e9",
        "--rays",
        "1000",
        "--no-reflection",
        "--no-transmission",
        "--tx-antenna",
        antenna,
        "--out",
        out.to_str().unwrap(),
    ])
}

#[test]
fn tx_antenna_points_a_sector_by_compass_bearing_and_refuses_bad_values() {
    let env = Env::new();
    // A line-of-sight link of the Sionna fixture: a sector whose boresight (compass bearing
    // clockwise from +y, downtilt) points at the receiver adds its 8 dBi peak to the LOS gain.
    let (tx, rx): ([f64; 3], [f64; 3]) = (
        [-33.0, 0.0, 32.0],
        [-55.72472001627618, -3.6680258971450135, 1.5],
    );
    let (dx, dy, dz) = (rx[0] - tx[0], rx[1] - tx[1], rx[2] - tx[2]);
    let bearing = dx.atan2(dy).to_degrees();
    let tilt = (-dz).atan2(dx.hypot(dy)).to_degrees();
    let gain = |antenna: &str| {
        let r = los_gain(&env, tx, rx, antenna);
        assert_eq!(r.code, 0, "{antenna}: {}", r.stderr);
        let text = std::fs::read_to_string(env.path("los_out.csv")).unwrap();
        let row = text.lines().nth(1).unwrap().to_owned();
        row.split(',').nth(6).unwrap().parse::<f64>().unwrap()
    };
    let iso = gain("iso");
    assert!(iso.is_finite(), "the link has a line of sight");
    let sector = gain(&format!("tr38901:{bearing}:{tilt}"));
    assert!(
        (sector - iso - 8.0).abs() < 2e-4,
        "iso {iso}, sector {sector}"
    );
    // Bad values exit 2 before any tracing, saying what was expected.
    for (bad, says) in [
        ("tr38901:nan:0", "finite"),
        ("tr38901:30:inf", "finite"),
        ("tr38901:north:0", "bearing"),
        ("tr38901:30", "a bearing and a tilt"),
        (
            "patch",
            "expected iso, dipole or tr38901:BEARING_DEG:TILT_DEG",
        ),
    ] {
        let r = los_gain(&env, tx, rx, bad);
        assert_eq!(r.code, 2, "{bad}: {}", r.stderr);
        assert!(
            r.stderr.contains("--tx-antenna") && r.stderr.contains(says),
            "{bad}: {}",
            r.stderr
        );
        assert!(!env.path("los_out.csv").exists());
    }
    let map = env.path("map.tif");
    let r = canyon_map(&env, &["--tx-antenna", "tr38901:90:x"], &map);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("tilt"), "{}", r.stderr);
    assert!(!map.exists());
}

/// `--device cuda` where it cannot run (a build without feature `cuda`, or no NVIDIA driver)
/// is the user's to fix: exit 2 and a line saying which, and no map written.
#[test]
fn radiomap_device_cuda_without_a_gpu_is_a_clear_error() {
    if kodama_nodes::rf::gpu::BUILT && kodama_nodes::rf::gpu::driver_present() {
        eprintln!("skipped: this machine has a CUDA driver");
        return;
    }
    let env = Env::new();
    let out = env.path("map.tif");
    let r = canyon_map(&env, &["--rays", "1000", "--device", "cuda"], &out);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("--features cuda") || r.stderr.contains("no CUDA driver"),
        "{}",
        r.stderr
    );
    assert!(!out.exists());
}

/// Flags are checked as a graph's params are: a non-finite or far-off transmitter and a cell that would
/// make more cells than a graph's RadioMap may (16 bytes each) are user errors, exit 2, before any
/// map is allocated or file written.
#[test]
fn radiomap_refuses_a_non_finite_transmitter_and_a_cell_too_fine() {
    let env = Env::new();
    let out = env.path("map.tif");
    for (tx, cell, says) in [
        ("NaN,0,10", "10", "expected finite coordinates"),
        ("0,inf,10", "10", "expected finite coordinates"),
        // Finite, and nowhere a scene can be.
        ("1e308,0,10", "10", "within 1e8 m of the site origin"),
        ("0,0,10", "1e-6", "use a coarser cell"),
    ] {
        let r = env.cli(&[
            "radiomap",
            "--scene",
            canyon().to_str().unwrap(),
            "--tx",
            tx,
            "--freq-hz",
            "3.5e9",
            "--cell-m",
            cell,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(r.code, 2, "{tx} {cell}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{tx} {cell}: {}", r.stderr);
        assert!(!out.exists());
    }
}
