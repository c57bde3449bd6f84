//! The clutter chain's knobs and the default class names of the views' clutter labels.

use std::collections::BTreeMap;

use super::assets::AssetKind;

/// Knobs of the clutter chain.
#[derive(Clone, Debug)]
pub struct ClutterConfig {
    /// View class name -> asset.
    pub classes: BTreeMap<String, AssetKind>,
    /// One calibration ray every `calib_stride` pixels each way.
    pub calib_stride: u32,
    /// At least this many calibration samples per view, else the pooled fit of all views.
    pub min_calib_samples: usize,
    /// Instances with fewer pixels are ignored.
    pub min_pixels: usize,
    /// Lifted points farther than this from the camera are ignored, metres.
    pub max_range_m: f64,
    /// Detections of one class within this many metres (times the class length, at least 1 m)
    /// join one cluster.
    pub cluster_factor: f64,
    /// A cluster within this many class lengths (at least 1.5 m) of a stronger one of its class
    /// is suppressed.
    pub nms_factor: f64,
    /// Clusters seen from fewer distinct views are dropped.
    pub min_views: usize,
    /// Clusters detected by fewer than this share of the views that should have seen them
    /// (framed, in range, unoccluded) are dropped: a segmenter's one-off errors.
    pub min_view_share: f64,
    /// Slack of the occlusion test of that count: a view's calibrated depth at the object may
    /// fall this many metres (plus 5 % of the range) in front of it and still count as seeing it.
    pub occlusion_tol_m: f64,
    /// Vehicles farther than this from the nearest street axis the camera track draws are
    /// off the road, metres.
    pub road_half_width_m: f64,
    /// Vehicles closer than this to a building are on the sidewalk, metres.
    pub vehicle_building_gap_m: f64,
    /// Roadside furniture closer than this to the nearest street axis the track draws is in
    /// the carriageway, metres.
    pub roadside_min_m: f64,
    /// A point free of buildings this far on both sides across the street is in an intersection.
    pub intersection_run_m: f64,
    /// Whether vehicles in intersections are dropped.
    pub drop_vehicles_in_intersections: bool,
    /// Seed of the Theil-Sen pair draws.
    pub seed: u64,
}

impl Default for ClutterConfig {
    fn default() -> Self {
        ClutterConfig {
            classes: default_classes(),
            calib_stride: 6,
            min_calib_samples: 50,
            min_pixels: 12,
            max_range_m: 45.0,
            cluster_factor: 0.6,
            nms_factor: 1.0,
            min_views: 1,
            min_view_share: 0.4,
            occlusion_tol_m: 1.0,
            road_half_width_m: 7.0,
            vehicle_building_gap_m: 2.0,
            roadside_min_m: 4.0,
            intersection_run_m: 20.0,
            drop_vehicles_in_intersections: true,
            seed: 7,
        }
    }
}

/// The default class table: the names the synthetic views and common clutter models use.
pub fn default_classes() -> BTreeMap<String, AssetKind> {
    [
        ("car", AssetKind::Car),
        ("van", AssetKind::Van),
        ("truck", AssetKind::Van),
        ("bus", AssetKind::Bus),
        ("pole", AssetKind::Pole),
        ("sign", AssetKind::Sign),
        ("bench", AssetKind::Bench),
        ("shelter", AssetKind::Shelter),
        ("hydrant", AssetKind::Hydrant),
        ("tree", AssetKind::SmallTree),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}
