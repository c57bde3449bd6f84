//! The synthetic site's ground truth: what exists, described, before any sensor sees it.

use serde::{Deserialize, Serialize};

use super::Polygon;
use crate::artifact::Material;
use crate::artifact::TerrainModel;

/// An oriented rectangle: south-west corner (before rotation), length along `heading`, width.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rect {
    /// The corner the rectangle is rotated about.
    pub corner: [f64; 2],
    /// Along `heading`, metres.
    pub length: f64,
    /// Across, metres.
    pub width: f64,
    /// Radians, counter-clockwise from +x.
    pub heading: f64,
}

impl Rect {
    /// The four corners, counter-clockwise.
    pub fn corners(&self) -> Vec<[f64; 2]> {
        let (s, c) = self.heading.sin_cos();
        [
            (0.0, 0.0),
            (self.length, 0.0),
            (self.length, self.width),
            (0.0, self.width),
        ]
        .iter()
        .map(|&(u, v)| {
            [
                self.corner[0] + c * u - s * v,
                self.corner[1] + s * u + c * v,
            ]
        })
        .collect()
    }
}

/// A roof shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Roof {
    /// Flat at the eave.
    Flat,
    /// Two slopes meeting at a ridge along the rectangle's length.
    Gabled {
        /// The rectangle the roof covers (also the footprint).
        rect: Rect,
        /// Ridge height above the eave, metres.
        ridge_m: f64,
    },
    /// Four slopes (a pyramid when square).
    Hipped {
        /// The rectangle the roof covers (also the footprint).
        rect: Rect,
        /// Ridge height above the eave, metres.
        ridge_m: f64,
    },
    /// A smaller upper tier on a flat roof.
    Stepped {
        /// The tier's footprint.
        upper: Polygon,
        /// Its height above the eave, metres.
        upper_m: f64,
    },
    /// A dome on a flat roof.
    Domed {
        /// Dome centre.
        center: [f64; 2],
        /// Dome radius, metres.
        radius_m: f64,
        /// Dome height above the eave, metres.
        height_m: f64,
    },
}

/// Roof furniture: the small things KODAMA keeps (chimneys, HVAC units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoofBox {
    /// What it is.
    pub kind: String,
    /// Centre.
    pub center: [f64; 2],
    /// Length, width, height, metres.
    pub size: [f64; 3],
}

/// What a façade feature is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum FeatureKind {
    /// A window: a glazed recess.
    Window,
    /// A door: a recess from the ground, with a wooden leaf.
    Door,
    /// A balcony: a slab with a railing, protruding.
    Balcony,
    /// A drainpipe: a thin vertical pipe, protruding.
    Drainpipe,
}

/// A façade feature on one edge of a building's outline: the relief truth (paper Sec. 4.2.2
/// recovers these as recesses, s = -1, and protrusions, s = +1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FacadeFeature {
    /// What it is.
    pub kind: FeatureKind,
    /// Ring of the outline (0 = exterior, then holes) and edge index within it.
    pub ring: usize,
    /// Edge index: from vertex `edge` to vertex `edge + 1`.
    pub edge: usize,
    /// Extent along the edge, metres from its first vertex.
    pub along: (f64, f64),
    /// Extent in height, site-frame z.
    pub z: (f64, f64),
    /// Depth: negative into the wall (recess), positive out of it (protrusion), metres.
    pub depth_m: f64,
}

/// One building of the truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuildingSpec {
    /// `building-<n>`.
    pub id: String,
    /// Outline (with courtyards as holes).
    pub footprint: Polygon,
    /// Highest terrain under the outline: heights are measured from here.
    pub ground_z: f64,
    /// Bottom of the solid, below the lowest terrain under the outline.
    pub base_z: f64,
    /// Eave (flat roof) height above `ground_z`, metres.
    pub eave_m: f64,
    /// Roof shape.
    pub roof: Roof,
    /// Roof furniture, standing on the eave level.
    pub furniture: Vec<RoofBox>,
    /// Façade material.
    pub facade: Material,
    /// Roof material.
    pub roof_material: Material,
    /// Façade features (windows, doors, balconies, drainpipes); empty: plain walls.
    pub features: Vec<FacadeFeature>,
}

impl BuildingSpec {
    /// The façade feature at site-frame point `p`, if any: `p` lies within the feature's extent
    /// along its edge and in height, and between the wall plane and the feature's depth (a recess
    /// reaches the walls' outer layer in, [`Self::recess_depth_m`], a protrusion `depth_m` out),
    /// every extent widened by `slack_m` (the reveals of an opening lie exactly on its edges: a
    /// slack above float rounding keeps them in).
    /// The truth for scoring what views and fusion find on a façade.
    pub fn feature_at(&self, p: [f64; 3], slack_m: f64) -> Option<usize> {
        self.facades().feature_at(p, slack_m)
    }

    /// The façade features ready for many [`Facades::feature_at`] queries: each feature's edge
    /// frame and the walls' outer layer found once (a view asks of every building pixel).
    pub fn facades(&self) -> Facades<'_> {
        let frames = self
            .features
            .iter()
            .map(|f| {
                let ring = if f.ring == 0 {
                    &self.footprint.exterior
                } else {
                    self.footprint.holes.get(f.ring - 1)?
                };
                if ring.len() < 2 {
                    return None;
                }
                let (a, c) = (ring[f.edge % ring.len()], ring[(f.edge + 1) % ring.len()]);
                let len = (c[0] - a[0]).hypot(c[1] - a[1]);
                if len == 0.0 {
                    return None;
                }
                Some((a, [(c[0] - a[0]) / len, (c[1] - a[1]) / len]))
            })
            .collect();
        Facades {
            spec: self,
            frames,
            layer_m: self.recess_depth_m(),
        }
    }

    /// How deep the building's openings reach into its walls, metres: the deepest window or
    /// door recess (0 without any). The thickness of the walls' outer layer.
    pub fn recess_depth_m(&self) -> f64 {
        self.features
            .iter()
            .filter(|f| matches!(f.kind, FeatureKind::Window | FeatureKind::Door))
            .map(|f| -f.depth_m)
            .fold(0.0, f64::max)
    }

    /// Highest point of the roof above `ground_z`, furniture excluded.
    pub fn top_m(&self) -> f64 {
        self.eave_m
            + match &self.roof {
                Roof::Flat => 0.0,
                Roof::Gabled { ridge_m, .. } | Roof::Hipped { ridge_m, .. } => *ridge_m,
                Roof::Stepped { upper_m, .. } => *upper_m,
                Roof::Domed { height_m, .. } => *height_m,
            }
    }
}

/// A building's façade features with what every point query needs found once
/// ([`BuildingSpec::facades`]).
pub struct Facades<'a> {
    /// The building.
    pub spec: &'a BuildingSpec,
    /// Per feature, its edge's start and unit direction; None for an edge that is not one.
    frames: Vec<Option<([f64; 2], [f64; 2])>>,
    /// The walls' outer layer ([`BuildingSpec::recess_depth_m`]).
    layer_m: f64,
}

impl Facades<'_> {
    /// [`BuildingSpec::feature_at`]: the façade feature at `p`, every extent widened by
    /// `slack_m`.
    pub fn feature_at(&self, p: [f64; 3], slack_m: f64) -> Option<usize> {
        self.spec
            .features
            .iter()
            .zip(&self.frames)
            .position(|(f, frame)| {
                // Most features are on other storeys: the height test first.
                if !(p[2] >= f.z.0 - slack_m && p[2] <= f.z.1 + slack_m) {
                    return false;
                }
                let Some((a, t)) = frame else {
                    return false;
                };
                // The solid is left of every ring edge: `inward` grows into the building.
                let d = [p[0] - a[0], p[1] - a[1]];
                let along = d[0] * t[0] + d[1] * t[1];
                let inward = -d[0] * t[1] + d[1] * t[0];
                let (lo, hi) = if f.depth_m < 0.0 {
                    let own = -f.depth_m;
                    if inward <= own + slack_m {
                        (0.0, own)
                    } else {
                        (0.0, own.max(self.layer_m))
                    }
                } else {
                    (-f.depth_m, 0.0)
                };
                along >= f.along.0 - slack_m
                    && along <= f.along.1 + slack_m
                    && inward >= lo - slack_m
                    && inward <= hi + slack_m
            })
    }
}

/// The shape of a tree's crown.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum CrownShape {
    /// An ellipsoid: broadleaved trees, round, spreading or columnar by its proportions.
    #[default]
    Ellipsoid,
    /// A cone on a flat base: conifers.
    Cone,
}

/// A tree: trunk and crown.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TreeSpec {
    /// `tree-<n>`.
    pub id: String,
    /// Trunk position.
    pub pos: [f64; 2],
    /// Terrain height there.
    pub ground_z: f64,
    /// Height of the crown's bottom above ground.
    pub trunk_m: f64,
    /// Horizontal crown radius.
    pub crown_radius_m: f64,
    /// Crown height.
    pub crown_m: f64,
    /// Crown shape.
    #[serde(default)]
    pub crown: CrownShape,
}

impl TreeSpec {
    /// The crown's bottom and top over site-frame (x, y), where the crown covers it: the truth a
    /// canopy is scored against.
    pub fn crown_span(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let r2 =
            ((x - self.pos[0]).powi(2) + (y - self.pos[1]).powi(2)) / self.crown_radius_m.powi(2);
        if !(r2 < 1.0) {
            return None;
        }
        let base = self.ground_z + self.trunk_m;
        Some(match self.crown {
            CrownShape::Ellipsoid => {
                let cz = base + self.crown_m / 2.0;
                let hh = self.crown_m / 2.0 * (1.0 - r2).sqrt();
                (cz - hh, cz + hh)
            }
            CrownShape::Cone => (base, base + self.crown_m * (1.0 - r2.sqrt())),
        })
    }

    /// The crown's volume, cubic metres.
    pub fn crown_volume_m3(&self) -> f64 {
        let disk = std::f64::consts::PI * self.crown_radius_m.powi(2);
        match self.crown {
            CrownShape::Ellipsoid => disk * self.crown_m * 2.0 / 3.0,
            CrownShape::Cone => disk * self.crown_m / 3.0,
        }
    }
}

/// Street clutter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClutterSpec {
    /// `<kind>-<n>`.
    pub id: String,
    /// `car`, `pole`, `sign`, `shelter`.
    pub kind: String,
    /// Centre.
    pub center: [f64; 2],
    /// Radians, counter-clockwise from +x.
    pub heading: f64,
    /// Terrain height there.
    pub ground_z: f64,
    /// Length, width, height, metres.
    pub size: [f64; 3],
    /// Height of the bottom above ground (a sign on its pole).
    pub lift_m: f64,
    /// Material.
    pub material: Material,
}

/// A straight street: centre line and width.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Street {
    /// One end of the centre line.
    pub a: [f64; 2],
    /// The other end.
    pub b: [f64; 2],
    /// Width from the blocks on one side to those on the other, pavements included, metres.
    pub width_m: f64,
}

/// The synthetic site.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct City {
    /// The terrain (evaluated with [`crate::artifact::height_at`]).
    pub terrain: TerrainModel,
    /// Extent (east, north) from the site origin, metres.
    pub size_m: (f64, f64),
    /// Buildings.
    pub buildings: Vec<BuildingSpec>,
    /// Trees.
    pub trees: Vec<TreeSpec>,
    /// Clutter.
    pub clutter: Vec<ClutterSpec>,
    /// Street centre lines (where cameras drive and phones are carried).
    pub streets: Vec<Street>,
}
