//! What a ray's hit names: the wall chart of an object's triangle, and whether an object is
//! terrain.

use crate::artifact::{ChartKind, ChartSet, Scene};
use crate::street::fusion::ChartLookup;

/// Object and triangle -> chart index, and which objects are terrain.
pub(super) struct Lookup {
    pub(super) charts: ChartLookup,
    pub(super) terrain: Vec<bool>,
}

impl Lookup {
    pub(super) fn new(scene: &Scene, charts: &ChartSet) -> Lookup {
        let terrain = scene
            .objects
            .iter()
            .map(|o| o.class == crate::artifact::ObjectClass::Terrain)
            .collect();
        Lookup {
            charts: ChartLookup::new(scene, charts),
            terrain,
        }
    }

    pub(super) fn wall_chart(&self, charts: &ChartSet, object: usize, tri: usize) -> Option<u32> {
        let c = self.charts.chart(object, tri)?;
        (charts.charts[c as usize].kind == ChartKind::Wall).then_some(c)
    }
}
