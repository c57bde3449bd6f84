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
use crate::artifact::{Material, default_material};
use crate::buildings::regularize::{RegularizeConfig, regularize_polygon};
use crate::buildings::roof_planes::{PlaneConfig, PlaneFit, fit_planes, meeting_lines};
use crate::geom::mesh_build::{Builder, insert_rings, triangulate};
use crate::geom::mesh_check::check_solid;
use crate::geom::polygon::{segment_distance, simplify_polygon, trace};
use crate::raster::label::label_ids;
use crate::rng::mix;
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
    /// Outline regularization (`buildings::regularize`): walls within this angle of the building's
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
    /// Roof planes (`buildings::roof_planes`): the roof cells that lie on a plane fitted to them take
    /// its height, and where two planes meet (a ridge, a hip, a valley) their line is an edge of
    /// the roof mesh: one straight, sharp ridge where the cells' noise made a zigzag of small
    /// edges, so a ray diffracts over it as over the real one. Cells on no plane (units,
    /// chimneys, domes) keep their heights. Default true.
    pub roof_planes: bool,
}

impl Default for BuildingSolidsParams {
    fn default() -> Self {
        BuildingSolidsParams {
            tolerance_m: 0.1,
            outline_tolerance_m: 0.5,
            regularize_angle_deg: 12.0,
            embed_m: 0.5,
            material: default_material(ObjectClass::Building),
            roof_planes: true,
        }
    }
}

/// One closed solid per building label, `building-<label>`, in label order.
pub struct BuildingSolids;

impl Stage for BuildingSolids {
    const KIND: &'static str = "BuildingSolids";
    // 3: a cut corner beside a spike, or a spike of several edges, is squared (buildings::regularize).
    // 4: roof cells snapped to fitted planes, planes meeting at an edge (roof_planes).
    const VERSION: u32 = 4;
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
        let objects: Vec<Result<(SceneObject, Roof), String>> = outlines
            .into_par_iter()
            .map(|(label, polygons)| {
                let solid = solid(&cells, label, &polygons, p).map(|(mesh, roof)| {
                    let object = SceneObject {
                        id: format!("building-{label}"),
                        class: ObjectClass::Building,
                        mesh,
                    };
                    (object, roof)
                });
                ctx.progress.advance(1);
                solid
            })
            .collect();
        let (objects, roofs): (Vec<SceneObject>, Vec<Roof>) = objects
            .into_iter()
            .collect::<Result<Vec<_>, _>>()
            .map_err(StageError::Failed)?
            .into_iter()
            .unzip();
        let without: Vec<&str> = objects
            .iter()
            .zip(&roofs)
            .filter(|(_, r)| **r == Roof::WithoutLines)
            .map(|(o, _)| o.id.as_str())
            .collect();
        if !without.is_empty() {
            ctx.progress.warn(&format!(
                "{} of {} buildings have roofs built without their roof lines (the lines made the roof intersect itself or broke its triangulation; ridges kept only where the refinement's vertices keep them): {}",
                without.len(),
                objects.len(),
                crate::stage::named_few(&without)
            ));
        }
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

/// How a building's roof was built.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Roof {
    /// With the roof lines as edges of its triangulation.
    WithLines,
    /// Without them: with them the roof intersected itself or its triangulation failed.
    WithoutLines,
}

/// The solid of one building: one closed shell per polygon of its outline. Tries the simplified
/// outline first and the exact cell outline if that fails the checks.
fn solid(
    cells: &CellHeights,
    label: u32,
    polygons: &[Polygon],
    p: &BuildingSolidsParams,
) -> Result<(crate::artifact::Mesh, Roof), String> {
    let members = cells
        .members
        .get(&label)
        .ok_or_else(|| format!("building-{label} has no cells"))?;
    let floor = members
        .iter()
        .map(|&i| cells.ground[i as usize])
        .fold(f64::INFINITY, f64::min)
        - p.embed_m;
    let roof = RoofFit::new(cells, label, members, p.roof_planes);
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
    // spade 2.15 can panic ("Failed to locate position") on a triangulation whose constraint
    // edges (nearly parallel roof lines a fraction of a cell apart) leave slivers its point
    // location cannot walk; such a roof is built again without its lines, its ridges then kept
    // only as far as the refinement's vertices keep them.
    let lines_dropped = std::cell::Cell::new(false);
    let shell_of = |poly: &Polygon, roof_lines: bool| {
        let build = |lines: bool| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                shell(cells, &roof, label, members, poly, floor, p, lines)
            }))
        };
        let failed = || Err("the roof's triangulation failed inside spade".to_string());
        match build(roof_lines) {
            Ok(made) => made,
            Err(_) if roof_lines => {
                lines_dropped.set(true);
                build(false).unwrap_or_else(|_| failed())
            }
            Err(_) => failed(),
        }
    };
    // Each outline with the roof lines as edges, then (a roof whose lines cross into a surface
    // that intersects itself, seen in about one building in ten thousand) without them.
    for roof_lines in [true, false] {
        for outline in &candidates {
            let mut mesh = crate::artifact::Mesh::default();
            lines_dropped.set(!roof_lines);
            let built: Result<(), String> = outline.iter().try_for_each(|poly| {
                mesh.append(&shell_of(poly, roof_lines)?);
                Ok(())
            });
            match built.and_then(|()| check_solid(&mesh).map(|_| ())) {
                Ok(()) if lines_dropped.get() => return Ok((mesh, Roof::WithoutLines)),
                Ok(()) => return Ok((mesh, Roof::WithLines)),
                Err(e) if roof_lines => last_error = e,
                Err(_) => {}
            }
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

/// One closed shell: the adaptive roof over `poly` (with the roof lines as edges when
/// `roof_lines`), walls along its rings, a flat floor.
#[allow(clippy::too_many_arguments)]
fn shell(
    cells: &CellHeights,
    roof: &RoofFit,
    label: u32,
    members: &[u32],
    poly: &Polygon,
    floor: f64,
    p: &BuildingSolidsParams,
    roof_lines: bool,
) -> Result<crate::artifact::Mesh, String> {
    let g = cells.grid;
    let mut cdt = ConstrainedDelaunayTriangulation::<RoofVertex>::new();
    let mut missing = None;
    let ring = insert_rings(&mut cdt, poly, |q, _| {
        let z = roof.vertex_height(cells, label, q).unwrap_or_else(|| {
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
    let index = poly.index();
    let inside = |x: f64, y: f64| index.contains([x, y]);
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
                z: roof.cell_height(cells, i),
            })
        })
        .collect();
    // Where roof planes meet, their line is an edge: inside the outline, clear of its rings by
    // the margin, and not crossing an edge already made one.
    let clear = |q: [f64; 2]| {
        inside(q[0], q[1])
            && segments
                .iter()
                .all(|&(a, b)| segment_distance(q, a, b) > margin)
    };
    let lines: &[_] = if roof_lines { &roof.lines } else { &[] };
    for &(pa, _, from, to) in lines {
        let Some((a, b)) = clear_stretch(from, to, &clear) else {
            continue;
        };
        let plane = roof.fit.planes[pa as usize];
        let mut at = |q: [f64; 2]| {
            cdt.insert(RoofVertex {
                p: Point2::new(q[0], q[1]),
                z: plane.z(q[0], q[1]),
            })
            .map_err(|e| format!("cannot insert a roof line's end {q:?}: {e:?}"))
        };
        let (ha, hb) = (at(a)?, at(b)?);
        if ha != hb {
            cdt.try_add_constraint(ha, hb);
        }
    }
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

/// A building's roof planes: each of its cells' plane, and the lines where two planes meet.
struct RoofFit {
    fit: PlaneFit,
    /// Cell index -> plane.
    plane_of: BTreeMap<u32, u32>,
    /// (plane, plane, from, to) in the site frame.
    lines: Vec<(u32, u32, [f64; 2], [f64; 2])>,
}

impl RoofFit {
    fn new(cells: &CellHeights, label: u32, members: &[u32], enabled: bool) -> RoofFit {
        let g = cells.grid;
        if !enabled {
            return RoofFit {
                fit: PlaneFit::default(),
                plane_of: BTreeMap::new(),
                lines: Vec::new(),
            };
        }
        let xy: Vec<[f64; 2]> = members
            .iter()
            .map(|&i| {
                let (x, y) = g.center(i % g.width, i / g.width);
                [x, y]
            })
            .collect();
        let xyz: Vec<[f64; 3]> = members
            .iter()
            .zip(&xy)
            .map(|(&i, q)| [q[0], q[1], cells.roof[i as usize]])
            .collect();
        let fit = fit_planes(&xyz, &PlaneConfig::default(), mix(label as u64));
        let index: BTreeMap<u32, usize> =
            members.iter().enumerate().map(|(k, &i)| (i, k)).collect();
        let mut touching = Vec::new();
        for (k, &i) in members.iter().enumerate() {
            for j in [i + 1, i + g.width] {
                let same_row = j != i + 1 || (i + 1) % g.width != 0;
                if let Some(&m) = index.get(&j).filter(|_| same_row) {
                    touching.push((k, m));
                }
            }
        }
        // Planes meet at an edge where their touching cells straddle the line (within 0.75 m:
        // a cell and a half) and they turn by 5 degrees or more.
        let lines = meeting_lines(&fit, &xy, &touching, 0.75, 5.0);
        let plane_of = members
            .iter()
            .zip(&fit.of_cell)
            .filter_map(|(&i, p)| p.map(|p| (i, p)))
            .collect();
        RoofFit {
            fit,
            plane_of,
            lines,
        }
    }

    /// A cell's roof height: its plane's at its centre, else its own.
    fn cell_height(&self, cells: &CellHeights, i: u32) -> f64 {
        let g = cells.grid;
        match self.plane_of.get(&i) {
            Some(&p) => {
                let (x, y) = g.center(i % g.width, i / g.width);
                self.fit.planes[p as usize].z(x, y)
            }
            None => cells.roof[i as usize],
        }
    }

    /// An outline vertex's roof height: the plane of the nearest of the building's cells within
    /// a cell and a half, at the vertex; where that cell is on no plane, the cells' mean
    /// ([`CellHeights::corner_height`]).
    fn vertex_height(&self, cells: &CellHeights, label: u32, q: [f64; 2]) -> Option<f64> {
        let g = cells.grid;
        let (c, r) = (
            ((q[0] - g.x0) / g.cell_m).floor() as i64,
            ((g.y0 - q[1]) / g.cell_m).floor() as i64,
        );
        let mut best: Option<(f64, u32)> = None;
        for rr in r - 2..=r + 2 {
            for cc in c - 2..=c + 2 {
                if cc < 0 || rr < 0 || cc >= g.width as i64 || rr >= g.height as i64 {
                    continue;
                }
                let i = (rr * g.width as i64 + cc) as u32;
                if cells.label[i as usize] != label {
                    continue;
                }
                let (x, y) = g.center(cc as u32, rr as u32);
                let d = (x - q[0]).hypot(y - q[1]);
                if d <= 1.5 * g.cell_m && best.is_none_or(|(bd, bi)| d < bd || (d == bd && i < bi))
                {
                    best = Some((d, i));
                }
            }
        }
        match best.and_then(|(_, i)| self.plane_of.get(&i)) {
            Some(&p) => Some(self.fit.planes[p as usize].z(q[0], q[1])),
            None => cells.corner_height(label, q),
        }
    }
}

/// The part of the segment `from`-`to` whose points are `clear`: its ends moved toward each
/// other in quarter-metre steps until both are; None when less than a metre is left.
fn clear_stretch(
    from: [f64; 2],
    to: [f64; 2],
    clear: impl Fn([f64; 2]) -> bool,
) -> Option<([f64; 2], [f64; 2])> {
    let len = (to[0] - from[0]).hypot(to[1] - from[1]);
    if len < 1.0 {
        return None;
    }
    let at = |s: f64| {
        [
            from[0] + (to[0] - from[0]) * s / len,
            from[1] + (to[1] - from[1]) * s / len,
        ]
    };
    let mut s0 = 0.0;
    while s0 < len && !clear(at(s0)) {
        s0 += 0.25;
    }
    let mut s1 = len;
    while s1 > s0 && !clear(at(s1)) {
        s1 -= 0.25;
    }
    (s1 - s0 >= 1.0).then(|| (at(s0), at(s1)))
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
                // Only just: beside the chimney's top corner the roof drops 1.5 m within a
                // sliver, 15 m per metre, and 1 cm off the centre reads 0.14 m low.
                let (x, y) = (
                    (c as f64 + 0.5) * 0.5 + 0.0011,
                    (h - r) as f64 * 0.5 - 0.25 + 0.0007,
                );
                let hit = top.cast([x as f32, y as f32, 500.0], [0.0, 0.0, -1.0], 0.0, 1e3);
                let z = 500.0 - hit.unwrap().t as f64;
                let truth = 100.0 + (c as f64) * 0.05 + roof_at(c, r);
                worst = worst.max((z - truth).abs());
            }
        }
        assert!(worst <= 0.1 + 0.05 * 0.5 + 1e-3, "worst roof error {worst}");
    }

    /// How much of the ridge of a hipped roof (along x at y = 10 from x = 11 to 19, 9 m above
    /// the flat terrain at 100 m) the mesh's edges run along, at the ridge's height within 5 cm.
    fn ridge_cover(p: &BuildingSolidsParams) -> f64 {
        let (w, h) = (60, 40);
        let inside = |c: u32, r: u32| (10..50).contains(&c) && (8..32).contains(&r);
        let labels = raster(w, h, |c, r| if inside(c, r) { 1.0 } else { 0.0 });
        // Eaves 6 m over a 20 m x 12 m footprint, 0.5 m rise per metre, and a LiDAR's +-8 cm.
        let roofs = raster(w, h, |c, r| {
            if !inside(c, r) {
                return f32::NAN;
            }
            let (x, y) = ((c as f64 + 0.5) * 0.5, (h - r) as f64 * 0.5 - 0.25);
            let to_eave = (x - 5.0).min(25.0 - x).min(y - 4.0).min(16.0 - y);
            let noise = 0.16 * (crate::rng::unit(mix((r * w + c) as u64)) - 0.5);
            (6.0 + 0.5 * to_eave + noise) as f32
        });
        let terrain = raster(w, h, |_, _| 100.0);
        let scene = solids(&labels, &roofs, &terrain, p);
        let mesh = &scene.objects[0].mesh;
        check_solid(mesh).unwrap();
        let on_ridge =
            |v: [f32; 3]| (v[1] as f64 - 10.0).abs() < 0.05 && (v[2] as f64 - 109.0).abs() < 0.05;
        let mut spans: Vec<(f64, f64)> = Vec::new();
        for t in mesh.triangles.iter() {
            for k in 0..3 {
                let (a, b) = (
                    mesh.positions[t[k] as usize],
                    mesh.positions[t[(k + 1) % 3] as usize],
                );
                if on_ridge(a) && on_ridge(b) {
                    let (x0, x1) = (
                        (a[0].min(b[0]) as f64).max(11.0),
                        (a[0].max(b[0]) as f64).min(19.0),
                    );
                    if x1 > x0 {
                        spans.push((x0, x1));
                    }
                }
            }
        }
        spans.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut covered, mut reach) = (0.0, 11.0f64);
        for (x0, x1) in spans {
            covered += (x1 - x0.max(reach)).max(0.0);
            reach = reach.max(x1);
        }
        covered / 8.0
    }

    #[test]
    fn a_hipped_roof_read_through_lidar_noise_keeps_one_sharp_ridge() {
        let planes = ridge_cover(&Default::default());
        let cells = ridge_cover(&BuildingSolidsParams {
            roof_planes: false,
            ..Default::default()
        });
        println!("ridge covered {planes:.2} with roof planes, {cells:.2} from the cells alone");
        assert!(planes >= 0.8, "ridge covered {planes:.2} with roof planes");
        assert!(cells < 0.3, "ridge covered {cells:.2} from the cells alone");
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
