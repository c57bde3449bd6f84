//! Ingest of ASPRS LAS/LAZ point clouds (paper Sec. 4: airborne LiDAR) into the site frame: one
//! file, or a folder of tiles read as one cloud.

use std::path::{Path, PathBuf};

use las::Reader;
use serde::{Deserialize, Serialize};

use crate::artifact::PointSet;
use crate::io::crs::{Crs, ToSite, parse_geokeys};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadLas`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadLasParams {
    /// The `.las` or `.laz` file, or a folder of tiles: every `*.las`/`*.laz` directly inside it
    /// (not in subfolders), in file-name order, concatenated into one cloud. The whole folder is
    /// then the node's input: any file added, removed or changed in it reruns the node.
    pub path: String,
    /// The file's CRS (`"EPSG:<code>"` or a `+proj` string). Needed when the header carries none;
    /// when given, it overrides the header (of every tile). Default: from the header; the tiles
    /// of a folder must then all record the same CRS.
    #[serde(default)]
    pub crs: Option<String>,
}

/// Reads a LAS/LAZ file, or a folder of tiles as one cloud: positions reprojected into the site
/// frame, with class, intensity, return numbers and RGB when the point format has them (for a
/// folder, when every tile's does).
pub struct ReadLas;

impl Stage for ReadLas {
    const KIND: &'static str = "ReadLas";
    const VERSION: u32 = 2;
    const DOC: &'static str = "LAS/LAZ point cloud, one file or a folder of tiles (CRS from header or graph) into the site frame, Sec. 4";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadLasParams;
    type Output = PointSet;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::crs::check_crs_param(&p.crs)?;
        Ok(())
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }]
    }

    // A tile of a tiled run keeps the points in its window.
    const WINDOWED: bool = true;

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<PointSet, StageError> {
        let path = ctx.file(0)?;
        let points = if path.is_dir() {
            read_las_folder(path, p.crs.as_deref(), ctx)
        } else {
            read_las(path, p.crs.as_deref(), ctx)
        }?;
        let Some(w) = ctx.window else {
            return Ok(points);
        };
        let inside: Vec<usize> = (0..points.len())
            .filter(|&i| w.contains(points.xyz[i][0] as f64, points.xyz[i][1] as f64))
            .collect();
        let mut cropped = PointSet::default();
        cropped
            .append_selected(&points, &inside)
            .map_err(StageError::Failed)?;
        Ok(cropped)
    }
}

fn las_error(path: &Path, place: &str, e: las::Error) -> StageError {
    StageError::bad_input(path, place, format!("expected a valid LAS/LAZ file: {e}"))
}

/// The CRS recorded in a LAS header: GeoTIFF keys first, then an OGC WKT record.
pub fn header_crs(path: &Path, header: &las::Header) -> Result<Option<Crs>, StageError> {
    let vlr = |id: u16| {
        header
            .all_vlrs()
            .find(|v| v.user_id.trim_end_matches('\0') == "LASF_Projection" && v.record_id == id)
    };
    if let Some(dir) = vlr(34735) {
        let dir: Vec<u16> = dir
            .data
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        let doubles: Vec<f64> = vlr(34736)
            .map(|v| {
                v.data
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect()
            })
            .unwrap_or_default();
        let ascii = vlr(34737)
            .map(|v| String::from_utf8_lossy(&v.data).into_owned())
            .unwrap_or_default();
        let keys = parse_geokeys(&dir, &doubles, &ascii)
            .map_err(|m| StageError::bad_input(path, "GeoKeyDirectory record", m))?;
        return Crs::from_geokeys(&keys)
            .map(Some)
            .map_err(|m| StageError::bad_input(path, "GeoKeyDirectory record", m));
    }
    if let Some(wkt) = header
        .get_wkt_crs_bytes()
        .or_else(|| vlr(2112).map(|v| v.data.as_slice()))
    {
        let wkt = String::from_utf8_lossy(wkt);
        return Crs::from_wkt(&wkt)
            .map(Some)
            .map_err(|m| StageError::bad_input(path, "WKT record", m));
    }
    Ok(None)
}

/// The farthest coordinate a LAS header's scale and offset may reach, in the file's map units:
/// a thousand times any projected CRS's extent (10^7 m), so a scale of 1 still passes.
pub const LAS_MAX_COORD: f64 = 1e10;

/// What the las crate takes on trust from the header, checked against the file first: scales
/// and offsets (a zero or non-finite one makes every coordinate garbage), extended VLR lengths
/// (the crate allocates what they say) and, uncompressed, the points the data can hold (so a
/// truncated file is named at the point where its data stops).
pub fn check_las_header(path: &Path) -> Result<(), StageError> {
    use std::io::{Read, Seek, SeekFrom};
    let bad = |place: String, expected: String| StageError::bad_input(path, place, expected);
    let mut f =
        crate::io::open::open_regular(path).map_err(|e| bad("open".into(), e.to_string()))?;
    let len = f
        .metadata()
        .map_err(|e| bad("open".into(), e.to_string()))?
        .len();
    let h = las::raw::Header::read_from(&mut f).map_err(|e| las_error(path, "header", e))?;
    for (axis, scale, offset) in [
        ("x", h.x_scale_factor, h.x_offset),
        ("y", h.y_scale_factor, h.y_offset),
        ("z", h.z_scale_factor, h.z_offset),
    ] {
        if !(scale.is_finite() && scale != 0.0) {
            return Err(bad(
                "header".into(),
                format!("a finite, non-zero {axis} scale factor, found {scale}"),
            ));
        }
        if !offset.is_finite() {
            return Err(bad(
                "header".into(),
                format!("a finite {axis} offset, found {offset}"),
            ));
        }
        // Every coordinate is offset + scale x a 32-bit integer: finite factors can still put
        // points at 1e308 m, where one point empties every raster made from the cloud.
        let reach = offset.abs() + scale.abs() * f64::from(i32::MAX);
        if !(reach <= LAS_MAX_COORD) {
            return Err(bad(
                "header".into(),
                format!(
                    "an {axis} scale and offset giving coordinates within {LAS_MAX_COORD:e} \
                     (map units), found offset {offset} and scale {scale}: up to {reach:e}"
                ),
            ));
        }
    }
    if let Some(evlr) = &h.evlr {
        let mut at = evlr.start_of_first_evlr;
        for k in 0..evlr.number_of_evlrs {
            let place = || format!("extended VLR {} at byte {at}", k + 1);
            let mut head = [0u8; 60];
            f.seek(SeekFrom::Start(at))
                .and_then(|_| f.read_exact(&mut head))
                .map_err(|_| {
                    bad(
                        place(),
                        format!("a 60-byte record header within the file's {len} bytes"),
                    )
                })?;
            let n = u64::from_le_bytes(head[20..28].try_into().expect("8 bytes"));
            let end = at.checked_add(60).and_then(|a| a.checked_add(n));
            match end {
                Some(e) if e <= len => at = e,
                _ => {
                    return Err(bad(
                        place(),
                        format!("a record within the file's {len} bytes, not one of {n} bytes"),
                    ));
                }
            }
        }
    }
    let compressed = h.point_data_record_format & 0xC0 != 0;
    let n = h
        .large_file
        .as_ref()
        .map(|l| l.number_of_point_records)
        .filter(|&n| n > 0)
        .unwrap_or(h.number_of_point_records as u64);
    let record = h.point_data_record_length as u64;
    // Even with no points: the las crate reads the chunk table when it opens the file, and
    // sizes a list by its chunk count (a 10-minute fuzz run found a 61 GB one behind a header
    // announcing 0 points).
    if compressed {
        check_laz_chunk_table(path, &mut f, &h, len, n)?;
    }
    if !compressed && n > 0 {
        let data_end = match &h.evlr {
            Some(e)
                if e.number_of_evlrs > 0
                    && e.start_of_first_evlr >= h.offset_to_point_data as u64 =>
            {
                e.start_of_first_evlr.min(len)
            }
            _ => len,
        };
        let held = data_end.saturating_sub(h.offset_to_point_data as u64) / record.max(1);
        if held < n {
            return Err(bad(
                format!("point {}", held + 1),
                format!(
                    "the header announces {n} points of {record} bytes but the data stops after point {held}"
                ),
            ));
        }
    }
    Ok(())
}

/// A LAZ file's chunk table (its offset is the first 8 bytes of the point data, and the las
/// crate reads it when opening the file): past the end of the file, the data was cut short and
/// the points are decoded one by one to name the first one missing; its chunk count bounds the
/// table the crate allocates, so one larger than the point count is refused.
fn check_laz_chunk_table(
    path: &Path,
    f: &mut std::fs::File,
    h: &las::raw::Header,
    len: u64,
    n: u64,
) -> Result<(), StageError> {
    use std::io::{Read, Seek, SeekFrom};
    let start = h.offset_to_point_data as u64;
    let mut read_u64_at = |at: u64| -> Option<u64> {
        let mut b = [0u8; 8];
        f.seek(SeekFrom::Start(at)).ok()?;
        f.read_exact(&mut b).ok()?;
        Some(u64::from_le_bytes(b))
    };
    let table = read_u64_at(start)
        .filter(|&t| t > start)
        .or_else(|| len.checked_sub(8).and_then(&mut read_u64_at));
    match table {
        Some(t) if t > start && t.checked_add(8).is_some_and(|e| e <= len) => {
            let place = format!("LAZ chunk table at byte {t}");
            let bad = |m: String| StageError::bad_input(path, place.clone(), m);
            let chunks = read_u64_at(t).map_or(0, |v| v >> 32);
            // Every chunk holds a point and its compressed bytes: more chunks than points, or
            // than bytes in the file, is a table the decoder must not size a list by.
            if chunks > n.min(len) + 1 {
                return Err(bad(format!(
                    "at most one chunk per point ({n}) and per byte of the file ({len}), found {chunks} chunks"
                )));
            }
            // The decoder sizes its buffers by the table's counts and asserts they agree with the
            // header's: checked here so a contradiction is an error, not an abort.
            let vlr = laz_vlr(path, h).ok_or_else(|| {
                StageError::bad_input(path, "LAZ VLR", "a readable laszip record")
            })?;
            if vlr.items_size() != h.point_data_record_length as u64 {
                return Err(StageError::bad_input(
                    path,
                    "LAZ VLR",
                    format!(
                        "points of {} bytes as the header says, found {}",
                        h.point_data_record_length,
                        vlr.items_size()
                    ),
                ));
            }
            f.seek(SeekFrom::Start(start))
                .map_err(|e| bad(e.to_string()))?;
            let table = decoding(path, &place, || {
                laz::laszip::ChunkTable::read_from(&mut *f, &vlr)
            })?
            .map_err(|e| bad(format!("a readable chunk table ({e})")))?;
            // Fixed-size chunks all count the chunk size, the last one too. The decoder
            // allocates a decoded chunk at a time: writers use some 50,000 points a chunk, so
            // a chunk decoding to more than 1 GiB is refused.
            let most = if vlr.uses_variable_size_chunks() {
                n
            } else {
                n.max(vlr.chunk_size() as u64)
            };
            let record = h.point_data_record_length as u64;
            const MAX_CHUNK_BYTES: u64 = 1 << 30;
            let (mut points, mut bytes) = (0u64, 0u64);
            for e in table.as_ref() {
                points = points.saturating_add(e.point_count);
                bytes = bytes.saturating_add(e.byte_count);
                if e.point_count.saturating_mul(record) > MAX_CHUNK_BYTES {
                    return Err(bad(format!(
                        "chunks of at most {MAX_CHUNK_BYTES} bytes decoded, found one of {} points of {record} bytes",
                        e.point_count
                    )));
                }
                if e.point_count > most || bytes > len {
                    return Err(bad(format!(
                        "chunks within the header's {n} points and the file's {len} bytes"
                    )));
                }
            }
            if points < n {
                return Err(bad(format!(
                    "chunks holding the header's {n} points, found {points}"
                )));
            }
            Ok(())
        }
        // No table and nothing announced: nothing to decode.
        _ if n == 0 => Ok(()),
        _ => {
            let held = laz_points_held(path, h, n);
            Err(StageError::bad_input(
                path,
                format!("point {}", held + 1),
                format!(
                    "the header announces {n} points but the compressed data stops after point {held} (the file is cut short: its chunk table is missing)"
                ),
            ))
        }
    }
}

/// The laszip record among the VLRs after the header.
fn laz_vlr(path: &Path, h: &las::raw::Header) -> Option<laz::LazVlr> {
    use std::io::{BufReader, Seek, SeekFrom};
    let mut f = BufReader::new(crate::io::open::open_regular(path).ok()?);
    f.seek(SeekFrom::Start(h.header_size as u64)).ok()?;
    for _ in 0..h.number_of_variable_length_records {
        let v = las::raw::Vlr::read_from(&mut f, false).ok()?;
        if v.user_id.starts_with(laz::LazVlr::USER_ID.as_bytes())
            && v.record_id == laz::LazVlr::RECORD_ID
        {
            return laz::LazVlr::from_buffer(&v.data).ok();
        }
    }
    None
}

/// How many points of a LAZ file decode, reading sequentially without the chunk table.
fn laz_points_held(path: &Path, h: &las::raw::Header, n: u64) -> u64 {
    use std::io::{BufReader, Read, Seek, SeekFrom};
    // A source that cannot seek: the decoder then skips the chunk table and reads chunk after
    // chunk, which is all a cut-short file allows.
    struct NoSeek<R>(R);
    impl<R: Read> Read for NoSeek<R> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            self.0.read(buf)
        }
    }
    impl<R> Seek for NoSeek<R> {
        fn seek(&mut self, _: SeekFrom) -> std::io::Result<u64> {
            Err(std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                "sequential",
            ))
        }
    }
    let count = || -> Option<u64> {
        let vlr = laz_vlr(path, h)?;
        if vlr.items_size() != h.point_data_record_length as u64 {
            return None;
        }
        let mut f = BufReader::new(crate::io::open::open_regular(path).ok()?);
        f.seek(SeekFrom::Start(h.offset_to_point_data as u64))
            .ok()?;
        let mut d = laz::LasZipDecompressor::new(NoSeek(f), vlr).ok()?;
        let mut buf = vec![0u8; h.point_data_record_length as usize];
        Some(
            (0..n)
                .position(|_| d.decompress_one(&mut buf).is_err())
                .map_or(n, |k| k as u64),
        )
    };
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(count))
        .ok()
        .flatten()
        .unwrap_or(0)
}

/// Runs a step of the LAZ decoder, whose arithmetic decoder asserts on corrupt data (in builds
/// with debug assertions): such a panic is the file's fault, reported at `place`.
fn decoding<T>(path: &Path, place: &str, f: impl FnOnce() -> T) -> Result<T, StageError> {
    StageError::catch_decoder_panic(path, place, "decodable LAZ data (the decoder failed", f)
}

/// Reads `path` into the site frame of `ctx`, in batches so progress can be reported.
pub fn read_las(path: &Path, crs: Option<&str>, ctx: &Ctx) -> Result<PointSet, StageError> {
    let reader = open_reader(path)?;
    let tile = tile_of(path, reader.header(), crs)?;
    ctx.progress.set_total(tile.points);
    let mut out = PointSet::default();
    read_tile(path, reader, &tile.crs, ctx, &mut out)?;
    normalize_rgb(&mut out.rgb);
    Ok(out)
}

/// What a tile's header says, checked: its CRS (from `crs` when given), point count and whether
/// its points carry colour.
struct Tile {
    crs: Crs,
    points: u64,
    has_color: bool,
}

fn open_reader(path: &Path) -> Result<Reader, StageError> {
    check_las_header(path)?;
    decoding(path, "header", || Reader::from_path(path))?.map_err(|e| las_error(path, "header", e))
}

fn tile_of(path: &Path, header: &las::Header, crs: Option<&str>) -> Result<Tile, StageError> {
    let crs = match crs {
        Some(c) => Crs::from_user(c).map_err(|m| StageError::Param(ParamError::new("crs", m)))?,
        None => header_crs(path, header)?.ok_or_else(|| {
            StageError::bad_input(path, "header", "no CRS recorded (no GeoTIFF keys or WKT record); give it in the graph, e.g. crs: \"EPSG:28992\"")
        })?,
    };
    Ok(Tile {
        crs,
        points: header.number_of_points(),
        has_color: header.point_format().has_color,
    })
}

/// Appends the points of `path`, in `crs`, to `out` (colours as stored, not yet normalized).
fn read_tile(
    path: &Path,
    mut reader: Reader,
    crs: &Crs,
    ctx: &Ctx,
    out: &mut PointSet,
) -> Result<(), StageError> {
    let header = reader.header().clone();
    let to_site = ToSite::new(crs, ctx.site).map_err(|m| StageError::bad_input(path, "CRS", m))?;
    let n = header.number_of_points();
    // Position, class, intensity, return numbers and colour: 23 bytes a point.
    crate::params::check_bytes("the points", (out.xyz.len() as u64 + n) as f64, 23)
        .map_err(|m| StageError::bad_input(path, "header", format!("{m}; tile the data")))?;
    let format = header.point_format();
    // Grown as points arrive: a compressed file's count is not checked against its length.
    out.xyz.reserve(n.min(1 << 22) as usize);
    const BATCH: u64 = 1 << 20;
    let mut done = 0u64;
    while done < n {
        let place = format!("point {}", done + 1);
        let pd = decoding(path, &place, || reader.read_points(BATCH.min(n - done)))?
            .map_err(|e| las_error(path, &place, e))?;
        if pd.is_empty() {
            return Err(StageError::bad_input(
                path,
                format!("point {}", done + 1),
                format!("the header announces {n} points but the file ends after {done}"),
            ));
        }
        for ((x, y), z) in pd.x().zip(pd.y()).zip(pd.z()) {
            let (sx, sy, sz) = to_site
                .apply(x, y, z)
                .map_err(|m| StageError::bad_input(path, format!("point {}", done + 1), m))?;
            out.xyz.push([sx as f32, sy as f32, sz as f32]);
        }
        out.class.extend(pd.classification());
        out.intensity.extend(pd.intensity());
        out.return_number.extend(pd.return_number());
        out.number_of_returns.extend(pd.number_of_returns());
        if format.has_color
            && let Some(rgb) = pd.rgb()
        {
            out.rgb.extend(rgb.map(|(r, g, b)| [r, g, b]));
        }
        done += pd.len() as u64;
        ctx.progress.advance(pd.len() as u64);
    }
    Ok(())
}

/// The `.las`/`.laz` files directly inside `dir` (any case), sorted by file name.
pub fn las_tiles(dir: &Path) -> Result<Vec<PathBuf>, StageError> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| StageError::bad_input(dir, "folder", e.to_string()))?;
    let mut tiles = Vec::new();
    for e in entries {
        let e = e.map_err(|e| StageError::bad_input(dir, "folder", e.to_string()))?;
        let path = e.path();
        let ext = path.extension().map(|x| x.to_ascii_lowercase());
        if path.is_file() && (ext == Some("las".into()) || ext == Some("laz".into())) {
            tiles.push(path);
        }
    }
    tiles.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(tiles)
}

/// Reads every tile of `dir` (see [`las_tiles`]) into one cloud. Every header is read and checked
/// first: all tiles must share one CRS (from their headers, or `crs` for all), and the total
/// must fit the point budget, before any point is decoded. Colours are kept when every tile has
/// them, each tile's scaled to 16 bits on its own (see [`normalize_rgb`]).
pub fn read_las_folder(dir: &Path, crs: Option<&str>, ctx: &Ctx) -> Result<PointSet, StageError> {
    let paths = las_tiles(dir)?;
    if paths.is_empty() {
        return Err(StageError::bad_input(
            dir,
            "folder",
            "at least one .las or .laz file directly inside it, found none",
        ));
    }
    let mut tiles: Vec<Tile> = Vec::with_capacity(paths.len());
    // Headers only: no reader is held open across tiles.
    for path in &paths {
        let tile = tile_of(path, open_reader(path)?.header(), crs)?;
        if let Some(t0) = tiles.first()
            && !same_crs(&tile.crs, &t0.crs)
        {
            return Err(StageError::bad_input(
                path,
                "CRS",
                format!(
                    "the CRS of the folder's first tile {} ({}), found {} (give `crs` to override every tile's header)",
                    paths[0].file_name().unwrap_or_default().to_string_lossy(),
                    t0.crs.label,
                    tile.crs.label
                ),
            ));
        }
        tiles.push(tile);
    }
    let total: u64 = tiles.iter().map(|t| t.points).sum();
    crate::params::check_bytes("the points", total as f64, 23).map_err(|m| {
        StageError::bad_input(
            dir,
            "folder",
            format!("{m} in {} tiles; read fewer", tiles.len()),
        )
    })?;
    let color = tiles.iter().all(|t| t.has_color);
    ctx.progress.set_total(total);
    let mut out = PointSet::default();
    for (path, tile) in paths.iter().zip(&tiles) {
        let from = out.rgb.len();
        read_tile(path, open_reader(path)?, &tile.crs, ctx, &mut out)?;
        normalize_rgb(&mut out.rgb[from..]);
    }
    if !color {
        out.rgb.clear();
    }
    Ok(out)
}

/// Whether two CRSs place points alike: the same definition and vertical unit, whatever their
/// labels (a GeoTIFF key and a WKT record of one CRS are named differently).
fn same_crs(a: &Crs, b: &Crs) -> bool {
    a.proj4 == b.proj4 && a.z_to_m == b.z_to_m
}

/// LAS colours are 16-bit, but many writers store 8-bit values in them. When no channel of any
/// point exceeds 255 the file is taken to be 8-bit and scaled by 257, so every [`PointSet`] colour
/// spans 0..=65535.
fn normalize_rgb(rgb: &mut [[u16; 3]]) {
    if rgb.iter().all(|c| c.iter().all(|&v| v <= 255)) {
        for c in rgb.iter_mut() {
            for v in c.iter_mut() {
                *v *= 257;
            }
        }
    }
}
