//! OGC 3D Tiles 1.1 export of scenes: `tileset.json` and one glTF (`.glb`) tile per square of the
//! site, placed on the globe exactly.
//!
//! The site frame is a projected grid, not a local tangent plane: meridian convergence and scale
//! would put a naive east-north-up tile metres off a few hundred metres from the origin. So each
//! vertex is converted exactly (site -> WGS84 -> ECEF) and written in the east-north-up frame of
//! its tile's centre, which the tile's `transform` places in ECEF. Heights are written as
//! ellipsoidal heights (no geoid model is applied), and read back the same way.

use serde_json::{Value, json};

use super::glb::write_glb_objects;
use crate::artifact::{Scene, SceneObject};
use crate::io::crs::{Crs, ToSite};
use crate::io::ecef::{enu_axes, to_ecef};
use crate::site::Site;

/// Where an object's tile is: the square of `tile_m` holding its centroid, or, for an object a
/// tiled run merged (its id prefixed with its run tile, `x2y1/building-7`), that run tile.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Leaf {
    Square(i64, i64),
    RunTile(String),
}

/// The run tile an id names (`x2y1` of `x2y1/building-7`), if it names one.
fn run_tile(id: &str) -> Option<&str> {
    let (tile, _) = id.split_once('/')?;
    let (x, y) = tile.strip_prefix('x')?.split_once('y')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    (digits(x) && digits(y)).then_some(tile)
}

/// The tileset files: `tileset.json` first, then `tiles/<i>_<j>.glb` (a square of `tile_m`) or
/// `tiles/<run tile>.glb` (the objects one tile of a tiled run gave a merged scene: one leaf per
/// run tile).
pub fn write_tileset(
    scene: &Scene,
    site: &Site,
    tile_m: f64,
) -> Result<Vec<(String, Vec<u8>)>, String> {
    let wgs84 = ToSite::new(&Crs::from_epsg(4326)?, site)?;
    // Group objects by the tile holding their centroid, or the run tile that made them.
    let mut tiles: std::collections::BTreeMap<Leaf, Vec<&SceneObject>> = Default::default();
    for o in scene.objects.iter().filter(|o| !o.mesh.is_empty()) {
        let leaf = match run_tile(&o.id) {
            Some(t) => Leaf::RunTile(t.to_owned()),
            None => {
                let c = centroid(o);
                Leaf::Square(
                    (c[0] / tile_m).floor() as i64,
                    (c[1] / tile_m).floor() as i64,
                )
            }
        };
        tiles.entry(leaf).or_default().push(o);
    }
    let mut files = Vec::new();
    let mut children = Vec::new();
    let (mut west, mut south, mut east, mut north, mut hmin, mut hmax) =
        (f64::MAX, f64::MAX, f64::MIN, f64::MIN, f64::MAX, f64::MIN);
    for (leaf, objects) in &tiles {
        let (center, uri) = match leaf {
            Leaf::Square(i, j) => (
                [(*i as f64 + 0.5) * tile_m, (*j as f64 + 0.5) * tile_m],
                format!("tiles/{i}_{j}.glb"),
            ),
            Leaf::RunTile(name) => {
                let cs: Vec<[f64; 2]> = objects.iter().map(|o| centroid(o)).collect();
                let n = cs.len() as f64;
                let c = cs
                    .iter()
                    .fold([0.0, 0.0], |a, c| [a[0] + c[0] / n, a[1] + c[1] / n]);
                (c, format!("tiles/{name}.glb"))
            }
        };
        let (clon, clat) = wgs84.inverse(center[0], center[1])?;
        let origin = to_ecef(clon, clat, 0.0);
        let axes = enu_axes(clon, clat);
        let mut failure = None;
        let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
        let to_local = |p: [f32; 3]| -> [f32; 3] {
            let (lon, lat) = match wgs84.inverse(p[0] as f64, p[1] as f64) {
                Ok(v) => v,
                Err(_) => return [f32::NAN; 3],
            };
            let e = to_ecef(lon, lat, p[2] as f64);
            let d = [e[0] - origin[0], e[1] - origin[1], e[2] - origin[2]];
            let enu = axes.map(|a| a[0] * d[0] + a[1] * d[1] + a[2] * d[2]);
            // glTF is y-up: (east, north, up) -> (east, up, -north).
            [enu[0] as f32, enu[2] as f32, -enu[1] as f32]
        };
        for o in objects {
            for p in o.mesh.positions.iter() {
                let l = to_local(*p);
                if l[0].is_nan() {
                    failure = Some(format!("{}: cannot place vertex {p:?} on the globe", o.id));
                }
                let enu = [l[0] as f64, -l[2] as f64, l[1] as f64];
                for k in 0..3 {
                    lo[k] = lo[k].min(enu[k]);
                    hi[k] = hi[k].max(enu[k]);
                }
                let (lon, lat) = wgs84.inverse(p[0] as f64, p[1] as f64)?;
                (west, east, south, north) =
                    (west.min(lon), east.max(lon), south.min(lat), north.max(lat));
                (hmin, hmax) = (hmin.min(p[2] as f64), hmax.max(p[2] as f64));
            }
        }
        if let Some(f) = failure {
            return Err(f);
        }
        files.push((uri.clone(), write_glb_objects(objects, to_local, true)?));
        // Column-major ENU -> ECEF.
        let transform: Vec<f64> = [
            axes[0].to_vec(),
            vec![0.0],
            axes[1].to_vec(),
            vec![0.0],
            axes[2].to_vec(),
            vec![0.0],
            origin.to_vec(),
            vec![1.0],
        ]
        .concat();
        let c = [
            (lo[0] + hi[0]) / 2.0,
            (lo[1] + hi[1]) / 2.0,
            (lo[2] + hi[2]) / 2.0,
        ];
        let h = [
            (hi[0] - lo[0]) / 2.0 + 0.01,
            (hi[1] - lo[1]) / 2.0 + 0.01,
            (hi[2] - lo[2]) / 2.0 + 0.01,
        ];
        children.push(json!({
            "transform": transform,
            "boundingVolume": {"box": [c[0], c[1], c[2], h[0], 0.0, 0.0, 0.0, h[1], 0.0, 0.0, 0.0, h[2]]},
            "geometricError": 0.0,
            "content": {"uri": uri},
        }));
    }
    let rad = f64::to_radians;
    let tileset: Value = json!({
        "asset": {"version": "1.1", "generator": concat!("kodama-dag ", env!("CARGO_PKG_VERSION"))},
        "geometricError": tile_m,
        "root": {
            "boundingVolume": {"region": [rad(west), rad(south), rad(east), rad(north), hmin, hmax]},
            "geometricError": tile_m,
            "refine": "ADD",
            "children": children,
        },
    });
    let mut out = vec![(
        "tileset.json".to_owned(),
        serde_json::to_vec_pretty(&tileset).map_err(|e| e.to_string())?,
    )];
    out.extend(files);
    Ok(out)
}

/// The mean of an object's vertices, plan only.
fn centroid(o: &SceneObject) -> [f64; 2] {
    let n = o.mesh.positions.len() as f64;
    o.mesh.positions.iter().fold([0.0, 0.0], |a, p| {
        [a[0] + p[0] as f64 / n, a[1] + p[1] as f64 / n]
    })
}
