//! The synthetic city's true building footprints, with heights, for scoring reconstructions
//! (footprint IoU, roof height error) and as an OSM-like input with perfect tags.

use serde::{Deserialize, Serialize};

use crate::artifact::{ArtifactType, City, Footprint, Footprints};
use crate::stage::{Ctx, InputSpec, Inputs, Stage, StageError};

/// [`CityFootprints`] has no parameters.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CityFootprintsParams {}

/// One footprint per building: its outline and the height of its highest roof point above its
/// ground (furniture excluded).
pub struct CityFootprints;

impl Stage for CityFootprints {
    const KIND: &'static str = "CityFootprints";
    const VERSION: u32 = 1;
    const DOC: &'static str = "true footprints of a synthetic city, with roof heights";
    const INPUTS: &'static [InputSpec] = &[InputSpec::one(
        "city",
        ArtifactType::City,
        "the synthetic city",
    )];
    type Params = CityFootprintsParams;
    type Output = Footprints;

    fn run(_: &Self::Params, inputs: &Inputs, _: &Ctx) -> Result<Footprints, StageError> {
        let city: &City = inputs.one("city")?;
        Ok(Footprints {
            items: city
                .buildings
                .iter()
                .map(|b| Footprint {
                    id: b.id.clone(),
                    polygons: vec![b.footprint.clone()],
                    height_m: Some(b.top_m()),
                    min_height_m: None,
                    levels: None,
                    min_level: None,
                })
                .collect(),
        })
    }
}
