//! Coordinate reference systems and reprojection into the site frame.
//!
//! A source's CRS comes from its header (an EPSG code in GeoTIFF keys or WKT, or a user-defined
//! projection spelled out in GeoTIFF keys) or from the graph when the header has none. Everything
//! is turned into a PROJ.4 string for proj4rs.
//!
//! # Units
//! The site frame is metres east and north of the site origin, z up, in metres. A source in feet is
//! converted horizontally by proj4rs; its z is scaled by the vertical unit key when present, else by
//! the horizontal linear unit (LAS files in US state planes store z in the same feet as x and y).

use proj4rs::Proj;
use proj4rs::transform::transform;

use crate::site::Site;
use crate::stage::{ParamError, StageError};

/// A CRS, as the PROJ.4 definition proj4rs runs and a label for messages.
#[derive(Clone, Debug, PartialEq)]
pub struct Crs {
    /// `EPSG:<code>` or a description of where the definition came from.
    pub label: String,
    /// The PROJ.4 definition.
    pub proj4: String,
    /// Metres per vertical unit of the source's z values.
    pub z_to_m: f64,
}

/// A GeoTIFF GeoKey value.
#[derive(Clone, Debug, PartialEq)]
pub enum GeoKeyValue {
    /// A SHORT stored in the directory.
    Short(u16),
    /// Values from GeoDoubleParams.
    Doubles(Vec<f64>),
    /// Text from GeoAsciiParams (trailing `|` removed).
    Ascii(String),
}

/// Parses a GeoKeyDirectory (tag/record 34735) with its double (34736) and ASCII (34737) params.
pub fn parse_geokeys(
    dir: &[u16],
    doubles: &[f64],
    ascii: &str,
) -> Result<Vec<(u16, GeoKeyValue)>, String> {
    if dir.len() < 4 {
        return Err(format!(
            "GeoKeyDirectory has {} values, expected at least 4",
            dir.len()
        ));
    }
    let n = dir[3] as usize;
    if dir.len() < 4 + 4 * n {
        return Err(format!(
            "GeoKeyDirectory announces {n} keys but holds {}",
            (dir.len() - 4) / 4
        ));
    }
    let mut keys = Vec::with_capacity(n);
    for k in dir[4..4 + 4 * n].chunks_exact(4) {
        let (id, loc, count, off) = (k[0], k[1], k[2] as usize, k[3] as usize);
        let v = match loc {
            0 => GeoKeyValue::Short(off as u16),
            34736 => GeoKeyValue::Doubles(
                doubles
                    .get(off..off + count)
                    .ok_or_else(|| {
                        format!("GeoKey {id}: doubles {off}..{} out of range", off + count)
                    })?
                    .to_vec(),
            ),
            34737 => {
                let s = ascii
                    .get(off..(off + count).min(ascii.len()))
                    .ok_or_else(|| format!("GeoKey {id}: ASCII out of range"))?;
                GeoKeyValue::Ascii(s.trim_end_matches(['|', '\0']).to_owned())
            }
            34735 => GeoKeyValue::Short(dir.get(off).copied().unwrap_or(0)),
            other => return Err(format!("GeoKey {id}: unknown location tag {other}")),
        };
        keys.push((id, v));
    }
    Ok(keys)
}

const USER_DEFINED: u16 = 32767;

fn short(keys: &[(u16, GeoKeyValue)], id: u16) -> Option<u16> {
    keys.iter().find_map(|(k, v)| match v {
        GeoKeyValue::Short(s) if *k == id => Some(*s),
        _ => None,
    })
}

fn double(keys: &[(u16, GeoKeyValue)], id: u16) -> Option<f64> {
    keys.iter().find_map(|(k, v)| match v {
        GeoKeyValue::Doubles(d) if *k == id => d.first().copied(),
        _ => None,
    })
}

/// Metres per unit for an EPSG linear unit code.
fn linear_unit(code: u16) -> Result<f64, String> {
    Ok(match code {
        9001 => 1.0,
        9002 => 0.3048,
        9003 => 1200.0 / 3937.0,
        9036 => 1000.0,
        other => {
            return Err(format!(
                "unsupported linear unit EPSG:{other} (expected metre 9001, foot 9002 or US survey foot 9003)"
            ));
        }
    })
}

impl Crs {
    /// The CRS with EPSG code `code`.
    pub fn from_epsg(code: u16) -> Result<Crs, String> {
        let def =
            crs_definitions::from_code(code).ok_or_else(|| format!("unknown EPSG code {code}"))?;
        let crs = Crs {
            label: format!("EPSG:{code}"),
            proj4: def.proj4.to_owned(),
            z_to_m: 1.0,
        };
        let to_m = crs.proj()?.to_meter();
        Ok(Crs {
            z_to_m: if crs.is_geographic() { 1.0 } else { to_m },
            ..crs
        })
    }

    /// `EPSG:<code>` or a `+proj=...` string, as a user writes it in a graph.
    pub fn from_user(s: &str) -> Result<Crs, String> {
        let s = s.trim();
        if let Some(code) = s.strip_prefix("EPSG:").or_else(|| s.strip_prefix("epsg:")) {
            let code = code
                .parse::<u32>()
                .map_err(|_| format!("expected a numeric EPSG code, found {code:?}"))?;
            return u16::try_from(code)
                .map_err(|_| format!("unknown EPSG code {code}"))
                .and_then(Crs::from_epsg);
        }
        if s.starts_with('+') {
            let crs = Crs {
                label: s.to_owned(),
                proj4: s.to_owned(),
                z_to_m: 1.0,
            };
            crs.proj()?;
            return Ok(crs);
        }
        Err(format!(
            "expected \"EPSG:<code>\" or a \"+proj=...\" string, found {s:?}"
        ))
    }

    /// The CRS described by GeoTIFF keys: an EPSG projected or geographic code, or a user-defined
    /// projection (transverse Mercator, Lambert conformal conic 1SP/2SP, Albers, Mercator).
    pub fn from_geokeys(keys: &[(u16, GeoKeyValue)]) -> Result<Crs, String> {
        let vertical = short(keys, 4099).map(linear_unit).transpose()?;
        let model = short(keys, 1024);
        let mut crs = match (model, short(keys, 3072), short(keys, 2048)) {
            (_, Some(code), _) if code != USER_DEFINED && code != 0 => Crs::from_epsg(code)?,
            (Some(2), _, Some(code)) if code != USER_DEFINED && code != 0 => Crs::from_epsg(code)?,
            (Some(1), _, _) => user_defined_projection(keys)?,
            _ => {
                return Err(
                    "the GeoTIFF keys name neither a projected nor a geographic CRS".into(),
                );
            }
        };
        if let Some(v) = vertical {
            crs.z_to_m = v;
        }
        Ok(crs)
    }

    /// The CRS of a WKT string, by the EPSG authority of its outermost PROJCS or GEOGCS.
    pub fn from_wkt(wkt: &str) -> Result<Crs, String> {
        let code = outer_authority(wkt).ok_or_else(|| {
            let head: String = wkt.chars().take(60).collect();
            format!("the WKT ({head}...) carries no EPSG authority code; give the CRS in the graph")
        })?;
        Crs::from_epsg(code)
    }

    /// The proj4rs projection.
    pub fn proj(&self) -> Result<Proj, String> {
        Proj::from_proj_string(&self.proj4)
            .map_err(|e| format!("{}: cannot build the projection ({e:?})", self.label))
    }

    /// True for longitude/latitude CRSs.
    pub fn is_geographic(&self) -> bool {
        self.proj4.contains("+proj=longlat") || self.proj4.contains("+proj=latlong")
    }
}

/// The EPSG code of the outermost element's own AUTHORITY (a direct child, not a nested one).
fn outer_authority(wkt: &str) -> Option<u16> {
    let (mut depth, mut quoted, mut found) = (0usize, false, None);
    for (i, c) in wkt.char_indices() {
        match c {
            '"' => quoted = !quoted,
            '[' if !quoted => {
                if depth == 1 && wkt[..i].ends_with("AUTHORITY") {
                    found = Some(i + 1);
                }
                depth += 1;
            }
            ']' if !quoted => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    let rest = &wkt[found?..];
    let inner = &rest[..rest.find(']')?];
    let mut parts = inner.split(',').map(|p| p.trim().trim_matches('"'));
    (parts.next()? == "EPSG").then_some(())?;
    parts.next()?.parse().ok()
}

fn user_defined_projection(keys: &[(u16, GeoKeyValue)]) -> Result<Crs, String> {
    let unit = linear_unit(short(keys, 3076).unwrap_or(9001))?;
    let d = |id: u16, name: &str| {
        double(keys, id)
            .ok_or_else(|| format!("user-defined projection without {name} (GeoKey {id})"))
    };
    let proj = match short(keys, 3075) {
        Some(1) => format!(
            "+proj=tmerc +lat_0={} +lon_0={} +k={} +x_0={} +y_0={}",
            d(3081, "NatOriginLat")?,
            d(3080, "NatOriginLong")?,
            double(keys, 3092).unwrap_or(1.0),
            d(3082, "FalseEasting")? * unit,
            d(3083, "FalseNorthing")? * unit
        ),
        Some(8) => format!(
            "+proj=lcc +lat_1={} +lat_2={} +lat_0={} +lon_0={} +x_0={} +y_0={}",
            d(3078, "StdParallel1")?,
            d(3079, "StdParallel2")?,
            d(3085, "FalseOriginLat")?,
            d(3084, "FalseOriginLong")?,
            d(3086, "FalseOriginEasting")? * unit,
            d(3087, "FalseOriginNorthing")? * unit
        ),
        Some(9) => {
            let lat = d(3081, "NatOriginLat")?;
            format!(
                "+proj=lcc +lat_1={lat} +lat_0={lat} +lon_0={} +k_0={} +x_0={} +y_0={}",
                d(3080, "NatOriginLong")?,
                double(keys, 3092).unwrap_or(1.0),
                d(3082, "FalseEasting")? * unit,
                d(3083, "FalseNorthing")? * unit
            )
        }
        Some(11) => format!(
            "+proj=aea +lat_1={} +lat_2={} +lat_0={} +lon_0={} +x_0={} +y_0={}",
            d(3078, "StdParallel1")?,
            d(3079, "StdParallel2")?,
            d(3081, "NatOriginLat")?,
            d(3080, "NatOriginLong")?,
            d(3082, "FalseEasting")? * unit,
            d(3083, "FalseNorthing")? * unit
        ),
        Some(7) => format!(
            "+proj=merc +lon_0={} +k={} +x_0={} +y_0={}",
            d(3080, "NatOriginLong")?,
            double(keys, 3092).unwrap_or(1.0),
            d(3082, "FalseEasting")? * unit,
            d(3083, "FalseNorthing")? * unit
        ),
        other => {
            return Err(format!(
                "unsupported user-defined projection (ProjCoordTransGeoKey {other:?})"
            ));
        }
    };
    let datum = geodetic_terms(keys)?;
    let units = if unit == 1.0 {
        "+units=m".to_owned()
    } else {
        format!("+to_meter={unit}")
    };
    let proj4 = format!("{proj} {datum} {units} +no_defs");
    let crs = Crs {
        label: format!("user-defined ({proj4})"),
        proj4,
        z_to_m: unit,
    };
    crs.proj()?;
    Ok(crs)
}

/// `+ellps`/`+datum`/`+towgs84` terms for the geographic part of user-defined keys.
fn geodetic_terms(keys: &[(u16, GeoKeyValue)]) -> Result<String, String> {
    // A geographic CRS code, or the one EPSG pairs with a datum code (datum 6xxx -> GCS 4xxx).
    let gcs = match (short(keys, 2048), short(keys, 2050)) {
        (Some(c), _) if c != USER_DEFINED && c != 0 => Some(c),
        (_, Some(d)) if (6001..7000).contains(&d) => Some(d - 2000),
        _ => None,
    };
    if let Some(def) = gcs.and_then(crs_definitions::from_code) {
        let terms: Vec<&str> = def
            .proj4
            .split_whitespace()
            .filter(|t| {
                t.starts_with("+ellps")
                    || t.starts_with("+datum")
                    || t.starts_with("+towgs84")
                    || t.starts_with("+a=")
                    || t.starts_with("+b=")
                    || t.starts_with("+rf=")
            })
            .collect();
        if !terms.is_empty() {
            return Ok(terms.join(" "));
        }
    }
    match (double(keys, 2057), double(keys, 2059), double(keys, 2058)) {
        (Some(a), Some(rf), _) => Ok(format!("+a={a} +rf={rf}")),
        (Some(a), None, Some(b)) => Ok(format!("+a={a} +b={b}")),
        _ => Err("user-defined projection without a datum or ellipsoid".into()),
    }
}

/// Maps coordinates of a source CRS into the site frame (metres from the site origin).
pub struct ToSite {
    src: Option<(Proj, bool)>,
    dst: Proj,
    origin: (f64, f64),
    z_to_m: f64,
}

impl ToSite {
    /// A transformer from `src` to `site`'s frame.
    pub fn new(src: &Crs, site: &Site) -> Result<ToSite, String> {
        let site_crs = Crs::from_user(&site.crs)?;
        let dst = site_crs.proj()?;
        let same = src.proj4 == site_crs.proj4;
        let src_proj = if same {
            None
        } else {
            Some((src.proj()?, src.is_geographic()))
        };
        Ok(ToSite {
            src: src_proj,
            dst,
            origin: site.origin,
            z_to_m: src.z_to_m,
        })
    }

    /// True when the source CRS is the site's (no reprojection, just the origin shift).
    pub fn is_identity(&self) -> bool {
        self.src.is_none()
    }

    /// Site-frame (x, y, z) of a source point; geographic sources are in degrees.
    pub fn apply(&self, x: f64, y: f64, z: f64) -> Result<(f64, f64, f64), String> {
        let (e, n) = match &self.src {
            None => (x, y),
            Some((src, geographic)) => {
                let mut p = if *geographic {
                    (x.to_radians(), y.to_radians(), 0.0)
                } else {
                    (x, y, 0.0)
                };
                transform(src, &self.dst, &mut p)
                    .map_err(|e| format!("cannot reproject ({x}, {y}): {e:?}"))?;
                (p.0, p.1)
            }
        };
        Ok((e - self.origin.0, n - self.origin.1, z * self.z_to_m))
    }
}

impl ToSite {
    /// The source-CRS (x, y) of a site-frame point (degrees for geographic sources).
    pub fn inverse(&self, x: f64, y: f64) -> Result<(f64, f64), String> {
        let (e, n) = (x + self.origin.0, y + self.origin.1);
        match &self.src {
            None => Ok((e, n)),
            Some((src, geographic)) => {
                let mut p = (e, n, 0.0);
                transform(&self.dst, src, &mut p)
                    .map_err(|err| format!("cannot reproject site point ({x}, {y}): {err:?}"))?;
                Ok(if *geographic {
                    (p.0.to_degrees(), p.1.to_degrees())
                } else {
                    (p.0, p.1)
                })
            }
        }
    }
}

impl ToSite {
    /// The meridian convergence γ at a site-frame point, degrees: the angle from true north to
    /// grid north (the site frame's +y), clockwise, so a true bearing b is the grid bearing
    /// b − γ. Found numerically: the point's meridian is projected a step either side of its
    /// latitude (about 11 m), and γ is minus the grid bearing of that chord. The source must be
    /// geographic (it names the meridians).
    ///
    /// # References
    /// Snyder, *Map Projections: A Working Manual* (USGS PP 1395, 1987), §8: γ is the angle
    /// between the projected meridian and grid north. About 1.21° at Duke in UTM 17N.
    pub fn convergence_deg(&self, x: f64, y: f64) -> Result<f64, String> {
        if !matches!(self.src, Some((_, true))) {
            return Err("meridian convergence needs a geographic source CRS".into());
        }
        let (lon, lat) = self.inverse(x, y)?;
        let h = 1e-4;
        let (s, n) = ((lat - h).max(-90.0), (lat + h).min(90.0));
        let (xs, ys, _) = self.apply(lon, s, 0.0)?;
        let (xn, yn, _) = self.apply(lon, n, 0.0)?;
        Ok(-(xn - xs).atan2(yn - ys).to_degrees())
    }
}

/// An optional CRS must be one we can build (`EPSG:<code>` or a `+proj` string).
pub fn check_crs_param(crs: &Option<String>) -> Result<(), ParamError> {
    if let Some(c) = crs {
        Crs::from_user(c).map_err(|m| ParamError::new("crs", m))?;
    }
    Ok(())
}

/// A site as a user wrote it: its own checks ([`Site::validate`]) and a projection in metres.
pub fn check_site(site: &Site) -> Result<(), (&'static str, String)> {
    site.validate()?;
    check_site_crs(&site.crs).map_err(|m| ("crs", m))
}

/// The site frame's projection, checked to be projected and metric.
pub fn check_site_crs(crs: &str) -> Result<(), String> {
    let c = Crs::from_user(crs)?;
    if c.is_geographic() {
        return Err(format!(
            "{crs} is geographic; the site needs a projected CRS in metres (a UTM zone, say)"
        ));
    }
    let to_m = c.proj()?.to_meter();
    if (to_m - 1.0).abs() > 1e-12 {
        return Err(format!(
            "{crs} is in units of {to_m} m; the site needs a projected CRS in metres"
        ));
    }
    Ok(())
}

/// The CRS to use: the graph's if given, else the file's, else an error naming the file.
pub fn source_crs(
    param: Option<&str>,
    recorded: Option<Crs>,
    path: &std::path::Path,
) -> Result<Crs, StageError> {
    match (param, recorded) {
        (Some(c), _) => Crs::from_user(c).map_err(|m| StageError::Param(ParamError::new("crs", m))),
        (None, Some(c)) => Ok(c),
        (None, None) => Err(StageError::bad_input(
            path,
            "georeferencing",
            "no CRS recorded; give it in the graph, e.g. crs: \"EPSG:32618\"",
        )),
    }
}

/// A box in WGS 84 degrees, sides named so that no axis order has to be remembered: what a user
/// copies from a map or from an OSM extract's `<bounds>` (minlat, minlon, maxlat, maxlon).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LonLatBox {
    /// Western longitude, degrees east.
    pub west: f64,
    /// Southern latitude, degrees north.
    pub south: f64,
    /// Eastern longitude, degrees east.
    pub east: f64,
    /// Northern latitude, degrees north.
    pub north: f64,
}

impl LonLatBox {
    /// Checks the sides: finite, latitudes within ±90, longitudes within ±180, each min below its
    /// max (a box across the antimeridian is not supported).
    pub fn check(&self) -> Result<(), String> {
        let ok = [self.west, self.south, self.east, self.north]
            .iter()
            .all(|v| v.is_finite())
            && (-90.0..=90.0).contains(&self.south)
            && (-90.0..=90.0).contains(&self.north)
            && (-180.0..=180.0).contains(&self.west)
            && (-180.0..=180.0).contains(&self.east)
            && self.west < self.east
            && self.south < self.north;
        if ok {
            Ok(())
        } else {
            Err(format!(
                "expected (west, south, east, north) in degrees, west < east within ±180, south < \
                 north within ±90; found ({}, {}, {}, {})",
                self.west, self.south, self.east, self.north
            ))
        }
    }

    /// The site-frame rectangle (x_min, y_min, x_max, y_max) holding the box: its edges are
    /// sampled (16 points a side), since a meridian or parallel is curved in a projected CRS.
    pub fn site_window(&self, site: &Site) -> Result<(f64, f64, f64, f64), String> {
        self.check()?;
        let wgs84 = ToSite::new(&Crs::from_epsg(4326)?, site)?;
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        const STEPS: usize = 16;
        for i in 0..=STEPS {
            let t = i as f64 / STEPS as f64;
            let lon = self.west + t * (self.east - self.west);
            let lat = self.south + t * (self.north - self.south);
            for (x, y) in [
                (lon, self.south),
                (lon, self.north),
                (self.west, lat),
                (self.east, lat),
            ] {
                let (sx, sy, _) = wgs84.apply(x, y, 0.0)?;
                lo = (lo.0.min(sx), lo.1.min(sy));
                hi = (hi.0.max(sx), hi.1.max(sy));
            }
        }
        Ok((lo.0, lo.1, hi.0, hi.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn site(crs: &str, origin: (f64, f64)) -> Site {
        Site {
            crs: crs.into(),
            origin,
            cell_m: 1.0,
        }
    }

    #[test]
    fn wgs84_to_utm_matches_the_textbook_point() {
        // lon -75, lat 40 is on UTM 18N's central meridian: E = 500000 exactly, N = 4427757.22 m
        // (k0 = 0.9996 times the WGS84 meridian arc to 40 degrees, 4429529.03 m).
        let t = ToSite::new(
            &Crs::from_epsg(4326).unwrap(),
            &site("EPSG:32618", (0.0, 0.0)),
        )
        .unwrap();
        let (e, n, _) = t.apply(-75.0, 40.0, 0.0).unwrap();
        assert!((e - 500_000.0).abs() < 1e-3, "{e}");
        assert!((n - 4_427_757.22).abs() < 0.05, "{n}");
    }

    #[test]
    fn inverse_undoes_apply() {
        let t = ToSite::new(
            &Crs::from_epsg(4326).unwrap(),
            &site("EPSG:32618", (583000.0, 4506000.0)),
        )
        .unwrap();
        let (x, y, _) = t.apply(-74.01, 40.70, 0.0).unwrap();
        let (lon, lat) = t.inverse(x, y).unwrap();
        assert!(
            (lon + 74.01).abs() < 1e-9 && (lat - 40.70).abs() < 1e-9,
            "{lon} {lat}"
        );
    }

    #[test]
    fn identity_when_source_is_the_site_crs() {
        let t = ToSite::new(
            &Crs::from_user("EPSG:28992").unwrap(),
            &site("EPSG:28992", (84800.0, 447400.0)),
        )
        .unwrap();
        assert!(t.is_identity());
        let (x, y, z) = t.apply(84808.3, 447412.8, 1.0).unwrap();
        assert!((x - 8.3).abs() < 1e-9 && (y - 12.8).abs() < 1e-9 && z == 1.0);
    }

    #[test]
    fn unknown_codes_and_non_metric_sites_are_clear_errors() {
        assert_eq!(
            Crs::from_user("EPSG:99999").unwrap_err(),
            "unknown EPSG code 99999"
        );
        assert_eq!(Crs::from_user("EPSG:1").unwrap_err(), "unknown EPSG code 1");
        assert!(
            check_site_crs("EPSG:4326")
                .unwrap_err()
                .contains("geographic")
        );
        assert!(
            check_site_crs("EPSG:2994")
                .unwrap_err()
                .contains("units of 0.3048 m")
        );
        assert!(check_site_crs("EPSG:32618").is_ok());
    }

    #[test]
    fn meridian_convergence_at_duke_is_1_21_degrees() {
        let t = ToSite::new(
            &Crs::from_epsg(4326).unwrap(),
            &site("EPSG:32617", (687000.0, 3985000.0)),
        )
        .unwrap();
        // The Duke A-D site, 2.06° east of UTM 17N's central meridian (81° W): γ ≈ Δλ sin φ
        // = 1.211° (the sphere's first term; pyproj gives 1.21).
        let (lat, lon) = (35.999186, -78.939786);
        let (x, y, _) = t.apply(lon, lat, 0.0).unwrap();
        let g = t.convergence_deg(x, y).unwrap();
        let first_term = (lon + 81.0f64) * lat.to_radians().sin();
        assert!((g - 1.21).abs() < 0.005, "{g}");
        assert!((g - first_term).abs() < 0.005, "{g} vs {first_term}");
        // Zero on the central meridian, negative west of it.
        let (x, y, _) = t.apply(-81.0, lat, 0.0).unwrap();
        assert!(t.convergence_deg(x, y).unwrap().abs() < 1e-6);
        let (x, y, _) = t.apply(-82.0, lat, 0.0).unwrap();
        assert!(t.convergence_deg(x, y).unwrap() < -0.5);
        // A projected source names no meridians.
        let same = ToSite::new(
            &Crs::from_user("EPSG:32617").unwrap(),
            &site("EPSG:32617", (0.0, 0.0)),
        )
        .unwrap();
        assert!(same.convergence_deg(0.0, 0.0).is_err());
    }

    #[test]
    fn outer_wkt_authority() {
        let wkt = r#"PROJCS["Amersfoort / RD New",GEOGCS["Amersfoort",AUTHORITY["EPSG","4289"]],UNIT["metre",1],AUTHORITY["EPSG","28992"]]"#;
        assert_eq!(outer_authority(wkt), Some(28992));
        let inner_only = r#"PROJCS["x",GEOGCS["y",AUTHORITY["EPSG","4152"]],UNIT["foot",0.3048,AUTHORITY["EPSG","9002"]]]"#;
        assert_eq!(outer_authority(inner_only), None);
    }
}
