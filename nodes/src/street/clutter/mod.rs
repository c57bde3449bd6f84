//! Clutter from street views (paper Sec. 4.2.4): each view's depth calibrated against the twin
//! with a Theil-Sen affine fit, clutter instances lifted to world positions, repeated detections
//! clustered across views, clusters too few of the views framing them detected dropped,
//! non-maximum suppression by class and distance, a scene grammar whose every rule's effect is
//! counted, and the survivors instantiated from the asset library.

pub mod assets;

mod clustering;
mod config;
mod grammar;
mod lifting;
mod spread;
mod support;
mod track;

use std::collections::BTreeMap;

use crate::artifact::{Metrics, Raster, Scene, SceneObject, Views};
use crate::geom::theil_sen::median;
use crate::stage::StageError;

pub use clustering::{Cluster, cluster, nms};
pub use config::{ClutterConfig, default_classes};
pub use grammar::{Ground, Placed, grammar};
pub use lifting::{Calibration, Detection, calibrate, calibration_samples, lift_view};
pub use support::{should_see, supported};
pub use track::Track;

/// The whole chain over a view set: calibration, lifting, clustering, support, NMS, grammar.
/// Returns the placed objects and the counts (detections, clusters, unsupported, suppressed, each
/// grammar rule, placed per class, calibration figures).
///
/// Three passes over the views (calibration, lifting, support), each reading a view at a time.
pub fn place_clutter(
    views: Views,
    twin: &Scene,
    terrain: &Raster,
    canopies: Option<&Scene>,
    cfg: &ClutterConfig,
) -> Result<(Vec<Placed>, Metrics), StageError> {
    let cals = calibrate(views, twin, cfg)?;
    let track = Track::new(&views.set.views);
    let dets: Vec<Detection> = views
        .map(|k, v| {
            cals[k]
                .map(|c| lift_view(k, v, &c, Some(&track), cfg))
                .unwrap_or_default()
        })?
        .into_iter()
        .flatten()
        .collect();
    let mut m = Metrics::default();
    let fitted: Vec<&Calibration> = cals.iter().flatten().collect();
    m.set("views", views.len() as f64);
    m.set(
        "calibration_views_uncalibrated",
        cals.iter().filter(|c| c.is_none()).count() as f64,
    );
    m.set(
        "calibration_views_pooled",
        fitted.iter().filter(|c| c.pooled).count() as f64,
    );
    if !fitted.is_empty() {
        let mut a: Vec<f64> = fitted.iter().map(|c| c.fit.slope).collect();
        let mut b: Vec<f64> = fitted.iter().map(|c| c.fit.intercept).collect();
        m.set(
            "calibration_median_slope",
            median(&mut a).unwrap_or(f64::NAN),
        );
        m.set(
            "calibration_median_intercept_m",
            median(&mut b).unwrap_or(f64::NAN),
        );
    }
    m.set("detections", dets.len() as f64);
    let clusters = cluster(&dets, cfg);
    m.set("clusters", clusters.len() as f64);
    let (clusters, unsupported) = supported(clusters, views, &cals, cfg)?;
    m.set("unsupported", unsupported as f64);
    let (kept, suppressed) = nms(clusters, cfg);
    m.set("nms_suppressed", suppressed as f64);
    let ground = Ground::new(terrain, twin, &views.set.views, canopies);
    let mut counts = BTreeMap::new();
    let mut placed = grammar(kept, &ground, cfg, &mut counts);
    placed.sort_by(|a, b| {
        a.class
            .cmp(&b.class)
            .then(a.xy[0].total_cmp(&b.xy[0]))
            .then(a.xy[1].total_cmp(&b.xy[1]))
    });
    for (k, v) in counts {
        m.set(k, v as f64);
    }
    for p in &placed {
        let key = format!("placed_{}", p.class);
        let n = m.get(&key).unwrap_or(0.0);
        m.set(key, n + 1.0);
    }
    m.set("placed", placed.len() as f64);
    Ok((placed, m))
}

/// The placed objects as scene objects from the asset library, ids `<class>-<n>` (and
/// `<class>-<n>-trunk` for a tree's trunk), sunk 0.1 m into the terrain so slopes leave no gap.
pub fn instantiate(placed: &[Placed]) -> Scene {
    let mut n: BTreeMap<&str, usize> = BTreeMap::new();
    let mut objects = Vec::new();
    for p in placed {
        let k = n.entry(p.class.as_str()).or_default();
        let id = format!("{}-{}", p.class, *k);
        *k += 1;
        for part in p
            .kind
            .build(p.xy, p.heading, p.ground_z - 0.1, p.height_scale)
        {
            objects.push(SceneObject {
                id: format!("{id}{}", part.suffix),
                class: part.class,
                mesh: part.mesh,
            });
        }
    }
    Scene { objects }
}
