//! Ingest of OpenStreetMap buildings from `.osm.pbf` or OSM XML (`.osm`, as the Overpass API and
//! JOSM write it): the footprints and height tags the peers' OSM-extruded scenes are built from
//! (paper Sec. 5 baseline). Both formats become the same [`OsmElement`]s, so what is made of
//! them is written once.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use osmpbf::{Element, ElementReader, RelMemberType};
use serde::{Deserialize, Serialize};

use crate::artifact::point_in_ring;
use crate::artifact::{Footprint, Footprints, Polygon};
use crate::io::crs::{Crs, ToSite};
use crate::io::osm_xml::{Member, OsmElement, OsmKind, for_each_xml_element, is_osm_xml};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`ReadOsmBuildings`]: `path` for one file, or `paths` for several.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadOsmBuildingsParams {
    /// The `.osm.pbf` or OSM XML (`.osm`) file; the format is told by content (XML starts with
    /// `<?xml` or `<osm`), not by name. Compressed XML (`.osm.bz2`, `.osm.gz`) is not read.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub path: String,
    /// Several extracts read as one, e.g. overlapping boxes of one campus. A building (an OSM way
    /// or relation id) found in more than one file is taken from the first file that has it, so
    /// list the file whose tags you trust most first; the duplicates are counted in a warning.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub paths: Vec<String>,
}

/// The most files one node reads (a bound on what a graph can ask for).
pub const MAX_OSM_FILES: usize = 64;

/// Reads every closed way and multipolygon relation tagged `building=*` (or `building:part`), with
/// `height`, `min_height`, `building:levels` and `building:min_level`.
pub struct ReadOsmBuildings;

impl Stage for ReadOsmBuildings {
    const KIND: &'static str = "ReadOsmBuildings";
    // 3: `paths`, several files merged, the first file's copy of a building kept.
    const VERSION: u32 = 3;
    const DOC: &'static str = "OSM buildings from PBF or XML (ways and multipolygons, height/levels tags) into the site frame, Sec. 5";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadOsmBuildingsParams;
    type Output = Footprints;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        match (p.path.is_empty(), p.paths.len()) {
            (true, 0) => Err(ParamError::new(
                "path",
                "expected `path: \"file.osm\"` or `paths: [\"a.osm\", \"b.osm\"]`",
            )),
            (false, n) if n > 0 => Err(ParamError::new(
                "paths",
                "expected `path` or `paths`, not both",
            )),
            (_, n) if n > MAX_OSM_FILES => Err(ParamError::new(
                "paths",
                format!("expected at most {MAX_OSM_FILES} files, found {n}"),
            )),
            _ => Ok(()),
        }
    }

    fn files(p: &Self::Params) -> Vec<FileRef> {
        if p.paths.is_empty() {
            return vec![FileRef {
                field: "path",
                path: p.path.clone(),
            }];
        }
        p.paths
            .iter()
            .map(|path| FileRef {
                field: "paths",
                path: path.clone(),
            })
            .collect()
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Footprints, StageError> {
        let wgs84 = ToSite::new(&Crs::from_epsg(4326).expect("EPSG:4326 is known"), ctx.site)
            .map_err(StageError::Failed)?;
        let files = p.paths.len().max(1);
        let mut parts = Vec::with_capacity(files);
        for i in 0..files {
            let path = ctx.file(i)?;
            let (part, implausible) = read_osm_buildings(path, &wgs84)?;
            if !implausible.is_empty() {
                let shown: Vec<&str> = implausible.iter().map(String::as_str).collect();
                ctx.progress.warn(&format!(
                    "{}: {} building tags left out as no building's (heights up to \
                     {MAX_BUILDING_HEIGHT_M} m, levels up to {MAX_LEVELS}; the buildings keep \
                     their other tags): {}",
                    path.display(),
                    implausible.len(),
                    crate::stage::named_few(&shown)
                ));
            }
            parts.push(part);
        }
        let (merged, duplicates) = first_file_wins(parts);
        if duplicates > 0 {
            ctx.progress.warn(&format!(
                "{duplicates} buildings are in more than one file; each was taken from the first \
                 file listing it"
            ));
        }
        Ok(merged)
    }
}

/// The buildings of several files as one set, in file order; a building id met again in a later
/// file is skipped (and counted), so the first file's tags win.
fn first_file_wins(parts: Vec<Footprints>) -> (Footprints, usize) {
    let mut seen = HashSet::new();
    let mut items = Vec::new();
    let mut duplicates = 0;
    for f in parts.into_iter().flat_map(|p| p.items) {
        if seen.insert(f.id.clone()) {
            items.push(f);
        } else {
            duplicates += 1;
        }
    }
    (Footprints { items }, duplicates)
}

fn is_building<'a>(mut tags: impl Iterator<Item = (&'a str, &'a str)>) -> bool {
    tags.any(|(k, v)| k == "building" && v != "no")
}

/// A length tag in metres: `12`, `12 m`, `12.5m`, `40'`, `40 ft`.
pub fn parse_length(v: &str) -> Option<f64> {
    let v = v.trim();
    let (num, scale) = if let Some(n) = v.strip_suffix("ft").or_else(|| v.strip_suffix('\'')) {
        (n, 0.3048)
    } else {
        (v.strip_suffix('m').unwrap_or(v), 1.0)
    };
    num.trim()
        .replace(',', ".")
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite() && *x >= 0.0)
        .map(|x| x * scale)
}

struct Tags {
    height_m: Option<f64>,
    min_height_m: Option<f64>,
    levels: Option<f64>,
    min_level: Option<f64>,
    /// `key=value` of the tags left out as no building's (out of range, not finite).
    implausible: Vec<String>,
}

/// The tallest building a height tag may give, metres: the tallest standing is 828 m, and a
/// height of 1e300 (or `inf`) would make a solid no tracer can hold.
pub const MAX_BUILDING_HEIGHT_M: f64 = 1000.0;
/// The most levels a `building:levels` tag may give (the most built is 163).
pub const MAX_LEVELS: f64 = 300.0;

fn tags<'a>(it: impl Iterator<Item = (&'a str, &'a str)>) -> Tags {
    let mut t = Tags {
        height_m: None,
        min_height_m: None,
        levels: None,
        min_level: None,
        implausible: Vec::new(),
    };
    // A value that parses but is no building's is left out, as an unparsable one is, and
    // named, so one bad tag costs its building the tag, not the run its scene.
    let mut implausible = Vec::new();
    let mut within = |k: &str, v: &str, x: Option<f64>, most: f64| {
        let x = x?;
        if (0.0..=most).contains(&x) {
            Some(x)
        } else {
            implausible.push(format!("{k}={v}"));
            None
        }
    };
    for (k, v) in it {
        let number = || v.trim().parse::<f64>().ok();
        match k {
            "height" | "building:height" => {
                t.height_m = t
                    .height_m
                    .or(within(k, v, parse_length(v), MAX_BUILDING_HEIGHT_M))
            }
            "min_height" => t.min_height_m = within(k, v, parse_length(v), MAX_BUILDING_HEIGHT_M),
            "building:levels" => t.levels = within(k, v, number(), MAX_LEVELS),
            "building:min_level" => t.min_level = within(k, v, number(), MAX_LEVELS),
            _ => {}
        }
    }
    t.implausible = implausible;
    t
}

fn osm_error(path: &Path, e: osmpbf::Error) -> StageError {
    StageError::bad_input(path, "PBF data", format!("expected an OSM PBF file: {e}"))
}

/// Joins way node lists into closed rings by matching end points; open leftovers are dropped.
fn assemble_rings(mut parts: Vec<Vec<i64>>) -> Vec<Vec<i64>> {
    let mut rings = Vec::new();
    while let Some(mut ring) = parts.pop() {
        while ring.len() > 1 && ring.first() != ring.last() {
            let end = *ring.last().expect("non-empty");
            let Some(k) = parts
                .iter()
                .position(|p| p.first() == Some(&end) || p.last() == Some(&end))
            else {
                break;
            };
            let mut next = parts.swap_remove(k);
            if next.first() != Some(&end) {
                next.reverse();
            }
            ring.extend_from_slice(&next[1..]);
        }
        if ring.len() >= 4 && ring.first() == ring.last() {
            rings.push(ring);
        }
    }
    rings
}

/// Three passes: building relations and their member ways; building ways and members' node ids;
/// the coordinates of just those nodes. Beside the footprints, the tags left out as no
/// building's (`way 12: height=1e300`).
pub fn read_osm_buildings(
    path: &Path,
    wgs84: &ToSite,
) -> Result<(Footprints, Vec<String>), StageError> {
    let rels = read_building_relations(path)?;
    let members: HashSet<i64> = rels
        .iter()
        .flat_map(|r| r.outer.iter().chain(&r.inner))
        .copied()
        .collect();
    let ways = read_ways(path, &members)?;
    let nodes = read_node_coords(path, wgs84, &ways.refs)?;
    let named = |kind: &str, id: i64, t: &Tags| {
        t.implausible
            .iter()
            .map(|tag| format!("{kind} {id}: {tag}"))
            .collect::<Vec<_>>()
    };
    let mut implausible: Vec<String> = (ways.buildings.iter())
        .flat_map(|(id, t)| named("way", *id, t))
        .collect();
    implausible.extend(rels.iter().flat_map(|r| named("relation", r.id, &r.tags)));
    let mut items = way_footprints(ways.buildings, &ways.refs, &nodes);
    items.extend(relation_footprints(rels, &ways.refs, &nodes));
    Ok((Footprints { items }, implausible))
}

/// A multipolygon (or `type=building`) relation tagged as a building.
struct Rel {
    id: i64,
    outer: Vec<i64>,
    inner: Vec<i64>,
    tags: Tags,
}

/// One pass over the file, PBF or XML (told apart by content, not by name), handing `f` every
/// element of kind `want`.
fn for_each_element(
    path: &Path,
    want: OsmKind,
    mut f: impl FnMut(&OsmElement),
) -> Result<(), StageError> {
    if is_osm_xml(path)? {
        return for_each_xml_element(path, want, f);
    }
    let mut refs = Vec::new();
    ElementReader::from_path(path)
        .map_err(|e| osm_error(path, e))?
        .for_each(|el| match (want, el) {
            (OsmKind::Node, Element::Node(n)) => f(&OsmElement::Node {
                id: n.id(),
                lat: n.lat(),
                lon: n.lon(),
            }),
            (OsmKind::Node, Element::DenseNode(n)) => f(&OsmElement::Node {
                id: n.id(),
                lat: n.lat(),
                lon: n.lon(),
            }),
            (OsmKind::Way, Element::Way(w)) => {
                let tags: Vec<(&str, &str)> = w.tags().collect();
                refs.clear();
                refs.extend(w.refs());
                f(&OsmElement::Way {
                    id: w.id(),
                    refs: &refs,
                    tags: &tags,
                })
            }
            (OsmKind::Relation, Element::Relation(r)) => {
                let tags: Vec<(&str, &str)> = r.tags().collect();
                let members: Vec<Member> = r
                    .members()
                    .map(|m| Member {
                        kind: match m.member_type {
                            RelMemberType::Node => OsmKind::Node,
                            RelMemberType::Way => OsmKind::Way,
                            RelMemberType::Relation => OsmKind::Relation,
                        },
                        id: m.member_id,
                        role: m.role().unwrap_or_default(),
                    })
                    .collect();
                f(&OsmElement::Relation {
                    id: r.id(),
                    members: &members,
                    tags: &tags,
                })
            }
            _ => {}
        })
        .map_err(|e| osm_error(path, e))
}

fn read_building_relations(path: &Path) -> Result<Vec<Rel>, StageError> {
    let mut rels = Vec::new();
    for_each_element(path, OsmKind::Relation, |el| {
        if let &OsmElement::Relation {
            id,
            members,
            tags: t,
        } = el
        {
            let it = || t.iter().copied();
            let mp = it().any(|(k, v)| k == "type" && (v == "multipolygon" || v == "building"));
            if mp && is_building(it()) {
                let (mut outer, mut inner) = (Vec::new(), Vec::new());
                for m in members.iter().filter(|m| m.kind == OsmKind::Way) {
                    match m.role {
                        "inner" => inner.push(m.id),
                        _ => outer.push(m.id),
                    }
                }
                rels.push(Rel {
                    id,
                    outer,
                    inner,
                    tags: tags(it()),
                });
            }
        }
    })?;
    Ok(rels)
}

/// The ways footprints are made of.
struct Ways {
    /// The node ids of each building way and relation member.
    refs: HashMap<i64, Vec<i64>>,
    /// Building ways and their tags, in file order.
    buildings: Vec<(i64, Tags)>,
}

fn read_ways(path: &Path, members: &HashSet<i64>) -> Result<Ways, StageError> {
    let mut refs_of: HashMap<i64, Vec<i64>> = HashMap::new();
    let mut buildings = Vec::new();
    for_each_element(path, OsmKind::Way, |el| {
        if let &OsmElement::Way { id, refs, tags: t } = el {
            let building = is_building(t.iter().copied());
            if building || members.contains(&id) {
                refs_of.insert(id, refs.to_vec());
            }
            if building {
                buildings.push((id, tags(t.iter().copied())));
            }
        }
    })?;
    Ok(Ways {
        refs: refs_of,
        buildings,
    })
}

/// Site coordinates of the nodes `ways` use.
fn read_node_coords(
    path: &Path,
    wgs84: &ToSite,
    ways: &HashMap<i64, Vec<i64>>,
) -> Result<HashMap<i64, [f64; 2]>, StageError> {
    let needed: HashSet<i64> = ways.values().flatten().copied().collect();
    let mut nodes: HashMap<i64, [f64; 2]> = HashMap::with_capacity(needed.len());
    let mut failure = None;
    for_each_element(path, OsmKind::Node, |el| {
        let &OsmElement::Node { id, lat, lon } = el else {
            return;
        };
        if needed.contains(&id) {
            match wgs84.apply(lon, lat, 0.0) {
                Ok((x, y, _)) => {
                    nodes.insert(id, [x, y]);
                }
                Err(m) => failure = Some(StageError::bad_input(path, format!("node {id}"), m)),
            }
        }
    })?;
    match failure {
        Some(e) => Err(e),
        None => Ok(nodes),
    }
}

/// Ways whose nodes are missing (clipped at the extract's edge) are skipped, as osmium does.
fn coords(nodes: &HashMap<i64, [f64; 2]>, refs: &[i64]) -> Option<Vec<[f64; 2]>> {
    refs.iter().map(|r| nodes.get(r).copied()).collect()
}

fn footprint(id: String, polygons: Vec<Polygon>, t: Tags) -> Footprint {
    Footprint {
        id,
        polygons,
        height_m: t.height_m,
        min_height_m: t.min_height_m,
        levels: t.levels,
        min_level: t.min_level,
    }
}

/// Closed building ways, each one polygon.
fn way_footprints(
    building_ways: Vec<(i64, Tags)>,
    ways: &HashMap<i64, Vec<i64>>,
    nodes: &HashMap<i64, [f64; 2]>,
) -> Vec<Footprint> {
    let mut out = Vec::new();
    for (id, t) in building_ways {
        let refs = &ways[&id];
        if refs.len() < 4 || refs.first() != refs.last() {
            continue;
        }
        let Some(ring) = coords(nodes, refs) else {
            continue;
        };
        if let Some(p) = Polygon::normalized(ring, Vec::new()) {
            out.push(footprint(format!("w{id}"), vec![p], t));
        }
    }
    out
}

/// Building relations, their member ways joined into rings.
fn relation_footprints(
    rels: Vec<Rel>,
    ways: &HashMap<i64, Vec<i64>>,
    nodes: &HashMap<i64, [f64; 2]>,
) -> Vec<Footprint> {
    let rings =
        |ids: &[i64]| assemble_rings(ids.iter().filter_map(|w| ways.get(w).cloned()).collect());
    let mut out = Vec::new();
    for r in rels {
        let inner: Vec<Vec<[f64; 2]>> = rings(&r.inner)
            .iter()
            .filter_map(|ring| coords(nodes, ring))
            .collect();
        let mut polygons = Vec::new();
        for outer in rings(&r.outer) {
            let Some(outer) = coords(nodes, &outer) else {
                continue;
            };
            // Each inner ring goes to the outer ring that contains its first vertex.
            let holes = inner
                .iter()
                .filter(|h| point_in_ring(h[0], &outer))
                .cloned()
                .collect();
            polygons.extend(Polygon::normalized(outer, holes));
        }
        if !polygons.is_empty() {
            out.push(footprint(format!("r{}", r.id), polygons, r.tags));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn building(id: &str, height_m: Option<f64>) -> Footprint {
        Footprint {
            id: id.into(),
            polygons: vec![],
            height_m,
            min_height_m: None,
            levels: None,
            min_level: None,
        }
    }

    #[test]
    fn the_first_file_listing_a_building_wins() {
        let a = Footprints {
            items: vec![building("w1", Some(12.0)), building("w2", None)],
        };
        let b = Footprints {
            items: vec![building("w1", None), building("w3", Some(4.0))],
        };
        let (m, dup) = first_file_wins(vec![a, b]);
        let got: Vec<(&str, Option<f64>)> = m
            .items
            .iter()
            .map(|f| (f.id.as_str(), f.height_m))
            .collect();
        assert_eq!(got, [("w1", Some(12.0)), ("w2", None), ("w3", Some(4.0))]);
        assert_eq!(dup, 1);
    }

    #[test]
    fn path_or_paths_one_of_them() {
        let p = |path: &str, paths: &[&str]| ReadOsmBuildingsParams {
            path: path.into(),
            paths: paths.iter().map(|s| s.to_string()).collect(),
        };
        assert!(ReadOsmBuildings::validate(&p("a.osm", &[])).is_ok());
        assert!(ReadOsmBuildings::validate(&p("", &["a.osm", "b.osm"])).is_ok());
        assert!(ReadOsmBuildings::validate(&p("", &[])).is_err());
        assert!(ReadOsmBuildings::validate(&p("a.osm", &["b.osm"])).is_err());
        let many: Vec<&str> = vec!["a.osm"; MAX_OSM_FILES + 1];
        assert!(ReadOsmBuildings::validate(&p("", &many)).is_err());
    }

    #[test]
    fn lengths() {
        assert_eq!(parse_length("12"), Some(12.0));
        assert_eq!(parse_length("12.5 m"), Some(12.5));
        assert_eq!(parse_length("40'"), Some(40.0 * 0.3048));
        assert_eq!(parse_length("3,5"), Some(3.5));
        assert_eq!(parse_length("tall"), None);
    }

    #[test]
    fn rings_join_open_ways_in_either_direction() {
        let rings = assemble_rings(vec![
            vec![1, 2, 3],
            vec![5, 4, 3],
            vec![5, 6, 1],
            vec![7, 8],
        ]);
        assert_eq!(rings, vec![vec![5, 6, 1, 2, 3, 4, 5]]);
    }
}
