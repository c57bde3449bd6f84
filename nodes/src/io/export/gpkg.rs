//! Footprints as an OGC GeoPackage 1.4 (<https://www.geopackage.org/spec140/>): the one-file
//! vector format QGIS, GDAL/OGR, ArcGIS and GeoPandas open natively, with the CRS inside.
//!
//! A SQLite database (built in memory by the bundled SQLite, then serialized) holding the three
//! required metadata tables and one feature table, `footprints`: a `MULTIPOLYGON` column `geom`
//! in the site's CRS (its WKT from the EPSG definitions we ship) and the GeoJSON export's
//! attributes. Geometries are GeoPackage binary: the `GP` header with the XY envelope, then
//! little-endian WKB. Coordinates are rounded to the millimetre, as the GeoJSON's. The contents'
//! `last_change` is the Unix epoch, not the time of writing, so the same footprints give the same
//! bytes (the output invariant of DESIGN.md).

use rusqlite::{Connection, params};

use crate::artifact::{Footprints, Polygon};
use crate::io::geojson::round_mm;
use crate::site::Site;

/// The feature table's name.
const TABLE: &str = "footprints";

/// A fixed `last_change` (module docs).
const EPOCH: &str = "1970-01-01T00:00:00.000Z";

/// SQLite's `application_id` for a GeoPackage ("GPKG") and the version in `user_version`.
const APPLICATION_ID: i32 = 0x4750_4B47;
const USER_VERSION: i32 = 10400;

/// One polygon's rings in CRS coordinates, closed, mm-rounded.
fn rings(p: &Polygon, origin: (f64, f64)) -> Vec<Vec<[f64; 2]>> {
    std::iter::once(&p.exterior)
        .chain(&p.holes)
        .map(|r| {
            let mut pts: Vec<[f64; 2]> = r
                .iter()
                .map(|q| [round_mm(q[0] + origin.0), round_mm(q[1] + origin.1)])
                .collect();
            if let Some(&first) = pts.first() {
                pts.push(first);
            }
            pts
        })
        .collect()
}

/// A multipolygon as GeoPackage binary (module docs) and its envelope, `None` when empty.
fn geometry_blob(polygons: &[Vec<Vec<[f64; 2]>>], srs_id: i32) -> (Vec<u8>, Option<[f64; 4]>) {
    let mut env = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in polygons.iter().flatten().flatten() {
        env = [
            env[0].min(p[0]),
            env[1].max(p[0]),
            env[2].min(p[1]),
            env[3].max(p[1]),
        ];
    }
    let envelope = env[0].is_finite().then_some(env);
    let mut b = Vec::new();
    b.extend_from_slice(b"GP");
    b.push(0); // version 1 of the binary format
    // Bit 0: little-endian; bits 1-3: envelope [minx, maxx, miny, maxy] (1) or none (0);
    // bit 4: empty geometry.
    b.push(match envelope {
        Some(_) => 0b0000_0011,
        None => 0b0001_0001,
    });
    b.extend_from_slice(&srs_id.to_le_bytes());
    for v in envelope.iter().flatten() {
        b.extend_from_slice(&v.to_le_bytes());
    }
    // WKB MultiPolygon (6) of Polygons (3).
    b.push(1);
    b.extend_from_slice(&6u32.to_le_bytes());
    b.extend_from_slice(&(polygons.len() as u32).to_le_bytes());
    for poly in polygons {
        b.push(1);
        b.extend_from_slice(&3u32.to_le_bytes());
        b.extend_from_slice(&(poly.len() as u32).to_le_bytes());
        for ring in poly {
            b.extend_from_slice(&(ring.len() as u32).to_le_bytes());
            for p in ring {
                b.extend_from_slice(&p[0].to_le_bytes());
                b.extend_from_slice(&p[1].to_le_bytes());
            }
        }
    }
    (b, envelope)
}

/// The spatial reference systems a GeoPackage must hold (-1, 0, WGS 84) and the site's.
fn spatial_ref_sys(site: &Site, epsg: u16) -> Result<Vec<(String, i32, String, String)>, String> {
    let wkt = |code: u16| {
        crs_definitions::from_code(code)
            .map(|d| d.wkt.to_string())
            .ok_or_else(|| format!("EPSG:{code} has no WKT definition"))
    };
    let mut rows = vec![
        (
            "Undefined cartesian SRS".to_string(),
            -1,
            "NONE".to_string(),
            "undefined".to_string(),
        ),
        (
            "Undefined geographic SRS".to_string(),
            0,
            "NONE".to_string(),
            "undefined".to_string(),
        ),
        (
            "WGS 84 geodetic".to_string(),
            4326,
            "EPSG".to_string(),
            wkt(4326)?,
        ),
    ];
    if epsg != 4326 {
        rows.push((
            site.crs.clone(),
            epsg as i32,
            "EPSG".to_string(),
            wkt(epsg)?,
        ));
    }
    Ok(rows)
}

/// `f` as a GeoPackage file (module docs).
pub fn write_gpkg(f: &Footprints, site: &Site) -> Result<Vec<u8>, String> {
    let epsg = site.epsg()?;
    let srs_id = epsg as i32;
    let sql = |e: rusqlite::Error| format!("GeoPackage: {e}");
    let mut db = Connection::open_in_memory().map_err(sql)?;
    db.execute_batch(&format!(
        "PRAGMA application_id = {APPLICATION_ID}; PRAGMA user_version = {USER_VERSION};
         CREATE TABLE gpkg_spatial_ref_sys (
           srs_name TEXT NOT NULL, srs_id INTEGER NOT NULL PRIMARY KEY,
           organization TEXT NOT NULL, organization_coordsys_id INTEGER NOT NULL,
           definition TEXT NOT NULL, description TEXT);
         CREATE TABLE gpkg_contents (
           table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL,
           identifier TEXT UNIQUE, description TEXT DEFAULT '',
           last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
           min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER,
           CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id));
         CREATE TABLE gpkg_geometry_columns (
           table_name TEXT NOT NULL, column_name TEXT NOT NULL,
           geometry_type_name TEXT NOT NULL, srs_id INTEGER NOT NULL,
           z TINYINT NOT NULL, m TINYINT NOT NULL,
           CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name),
           CONSTRAINT uk_gc_table_name UNIQUE (table_name),
           CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name),
           CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id));
         CREATE TABLE \"{TABLE}\" (
           fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom MULTIPOLYGON,
           id TEXT NOT NULL, height_m DOUBLE, min_height_m DOUBLE, levels DOUBLE,
           min_level DOUBLE, area_m2 DOUBLE);"
    ))
    .map_err(sql)?;
    let tx = db.transaction().map_err(sql)?;
    for (name, id, org, def) in spatial_ref_sys(site, epsg)? {
        tx.execute(
            "INSERT INTO gpkg_spatial_ref_sys VALUES (?1, ?2, ?3, ?2, ?4, NULL)",
            params![name, id, org, def],
        )
        .map_err(sql)?;
    }
    let mut extent = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    {
        let mut insert = tx
            .prepare(&format!(
                "INSERT INTO \"{TABLE}\" (geom, id, height_m, min_height_m, levels, min_level, \
                 area_m2) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)"
            ))
            .map_err(sql)?;
        for b in &f.items {
            let polys: Vec<_> = b.polygons.iter().map(|p| rings(p, site.origin)).collect();
            let (blob, env) = geometry_blob(&polys, srs_id);
            if let Some(e) = env {
                extent = [
                    extent[0].min(e[0]),
                    extent[1].max(e[1]),
                    extent[2].min(e[2]),
                    extent[3].max(e[3]),
                ];
            }
            let area = (b.polygons.iter().map(Polygon::area).sum::<f64>() * 100.0).round() / 100.0;
            insert
                .execute(params![
                    blob,
                    b.id,
                    b.height_m,
                    b.min_height_m,
                    b.levels,
                    b.min_level,
                    area
                ])
                .map_err(sql)?;
        }
    }
    let bounds: [Option<f64>; 4] = if extent[0].is_finite() {
        [
            Some(extent[0]),
            Some(extent[2]),
            Some(extent[1]),
            Some(extent[3]),
        ]
    } else {
        [None; 4]
    };
    tx.execute(
        "INSERT INTO gpkg_contents VALUES (?1, 'features', ?1, 'building footprints', ?2, ?3, ?4, \
         ?5, ?6, ?7)",
        params![
            TABLE, EPOCH, bounds[0], bounds[1], bounds[2], bounds[3], srs_id
        ],
    )
    .map_err(sql)?;
    tx.execute(
        "INSERT INTO gpkg_geometry_columns VALUES (?1, 'geom', 'MULTIPOLYGON', ?2, 0, 0)",
        params![TABLE, srs_id],
    )
    .map_err(sql)?;
    tx.commit().map_err(sql)?;
    let bytes = db.serialize(rusqlite::MAIN_DB).map_err(sql)?;
    Ok(bytes.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Footprint;

    fn footprints() -> Footprints {
        let square = |x: f64, y: f64, s: f64| vec![[x, y], [x + s, y], [x + s, y + s], [x, y + s]];
        Footprints {
            items: vec![
                Footprint {
                    id: "b1".into(),
                    polygons: vec![Polygon {
                        exterior: square(0.0, 0.0, 20.0),
                        // Holes run clockwise, as the artifact's rings do.
                        holes: vec![square(5.0, 5.0, 4.0).into_iter().rev().collect()],
                    }],
                    height_m: Some(12.5),
                    min_height_m: None,
                    levels: Some(4.0),
                    min_level: None,
                },
                Footprint {
                    id: "b2".into(),
                    polygons: vec![
                        Polygon {
                            exterior: square(40.0, 0.0, 10.0),
                            holes: vec![],
                        },
                        Polygon {
                            exterior: square(60.0, 0.0, 5.0),
                            holes: vec![],
                        },
                    ],
                    height_m: None,
                    min_height_m: None,
                    levels: None,
                    min_level: None,
                },
            ],
        }
    }

    fn site() -> Site {
        Site {
            crs: "EPSG:32618".into(),
            origin: (583_200.0, 4_506_600.0),
            cell_m: 0.5,
        }
    }

    #[test]
    fn the_file_is_a_geopackage_sqlite_reads_back() {
        let bytes = write_gpkg(&footprints(), &site()).unwrap();
        assert_eq!(&bytes[..16], b"SQLite format 3\0");
        // application_id at byte 68, user_version at 60 (big-endian), as the spec requires.
        assert_eq!(&bytes[68..72], b"GPKG");
        assert_eq!(i32::from_be_bytes(bytes[60..64].try_into().unwrap()), 10400);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.gpkg");
        std::fs::write(&path, &bytes).unwrap();
        let db = Connection::open(&path).unwrap();
        let ok: String = db
            .query_row("PRAGMA integrity_check", [], |r| r.get(0))
            .unwrap();
        assert_eq!(ok, "ok");
        let (n, srs): (i64, i64) = db
            .query_row(
                "SELECT count(*), (SELECT srs_id FROM gpkg_geometry_columns) FROM footprints",
                [],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .unwrap();
        assert_eq!((n, srs), (2, 32618));
        let (blob, area): (Vec<u8>, f64) = db
            .query_row(
                "SELECT geom, area_m2 FROM footprints WHERE id = 'b1'",
                [],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .unwrap();
        assert_eq!(area, 400.0 - 16.0);
        assert_eq!(&blob[..4], b"GP\0\x03");
        assert_eq!(i32::from_le_bytes(blob[4..8].try_into().unwrap()), 32618);
        let env: Vec<f64> = (0..4)
            .map(|k| f64::from_le_bytes(blob[8 + 8 * k..16 + 8 * k].try_into().unwrap()))
            .collect();
        assert_eq!(env, [583_200.0, 583_220.0, 4_506_600.0, 4_506_620.0]);
        // WKB: little-endian MultiPolygon of one polygon with two closed rings of 5 points.
        let wkb = &blob[40..];
        assert_eq!(wkb[0], 1);
        assert_eq!(u32::from_le_bytes(wkb[1..5].try_into().unwrap()), 6);
        assert_eq!(u32::from_le_bytes(wkb[5..9].try_into().unwrap()), 1);
        assert_eq!(u32::from_le_bytes(wkb[14..18].try_into().unwrap()), 2);
        assert_eq!(u32::from_le_bytes(wkb[18..22].try_into().unwrap()), 5);
        let def: String = db
            .query_row(
                "SELECT definition FROM gpkg_spatial_ref_sys WHERE srs_id = 32618",
                [],
                |r| r.get(0),
            )
            .unwrap();
        assert!(def.contains("UTM zone 18N"), "{def}");
    }

    #[test]
    fn the_same_footprints_give_the_same_bytes() {
        let a = write_gpkg(&footprints(), &site()).unwrap();
        let b = write_gpkg(&footprints(), &site()).unwrap();
        assert_eq!(a, b);
    }
}
