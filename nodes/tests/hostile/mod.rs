//! Seeds shared by the hostile-input tests and the parser fuzzing: small valid files of each
//! format, which the tests then break.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use kodama_nodes::artifact::{PodVec, Scene};

pub fn write(dir: &Path, rel: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(rel);
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(&p, bytes).unwrap();
    p
}

pub const SCENE_XML: &str = r#"<scene version="2.1.0">
<bsdf type="itu-radio-material" id="itu_concrete"><string name="type" value="concrete"/></bsdf>
<shape type="ply" id="mesh-b"><string name="filename" value="meshes/buildings.ply"/><ref id="itu_concrete" name="bsdf"/></shape>
</scene>
"#;

pub fn tetra() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    (
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
}

/// A glb of one object whose vertex 2 has `x` as its x (in glTF's y-up frame).
pub fn glb_with_x(x: f32) -> Vec<u8> {
    let (p, t) = tetra();
    let marker = 4321.5f32;
    let mut p: Vec<[f32; 3]> = p;
    p[2][0] = marker;
    let scene = Scene {
        objects: vec![kodama_nodes::artifact::SceneObject {
            id: "b".into(),
            class: kodama_nodes::artifact::ObjectClass::Building,
            mesh: kodama_nodes::artifact::Mesh {
                positions: PodVec(p),
                triangles: PodVec(t),
                materials: PodVec(vec![0; 4]),
            },
        }],
    };
    let mut glb = kodama_nodes::io::export::write_glb(&scene).unwrap();
    let at = glb
        .windows(4)
        .position(|w| w == marker.to_le_bytes())
        .expect("the marker vertex");
    glb[at..at + 4].copy_from_slice(&x.to_le_bytes());
    glb
}

pub const TILESET: &str = r#"{"asset": {"version": "1.0"}, "geometricError": 0,
 "root": {"geometricError": 0, "boundingVolume": {"box": [0,0,0,1,0,0,0,1,0,0,0,1]},
          "content": {"uri": "a.glb"}}}"#;

/// A small LAS 1.2 file of `n` points near the site origin, as the las crate writes it.
pub fn las_file(dir: &Path, name: &str, n: usize, compressed: bool) -> PathBuf {
    let path = dir.join(name);
    let mut b = las::Builder::from((1, 2));
    b.point_format = las::point::Format::new(0).unwrap();
    b.point_format.is_compressed = compressed;
    b.transforms = las::Vector {
        x: las::Transform {
            scale: 0.01,
            offset: 583000.0,
        },
        y: las::Transform {
            scale: 0.01,
            offset: 4506000.0,
        },
        z: las::Transform {
            scale: 0.01,
            offset: 0.0,
        },
    };
    let mut w = las::Writer::from_path(&path, b.into_header().unwrap()).unwrap();
    for i in 0..n {
        w.write_point(las::Point {
            x: 583200.0 + (i % 100) as f64,
            y: 4506600.0 + (i / 100) as f64,
            z: (i % 7) as f64,
            ..Default::default()
        })
        .unwrap();
    }
    w.close().unwrap();
    path
}

/// A minimal float32 GeoTIFF: `width` x `height` pixels (the strip is only there when small),
/// with the given pixel scale and tiepoint.
pub fn tiff(width: u32, height: u32, scale: [f64; 3], tie: [f64; 6]) -> Vec<u8> {
    let n_entries = 12u16;
    let ifd_len = 2 + 12 * n_entries as u32 + 4;
    let doubles_at = 8 + ifd_len;
    let data_at = doubles_at + 9 * 8;
    let data_len = (width as u64 * height as u64 * 4).min(u32::MAX as u64) as u32;
    let mut out = b"II*\0".to_vec();
    out.extend(8u32.to_le_bytes());
    out.extend(n_entries.to_le_bytes());
    let mut entry = |tag: u16, ty: u16, count: u32, value: u32| {
        out.extend(tag.to_le_bytes());
        out.extend(ty.to_le_bytes());
        out.extend(count.to_le_bytes());
        out.extend(value.to_le_bytes());
    };
    const SHORT: u16 = 3;
    const LONG: u16 = 4;
    const DOUBLE: u16 = 12;
    entry(256, LONG, 1, width);
    entry(257, LONG, 1, height);
    entry(258, SHORT, 1, 32);
    entry(259, SHORT, 1, 1);
    entry(262, SHORT, 1, 1);
    entry(273, LONG, 1, data_at);
    entry(277, SHORT, 1, 1);
    entry(278, LONG, 1, height);
    entry(279, LONG, 1, data_len);
    entry(339, SHORT, 1, 3);
    entry(33550, DOUBLE, 3, doubles_at);
    entry(33922, DOUBLE, 6, doubles_at + 24);
    out.extend(0u32.to_le_bytes());
    for v in scale.iter().chain(&tie) {
        out.extend(v.to_le_bytes());
    }
    if data_len < 1 << 20 {
        out.extend(vec![0u8; data_len as usize]);
    }
    out
}

/// OSM XML as the Overpass API writes it, near the test site (EPSG:32618 around 40.70 N, 74.00 W):
/// a multipolygon building whose outer ring is two ways and whose courtyard is a third, and a
/// building way inside the courtyard with a height in metres.
pub const OSM_XML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<osm version="0.6" generator="Overpass API 0.7.60.4">
<note>The data included in this document is from www.openstreetmap.org.</note>
  <bounds minlat="40.6999" minlon="-74.0001" maxlat="40.7011" maxlon="-73.9989"/>
  <node id="1" lat="40.7000000" lon="-74.0000000"/>
  <node id="2" lat="40.7000000" lon="-73.9990000"/>
  <node id="3" lat="40.7010000" lon="-73.9990000"/>
  <node id="4" lat="40.7010000" lon="-74.0000000"/>
  <node id="5" lat="40.7003000" lon="-73.9997000"/>
  <node id="6" lat="40.7003000" lon="-73.9993000"/>
  <node id="7" lat="40.7007000" lon="-73.9995000">
    <tag k="name" v="Caf&#233; &amp; bar"/>
  </node>
  <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/></way>
  <way id="11"><nd ref="1"/><nd ref="4"/><nd ref="3"/></way>
  <way id="12"><nd ref="5"/><nd ref="6"/><nd ref="7"/><nd ref="5"/></way>
  <way id="13">
    <nd ref="5"/><nd ref="6"/><nd ref="7"/><nd ref="5"/>
    <tag k="building" v="yes"/>
    <tag k="height" v="12 m"/>
  </way>
  <relation id="20">
    <member type="way" ref="10" role="outer"/>
    <member type="way" ref="11" role="outer"/>
    <member type="way" ref="12" role="inner"/>
    <tag k="building" v="apartments"/>
    <tag k="building:levels" v="4"/>
    <tag k="type" v="multipolygon"/>
  </relation>
</osm>
"#;
