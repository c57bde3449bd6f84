//! The clutter asset library (paper Sec. 4.2.4): a small closed mesh per class, built in code from
//! extruded profiles, prisms and ellipsoids, with ITU-R P.2040 materials (metal bodies, glass
//! windows, wooden benches and trunks, foliage crowns). Each part is one closed solid that passes
//! `mesh_check::check_solid`; an asset with a trunk and a crown is two parts.

use serde::{Deserialize, Serialize};

use crate::artifact::Material;
use crate::artifact::{Mesh, ObjectClass, Polygon};
use crate::geom::mesh_build::{Builder, ellipsoid, prism, triangulate};

/// The asset classes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum AssetKind {
    /// A passenger car, 4.5 x 1.8 x 1.5 m.
    Car,
    /// A van, 5.2 x 2.0 x 2.3 m.
    Van,
    /// A bus, 12 x 2.5 x 3.2 m.
    Bus,
    /// A street-light pole, 8 m.
    Pole,
    /// A traffic sign on its post, plate 0.9 x 0.6 m from 2.2 m.
    Sign,
    /// A bench with a backrest, 1.8 m.
    Bench,
    /// A bus shelter, 3.5 x 1.6 x 2.6 m.
    Shelter,
    /// A fire hydrant, 0.8 m.
    Hydrant,
    /// A small street tree: trunk and ellipsoidal crown.
    SmallTree,
}

/// Every asset kind, in order.
pub const ASSET_KINDS: [AssetKind; 9] = [
    AssetKind::Car,
    AssetKind::Van,
    AssetKind::Bus,
    AssetKind::Pole,
    AssetKind::Sign,
    AssetKind::Bench,
    AssetKind::Shelter,
    AssetKind::Hydrant,
    AssetKind::SmallTree,
];

/// One closed solid of a placed asset.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    /// Appended to the object id (`""` for the main body, `"-trunk"`...).
    pub suffix: &'static str,
    /// What the part is.
    pub class: ObjectClass,
    /// Its mesh in the site frame.
    pub mesh: Mesh,
}

impl AssetKind {
    /// Length (along the heading), width and height of the default asset, metres.
    pub fn size(self) -> [f64; 3] {
        match self {
            AssetKind::Car => [4.5, 1.8, 1.5],
            AssetKind::Van => [5.2, 2.0, 2.3],
            AssetKind::Bus => [12.0, 2.5, 3.2],
            AssetKind::Pole => [0.25, 0.25, 8.0],
            AssetKind::Sign => [0.9, 0.08, 2.8],
            AssetKind::Bench => [1.8, 0.5, 0.9],
            AssetKind::Shelter => [3.5, 1.6, 2.6],
            AssetKind::Hydrant => [0.3, 0.3, 0.8],
            AssetKind::SmallTree => [5.8, 5.8, 8.5],
        }
    }

    /// How far the surface a camera sees lies in front of the asset's centre, on average over
    /// its pixels, metres: half the width of a box seen face on; 2/3 of the radius of a round
    /// one (the mean of cos over a disc's projected area).
    pub fn visible_depth(self) -> f64 {
        match self {
            AssetKind::Pole => 2.0 / 3.0 * 0.125,
            AssetKind::Hydrant => 2.0 / 3.0 * 0.15,
            AssetKind::SmallTree => 2.0 / 3.0 * 2.9,
            AssetKind::Sign => 0.04,
            k => k.size()[1].min(k.size()[0]) / 2.0,
        }
    }

    /// Vehicles: on the carriageway, aligned with the street.
    pub fn is_vehicle(self) -> bool {
        matches!(self, AssetKind::Car | AssetKind::Van | AssetKind::Bus)
    }

    /// Street furniture that stands at road edges and on sidewalks.
    pub fn is_roadside(self) -> bool {
        matches!(
            self,
            AssetKind::Pole | AssetKind::Sign | AssetKind::Hydrant | AssetKind::Bench
        )
    }

    /// The asset standing on `z0` at `center`, turned `heading` radians counter-clockwise from +x,
    /// its height scaled by `height_scale` (1 = the default size).
    pub fn build(self, center: [f64; 2], heading: f64, z0: f64, height_scale: f64) -> Vec<Part> {
        let s = height_scale;
        let at = Placement {
            center,
            heading,
            z0,
            s,
        };
        let body = |mesh: Mesh| {
            vec![Part {
                suffix: "",
                class: ObjectClass::Clutter,
                mesh,
            }]
        };
        match self {
            AssetKind::Car => body(car(&at)),
            AssetKind::Van => body(van(&at)),
            AssetKind::Bus => body(bus(&at)),
            AssetKind::Pole => body(column(center, 0.125, z0, z0 + 8.0 * s, Material::Metal)),
            AssetKind::Hydrant => body(column(center, 0.15, z0, z0 + 0.8 * s, Material::Metal)),
            AssetKind::Sign => body(sign(&at)),
            AssetKind::Bench => body(bench(&at)),
            AssetKind::Shelter => body(shelter(&at)),
            AssetKind::SmallTree => small_tree(&at),
        }
    }
}

/// Where and how big an asset stands: the arguments of `AssetKind::build`, shared by its
/// per-class steps.
struct Placement {
    center: [f64; 2],
    heading: f64,
    z0: f64,
    /// The height scale (1 = the default size).
    s: f64,
}

/// A car: its side profile (length u, height z) extruded 1.8 m across, glass windscreen and
/// windows, metal body. A step of `AssetKind::build`: one class's shape and materials.
fn car(at: &Placement) -> Mesh {
    let s = at.s;
    let ring = [
        (-2.25, 0.0),
        (2.25, 0.0),
        (2.25, 0.75),
        (1.2, 0.9),
        (0.6, 1.5),
        (-1.2, 1.5),
        (-1.9, 0.95),
        (-2.25, 0.85),
    ];
    extrude(
        &scale_z(&ring, s),
        1.8,
        at.center,
        at.heading,
        at.z0,
        |e| {
            if e == 3 || e == 5 {
                Material::Glass
            } else {
                Material::Metal
            }
        },
        |_, z| {
            if z > 0.95 * s {
                Material::Glass
            } else {
                Material::Metal
            }
        },
    )
}

/// A van: its side profile extruded 2.0 m across, a glass windscreen and front side windows,
/// metal body. A step of `AssetKind::build`: one class's shape and materials.
fn van(at: &Placement) -> Mesh {
    let s = at.s;
    let ring = [
        (-2.6, 0.0),
        (2.6, 0.0),
        (2.6, 0.9),
        (2.1, 1.2),
        (1.7, 2.3),
        (-2.6, 2.3),
    ];
    extrude(
        &scale_z(&ring, s),
        2.0,
        at.center,
        at.heading,
        at.z0,
        |e| {
            if e == 3 {
                Material::Glass
            } else {
                Material::Metal
            }
        },
        |u, z| {
            if z > 1.3 * s && u > 0.9 {
                Material::Glass
            } else {
                Material::Metal
            }
        },
    )
}

/// A bus: its side profile extruded 2.5 m across, a glass windscreen and a band of side
/// windows, metal body. A step of `AssetKind::build`: one class's shape and materials.
fn bus(at: &Placement) -> Mesh {
    let s = at.s;
    let ring = [
        (-6.0, 0.0),
        (6.0, 0.0),
        (6.0, 1.1),
        (5.9, 3.2),
        (-5.9, 3.2),
        (-6.0, 1.1),
    ];
    extrude(
        &scale_z(&ring, s),
        2.5,
        at.center,
        at.heading,
        at.z0,
        |e| {
            if e == 2 {
                Material::Glass
            } else {
                Material::Metal
            }
        },
        |_, z| {
            if z > 1.4 * s && z < 2.8 * s {
                Material::Glass
            } else {
                Material::Metal
            }
        },
    )
}

/// A traffic sign: post and plate in one metal profile (its heights scaled in place), extruded
/// 0.08 m. A step of `AssetKind::build`: one class's shape and materials.
fn sign(at: &Placement) -> Mesh {
    let s = at.s;
    let (lift, top) = (2.2 * s, 2.8 * s);
    let ring = [
        (-0.04, 0.0),
        (0.04, 0.0),
        (0.04, lift),
        (0.45, lift),
        (0.45, top),
        (-0.45, top),
        (-0.45, lift),
        (-0.04, lift),
    ];
    extrude(
        &ring,
        0.08,
        at.center,
        at.heading,
        at.z0,
        |_| Material::Metal,
        |_, _| Material::Metal,
    )
}

/// A bench: its wooden side profile extruded along its 1.8 m length. A step of
/// `AssetKind::build`: one class's shape and materials.
fn bench(at: &Placement) -> Mesh {
    let s = at.s;
    // Side profile across the bench (depth u, height z), extruded along its length.
    let ring = [
        (-0.25, 0.0),
        (-0.17, 0.0),
        (-0.17, 0.42),
        (0.17, 0.42),
        (0.17, 0.0),
        (0.25, 0.0),
        (0.25, 0.5),
        (-0.17, 0.5),
        (-0.17, 0.9),
        (-0.25, 0.9),
    ];
    extrude(
        &scale_z(&ring, s),
        1.8,
        at.center,
        at.heading + std::f64::consts::FRAC_PI_2,
        at.z0,
        |_| Material::Wood,
        |_, _| Material::Wood,
    )
}

/// A bus shelter: its cross-section (glass back wall, metal roof) extruded along its 3.5 m
/// length. A step of `AssetKind::build`: one class's shape and materials.
fn shelter(at: &Placement) -> Mesh {
    let s = at.s;
    // Cross-section (depth u, height z): a glass back wall under a metal roof.
    let ring = [
        (-0.8, 0.0),
        (-0.7, 0.0),
        (-0.7, 2.5),
        (0.8, 2.5),
        (0.8, 2.6),
        (-0.8, 2.6),
    ];
    extrude(
        &scale_z(&ring, s),
        3.5,
        at.center,
        at.heading + std::f64::consts::FRAC_PI_2,
        at.z0,
        |e| {
            if e == 3 || e == 4 || e == 5 {
                Material::Metal
            } else {
                Material::Glass
            }
        },
        |_, z| {
            if z > 2.45 * s {
                Material::Metal
            } else {
                Material::Glass
            }
        },
    )
}

/// A small tree: a wooden trunk column and a foliage ellipsoid crown, two parts. A step of
/// `AssetKind::build`: one class's shape and materials.
fn small_tree(at: &Placement) -> Vec<Part> {
    let s = at.s;
    let (trunk, crown, radius) = (2.8 * s, 5.7 * s, 2.9);
    vec![
        Part {
            suffix: "-trunk",
            class: ObjectClass::Vegetation,
            mesh: column(at.center, 0.15, at.z0, at.z0 + trunk + 0.3, Material::Wood),
        },
        Part {
            suffix: "",
            class: ObjectClass::Vegetation,
            mesh: ellipsoid(
                [at.center[0], at.center[1], at.z0 + trunk + crown / 2.0],
                [radius, radius, crown / 2.0],
                12,
                Material::Foliage,
            ),
        },
    ]
}

fn scale_z(ring: &[(f64, f64)], s: f64) -> Vec<(f64, f64)> {
    ring.iter().map(|&(u, z)| (u, z * s)).collect()
}

/// A closed octagonal column of radius `r` from `z0` to `z1`.
fn column(c: [f64; 2], r: f64, z0: f64, z1: f64, m: Material) -> Mesh {
    let ring: Vec<[f64; 2]> = (0..8)
        .map(|k| {
            let a = std::f64::consts::TAU * (k as f64 + 0.5) / 8.0;
            [c[0] + r * a.cos(), c[1] + r * a.sin()]
        })
        .collect();
    let poly = Polygon::normalized(ring, vec![]).expect("an octagon is a polygon");
    prism(&poly, z0, z1, m, m).expect("an octagon triangulates")
}

/// A closed solid: the profile `ring` (counter-clockwise in the (u, z) plane, u along the heading)
/// extruded `width` metres across, centred on `center`, standing on `z0`. `edge_material(i)` is
/// the material of the strip along profile edge i -> i+1, `cap_material(u, z)` that of a cap
/// triangle with centroid (u, z).
fn extrude(
    ring: &[(f64, f64)],
    width: f64,
    center: [f64; 2],
    heading: f64,
    z0: f64,
    edge_material: impl Fn(usize) -> Material,
    cap_material: impl Fn(f64, f64) -> Material,
) -> Mesh {
    let poly = Polygon {
        exterior: ring.iter().map(|&(u, z)| [u, z]).collect(),
        holes: vec![],
    };
    let caps = triangulate(&poly).expect("asset profiles are simple polygons");
    let (sn, cs) = heading.sin_cos();
    let place = |u: f64, v: f64, z: f64| {
        [
            center[0] + cs * u - sn * v,
            center[1] + sn * u + cs * v,
            z0 + z,
        ]
    };
    let hw = width / 2.0;
    let mut b = Builder::default();
    let near: Vec<u32> = ring.iter().map(|&(u, z)| b.v(place(u, -hw, z))).collect();
    let far: Vec<u32> = ring.iter().map(|&(u, z)| b.v(place(u, hw, z))).collect();
    for t in &caps {
        let [i, j, k] = t.map(|i| i as usize);
        let (cu, cz) = (
            (ring[i].0 + ring[j].0 + ring[k].0) / 3.0,
            (ring[i].1 + ring[j].1 + ring[k].1) / 3.0,
        );
        let m = cap_material(cu, cz);
        // Counter-clockwise in (u, z) faces -v: the near cap as is, the far one reversed.
        b.tri(near[i], near[j], near[k], m);
        b.tri(far[i], far[k], far[j], m);
    }
    let n = ring.len();
    for i in 0..n {
        let j = (i + 1) % n;
        b.quad(near[i], far[i], far[j], near[j], edge_material(i));
    }
    b.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::mesh_check::check_solid;

    #[test]
    fn every_asset_is_a_checked_solid_of_its_size() {
        for kind in ASSET_KINDS {
            for heading in [0.0, 0.7, -2.0] {
                let parts = kind.build([10.0, -4.0], heading, 3.0, 1.0);
                assert!(!parts.is_empty());
                for p in &parts {
                    let r = check_solid(&p.mesh).unwrap_or_else(|e| panic!("{kind:?}: {e}"));
                    assert!(r.volume_m3 > 0.0);
                    assert_eq!(p.mesh.materials.len(), p.mesh.triangles.len());
                    let zmin = p
                        .mesh
                        .positions
                        .iter()
                        .map(|v| v[2])
                        .fold(f32::MAX, f32::min);
                    assert!(zmin >= 2.99, "{kind:?} below its base: {zmin}");
                }
                let top = parts
                    .iter()
                    .flat_map(|p| p.mesh.positions.iter())
                    .map(|v| v[2] as f64 - 3.0)
                    .fold(0.0, f64::max);
                assert!(
                    (top - kind.size()[2]).abs() < 0.05,
                    "{kind:?}: top {top} vs {}",
                    kind.size()[2]
                );
            }
        }
    }

    #[test]
    fn vehicles_have_metal_bodies_and_glass_windows() {
        for kind in [AssetKind::Car, AssetKind::Van, AssetKind::Bus] {
            let parts = kind.build([0.0, 0.0], 0.0, 0.0, 1.0);
            let m = &parts[0].mesh.materials;
            assert!(m.contains(&(Material::Metal as u8)), "{kind:?}");
            assert!(m.contains(&(Material::Glass as u8)), "{kind:?}");
        }
    }
}
