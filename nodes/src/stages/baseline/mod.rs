//! Baselines (Sec. 5): the OSM-extruded scene the peers build and the 3GPP TR 38.901 model.

pub mod osm_baseline;
pub mod tr38901;
