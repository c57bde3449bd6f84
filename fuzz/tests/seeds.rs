//! Writes each target's seed into its corpus folder (`corpus/<target>/seed.*`): small valid files
//! made by the same helpers the hostile-input tests break. The committed seeds came from here:
//!
//!     cargo test -p kodama-fuzz --test seeds -- --ignored
//!
//! (LAS headers carry the day they were written, so a rerun changes those two seeds' bytes.)

#[path = "../../nodes/tests/hostile/mod.rs"]
mod hostile;

use hostile::*;
use kodama_fuzz::corpus_dir;
use serde_json::json;

fn put(target: &str, file: &str, bytes: impl AsRef<[u8]>) {
    let dir = corpus_dir(target);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(file), bytes).unwrap();
}

const VIEWS: &str = r#"{"material_classes": ["glass", "brick"],
 "views": [{"id": "a", "image": "img.png", "width": 8, "height": 4,
            "intrinsics": {"fx": 4, "fy": 4, "cx": 4, "cy": 2},
            "pose": {"x": 0, "y": 0, "z": 2},
            "orientation": {"quat_wxyz": [1, 0, 0, 0]},
            "distortion": [0.1, 0.01]},
           {"id": 2, "image": "img.png", "width": 8, "height": 4,
            "intrinsics": {"hfov_deg": 90},
            "pose": {"lat": 40.7, "lon": -74.0, "alt_m": 10},
            "orientation": {"heading_deg": 90, "pitch_deg": 5}}]}
"#;

const MEASUREMENTS: &str = "\
tx_id,tx_x,tx_y,tx_z,rx_lat,rx_lon,rx_height_m,freq_hz,path_loss_db,rx_power_dbm,los
a,0,0,30,40.70,-74.00,1.5,3.5e9,100,,1
a,0,0,30,40.71,-74.01,1.5,3.5e9,,-80,0
";

/// Points in the site CRS around its origin: a header, a comment, spaces, tabs and commas.
const XYZ: &str = "\
x y z class
# two ground points and a roof
583200.0 4506600.0 1.5 2
583201.0\t4506600.5\t1.6\t2
583202.5,4506601.0,12.0,6
";

const GRAPH: &str = r#"// A small synthetic site: the sweep target's base graph too.
Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    nodes: {
        "city": SynthCity(seed: 3, size_m: (120.0, 100.0), blocks: (2, 2), street_m: 14.0, terrain: (size_m: (120.0, 100.0))),
        "truth": TruthScene(city: "city"),
        "footprints": CityFootprints(city: "city"),
        "lidar": SynthLidar(scene: "truth", density_per_m2: 4.0, seed: 3),
        "dsm": RasterizeSurface(points: "lidar", mode: Max),
        "dsm_stats": RasterStats(raster: "dsm"),
    },
    outputs: {
        "dsm.tif": "dsm",
    },
)
"#;

const SWEEP: &str = r#"Sweep(
    graph: "graph.ron",
    axes: {
        "density": Grid(set: "lidar.density_per_m2", values: [2.0, 4.0]),
        "mode": Switch({
            "mean": ["dsm.mode=Mean"],
            "max": [],
        }),
    },
    metrics: ["dsm_stats.valid", "dsm_stats.cells"],
)
"#;

#[test]
#[ignore]
fn write_the_seeds() {
    let (p, t) = tetra();
    put(
        "ply",
        "seed.ply",
        kodama_nodes::io::sionna_xml::write_ply(&p, &t),
    );
    put("sionna_xml", "seed.xml", SCENE_XML);
    put("glb", "seed.glb", glb_with_x(1.0));
    put("tileset_json", "seed.json", TILESET);
    put("views_json", "seed.json", VIEWS);
    put("measurements_csv", "seed.csv", MEASUREMENTS);
    let dir = tempfile::tempdir().unwrap();
    put(
        "las",
        "seed.las",
        std::fs::read(las_file(dir.path(), "s.las", 20, false)).unwrap(),
    );
    put(
        "laz",
        "seed.laz",
        std::fs::read(las_file(dir.path(), "s.laz", 200, true)).unwrap(),
    );
    put(
        "geotiff",
        "seed.tif",
        tiff(
            4,
            3,
            [1.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 583200.0, 4506600.0, 0.0],
        ),
    );
    put("osm_xml", "seed.osm", OSM_XML);
    let footprints = json!({
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32618"}},
        "features": [
            {"type": "Feature", "id": "a", "properties": {"height": 12.5},
             "geometry": {"type": "Polygon", "coordinates": [[
                 [583200.0, 4506600.0], [583210.0, 4506600.0], [583210.0, 4506608.0],
                 [583200.0, 4506608.0], [583200.0, 4506600.0]]]}},
            {"type": "Feature", "properties": {"id": "b", "height_m": "9 m"},
             "geometry": {"type": "MultiPolygon", "coordinates": [[[
                 [583220.0, 4506600.0], [583230.0, 4506600.0], [583225.0, 4506606.0],
                 [583220.0, 4506600.0]]]]}}
        ]
    });
    put("geojson", "seed.geojson", footprints.to_string());
    put("xyz", "seed.xyz", XYZ);
    let depth: Vec<f32> = (0..12).map(|i| 2.0 + i as f32 * 0.5).collect();
    put(
        "exr",
        "seed.exr",
        kodama_nodes::io::exr_io::write_exr(4, 3, vec![("Z", depth)]).unwrap(),
    );
    put("ron_graph", "seed.ron", GRAPH);
    put("ron_sweep", "seed.ron", SWEEP);
}
