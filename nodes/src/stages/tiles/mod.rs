//! City scale: the merges of a tiled run. A tiled run (`tiling:` in a graph, `--tile-m` on the
//! command line) makes the nodes downstream of a windowed stage once per tile, each reading its
//! tile's core grown by the halo, and gives each node the graph names in `tiling.merge` one merge
//! of its tiles' outputs: every object, cell or point is taken from the one tile whose core holds
//! it. The engine adds these nodes; a graph never names them.

use crate::artifact::ArtifactType;

pub mod merge_points;
pub mod merge_rasters;
pub mod merge_scenes;

/// The kind of the node that merges the tiles' outputs of type `ty`, if there is one.
pub fn merge_kind(ty: ArtifactType) -> Option<&'static str> {
    use crate::Stage;
    match ty {
        ArtifactType::Scene => Some(merge_scenes::MergeScenes::KIND),
        ArtifactType::Raster => Some(merge_rasters::MergeRasters::KIND),
        ArtifactType::Points => Some(merge_points::MergePoints::KIND),
        _ => None,
    }
}

/// The types [`merge_kind`] merges, for messages.
pub const MERGED_TYPES: &str = "Scene, Raster, Points";
