//! Ingest through the CLI on the real files in ../shared/data (read in place via --data), and the
//! input errors a user meets: each exits 2 naming the file and the problem.

mod common;
use common::*;

const DELFT: &str = r#"
Graph(
    site: Site(crs: "EPSG:28992", origin: (84800.0, 447400.0), cell_m: 0.5),
    nodes: {
        "lidar": ReadLas(path: "delft/ahn3_tile1.laz", crs: "EPSG:28992"),
        "stats": PointStats(points: "lidar"),
        "dsm":   RasterizeSurface(points: "lidar", mode: Max),
    },
    outputs: { "stats": "stats", "dsm": "dsm" },
)
"#;

#[test]
fn delft_through_the_cli_with_data_dir() {
    let env = Env::new();
    let g = env.write("delft.ron", DELFT);
    let data = shared_data();
    let r = env.run(&g, &["--data", data.to_str().unwrap()]).ok();
    assert_eq!(r.status("lidar"), "ran");
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(env.out().join("stats.json")).unwrap()).unwrap();
    assert_eq!(stats["count"], 640_510.0);
    assert_eq!(stats["class_6"], 246_753.0);
    // 192 x 229 m at 0.5 m: the DSM covers the tile.
    let tif = std::fs::read(env.out().join("dsm.tif")).unwrap();
    assert_eq!(&tif[..4], b"II*\0");
    // The input file is digested behind the stat cache: a rerun reads nothing and runs nothing.
    let again = env.run(&g, &["--data", data.to_str().unwrap()]).ok();
    assert_eq!(again.with_status("cached").len(), 3);
}

#[test]
fn truncated_las_names_the_file_and_where_it_ends() {
    let env = Env::new();
    let las = std::fs::read(shared_data().join("autzen/autzen_trim.las")).unwrap();
    std::fs::write(env.path("cut.las"), &las[..las.len() / 2]).unwrap();
    let g = env.write(
        "g.ron",
        "Graph(\n  site: Site(crs: \"EPSG:32610\", origin: (494000.0, 4877000.0), cell_m: 1.0),\n  nodes: { \"p\": ReadLas(path: \"cut.las\") },\n)\n",
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("cut.las: point "), "{}", r.stderr);
    assert_eq!(r.status("p"), "failed");
}

#[test]
fn unknown_epsg_code_is_rejected_before_running() {
    let env = Env::new();
    let g = env.write(
        "g.ron",
        "Graph(\n  site: Site(crs: \"EPSG:28992\", origin: (0.0, 0.0), cell_m: 1.0),\n  nodes: { \"p\": ReadLas(path: \"g.ron\", crs: \"EPSG:1\") },\n)\n",
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr
            .contains("g.ron:3:45: node \"p\": invalid `crs`: unknown EPSG code 1"),
        "{}",
        r.stderr
    );
    let g = env.write("s.ron", "Graph(\n  site: Site(crs: \"EPSG:2994\", origin: (0.0, 0.0), cell_m: 1.0),\n  nodes: {},\n)\n");
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr
            .contains("s.ron:2:19: invalid `crs`: EPSG:2994 is in units of 0.3048 m"),
        "{}",
        r.stderr
    );
}

#[test]
fn csv_with_a_missing_column_exits_2() {
    let env = Env::new();
    env.write(
        "m.csv",
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,path_loss_db\n0,0,10,5,5,1.5,80\n",
    );
    let g = env.write(
        "g.ron",
        "Graph(\n  site: Site(crs: \"EPSG:32618\", origin: (0.0, 0.0), cell_m: 1.0),\n  nodes: { \"m\": ReadMeasurements(path: \"m.csv\") },\n  outputs: { \"m\": \"m\" },\n)\n",
    );
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("m.csv: header: expected a column `freq_hz`"),
        "{}",
        r.stderr
    );
    assert!(
        !env.out().join("m.csv").exists(),
        "nothing written for a failed node"
    );
}

#[test]
fn geotiff_without_georeferencing_exits_2() {
    let env = Env::new();
    // A plain TIFF: the fixture's pixels re-encoded without any GeoTIFF tags.
    let mut buf = std::io::Cursor::new(Vec::new());
    tiff::encoder::TiffEncoder::new(&mut buf)
        .unwrap()
        .write_image::<tiff::encoder::colortype::Gray32Float>(3, 2, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
        .unwrap();
    std::fs::write(env.path("plain.tif"), buf.into_inner()).unwrap();
    let g = env.write("g.ron", "Graph(\n  site: Site(crs: \"EPSG:32618\", origin: (0.0, 0.0), cell_m: 1.0),\n  nodes: { \"dem\": ReadRaster(path: \"plain.tif\") },\n)\n");
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("plain.tif: georeferencing: no ModelTiepoint + ModelPixelScale"),
        "{}",
        r.stderr
    );
}

#[test]
fn views_file_pointing_at_a_missing_image_exits_2() {
    let env = Env::new();
    env.write(
        "views/views.json",
        r#"{"material_classes": [], "views": [{"id": "0001", "image": "img/0001.jpg", "width": 640, "height": 480,
            "intrinsics": {"hfov_deg": 90}, "pose": {"lat": 40.70, "lon": -74.01, "alt_m": 12.0},
            "orientation": {"heading_deg": 30, "pitch_deg": 5, "roll_deg": 0}}]}"#,
    );
    let g = env.write("g.ron", "Graph(\n  site: Site(crs: \"EPSG:32618\", origin: (583000.0, 4506000.0), cell_m: 1.0),\n  nodes: { \"v\": ReadViews(path: \"views/views.json\") },\n)\n");
    let r = env.run(&g, &[]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("views.json: view \"0001\", image: the image")
            && r.stderr.contains("img/0001.jpg does not exist"),
        "{}",
        r.stderr
    );
}

/// ReadLas on a folder of tiles: the folder is the node's input, so adding a tile reruns it and
/// the cloud grows by the tile (issue 49).
#[test]
fn las_folder_is_one_input_and_a_new_tile_reruns_the_node() {
    let env = Env::new();
    let las = shared_data().join("autzen/autzen_trim.las");
    std::fs::create_dir(env.path("tiles")).unwrap();
    std::fs::copy(&las, env.path("tiles/a.las")).unwrap();
    let g = env.write(
        "g.ron",
        "Graph(\n  site: Site(crs: \"EPSG:32610\", origin: (494000.0, 4877000.0), cell_m: 1.0),\n  nodes: { \"p\": ReadLas(path: \"tiles\"), \"s\": PointStats(points: \"p\") },\n  outputs: { \"s\": \"s\" },\n)\n",
    );
    let count = || {
        let s: serde_json::Value =
            serde_json::from_slice(&std::fs::read(env.out().join("s.json")).unwrap()).unwrap();
        s["count"].as_f64().unwrap()
    };
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.status("p"), "ran");
    assert_eq!(count(), 110_000.0);
    assert_eq!(env.run(&g, &[]).ok().status("p"), "cached");
    std::fs::copy(&las, env.path("tiles/b.las")).unwrap();
    let r = env.run(&g, &[]).ok();
    assert_eq!(r.status("p"), "ran");
    assert_eq!(count(), 220_000.0);
}

/// Broken OSM XML through the CLI: exit 2, the file and the line.
#[test]
fn broken_osm_xml_exits_2_naming_the_line() {
    let env = Env::new();
    std::fs::write(
        env.path("b.osm"),
        "<?xml version=\"1.0\"?>\n<osm version=\"0.6\">\n  <node id=\"1\" lat=\"x\" lon=\"0\"/>\n</osm>\n",
    )
    .unwrap();
    let g = env.write(
        "g.ron",
        "Graph(\n  site: Site(crs: \"EPSG:32618\", origin: (583200.0, 4506600.0), cell_m: 1.0),\n  nodes: { \"b\": ReadOsmBuildings(path: \"b.osm\") },\n)\n",
    );
    let r = env.run(&g, &[]);
    // Nothing references node 1, but every node is read: its bad latitude is still an error.
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("b.osm: line 3"), "{}", r.stderr);
    assert!(r.stderr.contains("a lat in degrees"), "{}", r.stderr);
}
