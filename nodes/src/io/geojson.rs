//! GeoJSON footprints: reading Polygon/MultiPolygon features (with the legacy `crs` member QGIS,
//! GDAL and the Dutch BGT write), and writing them in the site CRS.

use std::path::Path;

use serde_json::{Value, json};

use crate::artifact::{Footprint, Footprints, Polygon};
use crate::io::crs::{Crs, ToSite};
use crate::site::Site;
use crate::stage::StageError;

/// The CRS named by a GeoJSON `crs` member, or WGS84 lon/lat (RFC 7946) when there is none.
pub fn geojson_crs(doc: &Value) -> Result<Crs, String> {
    let Some(name) = doc.pointer("/crs/properties/name").and_then(Value::as_str) else {
        return Crs::from_epsg(4326);
    };
    if name.ends_with("CRS84") {
        return Crs::from_epsg(4326);
    }
    // urn:ogc:def:crs:EPSG::28992, urn:ogc:def:crs:EPSG:6.6:28992, EPSG:28992
    let code = name.rsplit(':').next().unwrap_or("");
    if name.contains("EPSG") {
        Crs::from_user(&format!("EPSG:{code}"))
    } else {
        Err(format!("unrecognised crs name {name:?}"))
    }
}

/// How to read feature properties.
#[derive(Clone, Debug, Default)]
pub struct PropertyNames {
    /// Property holding the id; default: the feature's `id`, else `id`, else the feature index.
    pub id: Option<String>,
    /// Property holding the height in metres; default: `height`, else `height_m`.
    pub height: Option<String>,
}

fn number(v: Option<&Value>) -> Option<f64> {
    match v? {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.trim().trim_end_matches('m').trim().parse().ok(),
        _ => None,
    }
}

/// Reads the Polygon and MultiPolygon features of a GeoJSON file into the site frame.
pub fn read_footprints(
    path: &Path,
    crs: Option<&Crs>,
    names: &PropertyNames,
    site: &Site,
) -> Result<Footprints, StageError> {
    let text = crate::io::open::read_regular_to_string(path)
        .map_err(|e| StageError::bad_input(path, "open", e.to_string()))?;
    let doc: Value = serde_json::from_str(&text).map_err(|e| {
        StageError::bad_input(
            path,
            format!("line {}, column {}", e.line(), e.column()),
            format!("expected JSON: {e}"),
        )
    })?;
    let crs = match crs {
        Some(c) => c.clone(),
        None => geojson_crs(&doc).map_err(|m| StageError::bad_input(path, "crs member", m))?,
    };
    let to_site = ToSite::new(&crs, site).map_err(|m| StageError::bad_input(path, "crs", m))?;
    let features = doc
        .get("features")
        .and_then(Value::as_array)
        .ok_or_else(|| {
            StageError::bad_input(
                path,
                "top level",
                "expected a FeatureCollection with a `features` array",
            )
        })?;
    let mut out = Footprints::default();
    for (i, f) in features.iter().enumerate() {
        let place = || format!("feature {i}");
        let geom = f.get("geometry").unwrap_or(&Value::Null);
        if geom.is_null() {
            continue;
        }
        let coords = geom
            .get("coordinates")
            .ok_or_else(|| StageError::bad_input(path, place(), "geometry without coordinates"))?;
        let polys: Vec<&Value> = match geom.get("type").and_then(Value::as_str) {
            Some("Polygon") => vec![coords],
            Some("MultiPolygon") => coords
                .as_array()
                .map(|a| a.iter().collect())
                .unwrap_or_default(),
            other => {
                return Err(StageError::bad_input(
                    path,
                    place(),
                    format!("expected a Polygon or MultiPolygon footprint, found {other:?}"),
                ));
            }
        };
        let ring = |r: &Value| -> Result<Vec<[f64; 2]>, StageError> {
            r.as_array()
                .ok_or_else(|| {
                    StageError::bad_input(path, place(), "expected a ring of positions")
                })?
                .iter()
                .map(|p| {
                    let (x, y) = (number(p.get(0)), number(p.get(1)));
                    let (Some(x), Some(y)) = (x, y) else {
                        return Err(StageError::bad_input(
                            path,
                            place(),
                            format!("expected a position [x, y], found {p}"),
                        ));
                    };
                    let (sx, sy, _) = to_site
                        .apply(x, y, 0.0)
                        .map_err(|m| StageError::bad_input(path, place(), m))?;
                    Ok([sx, sy])
                })
                .collect()
        };
        let mut polygons = Vec::new();
        for p in polys {
            let rings = p
                .as_array()
                .ok_or_else(|| StageError::bad_input(path, place(), "expected a list of rings"))?;
            let Some((outer, inner)) = rings.split_first() else {
                continue;
            };
            let holes = inner.iter().map(ring).collect::<Result<Vec<_>, _>>()?;
            polygons.extend(Polygon::normalized(ring(outer)?, holes));
        }
        if polygons.is_empty() {
            continue;
        }
        let props = f.get("properties").unwrap_or(&Value::Null);
        let id = match &names.id {
            Some(k) => props.get(k).map(value_text),
            None => f.get("id").or_else(|| props.get("id")).map(value_text),
        }
        .unwrap_or_else(|| i.to_string());
        let height_m = match &names.height {
            Some(k) => number(props.get(k)),
            None => number(props.get("height")).or_else(|| number(props.get("height_m"))),
        };
        out.items.push(Footprint {
            id,
            polygons,
            height_m,
            min_height_m: number(props.get("min_height"))
                .or_else(|| number(props.get("min_height_m"))),
            levels: number(props.get("building:levels")).or_else(|| number(props.get("levels"))),
            min_level: number(props.get("building:min_level")),
        });
    }
    Ok(out)
}

fn value_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Footprints as a GeoJSON FeatureCollection in the site CRS (absolute projected coordinates),
/// with a `crs` member, one feature per building carrying its id and heights.
pub fn write_footprints(f: &Footprints, site: &Site) -> Result<String, String> {
    let epsg = site.epsg()?;
    let (ox, oy) = site.origin;
    let ring = |r: &[[f64; 2]]| {
        let mut pts: Vec<Value> = r
            .iter()
            .map(|p| json!([round_mm(p[0] + ox), round_mm(p[1] + oy)]))
            .collect();
        pts.push(pts[0].clone());
        Value::Array(pts)
    };
    let features: Vec<Value> = f
        .items
        .iter()
        .map(|b| {
            let polys: Vec<Value> = b
                .polygons
                .iter()
                .map(|p| Value::Array(std::iter::once(ring(&p.exterior)).chain(p.holes.iter().map(|h| ring(h))).collect()))
                .collect();
            json!({
                "type": "Feature",
                "id": b.id,
                "properties": {
                    "id": b.id,
                    "height_m": b.height_m,
                    "min_height_m": b.min_height_m,
                    "levels": b.levels,
                    "area_m2": (b.polygons.iter().map(Polygon::area).sum::<f64>() * 100.0).round() / 100.0,
                },
                "geometry": {"type": "MultiPolygon", "coordinates": polys},
            })
        })
        .collect();
    let doc = json!({
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": format!("urn:ogc:def:crs:EPSG::{epsg}")}},
        "features": features,
    });
    serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())
}

/// `v` rounded to the millimetre, as the vector exports write coordinates.
pub(crate) fn round_mm(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}
