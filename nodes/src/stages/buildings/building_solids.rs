//! Building solids (paper Sec. 4.1): each cleaned roof extruded down to the terrain,
//! B_b = {(x, z) : x in F_b, 0 <= z - T(x) <= Z̃_b(x)}, and its boundary remeshed into one closed,
//! 2-manifold, outward-oriented triangle mesh per building.
//!
//! The roof is an adaptive triangulation of the roof heights (greedy insertion, Garland and
//! Heckbert 1995): starting from the footprint outline, the cell whose height is furthest from the
//! current surface is inserted into every triangle until no cell is further than the tolerance,
//! so flat roofs take a handful of triangles while ridges, steps, domes, chimneys and HVAC units
//! keep theirs. Walls drop from the outline to a flat floor below the lowest terrain under the
//! building. Every mesh passes [`check_solid`] or the stage fails.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use spade::{
    ConstrainedDelaunayTriangulation, HasPosition, Point2, PositionInTriangulation, Triangulation,
};

use crate::artifact::{
    ArtifactType, Grid, ObjectClass, PodVec, PointSet, Polygon, Raster, Scene, SceneObject,
};
use crate::geom::mesh_build::{Builder, insert_rings, triangulate};
use crate::geom::mesh_check::check_solid;
use crate::geom::polygon::{point_in_ring, segment_distance, simplify_polygon, trace};
use crate::geom::regularize::{RegularizeConfig, regularize_polygon};
use crate::raster::label::label_ids;
use crate::rf::materials::{Material, default_material};
use crate::stage::{Ctx, InputSpec, Inputs, ParamError, Stage, StageError};

/// Params of [`BuildingSolids`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuildingSolidsParams {
    /// The largest vertical distance between a roof cell and the roof mesh, metres. Default 0.1.
    pub tolerance_m: f64,
    /// Douglas-Peucker tolerance for the outlines, metres: one cell straightens the stair steps of
    /// walls that run diagonally to the grid. Default 0.5. Where simplifying would make the solid
    /// invalid, the exact cell outline is used.
    pub outline_tolerance_m: f64,
    /// Outline regularization (`geom::regularize`): walls within this angle of the building's
    /// dominant orientation or its right angle are turned to it, straight runs become one wall,
    /// corners meet square, degrees; 0 turns it off. Default 12. Where the regularized outline
    /// fails its checks or makes an invalid solid, the simplified one is used.
    pub regularize_angle_deg: f64,
    /// How far the floor goes below the lowest terrain under the building, metres: walls then
    /// meet the terrain mesh everywhere. Default 0.5.
    pub embed_m: f64,
    /// Material of walls and roofs until the material stages assign per-surface ones. Default the
    /// building class's ([`default_material`]): concrete.
    pub material: Material,
}

impl Default for BuildingSolidsParams {
    fn default() -> Self {
        BuildingSolidsParams {
            tolerance_m: 0.1,
            outline_tolerance_m: 0.5,
            regularize_angle_deg: 12.0,
            embed_m: 0.5,
            material: default_material(ObjectClass::Building),
        }
    }
}

/// One closed solid per building label, `building-<label>`, in label order.
pub struct BuildingSolids;

impl Stage for BuildingSolids {
    const KIND: &'static str = "BuildingSolids";
    // 3: a cut corner beside a spike, or a spike of several edges, is squared (geom::regularize).
    const VERSION: u32 = 3;
    const DOC: &'static str = "watertight building solids: cleaned roofs extruded to the terrain, remeshed to a tolerance and checked, Sec. 4.1";
    const INPUTS: &'static [InputSpec] = &[
        InputSpec::one(
            "labels",
            ArtifactType::Raster,
            "building labels F_b (1, 2, ...; 0 = none)",
        ),
        InputSpec::one(
            "roofs",
            ArtifactType::Raster,
            "cleaned roof heights Z̃_b above the terrain, on the labels' grid",
        ),
        InputSpec::one("terrain", ArtifactType::Raster, "the terrain T"),
        InputSpec::optional(
            "points",
            ArtifactType::Points,
            "the LiDAR returns: regularized walls move to the edge of the roof returns",
        ),
    ];
    type Params = BuildingSolidsParams;
    type Output = Scene;

    fn validate(p: &Self::Params) -> Result<(), ParamError> {
        if !(p.tolerance_m > 0.0 && p.tolerance_m.is_finite()) {
            return Err(ParamError::new(
                "tolerance_m",
                "expected a positive tolerance in metres",
            ));
        }
        for (name, v) in [
            ("outline_tolerance_m", p.outline_tolerance_m),
            ("embed_m", p.embed_m),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(ParamError::new(
                    name,
                    "expected a non-negative length in metres",
                ));
            }
        }
        if !(0.0..=30.0).contains(&p.regularize_angle_deg) {
            return Err(ParamError::new(
                "regularize_angle_deg",
                "expected an angle from 0 (off) to 30 degrees",
            ));
        }
        if p.embed_m < 0.01 {
            return Err(ParamError::new(
                "embed_m",
                "expected at least 0.01 m, so walls never have zero height",
            ));
        }
        Ok(())
    }

    fn run(p: &Self::Params, inputs: &Inputs, ctx: &Ctx) -> Result<Scene, StageError> {
        let labels: &Raster = inputs.one("labels")?;
        let roofs: &Raster = inputs.one("roofs")?;
        let terrain: &Raster = inputs.one("terrain")?;
        if labels.grid != roofs.grid {
            return Err(StageError::Failed(
                "labels and roofs must share one grid (RoofClean keeps the labels' grid)".into(),
            ));
        }
        let g = labels.grid;
        let mut cells = CellHeights::new(labels, roofs, terrain)?;
        if let Some(points) = inputs.optional::<PointSet>("points")? {
            cells.collect_roof_returns(points);
        }
        let outlines = trace(&Raster {
            grid: g,
            data: PodVec(cells.label.iter().map(|&l| l as f32).collect()),
        });
        ctx.progress.set_total(outlines.len() as u64);
        let objects: Vec<Result<SceneObject, String>> = outlines
            .into_par_iter()
            .map(|(label, polygons)| {
                let solid = solid(&cells, label, &polygons, p).map(|mesh| SceneObject {
                    id: format!("building-{label}"),
                    class: ObjectClass::Building,
                    mesh,
                });
                ctx.progress.advance(1);
                solid
            })
            .collect();
        let objects = objects
            .into_iter()
            .collect::<Result<Vec<_>, _>>()
            .map_err(StageError::Failed)?;
        Ok(Scene { objects })
    }
}

/// Per cell: the building label (after corner touches are resolved) and the absolute roof and
/// terrain heights.
struct CellHeights {
    grid: Grid,
    label: Vec<u32>,
    roof: Vec<f64>,
    ground: Vec<f64>,
    /// The cells of each label.
    members: BTreeMap<u32, Vec<u32>>,
    /// Plan positions of each label's roof returns (within [`ROOF_BAND_M`] of its roof).
    roof_returns: BTreeMap<u32, Vec<[f64; 2]>>,
}

/// A return this close below a cell's roof height, or above it, is a roof return, metres: wall
/// and balcony returns lie further down.
const ROOF_BAND_M: f64 = 1.0;
/// The fewest roof returns along a wall that place it.
const MIN_WALL_RETURNS: usize = 8;

impl CellHeights {
    fn new(labels: &Raster, roofs: &Raster, terrain: &Raster) -> Result<CellHeights, StageError> {
        let g = labels.grid;
        let mut label = label_ids(labels);
        let ground: Vec<f64> = (0..g.len())
            .map(|i| {
                let (x, y) = g.center(i as u32 % g.width, i as u32 / g.width);
                terrain.bilinear(x, y).unwrap_or(f64::NAN)
            })
            .collect();
        let mut roof: Vec<f64> = (0..g.len())
            .map(|i| ground[i] + roofs.data[i] as f64)
            .collect();
        // A cell without a roof height or terrain under it is not part of a building.
        for i in 0..g.len() {
            if !roof[i].is_finite() {
                label[i] = 0;
            }
        }
        separate_corner_touches(&mut label, &mut roof, g.width, g.height)
            .map_err(|e| StageError::Failed(format!("building labels: {e}")))?;
        let mut members: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for (i, &l) in label.iter().enumerate() {
            if l > 0 {
                members.entry(l).or_default().push(i as u32);
            }
        }
        Ok(CellHeights {
            grid: g,
            label,
            roof,
            ground,
            members,
            roof_returns: BTreeMap::new(),
        })
    }

    /// Sorts the returns that fall in a building's cells near its roof height by building.
    fn collect_roof_returns(&mut self, points: &PointSet) {
        let g = self.grid;
        for p in points.xyz.iter() {
            let (x, y) = (p[0] as f64, p[1] as f64);
            let Some((c, r)) = g.cell_of(x, y) else {
                continue;
            };
            let i = (r * g.width + c) as usize;
            let l = self.label[i];
            if l > 0 && p[2] as f64 >= self.roof[i] - ROOF_BAND_M {
                self.roof_returns.entry(l).or_default().push([x, y]);
            }
        }
    }

    /// Where the wall along a regularized line is: the outermost roof returns of `label` within
    /// the line's extent (less half a metre at each end, where the other wall's returns are)
    /// and 2 m of it, at their 2nd percentile of distance out (a few noisy returns beyond the
    /// roof's edge do not move it).
    fn wall_offset(&self, label: u32, d: [f64; 2], o: f64, extent: [f64; 2]) -> Option<f64> {
        let pts = self.roof_returns.get(&label)?;
        let n = [-d[1], d[0]];
        let mut v: Vec<f64> = pts
            .iter()
            .filter(|p| {
                let s = d[0] * p[0] + d[1] * p[1];
                s >= extent[0] + 0.5 && s <= extent[1] - 0.5
            })
            .map(|p| n[0] * p[0] + n[1] * p[1] - o)
            .filter(|v| v.abs() <= 2.0)
            .collect();
        if v.len() < MIN_WALL_RETURNS {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(o + v[(v.len() - 1) * 2 / 100])
    }

    /// The roof height at an outline vertex: the mean over the cells of `label` that touch the
    /// nearest cell corner; a regularized vertex off the cell boundary (a squared corner) takes
    /// the nearest cells of `label` within two cells.
    fn corner_height(&self, label: u32, p: [f64; 2]) -> Option<f64> {
        let g = self.grid;
        let c = ((p[0] - g.x0) / g.cell_m).round() as i64;
        let r = ((g.y0 - p[1]) / g.cell_m).round() as i64;
        let at = |cc: i64, rr: i64| {
            (cc >= 0 && rr >= 0 && cc < g.width as i64 && rr < g.height as i64)
                .then(|| (rr * g.width as i64 + cc) as usize)
                .filter(|&i| self.label[i] == label)
        };
        let mean = |cells: &mut dyn Iterator<Item = usize>| {
            let (mut sum, mut n) = (0.0, 0);
            for i in cells {
                sum += self.roof[i];
                n += 1;
            }
            (n > 0).then(|| sum / n as f64)
        };
        let touching = [(c - 1, r - 1), (c, r - 1), (c - 1, r), (c, r)];
        if let Some(z) = mean(&mut touching.iter().filter_map(|&(cc, rr)| at(cc, rr))) {
            return Some(z);
        }
        for ring in 1..=2i64 {
            let near = (-ring - 1..=ring).flat_map(|dr| (-ring - 1..=ring).map(move |dc| (dc, dr)));
            if let Some(z) = mean(&mut near.filter_map(|(dc, dr)| at(c + dc, r + dr))) {
                return Some(z);
            }
        }
        None
    }
}

/// Two cells of one building that touch only at a corner (with the other two cells not of that
/// building) would make a vertex shared by two walls: not a manifold. Each such corner is joined
/// through an empty neighbour cell when there is one (taking the mean roof of the pair), else
/// the second cell leaves the building. Repeats until no such corner is left.
fn separate_corner_touches(
    label: &mut [u32],
    roof: &mut [f64],
    w: u32,
    h: u32,
) -> Result<(), String> {
    let (w, h) = (w as usize, h as usize);
    for _ in 0..64 {
        let mut changed = false;
        for r in 0..h.saturating_sub(1) {
            for c in 0..w.saturating_sub(1) {
                let (a, b, cc, d) = (
                    r * w + c,
                    r * w + c + 1,
                    (r + 1) * w + c,
                    (r + 1) * w + c + 1,
                );
                for (p, q, x, y) in [(a, d, b, cc), (b, cc, a, d)] {
                    let l = label[p];
                    if l == 0 || label[q] != l || label[x] == l || label[y] == l {
                        continue;
                    }
                    if let Some(e) = [x, y].into_iter().find(|&e| label[e] == 0) {
                        label[e] = l;
                        roof[e] = (roof[p] + roof[q]) / 2.0;
                    } else {
                        label[q] = 0;
                        roof[q] = f64::NAN;
                    }
                    changed = true;
                }
            }
        }
        if !changed {
            return Ok(());
        }
    }
    Err("buildings keep touching at cell corners after 64 passes".into())
}

/// The solid of one building: one closed shell per polygon of its outline. Tries the simplified
/// outline first and the exact cell outline if that fails the checks.
fn solid(
    cells: &CellHeights,
    label: u32,
    polygons: &[Polygon],
    p: &BuildingSolidsParams,
) -> Result<crate::artifact::Mesh, String> {
    let members = cells
        .members
        .get(&label)
        .ok_or_else(|| format!("building-{label} has no cells"))?;
    let floor = members
        .iter()
        .map(|&i| cells.ground[i as usize])
        .fold(f64::INFINITY, f64::min)
        - p.embed_m;
    let mut last_error = String::new();
    // Outlines to try, best first: regularized, simplified, the exact cell boundary.
    let mut candidates: Vec<Vec<Polygon>> = Vec::new();
    if p.regularize_angle_deg > 0.0 {
        let cfg = RegularizeConfig {
            simplify_m: p.outline_tolerance_m.max(1.5 * cells.grid.cell_m),
            angle_tol_deg: p.regularize_angle_deg,
            ..RegularizeConfig::default()
        };
        let regular = polygons
            .iter()
            .map(|poly| {
                let snap =
                    |d: [f64; 2], o: f64, extent: [f64; 2]| cells.wall_offset(label, d, o, extent);
                regularize_polygon(poly, &cfg, Some(&snap))
            })
            .collect::<Option<Vec<_>>>();
        if let Some(r) = regular {
            candidates.push(r);
        }
    }
    if p.outline_tolerance_m > 0.0 {
        candidates.push(
            polygons
                .iter()
                .map(|poly| simplify_polygon(poly.clone(), p.outline_tolerance_m))
                .collect(),
        );
    }
    candidates.push(polygons.to_vec());
    for outline in candidates {
        let mut mesh = crate::artifact::Mesh::default();
        let built: Result<(), String> = outline.iter().try_for_each(|poly| {
            mesh.append(&shell(cells, label, members, poly, floor, p)?);
            Ok(())
        });
        match built.and_then(|()| check_solid(&mesh).map(|_| ())) {
            Ok(()) => return Ok(mesh),
            Err(e) => last_error = e,
        }
    }
    Err(format!("building-{label}: {last_error}"))
}

/// A roof vertex: its plan position and height.
#[derive(Clone, Copy)]
struct RoofVertex {
    p: Point2<f64>,
    z: f64,
}

impl HasPosition for RoofVertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

/// One closed shell: the adaptive roof over `poly`, walls along its rings, a flat floor.
fn shell(
    cells: &CellHeights,
    label: u32,
    members: &[u32],
    poly: &Polygon,
    floor: f64,
    p: &BuildingSolidsParams,
) -> Result<crate::artifact::Mesh, String> {
    let g = cells.grid;
    let mut cdt = ConstrainedDelaunayTriangulation::<RoofVertex>::new();
    let mut missing = None;
    let ring = insert_rings(&mut cdt, poly, |q, _| {
        let z = cells.corner_height(label, q).unwrap_or_else(|| {
            missing = Some(q);
            f64::NAN
        });
        RoofVertex {
            p: Point2::new(q[0], q[1]),
            z,
        }
    })?;
    if let Some(q) = missing {
        return Err(format!(
            "outline vertex {q:?} touches no cell of the building"
        ));
    }
    let inside = |x: f64, y: f64| {
        point_in_ring([x, y], &poly.exterior)
            && !poly.holes.iter().any(|h| point_in_ring([x, y], h))
    };
    // Cell centres well inside the outline: never on a wall, so the roof's rim stays the ring.
    let margin = 0.25 * g.cell_m;
    let segments: Vec<([f64; 2], [f64; 2])> = std::iter::once(&poly.exterior)
        .chain(&poly.holes)
        .flat_map(|r| (0..r.len()).map(move |k| (r[k], r[(k + 1) % r.len()])))
        .collect();
    let candidates: Vec<RoofVertex> = members
        .iter()
        .filter_map(|&i| {
            let (x, y) = g.center(i % g.width, i / g.width);
            (inside(x, y)
                && segments
                    .iter()
                    .all(|&(a, b)| segment_distance([x, y], a, b) > margin))
            .then(|| RoofVertex {
                p: Point2::new(x, y),
                z: cells.roof[i as usize],
            })
        })
        .collect();
    refine(&mut cdt, &candidates, p.tolerance_m)?;

    let mut b = Builder::default();
    let top: Vec<u32> = cdt
        .vertices()
        .map(|v| {
            let d = *v.data();
            b.v([d.p.x, d.p.y, d.z])
        })
        .collect();
    let bottom: Vec<u32> = ring
        .iter()
        .map(|h| {
            let d = *cdt.vertex(*h).data();
            b.v([d.p.x, d.p.y, floor])
        })
        .collect();
    for f in cdt.inner_faces() {
        let vs = f.vertices();
        let c = vs.iter().fold([0.0, 0.0], |acc, v| {
            [acc[0] + v.position().x / 3.0, acc[1] + v.position().y / 3.0]
        });
        if inside(c[0], c[1]) {
            let [a, bb, cc] = vs.map(|v| top[v.fix().index()]);
            b.tri(a, bb, cc, p.material);
        }
    }
    for t in triangulate(poly)? {
        b.tri(
            bottom[t[0] as usize],
            bottom[t[2] as usize],
            bottom[t[1] as usize],
            p.material,
        );
    }
    let mut start = 0;
    for r in std::iter::once(&poly.exterior).chain(&poly.holes) {
        let n = r.len();
        for k in 0..n {
            let (i, j) = (start + k, start + (k + 1) % n);
            let (ti, tj) = (top[ring[i].index()], top[ring[j].index()]);
            b.quad(bottom[i], bottom[j], tj, ti, p.material);
        }
        start += n;
    }
    Ok(b.finish())
}

/// Greedy insertion: each round, the candidate furthest above or below the surface in each
/// triangle goes in, until none is further than `tolerance`. Ties go to the earlier candidate, and
/// a round's insertions are made in candidate order, so the result is deterministic.
fn refine(
    cdt: &mut ConstrainedDelaunayTriangulation<RoofVertex>,
    candidates: &[RoofVertex],
    tolerance: f64,
) -> Result<(), String> {
    let mut inserted = vec![false; candidates.len()];
    loop {
        let mut worst: BTreeMap<usize, (f64, usize)> = BTreeMap::new();
        for (k, c) in candidates.iter().enumerate() {
            if inserted[k] {
                continue;
            }
            let (face, z) = match cdt.locate(c.p) {
                PositionInTriangulation::OnFace(f) => {
                    let f = cdt.face(f);
                    (
                        f.fix().index(),
                        interpolate(f.vertices().map(|v| *v.data()), c.p),
                    )
                }
                PositionInTriangulation::OnEdge(e) => {
                    let e = cdt.directed_edge(e);
                    let (a, b) = (*e.from().data(), *e.to().data());
                    let t = distance(a.p, c.p) / distance(a.p, b.p).max(1e-12);
                    (e.face().fix().index(), a.z + t * (b.z - a.z))
                }
                _ => {
                    inserted[k] = true;
                    continue;
                }
            };
            let err = (c.z - z).abs();
            if err > tolerance {
                let e = worst.entry(face).or_insert((err, k));
                if err > e.0 {
                    *e = (err, k);
                }
            }
        }
        if worst.is_empty() {
            return Ok(());
        }
        let mut picks: Vec<usize> = worst.values().map(|&(_, k)| k).collect();
        picks.sort_unstable();
        for k in picks {
            cdt.insert(candidates[k])
                .map_err(|e| format!("cannot insert roof point: {e:?}"))?;
            inserted[k] = true;
        }
    }
}

fn distance(a: Point2<f64>, b: Point2<f64>) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// The height at `q` of the plane through three roof vertices.
fn interpolate(v: [RoofVertex; 3], q: Point2<f64>) -> f64 {
    let (a, b, c) = (v[0], v[1], v[2]);
    let det = (b.p.x - a.p.x) * (c.p.y - a.p.y) - (c.p.x - a.p.x) * (b.p.y - a.p.y);
    let l1 = ((q.x - a.p.x) * (c.p.y - a.p.y) - (c.p.x - a.p.x) * (q.y - a.p.y)) / det;
    let l2 = ((b.p.x - a.p.x) * (q.y - a.p.y) - (q.x - a.p.x) * (b.p.y - a.p.y)) / det;
    a.z + l1 * (b.z - a.z) + l2 * (c.z - a.z)
}

/// Distance from `q` to the segment `a b`.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Grid;

    fn raster(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> Raster {
        Raster {
            grid: Grid {
                x0: 0.0,
                y0: h as f64 * 0.5,
                cell_m: 0.5,
                width: w,
                height: h,
            },
            data: PodVec((0..w * h).map(|i| f(i % w, i / w)).collect()),
        }
    }

    fn solids(
        labels: &Raster,
        roofs: &Raster,
        terrain: &Raster,
        p: &BuildingSolidsParams,
    ) -> Scene {
        let inputs = Inputs::new()
            .with(
                "labels",
                Slot::One(Arc::new(Artifact::Raster(labels.clone()))),
            )
            .with(
                "roofs",
                Slot::One(Arc::new(Artifact::Raster(roofs.clone()))),
            )
            .with(
                "terrain",
                Slot::One(Arc::new(Artifact::Raster(terrain.clone()))),
            );
        let site = crate::Site {
            crs: "EPSG:32618".into(),
            origin: (0.0, 0.0),
            cell_m: 0.5,
        };
        BuildingSolids::run(p, &inputs, &Ctx::new(&site, &[])).unwrap()
    }
    use crate::Artifact;
    use crate::stage::Slot;
    use std::sync::Arc;

    #[test]
    fn a_gabled_roof_with_a_chimney_keeps_its_shape_in_few_triangles() {
        // 20 x 12 m building on a slope: ridge along x at 9 m, eaves at 6 m, a 1 x 1 m chimney
        // 1.5 m above the roof.
        let (w, h) = (60, 40);
        let inside = |c: u32, r: u32| (10..50).contains(&c) && (8..32).contains(&r);
        let labels = raster(w, h, |c, r| if inside(c, r) { 1.0 } else { 0.0 });
        let roof_at = |c: u32, r: u32| {
            let y = (r as f64 + 0.5) * 0.5;
            let mut z = 9.0 - (y - 10.0).abs() * 0.5;
            if (30..32).contains(&c) && (12..14).contains(&r) {
                z += 1.5;
            }
            z
        };
        let roofs = raster(w, h, |c, r| {
            if inside(c, r) {
                roof_at(c, r) as f32
            } else {
                f32::NAN
            }
        });
        let terrain = raster(w, h, |c, _| 100.0 + c as f32 * 0.05);
        let scene = solids(&labels, &roofs, &terrain, &Default::default());
        assert_eq!(scene.objects.len(), 1);
        let mesh = &scene.objects[0].mesh;
        check_solid(mesh).unwrap();
        assert!(mesh.len() < 120, "{} triangles", mesh.len());
        // Every roof cell within the tolerance of the mesh's top surface.
        let top = crate::geom::raycast::SceneRays::new(&scene);
        let mut worst: f64 = 0.0;
        for r in 8..32 {
            for c in 10..50 {
                // Just off the cell centre: rays exactly through a vertex can slip between faces.
                let (x, y) = (
                    (c as f64 + 0.5) * 0.5 + 0.011,
                    (h - r) as f64 * 0.5 - 0.25 + 0.007,
                );
                let hit = top.cast([x as f32, y as f32, 500.0], [0.0, 0.0, -1.0], 0.0, 1e3);
                let z = 500.0 - hit.unwrap().t as f64;
                let truth = 100.0 + (c as f64) * 0.05 + roof_at(c, r);
                worst = worst.max((z - truth).abs());
            }
        }
        assert!(worst <= 0.1 + 0.05 * 0.5 + 1e-3, "worst roof error {worst}");
    }

    #[test]
    fn corner_touches_are_joined_and_courtyards_stay_open() {
        // A ring of cells with a courtyard, plus a cell touching it only at a corner.
        let rows = ["000000", "011110", "010010", "011110", "000001"];
        let labels = raster(6, 5, |c, r| {
            (rows[r as usize].as_bytes()[c as usize] - b'0') as f32
        });
        let roofs = raster(6, 5, |_, _| 6.0);
        let terrain = raster(6, 5, |_, _| 0.0);
        // The exact cell outline: neither simplified nor regularized.
        let exact = BuildingSolidsParams {
            outline_tolerance_m: 0.0,
            regularize_angle_deg: 0.0,
            ..Default::default()
        };
        let scene = solids(&labels, &roofs, &terrain, &exact);
        let mesh = &scene.objects[0].mesh;
        let report = check_solid(mesh).unwrap();
        // 10 ring cells + the corner cell + the joining cell, 6.5 m tall from the floor.
        assert!(
            (report.volume_m3 - 12.0 * 0.25 * 6.5).abs() < 1e-3,
            "{}",
            report.volume_m3
        );
    }

    #[test]
    fn a_regularize_angle_outside_0_to_30_degrees_is_refused() {
        for bad in [f64::NAN, f64::INFINITY, -1.0, 45.0] {
            let p = BuildingSolidsParams {
                regularize_angle_deg: bad,
                ..Default::default()
            };
            let e = BuildingSolids::validate(&p).unwrap_err();
            assert!(
                format!("{e:?}").contains("regularize_angle_deg"),
                "{bad}: {e:?}"
            );
        }
        for ok in [0.0, 12.0, 30.0] {
            let p = BuildingSolidsParams {
                regularize_angle_deg: ok,
                ..Default::default()
            };
            assert!(BuildingSolids::validate(&p).is_ok(), "{ok}");
        }
    }
}
