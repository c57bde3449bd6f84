//! Relief layers as an atlas a person can open: every chart that carries a value packed into one
//! image: `relief.exr` with a channel per layer (exposure, the recessed and protruding evidence,
//! their posteriors of eq. (4), and Delta where a source mesh was given; NaN where a layer has no
//! value), `posterior.png` (white flat, blue recessed, red protruding, grey unobserved) and
//! `relief.json` saying where each chart sits.

use image::{ImageBuffer, Rgba, RgbaImage};
use serde_json::json;

use super::atlas::{AtlasLayout, png};
use crate::artifact::{ReliefLayers, ReliefSet, SparseLayer};
use crate::io::exr_io::write_exr_zip;

/// Colour of a texel with no posterior (unobserved, no mesh).
const UNOBSERVED: [u8; 4] = [150, 150, 150, 255];

/// The layers of `l` as (channel name, layer), Delta only with a mesh.
fn channels(l: &ReliefLayers, with_mesh: bool) -> Vec<(&'static str, &SparseLayer)> {
    let mut c = vec![
        ("exposure", &l.exposure),
        ("recessed", &l.recessed),
        ("protruding", &l.protruding),
        ("pr_recessed", &l.pr_recessed),
        ("pr_protruding", &l.pr_protruding),
    ];
    if with_mesh {
        c.push(("delta", &l.delta));
    }
    c
}

/// The colour of a texel's posterior: white for flat, toward blue as Pr(recessed) grows and
/// toward red as Pr(protruding) does.
fn posterior_colour(recessed: f32, protruding: f32) -> [u8; 4] {
    if !(recessed.is_finite() && protruding.is_finite()) {
        return UNOBSERVED;
    }
    let (r, p) = (recessed.clamp(0.0, 1.0), protruding.clamp(0.0, 1.0));
    let c = |v: f32| (255.0 * v.clamp(0.0, 1.0)).round() as u8;
    [c(1.0 - r), c(1.0 - r - p), c(1.0 - p), 255]
}

/// The atlas folder of `r`. Charts whose layers hold no value at all (no view saw them, no mesh
/// reached them) are left out; `relief.json` names the chart each packed grid belongs to.
pub fn write_relief_atlas(r: &ReliefSet) -> Result<Vec<(String, Vec<u8>)>, String> {
    let packed: Vec<(usize, &ReliefLayers)> = r
        .layers
        .iter()
        .enumerate()
        .filter(|(_, l)| {
            channels(l, r.with_mesh)
                .iter()
                .any(|(_, s)| !s.values.is_empty())
        })
        .collect();
    let sizes: Vec<(u32, u32)> = packed.iter().map(|(_, l)| (l.width, l.height)).collect();
    let layout = AtlasLayout::of_sizes(&sizes)?;
    let (w, h) = (layout.width, layout.height);
    let n = (w as usize) * (h as usize);
    let names: Vec<&str> = channels(&ReliefLayers::default(), r.with_mesh)
        .iter()
        .map(|(name, _)| *name)
        .collect();
    let mut planes: Vec<Vec<f32>> = vec![vec![f32::NAN; n]; names.len()];
    let mut picture: RgbaImage = ImageBuffer::from_pixel(w, h, Rgba([0; 4]));
    for (slot, (_, l)) in packed.iter().enumerate() {
        let layers = channels(l, r.with_mesh);
        // Unobserved first, then every kept value where it lies.
        for j in 0..l.height {
            for i in 0..l.width {
                let (x, y) = layout.pixel(slot, l.height, i, j);
                picture.put_pixel(x, y, Rgba(UNOBSERVED));
                for (plane, (_, layer)) in planes.iter_mut().zip(&layers) {
                    plane[(y * w + x) as usize] = layer.fill;
                }
            }
        }
        for (plane, (_, layer)) in planes.iter_mut().zip(&layers) {
            for (k, v) in layer.kept() {
                let (i, j) = ((k % l.width as usize) as u32, (k / l.width as usize) as u32);
                let (x, y) = layout.pixel(slot, l.height, i, j);
                plane[(y * w + x) as usize] = v;
            }
        }
        for (k, rec) in l.pr_recessed.kept() {
            let (i, j) = ((k % l.width as usize) as u32, (k / l.width as usize) as u32);
            let (x, y) = layout.pixel(slot, l.height, i, j);
            picture.put_pixel(x, y, Rgba(posterior_colour(rec, l.pr_protruding.get(k))));
        }
    }
    let index = json!({
        "width": w,
        "height": h,
        "note": "chart k's texel (i, j) is at atlas pixel (x + i, y + height - 1 - j); relief.exr holds one channel per layer (NaN where the layer has no value, 0 exposure where no view saw the texel); posterior.png is white where flat, blue where recessed, red where protruding, grey where unobserved, transparent between charts",
        "channels": names,
        "with_mesh": r.with_mesh,
        "charts": packed.iter().zip(&layout.at).map(|((ci, l), &(x, y))| json!({
            "chart": ci, "x": x, "y": y, "width": l.width, "height": l.height,
        })).collect::<Vec<_>>(),
        "stats": r.stats,
    });
    Ok(vec![
        (
            "relief.json".into(),
            serde_json::to_vec_pretty(&index).map_err(|e| e.to_string())?,
        ),
        (
            "relief.exr".into(),
            write_exr_zip(
                w as usize,
                h as usize,
                names.iter().copied().zip(planes).collect(),
            )?,
        ),
        ("posterior.png".into(), png(&picture)?),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::exr_io::read_exr;

    /// A 3 x 2 chart: texel 0 observed flat, texel 4 observed recessed, texel 5 seen under the
    /// threshold (exposure only), the rest unseen.
    fn seen_chart() -> ReliefLayers {
        let nan = f32::NAN;
        let dense = |v: [f32; 6], fill| SparseLayer::from_dense(&v, fill);
        ReliefLayers {
            width: 3,
            height: 2,
            exposure: dense([2.0, 0.0, 0.0, 0.0, 3.0, 0.5], 0.0),
            recessed: dense([0.0, nan, nan, nan, 0.8, nan], nan),
            protruding: dense([0.05, nan, nan, nan, 0.0, nan], nan),
            delta: SparseLayer::filled(nan, 0),
            pr_recessed: dense([0.02, nan, nan, nan, 0.9, nan], nan),
            pr_protruding: dense([0.03, nan, nan, nan, 0.01, nan], nan),
        }
    }

    #[test]
    fn the_atlas_holds_every_kept_value_where_its_texel_lies() {
        let unseen = ReliefLayers {
            width: 50,
            height: 40,
            exposure: SparseLayer::filled(0.0, 2000),
            recessed: SparseLayer::filled(f32::NAN, 2000),
            protruding: SparseLayer::filled(f32::NAN, 2000),
            delta: SparseLayer::filled(f32::NAN, 0),
            pr_recessed: SparseLayer::filled(f32::NAN, 2000),
            pr_protruding: SparseLayer::filled(f32::NAN, 2000),
        };
        let r = ReliefSet {
            layers: vec![unseen, seen_chart()],
            ..Default::default()
        };
        let files = write_relief_atlas(&r).unwrap();
        let get = |name: &str| &files.iter().find(|(n, _)| n == name).unwrap().1;
        let index: serde_json::Value = serde_json::from_slice(get("relief.json")).unwrap();
        // The unseen chart is left out; the seen one is chart 1.
        let charts = index["charts"].as_array().unwrap();
        assert_eq!(charts.len(), 1);
        assert_eq!(charts[0]["chart"], 1);
        let (x0, y0) = (
            charts[0]["x"].as_u64().unwrap() as usize,
            charts[0]["y"].as_u64().unwrap() as usize,
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("relief.exr");
        std::fs::write(&path, get("relief.exr")).unwrap();
        let (w, _, read) = read_exr(&path).unwrap();
        let channel = |name: &str| &read.iter().find(|(n, _)| n == name).unwrap().1;
        assert!(read.iter().all(|(n, _)| n != "delta"));
        // Texel (i, j) of the 2-row chart sits at (x0 + i, y0 + 1 - j).
        let at = |i: usize, j: usize| (y0 + 1 - j) * w + x0 + i;
        let l = seen_chart();
        for k in 0..6 {
            let (i, j) = (k % 3, k / 3);
            for (name, layer) in channels(&l, false) {
                let (got, want) = (channel(name)[at(i, j)], layer.get(k));
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "{name} at texel {k}: {got} against {want}"
                );
            }
        }
        // The picture: recessed texel blue-ish, flat texel near white, unobserved grey.
        let img = image::load_from_memory(get("posterior.png"))
            .unwrap()
            .to_rgba8();
        let px = |i: usize, j: usize| img.get_pixel((x0 + i) as u32, (y0 + 1 - j) as u32).0;
        assert_eq!(px(1, 1), [26, 23, 252, 255]);
        assert_eq!(px(0, 0), [250, 242, 247, 255]);
        assert_eq!(px(1, 0), UNOBSERVED);
    }
}
