//! 3D Tiles: the synthetic site's truth written as a tileset and read back through ReadTileset,
//! and b3dm content with an RTC_CENTER.

mod common;
use common::*;

use std::path::Path;

use kodama_nodes::artifact::Scene;
use kodama_nodes::io::export::{Encoded, encode, write_glb};
use kodama_nodes::stages::ingest::read_tiles::{ReadTileset, ReadTilesetParams};
use kodama_nodes::synth::synth_city::generate;
use kodama_nodes::{Artifact, Ctx, Inputs, Stage};

fn truth() -> Scene {
    scene_of(&generate(&small_city()))
}

fn write_folder(dir: &Path, files: Vec<(String, Vec<u8>)>) {
    for (rel, bytes) in files {
        let f = dir.join(rel);
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
        std::fs::write(f, bytes).unwrap();
    }
}

fn read(dir: &Path) -> Scene {
    let p = ReadTilesetParams {
        path: "tiles/tileset.json".into(),
        crs: None,
    };
    let files = [dir.to_path_buf()];
    ReadTileset::run(&p, &Inputs::new(), &Ctx::new(&site(), &files)).unwrap()
}

#[test]
fn the_truth_as_3d_tiles_reads_back_in_place() {
    let scene = truth();
    let Encoded::Folder(files) =
        encode(&Artifact::Scene(scene.clone()), &site(), "3dtiles").unwrap()
    else {
        panic!("a folder")
    };
    assert_eq!(files[0].0, "tileset.json");
    let dir = tempfile::tempdir().unwrap();
    write_folder(dir.path(), files);
    let back = read(dir.path());
    assert_eq!(back.objects.len(), scene.objects.len());
    let by_id = |id: &str| {
        scene
            .objects
            .iter()
            .find(|o| id.ends_with(&format!("#{}", o.id)))
            .unwrap()
    };
    let mut worst = 0f32;
    for o in &back.objects {
        let orig = by_id(&o.id);
        assert_eq!(
            o.mesh.positions.len(),
            orig.mesh.positions.len(),
            "{}: vertices read once",
            o.id
        );
        // GLB groups triangles by material: compare (triangle, material) as sets.
        let pairs = |m: &kodama_nodes::artifact::Mesh| {
            let mut v: Vec<([u32; 3], u8)> = m
                .triangles
                .iter()
                .copied()
                .zip(m.materials.iter().copied())
                .collect();
            v.sort();
            v
        };
        assert_eq!(
            pairs(&o.mesh),
            pairs(&orig.mesh),
            "{}: triangles and their ITU materials",
            o.id
        );
        for (a, b) in o.mesh.positions.iter().zip(orig.mesh.positions.iter()) {
            worst = worst.max((0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f32::max));
        }
    }
    println!("worst vertex displacement after site -> ECEF tiles -> site: {worst} m");
    assert!(worst < 0.01, "{worst}");
}

#[test]
fn b3dm_content_with_rtc_center() {
    // One object, written as a b3dm whose positions are relative to an RTC_CENTER in ECEF.
    let scene = truth();
    let one = Scene {
        objects: vec![
            scene
                .objects
                .iter()
                .find(|o| o.id.starts_with("building"))
                .unwrap()
                .clone(),
        ],
    };
    let Encoded::Folder(files) = encode(&Artifact::Scene(one.clone()), &site(), "3dtiles").unwrap()
    else {
        panic!()
    };
    let mut tileset: serde_json::Value = serde_json::from_slice(&files[0].1).unwrap();
    let child = &mut tileset["root"]["children"][0];
    // Move the tile's translation into the b3dm's RTC_CENTER, leaving only the rotation.
    let t: Vec<f64> = child["transform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let rtc = [t[12], t[13], t[14]];
    // RTC applies in the tile's frame, before the transform: convert the ECEF offset to it.
    let local = [0, 1, 2].map(|c| (0..3).map(|r| t[c * 4 + r] * rtc[r]).sum::<f64>());
    let mut m = t.clone();
    m[12] = 0.0;
    m[13] = 0.0;
    m[14] = 0.0;
    child["transform"] = serde_json::json!(m);
    child["content"]["uri"] = "tiles/one.b3dm".into();
    let glb = &files[1].1;
    let mut ft =
        serde_json::to_vec(&serde_json::json!({"BATCH_LENGTH": 0, "RTC_CENTER": local})).unwrap();
    while !(28 + ft.len()).is_multiple_of(8) {
        ft.push(b' ');
    }
    let mut b3dm = Vec::new();
    b3dm.extend_from_slice(b"b3dm");
    for v in [
        1u32,
        (28 + ft.len() + glb.len()) as u32,
        ft.len() as u32,
        0,
        0,
        0,
    ] {
        b3dm.extend_from_slice(&v.to_le_bytes());
    }
    b3dm.extend_from_slice(&ft);
    b3dm.extend_from_slice(glb);
    let dir = tempfile::tempdir().unwrap();
    write_folder(
        dir.path(),
        vec![
            ("tileset.json".into(), serde_json::to_vec(&tileset).unwrap()),
            ("tiles/one.b3dm".into(), b3dm),
        ],
    );
    let back = read(dir.path());
    let worst = back.objects[0]
        .mesh
        .positions
        .iter()
        .zip(one.objects[0].mesh.positions.iter())
        .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f32::max))
        .fold(0.0, f32::max);
    assert!(worst < 0.01, "{worst}");
    let _ = write_glb(&one).unwrap();
}
