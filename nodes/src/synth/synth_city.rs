//! The seeded synthetic city: a benchmark generator whose ground truth every reconstruction stage
//! can be scored against (DESIGN: Synthetic site).
//!
//! Layout: a grid of blocks separated by streets; each block is cut into lots along its length
//! (one or two rows); each lot draws a building type (flat, L-shaped, courtyard, gabled, hipped,
//! stepped, domed) or a small park. Streets get trees, parked cars, poles, signs and shelters. All
//! draws are hashes of (seed, purpose, index), so the city does not depend on evaluation order.
//!
//! Façades and clutter vary ([`CityVariation`]): recess and balcony depths drawn per building,
//! bay windows standing out of some façades, glass shopfronts under masonry, cars, poles, signs
//! and shelters of many sizes. The street-level stages have to measure these: no class, material
//! or asset table of theirs holds the answer.

use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::{
    BuildingSpec, City, ClutterSpec, CrownShape, FacadeFeature, FeatureKind, Polygon, Rect, Roof,
    RoofBox, Street, TreeSpec,
};
use crate::artifact::{TerrainModel, height_at};
use crate::rng::{mix, unit};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// The largest synthetic city, metres each way: 20 km x 20 km is some 10^5 buildings already.
pub const MAX_SIZE_M: f64 = 20_000.0;

/// Params of [`SynthCity`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthCityParams {
    /// Seed of every draw. Default 7.
    pub seed: u64,
    /// Extent (east, north) from the site origin, metres. Default (400, 300).
    pub size_m: (f64, f64),
    /// Blocks (east, north). Default (4, 3).
    pub blocks: (u32, u32),
    /// Street width between blocks, metres. Default 18.
    pub street_m: f64,
    /// Lot frontage range, metres. Default (16, 30).
    pub lot_m: (f64, f64),
    /// Eave height range of flat-roofed buildings, metres. Default (8, 32).
    pub height_m: (f64, f64),
    /// Street tree spacing, metres (0: none). Default 15.
    pub tree_spacing_m: f64,
    /// Parked cars per 100 m of kerb. Default 6.
    pub cars_per_100m: f64,
    /// How façades and street clutter vary from one building or item to the next.
    pub variation: CityVariation,
    /// The terrain under the city.
    pub terrain: TerrainModel,
}

/// How the city's façades and clutter vary. [`CityVariation::none`] gives the uniform city of
/// SynthCity v2 (every recess 0.25 m, every balcony 1.2 m, one size per clutter kind), for tests
/// that isolate one stage from this variation.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CityVariation {
    /// Depth range of window and door recesses, drawn once per building, metres. Default
    /// (0.12, 0.40): the reveal of a window set in a thin rendered wall to one in a solid brick
    /// wall of one and a half bricks.
    pub recess_m: (f64, f64),
    /// Depth range of balconies, drawn once per building, metres. Default (0.8, 1.8): French
    /// balconies' shallow slabs to the 1.5 m-plus that housing codes ask of a usable one.
    pub balcony_m: (f64, f64),
    /// Share of masonry buildings of two storeys or more whose front wall has bay windows
    /// standing out of it on the upper storeys. Default 0.15.
    pub bay_share: f64,
    /// How far bays stand out, drawn per building, metres. Default (0.3, 0.8).
    pub bay_m: (f64, f64),
    /// Share of masonry buildings with glass shopfronts along the ground floor of the front
    /// wall: one building, two façade materials. Default 0.35.
    pub shopfront_share: f64,
    /// Whether clutter sizes are drawn per item (cars from small hatchbacks to vans, poles 6 to
    /// 10 m, shelters and signs of several sizes) rather than one size per kind. Default true.
    pub clutter_sizes: bool,
    /// Whether tree crowns take several shapes (a fifth conical, a fifth narrow and columnar,
    /// the rest round or spreading) rather than all round. Default true.
    pub crown_shapes: bool,
}

impl Default for CityVariation {
    fn default() -> Self {
        CityVariation {
            recess_m: (0.12, 0.40),
            balcony_m: (0.8, 1.8),
            bay_share: 0.15,
            bay_m: (0.3, 0.8),
            shopfront_share: 0.35,
            clutter_sizes: true,
            crown_shapes: true,
        }
    }
}

impl CityVariation {
    /// No variation: every building and clutter item as SynthCity v2 drew them.
    pub fn none() -> Self {
        CityVariation {
            recess_m: (UNIFORM_RECESS_M, UNIFORM_RECESS_M),
            balcony_m: (UNIFORM_BALCONY_M, UNIFORM_BALCONY_M),
            bay_share: 0.0,
            bay_m: (0.3, 0.8),
            shopfront_share: 0.0,
            clutter_sizes: false,
            crown_shapes: false,
        }
    }

    fn validate(&self) -> Result<(), ParamError> {
        let range = |name: &'static str, (lo, hi): (f64, f64), min: f64, max: f64| {
            if lo >= min && lo <= hi && hi <= max {
                Ok(())
            } else {
                Err(ParamError::new(
                    name,
                    format!("expected {min} <= low <= high <= {max} metres, found ({lo}, {hi})"),
                ))
            }
        };
        range("variation.recess_m", self.recess_m, 0.05, 1.0)?;
        range("variation.balcony_m", self.balcony_m, 0.3, 3.0)?;
        range("variation.bay_m", self.bay_m, 0.1, 1.5)?;
        for (name, share) in [
            ("variation.bay_share", self.bay_share),
            ("variation.shopfront_share", self.shopfront_share),
        ] {
            if !(0.0..=1.0).contains(&share) {
                return Err(ParamError::new(
                    name,
                    format!("expected a share from 0 to 1, found {share}"),
                ));
            }
        }
        Ok(())
    }
}

/// SynthCity v2's one recess depth for every window and door, metres.
const UNIFORM_RECESS_M: f64 = 0.25;
/// SynthCity v2's one balcony depth, metres.
const UNIFORM_BALCONY_M: f64 = 1.2;

impl Default for SynthCityParams {
    fn default() -> Self {
        SynthCityParams {
            seed: 7,
            size_m: (400.0, 300.0),
            blocks: (4, 3),
            street_m: 18.0,
            lot_m: (16.0, 30.0),
            height_m: (8.0, 32.0),
            tree_spacing_m: 15.0,
            cars_per_100m: 6.0,
            variation: CityVariation::default(),
            terrain: TerrainModel {
                seed: 7,
                size_m: (400.0, 300.0),
                ..Default::default()
            },
        }
    }
}

/// Generates the ground truth of a synthetic city.
pub struct SynthCity;

impl Stage for SynthCity {
    const KIND: &'static str = "SynthCity";
    // 2: no street furniture in the crossings (poles and parked cars stood in the carriageway of
    // north-south streets). 3: façades and clutter vary (`variation`).
    const VERSION: u32 = 3;
    const DOC: &'static str =
        "seeded synthetic city ground truth: terrain, buildings with roof shapes, trees, clutter";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = SynthCityParams;
    type Output = City;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.size_m.0 >= 50.0 && p.size_m.1 >= 50.0) {
            return Err(ParamError::new("size_m", "expected at least 50 x 50 m"));
        }
        if !(p.size_m.0 <= MAX_SIZE_M && p.size_m.1 <= MAX_SIZE_M) {
            return Err(ParamError::new(
                "size_m",
                format!(
                    "expected at most {MAX_SIZE_M} x {MAX_SIZE_M} m, found {} x {} (buildings, trees and cars grow with the area)",
                    p.size_m.0, p.size_m.1
                ),
            ));
        }
        if !(p.street_m >= 0.0 && p.street_m.is_finite()) {
            return Err(ParamError::new(
                "street_m",
                "expected a non-negative, finite width in metres",
            ));
        }
        if !(p.tree_spacing_m == 0.0 || (p.tree_spacing_m >= 1.0 && p.tree_spacing_m.is_finite())) {
            return Err(ParamError::new(
                "tree_spacing_m",
                format!(
                    "expected 0 (no trees) or at least 1 m, found {}",
                    p.tree_spacing_m
                ),
            ));
        }
        if !(0.0..=50.0).contains(&p.cars_per_100m) {
            return Err(ParamError::new(
                "cars_per_100m",
                format!("expected 0 to 50 cars per 100 m, found {}", p.cars_per_100m),
            ));
        }
        if p.blocks.0 == 0 || p.blocks.1 == 0 {
            return Err(ParamError::new(
                "blocks",
                "expected at least one block each way",
            ));
        }
        let bw = (p.size_m.0 - (p.blocks.0 + 1) as f64 * p.street_m) / p.blocks.0 as f64;
        let bh = (p.size_m.1 - (p.blocks.1 + 1) as f64 * p.street_m) / p.blocks.1 as f64;
        if !(bw >= 20.0 && bh >= 20.0) {
            return Err(ParamError::new(
                "blocks",
                format!(
                    "blocks would be {bw:.1} x {bh:.1} m; expected at least 20 x 20 m (fewer blocks or narrower streets)"
                ),
            ));
        }
        if !(p.lot_m.0 >= 8.0 && p.lot_m.1 >= p.lot_m.0 && p.lot_m.1.is_finite()) {
            return Err(ParamError::new("lot_m", "expected 8 <= min <= max, finite"));
        }
        if !(p.height_m.0 >= 3.0 && p.height_m.1 >= p.height_m.0 && p.height_m.1.is_finite()) {
            return Err(ParamError::new(
                "height_m",
                "expected 3 <= min <= max, finite",
            ));
        }
        p.variation.validate()
    }

    fn run(p: &Self::Params, _: &Inputs, _: &Ctx) -> Result<City, StageError> {
        Ok(generate(p))
    }
}

/// Seeded draws: `r.u(purpose, index)` in [0, 1).
struct Draw(u64);

impl Draw {
    fn u(&self, purpose: u64, i: u64) -> f64 {
        unit(mix(
            self.0 ^ mix(purpose.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ mix(i))
        ))
    }
    fn range(&self, purpose: u64, i: u64, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.u(purpose, i)
    }
    fn pick<T: Copy>(&self, purpose: u64, i: u64, weighted: &[(T, f64)]) -> T {
        let total: f64 = weighted.iter().map(|w| w.1).sum();
        let mut x = self.u(purpose, i) * total;
        for &(v, w) in weighted {
            if x < w {
                return v;
            }
            x -= w;
        }
        weighted.last().expect("non-empty choice").0
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Flat,
    LShape,
    Courtyard,
    Gabled,
    Hipped,
    Stepped,
    Domed,
    Park,
}

fn rect_poly(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<[f64; 2]> {
    vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
}

/// The city for `p`.
pub fn generate(p: &SynthCityParams) -> City {
    let d = Draw(p.seed);
    let t = &p.terrain;
    let (nbx, nby) = p.blocks;
    let bw = (p.size_m.0 - (nbx + 1) as f64 * p.street_m) / nbx as f64;
    let bh = (p.size_m.1 - (nby + 1) as f64 * p.street_m) / nby as f64;
    let mut city = City {
        terrain: t.clone(),
        size_m: p.size_m,
        buildings: vec![],
        trees: vec![],
        clutter: vec![],
        streets: vec![],
    };
    for k in 0..=nby {
        let y = k as f64 * (bh + p.street_m) + p.street_m / 2.0;
        city.streets.push(Street {
            a: [0.0, y],
            b: [p.size_m.0, y],
            width_m: p.street_m,
        });
    }
    for k in 0..=nbx {
        let x = k as f64 * (bw + p.street_m) + p.street_m / 2.0;
        city.streets.push(Street {
            a: [x, 0.0],
            b: [x, p.size_m.1],
            width_m: p.street_m,
        });
    }
    let mut lot_id = 0u64;
    for by in 0..nby {
        for bx in 0..nbx {
            let x0 = p.street_m + bx as f64 * (bw + p.street_m);
            let y0 = p.street_m + by as f64 * (bh + p.street_m);
            // Lots run along the block's length; deep blocks get two rows back to back.
            let rows = if bh >= 50.0 { 2 } else { 1 };
            let depth = bh / rows as f64;
            for row in 0..rows {
                let ly0 = y0 + row as f64 * depth;
                let mut lx = x0;
                while x0 + bw - lx >= p.lot_m.0 {
                    let mut w = d.range(1, lot_id, p.lot_m.0, p.lot_m.1);
                    if x0 + bw - (lx + w) < p.lot_m.0 {
                        w = x0 + bw - lx;
                    }
                    add_lot(&mut city, &d, p, lot_id, [lx, ly0, lx + w, ly0 + depth]);
                    lot_id += 1;
                    lx += w;
                }
            }
        }
    }
    add_street_furniture(&mut city, &d, p, bw, bh);
    city
}

fn ground(t: &TerrainModel, pts: &[[f64; 2]]) -> (f64, f64) {
    pts.iter()
        .map(|q| height_at(t, q[0], q[1]))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
            (lo.min(z), hi.max(z))
        })
}

fn add_lot(city: &mut City, d: &Draw, p: &SynthCityParams, lot: u64, b: [f64; 4]) {
    let kind = lot_kind(d, lot, b);
    if kind == Kind::Park {
        add_park(city, d, p, lot, b);
        return;
    }
    let built = set_back(d, lot, b);
    let id = format!("building-{}", city.buildings.len());
    let facade = d.pick(
        4,
        lot,
        &[
            (Material::Concrete, 0.35),
            (Material::Brick, 0.3),
            (Material::Glass, 0.2),
            (Material::Marble, 0.1),
            (Material::Wood, 0.05),
        ],
    );
    let massing = massing(kind, d, p, lot, built);
    let footprint =
        Polygon::normalized(massing.outline, massing.holes).expect("generated outlines are valid");
    let (lo, hi) = ground(&p.terrain, &footprint.exterior);
    let furniture = roof_furniture(d, lot, built, &footprint, &massing.roof);
    let features = facade_features(
        d,
        lot,
        &p.terrain,
        &footprint,
        hi,
        lo - 1.0,
        hi + massing.eave_m,
        facade,
        &p.variation,
    );
    city.buildings.push(BuildingSpec {
        id,
        footprint,
        ground_z: hi,
        base_z: lo - 1.0,
        eave_m: massing.eave_m,
        roof: massing.roof,
        furniture,
        facade,
        roof_material: massing.roof_material,
        features,
    });
}

/// Courtyards only fit on big lots.
fn lot_kind(d: &Draw, lot: u64, b: [f64; 4]) -> Kind {
    let (w, h) = (b[2] - b[0], b[3] - b[1]);
    let big = w >= 24.0 && h >= 24.0;
    d.pick(
        2,
        lot,
        &[
            (Kind::Flat, 0.26),
            (Kind::LShape, 0.12),
            (Kind::Courtyard, if big { 0.10 } else { 0.0 }),
            (Kind::Gabled, 0.17),
            (Kind::Hipped, 0.13),
            (Kind::Stepped, 0.12),
            (Kind::Domed, 0.04),
            (Kind::Park, 0.06),
        ],
    )
}

fn add_park(city: &mut City, d: &Draw, p: &SynthCityParams, lot: u64, b: [f64; 4]) {
    for k in 0..3 {
        let pos = [
            d.range(30, lot * 8 + k, b[0] + 3.0, b[2] - 3.0),
            d.range(31, lot * 8 + k, b[1] + 3.0, b[3] - 3.0),
        ];
        add_tree(city, d, p, pos);
    }
}

/// The part of lot `b` a building may cover: `[x0, y0, x1, y1]` after a setback from each edge.
fn set_back(d: &Draw, lot: u64, b: [f64; 4]) -> [f64; 4] {
    let s = |k: u64| d.range(3, lot * 4 + k, 1.0, 3.0);
    [b[0] + s(0), b[1] + s(1), b[2] - s(2), b[3] - s(3)]
}

/// A building's shape before its furniture and facade features.
struct Massing {
    outline: Vec<[f64; 2]>,
    holes: Vec<Vec<[f64; 2]>>,
    roof: Roof,
    eave_m: f64,
    roof_material: Material,
}

/// The massing of a `kind` building on the set-back lot `built`.
fn massing(kind: Kind, d: &Draw, p: &SynthCityParams, lot: u64, built: [f64; 4]) -> Massing {
    let flat_eave = d.range(5, lot, p.height_m.0, p.height_m.1);
    let low_eave = d.range(5, lot, 6.0, 12.0f64.max(p.height_m.0));
    match kind {
        Kind::Flat | Kind::Domed => flat_or_domed(kind == Kind::Domed, d, lot, built, flat_eave),
        Kind::LShape => l_shaped(d, lot, built, flat_eave),
        Kind::Courtyard => courtyard(d, lot, built, flat_eave),
        Kind::Gabled | Kind::Hipped => pitched(kind == Kind::Gabled, d, lot, built, low_eave),
        Kind::Stepped => stepped(d, lot, built, flat_eave),
        Kind::Park => unreachable!("parks return early"),
    }
}

fn flat_or_domed(domed: bool, d: &Draw, lot: u64, built: [f64; 4], eave_m: f64) -> Massing {
    let [x0, y0, x1, y1] = built;
    let (fw, fh) = (x1 - x0, y1 - y0);
    let roof = if domed {
        let r = 0.35 * fw.min(fh);
        Roof::Domed {
            center: [(x0 + x1) / 2.0, (y0 + y1) / 2.0],
            radius_m: r,
            height_m: d.range(6, lot, 0.6, 1.0) * r,
        }
    } else {
        Roof::Flat
    };
    Massing {
        outline: rect_poly(x0, y0, x1, y1),
        holes: vec![],
        roof,
        eave_m,
        roof_material: if domed {
            Material::Metal
        } else {
            Material::Concrete
        },
    }
}

fn l_shaped(d: &Draw, lot: u64, built: [f64; 4], eave_m: f64) -> Massing {
    let [x0, y0, x1, y1] = built;
    let (fw, fh) = (x1 - x0, y1 - y0);
    let (cx, cy) = (
        x0 + fw * d.range(7, lot, 0.4, 0.6),
        y0 + fh * d.range(8, lot, 0.4, 0.6),
    );
    Massing {
        outline: vec![[x0, y0], [x1, y0], [x1, cy], [cx, cy], [cx, y1], [x0, y1]],
        holes: vec![],
        roof: Roof::Flat,
        eave_m,
        roof_material: Material::Concrete,
    }
}

fn courtyard(d: &Draw, lot: u64, built: [f64; 4], flat_eave: f64) -> Massing {
    let [x0, y0, x1, y1] = built;
    Massing {
        outline: rect_poly(x0, y0, x1, y1),
        holes: vec![inset_rect(d, lot, built, [9, 10], (0.25, 0.32))],
        roof: Roof::Flat,
        eave_m: flat_eave.min(20.0),
        roof_material: Material::Concrete,
    }
}

/// A gabled or hipped building.
fn pitched(gabled: bool, d: &Draw, lot: u64, built: [f64; 4], eave_m: f64) -> Massing {
    let [x0, y0, x1, y1] = built;
    let (fw, fh) = (x1 - x0, y1 - y0);
    // The ridge runs along the longer side.
    let rect = if fw >= fh {
        Rect {
            corner: [x0, y0],
            length: fw,
            width: fh,
            heading: 0.0,
        }
    } else {
        Rect {
            corner: [x1, y0],
            length: fh,
            width: fw,
            heading: std::f64::consts::FRAC_PI_2,
        }
    };
    let ridge_m = d.range(11, lot, 0.25, 0.45) * rect.width.min(14.0);
    let roof = if gabled {
        Roof::Gabled { rect, ridge_m }
    } else {
        Roof::Hipped { rect, ridge_m }
    };
    Massing {
        outline: rect.corners(),
        holes: vec![],
        roof,
        eave_m,
        roof_material: d.pick(
            12,
            lot,
            &[(Material::Metal, 0.4), (Material::Concrete, 0.6)],
        ),
    }
}

fn stepped(d: &Draw, lot: u64, built: [f64; 4], eave_m: f64) -> Massing {
    let [x0, y0, x1, y1] = built;
    let upper = Polygon::normalized(inset_rect(d, lot, built, [13, 14], (0.15, 0.3)), vec![])
        .expect("inner rectangle is valid");
    Massing {
        outline: rect_poly(x0, y0, x1, y1),
        holes: vec![],
        roof: Roof::Stepped {
            upper,
            upper_m: d.range(15, lot, 3.5, 9.0),
        },
        eave_m,
        roof_material: Material::Concrete,
    }
}

/// `built` shrunk on each side by a drawn fraction (in `frac`) of its width and depth, drawn by
/// `purposes` (x, y).
fn inset_rect(
    d: &Draw,
    lot: u64,
    built: [f64; 4],
    purposes: [u64; 2],
    frac: (f64, f64),
) -> Vec<[f64; 2]> {
    let [x0, y0, x1, y1] = built;
    let (fw, fh) = (x1 - x0, y1 - y0);
    let (ix, iy) = (
        fw * d.range(purposes[0], lot, frac.0, frac.1),
        fh * d.range(purposes[1], lot, frac.0, frac.1),
    );
    rect_poly(x0 + ix, y0 + iy, x1 - ix, y1 - iy)
}

/// HVAC units and chimneys on flat roofs (and a stepped roof's lower tier), kept clear of the
/// outline, any courtyard and the upper tier.
fn roof_furniture(
    d: &Draw,
    lot: u64,
    built: [f64; 4],
    footprint: &Polygon,
    roof: &Roof,
) -> Vec<RoofBox> {
    let mut furniture = Vec::new();
    if !matches!(roof, Roof::Flat | Roof::Stepped { .. }) {
        return furniture;
    }
    let [x0, y0, x1, y1] = built;
    let (fw, fh) = (x1 - x0, y1 - y0);
    for k in 0..d.pick(16, lot, &[(0u64, 0.3), (1, 0.35), (2, 0.25), (3, 0.1)]) {
        let hvac = d.u(17, lot * 4 + k) < 0.7;
        let size = if hvac {
            [
                d.range(18, lot * 4 + k, 2.0, 4.0),
                d.range(19, lot * 4 + k, 1.5, 3.0),
                1.6,
            ]
        } else {
            [0.7, 0.7, 1.8]
        };
        let c = [
            x0 + 2.5 + (fw - 5.0) * d.u(20, lot * 4 + k),
            y0 + 2.5 + (fh - 5.0) * d.u(21, lot * 4 + k),
        ];
        let corners = Rect {
            corner: [c[0] - size[0] / 2.0, c[1] - size[1] / 2.0],
            length: size[0],
            width: size[1],
            heading: 0.0,
        }
        .corners();
        if fits_on_roof(&corners, footprint, roof) {
            furniture.push(RoofBox {
                kind: if hvac {
                    "hvac".into()
                } else {
                    "chimney".into()
                },
                center: c,
                size,
            });
        }
    }
    furniture
}

fn fits_on_roof(corners: &[[f64; 2]], footprint: &Polygon, roof: &Roof) -> bool {
    use crate::artifact::point_in_ring;
    let inside = corners.iter().all(|q| {
        point_in_ring(*q, &footprint.exterior)
            && !footprint.holes.iter().any(|h| point_in_ring(*q, h))
    });
    let clear_of_tier = match roof {
        Roof::Stepped { upper, .. } => !corners.iter().any(|q| point_in_ring(*q, &upper.exterior)),
        _ => true,
    };
    inside && clear_of_tier
}

/// Storey height, metres.
pub const FLOOR_M: f64 = 3.2;

/// Windows on every storey of every wall long enough (every 3 m, 1.4 x 1.6 m, sill at 0.9 m), a
/// door in the middle of the first wall, balconies on some taller masonry buildings, and
/// drainpipes at two corners. With `v`'s variation: recess and balcony depths drawn per
/// building, bay windows (2.1 m tall, 1.6 m wide, standing out) on the upper storeys of some
/// masonry fronts, and glass shopfronts (2.6 m wide, 2.5 m tall, shallow) in place of the
/// ground-floor windows of others' first wall.
#[allow(clippy::too_many_arguments)]
fn facade_features(
    d: &Draw,
    lot: u64,
    t: &TerrainModel,
    fp: &Polygon,
    ground_z: f64,
    base_z: f64,
    eave_z: f64,
    facade: Material,
    v: &CityVariation,
) -> Vec<FacadeFeature> {
    let floors = ((eave_z - ground_z) / FLOOR_M).floor().max(1.0) as usize;
    let masonry = facade != Material::Glass;
    let balconies = floors >= 3 && masonry && d.u(60, lot) < 0.4;
    let recess_m = d.range(61, lot, v.recess_m.0, v.recess_m.1);
    let balcony_m = d.range(62, lot, v.balcony_m.0, v.balcony_m.1);
    let bays = floors >= 2 && masonry && d.u(63, lot) < v.bay_share;
    let bay_m = d.range(64, lot, v.bay_m.0, v.bay_m.1);
    let shopfront = masonry && d.u(65, lot) < v.shopfront_share;
    let shopfront_recess_m = d.range(66, lot, 0.08, 0.2);
    let mut out = Vec::new();
    let rings: Vec<&Vec<[f64; 2]>> = std::iter::once(&fp.exterior).chain(&fp.holes).collect();
    for (ri, ring) in rings.iter().enumerate() {
        for e in 0..ring.len() {
            let (a, b) = (ring[e], ring[(e + 1) % ring.len()]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            let n_win = ((len - 2.0) / 3.0).floor() as i64;
            if n_win < 1 {
                continue;
            }
            let first = (len - (n_win - 1) as f64 * 3.0) / 2.0;
            let front = ri == 0 && e == 0;
            let door = front.then_some(n_win / 2);
            for f in 0..floors {
                let z0 = ground_z + f as f64 * FLOOR_M;
                for k in 0..n_win {
                    let c = first + k as f64 * 3.0;
                    let feature = |kind, along, z, depth_m| FacadeFeature {
                        kind,
                        ring: ri,
                        edge: e,
                        along,
                        z,
                        depth_m,
                    };
                    if f == 0 && door == Some(k) {
                        let s = c / len;
                        let g = height_at(t, a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s);
                        out.push(feature(
                            FeatureKind::Door,
                            (c - 0.6, c + 0.6),
                            (g, g + 2.2),
                            -recess_m,
                        ));
                        continue;
                    }
                    let balcony = balconies && front && f >= 1 && k % 2 == 0;
                    if f == 0 && front && shopfront {
                        out.push(feature(
                            FeatureKind::Window,
                            (c - 1.3, c + 1.3),
                            (z0 + 0.4, z0 + 2.9),
                            -shopfront_recess_m,
                        ));
                    } else if bays && front && f >= 1 && !balcony {
                        out.push(feature(
                            FeatureKind::Window,
                            (c - 0.8, c + 0.8),
                            (z0 + 0.6, z0 + 2.7),
                            bay_m,
                        ));
                    } else {
                        out.push(feature(
                            FeatureKind::Window,
                            (c - 0.7, c + 0.7),
                            (z0 + 0.9, z0 + 2.5),
                            -recess_m,
                        ));
                    }
                    if balcony {
                        out.push(feature(
                            FeatureKind::Balcony,
                            (c - 1.1, c + 1.1),
                            (z0, z0 + 1.1),
                            balcony_m,
                        ));
                    }
                }
            }
        }
    }
    for e in 0..2.min(fp.exterior.len()) {
        out.push(FacadeFeature {
            kind: FeatureKind::Drainpipe,
            ring: 0,
            edge: e,
            along: (0.1, 0.22),
            z: (base_z, eave_z),
            depth_m: 0.15,
        });
    }
    out
}

/// A street tree: a round or spreading crown, or with `variation.crown_shapes` one in five a
/// conifer's cone (1.5-2.8 m across, 5-9 m tall) and one in five a columnar crown (1.2-2.0 m,
/// 6-9 m tall), as street-tree stock lists hold them.
fn add_tree(city: &mut City, d: &Draw, p: &SynthCityParams, pos: [f64; 2]) {
    let i = city.trees.len() as u64;
    let shape = if p.variation.crown_shapes {
        d.u(43, i)
    } else {
        1.0
    };
    let (crown, crown_radius_m, crown_m) = if shape < 0.2 {
        (
            CrownShape::Cone,
            d.range(44, i, 1.5, 2.8),
            d.range(45, i, 5.0, 9.0),
        )
    } else if shape < 0.4 {
        (
            CrownShape::Ellipsoid,
            d.range(44, i, 1.2, 2.0),
            d.range(45, i, 6.0, 9.0),
        )
    } else {
        (
            CrownShape::Ellipsoid,
            d.range(41, i, 2.0, 3.8),
            d.range(42, i, 4.0, 7.5),
        )
    };
    city.trees.push(TreeSpec {
        id: format!("tree-{i}"),
        pos,
        ground_z: height_at(&p.terrain, pos[0], pos[1]),
        trunk_m: d.range(40, i, 2.2, 3.5),
        crown_radius_m,
        crown_m,
        crown,
    });
}

/// Adds `c`, giving it the next id of its kind and the terrain height at its centre.
fn add_clutter(city: &mut City, p: &SynthCityParams, mut c: ClutterSpec) {
    let n = city.clutter.iter().filter(|k| k.kind == c.kind).count();
    c.id = format!("{}-{n}", c.kind);
    c.ground_z = height_at(&p.terrain, c.center[0], c.center[1]);
    city.clutter.push(c);
}

/// A clutter item before [`add_clutter`] names and grounds it.
fn item(
    kind: &str,
    center: [f64; 2],
    heading: f64,
    size: [f64; 3],
    lift_m: f64,
    material: Material,
) -> ClutterSpec {
    ClutterSpec {
        id: String::new(),
        kind: kind.into(),
        center,
        heading,
        ground_z: 0.0,
        size,
        lift_m,
        material,
    }
}

/// A parked car's length, width and height without size variation, metres.
const CAR_M: [f64; 3] = [4.5, 1.8, 1.5];

/// A parked car's length, width and height, metres: with `vary`, from a 3.6 m city car to a 5.2 m
/// estate (European segments A to E), one in ten a 5.4 m van 2.4 m tall; otherwise [`CAR_M`].
fn car_size(d: &Draw, i: u64, vary: bool) -> [f64; 3] {
    if !vary {
        return CAR_M;
    }
    if d.u(69, i) < 0.1 {
        return [5.4, 2.0, 2.4];
    }
    [
        d.range(58, i, 3.6, 5.2),
        d.range(67, i, 1.65, 1.95),
        d.range(68, i, 1.4, 1.75),
    ]
}

/// Pavements are this wide, so a street's carriageway ends this far inside each of its edges.
const PAVEMENT_M: f64 = 2.5;

/// Parked cars keep this far from a crossing street's kerb line, as traffic codes ask (e.g.
/// StVO Sec. 12: 5 m before and after a crossing).
const PARKING_CLEAR_OF_CROSSING_M: f64 = 5.0;

/// Whether something spanning `half_len_m` either side of `x`, along an east-west street,
/// reaches within `clear_m` of the centre line of any north-south street in `crossings`.
fn near_crossing(x: f64, half_len_m: f64, crossings: &[f64], clear_m: f64) -> bool {
    crossings
        .iter()
        .any(|xc| (x - xc).abs() < clear_m + half_len_m)
}

/// Trees on the pavements, cars at the kerbs, poles with some signs, and a few shelters, along
/// the east-west streets (kerbs 2.5 m inside each street edge). Nothing stands where a
/// north-south street crosses: a pavement's line runs on across the crossing's carriageway, and
/// a pole there would stand in the traffic (the scene grammar of Sec. 4.2.4 rightly drops such
/// detections, so the truth must not hold them either).
fn add_street_furniture(city: &mut City, d: &Draw, p: &SynthCityParams, bw: f64, bh: f64) {
    let (sx, sy) = p.size_m;
    let crossings: Vec<f64> = (0..=p.blocks.0)
        .map(|k| k as f64 * (bw + p.street_m) + p.street_m / 2.0)
        .collect();
    let carriageway_half_m = (p.street_m / 2.0 - PAVEMENT_M).max(0.0);
    let parking_clear_m = p.street_m / 2.0 + PARKING_CLEAR_OF_CROSSING_M;
    for street in 0..=p.blocks.1 {
        let yc = street as f64 * (bh + p.street_m) + p.street_m / 2.0;
        for side in [-1.0, 1.0] {
            let pavement = yc + side * (p.street_m / 2.0 - 1.5);
            let kerb = yc + side * (p.street_m / 2.0 - 4.0);
            let k = (street * 2 + (side > 0.0) as u32) as u64;
            if p.tree_spacing_m > 0.0 {
                let mut x = 6.0 + d.range(50, k, 0.0, p.tree_spacing_m);
                while x < sx - 6.0 {
                    let tx = x + d.range(51, (k << 20) + x as u64, -1.0, 1.0);
                    let clear = !near_crossing(tx, 0.5, &crossings, carriageway_half_m);
                    if clear && pavement > 2.0 && pavement < sy - 2.0 {
                        add_tree(city, d, p, [tx, pavement]);
                    }
                    x += p.tree_spacing_m;
                }
            }
            let gap = 100.0 / p.cars_per_100m.max(0.01);
            let mut x = 5.0 + d.range(52, k, 0.0, gap);
            let mut i = 0u64;
            while p.cars_per_100m > 0.0 && x < sx - 5.0 {
                let size = car_size(d, (k << 20) + i, p.variation.clutter_sizes);
                let clear = !near_crossing(x, size[0] / 2.0, &crossings, parking_clear_m);
                if clear && kerb > 2.0 && kerb < sy - 2.0 {
                    let heading = if d.u(53, (k << 20) + i) < 0.5 {
                        0.0
                    } else {
                        std::f64::consts::PI
                    };
                    let mat = Material::Metal;
                    add_clutter(city, p, item("car", [x, kerb], heading, size, 0.0, mat));
                }
                x += gap * d.range(54, (k << 20) + i, 0.6, 1.4);
                i += 1;
            }
            let mut x = 10.0 + d.range(55, k, 0.0, 20.0);
            let mut j = 0u64;
            while x < sx - 10.0 {
                let py = yc + side * (p.street_m / 2.0 - 0.5);
                // The widest thing on a pole is its 0.9 m sign.
                let clear = !near_crossing(x, 0.45, &crossings, carriageway_half_m);
                if clear && py > 1.0 && py < sy - 1.0 {
                    let sizes = p.variation.clutter_sizes;
                    let pole_m = if sizes {
                        d.range(70, (k << 20) + j, 6.0, 10.0)
                    } else {
                        8.0
                    };
                    add_clutter(
                        city,
                        p,
                        item(
                            "pole",
                            [x, py],
                            0.0,
                            [0.25, 0.25, pole_m],
                            0.0,
                            Material::Metal,
                        ),
                    );
                    if d.u(56, (k << 20) + j) < 0.3 {
                        // Traffic signs: 0.6 m to 0.9 m plates (Vienna Convention sizes).
                        let (w, h) = if sizes {
                            let w = d.range(72, (k << 20) + j, 0.6, 0.9);
                            (w, w * d.range(73, (k << 20) + j, 0.65, 1.0))
                        } else {
                            (0.9, 0.6)
                        };
                        add_clutter(
                            city,
                            p,
                            item(
                                "sign",
                                [x, py + side * 0.2],
                                0.0,
                                [w, 0.08, h],
                                2.2,
                                Material::Metal,
                            ),
                        );
                    }
                    // Shelters from a two-seat 3 m canopy to a 5 m one; the widest the
                    // crossing test allows for is the 5 m one.
                    let shelter = if sizes {
                        [
                            d.range(71, (k << 20) + j, 3.0, 5.0),
                            d.range(74, (k << 20) + j, 1.3, 2.0),
                            d.range(75, (k << 20) + j, 2.4, 2.8),
                        ]
                    } else {
                        [3.5, 1.6, 2.6]
                    };
                    let shelter_clear =
                        !near_crossing(x + 4.0, shelter[0] / 2.0, &crossings, carriageway_half_m);
                    if shelter_clear && d.u(57, (k << 20) + j) < 0.12 {
                        add_clutter(
                            city,
                            p,
                            item(
                                "shelter",
                                [x + 4.0, py - side * 0.6],
                                0.0,
                                shelter,
                                0.0,
                                Material::Glass,
                            ),
                        );
                    }
                }
                x += 30.0;
                j += 1;
            }
        }
    }
}
