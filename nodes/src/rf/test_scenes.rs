//! Scenes the tracer's tests share (the unit tests and, through the public module, the GPU
//! backend's integration tests).

use glam::DVec3;

use crate::artifact::Material;
use crate::artifact::{Grid, Mesh, ObjectClass, PodVec, Scene, SceneObject};
use crate::geom::mesh_build::cuboid;
use crate::rf::map_plane::MapPlane;
use crate::rf::scene::RfScene;

/// A transmitter 12 m up at the crossing of [`street_grid`]'s first streets.
pub const STREET_TX: DVec3 = DVec3::new(-60.0, -56.0, 12.0);

/// The street grid's map cells: 4 m, 50 x 50 over x, y in [-100, 100].
pub fn street_map_grid() -> Grid {
    Grid {
        x0: -100.0,
        y0: 100.0,
        cell_m: 4.0,
        width: 50,
        height: 50,
    }
}

/// [`street_map_grid`]'s cells on a plane 1.5 m up.
pub fn street_plane() -> MapPlane {
    MapPlane::plane(street_map_grid(), 1.5)
}

/// [`street_grid_scene`] at 3.5 GHz, ready to trace.
pub fn street_grid() -> RfScene {
    RfScene::new(&street_grid_scene(), 3.5e9, false).unwrap()
}

/// 36 concrete blocks of 8 to 24 m, some turned, on a 6 x 6 street grid over x, y in about
/// [-85, 85], standing on a 400 m ground of two triangles.
pub fn street_grid_scene() -> Scene {
    let mut objects: Vec<SceneObject> = (0..36)
        .map(|k| SceneObject {
            id: format!("b{k}"),
            class: ObjectClass::Building,
            mesh: cuboid(
                [(k % 6) as f64 * 30.0 - 75.0, (k / 6) as f64 * 28.0 - 70.0],
                [18.0 + (k % 4) as f64, 16.0, 8.0 + (k % 5) as f64 * 4.0],
                (k % 3) as f64 * 0.1,
                0.0,
                Material::Concrete,
            ),
        })
        .collect();
    objects.push(SceneObject {
        id: "ground".into(),
        class: ObjectClass::Terrain,
        mesh: Mesh {
            positions: PodVec(vec![
                [-200.0, -200.0, 0.0],
                [200.0, -200.0, 0.0],
                [200.0, 200.0, 0.0],
                [-200.0, 200.0, 0.0],
            ]),
            triangles: PodVec(vec![[0, 1, 2], [0, 2, 3]]),
            materials: PodVec(vec![Material::MediumDryGround as u8; 2]),
        },
    });
    Scene { objects }
}
