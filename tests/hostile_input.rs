//! Hostile input to the engine and CLI: every bad input ends in exit 2 naming the file, the place
//! and what was expected, in bounded time, with nothing written outside --out and the cache.

mod common;
use common::*;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const SITE: &str = r#"site: Site(crs: "EPSG:32618", origin: (0.0, 0.0), cell_m: 1.0)"#;

fn graph(nodes: &str, outputs: &str) -> String {
    format!(
        "Graph(\n    {SITE},\n    nodes: {{\n{nodes}\n    }},\n    outputs: {{ {outputs} }},\n)\n"
    )
}

fn has(stderr: &str, needle: &str) {
    assert!(stderr.contains(needle), "expected {needle:?} in:\n{stderr}");
}

/// Runs `cmd`, killing it after `limit`: a hang is a test failure, not a stuck test.
fn run_bounded(mut cmd: Command, limit: Duration) -> Run {
    use std::io::Read;
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn kodama-dag");
    // Both pipes drained as the child writes: a child with more to say than a pipe holds
    // would otherwise block, and look like a hang.
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            let _ = r.read_to_end(&mut v);
            v
        })
    };
    let out = drain(Box::new(child.stdout.take().unwrap()));
    let err = drain(Box::new(child.stderr.take().unwrap()));
    let t0 = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if t0.elapsed() > limit {
            child.kill().unwrap();
            let _ = child.wait();
            panic!(
                "still running after {limit:?}; stderr: {}",
                String::from_utf8_lossy(&err.join().unwrap())
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    finish(std::process::Output {
        status,
        stdout: out.join().unwrap(),
        stderr: err.join().unwrap(),
    })
}

/// `kodama-dag ARGS...` in the env's folder.
fn command(env: &Env, args: &[&str]) -> Command {
    let mut c = Command::new(BIN);
    c.args(args).current_dir(env.dir.path());
    c
}

fn mkfifo(p: &Path) {
    let c = std::ffi::CString::new(p.as_os_str().as_encoded_bytes()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo");
}

/// A 4 x 4 PNG.
fn png() -> Vec<u8> {
    let img = image::RgbImage::from_pixel(4, 4, image::Rgb([90, 90, 90]));
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png).unwrap();
    buf.into_inner()
}

/// A view set of one view with `id`, in `env/<folder>`.
fn view_set(env: &Env, folder: &str, id: &str) {
    let dir = env.path(folder);
    std::fs::create_dir_all(dir.join("img")).unwrap();
    std::fs::write(dir.join("img/a.png"), png()).unwrap();
    let views = serde_json::json!([{
        "id": id, "image": "img/a.png", "width": 4, "height": 4,
        "intrinsics": {"hfov_deg": 60.0},
        "pose": {"x": 1.0, "y": 2.0, "z": 1.5},
        "orientation": {"heading_deg": 0.0, "pitch_deg": 0.0, "roll_deg": 0.0},
    }]);
    std::fs::write(dir.join("views.json"), views.to_string()).unwrap();
}

// ---------------------------------------------------------------------------------- paths out

#[test]
fn output_names_that_are_not_plain_file_names_are_refused() {
    for (name, why) in [
        ("../up", "path separator"),
        ("a\\\\b", "path separator"),
        ("", "cannot be empty"),
        ("a:b", "Windows forbids"),
        ("CON", "device name"),
        (".hidden", "starts with a dot"),
        ("tab\\there", "control character"),
    ] {
        let env = Env::new();
        let g = env.write(
            "g.ron",
            &graph(
                r#"        "t": SynthTerrain(size_m: (20.0, 20.0)),"#,
                &format!("\"{name}\": \"t\""),
            ),
        );
        let r = env.run(&g, &[]);
        assert_eq!(r.code, 2, "{name:?}: {}", r.stderr);
        has(&r.stderr, "g.ron:6:16: invalid output name");
        has(&r.stderr, why);
    }
}

/// A view id is data: "../../../escaped" must not become a file outside --out.
#[test]
fn a_view_id_that_is_not_a_file_name_writes_nothing_outside_out() {
    let env = Env::new();
    view_set(&env, "views", "../../../escaped");
    let g = env.write(
        "g.ron",
        &graph(
            r#"        "v": ReadViews(path: "views/views.json"),
        "t": SynthTerrain(size_m: (20.0, 20.0)),"#,
            r#""views": "v", "t": "t""#,
        ),
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "../../../escaped");
    let escaped: Vec<PathBuf> = walk(env.dir.path())
        .into_iter()
        .filter(|p| p.to_string_lossy().contains("escaped"))
        .collect();
    assert!(escaped.is_empty(), "written outside: {escaped:?}");
    // ReadViews refuses the id when it reads views.json, before any export could use it.
    has(&r.stderr, "view 0, id");
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if e.file_type().unwrap().is_dir() {
            out.extend(walk(&p));
        }
        out.push(p);
    }
    out
}

// ----------------------------------------------------------------------------------- paths in

#[test]
fn data_paths_that_leave_the_graph_folder_need_allow_outside() {
    let env = Env::new();
    let pts = env.write("pts.xyz", "x y z\n1 1 1\n2 2 2\n");
    let nodes = |path: &str| {
        format!(
            "        \"p\": ReadXyz(path: {path:?}),\n        \"s\": PointStats(points: \"p\"),"
        )
    };
    let cases = [
        ("up.ron", "../pts.xyz".to_string(), "leads outside"),
        ("abs.ron", pts.display().to_string(), "absolute path"),
    ];
    for (file, path, why) in cases {
        let g = env.write(&format!("site/{file}"), &graph(&nodes(&path), ""));
        let r = env.run(&g, &[]);
        assert_eq!(r.code, 2, "{path}: {}", r.stderr);
        has(&r.stderr, &format!("{file}:4:28: node \"p\": `path`"));
        has(&r.stderr, why);
        has(&r.stderr, "--allow-outside");
        let r = env.run(&g, &["--allow-outside"]).ok();
        assert_ne!(r.status("s"), "failed");
    }
    // A symlink inside the folder that leads out of it is the same escape.
    std::os::unix::fs::symlink(&pts, env.path("site/link.xyz")).unwrap();
    let g = env.write("site/link.ron", &graph(&nodes("link.xyz"), ""));
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "leads outside");
    // --data is the root when given: inside it is fine, `..` out of it is not.
    let r = env.run(&g, &["--data", env.dir.path().to_str().unwrap()]);
    assert_eq!(r.code, 2, "link.xyz is not in --data: {}", r.stderr);
    let g = env.write("site/in.ron", &graph(&nodes("pts.xyz"), ""));
    env.run(&g, &["--data", env.dir.path().to_str().unwrap()])
        .ok();
    let r = env.run(&g, &["--data", env.path("site").to_str().unwrap()]);
    assert_eq!(r.code, 2);
    let g = env.write("site/up2.ron", &graph(&nodes("../pts.xyz"), ""));
    let r = env.run(&g, &["--data", env.path("site").to_str().unwrap()]);
    assert_eq!(r.code, 2);
    has(&r.stderr, "leads outside --data");
}

/// FIFOs, devices and a folder where a file was meant are refused when the graph loads, before
/// anything opens them: a FIFO must not block the run.
#[test]
fn special_files_are_refused_at_load_without_blocking() {
    let env = Env::new();
    mkfifo(&env.path("fifo.xyz"));
    std::fs::create_dir_all(env.path("folder.xyz")).unwrap();
    view_set(&env, "views", "v1");
    mkfifo(&env.path("views/img/b.png"));
    let g = env.write(
        "g.ron",
        &graph(
            r#"        "a": ReadXyz(path: "fifo.xyz"),
        "b": ReadXyz(path: "folder.xyz"),
        "c": ReadViews(path: "views/views.json"),"#,
            "",
        ),
    );
    let r = run_bounded(env.run_cmd(&g, &[]), Duration::from_secs(60));
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "g.ron:4:28: node \"a\": `path` (");
    has(
        &r.stderr,
        "fifo.xyz): expected a regular file or a folder, found a FIFO",
    );
    has(&r.stderr, "node \"b\": `path`");
    has(&r.stderr, "expected a .xyz file, found a folder");
    has(
        &r.stderr,
        "views/img/b.png: a FIFO (named pipe), not a regular file",
    );
    // The same through explain, which never runs anything.
    let r = run_bounded(
        command(&env, &["explain", g.to_str().unwrap()]),
        Duration::from_secs(60),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
}

/// A graph file that is endless or huge is refused, not read into all of memory: a device is
/// not a graph file, and a regular file is read up to a bound.
#[test]
fn an_endless_graph_file_is_refused() {
    let env = Env::new();
    let r = run_bounded(
        command(&env, &["explain", "/dev/zero"]),
        Duration::from_secs(60),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(
        &r.stderr,
        "expected a regular file, found a character device",
    );
    let huge = env.path("huge.ron");
    std::fs::File::create(&huge)
        .unwrap()
        .set_len(65 << 20)
        .unwrap();
    let r = run_bounded(
        command(&env, &["explain", huge.to_str().unwrap()]),
        Duration::from_secs(60),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "larger than 64 MiB");
}

/// A FIFO given where a file is read, or named inside one, is refused at once (exit 2, saying
/// what it found) rather than waited on: the graph of `run`, a sweep, `gc --keep`, and a mesh a
/// scene file names under `radiomap`.
#[test]
fn a_fifo_anywhere_a_file_is_read_is_refused_without_blocking() {
    let env = Env::new();
    let fifo = env.path("pipe.ron");
    mkfifo(&fifo);
    let f = fifo.to_str().unwrap();
    let cache = env.path("cache");
    let cache = cache.to_str().unwrap();
    for args in [
        vec!["run", f],
        vec!["sweep", f],
        vec!["explain", f],
        vec!["gc", "--cache", cache, "--max-bytes", "0", "--keep", f],
    ] {
        if args[0] == "gc" {
            // gc refuses a folder that is no cache before it reads --keep: make one.
            let g = env.write("g.ron", &graph("", ""));
            let r = run_bounded(env.run_cmd(&g, &[]), Duration::from_secs(60));
            assert_eq!(r.code, 0, "{}", r.stderr);
        }
        let r = run_bounded(command(&env, &args), Duration::from_secs(60));
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        has(&r.stderr, "found a FIFO");
    }
    std::fs::create_dir_all(env.path("scene/meshes")).unwrap();
    mkfifo(&env.path("scene/meshes/a.ply"));
    let xml = env.write(
        "scene/scene.xml",
        r#"<scene version="2.1.0">
<bsdf type="itu-radio-material" id="itu_metal"><string name="type" value="metal"/></bsdf>
<shape type="ply" id="mesh-a"><string name="filename" value="meshes/a.ply"/><ref id="itu_metal" name="bsdf"/></shape>
</scene>"#,
    );
    let out = env.path("map.tif");
    let r = run_bounded(
        command(
            &env,
            &[
                "radiomap",
                "--scene",
                xml.to_str().unwrap(),
                "--tx",
                "0,0,10",
                "--freq-hz",
                "3.5e9",
                "--out",
                out.to_str().unwrap(),
            ],
        ),
        Duration::from_secs(60),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "a.ply");
    has(&r.stderr, "found a FIFO");
    assert!(!out.exists());
}

#[test]
fn a_sweep_graph_outside_its_folder_needs_allow_outside() {
    let env = Env::new();
    env.write("g.ron", CHAIN);
    let near = env.write(
        "sweeps/near.ron",
        r#"Sweep(graph: "../g.ron", axes: { "s": Grid(set: "smooth.sigma_m", values: [1.0]) }, metrics: [])"#,
    );
    env.cli(&["sweep", near.to_str().unwrap(), "--dry-run"])
        .ok();
    let far = env.write(
        "a/sweeps/far.ron",
        r#"Sweep(graph: "../../g.ron", axes: { "s": Grid(set: "smooth.sigma_m", values: [1.0]) }, metrics: [])"#,
    );
    let r = env.cli(&["sweep", far.to_str().unwrap(), "--dry-run"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "far.ron:1:14: the base graph");
    has(&r.stderr, "--allow-outside");
    env.cli(&[
        "sweep",
        far.to_str().unwrap(),
        "--dry-run",
        "--allow-outside",
    ])
    .ok();
    mkfifo(&env.path("sweeps/fifo.ron"));
    let fifo = env.write(
        "sweeps/f.ron",
        r#"Sweep(graph: "fifo.ron", axes: {}, metrics: [])"#,
    );
    let r = run_bounded(
        command(&env, &["sweep", fifo.to_str().unwrap(), "--dry-run"]),
        Duration::from_secs(60),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "a FIFO");
}

// ------------------------------------------------------------------------------------ nesting

#[test]
fn deeply_nested_graphs_are_an_error_not_a_stack_overflow() {
    let env = Env::new();
    let deep = format!(
        "Graph(\n    {SITE},\n    nodes: {{ \"t\": SynthTerrain(size_m: {}) }},\n)\n",
        "[".repeat(20_000)
    );
    let g = env.write("deep.ron", &deep);
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "deep.ron:3:");
    has(&r.stderr, "nested more than 128 levels");
    // A `--set` path is nesting too.
    let g = env.write("g.ron", CHAIN);
    let set = format!("smooth.sigma_m{}=1", ".x".repeat(20_000));
    let r = env.run(&g, &["--set", &set]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "nested more than 128 levels");
}

// ----------------------------------------------------------------------------- scale and time

/// Loading is linear in the nodes: 50,000 of them took 8 s when a duplicate-key check was
/// quadratic. The bound is loose on purpose (this is not a benchmark): quadratic would be minutes.
#[test]
fn a_graph_of_50000_nodes_loads_quickly() {
    let env = Env::new();
    let mut nodes = String::from("        \"n0\": SynthTerrain(size_m: (10.0, 10.0)),\n");
    for i in 1..50_000 {
        nodes.push_str(&format!(
            "        \"n{i}\": Clamp(raster: \"n{}\", max: 1.0),\n",
            i - 1
        ));
    }
    let g = env.write("big.ron", &graph(&nodes, ""));
    let t0 = Instant::now();
    let r = env.cli(&["graph", g.to_str().unwrap()]).ok();
    assert!(t0.elapsed() < Duration::from_secs(20), "{:?}", t0.elapsed());
    assert_eq!(r.stdout.matches(" -> ").count(), 49_999);
}

#[test]
fn jobs_are_capped() {
    let env = Env::new();
    let g = env.write("g.ron", CHAIN);
    let r = env.run(&g, &["--jobs", "1000000000"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    has(
        &r.stderr,
        "warning: --jobs 1000000000 is more than 4 per core",
    );
    let r = env.run(&g, &["--jobs", "0"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "expected at least 1 worker thread");
}

/// `trace` says what it is doing while it runs (bars on a terminal, lines elsewhere).
#[test]
fn direct_commands_report_progress() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/sionna-scenes/simple_street_canyon/simple_street_canyon.xml");
    assert!(
        scene.exists(),
        "real test data missing: {}",
        scene.display()
    );
    let env = Env::new();
    let links = env.write(
        "links.csv",
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z\n-30,0,10,30,5,1.5\n-30,0,10,20,-5,1.5\n10,0,12,25,3,1.5\n",
    );
    let out = env.path("paths.csv");
    let r = env
        .cli(&[
            "trace",
            "--scene",
            scene.to_str().unwrap(),
            "--links",
            links.to_str().unwrap(),
            "--freq-hz",
            "3.5e9",
            "--rays",
            "20000",
            "--out",
            out.to_str().unwrap(),
        ])
        .ok();
    has(&r.stderr, "reading the scene");
    has(&r.stderr, "tracing 3 links from 2 transmitters");
    assert_eq!(std::fs::read_to_string(&out).unwrap().lines().count(), 4);
    // A FIFO named on the command line is refused, not read.
    mkfifo(&env.path("fifo.csv"));
    let r = run_bounded(
        command(
            &env,
            &[
                "trace",
                "--scene",
                scene.to_str().unwrap(),
                "--links",
                "fifo.csv",
                "--freq-hz",
                "3.5e9",
                "--out",
                "x.csv",
            ],
        ),
        Duration::from_secs(60),
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(
        &r.stderr,
        "--links fifo.csv: expected a regular file, found a FIFO",
    );
}

// ------------------------------------------------------------------------------------ garbage

#[test]
fn two_outputs_writing_one_file_are_refused() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        &graph(
            r#"        "t": SynthTerrain(size_m: (20.0, 20.0)),"#,
            r#""t": "t", "T.tif": "t""#,
        ),
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(
        &r.stderr,
        "g.ron:6:26: output \"T.tif\" writes T.tif, as output \"t\" does",
    );
}

#[test]
fn numbers_that_can_never_run_are_caught_at_load() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        &graph(
            r#"        "t": SynthTerrain(size_m: (inf, 1e400)),
        "b": GaussianBlur(raster: "t", sigma_m: NaN),"#,
            "",
        ),
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(
        &r.stderr,
        "g.ron:4:36: node \"t\": `size_m`: inf can never run; expected a finite number",
    );
    has(&r.stderr, "g.ron:4:41: node \"t\": `size_m`: inf");
    has(&r.stderr, "g.ron:5:49: node \"b\": `sigma_m`: NaN");
    let r = env.run(
        &env.write("g.ron", CHAIN),
        &["--set", "smooth.sigma_m=-inf"],
    );
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "`sigma_m`: -inf can never run");
    let g = env.write("site.ron", &CHAIN.replace("cell_m: 0.5", "cell_m: 1e-300"));
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(
        &r.stderr,
        "site.ron:3:74: invalid `cell_m`: a cell of 1e-300 m is finer than the 0.001 m",
    );
}

#[test]
fn a_sweep_metric_naming_nothing_is_refused() {
    let env = Env::new();
    env.write("g.ron", CHAIN);
    let s = env.write(
        "s.ron",
        r#"Sweep(graph: "g.ron", axes: { "s": Grid(set: "smooth.sigma_m", values: [1.0, 2.0]) }, metrics: ["stats.meen"])"#,
    );
    let r = env.sweep(&s, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "metric \"stats.meen\" names nothing");
    has(&r.stderr, "did you mean `mean`?");
}

/// The fields this issue added: a sweep's `metrics_only` that is not a boolean, and a SynthCity
/// variation range out of order or share above 1, are refused with exit 2, naming the file, the
/// place and what was expected, before anything runs.
#[test]
fn a_bad_metrics_only_or_city_variation_is_refused() {
    let env = Env::new();
    env.write("g.ron", CHAIN);
    let s = env.write(
        "s.ron",
        r#"Sweep(graph: "g.ron", axes: { "s": Grid(set: "smooth.sigma_m", values: [1.0]) }, metrics: ["stats.mean"], metrics_only: 1)"#,
    );
    let r = env.sweep(&s, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "s.ron:1:");
    has(&r.stderr, "expected true or false");
    let city = env.write(
        "city.ron",
        r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 1.0),
    nodes: {
        "city": SynthCity(size_m: (120.0, 100.0), blocks: (2, 2), street_m: 14.0, terrain: (size_m: (120.0, 100.0)), variation: (recess_m: (0.4, 0.1))),
    },
)"#,
    );
    let r = env.run(&city, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "city.ron:");
    has(&r.stderr, "variation.recess_m");
    let r = env.run(&city, &["--set", "city.variation=(bay_share: 1.5)"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "variation.bay_share");
    assert!(!env.cache().join("cas").exists() || env.blobs().is_empty());
}

// ------------------------------------------------------------------------------ output folder

fn inode(p: &Path) -> u64 {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(p).unwrap().ino()
}

/// The manifest trusts an output only while its files are the ones written: a touched file is
/// checked by content and kept, a deleted file inside a folder output brings the folder back, and
/// a run from elsewhere (another working folder) still recognises its files.
#[test]
fn the_output_manifest_checks_every_file_it_wrote() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 1.0),
    nodes: {
        "city":  SynthCity(size_m: (120.0, 100.0), blocks: (2, 2), street_m: 14.0, terrain: (size_m: (120.0, 100.0))),
        "truth": TruthScene(city: "city"),
    },
    outputs: { "truth": "truth", "tiles.3dtiles": "truth" },
)"#,
    );
    // A relative --out from the graph's folder...
    let run_rel = || {
        let mut c = command(
            &env,
            &["run", "g.ron", "--cache", "cache", "--out", "out", "-q"],
        );
        finish(c.output().unwrap()).ok()
    };
    run_rel();
    let glb = env.out().join("truth.glb");
    let tileset = env.out().join("tiles.3dtiles/tileset.json");
    let (glb_ino, tiles_ino) = (inode(&glb), inode(&tileset));
    // ...then the same folder by its absolute path, from another working folder: nothing rewritten.
    env.run(&g, &[]).ok();
    assert_eq!((inode(&glb), inode(&tileset)), (glb_ino, tiles_ino));
    // Touched, same bytes: checked by content and kept.
    let f = std::fs::File::options().write(true).open(&glb).unwrap();
    f.set_modified(std::time::SystemTime::now() - Duration::from_secs(60))
        .unwrap();
    drop(f);
    env.run(&g, &[]).ok();
    assert_eq!(inode(&glb), glb_ino, "a touched output is not rewritten");
    // Same size, other bytes: rewritten.
    let original = std::fs::read(&glb).unwrap();
    std::fs::write(&glb, vec![0u8; original.len()]).unwrap();
    env.run(&g, &[]).ok();
    assert_eq!(std::fs::read(&glb).unwrap(), original);
    // A file deleted inside a folder output: the folder is written again.
    let tile = std::fs::read_dir(env.out().join("tiles.3dtiles/tiles"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    std::fs::remove_file(&tile).unwrap();
    run_rel();
    assert!(tile.is_file(), "{} restored", tile.display());
}

/// Temp files and folders a killed export left behind are removed by the next run.
#[test]
fn temps_a_killed_run_left_are_removed() {
    let env = Env::new();
    let g = env.write("g.ron", CHAIN);
    env.run(&g, &[]).ok();
    // The pid of a process that has exited.
    let mut child = Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    let file = env.out().join(format!(".kodama-{dead}-3-0000abcd.tmp"));
    let folder = env.out().join(format!(".kodama-{dead}-tiles.3dtiles.tmp"));
    std::fs::write(&file, b"half").unwrap();
    std::fs::create_dir_all(folder.join("tiles")).unwrap();
    std::fs::write(folder.join("tiles/0_0.glb"), b"half").unwrap();
    let cache_tmp = env
        .cache()
        .join("tmp")
        .join(format!(".kodama-{dead}-1-0.tmp"));
    std::fs::write(&cache_tmp, b"half").unwrap();
    let mine = env
        .out()
        .join(format!(".kodama-{}-9-0.tmp", std::process::id()));
    std::fs::write(&mine, b"a live process's temp").unwrap();
    env.run(&g, &[]).ok();
    assert!(!file.exists() && !folder.exists() && !cache_tmp.exists());
    assert!(mine.exists(), "a live process's temp is left alone");
}

/// An output that cannot be written fails the run (exit 1) but the record is printed, and the
/// other outputs are written.
#[test]
fn the_run_record_is_printed_when_an_export_fails() {
    let env = Env::new();
    let g = env.write("g.ron", CHAIN);
    std::fs::create_dir_all(env.out().join("dsm.tif/in_the_way")).unwrap();
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    let rec = r.json();
    assert!(rec["output_errors"]["dsm"]["error"].is_string(), "{rec}");
    assert!(rec["outputs"]["stats"].is_string(), "{rec}");
    has(&r.stderr, "error: output \"dsm\" was not written");
}

#[test]
fn exr_outputs_are_byte_identical_run_to_run() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        &graph(
            r#"        "t": SynthTerrain(seed: 3, size_m: (600.0, 500.0), relief_m: 2.0),"#,
            r#""t.exr": "t""#,
        ),
    );
    let mut files = Vec::new();
    for out in ["a", "b", "c"] {
        let dir = env.path(out);
        env.cli(&[
            "run",
            g.to_str().unwrap(),
            "--cache",
            env.cache().to_str().unwrap(),
            "--out",
            dir.to_str().unwrap(),
            "-q",
        ])
        .ok();
        files.push(std::fs::read(dir.join("t.exr")).unwrap());
    }
    assert!(files.iter().all(|f| *f == files[0]));
}

// -------------------------------------------------------------------------------------- watch

/// watch keeps following an input that is deleted (the graph then fails to load) and recreated.
#[test]
fn watch_follows_an_input_that_is_deleted_and_recreated() {
    let env = Env::new();
    let pts = env.write("pts.xyz", "x y z\n1 1 1\n2 2 2\n");
    let g = env.write(
        "g.ron",
        &graph(
            "        \"p\": ReadXyz(path: \"pts.xyz\"),\n        \"s\": PointStats(points: \"p\"),",
            "",
        ),
    );
    let mut child = Command::new(BIN)
        .args(["watch", g.to_str().unwrap(), "--cache"])
        .arg(env.cache())
        .arg("--out")
        .arg(env.out())
        .args(["--json", "-q", "--debounce-ms", "200"])
        .current_dir(env.dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (tx, rx) = mpsc::channel::<(bool, String)>();
    let (out, err) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
    let t1 = tx.clone();
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines() {
            let _ = t1.send((true, l.unwrap_or_default()));
        }
    });
    std::thread::spawn(move || {
        for l in BufReader::new(err).lines() {
            let _ = tx.send((false, l.unwrap_or_default()));
        }
    });
    // Stdout and stderr arrive through two threads in no fixed order: each stream is read from
    // its own cursor.
    let mut lines: [Vec<String>; 2] = [Vec::new(), Vec::new()];
    let mut at = [0usize; 2];
    let mut wait_for = |stdout: bool, pat: &str| -> String {
        let k = usize::from(stdout);
        loop {
            while at[k] < lines[k].len() {
                at[k] += 1;
                if lines[k][at[k] - 1].contains(pat) {
                    return lines[k][at[k] - 1].clone();
                }
            }
            let (is_out, line) = rx
                .recv_timeout(Duration::from_secs(60))
                .unwrap_or_else(|_| panic!("no {pat:?} in time; seen: {lines:?}"));
            lines[usize::from(is_out)].push(line);
        }
    };
    wait_for(true, "\"nodes\"");
    wait_for(false, "watching");
    std::fs::remove_file(&pts).unwrap();
    wait_for(false, "file not found");
    wait_for(false, "watching");
    std::fs::write(&pts, "x y z\n1 1 1\n2 2 2\n3 3 3\n").unwrap();
    let rec: serde_json::Value = serde_json::from_str(&wait_for(true, "\"nodes\"")).unwrap();
    let status = |id: &str| {
        rec["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["id"] == id)
            .map(|n| n["status"].as_str().unwrap().to_owned())
    };
    assert_eq!(status("p").as_deref(), Some("ran"), "{rec}");
    child.kill().unwrap();
    child.wait().unwrap();
}

/// A graph file whose stem names no file of its own (`...ron`: the stem `..`) writes its outputs
/// to `out/graph`, not to the folder above `out`.
#[test]
fn a_graph_named_dot_dot_writes_inside_out() {
    let env = Env::new();
    env.write(
        "...ron",
        &graph(
            r#""terrain": SynthTerrain(seed: 1, size_m: (40.0, 40.0), relief_m: 1.0),"#,
            r#""terrain.tif": "terrain","#,
        ),
    );
    let r = env.cli(&["run", "...ron", "--cache", "cache", "--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(env.path("out/graph/terrain.tif").is_file(), "{}", r.stderr);
    assert!(!env.path("terrain.tif").exists() && !env.path("out/terrain.tif").exists());
}

/// Every scene a stage builds is checked before anything downstream sees it: a DEM cell of 3e38
/// (finite, and a terrain vertex no tracer can hold) leaves its mesh out, named; a scene left
/// with nothing is exit 2 rather than an empty scene traced as if it were the site.
#[test]
fn a_scene_object_past_any_site_is_named_not_traced() {
    use kodama_nodes::artifact::{Grid, PodVec, Raster};
    let env = Env::new();
    let site = kodama_nodes::site::Site {
        crs: "EPSG:32618".into(),
        origin: (0.0, 0.0),
        cell_m: 1.0,
    };
    let mut data = vec![10.0f32; 100];
    data[55] = 3e38;
    let dem = Raster {
        grid: Grid {
            x0: 0.0,
            y0: 10.0,
            cell_m: 1.0,
            width: 10,
            height: 10,
        },
        data: PodVec(data),
    };
    let mut f = std::fs::File::create(env.path("dem.tif")).unwrap();
    kodama_nodes::io::geotiff::write_geotiff(&dem, &site, &mut f).unwrap();
    let g = env.write(
        "g.ron",
        &graph(
            r#"        "dem": ReadRaster(path: "dem.tif"),
        "scene": AssembleScene(terrain: "dem", objects: []),"#,
            "",
        ),
    );
    let r = run_bounded(env.run_cmd(&g, &[]), Duration::from_secs(120));
    assert_eq!(r.code, 2, "{}", r.stderr);
    has(&r.stderr, "every one of the 1 failed");
    has(&r.stderr, "terrain: vertex");
    has(&r.stderr, "found 7.5e37");
}

/// What an error echoes reaches a terminal tamed: a node id with an escape byte is printed as
/// `\u{1b}`, never raw, and a file's 300,000 column names are cut to a line of bounded length.
#[test]
fn error_lines_are_escaped_and_bounded() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        &graph(
            r#"        "a\u{1b}]0;owned\u{7}": ReadXyz(path: "missing.xyz"),"#,
            "",
        ),
    );
    let r = run_bounded(env.run_cmd(&g, &[]), Duration::from_secs(60));
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        !r.stderr.contains('\u{1b}') && !r.stderr.contains('\u{7}'),
        "{:?}",
        r.stderr
    );
    has(&r.stderr, "\\u{1b}");
    let header: Vec<String> = (0..300_000).map(|i| format!("c{i}")).collect();
    env.write("m.csv", &format!("{}\n", header.join(",")));
    let g = env.write(
        "m.ron",
        &graph(
            r#"        "m": ReadMeasurements(path: "m.csv"),"#,
            r#""m": "m""#,
        ),
    );
    let r = run_bounded(env.run_cmd(&g, &[]), Duration::from_secs(60));
    assert_eq!(r.code, 2, "{}", &r.stderr[..r.stderr.len().min(500)]);
    let longest = r.stderr.lines().map(|l| l.chars().count()).max().unwrap();
    assert!(longest < 2100, "a line of {longest} characters");
    // Its end, which says what was expected, stays.
    has(&r.stderr, "c299999");
    has(&r.stderr, "characters left out)");
}
