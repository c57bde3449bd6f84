//! Where a radio map is measured: a horizontal plane or a surface lifted above the terrain, in
//! cells, and where a ray crosses it. The shooter (`radiomap`) and its diffraction
//! (`radiomap_diffraction`) both score on it.

use glam::DVec3;

use crate::artifact::{Grid, Raster};

use super::scene::{EPS, RfScene};

/// Where a map is measured: the cells of `grid` on the horizontal plane at height `z`, or on a
/// surface following the terrain (`lifted`, e.g. 1.5 m above it), which rays cross transparently.
pub struct MapPlane {
    /// The cells (north-up).
    pub grid: Grid,
    /// Height of the plane, metres (site frame); unused with a lifted surface.
    pub z: f64,
    /// The terrain-following measurement surface, if any.
    pub lifted: Option<crate::geom::raycast::SceneRays>,
}

impl MapPlane {
    /// A horizontal plane at `z` over `grid`.
    pub fn plane(grid: Grid, z: f64) -> MapPlane {
        MapPlane {
            grid,
            z,
            lifted: None,
        }
    }

    /// The surface `height_m` above `terrain`, over `grid`: the terrain meshed at the grid's
    /// cell size and lifted.
    pub fn above_terrain(grid: Grid, terrain: &Raster, height_m: f64) -> Result<MapPlane, String> {
        let mesh = crate::geom::terrain_mesh::terrain_mesh(
            terrain,
            grid.cell_m,
            crate::artifact::Material::MediumDryGround,
        )?;
        Ok(MapPlane::lifted(grid, mesh, height_m))
    }

    /// [`MapPlane::above_terrain`] for a window of the map's lattice: the terrain meshed
    /// under `grid` alone ([`crate::geom::terrain_mesh::terrain_mesh_over`]).
    pub fn above_terrain_over(
        grid: Grid,
        terrain: &Raster,
        height_m: f64,
    ) -> Result<MapPlane, String> {
        let mesh = crate::geom::terrain_mesh::terrain_mesh_over(
            terrain,
            grid,
            crate::artifact::Material::MediumDryGround,
        )?;
        Ok(MapPlane::lifted(grid, mesh, height_m))
    }

    /// The surface of `mesh` lifted by `height_m`, its crossings binned on `grid`.
    fn lifted(grid: Grid, mut mesh: crate::artifact::Mesh, height_m: f64) -> MapPlane {
        for p in mesh.positions.iter_mut() {
            p[2] += height_m as f32;
        }
        let scene = crate::artifact::Scene {
            objects: vec![crate::artifact::SceneObject {
                id: "measurement-surface".into(),
                class: crate::artifact::ObjectClass::Unsegmented,
                mesh,
            }],
        };
        MapPlane {
            grid,
            z: f64::NAN,
            lifted: Some(crate::geom::raycast::SceneRays::new(&scene)),
        }
    }

    /// Each crossing of the surface by the segment `o + t d`, t in (EPS, t_end), in order.
    pub(super) fn crossings(&self, o: DVec3, d: DVec3, t_end: f64, out: &mut Vec<Crossing>) {
        let g = self.grid;
        let mut add = |t: f64, normal: DVec3| {
            let p = o + d * t;
            if let Some((c, r)) = g.cell_of(p.x, p.y) {
                out.push(Crossing {
                    t,
                    cell: r * g.width + c,
                    normal,
                });
            }
        };
        match &self.lifted {
            None => {
                if d.z != 0.0 {
                    let t = (self.z - o.z) / d.z;
                    if t > EPS && t < t_end {
                        add(t, DVec3::Z);
                    }
                }
            }
            Some(rays) => {
                let mut tmin = EPS;
                while let Some(h) = rays.cast(
                    o.as_vec3().into(),
                    d.as_vec3().into(),
                    tmin as f32,
                    t_end.min(f32::MAX as f64) as f32,
                ) {
                    let t = h.t as f64;
                    add(t, DVec3::from(h.normal.map(f64::from)));
                    tmin = t + EPS;
                    // Past 2^14 m an f32 step of EPS can round back onto the same hit.
                    if (tmin as f32) <= h.t {
                        break;
                    }
                }
            }
        }
    }

    /// The area of the surface over one cell where its normal is `n`: a tilted patch over a cell
    /// of area A has area A / n_z.
    pub(super) fn patch_area(&self, n: DVec3) -> f64 {
        self.grid.cell_m * self.grid.cell_m / n.z.abs().max(1e-6)
    }
}

/// Where a ray crosses a map's surface: how far along, in which cell, and the surface's normal
/// there.
pub(super) struct Crossing {
    pub t: f64,
    pub cell: u32,
    pub normal: DVec3,
}

/// Sionna's default plane: the scene's horizontal extent in cells of `cell_m`, centred on it,
/// at height `z`.
pub fn default_plane(scene: &RfScene, cell_m: f64, z: f64) -> MapPlane {
    MapPlane::plane(default_grid(scene.bounds, cell_m), z)
}

/// [`default_plane`]'s cells for a scene of `bounds` (its triangles' corners, least and most).
pub fn default_grid((lo, hi): (DVec3, DVec3), cell_m: f64) -> Grid {
    let (cx, cy) = ((lo.x + hi.x) / 2.0, (lo.y + hi.y) / 2.0);
    let nx = ((hi.x - lo.x) / cell_m).ceil().max(1.0) as u32;
    let ny = ((hi.y - lo.y) / cell_m).ceil().max(1.0) as u32;
    Grid {
        x0: cx - nx as f64 * cell_m / 2.0,
        y0: cy + ny as f64 * cell_m / 2.0,
        cell_m,
        width: nx,
        height: ny,
    }
}
