//! The OSM route on real OSM: the Helsinki extract and the Duke campus extracts read, extruded by
//! OsmBaseline on a FlatGround and assembled into a scene, with every invalid building repaired or
//! dropped and counted, and every height's source counted.

mod common;
use common::*;

use std::collections::BTreeMap;
use std::sync::Arc;

use kodama_nodes::artifact::{Artifact, Footprints, Metrics, ObjectClass, Raster, Scene};
use kodama_nodes::geom::mesh_check::{OnInvalid, check_solid};
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::baseline::osm_baseline::{OsmBaseline, OsmBaselineParams};
use kodama_nodes::stages::buildings::assemble_scene::{AssembleScene, AssembleSceneParams};
use kodama_nodes::stages::heights::flat_ground::flat_ground;
use kodama_nodes::stages::ingest::read_osm::{ReadOsmBuildings, ReadOsmBuildingsParams};
use kodama_nodes::{Ctx, Inputs, Site, Stage};

fn read_osm(site: &Site, files: &[std::path::PathBuf]) -> Footprints {
    let p = ReadOsmBuildingsParams {
        paths: (0..files.len()).map(|i| format!("f{i}.osm")).collect(),
        ..Default::default()
    };
    ReadOsmBuildings::run(&p, &Inputs::new(), &Ctx::new(site, files)).unwrap()
}

/// A flat ground at z = 0 over the footprints' extent plus 50 m.
fn ground_under(f: &Footprints) -> Raster {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for q in f
        .items
        .iter()
        .flat_map(|b| &b.polygons)
        .flat_map(|p| &p.exterior)
    {
        lo = [lo[0].min(q[0]), lo[1].min(q[1])];
        hi = [hi[0].max(q[0]), hi[1].max(q[1])];
    }
    flat_ground(
        (lo[0] - 50.0, lo[1] - 50.0, hi[0] + 50.0, hi[1] + 50.0),
        10.0,
        0.0,
    )
    .unwrap()
}

fn baseline(
    site: &Site,
    f: &Footprints,
    ground: &Raster,
    p: &OsmBaselineParams,
) -> Result<(Scene, BTreeMap<String, f64>), kodama_nodes::StageError> {
    let inputs = Inputs::new()
        .with("footprints", slot(Artifact::Footprints(f.clone())))
        .with("terrain", slot(Artifact::Raster(ground.clone())));
    let r = OsmBaseline::run_reported(p, &inputs, &Ctx::new(site, &[]))?;
    let Artifact::Metrics(Metrics { values }) = &r.reports[0].1 else {
        panic!("the report is Metrics");
    };
    Ok((r.output, values.clone()))
}

fn assemble(site: &Site, ground: &Raster, scene: Scene) -> Result<Scene, kodama_nodes::StageError> {
    let inputs = Inputs::new()
        .with("terrain", slot(Artifact::Raster(ground.clone())))
        .with(
            "objects",
            Slot::Many(vec![Arc::new(Artifact::Scene(scene))]),
        );
    AssembleScene::run(
        &AssembleSceneParams::default(),
        &inputs,
        &Ctx::new(site, &[]),
    )
}

fn helsinki() -> Site {
    Site {
        crs: "EPSG:3067".into(),
        origin: (385000.0, 6672000.0),
        cell_m: 1.0,
    }
}

/// The building the issue found failing AssembleScene (`building-r1858248: triangles 4 and 130
/// intersect`): OsmBaseline now checks a building's polygons together and, by default, makes
/// each its own object, so the scene assembles; with `Fail` the same building stops the run.
#[test]
fn helsinki_assembles_with_repairs_counted() {
    let site = helsinki();
    let f = read_osm(&site, &[shared("osm/Helsinki.osm.pbf")]);
    let ground = ground_under(&f);
    let (scene, counts) = baseline(&site, &f, &ground, &OsmBaselineParams::default()).unwrap();
    println!("Helsinki OsmBaseline counts: {counts:?}");
    let n = |k: &str| counts[k] as usize;
    assert_eq!(n("footprints"), f.items.len());
    assert_eq!(
        n("height_from_tag") + n("height_from_levels") + n("height_default"),
        n("buildings")
    );
    assert!(n("height_default") > 0);
    assert!(n("repaired_split") >= 1, "{counts:?}");
    // Every building object is a valid solid, and the ground is the first object.
    assert_eq!(scene.objects[0].class, ObjectClass::Terrain);
    for o in scene
        .objects
        .iter()
        .filter(|o| o.class == ObjectClass::Building)
    {
        check_solid(&o.mesh).unwrap_or_else(|e| panic!("{}: {e}", o.id));
    }
    assert!(
        scene
            .objects
            .iter()
            .any(|o| o.id.starts_with("building-r1858248/"))
    );
    let whole = assemble(&site, &ground, scene).unwrap();
    assert!(
        whole
            .objects
            .iter()
            .filter(|o| o.class == ObjectClass::Terrain)
            .count()
            == 1
    );

    let fail = OsmBaselineParams {
        on_invalid: OnInvalid::Fail,
        ..OsmBaselineParams::default()
    };
    let e = baseline(&site, &f, &ground, &fail).unwrap_err();
    assert!(format!("{e}").contains("on_invalid"), "{e}");
}

/// Duke's two overlapping extracts read as one set (the first file's copy of a shared building
/// kept: the ML heights of pci_EF_new), extruded with every height's source counted.
#[test]
fn duke_extracts_merge_and_extrude() {
    let site = Site {
        crs: "EPSG:32617".into(),
        origin: (687000.0, 3985000.0),
        cell_m: 1.0,
    };
    let f = read_osm(
        &site,
        &[
            shared("duke/osm/pci_EF_new.osm"),
            shared("duke/osm/pci_ABCD.osm"),
        ],
    );
    // 116 in EF, 107 in ABCD, 65 in both (docs/research/duke.md, scripts/duke_split.py).
    assert_eq!(f.items.len(), 116 + 107 - 65);
    let ground = ground_under(&f);
    let (scene, counts) = baseline(&site, &f, &ground, &OsmBaselineParams::default()).unwrap();
    println!("Duke OsmBaseline counts: {counts:?}");
    assert_eq!(counts["footprints"], 158.0);
    assert!(counts["height_default"] >= 24.0, "{counts:?}");
    assert_eq!(
        counts["height_from_tag"] + counts["height_from_levels"] + counts["height_default"],
        counts["buildings"]
    );
    assemble(&site, &ground, scene).unwrap();
}
