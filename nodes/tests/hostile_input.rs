//! Hostile input (issue 19, part A): every bad file or value a reader or stage is given ends in a
//! `BadInput` or `Param` error (exit 2) naming the file, the place and what was expected, in
//! bounded time and memory: no panic, no abort on a huge allocation, no stack overflow.

mod common;
mod hostile;
use common::*;
use hostile::*;

use std::path::{Path, PathBuf};

use kodama_nodes::artifact::{Grid, PodVec, PointSet, Raster, Scene};
use kodama_nodes::io::sionna_xml::{read_scene, write_ply};
use kodama_nodes::{Artifact, Ctx, Inputs, Stage, StageError};
use serde_json::{Value, json};

/// Runs stage `S` with params given as JSON, on `files`, and returns its error (it must fail as
/// the user's fault).
fn fails<S: Stage>(params: Value, inputs: &Inputs, files: &[PathBuf]) -> String {
    let p: S::Params = serde_json::from_value(params).expect("params parse");
    if let Err(e) = S::validate(&p) {
        return format!("param `{}`: {}", e.field, e.message);
    }
    let site = site();
    match S::run(&p, inputs, &Ctx::new(&site, files)) {
        Ok(_) => panic!("{} accepted hostile input", S::KIND),
        Err(e) => {
            assert!(e.is_user_error(), "not a user error: {e}");
            e.to_string()
        }
    }
}

fn expect_all(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "{msg:?} lacks {p:?}");
    }
}

// ------------------------------------------------------------------------------------------------
// Non-finite numbers

#[test]
fn a_nan_vertex_in_a_ply_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let (mut p, t) = tetra();
    p[3][0] = f32::NAN;
    write(dir.path(), "meshes/buildings.ply", write_ply(&p, &t));
    let xml = write(dir.path(), "scene.xml", SCENE_XML);
    let e = read_scene(&xml).unwrap_err().to_string();
    expect_all(&e, &["buildings.ply", "vertex 3", "finite x", "NaN"]);
    // Infinity and a coordinate past any site, too.
    for v in [f32::INFINITY, 1e30] {
        p[3][0] = 0.0;
        p[1][2] = v;
        write(dir.path(), "meshes/buildings.ply", write_ply(&p, &t));
        let e = read_scene(&xml).unwrap_err().to_string();
        expect_all(&e, &["buildings.ply", "vertex 1", "finite z"]);
    }
}

fn tileset_fails(glb: Vec<u8>) -> String {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "tiles/a.glb", glb);
    write(dir.path(), "tiles/tileset.json", TILESET);
    fails::<kodama_nodes::stages::ingest::read_tiles::ReadTileset>(
        json!({"path": "tiles/tileset.json", "crs": "EPSG:32618"}),
        &Inputs::new(),
        &[dir.path().join("tiles")],
    )
}

#[test]
fn a_nan_vertex_in_3d_tiles_is_named() {
    for x in [f32::NAN, f32::NEG_INFINITY] {
        let e = tileset_fails(glb_with_x(x));
        expect_all(&e, &["a.glb", "vertex 2", "finite"]);
    }
}

#[test]
fn a_glb_accessor_past_its_buffer_is_refused() {
    // Cut the BIN chunk short: the accessors now point past the buffer the glb holds.
    let mut glb = glb_with_x(1.0);
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let bin_at = 20 + json_len;
    let bin_len = u32::from_le_bytes(glb[bin_at..bin_at + 4].try_into().unwrap());
    let cut = 24u32;
    glb[bin_at..bin_at + 4].copy_from_slice(&(bin_len - cut).to_le_bytes());
    glb.truncate(glb.len() - cut as usize);
    let total = glb.len() as u32;
    glb[8..12].copy_from_slice(&total.to_le_bytes());
    let e = tileset_fails(glb);
    assert!(e.contains("a.glb"), "{e}");
}

fn read_las_fails(path: &Path) -> String {
    fails::<kodama_nodes::stages::ingest::read_las::ReadLas>(
        json!({"path": "x.las", "crs": "EPSG:32618"}),
        &Inputs::new(),
        &[path.to_path_buf()],
    )
}

#[test]
fn a_las_scale_of_zero_or_a_non_finite_offset_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // x scale factor at byte 131, x offset at 155 (LAS 1.2 header).
    for (at, v, what) in [
        (131, 0.0, "x scale factor"),
        (139, f64::NAN, "y scale factor"),
        (171, f64::INFINITY, "z offset"),
        // Finite, but every point at 1e308 m.
        (
            171,
            1e308,
            "z scale and offset giving coordinates within 1e10",
        ),
    ] {
        let path = las_file(dir.path(), "a.las", 10, false);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
        std::fs::write(&path, bytes).unwrap();
        let e = read_las_fails(&path);
        expect_all(&e, &["a.las", "header", what]);
    }
}

#[test]
fn a_truncated_las_names_the_point_where_the_data_stops() {
    let dir = tempfile::tempdir().unwrap();
    let path = las_file(dir.path(), "t.las", 10, false);
    let bytes = std::fs::read(&path).unwrap();
    // Format 0 records are 20 bytes: keep 7 whole points and half of the 8th.
    std::fs::write(&path, &bytes[..bytes.len() - 2 * 20 - 10]).unwrap();
    let e = read_las_fails(&path);
    expect_all(&e, &["t.las", "point 8", "10 points", "after point 7"]);
}

#[test]
fn a_truncated_laz_names_a_point() {
    let dir = tempfile::tempdir().unwrap();
    let path = las_file(dir.path(), "t.laz", 5000, true);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let e = read_las_fails(&path);
    expect_all(
        &e,
        &["t.laz", "5000 points", "compressed data stops after point"],
    );
}

/// Found by a 10-minute fuzz run: a LAZ header announcing no points, whose chunk table claims
/// 3.85 billion chunks. The las crate reads that table when it opens the file and sized a 61 GB
/// list by it (an abort); the table is checked first, whatever the point count.
#[test]
fn a_laz_chunk_table_is_checked_even_with_no_points_announced() {
    let dir = tempfile::tempdir().unwrap();
    let path = las_file(dir.path(), "z.laz", 200, true);
    let mut b = std::fs::read(&path).unwrap();
    let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    // Legacy point count (LAS 1.0-1.4), and the 64-bit one of LAS 1.4 headers.
    b[107..111].copy_from_slice(&0u32.to_le_bytes());
    if u16::from_le_bytes([b[94], b[95]]) >= 375 {
        b[247..255].copy_from_slice(&0u64.to_le_bytes());
    }
    let data = u32_at(&b, 96) as usize;
    let table = u64::from_le_bytes(b[data..data + 8].try_into().unwrap()) as usize;
    b[table + 4..table + 8].copy_from_slice(&3_850_000_000u32.to_le_bytes());
    std::fs::write(&path, &b).unwrap();
    let e = read_las_fails(&path);
    expect_all(&e, &["z.laz", "LAZ chunk table", "3850000000 chunks"]);
}

fn read_raster_fails(dir: &Path, bytes: Vec<u8>) -> String {
    let path = write(dir, "dsm.tif", bytes);
    fails::<kodama_nodes::stages::ingest::read_raster::ReadRaster>(
        json!({"path": "dsm.tif", "crs": "EPSG:32618"}),
        &Inputs::new(),
        &[path],
    )
}

#[test]
fn non_finite_geotiff_georeferencing_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let tie = [0.0, 0.0, 0.0, 583200.0, 4506600.0, 0.0];
    // The good file reads.
    let p = write(dir.path(), "ok.tif", tiff(4, 3, [1.0, 1.0, 0.0], tie));
    let ok: Raster = kodama_nodes::stages::ingest::read_raster::ReadRaster::run(
        &serde_json::from_value(json!({"path": "ok.tif", "crs": "EPSG:32618"})).unwrap(),
        &Inputs::new(),
        &Ctx::new(&site(), &[p]),
    )
    .unwrap();
    assert_eq!((ok.grid.width, ok.grid.height), (4, 3));
    for (scale, tie, what) in [
        ([f64::NAN, 1.0, 0.0], tie, "NaN"),
        ([0.0, 1.0, 0.0], tie, "pixel sizes"),
        (
            [1.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, f64::INFINITY, 4506600.0, 0.0],
            "corner",
        ),
        ([1e308, 1e308, 0.0], tie, "extent"),
    ] {
        let e = read_raster_fails(dir.path(), tiff(4, 3, scale, tie));
        expect_all(&e, &["dsm.tif", "georeferencing", what]);
    }
}

#[test]
fn a_non_finite_world_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let img = image::RgbImage::new(4, 4);
    img.save(dir.path().join("o.png")).unwrap();
    for (text, place) in [
        ("0.5\n0\n0\n-0.5\nNaN\n4506600\n", "value 5"),
        ("inf\n0\n0\n-0.5\n583200\n4506600\n", "value 1"),
    ] {
        let world = write(dir.path(), "o.pgw", text);
        let e = fails::<kodama_nodes::stages::ingest::read_ortho::ReadOrtho>(
            json!({"path": "o.png", "crs": "EPSG:32618"}),
            &Inputs::new(),
            &[dir.path().join("o.png"), world],
        );
        expect_all(&e, &["o.pgw", place, "finite number"]);
    }
}

fn links_fails(csv: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "links.csv", csv);
    fails::<kodama_nodes::stages::ingest::read_measurements::ReadMeasurements>(
        json!({"path": "links.csv"}),
        &Inputs::new(),
        &[path],
    )
}

const HEADER: &str = "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,freq_hz,path_loss_db\n";

#[test]
fn non_finite_or_impossible_links_are_refused() {
    for (row, col) in [
        ("NaN,0,30,100,0,1.5,3.5e9,100", "tx_x"),
        ("0,0,30,inf,0,1.5,3.5e9,100", "rx_x"),
        ("0,0,30,100,0,-inf,3.5e9,100", "rx_z"),
        ("0,0,30,100,0,1.5,0,100", "freq_hz"),
        ("0,0,30,100,0,1.5,-3e9,100", "freq_hz"),
        ("0,0,30,100,0,1.5,3.5e9,NaN", "path_loss_db"),
    ] {
        let e = links_fails(&format!("{HEADER}0,0,30,50,0,1.5,3.5e9,90\n{row}\n"));
        expect_all(&e, &["links.csv", "line 3", col]);
    }
    let e = links_fails(
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,freq_hz,path_loss_db,tx_x\n0,0,30,50,0,1.5,3.5e9,90,1\n",
    );
    expect_all(&e, &["links.csv", "header", "`tx_x` is columns 1 and 9"]);
}

#[test]
fn non_finite_radio_params_are_refused() {
    use kodama_nodes::stages::radio::radio_map::RadioMap;
    use kodama_nodes::stages::radio::trace::Trace;
    let none = Inputs::new();
    for (params, field) in [
        (json!({"tx": [f64::NAN, 0.0, 10.0], "freq_hz": 3.5e9}), "tx"),
        (json!({"tx": [0.0, 0.0, 10.0], "freq_hz": 0.0}), "freq_hz"),
        (
            json!({"tx": [0.0, 0.0, 10.0], "freq_hz": 3.5e9, "options": {"rays": 0}}),
            "rays",
        ),
        (
            json!({"tx": [0.0, 0.0, 10.0], "freq_hz": 3.5e9, "height_m": f64::INFINITY}),
            "height_m",
        ),
    ] {
        // serde_json writes NaN and inf as null: build those params by hand.
        let p = match serde_json::from_value::<<RadioMap as Stage>::Params>(params.clone()) {
            Ok(p) => p,
            Err(_) => {
                let mut p: <RadioMap as Stage>::Params =
                    serde_json::from_value(json!({"tx": [0.0, 0.0, 10.0], "freq_hz": 3.5e9}))
                        .unwrap();
                if field == "tx" {
                    p.tx.0 = f64::NAN;
                } else {
                    p.height_m = f64::INFINITY;
                }
                p
            }
        };
        let e = RadioMap::validate(&p).unwrap_err();
        assert!(
            e.field == field || e.message.contains(field),
            "{field}: {e:?}"
        );
    }
    let mut t: <Trace as Stage>::Params = serde_json::from_value(json!({})).unwrap();
    t.tx_antenna.azimuth_deg = f64::NAN;
    assert_eq!(Trace::validate(&t).unwrap_err().field, "tx_antenna");
    let _ = none;
}

// ------------------------------------------------------------------------------------------------
// Sizes

fn cube_scene(half: f32) -> Scene {
    let mesh = kodama_nodes::geom::mesh_build::cuboid(
        [0.0, 0.0],
        [half as f64 * 2.0, half as f64 * 2.0, 10.0],
        0.0,
        0.0,
        kodama_nodes::artifact::Material::Concrete,
    );
    Scene {
        objects: vec![kodama_nodes::artifact::SceneObject {
            id: "b".into(),
            class: kodama_nodes::artifact::ObjectClass::Building,
            mesh,
        }],
    }
}

#[test]
fn a_radio_map_past_the_cell_budget_says_what_it_would_need() {
    use kodama_nodes::stages::radio::radio_map::RadioMap;
    let inputs = Inputs::new().with("scene", slot(Artifact::Scene(cube_scene(5000.0))));
    let e = fails::<RadioMap>(
        json!({"tx": [0.0, 0.0, 30.0], "freq_hz": 3.5e9, "cell_m": 1e-4, "options": {"rays": 10}}),
        &inputs,
        &[],
    );
    expect_all(&e, &["cell_m", "would need", "GiB", "limit"]);
}

#[test]
fn rasterizing_at_a_tiny_cell_says_what_it_would_need() {
    use kodama_nodes::stages::heights::rasterize_surface::RasterizeSurface;
    let points = PointSet {
        xyz: PodVec(vec![[0.0, 0.0, 1.0], [1000.0, 1000.0, 2.0]]),
        ..Default::default()
    };
    let inputs = Inputs::new().with("points", slot(Artifact::Points(points)));
    let e = fails::<RasterizeSurface>(json!({"mode": "Max", "cell_m": 1e-9}), &inputs, &[]);
    expect_all(&e, &["cell_m", "would need", "limit is 2147483648 cells"]);
}

#[test]
fn a_huge_blur_sigma_finishes_at_once() {
    use kodama_nodes::stages::heights::gaussian_blur::GaussianBlur;
    let grid = Grid {
        x0: 0.0,
        y0: 10.0,
        cell_m: 1.0,
        width: 10,
        height: 10,
    };
    let r = Raster {
        grid,
        data: PodVec((0..100).map(|v| v as f32).collect()),
    };
    let inputs = Inputs::new().with("raster", slot(Artifact::Raster(r)));
    let p = serde_json::from_value(json!({"sigma_m": 1e300})).unwrap();
    let t = std::time::Instant::now();
    let out = GaussianBlur::run(&p, &inputs, &Ctx::new(&site(), &[])).unwrap();
    assert!(t.elapsed().as_secs() < 5);
    // A sigma far wider than the raster is its mean everywhere.
    assert!(
        out.data.iter().all(|v| (v - 49.5).abs() < 1e-3),
        "{:?}",
        &out.data[..3]
    );
}

#[test]
fn a_ply_announcing_more_than_it_holds_is_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let xml = write(dir.path(), "scene.xml", SCENE_XML);
    let (p, t) = tetra();
    let ply = write_ply(&p, &t);
    let text = String::from_utf8_lossy(&ply).into_owned();
    for (from, to, what) in [
        ("element face 4", "element face 1000000000000000", "faces"),
        (
            "element vertex 4",
            "element vertex 9223372036854775807",
            "vertices",
        ),
    ] {
        let head_end = text.find("end_header\n").unwrap() + 11;
        let head = text[..head_end].replace(from, to);
        let mut bytes = head.into_bytes();
        bytes.extend_from_slice(&ply[head_end..]);
        write(dir.path(), "meshes/buildings.ply", bytes);
        let e = read_scene(&xml).unwrap_err().to_string();
        expect_all(&e, &["buildings.ply", what, "bytes"]);
    }
}

#[test]
fn a_geotiff_claiming_billions_of_pixels_is_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    let tie = [0.0, 0.0, 0.0, 583200.0, 4506600.0, 0.0];
    let e = read_raster_fails(dir.path(), tiff(200_000, 200_000, [1.0, 1.0, 0.0], tie));
    expect_all(&e, &["dsm.tif", "dimensions", "would need", "GiB"]);
}

/// A TIFF of a few hundred bytes whose 12 pixels claim 2,228 km each: the site grid covering it
/// holds 107 million cells, within the cell limit but sized by the georeferencing, not the data
/// (found by AFL++: 18 s a read). Refused before any cell is sampled.
#[test]
fn a_geotiff_whose_few_pixels_claim_thousands_of_km_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let tie = [0.0, 0.0, 0.0, 583200.0, 4506600.0, 0.0];
    let e = read_raster_fails(dir.path(), tiff(4, 3, [1.0, 2_228_224.0, 0.0], tie));
    expect_all(&e, &["dsm.tif", "4 x 3 pixels", "per pixel", "pixel size"]);
    // A coarse DEM on a fine grid is no such claim: 90 m pixels onto 0.5 m cells.
    let p = write(dir.path(), "coarse.tif", tiff(4, 3, [90.0, 90.0, 0.0], tie));
    let coarse: Raster = kodama_nodes::stages::ingest::read_raster::ReadRaster::run(
        &serde_json::from_value(json!({"path": "coarse.tif", "crs": "EPSG:32618", "cell_m": 0.5}))
            .unwrap(),
        &Inputs::new(),
        &Ctx::new(&site(), &[p]),
    )
    .unwrap();
    assert_eq!((coarse.grid.width, coarse.grid.height), (721, 542));
}

/// Within the cell limit but far past what the file holds: 46,340 x 46,340 floats (8.6 GB)
/// claimed by a TIFF of a few hundred bytes are refused before the decoder allocates them.
#[test]
fn a_tiff_claiming_more_pixels_than_it_stores_is_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    let tie = [0.0, 0.0, 0.0, 583200.0, 4506600.0, 0.0];
    let e = read_raster_fails(dir.path(), tiff(46_340, 46_340, [1.0, 1.0, 0.0], tie));
    expect_all(
        &e,
        &["dsm.tif", "strip or tile byte counts", "inside the file"],
    );
}

/// A grid sized by the data, not by a param: footprints 60 km apart at 0.5 m cells would make
/// 1.4 x 10^10 cells, refused naming what it would need instead of allocated (or wrapped).
#[test]
fn a_footprint_score_over_a_far_flung_extent_is_refused() {
    use kodama_nodes::artifact::{Footprint, Footprints, Polygon};
    use kodama_nodes::stages::eval::footprint_score::FootprintScore;
    let square = |x: f64, y: f64| Footprint {
        id: format!("{x}"),
        polygons: vec![Polygon {
            exterior: vec![[x, y], [x + 10.0, y], [x + 10.0, y + 10.0], [x, y + 10.0]],
            holes: vec![],
        }],
        height_m: None,
        min_height_m: None,
        levels: None,
        min_level: None,
    };
    let far = Footprints {
        items: vec![square(0.0, 0.0), square(60_000.0, 60_000.0)],
    };
    let inputs = Inputs::new()
        .with("predicted", slot(Artifact::Footprints(far.clone())))
        .with("reference", slot(Artifact::Footprints(far)))
        .with("region", kodama_nodes::stage::Slot::Optional(None))
        .with("returns", kodama_nodes::stage::Slot::Optional(None));
    let e = fails::<FootprintScore>(json!({"cell_m": 0.5}), &inputs, &[]);
    expect_all(&e, &["cell_m", "would need", "region"]);
}

/// Params within their own ranges whose product is not: 100,000 views of 8192 x 8192 pixels.
#[test]
fn a_synthetic_view_set_is_bounded_as_a_whole() {
    use kodama_nodes::synth::synth_views::{SynthViews, SynthViewsParams};
    let mut p = SynthViewsParams {
        max_views: 100_000,
        size: (8192, 8192),
        ..Default::default()
    };
    let e = SynthViews::validate(&p).unwrap_err();
    assert_eq!(e.field, "max_views");
    assert!(
        e.message.contains("lower max_views or size"),
        "{}",
        e.message
    );
    p.size = (640, 480);
    assert!(SynthViews::validate(&p).is_ok());
}

#[test]
fn a_synthetic_city_past_its_size_limit_is_refused() {
    use kodama_nodes::synth::synth_city::SynthCity;
    let mut p = small_city();
    p.size_m = (f64::INFINITY, 300.0);
    assert_eq!(SynthCity::validate(&p).unwrap_err().field, "size_m");
    p.size_m = (1e6, 1e6);
    assert!(
        SynthCity::validate(&p)
            .unwrap_err()
            .message
            .contains("at most")
    );
}

// ------------------------------------------------------------------------------------------------
// Nesting

#[test]
fn a_100000_deep_xml_scene_is_an_error_not_a_stack_overflow() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100_000;
    let xml = format!(
        "<scene version=\"2.1.0\">{}{}</scene>",
        "<a>".repeat(n),
        "</a>".repeat(n)
    );
    let path = write(dir.path(), "scene.xml", xml);
    let e = read_scene(&path).unwrap_err().to_string();
    expect_all(&e, &["scene.xml", "line 1, column", "nested at most"]);
}

#[test]
fn a_100000_deep_json_is_an_error_not_a_stack_overflow() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100_000;
    let deep = format!("{}{}", "[".repeat(n), "]".repeat(n));
    write(dir.path(), "v/views.json", &deep);
    let e = fails::<kodama_nodes::stages::ingest::read_views::ReadViews>(
        json!({"path": "v/views.json"}),
        &Inputs::new(),
        &[dir.path().join("v")],
    );
    expect_all(&e, &["views.json", "line 1, column", "recursion limit"]);
    write(
        dir.path(),
        "tiles/tileset.json",
        format!("{{\"root\": {deep}}}"),
    );
    let e = fails::<kodama_nodes::stages::ingest::read_tiles::ReadTileset>(
        json!({"path": "tiles/tileset.json"}),
        &Inputs::new(),
        &[dir.path().join("tiles")],
    );
    expect_all(&e, &["tileset.json", "line 1, column", "recursion limit"]);
}

// ------------------------------------------------------------------------------------------------
// Garbage accepted before

#[test]
fn a_text_file_with_no_numbers_is_not_an_empty_point_set() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "p.xyz",
        "This is not a point file.\nIt has words on every line.\n",
    );
    let e = fails::<kodama_nodes::stages::ingest::read_xyz::ReadXyz>(
        json!({"path": "p.xyz"}),
        &Inputs::new(),
        &[path],
    );
    expect_all(&e, &["p.xyz", "line 2", "expected 3 or 4 fields"]);
    let path = write(dir.path(), "e.xyz", "x y z\n# nothing\n");
    let e = fails::<kodama_nodes::stages::ingest::read_xyz::ReadXyz>(
        json!({"path": "e.xyz"}),
        &Inputs::new(),
        &[path],
    );
    expect_all(&e, &["e.xyz", "at least one point"]);
}

/// Reads a views.json of one 8 x 4 view with the given intrinsics and orientation, its image and
/// (when given) a material map of one class index beside it.
fn read_views(
    intrinsics: Value,
    orientation: Value,
    material: Option<u8>,
) -> Result<kodama_nodes::artifact::ViewSet, StageError> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("v/material")).unwrap();
    image::RgbImage::new(8, 4)
        .save(dir.path().join("v/img.png"))
        .unwrap();
    if let Some(m) = material {
        image::GrayImage::from_pixel(8, 4, image::Luma([m]))
            .save(dir.path().join("v/material/a.png"))
            .unwrap();
    }
    let doc = json!({
        "material_classes": ["glass", "brick"],
        "views": [{"id": "a", "image": "img.png", "width": 8, "height": 4,
                   "intrinsics": intrinsics, "pose": {"x": 0, "y": 0, "z": 2},
                   "orientation": orientation}]
    });
    write(dir.path(), "v/views.json", doc.to_string());
    let p = serde_json::from_value(json!({"path": "v/views.json"})).unwrap();
    let files = [dir.path().join("v")];
    kodama_nodes::stages::ingest::read_views::ReadViews::run(
        &p,
        &Inputs::new(),
        &Ctx::new(&site(), &files),
    )
}

fn views_fail(intrinsics: Value, orientation: Value, material: Option<u8>) -> String {
    let e = read_views(intrinsics, orientation, material).expect_err("hostile views accepted");
    assert!(e.is_user_error(), "{e}");
    e.to_string()
}

/// A depth map whose header gives another size than its view's is refused by its header, before
/// a pixel of it is decoded.
#[test]
fn a_depth_map_of_another_size_than_its_view_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("v")).unwrap();
    image::RgbImage::new(8, 4)
        .save(dir.path().join("v/img.png"))
        .unwrap();
    let exr = kodama_nodes::io::exr_io::write_exr(16, 4, vec![("Z", vec![1.0; 64])]).unwrap();
    write(dir.path(), "v/depth/a.exr", exr);
    let doc = json!({
        "views": [{"id": "a", "image": "img.png", "width": 8, "height": 4,
                   "intrinsics": {"fx": 4, "fy": 4, "cx": 4, "cy": 2},
                   "pose": {"x": 0, "y": 0, "z": 2}, "orientation": {"heading_deg": 0}}]
    });
    write(dir.path(), "v/views.json", doc.to_string());
    let e = fails::<kodama_nodes::stages::ingest::read_views::ReadViews>(
        json!({"path": "v/views.json"}),
        &Inputs::new(),
        &[dir.path().join("v")],
    );
    expect_all(&e, &["a.exr", "16 x 4 pixels, but views.json says 8 x 4"]);
}

#[test]
fn views_with_no_focal_length_no_rotation_or_unknown_materials_are_refused() {
    let k = json!({"fx": 4, "fy": 4, "cx": 4, "cy": 2});
    let level = json!({"heading_deg": 0});
    let e = views_fail(
        json!({"fx": 0, "fy": 4, "cx": 4, "cy": 2}),
        level.clone(),
        None,
    );
    expect_all(&e, &["views.json", "view 0 (\"a\"), intrinsics", "fx = 0"]);
    let e = views_fail(k.clone(), json!({"quat_wxyz": [0, 0, 0, 0]}), None);
    expect_all(
        &e,
        &["views.json", "view 0 (\"a\"), orientation", "rotation"],
    );
    let e = views_fail(k.clone(), level.clone(), Some(7));
    expect_all(&e, &["a.png", "pixel (0, 0)", "below 2", "found 7"]);
    // 255 is "none", not an index.
    read_views(k, level, Some(255)).unwrap();
}

// ------------------------------------------------------------------------------------------------
// Paths in data files: a file a data file names is read only from inside the folder the node
// declared (the one the cache digests)

#[test]
fn a_scene_xml_naming_a_ply_outside_its_folder_is_refused_before_reading_it() {
    let dir = tempfile::tempdir().unwrap();
    let (p, t) = tetra();
    // A readable PLY sits outside the scene's folder: it must not be read.
    write(dir.path(), "outside.ply", write_ply(&p, &t));
    for (path, why) in [
        ("../outside.ply", "leads outside"),
        ("meshes/../../outside.ply", "leads outside"),
        ("/etc/passwd", "absolute path"),
    ] {
        let xml = SCENE_XML.replace("meshes/buildings.ply", path);
        let xml = write(dir.path(), "scene/scene.xml", xml);
        let e = read_scene(&xml).unwrap_err();
        assert!(e.is_user_error(), "{e}");
        expect_all(
            &e.to_string(),
            &["scene.xml", "shape \"mesh-b\", filename", why],
        );
    }
}

/// One file named by many shapes counts each time: 17 shapes naming one 1 GiB file come to
/// more than a node may read, refused before a byte of mesh is read (the file is sparse, and
/// not even a PLY).
#[test]
fn a_file_named_by_many_shapes_counts_each_time() {
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("scene/meshes/big.ply");
    std::fs::create_dir_all(big.parent().unwrap()).unwrap();
    std::fs::File::create(&big)
        .unwrap()
        .set_len(1 << 30)
        .unwrap();
    let shapes: String = (0..17)
        .map(|i| {
            format!(
                "<shape type=\"ply\" id=\"mesh-{i}\"><string name=\"filename\" \
                 value=\"meshes/big.ply\"/><ref id=\"itu_concrete\" name=\"bsdf\"/></shape>\n"
            )
        })
        .collect();
    let xml = format!(
        "<scene version=\"2.1.0\">\n<bsdf type=\"itu-radio-material\" id=\"itu_concrete\">\
         <string name=\"type\" value=\"concrete\"/></bsdf>\n{shapes}</scene>\n"
    );
    let xml = write(dir.path(), "scene/scene.xml", xml);
    let e = read_scene(&xml).unwrap_err();
    assert!(e.is_user_error(), "{e}");
    expect_all(
        &e.to_string(),
        &[
            "scene.xml",
            "shape \"mesh-16\", filename",
            "past the limit of 16.0 GiB",
            "counts each time",
        ],
    );
}

/// The glb of [`glb_with_x`] with its JSON chunk edited by `edit`, the container rebuilt.
fn glb_with_json(edit: impl Fn(&mut Value)) -> Vec<u8> {
    let glb = glb_with_x(1.0);
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let mut doc: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    edit(&mut doc);
    let mut text = serde_json::to_vec(&doc).unwrap();
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let bin = &glb[20 + json_len..];
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend(((12 + 8 + text.len() + bin.len()) as u32).to_le_bytes());
    out.extend((text.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&text);
    out.extend(bin);
    out
}

/// glTF nodes form a forest: a node that is its own child, or a child of two nodes (a mesh
/// reached by 2^40 paths takes 40 such nodes), is named instead of walked forever.
#[test]
fn gltf_nodes_that_are_no_tree_are_refused() {
    let own_child = glb_with_json(|d| d["nodes"][0]["children"] = json!([0]));
    let e = tileset_fails(own_child);
    expect_all(&e, &["a.glb", "node 0", "form a tree"]);
    let shared = glb_with_json(|d| {
        let mesh = d["nodes"][0].clone();
        d["nodes"] = json!([{"children": [2]}, {"children": [2]}, mesh]);
        d["scenes"][0]["nodes"] = json!([0, 1]);
    });
    let e = tileset_fails(shared);
    expect_all(&e, &["a.glb", "node 2", "form a tree"]);
}

/// External tilesets that fan out (a thousand children, each a tileset of a thousand...) stop
/// at a bound on the tiles in all: depth alone bounds nothing here.
#[test]
fn a_tileset_fanning_out_is_bounded_in_width() {
    let dir = tempfile::tempdir().unwrap();
    let tile = |content: &str| {
        json!({"geometricError": 0, "boundingVolume": {"box": [0,0,0,1,0,0,0,1,0,0,0,1]},
               "content": {"uri": content}})
    };
    let fan = |children: Vec<Value>| {
        json!({"asset": {"version": "1.0"}, "geometricError": 0,
               "root": {"geometricError": 0, "refine": "ADD",
                        "boundingVolume": {"box": [0,0,0,1,0,0,0,1,0,0,0,1]},
                        "children": children}})
    };
    // 2,000 external tilesets of 2,000 empty tiles each: 4 million tiles, no cycle, depth 1.
    let empty = json!({"geometricError": 0, "boundingVolume": {"box": [0,0,0,1,0,0,0,1,0,0,0,1]}});
    let leaves = fan((0..2000).map(|_| empty.clone()).collect());
    let root = fan((0..2000).map(|_| tile("fan.json")).collect());
    write(
        dir.path(),
        "tiles/fan.json",
        serde_json::to_vec(&leaves).unwrap(),
    );
    write(
        dir.path(),
        "tiles/tileset.json",
        serde_json::to_vec(&root).unwrap(),
    );
    let e = fails::<kodama_nodes::stages::ingest::read_tiles::ReadTileset>(
        json!({"path": "tiles/tileset.json", "crs": "EPSG:32618"}),
        &Inputs::new(),
        &[dir.path().join("tiles")],
    );
    expect_all(&e, &["fan.json", "at most 1048576 tiles"]);
}

#[test]
fn a_view_image_outside_the_view_folder_or_an_id_that_is_a_path_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    image::RgbImage::new(8, 4)
        .save(dir.path().join("secret.png"))
        .unwrap();
    std::fs::create_dir_all(dir.path().join("v")).unwrap();
    let view = |id: &str, image: &str| {
        json!({"views": [{"id": id, "image": image, "width": 8, "height": 4,
                          "intrinsics": {"fx": 4, "fy": 4, "cx": 4, "cy": 2},
                          "pose": {"x": 0, "y": 0, "z": 2},
                          "orientation": {"heading_deg": 0}}]})
        .to_string()
    };
    let read = |doc: String| {
        write(dir.path(), "v/views.json", doc);
        let p = serde_json::from_value(json!({"path": "v/views.json"})).unwrap();
        let files = [dir.path().join("v")];
        kodama_nodes::stages::ingest::read_views::ReadViews::run(
            &p,
            &Inputs::new(),
            &Ctx::new(&site(), &files),
        )
        .expect_err("hostile views accepted")
    };
    for (image, why) in [
        ("../secret.png", "leads outside"),
        ("/tmp/x.png", "absolute path"),
    ] {
        let e = read(view("a", image));
        assert!(e.is_user_error(), "{e}");
        expect_all(&e.to_string(), &["views.json", "image", why]);
    }
    let e = read(view("../../x", "img.png"));
    expect_all(
        &e.to_string(),
        &["views.json", "view 0, id", "path separator"],
    );
}

#[test]
fn a_tileset_uri_outside_its_folder_or_remote_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "a.glb", glb_with_x(1.0));
    for (uri, why) in [
        ("../a.glb", "leads outside"),
        ("https://example.com/a.glb", "download remote content first"),
    ] {
        write(
            dir.path(),
            "tiles/tileset.json",
            TILESET.replace("a.glb", uri),
        );
        let e = fails::<kodama_nodes::stages::ingest::read_tiles::ReadTileset>(
            json!({"path": "tiles/tileset.json", "crs": "EPSG:32618"}),
            &Inputs::new(),
            &[dir.path().join("tiles")],
        );
        expect_all(&e, &["tileset.json", "root.content.uri", why]);
    }
}

// ------------------------------------------------------------------------------------------------
// OSM XML (issue 49): broken markup, wrong values, oversized markup and deep nesting end in an
// error naming the file, the line and byte, and what was expected.

fn read_osm_fails(dir: &Path, xml: &str) -> String {
    let path = write(dir, "b.osm", xml);
    fails::<kodama_nodes::stages::ingest::read_osm::ReadOsmBuildings>(
        json!({"path": "b.osm"}),
        &Inputs::new(),
        &[path],
    )
}

#[test]
fn osm_xml_seed_reads() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "b.osm", OSM_XML);
    let f = kodama_nodes::stages::ingest::read_osm::ReadOsmBuildings::run(
        &serde_json::from_value(json!({"path": "b.osm"})).unwrap(),
        &Inputs::new(),
        &Ctx::new(&site(), &[path]),
    )
    .unwrap();
    let ids: Vec<&str> = f.items.iter().map(|b| b.id.as_str()).collect();
    assert_eq!(ids, ["w13", "r20"]);
    assert_eq!(f.items[0].height_m, Some(12.0));
    assert_eq!(f.items[1].levels, Some(4.0));
    assert_eq!(f.items[1].polygons.len(), 1);
    assert_eq!(f.items[1].polygons[0].holes.len(), 1);
}

/// A height of 1e300 or `inf` levels is no building's: the tag is left out and named, the
/// building and every other one kept (where one such building once emptied the scene).
#[test]
fn implausible_osm_building_tags_are_left_out_and_named() {
    let dir = tempfile::tempdir().unwrap();
    let xml = OSM_XML.replace(r#"v="12 m""#, r#"v="1e300""#).replace(
        r#"<tag k="building:levels" v="4"/>"#,
        r#"<tag k="building:levels" v="inf"/>"#,
    );
    let path = write(dir.path(), "b.osm", xml);
    let warnings = Warnings::default();
    let files = [path];
    let site = site();
    let ctx = ctx_warning_into(&site, &files, &warnings);
    let f = kodama_nodes::stages::ingest::read_osm::ReadOsmBuildings::run(
        &serde_json::from_value(json!({"path": "b.osm"})).unwrap(),
        &Inputs::new(),
        &ctx,
    )
    .unwrap();
    let ids: Vec<&str> = f.items.iter().map(|b| b.id.as_str()).collect();
    assert_eq!(ids, ["w13", "r20"]);
    assert_eq!(f.items[0].height_m, None);
    assert_eq!(f.items[1].levels, None);
    let w = warnings.0.lock().unwrap().join("\n");
    expect_all(
        &w,
        &[
            "b.osm",
            "2 building tags left out",
            "way 13: height=1e300",
            "relation 20: building:levels=inf",
        ],
    );
}

#[test]
fn broken_osm_xml_is_named_by_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Cut in the middle of a way: the open elements are never closed.
    let cut = &OSM_XML[..OSM_XML
        .find("<nd ref=\"6\"/><nd ref=\"7\"/><nd ref=\"5\"/>\n")
        .unwrap()];
    let e = read_osm_fails(d, cut);
    expect_all(
        &e,
        &[
            "b.osm",
            "line 18",
            "well-formed OSM XML",
            "2 elements still open",
        ],
    );
    // A mismatched end tag, on line 13.
    let e = read_osm_fails(d, &OSM_XML.replacen("</node>", "</way>", 1));
    expect_all(&e, &["b.osm", "line 13", "well-formed OSM XML"]);
    // Not OSM at all.
    let e = read_osm_fails(d, "<?xml version=\"1.0\"?>\n<gpx><trk/></gpx>\n");
    expect_all(
        &e,
        &["b.osm", "line 2", "an <osm> root element, found <gpx>"],
    );
    let e = read_osm_fails(d, "<?xml version=\"1.0\"?>\n");
    expect_all(&e, &["b.osm", "an <osm> root element, found none"]);
    let e = read_osm_fails(d, &format!("{OSM_XML}<osm/>"));
    expect_all(&e, &["b.osm", "one <osm> root element"]);
}

#[test]
fn wrong_osm_xml_values_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (from, to, parts) in [
        (
            r#"lat="40.7003000" lon="-73.9993000""#,
            r#"lat="north" lon="-73.9993000""#,
            &[
                "line 10",
                "a lat in degrees within ±90 on node 6",
                "\"north\"",
            ][..],
        ),
        (
            r#"lon="-73.9990000"/>"#,
            r#"lon="-273.9990000"/>"#,
            &["line 6", "a lon in degrees within ±180 on node 2"][..],
        ),
        (
            r#"<way id="12">"#,
            r#"<way id="twelve">"#,
            &[
                "line 16",
                "<way> with a whole-number id attribute",
                "\"twelve\"",
            ][..],
        ),
        (
            r#"<nd ref="7"/><nd ref="5"/></way>"#,
            r#"<nd/><nd ref="5"/></way>"#,
            &[
                "line 16",
                "<nd> with a whole-number ref attribute, found none",
            ][..],
        ),
        (
            r#"<member type="way" ref="12""#,
            r#"<member type="area" ref="12""#,
            &["line 25", "<member> of type node, way or relation"][..],
        ),
        (
            r#"<tag k="height" v="12 m"/>"#,
            r#"<tag k="height"/>"#,
            &["line 20", "<tag> with a v attribute"][..],
        ),
        (
            r#"v="Caf&#233; &amp; bar""#,
            r#"v="Caf&eacute;""#,
            &["line 12", "a valid attribute value"][..],
        ),
    ] {
        assert!(OSM_XML.contains(from), "{from}");
        let e = read_osm_fails(d, &OSM_XML.replacen(from, to, 1));
        expect_all(&e, &["b.osm"]);
        expect_all(&e, parts);
    }
}

#[test]
fn oversized_or_deep_osm_xml_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // One tag value of 2 MiB: refused before quick-xml buffers more than about the limit.
    let huge = OSM_XML.replacen("12 m", &"1".repeat(2 << 20), 1);
    let e = read_osm_fails(d, &huge);
    expect_all(&e, &["b.osm", "line 20", "markup of at most 1048576 bytes"]);
    // Elements nested 1000 deep inside a node.
    let deep = OSM_XML.replacen(
        "<tag k=\"name\"",
        &format!(
            "{}{}<tag k=\"name\"",
            "<a>".repeat(1000),
            "</a>".repeat(1000)
        ),
        1,
    );
    let e = read_osm_fails(d, &deep);
    expect_all(&e, &["b.osm", "line 12", "nested at most 32 deep"]);
}

// ------------------------------------------------------------------------------------------------
// SRTM .hgt (issue 49): the size and the name are all a tile has to go by.

fn read_hgt_fails(dir: &Path, name: &str, len: usize) -> String {
    let path = write(dir, name, vec![0u8; len]);
    fails::<kodama_nodes::stages::ingest::read_raster::ReadRaster>(
        json!({"path": name, "cell_m": 90.0}),
        &Inputs::new(),
        &[path],
    )
}

#[test]
fn hgt_of_the_wrong_size_or_name_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let three = 2 * 1201 * 1201;
    for len in [0, 1, three - 2, three + 1, 2 * 3601 * 3600] {
        let e = read_hgt_fails(d, "N40W075.hgt", len);
        expect_all(
            &e,
            &[
                "N40W075.hgt: size",
                "3601 x 3601",
                "1201 x 1201",
                &format!("found {len} bytes"),
            ],
        );
    }
    for name in [
        "dem.hgt",
        "N4W075.hgt",
        "X40W075.hgt",
        "N40W75.hgt",
        "40N075W.hgt",
    ] {
        let e = read_hgt_fails(d, name, three);
        expect_all(
            &e,
            &[name, "file name", "like N40W074.hgt", "south-west corner"],
        );
    }
    let e = read_hgt_fails(d, "N95W075.hgt", three);
    expect_all(
        &e,
        &[
            "N95W075.hgt: file name",
            "within 90 S..89 N",
            "found 95, -75",
        ],
    );
    let e = read_hgt_fails(d, "S10E190.hgt", three);
    expect_all(
        &e,
        &["S10E190.hgt: file name", "180 W..179 E", "found -10, 190"],
    );
    // A tile of the right size and name reads (all zeros: sea level).
    let path = write(d, "N40W075.hgt", vec![0u8; three]);
    let r: Raster = kodama_nodes::stages::ingest::read_raster::ReadRaster::run(
        &serde_json::from_value(json!({"path": "N40W075.hgt", "cell_m": 900.0})).unwrap(),
        &Inputs::new(),
        &Ctx::new(&site(), &[path]),
    )
    .unwrap();
    assert!(r.data.contains(&0.0));
}

// ------------------------------------------------------------------------------------------------
// Errors at the right place

#[test]
fn a_truncated_xml_names_the_line_and_column_where_it_ends() {
    let dir = tempfile::tempdir().unwrap();
    let cut = &SCENE_XML[..SCENE_XML.find("<shape").unwrap() + 20];
    let path = write(dir.path(), "scene.xml", cut);
    let e = read_scene(&path).unwrap_err().to_string();
    expect_all(&e, &["scene.xml", "line 3, column", "well-formed XML"]);
}

#[test]
fn stage_errors_are_user_errors() {
    let e = StageError::bad_input(Path::new("f"), "p", "x");
    assert!(e.is_user_error());
}
