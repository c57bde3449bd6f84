//! `report.html`: Table 1, the plots and the twin in 3D, in one file that works offline and from
//! `file://` (browsers refuse to load module files there, so three.js is inlined, its ES-module
//! export list turned into a plain object).
//!
//! The 3D view draws each scene given (the twin, the truth, the baseline: toggles) with ITU-class
//! false colours, the radio map draped over the terrain, and the measured points coloured by the
//! first model's error; a click on a point shows its link's measurement and every model's
//! prediction. When the first frame is drawn the page sets `data-ready` on `<body>`, and
//! `data-nonblank` to the share of canvas pixels that differ from the background, so a headless
//! browser can check it; script errors are listed in `#errors` and set `data-errors`.

use serde_json::{Value, json};

use super::colormap::viridis;
use super::glb::material_color;
use crate::artifact::Material;
use crate::artifact::{Metrics, ObjectClass, Raster, Scene};
use crate::geom::raycast::SceneRays;
use crate::rf::calibration;

/// three.js (MIT; `nodes/assets/three/`, fetched by `scripts/vendor_three.sh`).
const THREE_JS: &str = include_str!("../../../assets/three/three.module.min.js");
const THREE_LICENSE: &str = include_str!("../../../assets/three/LICENSE");
const VIEWER_JS: &str = include_str!("report_viewer.js");

/// Triangles the 3D view carries over all its scenes (about 36 bytes each in the page).
const MAX_TRIANGLES: usize = 6_000_000;

/// One row of the score table.
pub struct TableRow {
    /// Metric label.
    pub label: String,
    /// One value per model, formatted.
    pub values: Vec<String>,
    /// The best model's column, bolded.
    pub best: Option<usize>,
}

/// A measured link as the 3D view shows it: at the receiver.
pub struct LinkPoint {
    /// Receiver, site frame (z on the ground).
    pub at: [f64; 3],
    /// Measured path loss with the model's offset taken out, dB.
    pub measured: Option<f64>,
    /// Each model's prediction, dB.
    pub predicted: Vec<Option<f64>>,
}

/// What the page shows.
pub struct Page<'a> {
    /// The site's name.
    pub site: &'a str,
    /// A paragraph under the title.
    pub intro: &'a str,
    /// How each figure of the table is computed, one paragraph each, shown under it.
    pub definitions: &'a [String],
    /// Column names.
    pub models: &'a [String],
    /// Table 1.
    pub table: &'a [TableRow],
    /// Why links were left out of the scores, per model (same columns); nothing when empty.
    pub left_out: &'a [TableRow],
    /// Plot files, relative to the page.
    pub plots: &'a [&'a str],
    /// Text shown under a plot, by its file: what it draws when that is not said elsewhere.
    pub plot_notes: &'a [(&'a str, String)],
    /// Scenes to draw, by name; the first is shown at load, and its terrain carries the map and
    /// the points.
    pub scenes: &'a [(&'a str, &'a Scene)],
    /// A radio map (dB) to drape over the terrain.
    pub radio_map: Option<&'a Raster>,
    /// The measured links.
    pub points: &'a [LinkPoint],
    /// Stages' reports (a carve's outcomes, the clutter's counts), by name: what each stage
    /// did, shown after the plots.
    pub evidence: &'a [(&'a str, &'a Metrics)],
}

/// A table of rows by model, each row's best value marked.
fn model_table(models: &[String], rows: &[TableRow]) -> String {
    let mut table = String::from("<table><thead><tr><th>metric</th>");
    for m in models {
        table += &format!("<th>{}</th>", esc(m));
    }
    table += "</tr></thead><tbody>";
    for r in rows {
        table += &format!("<tr><td>{}</td>", esc(&r.label));
        for (k, v) in r.values.iter().enumerate() {
            if r.best == Some(k) {
                table += &format!("<td class=\"best\">{}</td>", esc(v));
            } else {
                table += &format!("<td>{}</td>", esc(v));
            }
        }
        table += "</tr>";
    }
    table += "</tbody></table>";
    table
}

/// The definitions under Table 1 as a list; nothing without any.
fn definitions_list(defs: &[String]) -> String {
    if defs.is_empty() {
        return String::new();
    }
    let items: String = defs
        .iter()
        .map(|d| format!("<li>{}</li>", esc(d)))
        .collect();
    format!("<p>How each figure is computed:</p><ul>{items}</ul>")
}

/// The stages' reports as one table each (name, value), in a section of its own; nothing when
/// the graph gives none.
fn evidence_section(evidence: &[(&str, &Metrics)]) -> String {
    if evidence.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "<section><h2>Stage evidence</h2><p>What each stage did, from its own reports.</p>",
    );
    for (name, m) in evidence {
        let fitted = calibration::report_rows(m);
        if !fitted.is_empty() {
            out += &format!(
                "<h3>{}: calibrated parameters</h3><table><thead><tr>",
                esc(name)
            );
            for c in calibration::REPORT_COLUMNS {
                out += &format!("<th>{}</th>", esc(c));
            }
            out += "</tr></thead><tbody>";
            for row in fitted {
                out += "<tr>";
                for cell in row {
                    out += &format!("<td>{}</td>", esc(&cell));
                }
                out += "</tr>";
            }
            out += "</tbody></table>";
        }
        out += &format!(
            "<h3>{}</h3><table><thead><tr><th>figure</th><th>value</th></tr></thead><tbody>",
            esc(name)
        );
        for (k, v) in &m.values {
            out += &format!("<tr><td>{}</td><td>{}</td></tr>", esc(k), esc(&number(*v)));
        }
        out += "</tbody></table>";
    }
    out + "</section>\n"
}

/// A report's value as a reader wants it: counts whole, other figures to four significant
/// digits.
pub fn number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{v:.0}")
    } else if v.is_finite() {
        let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v}")
    }
}

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Standard base64 (RFC 4648) with padding.
pub(super) fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// three.js as a script that defines `THREE`: the module's closing `export{a as B, ...}` becomes
/// `return {B: a, ...}` of a function wrapping the whole file.
fn three_as_object() -> Result<String, String> {
    let at = THREE_JS
        .rfind("export{")
        .ok_or("the vendored three.js has no export list")?;
    let list = THREE_JS[at + "export{".len()..]
        .trim_end()
        .trim_end_matches(';')
        .trim_end_matches('}');
    let fields: Vec<String> = list
        .split(',')
        .map(|item| match item.split_once(" as ") {
            Some((local, name)) => format!("{}:{}", name.trim(), local.trim()),
            None => item.trim().to_owned(),
        })
        .collect();
    Ok(format!(
        "const THREE=(()=>{{{}\nreturn {{{}}};}})();",
        &THREE_JS[..at],
        fields.join(",")
    ))
}

/// Each scene's triangles grouped by material, as base64 little-endian f32 positions and u32
/// indices.
fn scene_json(name: &str, scene: &Scene) -> Value {
    let mut by_material: std::collections::BTreeMap<u8, (Vec<f32>, Vec<u32>)> = Default::default();
    for obj in &scene.objects {
        let m = &obj.mesh;
        // Per material, the group index of each of this object's vertices, once used.
        let mut remap: std::collections::BTreeMap<u8, Vec<u32>> = Default::default();
        for (t, &mat) in m.triangles.iter().zip(m.materials.iter()) {
            if t.iter().any(|&v| v as usize >= m.positions.len()) {
                continue;
            }
            let (pos, idx) = by_material.entry(mat).or_default();
            let map = remap
                .entry(mat)
                .or_insert_with(|| vec![u32::MAX; m.positions.len()]);
            for &v in t {
                if map[v as usize] == u32::MAX {
                    map[v as usize] = (pos.len() / 3) as u32;
                    pos.extend_from_slice(&m.positions[v as usize]);
                }
                idx.push(map[v as usize]);
            }
        }
    }
    let groups: Vec<Value> = by_material
        .iter()
        .map(|(&mat, (pos, idx))| {
            let (label, colour) = match Material::from_u8(mat) {
                Some(m) => (
                    m.itu_type().unwrap_or("foliage").to_owned(),
                    material_color(m),
                ),
                None => (format!("material {mat}"), [0.8, 0.2, 0.8]),
            };
            json!({
                "material": label,
                "colour": colour,
                "positions": base64(bytemuck::cast_slice(pos)),
                "indices": base64(bytemuck::cast_slice(idx)),
            })
        })
        .collect();
    json!({"name": name, "groups": groups})
}

/// The ground under (x, y): the highest terrain hit straight down, if any.
fn ground(terrain: &SceneRays, x: f64, y: f64) -> Option<f64> {
    terrain
        .cast([x as f32, y as f32, 1.0e5], [0.0, 0.0, -1.0], 0.0, 2.0e5)
        .map(|h| 1.0e5 - h.t as f64)
}

/// The radio map as a draped texture: RGBA viridis between the 2nd and 98th percentile
/// (transparent where no ray arrived) and the ground height under every cell centre.
fn radio_map_json(map: &Raster, terrain: Option<&SceneRays>) -> Result<Value, String> {
    let g = map.grid;
    let mut v: Vec<f32> = map.data.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f32::total_cmp);
    let (lo, hi) = match v.len() {
        0 => (0.0, 1.0),
        n => {
            let q = |p: f64| v[((n - 1) as f64 * p).round() as usize] as f64;
            let (a, b) = (q(0.02), q(0.98));
            if b > a { (a, b) } else { (a - 0.5, a + 0.5) }
        }
    };
    let mut img = image::RgbaImage::new(g.width, g.height);
    let mut heights = Vec::with_capacity((g.width * g.height) as usize);
    for row in 0..g.height {
        for col in 0..g.width {
            let x = map.at(col, row);
            let px = if x.is_finite() {
                let [r, gg, b] = viridis((x as f64 - lo) / (hi - lo));
                [r, gg, b, 215]
            } else {
                [0, 0, 0, 0]
            };
            img.put_pixel(col, row, image::Rgba(px));
            let (cx, cy) = g.center(col, row);
            heights.push(terrain.and_then(|t| ground(t, cx, cy)).unwrap_or(0.0) as f32);
        }
    }
    let png = super::atlas::png(&img)?;
    Ok(json!({
        "png": base64(&png),
        "x0": g.x0, "y0": g.y0, "cell": g.cell_m, "width": g.width, "height": g.height,
        "heights": base64(bytemuck::cast_slice(&heights)),
        "lo": lo, "hi": hi,
    }))
}

/// The page.
pub fn report_html(p: &Page) -> Result<String, String> {
    let terrain = p.scenes.first().map(|(_, s)| {
        SceneRays::new(&Scene {
            objects: s
                .objects
                .iter()
                .filter(|o| o.class == ObjectClass::Terrain)
                .cloned()
                .collect(),
        })
    });
    let points: Vec<Value> = p
        .points
        .iter()
        .map(|l| {
            let z = terrain
                .as_ref()
                .and_then(|t| ground(t, l.at[0], l.at[1]))
                .unwrap_or(l.at[2]);
            json!({"at": [l.at[0], l.at[1], z], "measured": l.measured, "predicted": l.predicted})
        })
        .collect();
    // Browsers choke on pages of hundreds of megabytes: scenes past the budget are left out
    // (named in the page), in the order given, so the first (the twin) is kept first.
    let mut budget = MAX_TRIANGLES;
    let mut left_out = Vec::new();
    let mut scenes = Vec::new();
    for (n, s) in p.scenes {
        let tris: usize = s.objects.iter().map(|o| o.mesh.triangles.len()).sum();
        if tris <= budget {
            budget -= tris;
            scenes.push(scene_json(n, s));
        } else {
            left_out.push(format!("{n} ({tris} triangles)"));
        }
    }
    let data = json!({
        "site": p.site,
        "models": p.models,
        "scenes": scenes,
        "left_out": left_out,
        "radio_map": p.radio_map.map(|m| radio_map_json(m, terrain.as_ref())).transpose()?,
        "points": points,
    });
    // In a <script> element, "</" would end it early.
    let data = serde_json::to_string(&data)
        .map_err(|e| e.to_string())?
        .replace("</", "<\\/");

    let table = model_table(p.models, p.table);
    let left_out_links = if p.left_out.is_empty() {
        String::new()
    } else {
        format!(
            "<h3>Links left out of the scores</h3>{}",
            model_table(p.models, p.left_out)
        )
    };
    let plots: String = p
        .plots
        .iter()
        .map(|f| {
            format!(
                "<figure><a href=\"{1}\" title=\"vector version (SVG)\"><img src=\"{0}\" alt=\"{0}\"></a><figcaption>{0} · <a href=\"{1}\">SVG</a>{2}</figcaption></figure>",
                esc(f),
                esc(&f.strip_suffix(".png").map_or_else(|| f.to_string(), |s| format!("{s}.svg"))),
                p.plot_notes
                    .iter()
                    .find(|(n, _)| n == f)
                    .map_or_else(String::new, |(_, t)| format!("<br>{}", esc(t)))
            )
        })
        .collect();
    let evidence = evidence_section(p.evidence);
    Ok(format!(
        r#"<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>KODAMA report: {site}</title>
<style>
body{{font:15px/1.45 system-ui,-apple-system,"Segoe UI",sans-serif;margin:0;color:#1d2430;background:#f7f8fa}}
header,section{{max-width:1200px;margin:0 auto;padding:12px 24px}}
h1{{font-size:26px;margin:18px 0 6px}} h2{{font-size:19px;margin:22px 0 8px}}
table{{border-collapse:collapse;background:#fff;box-shadow:0 1px 3px #0002}}
th,td{{padding:6px 12px;border-bottom:1px solid #e3e6ea;text-align:right}}
th:first-child,td:first-child{{text-align:left}} td.best{{font-weight:700;color:#0b6b3a}}
#viewer{{position:relative;height:640px;background:#eef2f5;border-radius:6px;overflow:hidden;box-shadow:0 1px 3px #0003}}
#c{{width:100%;height:100%;display:block;cursor:grab}}
#panel,#info,#legend{{position:absolute;background:#fffe;border-radius:6px;padding:8px 10px;font-size:13px;box-shadow:0 1px 3px #0003}}
#panel{{top:10px;left:10px}} #panel label{{display:block}}
#info{{top:10px;right:10px;min-width:220px;display:none}} #info table{{box-shadow:none}} #info td,#info th{{padding:2px 6px}}
#legend{{bottom:10px;left:10px;max-width:60%}} .sw{{display:inline-block;width:12px;height:12px;margin:0 4px 0 10px;vertical-align:-1px;border-radius:2px}}
.bar{{display:inline-block;width:140px;height:10px;vertical-align:-1px;margin:0 6px;border-radius:2px}}
figure{{display:inline-block;margin:8px;background:#fff;padding:8px;box-shadow:0 1px 3px #0002}} figure img{{max-width:560px;display:block}}
figcaption{{font-size:12px;color:#667}} #errors{{color:#b00020;white-space:pre-wrap}}
footer{{max-width:1200px;margin:0 auto;padding:12px 24px 40px;color:#667;font-size:12px}}
</style></head>
<body>
<header><h1>KODAMA report: {site}</h1><p>{intro}</p></header>
<section><h2>Table 1</h2>{table}{definitions}{left_out_links}</section>
<section><h2>The twin in 3D</h2>
<p>Drag to orbit, right-drag (or shift-drag) to pan, wheel to zoom; click a measured point for its link.</p>
<div id="viewer"><canvas id="c"></canvas><div id="panel"></div><div id="info"></div><div id="legend"></div></div>
<div id="errors"></div></section>
<section><h2>Plots</h2>{plots}</section>
{evidence}<footer>Written by kodama-dag {version}. The 3D view uses three.js (MIT licence, below).<details><summary>three.js licence</summary><pre>{license}</pre></details></footer>
<script>window.addEventListener('error',e=>{{const d=document.getElementById('errors');d.textContent+=String(e.message)+'\n';document.body.dataset.errors=(+(document.body.dataset.errors||0)+1)}});</script>
<script id="kodama-data" type="application/json">{data}</script>
<script type="module">
{three}
{viewer}
</script>
</body></html>
"#,
        site = esc(p.site),
        intro = esc(p.intro),
        definitions = definitions_list(p.definitions),
        version = env!("CARGO_PKG_VERSION"),
        license = esc(THREE_LICENSE),
        three = three_as_object()?,
        viewer = VIEWER_JS,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (plain, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), enc);
        }
    }

    #[test]
    fn stage_reports_become_escaped_tables_with_readable_numbers() {
        assert_eq!(evidence_section(&[]), "");
        let mut m = Metrics::default();
        m.values.insert("dropped_<thin>".into(), 12.0);
        m.values.insert("median_slope".into(), 1.244732269868257);
        m.values.insert("share".into(), 0.004567);
        let html = evidence_section(&[("Carve & co", &m)]);
        assert!(html.contains("<h3>Carve &amp; co</h3>"), "{html}");
        assert!(
            html.contains("<td>dropped_&lt;thin&gt;</td><td>12</td>"),
            "{html}"
        );
        assert!(
            html.contains("<td>median_slope</td><td>1.245</td>"),
            "{html}"
        );
        assert!(html.contains("<td>share</td><td>0.004567</td>"), "{html}");
        assert_eq!(number(-1.2183483536188164), "-1.218");
        assert_eq!(number(f64::NAN), "NaN");
    }

    /// A Calibrate node's evidence gets a table of what it fitted: the twin's value, the
    /// calibrated one, the prior and bounds, the posterior spread.
    #[test]
    fn a_calibration_becomes_a_table_of_its_parameters() {
        let mut m = Metrics::default();
        for (k, v) in [
            ("calibration/permittivity/concrete", 0.77),
            ("fit/permittivity/concrete/itu_at_first_carrier", 5.24),
            ("fit/permittivity/concrete/prior_width_ln", 1.5f64.ln()),
            ("fit/permittivity/concrete/lo", 1.0 / 3.0),
            ("fit/permittivity/concrete/hi", 3.0),
            ("fit/permittivity/concrete/spread_ln", 0.01),
            ("calibration/height_m/A", 2.5),
            ("fit/height_m/A/prior_width_ln", 3.0),
            ("fit/height_m/A/lo", -6.0),
            ("fit/height_m/A/hi", 6.0),
            ("fit/height_m/A/spread_ln", 0.4),
        ] {
            m.set(k, v);
        }
        let html = evidence_section(&[("calibration", &m)]);
        assert!(
            html.contains("<h3>calibration: calibrated parameters</h3>"),
            "{html}"
        );
        assert!(
            html.contains(
                "<td>permittivity/concrete</td><td>5.24</td><td>4.03 (×0.770)</td>\
                 <td>×/÷1.50</td><td>×0.333 to ×3.00</td><td>×/÷1.01</td>"
            ),
            "{html}"
        );
        assert!(
            html.contains(
                "<td>height_m/A</td><td>as mounted</td><td>+2.50 m</td><td>±3.000 m</td>\
                 <td>-6.00 m to +6.00 m</td><td>±0.400 m</td>"
            ),
            "{html}"
        );
        let plain = evidence_section(&[("counts", &Metrics::default())]);
        assert!(!plain.contains("calibrated parameters"), "{plain}");
    }

    #[test]
    fn three_becomes_an_object_with_its_exports() {
        let s = three_as_object().unwrap();
        assert!(!s.contains("export{"));
        assert!(s.contains("WebGLRenderer:") && s.contains("PerspectiveCamera:"));
    }
}
