//! Building masks on the synthetic site against its true outlines, with the LiDAR's building
//! class and from geometric cues alone.

mod common;
use common::*;

use std::sync::Arc;

use kodama_nodes::artifact::Raster;
use kodama_nodes::artifact::point_in_ring;
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::buildings::building_mask::{BuildingMask, BuildingMaskParams};
use kodama_nodes::synth::synth_city::{SynthCityParams, generate};
use kodama_nodes::{Artifact, Ctx, Inputs, Site, Stage};

#[test]
fn masks_match_the_true_outlines() {
    let site = site();
    let ctx = Ctx::new(&site, &[]);
    let city = generate(&SynthCityParams::default());
    let Reconstruction {
        lidar, above: a, ..
    } = reconstruct(&scene_of(&city));
    let truth: Vec<bool> = (0..a.grid.len())
        .map(|i| {
            let (x, y) = a
                .grid
                .center(i as u32 % a.grid.width, i as u32 / a.grid.width);
            city.buildings.iter().any(|b| {
                point_in_ring([x, y], &b.footprint.exterior)
                    && !b.footprint.holes.iter().any(|hl| point_in_ring([x, y], hl))
            })
        })
        .collect();
    {
        let rough = kodama_nodes::stages::buildings::building_mask::roughness(&a);
        let pct = |mut v: Vec<f32>| {
            v.sort_by(f32::total_cmp);
            [0.5, 0.9, 0.98].map(|q| v[((v.len() - 1) as f64 * q) as usize])
        };
        let roof: Vec<f32> = (0..a.grid.len())
            .filter(|&i| truth[i])
            .map(|i| rough[i])
            .collect();
        let tree: Vec<f32> = (0..a.grid.len())
            .filter(|&i| {
                let (x, y) = a
                    .grid
                    .center(i as u32 % a.grid.width, i as u32 / a.grid.width);
                !truth[i]
                    && a.data[i] > 2.5
                    && city
                        .trees
                        .iter()
                        .any(|t| (t.pos[0] - x).hypot(t.pos[1] - y) < t.crown_radius_m)
            })
            .map(|i| rough[i])
            .collect();
        println!(
            "roughness roof p50/p90/p98 {:?}; tree {:?}",
            pct(roof),
            pct(tree)
        );
    }
    for use_classes in [true, false] {
        let params = BuildingMaskParams {
            use_classes,
            ..Default::default()
        };
        let inputs = Inputs::new()
            .with("above", slot(Artifact::Raster(a.clone())))
            .with(
                "points",
                Slot::Optional(Some(Arc::new(Artifact::Points(lidar.clone())))),
            );
        let labels = BuildingMask::run(&params, &inputs, &ctx).unwrap();
        let found: Vec<bool> = labels
            .data
            .iter()
            .map(|&l| l.is_finite() && l > 0.0)
            .collect();
        let inter = found.iter().zip(&truth).filter(|(f, t)| **f && **t).count();
        let union = found.iter().zip(&truth).filter(|(f, t)| **f || **t).count();
        let iou = inter as f64 / union as f64;
        let components = labels
            .data
            .iter()
            .filter(|l| l.is_finite())
            .fold(0.0f32, |m, &l| m.max(l));
        println!(
            "{}: footprint IoU {iou:.3}, {components} components for {} buildings",
            if use_classes {
                "LiDAR classes"
            } else {
                "geometric cues"
            },
            city.buildings.len()
        );
        assert!(iou >= 0.9, "{iou}");
        if use_classes {
            check_traced_polygons(&labels, &a, &site);
        }
    }
}

/// The traced polygons, rasterized back at cell centres, are exactly the mask (outlines and
/// courtyards), carry heights, and export as GeoJSON.
fn check_traced_polygons(labels: &Raster, a: &Raster, site: &Site) {
    use kodama_nodes::stages::buildings::trace_footprints::{
        TraceFootprints, TraceFootprintsParams,
    };
    let inputs = Inputs::new()
        .with("labels", slot(Artifact::Raster(labels.clone())))
        .with(
            "above",
            Slot::Optional(Some(Arc::new(Artifact::Raster(a.clone())))),
        );
    let fp = TraceFootprints::run(
        &TraceFootprintsParams::default(),
        &inputs,
        &Ctx::new(site, &[]),
    )
    .unwrap();
    let g = labels.grid;
    let mut mismatches = 0;
    for i in 0..g.len() {
        let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
        let inside = fp.items.iter().flat_map(|b| &b.polygons).any(|p| {
            point_in_ring([x, y], &p.exterior)
                && !p.holes.iter().any(|hl| point_in_ring([x, y], hl))
        });
        let labelled = labels.data[i].is_finite() && labels.data[i] > 0.0;
        mismatches += (inside != labelled) as usize;
    }
    let holes: usize = fp
        .items
        .iter()
        .flat_map(|b| &b.polygons)
        .map(|p| p.holes.len())
        .sum();
    println!(
        "{} footprints traced, {holes} courtyards, {mismatches} cells differ from the mask",
        fp.items.len()
    );
    assert_eq!(mismatches, 0);
    assert!(holes >= 3, "the courtyards are holes");
    assert!(fp.items.iter().all(|b| b.height_m.is_some_and(|h| h > 3.0)));
    let kodama_nodes::io::export::Encoded::File(json) =
        kodama_nodes::io::export::encode(&Artifact::Footprints(fp), site, "geojson").unwrap()
    else {
        panic!()
    };
    assert!(
        String::from_utf8(json)
            .unwrap()
            .contains("urn:ogc:def:crs:EPSG::32618")
    );
}
