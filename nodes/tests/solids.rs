//! The building chain of Sec. 4.1 on the synthetic site, scored against its ground truth: masks,
//! cleaned roofs and watertight solids, on the demo terrain and on a steeper one. Prints the
//! figures the issue asks for (footprint IoU, roof height RMSE, terrain RMSE).

mod common;
use common::*;

use std::sync::Arc;

use kodama_nodes::artifact::point_in_ring;
use kodama_nodes::artifact::{Metrics, ObjectClass, PointSet, Raster, Scene};
use kodama_nodes::geom::mesh_check::check_solid;
use kodama_nodes::geom::raycast::SceneRays;
use kodama_nodes::stage::Slot;
use kodama_nodes::stages::buildings::building_mask::{BuildingMask, BuildingMaskParams};
use kodama_nodes::stages::buildings::building_solids::{BuildingSolids, BuildingSolidsParams};
use kodama_nodes::stages::buildings::roof_clean::{RoofClean, RoofCleanParams};
use kodama_nodes::stages::buildings::split_buildings::{SplitBuildings, SplitBuildingsParams};
use kodama_nodes::stages::buildings::trace_footprints::{TraceFootprints, TraceFootprintsParams};
use kodama_nodes::stages::eval::footprint_score::FootprintScore;
use kodama_nodes::synth::city_footprints::CityFootprints;
use kodama_nodes::synth::synth_city::{SynthCityParams, generate};
use kodama_nodes::{Artifact, Ctx, Inputs, Stage};

/// What the chain made of one site, scored.
struct Score {
    iou: f64,
    /// Per building with one solid: its floor's corners less the true footprint's.
    corner_errors: Vec<i64>,
    /// Cells inside our solids only, and inside the true footprints only.
    extra: usize,
    missed: usize,
    roof_rmse: f64,
    terrain_rmse: f64,
    buildings: usize,
    solids: usize,
    triangles: usize,
    swallowed: usize,
    /// Mean IoU of each true footprint with the traced outline overlapping it most, before and
    /// after SplitBuildings.
    building_iou: [f64; 2],
}

fn optional(a: Artifact) -> Slot {
    Slot::Optional(Some(Arc::new(a)))
}

/// Mask, clean and mesh the buildings of `params`' city from its simulated survey.
fn run_chain(params: &SynthCityParams, use_classes: bool) -> Score {
    let s = site();
    let ctx = Ctx::new(&s, &[]);
    let city = generate(params);
    let truth = scene_of(&city);
    let Reconstruction {
        lidar,
        terrain,
        above,
        ..
    } = reconstruct(&truth);
    let labels = BuildingMask::run(
        &BuildingMaskParams {
            use_classes,
            ..Default::default()
        },
        &Inputs::new()
            .with("above", slot(Artifact::Raster(above.clone())))
            .with("points", optional(Artifact::Points(lidar.clone()))),
        &ctx,
    )
    .unwrap();
    let roofs = clean(&labels, &above, &lidar, &terrain, use_classes);
    let unsplit = labels.clone();
    let labels = SplitBuildings::run(
        &SplitBuildingsParams::default(),
        &Inputs::new()
            .with("labels", slot(Artifact::Raster(labels)))
            .with("roofs", slot(Artifact::Raster(roofs.clone()))),
        &ctx,
    )
    .unwrap();
    let solids = BuildingSolids::run(
        &BuildingSolidsParams::default(),
        &Inputs::new()
            .with("labels", slot(Artifact::Raster(labels.clone())))
            .with("roofs", slot(Artifact::Raster(roofs)))
            .with("terrain", slot(Artifact::Raster(terrain.clone())))
            .with("points", optional(Artifact::Points(lidar.clone()))),
        &ctx,
    )
    .unwrap();
    let mut triangles = 0;
    for o in &solids.objects {
        assert_eq!(o.class, ObjectClass::Building);
        assert!(o.id.starts_with("building-"));
        check_solid(&o.mesh).unwrap_or_else(|e| panic!("{}: {e}", o.id));
        triangles += o.mesh.len();
    }
    // Corners: a solid's floor vertices (its outline's, courtyards included) against the true
    // footprint's, for each true building that exactly one solid stands on.
    let mut on: Vec<Vec<usize>> = vec![Vec::new(); city.buildings.len()];
    let floors: Vec<Vec<[f64; 2]>> = solids
        .objects
        .iter()
        .map(|o| {
            let zmin = o
                .mesh
                .positions
                .iter()
                .map(|p| p[2])
                .fold(f32::INFINITY, f32::min);
            let mut v: Vec<[f64; 2]> = o
                .mesh
                .positions
                .iter()
                .filter(|p| p[2] == zmin)
                .map(|p| [p[0] as f64, p[1] as f64])
                .collect();
            v.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
            v.dedup();
            v
        })
        .collect();
    for (k, f) in floors.iter().enumerate() {
        let n = f.len() as f64;
        let c = [
            f.iter().map(|p| p[0]).sum::<f64>() / n,
            f.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        if let Some(b) = city
            .buildings
            .iter()
            .position(|b| point_in_ring(c, &b.footprint.exterior))
        {
            on[b].push(k);
        }
    }
    let corner_errors: Vec<i64> = on
        .iter()
        .enumerate()
        .filter(|(_, s)| s.len() == 1)
        .map(|(b, s)| {
            let fp = &city.buildings[b].footprint;
            let truth = fp.exterior.len() + fp.holes.iter().map(Vec::len).sum::<usize>();
            floors[s[0]].len() as i64 - truth as i64
        })
        .collect();
    let per_building = |labels: &Raster| {
        let outlines = TraceFootprints::run(
            &TraceFootprintsParams {
                simplify_m: 0.5,
                ..Default::default()
            },
            &Inputs::new()
                .with("labels", slot(Artifact::Raster(labels.clone())))
                .with("above", Slot::Optional(None)),
            &ctx,
        )
        .unwrap();
        let truth_fp = CityFootprints::run(
            &Default::default(),
            &Inputs::new().with("city", slot(Artifact::City(city.clone()))),
            &ctx,
        )
        .unwrap();
        FootprintScore::run(
            &Default::default(),
            &Inputs::new()
                .with("predicted", slot(Artifact::Footprints(outlines)))
                .with("reference", slot(Artifact::Footprints(truth_fp)))
                .with("region", optional(Artifact::Raster(terrain.clone()))),
            &ctx,
        )
        .unwrap()
    };
    let (whole, split) = (per_building(&unsplit), per_building(&labels));
    Score {
        corner_errors,
        ..score(
            &city,
            &truth,
            &solids,
            &terrain,
            triangles,
            [&whole, &split],
        )
    }
}

fn clean(
    labels: &Raster,
    above: &Raster,
    lidar: &PointSet,
    terrain: &Raster,
    use_classes: bool,
) -> Raster {
    RoofClean::run(
        &RoofCleanParams {
            use_classes,
            ..Default::default()
        },
        &Inputs::new()
            .with("labels", slot(Artifact::Raster(labels.clone())))
            .with("above", slot(Artifact::Raster(above.clone())))
            .with("points", optional(Artifact::Points(lidar.clone())))
            .with("terrain", optional(Artifact::Raster(terrain.clone()))),
        &Ctx::new(&site(), &[]),
    )
    .unwrap()
}

/// Casts down at every cell centre of the terrain grid (nudged off the centre, where roof
/// vertices sit): footprints are where the solids are hit, roof heights where they are hit.
fn score(
    city: &kodama_nodes::artifact::City,
    truth: &Scene,
    solids: &Scene,
    terrain: &Raster,
    triangles: usize,
    per_building: [&Metrics; 2],
) -> Score {
    let only = |class: ObjectClass| Scene {
        objects: truth
            .objects
            .iter()
            .filter(|o| o.class == class)
            .cloned()
            .collect(),
    };
    let (truth_buildings, truth_ground) = (
        SceneRays::new(&only(ObjectClass::Building)),
        SceneRays::new(&only(ObjectClass::Terrain)),
    );
    let ours = SceneRays::new(solids);
    let top = |rays: &SceneRays, x: f64, y: f64| {
        rays.cast([x as f32, y as f32, 2000.0], [0.0, 0.0, -1.0], 0.0, 4000.0)
            .map(|h| 2000.0 - h.t as f64)
    };
    let g = terrain.grid;
    let (mut inter, mut union, mut roof_se, mut roof_n, mut t_se, mut t_n) =
        (0usize, 0usize, 0.0, 0usize, 0.0, 0usize);
    let (mut extra, mut missed) = (0usize, 0usize);
    let mut covered = vec![(0usize, 0usize); city.buildings.len()];
    for i in 0..g.len() {
        let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
        let (x, y) = (x + 0.011, y + 0.007);
        let inside = city.buildings.iter().position(|b| {
            point_in_ring([x, y], &b.footprint.exterior)
                && !b.footprint.holes.iter().any(|h| point_in_ring([x, y], h))
        });
        let found = top(&ours, x, y);
        if let Some(k) = inside {
            covered[k].1 += 1;
            if found.is_some() {
                covered[k].0 += 1;
            }
        }
        match (inside.is_some(), found) {
            (true, Some(z)) => {
                inter += 1;
                union += 1;
                if let Some(t) = top(&truth_buildings, x, y) {
                    roof_se += (z - t).powi(2);
                    roof_n += 1;
                }
            }
            (true, None) => {
                union += 1;
                missed += 1;
            }
            (false, Some(_)) => {
                union += 1;
                extra += 1;
            }
            (false, None) => {}
        }
        if let Some(t) = top(&truth_ground, x, y) {
            t_se += (terrain.data[i] as f64 - t).powi(2);
            t_n += 1;
        }
    }
    Score {
        iou: inter as f64 / union as f64,
        corner_errors: Vec::new(),
        extra,
        missed,
        roof_rmse: (roof_se / roof_n as f64).sqrt(),
        terrain_rmse: (t_se / t_n as f64).sqrt(),
        buildings: city.buildings.len(),
        solids: solids.objects.len(),
        triangles,
        swallowed: covered.iter().filter(|(hit, n)| *hit * 2 < *n).count(),
        building_iou: per_building.map(|m| m.get("building_iou_mean").unwrap_or(0.0)),
    }
}

fn report(name: &str, s: &Score) {
    println!(
        "{name}: footprint IoU {:.3} ({} cells ours only, {} truth only), per-building IoU {:.3} ({:.3} unsplit), roof height RMSE \
         {:.3} m, terrain RMSE {:.3} m; {} solids for {} buildings, {} triangles ({:.0} per \
         solid), {} buildings swallowed",
        s.iou,
        s.extra,
        s.missed,
        s.building_iou[1],
        s.building_iou[0],
        s.roof_rmse,
        s.terrain_rmse,
        s.solids,
        s.buildings,
        s.triangles,
        s.triangles as f64 / s.solids as f64,
        s.swallowed
    );
    let e = &s.corner_errors;
    let mut abs: Vec<i64> = e.iter().map(|v| v.abs()).collect();
    abs.sort();
    println!(
        "{name}: corners per building against the truth ({} buildings with one solid): exact {}, \
         mean |error| {:.2}, median {}, max {}, mean signed {:+.2}",
        e.len(),
        e.iter().filter(|&&v| v == 0).count(),
        abs.iter().sum::<i64>() as f64 / e.len().max(1) as f64,
        abs.get(abs.len() / 2).copied().unwrap_or(0),
        abs.last().copied().unwrap_or(0),
        e.iter().sum::<i64>() as f64 / e.len().max(1) as f64
    );
    assert!(s.iou >= 0.9, "{name}: IoU {}", s.iou);
    assert!(
        s.building_iou[1] >= 0.87,
        "{name}: per-building IoU {}",
        s.building_iou[1]
    );
    // SplitBuildings must earn its place: measured 0.890 against 0.858 unsplit (demo), 0.893
    // against 0.768 (geometric cues), 0.902 against 0.858 (steep).
    assert!(
        s.building_iou[1] >= s.building_iou[0] + 0.02,
        "{name}: per-building IoU {} split, {} unsplit",
        s.building_iou[1],
        s.building_iou[0]
    );
    // Measured 0.169-0.182 m with regularized outlines (0.28-0.35 m before).
    assert!(s.roof_rmse <= 0.25, "{name}: roof RMSE {}", s.roof_rmse);
    assert!(
        s.terrain_rmse <= 0.25,
        "{name}: terrain RMSE {}",
        s.terrain_rmse
    );
    assert_eq!(s.swallowed, 0, "{name}");
}

#[test]
fn demo_site_solids_match_the_truth() {
    let s = run_chain(&SynthCityParams::default(), true);
    report("demo site, LiDAR classes", &s);
    // Regularized outlines snapped to the roof returns: 0.977 (0.951 with outlines simplified
    // from the cells, which bulge beyond the walls); the target is 0.97.
    assert!(s.iou >= 0.97, "footprint IoU {:.3}", s.iou);
    let exact = s.corner_errors.iter().filter(|&&e| e == 0).count();
    assert!(
        exact * 4 >= s.corner_errors.len(),
        "only {exact} of {} buildings with their true corner count",
        s.corner_errors.len()
    );
}

#[test]
fn demo_site_solids_from_geometric_cues_match_the_truth() {
    let s = run_chain(&SynthCityParams::default(), false);
    report("demo site, geometric cues", &s);
}

#[test]
fn steep_site_solids_match_the_truth() {
    let params = SynthCityParams {
        terrain: steep_terrain(),
        ..Default::default()
    };
    let s = run_chain(&params, true);
    report("steep site, LiDAR classes", &s);
    assert!(s.iou >= 0.97, "footprint IoU {:.3}", s.iou);
}
