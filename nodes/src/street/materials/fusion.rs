//! Per-surface ITU-R P.2040 materials from street-view material maps (paper Sec. 4.2.3): the
//! pixel-class table, instance refinement, eq. (5) per texel and the extension of the dominant
//! material onto what no view saw.

use std::collections::BTreeMap;

use crate::artifact::Material;
use crate::artifact::{
    Chart, ChartKind, ChartLayers, ChartMaterials, ChartSet, MaterialSource, NO_MATERIAL, PodVec,
    View,
};

/// What a pixel labelled with a segmentation class says about a building surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PixelTarget {
    /// A building surface material: votes for it.
    Surface(Material),
    /// A ground medium (P.2040 ground classes, valid 1-10 GHz): never a building surface, so on
    /// a building chart it counts as exposure without a vote.
    Ground(Material),
    /// Something in front of the surface (foliage): neither a vote nor exposure.
    Occluder,
    /// No material information (sky, people, fabric, rubber): exposure without a vote.
    NoVote,
}

/// The default target of each of RMSNet's 20 classes (shared/DESIGN.md): exterior plaster is
/// concrete (render, not plasterboard); asphalt and road marking concrete; ceramic brick;
/// cobblestone marble; sand, gravel, grass, water the three P.2040 grounds; leaf foliage (a volume,
/// never a surface); fabric, rubber, human body, sky no vote. Plastic has no P.2040 class: no vote.
pub fn rmsnet_target(class: &str) -> Option<PixelTarget> {
    use Material as M;
    use PixelTarget::*;
    Some(match class {
        "concrete" | "plaster" | "asphalt" | "road marking" => Surface(M::Concrete),
        "brick" | "ceramic" => Surface(M::Brick),
        "glass" => Surface(M::Glass),
        "metal" => Surface(M::Metal),
        "wood" => Surface(M::Wood),
        "cobblestone" => Surface(M::Marble),
        "sand" => Ground(M::VeryDryGround),
        "gravel" => Ground(M::MediumDryGround),
        "grass" | "water" => Ground(M::WetGround),
        "leaf" => Occluder,
        "fabric/leather" | "rubber" | "human body" | "sky" | "plastic" => NoVote,
        _ => return None,
    })
}

/// A target named in a params table: a P.2040 class (`concrete`, `itu_glass`, ...; the ground
/// classes are ground-only), `foliage` (an occluder) or `none` (no vote).
pub fn parse_target(name: &str) -> Option<PixelTarget> {
    match name {
        "none" => Some(PixelTarget::NoVote),
        "foliage" => Some(PixelTarget::Occluder),
        _ => Material::from_name(name).map(|m| match m {
            Material::VeryDryGround | Material::MediumDryGround | Material::WetGround => {
                PixelTarget::Ground(m)
            }
            Material::Foliage => PixelTarget::Occluder,
            m => PixelTarget::Surface(m),
        }),
    }
}

/// The classes votes index: every P.2040 surface class, named as Sionna names them, at their
/// Material discriminant (foliage, the last, is no surface and has no slot).
pub fn vote_classes() -> Vec<String> {
    Material::ALL
        .iter()
        .filter_map(|m| m.itu_type().map(str::to_owned))
        .collect()
}

/// The view set's classes mapped to targets: the defaults of [`rmsnet_target`] with `overrides`
/// (class name -> target name) on top. Every override must name a class of the view set and a
/// known target; a class with neither a default nor an override is an error.
pub fn class_table(
    view_classes: &[String],
    overrides: &BTreeMap<String, String>,
) -> Result<Vec<PixelTarget>, String> {
    for (k, v) in overrides {
        if !view_classes.contains(k) {
            return Err(format!(
                "class {k:?} is not in the views' material table ({})",
                view_classes.join(", ")
            ));
        }
        if parse_target(v).is_none() {
            return Err(format!(
                "{k:?} -> {v:?}: expected a P.2040 class ({}), \"foliage\" or \"none\"",
                vote_classes().join(", ")
            ));
        }
    }
    view_classes
        .iter()
        .map(|c| {
            overrides
                .get(c)
                .and_then(|t| parse_target(t))
                .or_else(|| rmsnet_target(c))
                .ok_or_else(|| {
                    format!(
                        "the views' material class {c:?} has no default P.2040 class: map it in `classes`"
                    )
                })
        })
        .collect()
}

/// Per-pixel code of a refined material map: a Material discriminant below [`SEEN`].
pub const SEEN: u8 = 254;
/// Per-pixel code: masked (clutter in front, or an occluder class).
pub const MASKED: u8 = 255;

/// What instance refinement did on one view.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RefineStats {
    /// Pixels whose code changed.
    pub pixels: u64,
    /// Instances whose mask was filled.
    pub instances: u64,
}

/// One view's material map as votes on building surfaces: each pixel's class through `table`,
/// clutter-instance pixels masked (when `mask_clutter`), and, inside each architectural instance
/// whose class `refine` lists (e.g. `window` -> glass, metal, wood), the dominant compatible class
/// over the instance's pixels applied throughout its mask (paper Sec. 4.2.3). Codes: Material
/// discriminant, [`SEEN`] (exposure, no vote) or [`MASKED`].
pub fn refine_view(
    view: &View,
    table: &[PixelTarget],
    refine: &BTreeMap<String, Vec<Material>>,
    mask_clutter: bool,
) -> (Vec<u8>, RefineStats) {
    let n = view.width as usize * view.height as usize;
    let clutter = |px: usize| {
        mask_clutter
            && view
                .clutter
                .as_ref()
                .is_some_and(|c| c.ids.get(px).is_some_and(|&id| id != 0))
    };
    let mut codes: Vec<u8> = (0..n)
        .map(|px| {
            if clutter(px) {
                return MASKED;
            }
            let class = view.material.as_ref().and_then(|m| m.get(px)).copied();
            match class.and_then(|c| table.get(c as usize)) {
                Some(PixelTarget::Surface(m)) => *m as u8,
                Some(PixelTarget::Occluder) => MASKED,
                Some(PixelTarget::Ground(_) | PixelTarget::NoVote) | None => SEEN,
            }
        })
        .collect();
    let mut stats = RefineStats::default();
    let Some(arch) = &view.arch else {
        return (codes, stats);
    };
    // Instance id -> compatible classes, for the instances refinement applies to.
    let compatible: BTreeMap<u16, &Vec<Material>> = arch
        .classes
        .iter()
        .filter_map(|(id, class)| refine.get(class).map(|c| (*id, c)))
        .collect();
    if compatible.is_empty() {
        return (codes, stats);
    }
    // Votes per (instance, material) over the instance's unmasked pixels.
    let mut counts: BTreeMap<u16, [u64; 16]> = BTreeMap::new();
    for (px, &id) in arch.ids.iter().enumerate().take(n) {
        let Some(ok) = compatible.get(&id) else {
            continue;
        };
        let c = codes[px];
        if (c as usize) < Material::ALL.len() && ok.iter().any(|m| *m as u8 == c) {
            counts.entry(id).or_insert([0; 16])[c as usize] += 1;
        }
    }
    let dominant: BTreeMap<u16, u8> = counts
        .iter()
        .filter_map(|(&id, c)| {
            let (best, n) = c
                .iter()
                .enumerate()
                .fold((0, 0), |b, (k, &n)| if n > b.1 { (k, n) } else { b });
            (n > 0).then_some((id, best as u8))
        })
        .collect();
    stats.instances = dominant.len() as u64;
    for (px, &id) in arch.ids.iter().enumerate().take(n) {
        if let Some(&m) = dominant.get(&id)
            && codes[px] != MASKED
            && codes[px] != m
        {
            codes[px] = m;
            stats.pixels += 1;
        }
    }
    (codes, stats)
}

/// Eq. (5): the material at texel `k` of a chart, argmax over m of mu_m times the sum of ω over
/// pixels labelled m (the fused votes E_m(q) of `layers`); `weights[m]` is mu_m (missing weights
/// are 1). `None` where no class has a vote. Ties go to the lowest class index.
pub fn select_material(layers: &ChartLayers, weights: &[f64], k: usize) -> Option<u16> {
    let mut best: Option<(u16, f64)> = None;
    for (c, v) in &layers.votes {
        let e = v.get(k).copied().unwrap_or(0.0) as f64;
        if e <= 0.0 {
            continue;
        }
        let score = weights.get(*c as usize).copied().unwrap_or(1.0) * e;
        if best.is_none_or(|(bc, b)| score > b || (score == b && *c < bc)) {
            best = Some((*c, score));
        }
    }
    best.map(|(c, _)| c)
}

/// How [`assign_materials`] fills what no view saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extension {
    /// Extend at all; when false, unobserved texels take the default of their chart's kind.
    pub enabled: bool,
    /// A texel is observed when its W_exp exceeds this and some class has a vote.
    pub min_exposure: f64,
    /// Walls with nothing observed on the building's walls.
    pub wall_default: Material,
    /// Roofs with nothing observed on the building's roofs.
    pub roof_default: Material,
}

/// Eq. (5) on every texel, then the extension of the paper: each chart's dominant observed
/// material fills its unobserved texels; charts with nothing observed take the dominant material
/// of the same building's charts of the same kind (by observed area), else the kind's default.
/// The source of every choice is kept.
pub fn assign_materials(
    charts: &ChartSet,
    layers: &[ChartLayers],
    weights: &[f64],
    ext: &Extension,
) -> Vec<ChartMaterials> {
    let n_mat = Material::ALL.len();
    // Eq. (5) where observed, and per chart the observed texel count per material.
    let mut out: Vec<ChartMaterials> = Vec::with_capacity(charts.charts.len());
    let mut observed_count: Vec<Vec<u64>> = Vec::with_capacity(charts.charts.len());
    for (c, l) in charts.charts.iter().zip(layers) {
        let mut material = vec![NO_MATERIAL; c.len()];
        let mut source = vec![MaterialSource::Off as u8; c.len()];
        let mut count = vec![0u64; n_mat];
        for k in 0..c.len() {
            if c.triangle_at[k] == u32::MAX {
                continue;
            }
            let w = l.w_exp.get(k).copied().unwrap_or(0.0) as f64;
            if w > ext.min_exposure
                && let Some(m) = select_material(l, weights, k)
            {
                material[k] = m as u8;
                source[k] = MaterialSource::Observed as u8;
                count[m as usize] += 1;
            }
        }
        let dominant = argmax(&count.iter().map(|&n| n as f64).collect::<Vec<_>>());
        out.push(ChartMaterials {
            material: PodVec(material),
            source: PodVec(source),
            dominant: dominant.map(|m| m as u8),
        });
        observed_count.push(count);
    }
    // The building's dominant material per kind, by observed area.
    let mut building: BTreeMap<(&str, bool), Vec<f64>> = BTreeMap::new();
    for (c, count) in charts.charts.iter().zip(&observed_count) {
        let a = building
            .entry((c.building.as_str(), c.kind == ChartKind::Roof))
            .or_insert_with(|| vec![0.0; n_mat]);
        let texel_area = c.texel_m * c.texel_m;
        for (m, &n) in count.iter().enumerate() {
            a[m] += n as f64 * texel_area;
        }
    }
    for (c, m) in charts.charts.iter().zip(out.iter_mut()) {
        let roof = c.kind == ChartKind::Roof;
        let (fill, src) = if ext.enabled
            && let Some(d) = m.dominant
        {
            (d, MaterialSource::Chart)
        } else if ext.enabled
            && let Some(d) = building
                .get(&(c.building.as_str(), roof))
                .and_then(|a| argmax(a))
        {
            (d as u8, MaterialSource::Building)
        } else {
            let d = if roof {
                ext.roof_default
            } else {
                ext.wall_default
            };
            (d as u8, MaterialSource::Default)
        };
        fill_unobserved(c, m, fill, src);
    }
    out
}

fn fill_unobserved(c: &Chart, m: &mut ChartMaterials, fill: u8, src: MaterialSource) {
    for k in 0..c.len() {
        if c.triangle_at[k] != u32::MAX && m.source[k] == MaterialSource::Off as u8 {
            m.material[k] = fill;
            m.source[k] = src as u8;
        }
    }
}

/// Index of the largest positive value (the lowest on a tie), `None` when none is positive.
fn argmax(v: &[f64]) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (k, &x) in v.iter().enumerate() {
        if x > 0.0 && best.is_none_or(|(_, b)| x > b) {
            best = Some((k, x));
        }
    }
    best.map(|(k, _)| k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::{Instances, Intrinsics, Pose, RMSNET_CLASSES};

    fn layers(votes: Vec<(u16, Vec<f32>)>) -> ChartLayers {
        let n = votes[0].1.len();
        ChartLayers {
            width: n as u32,
            height: 1,
            w_exp: PodVec(vec![1.0; n]),
            hits: PodVec(vec![1; n]),
            votes: votes.into_iter().map(|(c, v)| (c, PodVec(v))).collect(),
        }
    }

    #[test]
    fn eq5_picks_the_weighted_argmax() {
        let (g, c) = (Material::Glass as u16, Material::Concrete as u16);
        // Texel 0: concrete 3, glass 2.6; texel 1: glass only; texel 2: nothing.
        let l = layers(vec![(c, vec![3.0, 0.0, 0.0]), (g, vec![2.6, 1.0, 0.0])]);
        let unit = vec![1.0; 14];
        assert_eq!(select_material(&l, &unit, 0), Some(c));
        assert_eq!(select_material(&l, &unit, 1), Some(g));
        assert_eq!(select_material(&l, &unit, 2), None);
        // mu_glass = 1.2: 1.2 x 2.6 = 3.12 > 3, glass wins.
        let mut w = unit.clone();
        w[g as usize] = 1.2;
        assert_eq!(select_material(&l, &w, 0), Some(g));
        // mu_glass = 1.15: 2.99 < 3, concrete still.
        w[g as usize] = 1.15;
        assert_eq!(select_material(&l, &w, 0), Some(c));
    }

    #[test]
    fn the_default_table_follows_the_design() {
        let names: Vec<String> = RMSNET_CLASSES.iter().map(|s| s.to_string()).collect();
        let t = class_table(&names, &BTreeMap::new()).unwrap();
        let at = |n: &str| t[names.iter().position(|c| c == n).unwrap()];
        assert_eq!(at("plaster"), PixelTarget::Surface(Material::Concrete));
        assert_eq!(at("ceramic"), PixelTarget::Surface(Material::Brick));
        assert_eq!(at("cobblestone"), PixelTarget::Surface(Material::Marble));
        assert_eq!(at("leaf"), PixelTarget::Occluder);
        assert_eq!(at("sky"), PixelTarget::NoVote);
        assert_eq!(at("grass"), PixelTarget::Ground(Material::WetGround));
        let o = BTreeMap::from([("plaster".to_string(), "plasterboard".to_string())]);
        let t = class_table(&names, &o).unwrap();
        assert_eq!(t[6], PixelTarget::Surface(Material::Plasterboard));
        let bad = BTreeMap::from([("plaster".to_string(), "cheese".to_string())]);
        assert!(class_table(&names, &bad).unwrap_err().contains("cheese"));
        let bad = BTreeMap::from([("tarmac".to_string(), "concrete".to_string())]);
        assert!(class_table(&names, &bad).unwrap_err().contains("tarmac"));
    }

    fn view(material: Vec<u8>, arch: Vec<u16>, clutter: Vec<u16>) -> View {
        let n = material.len() as u32;
        View {
            id: "v".into(),
            width: n,
            height: 1,
            intrinsics: Intrinsics {
                fx: 1.0,
                fy: 1.0,
                cx: 0.0,
                cy: 0.0,
            },
            pose: Pose::from_angles([0.0; 3], 0.0, 0.0, 0.0),
            captured_at: None,
            pose_source: None,
            distortion: None,
            image: PodVec(vec![[0; 3]; n as usize]),
            arch: Some(Instances {
                ids: PodVec(arch),
                classes: BTreeMap::from([(1, "window".into()), (2, "wall".into())]),
            }),
            clutter: Some(Instances {
                ids: PodVec(clutter),
                classes: BTreeMap::from([(1, "car".into())]),
            }),
            material: Some(PodVec(material)),
            depth: None,
            normal: None,
        }
    }

    #[test]
    fn refinement_fills_windows_and_masks_clutter() {
        let names: Vec<String> = RMSNET_CLASSES.iter().map(|s| s.to_string()).collect();
        let table = class_table(&names, &BTreeMap::new()).unwrap();
        let idx = |n: &str| names.iter().position(|c| c == n).unwrap() as u8;
        // A window of 5 pixels: 3 glass, 1 concrete (label noise), 1 sky (a reflection); then a
        // wall pixel of brick, and a car pixel of metal in front of the wall.
        let v = view(
            vec![
                idx("glass"),
                idx("glass"),
                idx("concrete"),
                idx("sky"),
                idx("glass"),
                idx("brick"),
                idx("metal"),
            ],
            vec![1, 1, 1, 1, 1, 2, 2],
            vec![0, 0, 0, 0, 0, 0, 1],
        );
        let refine = BTreeMap::from([(
            "window".to_string(),
            vec![Material::Glass, Material::Metal, Material::Wood],
        )]);
        let (codes, s) = refine_view(&v, &table, &refine, true);
        let g = Material::Glass as u8;
        assert_eq!(
            codes,
            vec![g, g, g, g, g, Material::Brick as u8, MASKED],
            "window filled, wall kept, car masked"
        );
        assert_eq!((s.pixels, s.instances), (2, 1));
        // Without refinement the noise stays; without masking the car votes metal.
        let (codes, _) = refine_view(&v, &table, &BTreeMap::new(), false);
        assert_eq!(codes[2], Material::Concrete as u8);
        assert_eq!(codes[3], SEEN);
        assert_eq!(codes[6], Material::Metal as u8);
    }
}
