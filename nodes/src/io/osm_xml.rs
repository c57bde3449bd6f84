//! OpenStreetMap XML (`.osm`, as the Overpass API, JOSM and osmium write it), read as a stream of
//! [`OsmElement`]s: the element type the PBF reader hands over too, so what is made of the
//! elements (`stages::ingest::read_osm`) is written once for both formats.
//!
//! The file is never held whole: quick-xml reads it event by event, each markup bounded to
//! [`MAX_MARKUP_BYTES`] and the nesting to [`MAX_DEPTH`], so memory follows what the caller keeps,
//! not the file's size. Errors name the file, the line and byte, and what was expected.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use quick_xml::Reader;
use quick_xml::XmlVersion;
use quick_xml::events::{BytesStart, Event};

use crate::stage::StageError;

/// One markup (a tag with its attributes, a text run, a comment) of at most this many bytes: OSM
/// XML's longest are a few hundred (a tag value holds at most 255 characters).
pub const MAX_MARKUP_BYTES: u64 = 1 << 20;

/// Elements nested at most this deep (OSM XML uses 3: `osm`, `way`, `nd`).
pub const MAX_DEPTH: usize = 32;

/// The three kinds of OSM element.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OsmKind {
    /// A node: a point with coordinates.
    Node,
    /// A way: an ordered list of nodes.
    Way,
    /// A relation: a list of members with roles.
    Relation,
}

/// A relation member.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Member<'a> {
    /// What it refers to.
    pub kind: OsmKind,
    /// The id of what it refers to.
    pub id: i64,
    /// Its role (`outer`, `inner`, ...; empty when none is given).
    pub role: &'a str,
}

/// One OSM element, its lists borrowed from the reader for the length of one callback.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OsmElement<'a> {
    /// A node, coordinates in degrees (WGS84).
    Node {
        /// Node id.
        id: i64,
        /// Latitude.
        lat: f64,
        /// Longitude.
        lon: f64,
    },
    /// A way.
    Way {
        /// Way id.
        id: i64,
        /// Its node ids in order.
        refs: &'a [i64],
        /// Its tags, key and value.
        tags: &'a [(&'a str, &'a str)],
    },
    /// A relation.
    Relation {
        /// Relation id.
        id: i64,
        /// Its members in order.
        members: &'a [Member<'a>],
        /// Its tags, key and value.
        tags: &'a [(&'a str, &'a str)],
    },
}

/// Whether the file is XML rather than PBF, by its first bytes: `<?xml` or `<osm` after an
/// optional byte-order mark and white space. A PBF file starts with a 4-byte length.
pub fn is_osm_xml(path: &Path) -> Result<bool, StageError> {
    let mut head = Vec::with_capacity(64);
    crate::io::open::open_regular(path)
        .and_then(|f| f.take(64).read_to_end(&mut head))
        .map_err(|e| StageError::bad_input(path, "open", e.to_string()))?;
    let head = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&head);
    let start = head
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(head.len());
    let head = &head[start..];
    Ok(head.starts_with(b"<?xml") || head.starts_with(b"<osm"))
}

/// Latitude or longitude in degrees computed as the PBF reader computes it (nanodegrees times
/// 1e-9), so the same coordinate written as text or as PBF integers gives the same f64. Text with
/// more than 9 decimals or an exponent is parsed as a float.
fn parse_degrees(s: &str) -> Option<f64> {
    let s = s.trim();
    let (neg, digits) = match s.strip_prefix('-') {
        Some(d) => (true, d),
        None => (false, s.strip_prefix('+').unwrap_or(s)),
    };
    let (int, frac) = digits.split_once('.').unwrap_or((digits, ""));
    let plain = |d: &str| d.bytes().all(|b| b.is_ascii_digit());
    let nano = if !int.is_empty() && int.len() <= 3 && frac.len() <= 9 && plain(int) && plain(frac)
    {
        let frac_nano = format!("{frac:0<9}").parse::<i64>().ok()?;
        Some(int.parse::<i64>().ok()? * 1_000_000_000 + frac_nano)
    } else {
        None
    };
    let deg = match nano {
        Some(n) => 1e-9 * (if neg { -n } else { n }) as f64,
        None => s.parse::<f64>().ok()?,
    };
    deg.is_finite().then_some(deg)
}

/// A reader that refuses a markup longer than [`MAX_MARKUP_BYTES`]: quick-xml buffers one event
/// whole, so bounding the bytes read between two events bounds its buffer.
struct Bounded<R> {
    inner: R,
    since_event: u64,
    over: bool,
}

impl<R: BufRead> Read for Bounded<R> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let n = {
            let buf = self.fill_buf()?;
            let n = buf.len().min(out.len());
            out[..n].copy_from_slice(&buf[..n]);
            n
        };
        self.consume(n);
        Ok(n)
    }
}

impl<R: BufRead> BufRead for Bounded<R> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        if self.over {
            return Err(std::io::Error::other("markup too long"));
        }
        self.inner.fill_buf()
    }
    fn consume(&mut self, amt: usize) {
        self.since_event += amt as u64;
        self.over |= self.since_event > MAX_MARKUP_BYTES;
        self.inner.consume(amt);
    }
}

/// The 1-based line holding byte `at` of the file (read again only when an error is reported).
fn line_at(path: &Path, at: u64) -> u64 {
    let Ok(f) = crate::io::open::open_regular(path) else {
        return 0;
    };
    let mut r = BufReader::new(f.take(at));
    let (mut lines, mut buf) = (1u64, [0u8; 1 << 16]);
    while let Ok(n) = r.read(&mut buf) {
        if n == 0 {
            break;
        }
        lines += buf[..n].iter().filter(|&&b| b == b'\n').count() as u64;
    }
    lines
}

fn error_at(path: &Path, at: u64, expected: impl Into<String>) -> StageError {
    StageError::bad_input(
        path,
        format!("line {}, byte {at}", line_at(path, at)),
        expected,
    )
}

/// The element being read: its kind, id, and what its children added.
#[derive(Default)]
struct Open {
    kind: Option<OsmKind>,
    id: i64,
    lat_lon: Option<(f64, f64)>,
    refs: Vec<i64>,
    tags: Vec<(String, String)>,
    members: Vec<(OsmKind, i64, String)>,
}

impl Open {
    fn element<R>(&self, f: &mut impl FnMut(&OsmElement) -> R) -> Option<R> {
        let tags: Vec<(&str, &str)> = self
            .tags
            .iter()
            .map(|(k, v)| (k.as_str(), v.as_str()))
            .collect();
        let el = match self.kind? {
            // A node without coordinates (deleted, or written by `out ids`) places nothing.
            OsmKind::Node => {
                let (lat, lon) = self.lat_lon?;
                OsmElement::Node {
                    id: self.id,
                    lat,
                    lon,
                }
            }
            OsmKind::Way => OsmElement::Way {
                id: self.id,
                refs: &self.refs,
                tags: &tags,
            },
            OsmKind::Relation => {
                let members: Vec<Member> = self
                    .members
                    .iter()
                    .map(|(kind, id, role)| Member {
                        kind: *kind,
                        id: *id,
                        role,
                    })
                    .collect();
                return Some(f(&OsmElement::Relation {
                    id: self.id,
                    members: &members,
                    tags: &tags,
                }));
            }
        };
        Some(f(&el))
    }
}

/// One attribute's value, unescaped, or None when absent.
fn attr(e: &BytesStart, key: &str) -> Result<Option<String>, String> {
    for a in e.attributes() {
        let a = a.map_err(|e| format!("well-formed attributes ({e})"))?;
        if a.key.as_ref() == key {
            return a
                .normalized_value(XmlVersion::Implicit1_0)
                .map(|v| Some(v.into_owned()))
                .map_err(|e| format!("a valid attribute value ({e})"));
        }
    }
    Ok(None)
}

fn name_of(e: &BytesStart) -> String {
    e.name().as_ref().to_string()
}

/// A required whole-number attribute (an id or a reference).
fn id_attr(e: &BytesStart, key: &str) -> Result<i64, String> {
    let v = attr(e, key)?;
    let what = || format!("<{}> with a whole-number {key} attribute", name_of(e));
    match v {
        Some(v) => v
            .trim()
            .parse()
            .map_err(|_| format!("{}, found {key}={v:?}", what())),
        None => Err(format!("{}, found none", what())),
    }
}

/// Reads what a start (or empty) element at `depth` (1 = a child of `<osm>`) adds to `open`.
fn start(e: &BytesStart, depth: usize, want: OsmKind, open: &mut Open) -> Result<(), String> {
    let name = e.name();
    let name = name.as_ref();
    if depth == 0 {
        return match name {
            "osm" => Ok(()),
            _ => Err(format!("an <osm> root element, found <{}>", name_of(e))),
        };
    }
    if depth == 1 {
        *open = Open::default();
        let kind = match name {
            "node" => OsmKind::Node,
            "way" => OsmKind::Way,
            "relation" => OsmKind::Relation,
            // bounds, note, meta, changeset, Overpass's area: nothing to read.
            _ => return Ok(()),
        };
        if kind != want {
            return Ok(());
        }
        open.kind = Some(kind);
        open.id = id_attr(e, "id")?;
        if kind == OsmKind::Node && attr(e, "visible")?.as_deref() != Some("false") {
            let (lat, lon) = (attr(e, "lat")?, attr(e, "lon")?);
            if let (Some(lat), Some(lon)) = (lat, lon) {
                let deg = |v: &str, key: &str, limit: f64| {
                    parse_degrees(v)
                        .filter(|d| d.abs() <= limit)
                        .ok_or_else(|| {
                            format!(
                                "a {key} in degrees within ±{limit} on node {}, found {v:?}",
                                open.id
                            )
                        })
                };
                open.lat_lon = Some((deg(&lat, "lat", 90.0)?, deg(&lon, "lon", 180.0)?));
            }
        }
        return Ok(());
    }
    if depth != 2 || open.kind.is_none() {
        return Ok(());
    }
    match name {
        "tag" => {
            let k = attr(e, "k")?.ok_or("<tag> with a k attribute, found none")?;
            let v = attr(e, "v")?.ok_or("<tag> with a v attribute, found none")?;
            open.tags.push((k, v));
        }
        "nd" if open.kind == Some(OsmKind::Way) => open.refs.push(id_attr(e, "ref")?),
        "member" if open.kind == Some(OsmKind::Relation) => {
            let kind = match attr(e, "type")?.as_deref() {
                Some("node") => OsmKind::Node,
                Some("way") => OsmKind::Way,
                Some("relation") => OsmKind::Relation,
                t => {
                    return Err(format!(
                        "<member> of type node, way or relation, found {t:?}"
                    ));
                }
            };
            let role = attr(e, "role")?.unwrap_or_default();
            open.members.push((kind, id_attr(e, "ref")?, role));
        }
        _ => {}
    }
    Ok(())
}

/// Calls `f` on every element of kind `want` in `path`, in file order. The rest of the file is
/// checked as XML (well-formed, bounded) but not interpreted.
pub fn for_each_xml_element(
    path: &Path,
    want: OsmKind,
    mut f: impl FnMut(&OsmElement),
) -> Result<(), StageError> {
    let file = crate::io::open::open_regular(path)
        .map_err(|e| StageError::bad_input(path, "open", e.to_string()))?;
    let mut reader = Reader::from_reader(Bounded {
        inner: BufReader::with_capacity(1 << 16, file),
        since_event: 0,
        over: false,
    });
    let (mut buf, mut depth, mut open, mut seen_root) =
        (Vec::new(), 0usize, Open::default(), false);
    loop {
        reader.get_mut().since_event = 0;
        buf.clear();
        let at = reader.buffer_position();
        let event = match reader.read_event_into(&mut buf) {
            Ok(e) => e,
            Err(_) if reader.get_ref().over => {
                return Err(error_at(
                    path,
                    at,
                    format!(
                        "OSM XML markup of at most {MAX_MARKUP_BYTES} bytes, found a longer one"
                    ),
                ));
            }
            Err(e) => {
                return Err(error_at(
                    path,
                    reader.error_position(),
                    format!("well-formed OSM XML: {e}"),
                ));
            }
        };
        let bad = |m: String| error_at(path, at, m);
        match event {
            Event::Start(e) | Event::Empty(e) if depth == 0 && seen_root => {
                return Err(bad(format!(
                    "one <osm> root element, found another element <{}> after it",
                    name_of(&e)
                )));
            }
            Event::Start(e) => {
                if depth >= MAX_DEPTH {
                    return Err(bad(format!("elements nested at most {MAX_DEPTH} deep")));
                }
                start(&e, depth, want, &mut open).map_err(bad)?;
                seen_root = true;
                depth += 1;
            }
            Event::Empty(e) => {
                start(&e, depth, want, &mut open).map_err(bad)?;
                seen_root = true;
                if depth == 1 {
                    open.element(&mut f);
                    open.kind = None;
                }
            }
            Event::End(_) => {
                depth = depth.saturating_sub(1);
                if depth == 1 {
                    open.element(&mut f);
                    open.kind = None;
                }
            }
            Event::Text(t) if depth == 0 && !t.as_ref().trim().is_empty() => {
                return Err(bad("nothing but markup outside the <osm> element".into()));
            }
            Event::Eof if !seen_root => {
                return Err(bad("an <osm> root element, found none".into()));
            }
            Event::Eof if depth > 0 => {
                return Err(bad(format!(
                    "well-formed OSM XML: {depth} elements still open where the file ends (cut short?)"
                )));
            }
            Event::Eof => return Ok(()),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degrees_as_the_pbf_reader_computes_them() {
        // 60.1701234 as PBF nanodegrees is 60170123400 * 1e-9, which is not the nearest double
        // to 60.1701234 that `str::parse` gives; the reader must match the PBF one.
        for (text, nano) in [
            ("60.1701234", 60_170_123_400i64),
            ("-78.9271730", -78_927_173_000),
            ("0.0000001", 100),
            ("24", 24_000_000_000),
            ("-0.5", -500_000_000),
        ] {
            assert_eq!(parse_degrees(text), Some(1e-9 * nano as f64), "{text}");
        }
        assert_eq!(parse_degrees("1e1"), Some(10.0));
        assert_eq!(parse_degrees("60.17012345678901"), Some(60.17012345678901));
        assert_eq!(parse_degrees("north"), None);
        assert_eq!(parse_degrees("NaN"), None);
        assert_eq!(parse_degrees(""), None);
    }
}
