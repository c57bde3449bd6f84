//! Raster and orthophoto ingest: files written by GDAL (tests/fixtures, made by
//! scripts/make_geotiff_fixtures.py), our own GeoTIFFs read back, warping, and the real Autzen
//! orthophoto checked against the colours stored in the Autzen LiDAR points.

mod common;
use common::*;

use std::path::PathBuf;

use kodama_nodes::artifact::{Grid, Ortho, PodVec, Raster};
use kodama_nodes::io::crs::{Crs, ToSite};
use kodama_nodes::io::geotiff::{read_geotiff, write_geotiff, write_geotiff_rgb};
use kodama_nodes::io::warp::Resample;
use kodama_nodes::stages::ingest::read_ortho::{ReadOrtho, ReadOrthoParams};
use kodama_nodes::stages::ingest::read_raster::{ReadRaster, ReadRasterParams};
use kodama_nodes::{Ctx, Inputs, Site, Stage};

fn raster_params(path: &str) -> ReadRasterParams {
    ReadRasterParams {
        path: path.into(),
        crs: None,
        band: 1,
        cell_m: None,
        resample: Resample::Bilinear,
        nodata: None,
        window: None,
    }
}

fn read_raster(p: &ReadRasterParams, file: PathBuf, site: &Site) -> Raster {
    let files = [file];
    ReadRaster::run(p, &Inputs::new(), &Ctx::new(site, &files)).unwrap()
}

#[test]
fn gdal_float_dem_with_nodata_on_its_native_grid() {
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let r = read_raster(&raster_params("x"), fixture("gdal_dem_f32.tif"), &site);
    assert_eq!(
        r.grid,
        Grid {
            x0: 0.0,
            y0: 60.0,
            cell_m: 2.0,
            width: 40,
            height: 30
        }
    );
    for row in 0..30 {
        for col in 0..40 {
            let v = r.at(col, row);
            if (col, row) == (3, 4) || (col, row) == (10, 20) {
                assert!(v.is_nan(), "no-data at ({col}, {row})");
            } else {
                assert_eq!(v, 100.0 + 0.5 * col as f32 - 0.25 * row as f32);
            }
        }
    }
}

/// In a tiled run, a tile reads the cells of its window: the cells a `window` param of the same
/// rectangle reads, and within a `window` param, the cells in both.
#[test]
fn a_tile_reads_the_cells_of_its_window() {
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let files = [fixture("gdal_dem_f32.tif")];
    let tile = kodama_nodes::Window {
        min: (9.0, 21.0),
        max: (31.0, 41.0),
    };
    let in_tile = |p: &ReadRasterParams| {
        ReadRaster::run(
            p,
            &Inputs::new(),
            &Ctx::new(&site, &files).with_window(tile),
        )
        .unwrap()
    };
    let by_param = ReadRasterParams {
        window: Some((9.0, 21.0, 31.0, 41.0)),
        ..raster_params("x")
    };
    assert_eq!(
        in_tile(&raster_params("x")),
        read_raster(&by_param, files[0].clone(), &site)
    );
    let both = ReadRasterParams {
        window: Some((0.0, 0.0, 20.0, 30.0)),
        ..raster_params("x")
    };
    let overlap = ReadRasterParams {
        window: Some((9.0, 21.0, 20.0, 30.0)),
        ..raster_params("x")
    };
    assert_eq!(
        in_tile(&both),
        read_raster(&overlap, files[0].clone(), &site)
    );
}

/// A window keeps the cells whose centres fall in it, with the values the whole file has there:
/// on the file's own grid (a cut) and through a warp (a coarser grid, cut after covering).
#[test]
fn a_window_reads_only_the_cells_inside_it() {
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let whole = read_raster(&raster_params("x"), fixture("gdal_dem_f32.tif"), &site);
    let p = ReadRasterParams {
        window: Some((9.0, 21.0, 31.0, 41.0)),
        ..raster_params("x")
    };
    let cut = read_raster(&p, fixture("gdal_dem_f32.tif"), &site);
    // Cells of 2 m from x = 0, y = 60: centres 9..31 in x (12 columns), 41..21 in y (11 rows).
    assert_eq!(
        cut.grid,
        Grid {
            x0: 8.0,
            y0: 42.0,
            cell_m: 2.0,
            width: 12,
            height: 11
        }
    );
    for row in 0..cut.grid.height {
        for col in 0..cut.grid.width {
            let (x, y) = cut.grid.center(col, row);
            let (c, r) = whole.grid.cell_of(x, y).unwrap();
            assert_eq!(cut.at(col, row).to_bits(), whole.at(c, r).to_bits());
        }
    }
    let coarse = ReadRasterParams {
        cell_m: Some(4.0),
        ..p.clone()
    };
    let warped = read_raster(&coarse, fixture("gdal_dem_f32.tif"), &site);
    let (x1, y1) = (
        warped.grid.x0 + warped.grid.width as f64 * 4.0,
        warped.grid.y0 - warped.grid.height as f64 * 4.0,
    );
    assert!(
        warped.grid.x0 >= 9.0 - 2.0 && x1 <= 31.0 + 2.0,
        "{:?}",
        warped.grid
    );
    assert!(
        y1 >= 21.0 - 2.0 && warped.grid.y0 <= 41.0 + 2.0,
        "{:?}",
        warped.grid
    );
    assert!(!warped.grid.is_empty());
    // A window off the file is an error naming it and the file's extent.
    let off = ReadRasterParams {
        window: Some((500.0, 500.0, 600.0, 600.0)),
        ..raster_params("x")
    };
    let files = [fixture("gdal_dem_f32.tif")];
    let e = ReadRaster::run(&off, &Inputs::new(), &Ctx::new(&site, &files)).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("gdal_dem_f32.tif")
            && msg.contains("does not overlap the file, which covers x 0.0 to 80.0, y 0.0 to 60.0"),
        "{msg}"
    );
    // A window upside down is refused as a param.
    let bad = ReadRasterParams {
        window: Some((10.0, 0.0, 5.0, 1.0)),
        ..raster_params("x")
    };
    assert!(ReadRaster::validate(&bad).is_err());
}

#[test]
fn gdal_tiled_lzw_uint16() {
    let site = Site {
        crs: "EPSG:28992".into(),
        origin: (84800.0, 447600.0),
        cell_m: 0.5,
    };
    let r = read_raster(&raster_params("x"), fixture("gdal_u16_tiled.tif"), &site);
    assert_eq!(
        r.grid,
        Grid {
            x0: 0.0,
            y0: 50.0,
            cell_m: 0.5,
            width: 64,
            height: 48
        }
    );
    assert!((0..48).all(|row| (0..64).all(|col| r.at(col, row) == (7 * col + 3 * row) as f32)));
}

#[test]
fn gdal_rgb_orthophoto() {
    gdal_rgb_orthophoto_in(None, (10.0, 50.0, 20, 10), (0, 0));
    // The same image cut to a window: the pixels inside it, the same colours.
    gdal_rgb_orthophoto_in(Some((14.2, 43.0, 19.9, 47.6)), (14.0, 48.0, 6, 5), (4, 2));
}

/// Reads the GDAL orthophoto (20 x 10 pixels of 1 m from x 10, y 50; red 10 per column, green 20
/// per row) through `window`, expecting the grid (x0, y0, width, height) starting at pixel `first`.
fn gdal_rgb_orthophoto_in(
    window: Option<(f64, f64, f64, f64)>,
    (x0, y0, width, height): (f64, f64, u32, u32),
    first: (usize, usize),
) {
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let p = ReadOrthoParams {
        path: "o.tif".into(),
        world_file: None,
        crs: None,
        cell_m: None,
        window,
    };
    let files = [fixture("gdal_ortho_rgb.tif")];
    let o: Ortho = ReadOrtho::run(&p, &Inputs::new(), &Ctx::new(&site, &files)).unwrap();
    assert_eq!(
        o.grid,
        Grid {
            x0,
            y0,
            cell_m: 1.0,
            width,
            height
        }
    );
    let w = width as usize;
    for row in 0..height as usize {
        for col in 0..w {
            let (c, r) = (first.0 + col, first.1 + row);
            assert_eq!(o.rgb[row * w + col], [10 * c as u8, 20 * r as u8, 7]);
        }
    }
}

#[test]
fn our_geotiffs_read_back_with_identical_georeferencing() {
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (583200.0, 4506600.0),
        cell_m: 0.5,
    };
    let grid = Grid {
        x0: 12.5,
        y0: 80.0,
        cell_m: 0.5,
        width: 7,
        height: 5,
    };
    let data: Vec<f32> = (0..35)
        .map(|i| {
            if i == 9 {
                f32::NAN
            } else {
                i as f32 * 0.25 - 3.0
            }
        })
        .collect();
    let raster = Raster {
        grid,
        data: PodVec(data),
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.tif");
    let mut f = std::fs::File::create(&path).unwrap();
    write_geotiff(&raster, &site, &mut f).unwrap();
    drop(f);
    let tif = read_geotiff(&path).unwrap();
    assert_eq!(tif.crs, Some(Crs::from_epsg(32618).unwrap()));
    assert_eq!(
        (
            tif.pixels.west,
            tif.pixels.north,
            tif.pixels.dx,
            tif.pixels.dy
        ),
        (583212.5, 4506680.0, 0.5, 0.5)
    );
    let back = read_raster(&raster_params("r.tif"), path, &site);
    assert_eq!(back.grid, grid);
    assert!(
        back.data
            .iter()
            .zip(raster.data.iter())
            .all(|(a, b)| a == b || (a.is_nan() && b.is_nan()))
    );

    let rgb: Vec<[u8; 3]> = (0..35)
        .map(|i| [i as u8, 2 * i as u8, 255 - i as u8])
        .collect();
    let path = dir.path().join("o.tif");
    let mut f = std::fs::File::create(&path).unwrap();
    write_geotiff_rgb(&rgb, &grid, &site, &mut f).unwrap();
    drop(f);
    let p = ReadOrthoParams {
        path: "o.tif".into(),
        world_file: None,
        crs: None,
        cell_m: None,
        window: None,
    };
    let files = [path];
    let o = ReadOrtho::run(&p, &Inputs::new(), &Ctx::new(&site, &files)).unwrap();
    assert_eq!((o.grid, o.rgb.0), (grid, rgb));
}

#[test]
fn tiff_without_georeferencing_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.tif");
    let mut f = std::fs::File::create(&path).unwrap();
    let mut enc = tiff::encoder::TiffEncoder::new(&mut f).unwrap();
    enc.write_image::<tiff::encoder::colortype::Gray32Float>(2, 2, &[1.0, 2.0, 3.0, 4.0])
        .unwrap();
    drop(f);
    let site = Site {
        crs: "EPSG:32618".into(),
        origin: (0.0, 0.0),
        cell_m: 1.0,
    };
    let files = [path];
    let e = ReadRaster::run(
        &raster_params("plain.tif"),
        &Inputs::new(),
        &Ctx::new(&site, &files),
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("plain.tif: georeferencing: no ModelTiepoint"),
        "{e}"
    );
    assert!(e.is_user_error());
}

/// Resampling onto another CRS: the lattice-interpolated mapping against an exact per-cell
/// reprojection of the same plane.
#[test]
fn warp_into_another_utm_zone_matches_exact_reprojection() {
    let site = Site {
        crs: "EPSG:32617".into(),
        origin: (1_090_000.0, 4_514_000.0),
        cell_m: 1.0,
    };
    let p = ReadRasterParams {
        cell_m: Some(1.0),
        ..raster_params("x")
    };
    let r = read_raster(&p, fixture("gdal_dem_f32.tif"), &site);
    let exact = ToSite::new(&Crs::from_epsg(32618).unwrap(), &site).unwrap();
    let mut checked = 0;
    for row in 0..r.grid.height {
        for col in 0..r.grid.width {
            let v = r.at(col, row);
            if !v.is_finite() {
                continue;
            }
            let (x, y) = r.grid.center(col, row);
            let (e, n) = exact.inverse(x, y).unwrap();
            let (u, w) = ((e - 583200.0) / 2.0, (4506660.0 - n) / 2.0);
            // Inside the plane region, away from the border and the two no-data pixels.
            if !(1.0..38.0).contains(&u)
                || !(1.0..28.0).contains(&w)
                || ((u - 3.5).abs() < 2.0 && (w - 4.5).abs() < 2.0)
                || ((u - 10.5).abs() < 2.0 && (w - 20.5).abs() < 2.0)
            {
                continue;
            }
            let expected = 100.0 + 0.5 * (u - 0.5) - 0.25 * (w - 0.5);
            assert!(
                (v as f64 - expected).abs() < 2e-3,
                "({col}, {row}): {v} vs {expected}"
            );
            checked += 1;
        }
    }
    assert!(checked > 3000, "{checked}");
}

/// Autzen's LiDAR points carry RGB sampled from an orthophoto of the same area. Reading the JPEG +
/// world file (EPSG:2994) and the LAS (user-defined keys) into one UTM site, each point must find
/// its own colour in the orthophoto; a 10 m misregistration must not.
#[test]
fn autzen_orthophoto_registers_with_the_lidar_colours() {
    let site = Site {
        crs: "EPSG:3740".into(),
        origin: (494000.0, 4877000.0),
        cell_m: 0.5,
    };
    let p = ReadOrthoParams {
        path: "autzen.jpg".into(),
        world_file: None,
        crs: Some("EPSG:2994".into()),
        cell_m: Some(0.5),
        window: None,
    };
    let files = [shared("autzen/autzen.jpg"), shared("autzen/autzen.wld")];
    let o = ReadOrtho::run(&p, &Inputs::new(), &Ctx::new(&site, &files)).unwrap();
    let pts = kodama_nodes::stages::ingest::read_las::read_las(
        &shared("autzen/autzen_trim.las"),
        None,
        &Ctx::new(&site, &[]),
    )
    .unwrap();
    let mean_diff = |dx: f64| {
        let (mut sum, mut n) = (0.0, 0usize);
        for (q, c) in pts.xyz.iter().zip(pts.rgb.iter()).step_by(7) {
            let Some((col, row)) = o.grid.cell_of(q[0] as f64 + dx, q[1] as f64) else {
                continue;
            };
            let i = row as usize * o.grid.width as usize + col as usize;
            if o.valid[i] == 0 {
                continue;
            }
            let px = o.rgb[i];
            sum += (0..3)
                .map(|k| (px[k] as f64 - (c[k] >> 8) as f64).abs())
                .sum::<f64>()
                / 3.0;
            n += 1;
        }
        assert!(n > 10_000, "{n} points inside the orthophoto");
        sum / n as f64
    };
    let registered = mean_diff(0.0);
    let shifted = mean_diff(10.0);
    println!(
        "autzen: mean |RGB difference| {registered:.1} registered, {shifted:.1} with a 10 m shift"
    );
    assert!(
        registered < 5.0 && registered < 0.3 * shifted,
        "{registered} vs {shifted}"
    );
}

/// An SRTM tile of `side` x `side` posts: `height(row, col)` big-endian, rows from the north.
fn write_hgt(path: &std::path::Path, side: usize, height: impl Fn(usize, usize) -> i16) {
    let mut bytes = Vec::with_capacity(2 * side * side);
    for row in 0..side {
        for col in 0..side {
            bytes.extend(height(row, col).to_be_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A synthetic 3 arc-second tile N40W075 whose heights are linear in latitude and longitude
/// (whole metres at every post, so bilinear reading reproduces the plane exactly), read into
/// the test site on 90 m cells. Cells are checked against the plane at the latitude and
/// longitude PROJ gives for their centres (tests/fixtures/hgt_reference.csv, made by
/// scripts/hgt_reference.py): a tile placed half a post off, flipped, or read little-endian
/// misses by metres. A block of void posts becomes NaN, and only around it.
#[test]
fn srtm_hgt_tile_reads_into_the_site() {
    // h = 100 + 1200 (lat - 40) + 2400 (lon + 75): post (row, col) is at lat 41 - row/1200,
    // lon -75 + col/1200.
    let plane = |lat: f64, lon: f64| 100.0 + 1200.0 * (lat - 40.0) + 2400.0 * (lon + 75.0);
    let post = |row: usize, col: usize| 100 + 1200 - row as i16 + 2 * col as i16;
    let void = |row: usize, col: usize| (600..610).contains(&row) && (300..310).contains(&col);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("N40W075.hgt");
    write_hgt(
        &path,
        1201,
        |r, c| if void(r, c) { -32768 } else { post(r, c) },
    );
    let site = site();
    let mut p = raster_params("N40W075.hgt");
    p.cell_m = Some(90.0);
    let r = read_raster(&p, path, &site);
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/fixtures/hgt_reference.csv"),
    )
    .unwrap();
    let mut worst: f64 = 0.0;
    for line in text.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|f| f.parse().unwrap()).collect();
        let (x, y, lat, lon) = (v[0], v[1], v[2], v[3]);
        let (col, row) = r.grid.cell_of(x, y).expect("inside the tile");
        let c = r.grid.center(col, row);
        assert!(
            (c.0 - x).abs() < 1e-6 && (c.1 - y).abs() < 1e-6,
            "{c:?} is not ({x}, {y})"
        );
        let got = r.at(col, row) as f64;
        let want = plane(lat, lon);
        assert!(
            (got - want).abs() < 0.02,
            "({x}, {y}): {got} m, the plane {want} m"
        );
        worst = worst.max((got - want).abs());
    }
    println!("worst difference from the plane: {worst:.4} m");
    // The void: 10 x 10 posts at lat 40.5, lon -74.75; with the bilinear reading's one-post
    // margin, 11 x 11 posts of 3" (1.02 x 0.78 km, 0.79 km2) in 90 m cells.
    let wgs = ToSite::new(&Crs::from_epsg(4326).unwrap(), &site).unwrap();
    let posts = |c: u32, rw: u32| {
        let (x, y) = r.grid.center(c, rw);
        let (lon, lat) = wgs.inverse(x, y).unwrap();
        ((41.0 - lat) * 1200.0, (lon + 75.0) * 1200.0)
    };
    // NaN cells inside the tile, away from its edges (the grid's corners lie outside it).
    let nan: Vec<(f64, f64)> = (0..r.grid.height)
        .flat_map(|row| (0..r.grid.width).map(move |col| (col, row)))
        .filter(|&(c, rw)| r.at(c, rw).is_nan())
        .map(|(c, rw)| posts(c, rw))
        .filter(|&(row, col)| (2.0..1198.0).contains(&row) && (2.0..1198.0).contains(&col))
        .collect();
    assert!(!nan.is_empty(), "the void cells were read as heights");
    for &(row, col) in &nan {
        assert!(
            (598.5..611.5).contains(&row) && (298.5..311.5).contains(&col),
            "NaN at post ({row:.1}, {col:.1}), away from the void"
        );
    }
    let area = nan.len() as f64 * 90.0 * 90.0;
    assert!((0.5e6..1.1e6).contains(&area), "{} NaN cells", nan.len());
}

/// A 1 arc-second tile: posts every 1/3600 degree, the same plane read back at the PROJ points.
#[test]
fn srtm_one_arc_second_tile() {
    let plane = |lat: f64, lon: f64| 100.0 + 3600.0 * (lat - 40.0) + 3600.0 * (lon + 75.0);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("N40W075.hgt");
    write_hgt(&path, 3601, |r, c| (100 + 3600 - r + c) as i16);
    let mut p = raster_params("N40W075.hgt");
    p.cell_m = Some(90.0);
    let r = read_raster(&p, path, &site());
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/fixtures/hgt_reference.csv"),
    )
    .unwrap();
    for line in text.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|f| f.parse().unwrap()).collect();
        let (col, row) = r.grid.cell_of(v[0], v[1]).unwrap();
        let (got, want) = (r.at(col, row) as f64, plane(v[2], v[3]));
        assert!(
            (got - want).abs() < 0.05,
            "({}, {}): {got} vs {want}",
            v[0],
            v[1]
        );
    }
}
