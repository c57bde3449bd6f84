//! The artifact types that flow along graph edges. Plain data, serializable, deterministic.

mod array;
mod charts;
mod city;
mod footprints;
mod material;
mod material_layers;
mod measurements;
mod metrics;
mod ortho;
mod parts;
mod points;
mod raster;
mod relief;
mod report;
mod scene;
mod terrain_model;
mod views;

use serde::{Deserialize, Serialize};

pub use array::{PodVec, SparseLayer};
pub use charts::{Chart, ChartFrame, ChartKind, ChartLayers, ChartSet, FusionStats, TexelLayers};
pub use city::{
    BuildingSpec, City, ClutterSpec, CrownShape, FacadeFeature, Facades, FeatureKind, Rect, Roof,
    RoofBox, Street, TreeSpec,
};
pub use footprints::{Footprint, Footprints, Polygon, point_in_ring, ring_area};
pub use material::{Material, default_material};
pub use material_layers::{
    ChartMaterials, MaterialLayers, MaterialSource, MaterialStats, NO_MATERIAL,
};
pub use measurements::{Endpoint, Height, Link, Measurements, link_distance, measured_loss};
pub use metrics::{Half, Metrics, block_half, carrier_label};
pub use ortho::Ortho;
pub use parts::{MemParts, PartError, PartRef, PartStore, process_parts};
pub use points::PointSet;
pub use raster::{Grid, Raster};
pub use relief::{ReliefInstance, ReliefLayers, ReliefSet, ReliefStats};
pub use report::ReportFiles;
pub use scene::{MAX_COORD_M, Mesh, ObjectClass, Scene, SceneObject};
pub use terrain_model::{TerrainModel, height_at};
pub use views::{Instances, Intrinsics, Pose, RMSNET_CLASSES, View, ViewHead, ViewSet, Views};

/// The type of an artifact, as the loader checks it on every edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum ArtifactType {
    /// A [`Raster`]: one f32 band on a grid in the site frame.
    Raster,
    /// A [`PointSet`]: points in the site frame with per-point attributes.
    Points,
    /// [`Metrics`]: named numbers.
    Metrics,
    /// An [`Ortho`]: an RGB orthophoto in the site frame.
    Ortho,
    /// [`Measurements`]: measured radio links.
    Measurements,
    /// [`Footprints`]: building footprints.
    Footprints,
    /// A [`Scene`]: objects as triangle meshes with materials.
    Scene,
    /// A [`City`]: the synthetic site's ground truth.
    City,
    /// A [`ViewSet`]: street-level views with model outputs.
    Views,
    /// A report folder.
    Report,
    /// [`ChartSet`]: planar charts with texel grids on building surfaces.
    Charts,
    /// [`TexelLayers`]: per-texel exposure, hits and votes fused from street views.
    Texels,
    /// [`ReliefSet`]: façade relief posteriors (eq. (4)) and instances with their evidence.
    Relief,
    /// [`MaterialLayers`]: per-texel P.2040 materials (eq. (5)) with their evidence.
    Materials,
}

impl std::fmt::Display for ArtifactType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(self, f)
    }
}

/// Any artifact. The engine stores these as MessagePack; large arrays inside are raw bytes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Artifact {
    /// See [`Raster`].
    Raster(Raster),
    /// See [`PointSet`].
    Points(PointSet),
    /// See [`Metrics`].
    Metrics(Metrics),
    /// See [`Ortho`].
    Ortho(Ortho),
    /// See [`Measurements`].
    Measurements(Measurements),
    /// See [`Footprints`].
    Footprints(Footprints),
    /// See [`Scene`].
    Scene(Scene),
    /// See [`City`].
    City(City),
    /// See [`ViewSet`].
    Views(ViewSet),
    /// A report folder.
    Report(ReportFiles),
    /// See [`ChartSet`].
    Charts(ChartSet),
    /// See [`TexelLayers`].
    Texels(TexelLayers),
    /// See [`ReliefSet`].
    Relief(ReliefSet),
    /// See [`MaterialLayers`].
    Materials(MaterialLayers),
}

impl Artifact {
    /// The artifact's type.
    pub fn ty(&self) -> ArtifactType {
        match self {
            Artifact::Raster(_) => ArtifactType::Raster,
            Artifact::Points(_) => ArtifactType::Points,
            Artifact::Metrics(_) => ArtifactType::Metrics,
            Artifact::Ortho(_) => ArtifactType::Ortho,
            Artifact::Measurements(_) => ArtifactType::Measurements,
            Artifact::Footprints(_) => ArtifactType::Footprints,
            Artifact::Scene(_) => ArtifactType::Scene,
            Artifact::City(_) => ArtifactType::City,
            Artifact::Views(_) => ArtifactType::Views,
            Artifact::Report(_) => ArtifactType::Report,
            Artifact::Charts(_) => ArtifactType::Charts,
            Artifact::Texels(_) => ArtifactType::Texels,
            Artifact::Relief(_) => ArtifactType::Relief,
            Artifact::Materials(_) => ArtifactType::Materials,
        }
    }

    /// The parts the artifact names (a view set's pixels), in order: the engine keeps them with
    /// the artifact (stored, uploaded and collected together).
    pub fn parts(&self) -> Vec<PartRef> {
        match self {
            Artifact::Views(set) => set.parts().collect(),
            _ => Vec::new(),
        }
    }
}

/// A concrete artifact type that can be wrapped into and read out of [`Artifact`].
pub trait Typed: Sized + Send + Sync + 'static {
    /// Its [`ArtifactType`].
    const TYPE: ArtifactType;
    /// Wraps it.
    fn into_artifact(self) -> Artifact;
    /// Reads it out, if `a` is of this type.
    fn from_artifact(a: &Artifact) -> Option<&Self>;
}

macro_rules! typed {
    ($($variant:ident => $t:ty),* $(,)?) => {$(
        impl Typed for $t {
            const TYPE: ArtifactType = ArtifactType::$variant;
            fn into_artifact(self) -> Artifact { Artifact::$variant(self) }
            fn from_artifact(a: &Artifact) -> Option<&Self> {
                match a { Artifact::$variant(x) => Some(x), _ => None }
            }
        }
    )*};
}
typed!(
    Raster => Raster,
    Points => PointSet,
    Views => ViewSet,
    Report => ReportFiles,
    Metrics => Metrics,
    Ortho => Ortho,
    Measurements => Measurements,
    Footprints => Footprints,
    Scene => Scene,
    City => City,
    Charts => ChartSet,
    Texels => TexelLayers,
    Relief => ReliefSet,
    Materials => MaterialLayers,
);
