//! Per-texel ITU-R P.2040 materials on building charts (paper Sec. 4.2.3, eq. (5)): the fused
//! votes, the chosen material, and where each choice came from, so direct evidence and
//! extrapolation stay distinguishable.

use serde::{Deserialize, Serialize};

use super::{PodVec, TexelLayers};

/// Where a texel's material came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[repr(u8)]
pub enum MaterialSource {
    /// The texel's centre is off the surface: no material.
    Off = 0,
    /// Eq. (5): the texel had votes of its own.
    Observed = 1,
    /// Extension: no votes here; the chart's dominant observed material.
    Chart = 2,
    /// Extension: nothing observed on the chart; the building's dominant material on charts of
    /// the same kind (walls from walls, roofs from roofs).
    Building = 3,
    /// Nothing observed on the building's charts of this kind: the class default (a param).
    Default = 4,
}

impl MaterialSource {
    /// Every source, in discriminant order.
    pub const ALL: [MaterialSource; 5] = [
        MaterialSource::Off,
        MaterialSource::Observed,
        MaterialSource::Chart,
        MaterialSource::Building,
        MaterialSource::Default,
    ];

    /// The source with discriminant `v`.
    pub fn from_u8(v: u8) -> Option<MaterialSource> {
        MaterialSource::ALL.get(v as usize).copied()
    }
}

/// The materials of one chart, per texel (row-major, `v` rows, as its grid).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChartMaterials {
    /// [`crate::artifact::Material`] discriminant per texel; [`NO_MATERIAL`] off the surface.
    pub material: PodVec<u8>,
    /// [`MaterialSource`] discriminant per texel.
    pub source: PodVec<u8>,
    /// The chart's dominant observed material (most observed texels), if any texel was observed.
    pub dominant: Option<u8>,
}

/// The `material` value of a texel off the surface.
pub const NO_MATERIAL: u8 = 255;

/// What the material fusion did, in numbers.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaterialStats {
    /// Texels on the surface, over all charts.
    pub texels: u64,
    /// Texels per [`MaterialSource`] (index = discriminant; `Off` counts off-surface texels).
    pub by_source: [u64; 5],
    /// Surface texels per material (index = Material discriminant).
    pub by_material: Vec<u64>,
    /// Surface area per material, m² (roof texels measured in plan).
    pub area_m2: Vec<f64>,
    /// View pixels whose class was replaced by their architectural instance's dominant
    /// compatible class.
    pub refined_pixels: u64,
    /// Architectural instances refined (summed over views).
    pub refined_instances: u64,
    /// Rays cast that hit a chart within the gate but were masked: their pixel belongs to a
    /// clutter instance or shows an occluder (foliage).
    pub masked_rays: u64,
}

/// Material layers over a chart set: eq. (5)'s inputs and its result.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaterialLayers {
    /// The fused votes: exposure W_exp^(mat), hit counts and, per material (classes are
    /// P.2040 names indexed by Material discriminant), the sum of ω over pixels voting for it.
    pub fused: TexelLayers,
    /// The vote weight mu_m per class (same index as `fused.classes`).
    pub weights: Vec<f64>,
    /// One per chart, in the charts' order.
    pub charts: Vec<ChartMaterials>,
    /// Counts.
    pub stats: MaterialStats,
}
