//! Measurement ingest: the real Duke CBRS drive test, the project's CSV layout, and its errors.

mod common;
use common::*;

use std::path::PathBuf;

use kodama_nodes::artifact::{Height, Measurements};
use kodama_nodes::stages::ingest::read_measurements::{
    Layout, ReadMeasurements, ReadMeasurementsParams,
};
use kodama_nodes::{Artifact, Ctx, Inputs, Site, Stage};

fn read(
    layout: Layout,
    files: &[PathBuf],
    site: &Site,
) -> Result<Measurements, kodama_nodes::StageError> {
    let p = ReadMeasurementsParams {
        path: "m.csv".into(),
        layout,
    };
    ReadMeasurements::run(&p, &Inputs::new(), &Ctx::new(site, files))
}

fn durham() -> Site {
    // UTM 17N, origin near the Duke campus.
    Site {
        crs: "EPSG:32617".into(),
        origin: (687000.0, 3985000.0),
        cell_m: 1.0,
    }
}

#[test]
fn duke_cbrs_drive_test() {
    let layout = Layout::DukeCbrs {
        cells: "cells.json".into(),
        tx_height_m: 20.0,
        tx_heights_m: [("E".to_string(), 15.0), ("F".to_string(), 15.0)].into(),
        rx_height_m: 1.5,
    };
    let m = read(
        layout,
        &[shared("rf/duke_cbrs.csv"), shared("rf/duke_cells.json")],
        &durham(),
    )
    .unwrap();
    // 46,655 rows, as Python's csv module also counts. (The data README says 46,654: the file has
    // no final newline, so `wc -l` minus the header comes out one short.)
    assert_eq!(m.links.len(), 46_655);
    for (pci, n, freq) in [
        ("A", 3491, 3.69e9),
        ("B", 2363, 3.64e9),
        ("C", 8256, 3.58e9),
        ("D", 6953, 3.56e9),
        ("E", 14683, 3.69e9),
        ("F", 10909, 3.64e9),
    ] {
        let links: Vec<_> = m.links.iter().filter(|l| l.tx.id == pci).collect();
        assert_eq!(links.len(), n, "cell {pci}");
        assert!(
            links
                .iter()
                .all(|l| l.freq_hz == freq && l.tx_eirp_dbm.is_none() && l.rx_power_dbm.is_some())
        );
    }
    // Receivers lie within a campus-sized distance of their cell, on the ground plus 1.5 m.
    let max_d = m
        .links
        .iter()
        .map(|l| ((l.rx.x - l.tx.x).powi(2) + (l.rx.y - l.tx.y).powi(2)).sqrt())
        .fold(0.0, f64::max);
    assert!(max_d > 100.0 && max_d < 3000.0, "{max_d}");
    assert_eq!(m.links[0].rx.z, Height::AboveGround(1.5));
    assert_eq!(m.links[0].rx_power_dbm, Some(-124.0));
    // The cells' true bearings become grid bearings: less the meridian convergence at the site,
    // 1.211° at A-D (pyproj's `get_factors`), 1.213° at E/F.
    for (pci, true_deg, gamma) in [
        ("A", 212.0, 1.2113),
        ("C", 30.0, 1.2113),
        ("E", 216.0, 1.2130),
    ] {
        let l = m.links.iter().find(|l| l.tx.id == pci).unwrap();
        let grid = l.tx.azimuth_deg.unwrap();
        assert!((grid - (true_deg - gamma)).abs() < 1e-3, "{pci}: {grid}");
    }
    // Heights by cell override the one for all.
    for l in &m.links {
        let want = if l.tx.id == "E" || l.tx.id == "F" {
            15.0
        } else {
            20.0
        };
        assert_eq!(l.tx.z, Height::AboveGround(want), "cell {}", l.tx.id);
    }
}

/// A height for a cell the file does not have is a typo, said as such.
#[test]
fn duke_heights_for_an_unknown_cell_are_refused() {
    let layout = Layout::DukeCbrs {
        cells: "cells.json".into(),
        tx_height_m: 20.0,
        tx_heights_m: [("G".to_string(), 15.0)].into(),
        rx_height_m: 1.5,
    };
    let Err(e) = read(
        layout,
        &[shared("rf/duke_cbrs.csv"), shared("rf/duke_cells.json")],
        &durham(),
    ) else {
        panic!("a height for cell G was accepted");
    };
    assert!(format!("{e}").contains("\"G\""), "{e}");
}

#[test]
fn links_layout_in_site_and_geographic_coordinates_round_trips_through_export() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("m.csv");
    std::fs::write(
        &csv,
        "tx_id,tx_lat,tx_lon,tx_height_m,tx_azimuth_deg,rx_x,rx_y,rx_z,freq_hz,rx_power_dbm,tx_eirp_dbm,los\n\
         A,35.9992,-78.9398,25,0.5,10.5,-20.25,101.5,3.5e9,-80.5,46,1\n\
         A,35.9992,-78.9398,25,,30,40,99,3.5e9,-95,46,0\n",
    )
    .unwrap();
    let site = durham();
    let m = read(Layout::Links, &[csv], &site).unwrap();
    assert_eq!(m.links.len(), 2);
    let l = &m.links[0];
    assert_eq!(
        (l.tx.id.as_str(), l.tx.z, l.rx.z),
        ("A", Height::AboveGround(25.0), Height::Absolute(101.5))
    );
    assert_eq!(
        (
            l.rx.x,
            l.rx.y,
            l.freq_hz,
            l.rx_power_dbm,
            l.tx_eirp_dbm,
            l.los
        ),
        (10.5, -20.25, 3.5e9, Some(-80.5), Some(46.0), Some(true))
    );
    // Beside a latitude and longitude the bearing is true: less 1.211° of convergence, it is a
    // grid bearing, wrapped into [0, 360).
    let grid = l.tx.azimuth_deg.unwrap();
    assert!((grid - (360.0 + 0.5 - 1.2113)).abs() < 1e-3, "{grid}");
    assert_eq!(m.links[1].tx.azimuth_deg, None);
    assert_eq!(
        kodama_nodes::io::export::formats(kodama_nodes::ArtifactType::Measurements),
        ["csv"]
    );
    let kodama_nodes::io::export::Encoded::File(bytes) =
        kodama_nodes::io::export::encode(&Artifact::Measurements(m.clone()), &site, "csv").unwrap()
    else {
        panic!("a file")
    };
    // Beside the site frame, each end's WGS 84 position for a GIS: the transmitter's is the
    // latitude and longitude it was read from.
    let text = String::from_utf8(bytes.clone()).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let row: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let col = |name: &str| -> f64 {
        let k = header.iter().position(|h| *h == name).unwrap();
        row[k].parse().unwrap()
    };
    assert!((col("tx_lat") - 35.9992).abs() < 1e-7, "{}", col("tx_lat"));
    assert!((col("tx_lon") + 78.9398).abs() < 1e-7, "{}", col("tx_lon"));
    let again = dir.path().join("again.csv");
    std::fs::write(&again, bytes).unwrap();
    let back = read(Layout::Links, &[again], &site).unwrap();
    assert_eq!(back.links.len(), 2);
    for (a, b) in back.links.iter().zip(&m.links) {
        assert!(
            (a.tx.x - b.tx.x).abs() < 1e-3 && (a.tx.y - b.tx.y).abs() < 1e-3,
            "site-frame coordinates to the millimetre"
        );
        assert_eq!(
            (a.tx.z, a.rx.z, a.rx_power_dbm, a.los),
            (b.tx.z, b.rx.z, b.rx_power_dbm, b.los)
        );
        // Export writes the grid bearing beside site coordinates, read back as it is.
        assert_eq!(a.tx.azimuth_deg, b.tx.azimuth_deg);
    }
}

#[test]
fn csv_errors_name_the_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("m.csv");
    std::fs::write(
        &csv,
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,path_loss_db\n0,0,10,5,5,1.5,80\n",
    )
    .unwrap();
    let e = read(Layout::Links, std::slice::from_ref(&csv), &durham()).unwrap_err();
    assert!(
        e.to_string()
            .contains("m.csv: header: expected a column `freq_hz`; found: tx_x, tx_y"),
        "{e}"
    );
    std::fs::write(&csv, "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,freq_hz,path_loss_db\n0,0,10,5,5,1.5,3e9,80\n0,0,10,5,x5,1.5,3e9,80\n").unwrap();
    let e = read(Layout::Links, std::slice::from_ref(&csv), &durham()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: line 3, column `rx_y`: expected a number, found \"x5\"",
            csv.display()
        )
    );
    std::fs::write(
        &csv,
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,freq_hz\n0,0,10,5,5,1.5,3e9\n",
    )
    .unwrap();
    let e = read(Layout::Links, &[csv], &durham()).unwrap_err();
    assert!(
        e.to_string()
            .contains("expected a column `path_loss_db` or `rx_power_dbm`"),
        "{e}"
    );
}
