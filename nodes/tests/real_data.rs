//! Ingest of the real files in ../shared/data, read in place, checked against independent
//! references: published counts, the files' own headers, and PROJ (tests/fixtures, made by
//! scripts/crs_reference.py).

mod common;
use common::*;

use kodama_nodes::io::crs::{Crs, ToSite};
use kodama_nodes::stages::ingest::read_las::{header_crs, read_las};
use kodama_nodes::{Ctx, Site};

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
