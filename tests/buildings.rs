//! The building chain of Sec. 4.1 end to end through the CLI: the demo graph and the real Delft
//! AHN3 tile. Every building mesh in the exported glb files is read back and passes the mesh
//! checker; the Delft footprints, derived from the LiDAR alone, are scored against the BGT.

mod common;
use common::*;

use std::path::{Path, PathBuf};

use kodama_nodes::artifact::{Mesh, PodVec};
use kodama_nodes::mesh_check::check_solid;

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The meshes of a glb whose node names contain "building", with their names.
fn building_meshes(glb: &Path) -> Vec<(String, Mesh)> {
    let (doc, buffers, _) = gltf::import(glb).unwrap_or_else(|e| panic!("{}: {e}", glb.display()));
    let mut out = Vec::new();
    for node in doc.nodes() {
        let name = node.name().unwrap_or_default().to_string();
        let Some(mesh) = node.mesh() else { continue };
        if !name.contains("building") {
            continue;
        }
        let mut m = Mesh::default();
        for prim in mesh.primitives() {
            let r = prim.reader(|b| Some(&buffers[b.index()]));
            if m.positions.is_empty() {
                m.positions = PodVec(r.read_positions().unwrap().collect());
            }
            let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
            m.triangles
                .extend(idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
            m.materials.extend(std::iter::repeat_n(0u8, idx.len() / 3));
        }
        out.push((name, m));
    }
    out
}

fn check_all(glb: &Path) -> usize {
    let meshes = building_meshes(glb);
    for (name, m) in &meshes {
        check_solid(m).unwrap_or_else(|e| panic!("{}: {name}: {e}", glb.display()));
    }
    meshes.len()
}

#[test]
fn demo_scenes_hold_only_valid_building_solids() {
    let env = Env::new();
    env.run(&repo("graphs/demo.ron"), &[]).ok();
    let kodama = check_all(&env.out().join("scene.glb"));
    let baseline = check_all(&env.out().join("osm_scene.glb"));
    println!(
        "demo: {kodama} KODAMA building solids, {baseline} OSM-baseline prisms, all pass the checker"
    );
    assert!(kodama >= 65, "{kodama}");
    assert_eq!(baseline, 72, "one prism per true footprint");
}

#[test]
fn delft_tile_footprints_and_solids() {
    let data = repo("../shared/data");
    assert!(data.is_dir(), "real test data missing: {}", data.display());
    let env = Env::new();
    env.run(
        &repo("graphs/delft.ron"),
        &["--data", data.to_str().unwrap()],
    )
    .ok();
    let solids = check_all(&env.out().join("scene.glb"));
    let score: serde_json::Value =
        serde_json::from_slice(&std::fs::read(env.out().join("footprint_score.json")).unwrap())
            .unwrap();
    let get = |k: &str| {
        score[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} missing: {score}"))
    };
    println!(
        "delft: {solids} building solids pass the checker; against the BGT ({} buildings scored): \
         per-building IoU mean {:.3} (median {:.3}), merge-tolerant block IoU mean {:.3} over {} \
         blocks, footprint IoU {:.3}",
        get("buildings_scored"),
        get("building_iou_mean"),
        get("building_iou_median"),
        get("block_iou_mean"),
        get("blocks_scored"),
        get("iou"),
    );
    assert!(solids > 50, "{solids}");
    assert!(get("iou") >= 0.8, "footprint IoU {}", get("iou"));
    assert!(get("block_iou_mean") >= 0.65);
    // The derived footprints are the LiDAR's: they must not be the BGT's own polygons.
    let ours = std::fs::read_to_string(env.out().join("building_footprints.geojson")).unwrap();
    assert!(
        !ours.contains("b31e1feb1"),
        "BGT ids leaked into the derived footprints"
    );
}
