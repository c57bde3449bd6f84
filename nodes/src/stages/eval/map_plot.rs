//! A map figure for the report (a per-stage figure a reviewer asks for): over the orthophoto at
//! native resolution, any of a colour-mapped raster (terrain error, a radio map), footprint
//! outlines against reference outlines, placed objects against the truth's clutter, and the
//! transmitters of a set of links (a triangle per site, a line along each antenna's bearing, the
//! ids beside it).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::artifact::{
    ArtifactType, City, Footprints, Measurements, Ortho, Raster, ReportFiles, Scene,
};
use crate::io::export::figures::maps::{
    Layer, MAX_CATEGORIES, MapFigure, Markers, Palette, Path, SiteMarker, robust_range, view_grid,
};
use crate::io::export::figures::{PALETTE, render};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Colour scale of the raster layer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub enum MapPalette {
    /// Viridis between the 2nd and 98th percentile (levels).
    #[default]
    Viridis,
    /// Blue-white-red symmetric about zero (signed errors).
    Diverging,
    /// One distinct colour per whole value 0, 1, 2, ... (Coverage's `BestServer`), with a legend
    /// of `categories` in place of the colour bar; other values are not drawn.
    Categorical,
}

/// Params of [`MapPlot`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapPlotParams {
    /// The figure's file stem in the report (`<name>.png`, `<name>.svg`).
    pub name: String,
    /// The title over the map.
    pub title: String,
    /// The raster's colour scale.
    #[serde(default)]
    pub palette: MapPalette,
    /// The raster's value range; default the 2nd to 98th percentile (symmetric when diverging).
    #[serde(default)]
    pub range: Option<(f64, f64)>,
    /// The colour bar's caption.
    #[serde(default = "units")]
    pub units: String,
    /// Raster opacity over the orthophoto. Default 0.65.
    #[serde(default = "alpha")]
    pub alpha: f64,
    /// The names of a `Categorical` palette's values 0, 1, 2, ... (for a best-server map, the
    /// transmitter ids in Coverage's order), at most 64. Default none: the values themselves.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub categories: Vec<String>,
}

fn units() -> String {
    "value".into()
}
fn alpha() -> f64 {
    0.65
}

/// The map figure, as `<name>.svg` and `<name>.png` in a report folder (give it to Report's
/// `figures`).
pub struct MapPlot;

/// The radius of the truth's rings, metres.
const MATCH_RADIUS_M: f64 = 1.5;
const OURS: [u8; 3] = [230, 30, 30];
const REFERENCE: [u8; 3] = [0, 200, 230];

impl Stage for MapPlot {
    const KIND: &'static str = "MapPlot";
    // 2: the `transmitters` input, the Categorical palette and its `categories`; a map without
    //    them is drawn byte for byte as before (`a_plain_map_is_drawn_as_before`).
    const VERSION: u32 = 2;
    const DOC: &'static str = "A map figure (SVG and PNG) over the orthophoto: a colour-mapped raster (or categories, e.g. best server), outlines against reference outlines, objects against the truth's clutter, transmitters with their bearings";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::optional("ortho", ArtifactType::Ortho, "the orthophoto under the map"),
        InputSpec::optional("raster", ArtifactType::Raster, "a raster to colour-map"),
        InputSpec::optional(
            "outlines",
            ArtifactType::Footprints,
            "outlines drawn in red",
        ),
        InputSpec::optional(
            "reference",
            ArtifactType::Footprints,
            "reference outlines drawn in cyan",
        ),
        InputSpec::optional(
            "objects",
            ArtifactType::Scene,
            "placed objects (e.g. clutter) as discs by class",
        ),
        InputSpec::optional(
            "city",
            ArtifactType::City,
            "the synthetic truth: its clutter as rings by class",
        ),
        InputSpec::optional(
            "transmitters",
            ArtifactType::Measurements,
            "links whose distinct transmitters are drawn as triangles with a line along each azimuth_deg (compass bearing), labelled by id; co-sited ones (within 1 m) share one",
        ),
    ];
    type Params = MapPlotParams;
    type Output = ReportFiles;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        crate::io::safe_name::check_file_name(&p.name).map_err(|m| ParamError::new("name", m))?;
        if !(p.alpha.is_finite() && (0.0..=1.0).contains(&p.alpha)) {
            return Err(ParamError::new("alpha", "expected an opacity in [0, 1]"));
        }
        if let Some((lo, hi)) = p.range
            && !(lo.is_finite() && hi.is_finite() && lo < hi)
        {
            return Err(ParamError::new(
                "range",
                "expected finite (low, high) with low < high",
            ));
        }
        if !p.categories.is_empty() && p.palette != MapPalette::Categorical {
            return Err(ParamError::new(
                "categories",
                "names the values of a Categorical palette: set `palette: Categorical` or leave categories out",
            ));
        }
        if p.categories.len() > MAX_CATEGORIES || p.categories.iter().any(|c| c.trim().is_empty()) {
            return Err(ParamError::new(
                "categories",
                format!("expected at most {MAX_CATEGORIES} non-empty names"),
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<ReportFiles, StageError> {
        let ortho: Option<&Ortho> = inputs.optional("ortho")?;
        let raster: Option<&Raster> = inputs.optional("raster")?;
        let extent = raster
            .map(|r| r.grid)
            .or(ortho.map(|o| o.grid))
            .ok_or_else(|| {
                StageError::Failed("a map needs a `raster` or an `ortho` to set its extent".into())
            })?;
        let cells: Vec<f64> = raster
            .iter()
            .map(|r| r.grid.cell_m)
            .chain(ortho.map(|o| o.grid.cell_m))
            .collect();
        let view = view_grid(&extent, &cells);
        let palette = match p.palette {
            MapPalette::Viridis => Palette::Viridis,
            MapPalette::Diverging => Palette::Diverging,
            MapPalette::Categorical => Palette::Categorical,
        };
        let layer = raster.map(|r| Layer {
            raster: r,
            palette,
            range: p.range.unwrap_or_else(|| robust_range(r, palette)),
            alpha: if ortho.is_some() { p.alpha } else { 1.0 },
            units: p.units.clone(),
        });
        let mut fig = MapFigure::new(p.title.clone(), view, ortho, layer);
        fig.categories = p.categories.clone();
        if let Some(m) = inputs.optional::<Measurements>("transmitters")? {
            fig.sites = transmitter_sites(m);
            if !fig.sites.is_empty() {
                fig.legend.push(("transmitter, bearing".into(), [0, 0, 0]));
            }
        }
        let rings = |f: &Footprints, color: [u8; 3], width: u32| -> Vec<Path> {
            f.items
                .iter()
                .flat_map(|b| &b.polygons)
                .flat_map(|poly| std::iter::once(&poly.exterior).chain(&poly.holes))
                .map(|ring| Path {
                    points: ring.clone(),
                    closed: true,
                    color,
                    width,
                })
                .collect()
        };
        if let Some(f) = inputs.optional::<Footprints>("reference")? {
            fig.paths.extend(rings(f, REFERENCE, 3));
            fig.legend.push(("reference outlines".into(), REFERENCE));
        }
        if let Some(f) = inputs.optional::<Footprints>("outlines")? {
            fig.paths.extend(rings(f, OURS, 2));
            fig.legend.push(("outlines".into(), OURS));
        }
        // One colour per class across the placed objects and the truth, so a disc inside a ring
        // of its colour is a hit.
        let mut placed: BTreeMap<String, Vec<[f64; 2]>> = BTreeMap::new();
        if let Some(s) = inputs.optional::<Scene>("objects")? {
            for (class, at) in object_centres(s) {
                placed.entry(class).or_default().push(at);
            }
        }
        let mut truth: BTreeMap<String, Vec<[f64; 2]>> = BTreeMap::new();
        if let Some(c) = inputs.optional::<City>("city")? {
            for k in &c.clutter {
                truth.entry(k.kind.clone()).or_default().push(k.center);
            }
        }
        let mut classes: Vec<&String> = placed.keys().chain(truth.keys()).collect();
        classes.sort();
        classes.dedup();
        let colour =
            |c: &str| PALETTE[classes.iter().position(|k| *k == c).unwrap_or(0) % PALETTE.len()];
        // Rings as wide as the 1.5 m within which a placed object counts as found (issue 15's
        // matching radius), so a reader can count hits by eye.
        let ring_px = (MATCH_RADIUS_M / view.cell_m).round().clamp(4.0, 60.0) as u32;
        for (class, pts) in &truth {
            fig.markers.push(Markers {
                points: pts.clone(),
                color: colour(class),
                filled: false,
                radius: ring_px,
                label: format!("{class} (truth, {MATCH_RADIUS_M} m ring)"),
            });
        }
        for (class, pts) in &placed {
            fig.markers.push(Markers {
                points: pts.clone(),
                color: colour(class),
                filled: true,
                radius: 6,
                label: format!("{class} (placed)"),
            });
        }
        let f = render(&fig).map_err(StageError::Failed)?;
        Ok(ReportFiles {
            files: vec![
                (format!("{}.svg", p.name), f.svg.into_bytes()),
                (format!("{}.png", p.name), f.png),
            ],
        })
    }
}

/// Transmitters within this distance of each other share one marker, metres.
const CO_SITED_M: f64 = 1.0;

/// The distinct transmitters of `m` (by id, at the first link naming each) as sites: by id,
/// each joining the first site within [`CO_SITED_M`] of it, with one bearing per distinct
/// azimuth (within 0.5°) and the ids joined as [`join_ids`] does.
fn transmitter_sites(m: &Measurements) -> Vec<SiteMarker> {
    let mut txs: BTreeMap<&str, (f64, f64, Option<f64>)> = BTreeMap::new();
    for l in &m.links {
        let t = &l.tx;
        if t.x.is_finite() && t.y.is_finite() {
            txs.entry(t.id.as_str())
                .or_insert((t.x, t.y, t.azimuth_deg.filter(|a| a.is_finite())));
        }
    }
    let mut sites: Vec<(SiteMarker, Vec<String>)> = Vec::new();
    for (id, (x, y, az)) in txs {
        let k = match sites
            .iter()
            .position(|(s, _)| (s.at[0] - x).hypot(s.at[1] - y) <= CO_SITED_M)
        {
            Some(k) => k,
            None => {
                sites.push((
                    SiteMarker {
                        at: [x, y],
                        bearings_deg: Vec::new(),
                        label: String::new(),
                    },
                    Vec::new(),
                ));
                sites.len() - 1
            }
        };
        let (site, ids) = &mut sites[k];
        ids.push(id.to_owned());
        if let Some(a) = az {
            let a = a.rem_euclid(360.0);
            let near = |b: &f64| {
                let d = (a - b).rem_euclid(360.0);
                d.min(360.0 - d) < 0.5
            };
            if !site.bearings_deg.iter().any(near) {
                site.bearings_deg.push(a);
            }
        }
    }
    sites
        .into_iter()
        .map(|(mut s, ids)| {
            s.label = join_ids(&ids);
            s
        })
        .collect()
}

/// Sorted ids as one label: a run of three or more consecutive single letters as "A-D", else
/// "A,B" or "alpha,beta".
fn join_ids(ids: &[String]) -> String {
    let letters: Vec<u8> = ids
        .iter()
        .filter(|i| i.len() == 1 && i.as_bytes()[0].is_ascii_alphabetic())
        .map(|i| i.as_bytes()[0])
        .collect();
    let run = letters.len() == ids.len()
        && ids.len() >= 3
        && letters.windows(2).all(|w| w[1] == w[0] + 1);
    if run {
        format!("{}-{}", ids[0], ids[ids.len() - 1])
    } else {
        ids.join(",")
    }
}

/// Each object's class (its id before the trailing `-<n>`, parts such as `-trunk` folded into
/// their object) and plan centre (the mean of its vertices), in object order.
fn object_centres(s: &Scene) -> Vec<(String, [f64; 2])> {
    let mut order: Vec<String> = Vec::new();
    let mut sums: BTreeMap<String, ([f64; 2], usize)> = BTreeMap::new();
    for o in &s.objects {
        let base = base_id(&o.id);
        let e = sums.entry(base.to_owned()).or_insert_with(|| {
            order.push(base.to_owned());
            ([0.0; 2], 0)
        });
        for v in o.mesh.positions.iter() {
            e.0[0] += v[0] as f64;
            e.0[1] += v[1] as f64;
            e.1 += 1;
        }
    }
    order
        .into_iter()
        .filter_map(|id| {
            let (s, n) = sums[&id];
            let class = id
                .rsplit_once('-')
                .map_or(id.as_str(), |(c, _)| c)
                .to_owned();
            (n > 0).then(|| (class, [s[0] / n as f64, s[1] / n as f64]))
        })
        .collect()
}

/// `car-3-trunk` -> `car-3`: the id up to and including its first numeric part.
fn base_id(id: &str) -> &str {
    let mut end = 0;
    for (k, part) in id.split('-').enumerate() {
        end += part.len() + usize::from(k > 0);
        if k > 0 && !part.is_empty() && part.bytes().all(|b| b.is_ascii_digit()) {
            return &id[..end];
        }
    }
    id
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Artifact;
    use crate::stage::Slot;
    use std::sync::Arc;

    /// FNV-1a, 64 bits: a fixed hash of a figure's bytes.
    fn fnv(bytes: &[u8]) -> u64 {
        bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
            (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
        })
    }

    /// A radio map as RadioMap makes one: path gain falling away from a point, NaN in a corner.
    fn gain_map() -> Raster {
        let grid = crate::artifact::Grid {
            x0: 0.0,
            y0: 200.0,
            cell_m: 5.0,
            width: 40,
            height: 30,
        };
        let data = (0..grid.len())
            .map(|i| {
                let (c, r) = ((i % 40) as f64, (i / 40) as f64);
                if c + r < 5.0 {
                    f32::NAN
                } else {
                    (-60.0 - 20.0 * ((c - 20.0).hypot(r - 12.0) + 1.0).log10()) as f32
                }
            })
            .collect();
        Raster {
            grid,
            data: crate::artifact::PodVec(data),
        }
    }

    fn plot(p: &MapPlotParams, inputs: &Inputs) -> ReportFiles {
        let site = crate::Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 1.0,
        };
        MapPlot::run(p, inputs, &Ctx::new(&site, &[])).unwrap()
    }

    fn params() -> MapPlotParams {
        serde_json::from_str(r#"{"name": "m", "title": "path gain", "units": "dB"}"#).unwrap()
    }

    /// A map without transmitters or categories is drawn byte for byte as VERSION 1 drew it
    /// (the hashes were taken before either existed): update them only when the drawing of
    /// plain maps changes on purpose.
    #[test]
    fn a_plain_map_is_drawn_as_before() {
        let inputs = Inputs::new().with(
            "raster",
            Slot::Optional(Some(Arc::new(Artifact::Raster(gain_map())))),
        );
        let f = plot(&params(), &inputs);
        let hashes: Vec<String> = f
            .files
            .iter()
            .map(|(n, b)| format!("{n} {:016x}", fnv(b)))
            .collect();
        assert_eq!(hashes, ["m.svg 393fdea84d0b8a40", "m.png 26117e40f13a0372"]);
    }

    fn link(id: &str, x: f64, y: f64, azimuth_deg: Option<f64>) -> crate::artifact::Link {
        use crate::artifact::{Endpoint, Height, Link};
        let end = |id: &str, x, y, azimuth_deg| Endpoint {
            id: id.into(),
            x,
            y,
            z: Height::AboveGround(30.0),
            azimuth_deg,
        };
        Link {
            tx: end(id, x, y, azimuth_deg),
            rx: end("", 50.0, 50.0, None),
            freq_hz: 3.69e9,
            path_loss_db: None,
            rx_power_dbm: None,
            tx_eirp_dbm: None,
            los: None,
        }
    }

    /// Four cells on one mast (half a metre apart) share a marker, "A-D", with one line per
    /// distinct bearing; a lone cell without an azimuth has its own, without a line.
    #[test]
    fn co_sited_transmitters_share_a_marker() {
        let m = Measurements {
            links: vec![
                link("C", 100.5, 100.0, Some(240.0)),
                link("A", 100.0, 100.0, Some(0.0)),
                link("A", 100.0, 100.0, Some(0.0)),
                link("B", 100.0, 100.4, Some(120.0)),
                link("D", 100.0, 100.0, Some(-120.0)),
                link("E", 30.0, 150.0, None),
            ],
        };
        let sites = transmitter_sites(&m);
        assert_eq!(sites.len(), 2);
        assert_eq!(sites[0].label, "A-D");
        assert_eq!(sites[0].at, [100.0, 100.0]);
        assert_eq!(sites[0].bearings_deg, [0.0, 120.0, 240.0]);
        assert_eq!(sites[1].label, "E");
        assert!(sites[1].bearings_deg.is_empty());
        let ids = |v: &[&str]| join_ids(&v.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        assert_eq!(ids(&["A", "B"]), "A,B");
        assert_eq!(ids(&["A", "C", "D"]), "A,C,D");
        assert_eq!(ids(&["cell1", "cell2", "cell3"]), "cell1,cell2,cell3");
    }

    fn pixel(png: &[u8], x: u32, y: u32) -> [u8; 3] {
        image::load_from_memory(png)
            .unwrap()
            .to_rgb8()
            .get_pixel(x, y)
            .0
    }

    /// A best-server map: each server's cells in its own colour, the legend naming them, the
    /// transmitters drawn where they stand with their label.
    #[test]
    fn a_best_server_map_with_its_transmitters() {
        // Server 0 in the west third, 1 in the middle, 2 in the east, none in the top row.
        let mut r = gain_map();
        for (i, v) in r.data.0.iter_mut().enumerate() {
            *v = if i < 40 {
                f32::NAN
            } else {
                ((i % 40) / 14) as f32
            };
        }
        let m = Measurements {
            links: vec![
                link("A", 20.0, 100.0, Some(90.0)),
                link("B", 20.0, 100.0, Some(270.0)),
                link("C", 180.0, 100.0, None),
            ],
        };
        let inputs = Inputs::new()
            .with(
                "raster",
                Slot::Optional(Some(Arc::new(Artifact::Raster(r)))),
            )
            .with(
                "transmitters",
                Slot::Optional(Some(Arc::new(Artifact::Measurements(m)))),
            );
        let p = MapPlotParams {
            palette: MapPalette::Categorical,
            categories: vec!["A".into(), "B".into(), "C".into()],
            ..params()
        };
        assert!(MapPlot::validate(&p).is_ok());
        let f = plot(&p, &inputs);
        let (svg, png) = (
            String::from_utf8(f.files[0].1.clone()).unwrap(),
            &f.files[1].1,
        );
        for label in ["A,B", "transmitter, bearing"] {
            assert!(svg.contains(label), "{label} not in the SVG");
        }
        // The view has whole pixels per 5 m cell; sample cell centres away from the markers.
        let view = view_grid(&gain_map().grid, &[5.0]);
        let px = |x: f64, y: f64| {
            (
                40 + ((x - view.x0) / view.cell_m) as u32,
                80 + ((view.y0 - y) / view.cell_m) as u32,
            )
        };
        use crate::io::export::figures::maps::CATEGORICAL;
        for (x, k) in [(12.5, 0), (102.5, 1), (192.5, 2)] {
            let (u, v) = px(x, 52.5);
            assert_eq!(pixel(png, u, v), CATEGORICAL[k], "server {k}");
        }
        // The triangles are black at the sites.
        for x in [20.0, 180.0] {
            let (u, v) = px(x, 100.0);
            assert_eq!(pixel(png, u, v), [0, 0, 0], "site at x = {x}");
        }
        // Categories need the categorical palette.
        let e = MapPlot::validate(&MapPlotParams {
            categories: vec!["A".into()],
            ..params()
        })
        .unwrap_err();
        assert_eq!(e.field, "categories");
    }

    #[test]
    fn parts_fold_into_their_object() {
        assert_eq!(base_id("car-3"), "car-3");
        assert_eq!(base_id("small_tree-12-trunk"), "small_tree-12");
        assert_eq!(base_id("bus"), "bus");
    }
}
