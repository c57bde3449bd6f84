//! Façade relief written beside the mesh: every instance with the evidence that decided it, as
//! JSON (site frame) or GeoJSON (polygons with heights in the site's CRS).

use serde_json::{Value, json};

use crate::artifact::{ReliefInstance, ReliefSet};
use crate::site::Site;

fn evidence(i: &ReliefInstance) -> Value {
    json!({
        "building": i.building,
        "chart": i.chart,
        "relief": if i.sign < 0 { "recessed" } else { "protruding" },
        "class": i.class,
        "depth_m": i.depth_m,
        "measured_depth_m": i.measured_depth_m,
        "posterior": i.posterior,
        "exposure": i.exposure,
        "texels": i.texels,
        "views": i.views,
        "delta_agreement": i.delta_agreement,
    })
}

/// The instances and the run's counts, site-frame corners, metres.
pub fn relief_json(r: &ReliefSet) -> Result<Vec<u8>, String> {
    let instances: Vec<Value> = r
        .instances
        .iter()
        .map(|i| {
            let mut v = evidence(i);
            v["rect_texels"] = json!(i.rect);
            v["corners"] = json!(i.corners);
            v
        })
        .collect();
    let mut s = serde_json::to_string_pretty(&json!({
        "with_mesh": r.with_mesh,
        "stats": r.stats,
        "instances": instances,
    }))
    .map_err(|e| e.to_string())?;
    s.push('\n');
    Ok(s.into_bytes())
}

/// One Polygon feature per instance: its four corners (closed ring) in the site's CRS, with
/// heights, and the evidence as properties.
pub fn relief_geojson(r: &ReliefSet, site: &Site) -> Result<Vec<u8>, String> {
    let (ox, oy) = site.origin;
    let features: Vec<Value> = r
        .instances
        .iter()
        .map(|i| {
            let mut ring: Vec<[f64; 3]> = i
                .corners
                .iter()
                .map(|c| [c[0] + ox, c[1] + oy, c[2]])
                .collect();
            ring.push(ring[0]);
            json!({
                "type": "Feature",
                "geometry": { "type": "Polygon", "coordinates": [ring] },
                "properties": evidence(i),
            })
        })
        .collect();
    let mut s = serde_json::to_string_pretty(&json!({
        "type": "FeatureCollection",
        "crs": { "type": "name", "properties": { "name": crs_urn(&site.crs) } },
        "features": features,
    }))
    .map_err(|e| e.to_string())?;
    s.push('\n');
    Ok(s.into_bytes())
}

/// `EPSG:32618` as the OGC URN GeoJSON readers expect; any other CRS string as given.
fn crs_urn(crs: &str) -> String {
    match crs.strip_prefix("EPSG:") {
        Some(code) => format!("urn:ogc:def:crs:EPSG::{code}"),
        None => crs.to_owned(),
    }
}
