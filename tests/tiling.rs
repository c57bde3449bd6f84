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
