//! Ingest of Sionna RT scenes (Mitsuba 3 XML + PLY): the scenes Sionna ships, and any exported
//! from Blender for it, become scenes our tracer and exporters use.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::artifact::Scene;
use crate::io::sionna_xml::read_scene;
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, Stage, StageError};

/// Params of [`ReadSionnaScene`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadSionnaSceneParams {
    /// The scene XML; the PLY files it names sit in its folder (which is what the cache digests).
    pub path: String,
}

/// One object per shape, its triangles carrying the shape's ITU material. Coordinates are taken
/// as site-frame metres, z up (Sionna scenes are local).
pub struct ReadSionnaScene;

impl Stage for ReadSionnaScene {
    const KIND: &'static str = "ReadSionnaScene";
    const VERSION: u32 = 1;
    const DOC: &'static str = "a Sionna RT scene (Mitsuba XML + PLY, ITU radio materials)";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadSionnaSceneParams;
    type Output = Scene;

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: crate::params::folder_of(&p.path),
        }]
    }

    fn run(p: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        let folder = ctx.file(0)?;
        read_scene(&folder.join(Path::new(&p.path).file_name().unwrap_or_default()))
    }
}
