//! Tiled runs (city scale): a synthetic city run in tiles with halos gives the buildings an
//! untiled run gives, each once (owned by the tile holding its centroid), and a tiled graph's
//! mistakes are refused with exit 2.

mod common;
use common::*;

use kodama_nodes::artifact::Mesh;

/// A building as compared: where it stands (its volume centroid, from glTF's y-up frame back to
/// the site's), its volume and its horizontal bounds.
struct Solid {
    name: String,
    at: (f64, f64),
    volume: f64,
    lo: (f64, f64),
    hi: (f64, f64),
}

fn solids(glb: &std::path::Path) -> Vec<Solid> {
    building_meshes(glb)
        .into_iter()
        .map(|(name, m)| {
            // glTF is y-up: site (x, y, z) is stored as (x, z, -y).
            let site = Mesh {
                positions: kodama_nodes::artifact::PodVec(
                    m.positions.iter().map(|p| [p[0], -p[2], p[1]]).collect(),
                ),
                triangles: m.triangles.clone(),
                materials: m.materials.clone(),
            };
            let at = site.owner_point().expect("a building has vertices");
            let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
            for p in site.positions.iter() {
                lo = (lo.0.min(p[0] as f64), lo.1.min(p[1] as f64));
                hi = (hi.0.max(p[0] as f64), hi.1.max(p[1] as f64));
            }
            Solid {
                name,
                at,
                volume: site.volume(),
                lo,
                hi,
            }
        })
        .collect()
}

/// The terrain raster's cells by their centres (CRS metres, to the centimetre).
fn terrain_cells(tif: &std::path::Path) -> std::collections::HashMap<(i64, i64), f64> {
    let t = kodama_nodes::io::geotiff::read_geotiff(tif).unwrap();
    let g = &t.pixels;
    let mut out = std::collections::HashMap::new();
    for row in 0..g.height {
        for col in 0..g.width {
            let v = t.sample((row * g.width + col) as usize, 0);
            if v.is_finite() && t.nodata != Some(v) {
                let x = g.west + (col as f64 + 0.5) * g.dx;
                let y = g.north - (row as f64 + 0.5) * g.dy;
                out.insert(((x * 100.0).round() as i64, (y * 100.0).round() as i64), v);
            }
        }
    }
    out
}

fn run_scene(env: &Env, graph: &std::path::Path, out: &str, extra: &[&str]) -> Vec<Solid> {
    let out_dir = env.path(out);
    let cache = env.cache();
    let mut args = vec![
        "run",
        graph.to_str().unwrap(),
        "--cache",
        cache.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    let r = env.cli(&args);
    assert_eq!(r.code, 0, "{}", r.stderr);
    solids(&out_dir.join("scene.glb"))
}

/// The paper's Sec. 4.1 buildings of a 600 m city in 2 x 2 tiles of 300 m against one untiled
/// run: every untiled building is in the tiled scene once, at the same place, with the same
/// bounds and volume (to the float noise of a raster read in another window), and nothing else
/// is; each tiled building is named after the one tile that owns it. The merged terrain raster
/// has the untiled one's cells and heights.
#[test]
fn tiled_and_untiled_runs_give_the_same_buildings() {
    let env = Env::new();
    let graph = env.write("city.ron", TILED_CITY);
    let untiled = run_scene(&env, &graph, "untiled", &[]);
    let tiled = run_scene(&env, &graph, "tiled", &["--tile-m", "300"]);
    assert!(untiled.len() >= 20, "{} buildings untiled", untiled.len());
    let mut worst = (0.0f64, 0.0f64);
    let mut unmatched = Vec::new();
    let mut used = vec![false; tiled.len()];
    // Stacked parts of one building (a tower on its podium) stand at nearly the same centroid:
    // each untiled solid takes the unused tiled one nearest in place, bounds and volume.
    let differ = |t: &Solid, u: &Solid| {
        let bounds = [
            t.lo.0 - u.lo.0,
            t.lo.1 - u.lo.1,
            t.hi.0 - u.hi.0,
            t.hi.1 - u.hi.1,
        ]
        .iter()
        .fold(0.0f64, |m, d| m.max(d.abs()));
        (bounds, (t.volume - u.volume).abs() / u.volume)
    };
    for u in &untiled {
        let best = (0..tiled.len())
            .filter(|&k| !used[k])
            .filter(|&k| (tiled[k].at.0 - u.at.0).hypot(tiled[k].at.1 - u.at.1) < 0.5)
            .min_by(|&a, &b| {
                let (da, db) = (differ(&tiled[a], u), differ(&tiled[b], u));
                (da.0 + da.1).total_cmp(&(db.0 + db.1))
            });
        let Some(k) = best else {
            unmatched.push(format!("{} at {:?}", u.name, u.at));
            continue;
        };
        used[k] = true;
        let t = &tiled[k];
        let (bounds, volume) = differ(t, u);
        worst.0 = worst.0.max(bounds);
        worst.1 = worst.1.max(volume);
        let owner = t.name.split('/').next().unwrap_or_default();
        let (col, row) = ((u.at.0 / 300.0) as usize, (u.at.1 / 300.0) as usize);
        assert!(
            owner.ends_with(&format!("x{col}y{row}")),
            "{} at {:?} comes from {owner}",
            t.name,
            u.at
        );
    }
    println!(
        "{} buildings untiled, {} tiled; largest bound difference {:.4} m, volume {:.4} %",
        untiled.len(),
        tiled.len(),
        worst.0,
        100.0 * worst.1
    );
    // The merged terrain raster against the untiled one, cell by cell: continuous across the
    // seams (one mosaic on the site's lattice) and the same ground.
    let (t_untiled, t_tiled) = (
        terrain_cells(&env.path("untiled").join("terrain.tif")),
        terrain_cells(&env.path("tiled").join("terrain.tif")),
    );
    let dz: Vec<f64> = t_tiled
        .iter()
        .filter_map(|(k, z)| t_untiled.get(k).map(|u| (z - u).abs()))
        .collect();
    let worst_dz = dz.iter().copied().fold(0.0f64, f64::max);
    let mean_dz = dz.iter().sum::<f64>() / dz.len().max(1) as f64;
    println!(
        "terrain: {} of {} merged cells where the untiled raster has one; height difference mean {mean_dz:.4} m, largest {worst_dz:.3} m",
        dz.len(),
        t_tiled.len()
    );
    assert!(
        dz.len() * 10 >= t_tiled.len() * 9,
        "the terrain rasters do not share their cells"
    );
    // The 3D Tiles of the merged scene: one leaf per run tile, beside the terrain's.
    let tileset: serde_json::Value = serde_json::from_slice(
        &std::fs::read(env.path("tiled").join("scene.3dtiles/tileset.json")).unwrap(),
    )
    .unwrap();
    let uris: Vec<&str> = tileset["root"]["children"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|c| c["content"]["uri"].as_str())
        .collect();
    for tile in ["x0y0", "x1y0", "x0y1", "x1y1"] {
        assert!(
            uris.contains(&format!("tiles/{tile}.glb").as_str()),
            "{uris:?}"
        );
    }
    assert!(unmatched.is_empty(), "unmatched: {unmatched:#?}");
    assert_eq!(
        untiled.len(),
        tiled.len(),
        "the tiled scene has extra buildings"
    );
    assert!(worst.0 < 0.05 && worst.1 < 0.005, "{worst:?}");
}

/// A tiled graph's mistakes, each refused before anything runs, with exit 2 and a message
/// naming what was wrong.
#[test]
fn tiling_mistakes_are_refused() {
    let env = Env::new();
    let graph = env.write("city.ron", TILED_CITY);
    let g = graph.to_str().unwrap();
    let refused = |args: &[&str], says: &str| {
        let mut all = vec!["explain", g, "--cache", "c"];
        all.extend_from_slice(args);
        let r = env.cli(&all);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
    };
    refused(&["--tile-m", "0.3"], "tile size of at least 8 site cells");
    refused(&["--tile-m", "100.25"], "whole number");
    refused(&["--tile-m", "4"], "more than the 10000");
    refused(&["--tile-m", "nan"], "finite");
    refused(&["--tile-m", "300", "--halo-m", "1e9"], "halo");
    let bad = |from: &str, to: &str| env.write("bad.ron", &TILED_CITY.replace(from, to));
    // The graph file at `path`, tiled in 300 m tiles.
    let refused_file = |path: &std::path::Path, says: &str| {
        let r = env.cli(&[
            "explain",
            path.to_str().unwrap(),
            "--cache",
            "c",
            "--tile-m",
            "300",
        ]);
        assert_eq!(r.code, 2, "{}: {}", path.display(), r.stderr);
        assert!(r.stderr.contains(says), "{}: {}", path.display(), r.stderr);
    };
    for (from, to, says) in [
        (
            r#"merge: ["terrain2", "solids"]"#,
            r#"merge: ["solid"]"#,
            "did you mean `solids`",
        ),
        (
            r#"merge: ["terrain2", "solids"]"#,
            r#"merge: ["truth", "solids"]"#,
            "is made once",
        ),
        (
            r#"outputs: { "scene": "scene", "terrain": "terrain2", "scene.3dtiles": "scene" },"#,
            r#"outputs: { "scene": "scene", "dsm": "dsm" },"#,
            "made per tile: add it to `merge`",
        ),
        (
            r#"merge: ["terrain2", "solids"]"#,
            r#"merge: ["terrain2"]"#,
            "made per tile: add it to `merge`",
        ),
        ("max: (600.0, 600.0)", "max: (600.2, 600.0)", "cell lattice"),
        (
            "max: (600.0, 600.0)",
            "max: (1e15, 1e15)",
            "more than the 10000",
        ),
        (
            "max: (600.0, 600.0)",
            "max: (0.0, 600.0)",
            "south-west of `max`",
        ),
        ("merge:", "building_m: -1.0, merge:", "building_m"),
    ] {
        refused_file(&bad(from, to), says);
    }
    // Metrics are not merged.
    let stats = TILED_CITY
        .replace(
            r#""scene":     AssembleScene"#,
            r#""pstats": PointStats(points: "lidar"), "scene": AssembleScene"#,
        )
        .replace(
            r#"merge: ["terrain2", "solids"]"#,
            r#"merge: ["terrain2", "solids", "pstats"]"#,
        );
    refused_file(
        &env.write("stats.ron", &stats),
        "only Scene, Raster, Points are merged",
    );
    // A graph without a tiling block cannot be tiled from the command line.
    let plain = TILED_CITY.replace(
        r#"tiling: Tiling(area: (min: (0.0, 0.0), max: (600.0, 600.0)), merge: ["terrain2", "solids"]),"#,
        "",
    );
    refused_file(&env.write("plain.ron", &plain), "need the graph's `tiling");
    // --tile on an untiled run, and a tile past the last.
    let r = env.cli(&["run", g, "--cache", "c", "--tile", "0"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("need a tiled graph"), "{}", r.stderr);
    let r = env.cli(&["run", g, "--cache", "c", "--tile-m", "300", "--tile", "4"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("from 0 to 3"), "{}", r.stderr);
}

/// A small city's street level: Sec. 4.1's buildings, registered street views, façade materials
/// and relief, clutter and canopies, the finished twin merged from 2 x 1 tiles of 120 m.
const STREET_TILES: &str = r#"Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    tiling: Tiling(area: (min: (0.0, 0.0), max: (240.0, 120.0)), merge: ["terrain2", "twin"]),
    nodes: {
        "city":       SynthCity(seed: 5, size_m: (240.0, 120.0), blocks: (2, 1)),
        "truth":      TruthScene(city: "city"),
        "lidar":      SynthLidar(scene: "truth", density_per_m2: 8.0, noise_m: 0.05, seed: 5),
        "views":      SynthViews(scene: "truth", city: "city", size: (200, 150), spacing_m: 20.0, max_views: 200,
                                 pose_noise_m: 0.5, heading_noise_deg: 1.0),
        "dsm":        RasterizeSurface(points: "lidar", mode: Max, max_gap_m: 1.0),
        "terrain1":   TerrainPass(surface: "dsm", coarse_m: 32.0, percentile: 5.0, n_min: 0.9, tau_m: 4.0, sigma_m: 2.0),
        "terrain2":   TerrainPass(surface: "dsm", previous: "terrain1", coarse_m: 8.0, percentile: 10.0, n_min: 0.9, tau_m: 1.0, sigma_m: 1.0),
        "above":      AboveGround(surface: "dsm", terrain: "terrain2"),
        "buildings":  BuildingMask(above: "above", points: "lidar"),
        "roofs":      RoofClean(labels: "buildings", above: "above", points: "lidar", terrain: "terrain2"),
        "parts":      SplitBuildings(labels: "buildings", roofs: "roofs"),
        "solids":     BuildingSolids(labels: "parts", roofs: "roofs", terrain: "terrain2", points: "lidar"),
        "scene":      AssembleScene(terrain: "terrain2", objects: ["solids"]),
        "registered": RegisterViews(views: "views", scene: "scene"),
        "charts":     SurfaceCharts(scene: "scene"),
        "materials":  FuseMaterials(views: "registered", scene: "scene", charts: "charts"),
        "painted":    ApplyMaterials(scene: "scene", charts: "charts", materials: "materials"),
        "relief":     Relief(views: "registered", scene: "scene", charts: "charts"),
        "carved":     CarveRelief(scene: "painted", charts: "charts", relief: "relief"),
        "unassigned": UnassignedAbove(above: "above", labels: "parts"),
        "canopies":   Canopies(unassigned: "unassigned", terrain: "terrain2", points: "lidar"),
        "clutter":    PlaceClutter(views: "registered", scene: "scene", terrain: "terrain2", canopies: "canopies", drop_vehicles_in_intersections: false),
        "twin":       AssembleScene(terrain: "terrain2", objects: ["carved", "clutter", "canopies"]),
    },
    outputs: { "twin": "twin" },
)"#;

/// Per object of a twin's glb: its class (the node's `extras.class`) and horizontal bounds in
/// the site frame, read from the glTF JSON (glTF is y-up: site (x, y) is (x, -z)).
fn twin_objects(glb: &std::path::Path) -> Vec<(String, (f64, f64), (f64, f64))> {
    let bytes = std::fs::read(glb).unwrap();
    let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let j: serde_json::Value = serde_json::from_slice(&bytes[20..20 + len]).unwrap();
    let mut out = Vec::new();
    for node in j["nodes"].as_array().unwrap() {
        let class = node["extras"]["class"].as_str().unwrap_or("?").to_string();
        let Some(mesh) = node["mesh"].as_u64() else {
            continue;
        };
        let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
        for prim in j["meshes"][mesh as usize]["primitives"].as_array().unwrap() {
            let acc = &j["accessors"][prim["attributes"]["POSITION"].as_u64().unwrap() as usize];
            let (min, max) = (&acc["min"], &acc["max"]);
            let f = |v: &serde_json::Value, k: usize| v[k].as_f64().unwrap();
            lo = (lo.0.min(f(min, 0)), lo.1.min(-f(max, 2)));
            hi = (hi.0.max(f(max, 0)), hi.1.max(-f(min, 2)));
        }
        out.push((class, lo, hi));
    }
    out
}

/// The street level in tiles against one untiled run. The halo (the stages' reach, 140 m)
/// covers this small city, so each tile registers every view and places every object as the
/// untiled run does: the merged twin must be the untiled one object for object (buildings at
/// their place and bounds within a metre, and every object of every class, clutter and trees
/// included, once, its bounds within a centimetre) whatever the windows, phases and merges do.
/// Objects two tiles place apart at a seam (their views registered apart, on a city larger than
/// a tile's window) are MergeScenes' unit test.
#[test]
fn the_street_level_in_tiles_is_the_untiled_twin() {
    let env = Env::new();
    let graph = env.write("street.ron", STREET_TILES);
    let run = |out: &str, tile_m: &str| {
        let out_dir = env.path(out);
        let (g, c, o) = (
            graph.to_str().unwrap(),
            env.cache(),
            out_dir.to_str().unwrap().to_string(),
        );
        let r = env.cli(&[
            "run",
            g,
            "--cache",
            c.to_str().unwrap(),
            "--out",
            &o,
            "--quiet",
            "--tile-m",
            tile_m,
        ]);
        assert_eq!(r.code, 0, "{}", r.stderr);
        out_dir.join("twin.glb")
    };
    let (untiled, tiled) = (run("untiled", "1000"), run("tiled", "120"));
    let (a, b) = (solids(&untiled), solids(&tiled));
    assert!(!a.is_empty());
    assert_eq!(
        a.len(),
        b.len(),
        "buildings: untiled {} tiled {}",
        a.len(),
        b.len()
    );
    // Each untiled building's nearest tiled one (a part can stand inside another's bounds, its
    // centroid close): within a metre, its bounds too, and no tiled building taken twice.
    let mut taken = vec![false; b.len()];
    for s in &a {
        let gap = |t: &Solid| (t.at.0 - s.at.0).hypot(t.at.1 - s.at.1);
        let k = (0..b.len())
            .min_by(|&i, &j| gap(&b[i]).total_cmp(&gap(&b[j])))
            .unwrap();
        let t = &b[k];
        let bounds = [
            s.lo.0 - t.lo.0,
            s.lo.1 - t.lo.1,
            s.hi.0 - t.hi.0,
            s.hi.1 - t.hi.1,
        ];
        assert!(
            gap(t) < 1.0 && bounds.iter().all(|d| d.abs() < 1.0) && !taken[k],
            "{} at {:?}: nearest tiled {} at {:?}",
            s.name,
            s.at,
            t.name,
            t.at
        );
        taken[k] = true;
    }
    // Every object of every class, by its bounds: the untiled twin's, each once.
    let (oa, ob) = (twin_objects(&untiled), twin_objects(&tiled));
    assert_eq!(
        oa.len(),
        ob.len(),
        "objects: untiled {} tiled {}",
        oa.len(),
        ob.len()
    );
    let mut taken = vec![false; ob.len()];
    for (class, lo, hi) in &oa {
        let off = |o: &(String, (f64, f64), (f64, f64))| {
            [lo.0 - o.1.0, lo.1 - o.1.1, hi.0 - o.2.0, hi.1 - o.2.1]
                .iter()
                .fold(0.0f64, |m, d| m.max(d.abs()))
        };
        let k = (0..ob.len())
            .filter(|&k| ob[k].0 == *class && !taken[k])
            .min_by(|&i, &j| off(&ob[i]).total_cmp(&off(&ob[j])));
        let k = k.unwrap_or_else(|| panic!("{class} at {lo:?}: none left in the tiled twin"));
        assert!(
            off(&ob[k]) < 0.01,
            "{class} at {lo:?}: nearest tiled {:?}",
            ob[k]
        );
        taken[k] = true;
    }
}
