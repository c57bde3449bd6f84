//! The materials a surface or volume can carry: the ITU-R P.2040 classes (Table 3) as Sionna RT
//! names them, plus foliage. Only the names and their order live here (a scene stores one `u8`
//! per triangle); their electromagnetic laws are physics, in `rf::materials`.

use serde::{Deserialize, Serialize};

use crate::artifact::ObjectClass;

/// A surface or volume material. Stored per triangle as its `u8` discriminant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[repr(u8)]
pub enum Material {
    /// ITU concrete.
    Concrete = 0,
    /// ITU brick.
    Brick = 1,
    /// ITU plasterboard.
    Plasterboard = 2,
    /// ITU wood.
    Wood = 3,
    /// ITU glass.
    Glass = 4,
    /// ITU ceiling board.
    CeilingBoard = 5,
    /// ITU chipboard.
    Chipboard = 6,
    /// ITU plywood.
    Plywood = 7,
    /// ITU marble.
    Marble = 8,
    /// ITU floorboard.
    Floorboard = 9,
    /// ITU metal.
    Metal = 10,
    /// ITU very dry ground.
    VeryDryGround = 11,
    /// ITU medium dry ground.
    MediumDryGround = 12,
    /// ITU wet ground.
    WetGround = 13,
    /// Foliage: not a P.2040 surface but an absorbing volume (ITU-R P.833 loss along paths).
    Foliage = 14,
}

/// The ITU material an object of `class` gets until the material stages assign per-surface ones:
/// ground for the terrain, concrete for buildings (and surfaces not yet split into objects),
/// foliage for vegetation, metal for street clutter (cars, poles, signs).
pub fn default_material(class: ObjectClass) -> Material {
    match class {
        ObjectClass::Terrain => Material::MediumDryGround,
        ObjectClass::Building | ObjectClass::Unsegmented => Material::Concrete,
        ObjectClass::Vegetation => Material::Foliage,
        ObjectClass::Clutter => Material::Metal,
    }
}

impl Material {
    /// Every material, in discriminant order.
    pub const ALL: [Material; 15] = [
        Material::Concrete,
        Material::Brick,
        Material::Plasterboard,
        Material::Wood,
        Material::Glass,
        Material::CeilingBoard,
        Material::Chipboard,
        Material::Plywood,
        Material::Marble,
        Material::Floorboard,
        Material::Metal,
        Material::VeryDryGround,
        Material::MediumDryGround,
        Material::WetGround,
        Material::Foliage,
    ];

    /// The material with discriminant `v`.
    pub fn from_u8(v: u8) -> Option<Material> {
        Material::ALL.get(v as usize).copied()
    }

    /// Sionna RT's `itu_type` (the `itu_` prefix of scene ids removed); foliage has none.
    pub fn itu_type(self) -> Option<&'static str> {
        Some(match self {
            Material::Concrete => "concrete",
            Material::Brick => "brick",
            Material::Plasterboard => "plasterboard",
            Material::Wood => "wood",
            Material::Glass => "glass",
            Material::CeilingBoard => "ceiling_board",
            Material::Chipboard => "chipboard",
            Material::Plywood => "plywood",
            Material::Marble => "marble",
            Material::Floorboard => "floorboard",
            Material::Metal => "metal",
            Material::VeryDryGround => "very_dry_ground",
            Material::MediumDryGround => "medium_dry_ground",
            Material::WetGround => "wet_ground",
            Material::Foliage => return None,
        })
    }

    /// The material named by a Sionna id (`itu_concrete`, `mat-itu_concrete`, `concrete`).
    pub fn from_name(name: &str) -> Option<Material> {
        let n = name.strip_prefix("mat-").unwrap_or(name);
        let n = n.strip_prefix("itu_").unwrap_or(n);
        Material::ALL
            .into_iter()
            .find(|m| m.itu_type() == Some(n) || (n == "foliage" && *m == Material::Foliage))
    }
}
