//! OSM-like footprints from exact ones, for the synthetic site's baseline: OpenStreetMap buildings
//! are "frequently misshapen, displaced or missing, with less than 8 % carrying height data"
//! (paper Sec. 2, after Fan 2014 and Biljecki 2023). Starting from the truth would give the
//! baseline a map no real site has.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, Footprints, Polygon};
use crate::rng::{gaussian, mix, unit};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`OsmLike`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OsmLikeParams {
    /// Seed of every draw. Default 1.
    pub seed: u64,
    /// Fraction of buildings missing from the map. Default 0.1.
    pub missing: f64,
    /// Fraction keeping a height tag. Default 0.08.
    pub with_height: f64,
    /// Fraction of the others tagged with levels (height / 3 m, rounded). Default 0.3.
    pub with_levels: f64,
    /// Standard deviation of the whole footprint's displacement, metres. Default 1.5.
    pub shift_m: f64,
    /// Standard deviation of each vertex's own error, metres. Default 0.5.
    pub jitter_m: f64,
}

impl Default for OsmLikeParams {
    fn default() -> Self {
        OsmLikeParams {
            seed: 1,
            missing: 0.1,
            with_height: 0.08,
            with_levels: 0.3,
            shift_m: 1.5,
            jitter_m: 0.5,
        }
    }
}

/// The footprints with OSM's typical faults drawn in: some missing, most heights untagged, the
/// rest displaced and misshapen.
pub struct OsmLike;

impl Stage for OsmLike {
    const KIND: &'static str = "OsmLike";
    const VERSION: u32 = 1;
    const DOC: &'static str = "OSM-like footprints from exact ones: missing buildings, few heights, displaced and jittered outlines";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "footprints",
        ArtifactType::Footprints,
        "exact footprints (the synthetic city's)",
    )];
    type Params = OsmLikeParams;
    type Output = Footprints;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        for (name, v) in [
            ("missing", p.missing),
            ("with_height", p.with_height),
            ("with_levels", p.with_levels),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(ParamError::new(name, "expected a fraction in [0, 1]"));
            }
        }
        for (name, v) in [("shift_m", p.shift_m), ("jitter_m", p.jitter_m)] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ParamError::new(
                    name,
                    "expected a non-negative length in metres",
                ));
            }
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Footprints, StageError> {
        let f: &Footprints = inputs.one("footprints")?;
        let mut items = Vec::new();
        for (k, fp) in f.items.iter().enumerate() {
            let h = |salt: u64| mix(p.seed ^ mix(k as u64 * 0x1_0000 + salt));
            if unit(h(1)) < p.missing {
                continue;
            }
            let mut fp = fp.clone();
            let (height, levels) = (fp.height_m, fp.height_m.map(|h| (h / 3.0).round().max(1.0)));
            fp.height_m = None;
            fp.levels = None;
            let u = unit(h(2));
            if u < p.with_height {
                fp.height_m = height;
            } else if u < p.with_height + (1.0 - p.with_height) * p.with_levels {
                fp.levels = levels;
            }
            let (dx, dy) = (p.shift_m * gaussian(h(3)), p.shift_m * gaussian(h(4)));
            let mut n = 5u64;
            let mut move_ring = |r: &[[f64; 2]]| -> Vec<[f64; 2]> {
                r.iter()
                    .map(|q| {
                        n += 2;
                        [
                            q[0] + dx + p.jitter_m * gaussian(h(n)),
                            q[1] + dy + p.jitter_m * gaussian(h(n + 1)),
                        ]
                    })
                    .collect()
            };
            fp.polygons = fp
                .polygons
                .iter()
                .filter_map(|poly| {
                    let ext = move_ring(&poly.exterior);
                    let holes = poly.holes.iter().map(|r| move_ring(r)).collect();
                    Polygon::normalized(ext, holes)
                })
                .collect();
            if !fp.polygons.is_empty() {
                items.push(fp);
            }
        }
        Ok(Footprints { items })
    }
}
