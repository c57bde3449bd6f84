//! A tiled run's scenes into one: each object from the tile that owns it.

use crate::artifact::{ArtifactType, Mesh, ObjectClass, Scene, SceneObject};
use crate::site::{MergeTilesParams, Window};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Each tile keeps the objects whose owner point ([`Mesh::owner_point`]: a solid's volume
/// centroid, its footprint's for a prism) lies in its core, their ids prefixed with the tile's
/// name (`x1y0/building-12`); a building therefore comes whole from one tile, and no solid is
/// cut at a seam. A terrain (or an unsegmented surface) is no solid: its triangles are kept by
/// their centroids, and the tiles' pieces join into one object of that id. A graph that wants one
/// seamless terrain merges the terrain raster instead and assembles the scene after the merge.
pub struct MergeScenes;

impl Stage for MergeScenes {
    const KIND: &'static str = "MergeScenes";
    const VERSION: u32 = 1;
    const DOC: &'static str = "a tiled run's scenes into one, each object from the tile holding its centroid (added by the engine)";
    const INPUTS: &'static [InputSpec] = &[InputSpec::many(
        "tiles",
        ArtifactType::Scene,
        "each tile's scene, in the order of `tiles`",
    )];
    type Params = MergeTilesParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        p.validate().map_err(|(f, m)| ParamError::new(f, m))
    }

    fn run(p: &Self::Params, inputs: &Inputs, _ctx: &Ctx) -> Result<Scene, StageError> {
        let parts: Vec<&Scene> = inputs.many("tiles")?;
        p.check_inputs(parts.len()).map_err(StageError::Failed)?;
        let mut surfaces: Vec<SceneObject> = Vec::new();
        let mut objects = Vec::new();
        for (tile, scene) in p.tiles.iter().zip(parts) {
            for o in &scene.objects {
                if is_surface(o.class) {
                    let piece = triangles_in(&o.mesh, tile.core);
                    match surfaces.iter_mut().find(|s| s.id == o.id) {
                        Some(s) => s.mesh.append(&piece),
                        None => surfaces.push(SceneObject {
                            id: o.id.clone(),
                            class: o.class,
                            mesh: piece,
                        }),
                    }
                } else if o
                    .mesh
                    .owner_point()
                    .is_some_and(|(x, y)| tile.core.contains(x, y))
                {
                    objects.push(SceneObject {
                        id: format!("{}/{}", tile.name, o.id),
                        class: o.class,
                        mesh: o.mesh.clone(),
                    });
                }
            }
        }
        surfaces.retain(|s| !s.mesh.is_empty());
        surfaces.extend(objects);
        Ok(Scene { objects: surfaces })
    }
}

/// Open surfaces, cut by triangle rather than owned whole.
fn is_surface(class: ObjectClass) -> bool {
    matches!(class, ObjectClass::Terrain | ObjectClass::Unsegmented)
}

/// The triangles of `mesh` whose centroids lie in `core`, with the vertices they use.
fn triangles_in(mesh: &Mesh, core: Window) -> Mesh {
    mesh.select_triangles(|ps| {
        let cx = (ps[0][0] as f64 + ps[1][0] as f64 + ps[2][0] as f64) / 3.0;
        let cy = (ps[0][1] as f64 + ps[1][1] as f64 + ps[2][1] as f64) / 3.0;
        core.contains(cx, cy)
    })
}
