//! Ingest of the real files in ../shared/data, read in place, checked against independent
//! references: published counts, the files' own headers, and PROJ (tests/fixtures, made by
//! scripts/crs_reference.py).

mod common;
use common::*;

use kodama_nodes::io::crs::{Crs, ToSite};
use std::path::PathBuf;

use kodama_nodes::artifact::PointSet;
use kodama_nodes::stages::ingest::read_las::{ReadLas, ReadLasParams, header_crs, read_las};
use kodama_nodes::{Ctx, Inputs, Site, Stage, StageError};

#[test]
fn delft_ahn3_tile_counts_classes_and_extent() {
    let site = Site {
        crs: "EPSG:28992".into(),
        origin: (84800.0, 447400.0),
        cell_m: 0.5,
    };
    let ctx = Ctx::new(&site, &[]);
    let pts = read_las(&shared("delft/ahn3_tile1.laz"), Some("EPSG:28992"), &ctx).unwrap();
    assert_eq!(pts.len(), 640_510);
    let count = |c: u8| pts.class.iter().filter(|&&k| k == c).count();
    assert_eq!(count(6), 246_753, "building points");
    assert_eq!(
        [1, 2, 6, 9, 26].iter().map(|&c| count(c)).sum::<usize>(),
        640_510,
        "classes 1, 2, 6, 9, 26 only"
    );
    let (lo, hi) = pts.bounds().unwrap();
    // The header's bounds, shifted by the site origin.
    for (got, want) in [
        (lo[0], 8.3),
        (lo[1], 12.8),
        (lo[2], -0.568),
        (hi[0], 199.999),
        (hi[1], 241.299),
        (hi[2], 19.398),
    ] {
        assert!((got as f64 - want).abs() < 1e-3, "{got} vs {want}");
    }
    assert_eq!(pts.intensity.len(), pts.len());
    assert!(pts.rgb.is_empty(), "point format 1 has no colour");
}

#[test]
fn delft_without_a_crs_is_a_clear_error() {
    let site = Site {
        crs: "EPSG:28992".into(),
        origin: (84800.0, 447400.0),
        cell_m: 0.5,
    };
    let e = read_las(&shared("delft/ahn3_tile1.laz"), None, &Ctx::new(&site, &[])).unwrap_err();
    assert!(
        e.to_string()
            .contains("ahn3_tile1.laz: header: no CRS recorded"),
        "{e}"
    );
    assert!(e.is_user_error());
}

#[test]
fn autzen_user_defined_lambert_in_feet() {
    let path = shared("autzen/autzen_trim.las");
    let header = las::Reader::from_path(&path).unwrap().header().clone();
    let crs = header_crs(&path, &header)
        .unwrap()
        .expect("autzen has GeoTIFF keys");
    assert!(crs.proj4.contains("+proj=lcc"), "{}", crs.proj4);
    assert_eq!(crs.z_to_m, 0.3048, "z in international feet like x and y");
    let site = Site {
        crs: "EPSG:32610".into(),
        origin: (494000.0, 4877000.0),
        cell_m: 1.0,
    };
    let pts = read_las(&path, None, &Ctx::new(&site, &[])).unwrap();
    assert_eq!(pts.len(), 110_000);
    assert_eq!(pts.rgb.len(), 110_000, "format 3 carries RGB");
    let (lo, hi) = pts.bounds().unwrap();
    // Header z range 406.26..520.51 ft.
    assert!(
        (lo[2] as f64 - 406.26 * 0.3048).abs() < 1e-3
            && (hi[2] as f64 - 520.51 * 0.3048).abs() < 1e-3
    );
    assert!(
        lo[0] > 100.0 && hi[0] < 500.0 && lo[1] > 400.0 && hi[1] < 620.0,
        "{lo:?} {hi:?}"
    );
}

/// Our CRS reading plus proj4rs against PROJ on the same points.
#[test]
fn reprojection_agrees_with_proj() {
    let text = std::fs::read_to_string(fixture("crs_reference.csv")).unwrap();
    let autzen = {
        let path = shared("autzen/autzen_trim.las");
        let header = las::Reader::from_path(&path).unwrap().header().clone();
        header_crs(&path, &header).unwrap().unwrap()
    };
    let mut checked = 0;
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let src = if f[1] == "autzen-header" {
            autzen.clone()
        } else {
            Crs::from_user(f[1]).unwrap()
        };
        let site = Site {
            crs: f[2].into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        let t = ToSite::new(&src, &site).unwrap();
        let num = |i: usize| f[i].parse::<f64>().unwrap();
        let (e, n, _) = t.apply(num(3), num(4), 0.0).unwrap();
        let err = ((e - num(5)).powi(2) + (n - num(6)).powi(2)).sqrt();
        // Same datum: millimetres. Across datums PROJ and the +towgs84 of the EPSG definitions may
        // pick different Helmert parameters (see scripts/crs_reference.py): metres.
        let tol = if f[0].ends_with("same_datum") {
            0.005
        } else {
            2.0
        };
        assert!(
            err < tol,
            "{}: ({}, {}) -> ({e:.3}, {n:.3}), PROJ ({}, {}): {err:.4} m off",
            f[0],
            f[3],
            f[4],
            f[5],
            f[6]
        );
        checked += 1;
    }
    assert_eq!(checked, 9);
}

// ------------------------------------------------------------------------------------------------
// ReadLas on a folder of tiles (issue 49)

fn read_las_node(path: PathBuf, crs: Option<&str>, site: &Site) -> Result<PointSet, StageError> {
    let p = ReadLasParams {
        path: "tiles".into(),
        crs: crs.map(Into::into),
    };
    ReadLas::run(&p, &Inputs::new(), &Ctx::new(site, &[path]))
}

fn autzen_site() -> Site {
    Site {
        crs: "EPSG:32610".into(),
        origin: (494000.0, 4877000.0),
        cell_m: 1.0,
    }
}

/// `points` written as a LAS (or LAZ) tile with `header`'s format, scales and VLRs (its CRS).
fn write_tile(path: &std::path::Path, header: &las::Header, points: &[las::Point], laz: bool) {
    let mut b = las::Builder::from(header.clone());
    b.point_format.is_compressed = laz;
    let mut w = las::Writer::from_path(path, b.into_header().unwrap()).unwrap();
    for p in points {
        w.write_point(p.clone()).unwrap();
    }
    w.close().unwrap();
}

/// Autzen cut in two, the first half as LAZ, written by the las crate into a folder (with a file
/// that is not a tile): the folder reads as exactly the whole file, point by point, with colour.
/// The second half is named so that it sorts first by name, and its points must come first.
#[test]
fn autzen_halves_in_a_folder_read_as_the_whole() {
    let whole_path = shared("autzen/autzen_trim.las");
    let mut reader = las::Reader::from_path(&whole_path).unwrap();
    let header = reader.header().clone();
    let points: Vec<las::Point> = reader
        .read_all()
        .unwrap()
        .points()
        .map(Result::unwrap)
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let (first, second) = points.split_at(61_234);
    write_tile(&dir.path().join("b_first.laz"), &header, first, true);
    write_tile(&dir.path().join("A_second.LAS"), &header, second, false);
    std::fs::write(dir.path().join("readme.txt"), "not a tile").unwrap();
    let site = autzen_site();
    let whole = read_las_node(whole_path, None, &site).unwrap();
    let tiles = read_las_node(dir.path().to_path_buf(), None, &site).unwrap();
    assert_eq!(tiles.len(), 110_000);
    assert_eq!(tiles.rgb.len(), 110_000);
    // "A_second.LAS" < "b_first.laz" (byte order): the second half comes first.
    let n2 = second.len();
    assert_eq!(tiles.xyz[..n2], whole.xyz[61_234..]);
    assert_eq!(tiles.xyz[n2..], whole.xyz[..61_234]);
    let reorder = |v: &[[u16; 3]]| [&v[61_234..], &v[..61_234]].concat();
    assert_eq!(tiles.rgb.to_vec(), reorder(&whole.rgb));
    assert_eq!(tiles.class[..n2], whole.class[61_234..]);
    assert_eq!(tiles.intensity[n2..], whole.intensity[..61_234]);
}

/// The Delft tile read in place through its folder (which also holds the BGT GeoJSON) is the
/// same cloud as the file.
#[test]
fn delft_folder_of_one_tile_reads_as_the_file() {
    let site = Site {
        crs: "EPSG:28992".into(),
        origin: (84800.0, 447400.0),
        cell_m: 0.5,
    };
    let file = read_las_node(shared("delft/ahn3_tile1.laz"), Some("EPSG:28992"), &site).unwrap();
    let folder = read_las_node(shared("delft"), Some("EPSG:28992"), &site).unwrap();
    assert_eq!(folder.len(), 640_510);
    assert!(folder == file);
    // Its header records no CRS: without `crs` the tile is named.
    let e = read_las_node(shared("delft"), None, &site)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ahn3_tile1.laz: header: no CRS recorded"), "{e}");
}

/// A header with a GeoKey directory naming one projected EPSG code.
fn utm_header(epsg: u16) -> las::Header {
    let keys: Vec<u16> = vec![1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, epsg];
    let mut b = las::Builder::from((1, 2));
    let t = |offset| las::Transform {
        scale: 0.01,
        offset,
    };
    b.transforms = las::Vector {
        x: t(583_000.0),
        y: t(4_506_000.0),
        z: t(0.0),
    };
    b.vlrs.push(las::Vlr {
        user_id: "LASF_Projection".into(),
        record_id: 34735,
        description: "GeoKeyDirectoryTag".into(),
        data: keys.iter().flat_map(|k| k.to_le_bytes()).collect(),
    });
    b.into_header().unwrap()
}

#[test]
fn tiles_in_other_crss_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let p = |x: f64| las::Point {
        x,
        y: 4_506_600.0,
        z: 1.0,
        ..Default::default()
    };
    write_tile(
        &dir.path().join("t1.las"),
        &utm_header(32618),
        &[p(583_200.0)],
        false,
    );
    write_tile(
        &dir.path().join("t2.las"),
        &utm_header(32618),
        &[p(583_201.0)],
        false,
    );
    write_tile(
        &dir.path().join("t3.las"),
        &utm_header(32617),
        &[p(583_202.0)],
        false,
    );
    let site = site();
    let e = read_las_node(dir.path().to_path_buf(), None, &site).unwrap_err();
    assert!(e.is_user_error());
    let e = e.to_string();
    for part in [
        "t3.las: CRS",
        "first tile t1.las (EPSG:32618)",
        "found EPSG:32617",
        "`crs`",
    ] {
        assert!(e.contains(part), "{e:?} lacks {part:?}");
    }
    // Given in the graph, the CRS overrides every header.
    let pts = read_las_node(dir.path().to_path_buf(), Some("EPSG:32618"), &site).unwrap();
    assert_eq!(pts.len(), 3);
    assert_eq!(pts.xyz[2][0], 2.0);
    // Without t3 the two tiles agree.
    std::fs::remove_file(dir.path().join("t3.las")).unwrap();
    let pts = read_las_node(dir.path().to_path_buf(), None, &site).unwrap();
    assert_eq!(pts.xyz.to_vec(), vec![[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]]);
}

#[test]
fn a_folder_without_tiles_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let site = site();
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    std::fs::write(dir.path().join("sub/x.las"), "in a subfolder: not read").unwrap();
    std::fs::write(dir.path().join("notes.txt"), "").unwrap();
    let e = read_las_node(dir.path().to_path_buf(), Some("EPSG:32618"), &site).unwrap_err();
    assert!(e.is_user_error());
    let e = e.to_string();
    assert!(
        e.contains("folder: at least one .las or .laz file directly inside it, found none"),
        "{e}"
    );
}
