//! Texel materials into the scene (paper Sec. 4.2.3): every chart's material map becomes
//! per-triangle materials, the chart's triangles split along the material regions' boundaries so
//! each piece carries one material, and the solid stays closed.
//!
//! A chart's regions are cleaned (components smaller than a minimum area join their most common
//! neighbour), and their boundaries become axis-parallel cut lines in the chart's texel frame
//! (texel edges where the material changes along a row or column, nearby positions snapped into
//! one). Every chart triangle is split by those lines into convex pieces, each taking the
//! majority material of the texels of its cell. A cut line meeting a mesh edge adds a vertex
//! there; that vertex is inserted into every triangle sharing the edge (the neighbouring chart's,
//! the floor's), so no T-junction opens the solid.

use std::collections::BTreeMap;

use glam::DVec3;

use crate::artifact::{Chart, ChartMaterials, ChartSet, Mesh, NO_MATERIAL, PodVec, Scene};
use crate::geom::mesh_check::check_solid;

/// How material regions are turned into geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ApplySpec {
    /// Connected regions of one material smaller than this (m², in plan on roofs) join their
    /// most common neighbouring material first.
    pub min_region_m2: f64,
    /// Cut positions closer than this (metres) merge into one line (the most used one).
    pub snap_m: f64,
}

impl Default for ApplySpec {
    fn default() -> Self {
        ApplySpec {
            min_region_m2: 0.16,
            snap_m: 0.2,
        }
    }
}

/// What [`apply_materials`] did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ApplyStats {
    /// Building triangles before.
    pub triangles_before: u64,
    /// ... and after.
    pub triangles_after: u64,
    /// Charts split by at least one cut line.
    pub charts_split: u64,
    /// Cut lines over all charts.
    pub cut_lines: u64,
    /// Vertices added on mesh edges (shared with the neighbours) and inside faces.
    pub vertices_added: u64,
    /// Objects split along their material regions.
    pub objects_split: u64,
    /// Objects whose split failed (or would open a closed solid), kept whole with each triangle
    /// painted the material at its centre: "id: why", in object order.
    pub kept_whole: Vec<String>,
}

impl ApplyStats {
    /// Adds one object's counts.
    fn absorb(&mut self, o: &ApplyStats) {
        self.triangles_before += o.triangles_before;
        self.triangles_after += o.triangles_after;
        self.charts_split += o.charts_split;
        self.cut_lines += o.cut_lines;
        self.vertices_added += o.vertices_added;
        self.objects_split += o.objects_split;
    }
}

/// Points closer than this (metres) to a cut line lie on it; edge points closer than half of it
/// merge.
const TOL_M: f64 = 1e-3;

/// The materials of `mats` (one per chart of `charts`, in order) applied to `scene`'s objects.
/// Objects without charts are returned as they are; triangles of charted objects outside any
/// chart (floors) keep their material.
pub fn apply_materials(
    scene: &Scene,
    charts: &ChartSet,
    mats: &[ChartMaterials],
    spec: &ApplySpec,
) -> Result<(Scene, ApplyStats), String> {
    if mats.len() != charts.charts.len() {
        return Err(format!(
            "{} chart material maps for {} charts: the materials were not fused on these charts",
            mats.len(),
            charts.charts.len()
        ));
    }
    let mut by_object: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (k, c) in charts.charts.iter().enumerate() {
        let o = scene.objects.get(c.object as usize).ok_or_else(|| {
            format!(
                "chart {k} is on object {} but the scene has {} objects",
                c.object,
                scene.objects.len()
            )
        })?;
        if o.id != c.building || c.triangles.iter().any(|&t| t as usize >= o.mesh.len()) {
            return Err(format!(
                "the charts were not made from this scene (chart on {} at object {})",
                c.building, c.object
            ));
        }
        let m = &mats[k];
        if m.material.len() != c.len() || m.source.len() != c.len() {
            return Err(format!(
                "chart {k} on {} has {} texels but its material map {}",
                c.building,
                c.len(),
                m.material.len()
            ));
        }
        by_object.entry(c.object).or_default().push(k);
    }
    let mut stats = ApplyStats::default();
    let mut out = scene.clone();
    for (&o, ks) in &by_object {
        let obj = &mut out.objects[o as usize];
        let plans: Vec<(usize, ChartPlan)> = ks
            .iter()
            .map(|&k| (k, plan_chart(&charts.charts[k], &mats[k], spec)))
            .collect();
        // One building's split going wrong (a cut through a sliver, a self-intersection the
        // new vertices make) must not cost the whole twin: that building keeps its checked
        // mesh, painted triangle by triangle, and is counted.
        let mut one = ApplyStats {
            triangles_before: obj.mesh.len() as u64,
            ..Default::default()
        };
        let split = split_object(&obj.mesh, charts, &plans, &mut one)
            .and_then(|mesh| keeps_a_solid(&obj.mesh, mesh));
        match split {
            Ok(mesh) => {
                one.triangles_after = mesh.len() as u64;
                one.objects_split = 1;
                stats.absorb(&one);
                obj.mesh = mesh;
            }
            Err(why) => {
                obj.mesh = painted_whole(&obj.mesh, charts, &plans);
                stats.triangles_before += one.triangles_before;
                stats.triangles_after += one.triangles_before;
                stats.kept_whole.push(format!("{}: {why}", obj.id));
            }
        }
    }
    Ok((out, stats))
}

/// `split` if it is a closed, manifold solid wherever `before` was one; an object that was no
/// checked solid to begin with (a truth scene's unions of shells) is not made worse by its split.
fn keeps_a_solid(before: &Mesh, split: Mesh) -> Result<Mesh, String> {
    match check_solid(&split) {
        Err(e) if check_solid(before).is_ok() => Err(format!(
            "the solid split along its material boundaries is not closed and manifold: {e}"
        )),
        _ => Ok(split),
    }
}

/// `mesh` unsplit, each charted triangle given its plan's material at the triangle's centre
/// (its own where the plan has none): coarser than the split, but the solid is the one checked.
fn painted_whole(mesh: &Mesh, charts: &ChartSet, plans: &[(usize, ChartPlan)]) -> Mesh {
    let plan_of = plan_of_triangles(mesh, charts, plans);
    let mut out = mesh.clone();
    out.materials.0.resize(mesh.len(), 0);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let Some((k, plan)) = plans.get(plan_of[t]) else {
            continue;
        };
        let centre = tri
            .iter()
            .map(|&v| DVec3::from(mesh.positions[v as usize].map(f64::from)))
            .sum::<DVec3>()
            / 3.0;
        let (u, v) = uv(&charts.charts[*k], centre);
        let m = plan.material_at(u, v);
        if m != NO_MATERIAL {
            out.materials.0[t] = m;
        }
    }
    out
}

/// One chart's cut lines (texel coordinates, ascending) and the material of each cell between
/// them (row-major over `v` cells).
#[derive(Clone, Debug, PartialEq)]
pub struct ChartPlan {
    /// Lines u = const.
    pub us: Vec<f64>,
    /// Lines v = const.
    pub vs: Vec<f64>,
    /// (us.len() + 1) x (vs.len() + 1) cells, `u` fastest.
    pub cells: Vec<u8>,
}

impl ChartPlan {
    /// The material of the cell holding texel coordinates (u, v).
    pub fn material_at(&self, u: f64, v: f64) -> u8 {
        let a = self.us.partition_point(|&x| x <= u);
        let b = self.vs.partition_point(|&x| x <= v);
        self.cells[b * (self.us.len() + 1) + a]
    }
}

/// The chart's material map, cleaned, as cut lines and cell materials.
pub fn plan_chart(c: &Chart, m: &ChartMaterials, spec: &ApplySpec) -> ChartPlan {
    let (w, h) = (c.width as usize, c.height as usize);
    let on: Vec<bool> = c.triangle_at.iter().map(|&t| t != u32::MAX).collect();
    let mut g: Vec<u8> = (0..w * h)
        .map(|k| if on[k] { m.material[k] } else { NO_MATERIAL })
        .collect();
    if g.iter().all(|&x| x == NO_MATERIAL) {
        let fill = m.dominant.unwrap_or(NO_MATERIAL);
        return ChartPlan {
            us: vec![],
            vs: vec![],
            cells: vec![fill],
        };
    }
    let texel_area = c.texel_m * c.texel_m;
    let min_texels = (spec.min_region_m2 / texel_area).ceil().clamp(0.0, 1e9) as usize;
    let snap_texels = (spec.snap_m / c.texel_m + 1e-9).floor().clamp(0.0, 1e6) as u32;
    remove_small_regions(&mut g, &on, w, h, min_texels);
    fill_off_surface(&mut g, w, h);
    // Where the material changes, counted over rows (u lines) and columns (v lines).
    let mut u_change = vec![0u32; w + 1];
    let mut v_change = vec![0u32; h + 1];
    for j in 0..h {
        for i in 1..w {
            if g[j * w + i] != g[j * w + i - 1] {
                u_change[i] += 1;
            }
        }
    }
    for j in 1..h {
        for i in 0..w {
            if g[j * w + i] != g[(j - 1) * w + i] {
                v_change[j] += 1;
            }
        }
    }
    let us = snap(&u_change, snap_texels);
    let vs = snap(&v_change, snap_texels);
    // Cell materials: the majority over the cell's surface texels (all its texels if none).
    let (nu, nv) = (us.len() + 1, vs.len() + 1);
    let bounds = |lines: &[usize], n: usize, k: usize| {
        (
            if k == 0 { 0 } else { lines[k - 1] },
            if k == lines.len() { n } else { lines[k] },
        )
    };
    let mut cells = vec![NO_MATERIAL; nu * nv];
    for b in 0..nv {
        let (j0, j1) = bounds(&vs, h, b);
        for a in 0..nu {
            let (i0, i1) = bounds(&us, w, a);
            let mut count = [[0u64; 256]; 2];
            for j in j0..j1 {
                for i in i0..i1 {
                    let k = j * w + i;
                    count[on[k] as usize][g[k] as usize] += 1;
                }
            }
            let pick = |c: &[u64; 256]| {
                c.iter()
                    .enumerate()
                    .filter(|(m, _)| *m != NO_MATERIAL as usize)
                    .fold(None, |best: Option<(usize, u64)>, (m, &n)| {
                        if n > 0 && best.is_none_or(|b| n > b.1) {
                            Some((m, n))
                        } else {
                            best
                        }
                    })
                    .map(|(m, _)| m as u8)
            };
            cells[b * nu + a] = pick(&count[1])
                .or_else(|| pick(&count[0]))
                .unwrap_or(NO_MATERIAL);
        }
    }
    ChartPlan {
        us: us.iter().map(|&x| x as f64).collect(),
        vs: vs.iter().map(|&x| x as f64).collect(),
        cells,
    }
}

/// Line positions from change counts: positions within `snap` of the first of a run merge into
/// the run's most used position (the lowest on a tie).
fn snap(changes: &[u32], snap: u32) -> Vec<usize> {
    let mut out = Vec::new();
    let mut run: Option<(usize, usize, u32)> = None; // (start, best, best count)
    for (x, &n) in changes.iter().enumerate() {
        if n == 0 {
            continue;
        }
        match &mut run {
            Some((start, best, bn)) if x - *start <= snap as usize => {
                if n > *bn {
                    (*best, *bn) = (x, n);
                }
            }
            _ => {
                if let Some((_, best, _)) = run {
                    out.push(best);
                }
                run = Some((x, x, n));
            }
        }
    }
    if let Some((_, best, _)) = run {
        out.push(best);
    }
    out
}

/// Components (4-connected, surface texels of one material) below `min` texels take the most
/// common material around them; repeated until none is left or nothing changes (at most 4
/// passes).
fn remove_small_regions(g: &mut [u8], on: &[bool], w: usize, h: usize, min: usize) {
    if min <= 1 {
        return;
    }
    for _ in 0..4 {
        let mut label = vec![u32::MAX; w * h];
        let mut changed = false;
        let mut next = 0u32;
        for start in 0..w * h {
            if !on[start] || label[start] != u32::MAX {
                continue;
            }
            let m = g[start];
            let mut comp = vec![start];
            label[start] = next;
            let mut at = 0;
            let mut around = [0u64; 256];
            while at < comp.len() {
                let k = comp[at];
                at += 1;
                let (i, j) = (k % w, k / w);
                let mut nb = [usize::MAX; 4];
                if i > 0 {
                    nb[0] = k - 1;
                }
                if i + 1 < w {
                    nb[1] = k + 1;
                }
                if j > 0 {
                    nb[2] = k - w;
                }
                if j + 1 < h {
                    nb[3] = k + w;
                }
                for q in nb {
                    if q == usize::MAX || !on[q] {
                        continue;
                    }
                    if g[q] == m {
                        if label[q] == u32::MAX {
                            label[q] = next;
                            comp.push(q);
                        }
                    } else {
                        around[g[q] as usize] += 1;
                    }
                }
            }
            next += 1;
            if comp.len() < min
                && let Some((best, _)) = around.iter().enumerate().filter(|(_, n)| **n > 0).fold(
                    None,
                    |b: Option<(usize, u64)>, (x, &n)| {
                        if b.is_none_or(|b| n > b.1) {
                            Some((x, n))
                        } else {
                            b
                        }
                    },
                )
            {
                for k in comp {
                    g[k] = best as u8;
                }
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}

/// Off-surface texels take the material of the nearest surface texel (breadth first, 4
/// neighbours, in index order), so cut lines are not made by the outline.
fn fill_off_surface(g: &mut [u8], w: usize, h: usize) {
    let mut frontier: Vec<usize> = (0..w * h).filter(|&k| g[k] != NO_MATERIAL).collect();
    while !frontier.is_empty() {
        let mut next = Vec::new();
        let mut set: Vec<(usize, u8)> = Vec::new();
        for &k in &frontier {
            let (i, j) = (k % w, k / w);
            let nbs = [
                (i > 0).then(|| k - 1),
                (i + 1 < w).then(|| k + 1),
                (j > 0).then(|| k - w),
                (j + 1 < h).then(|| k + w),
            ];
            for q in nbs.into_iter().flatten() {
                if g[q] == NO_MATERIAL {
                    set.push((q, g[k]));
                }
            }
        }
        for (q, m) in set {
            if g[q] == NO_MATERIAL {
                g[q] = m;
                next.push(q);
            }
        }
        frontier = next;
    }
}

/// What a polygon edge lies on: a mesh edge (its vertex pair, low first) or a cut line of the
/// chart being split (index into us then vs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Carrier {
    Edge(u32, u32),
    Line(u32),
}

/// Working vertices: the mesh's, then added ones, in f64.
struct Verts {
    pos: Vec<DVec3>,
    /// Points on mesh edges, by edge (low, high): (parameter from low to high, vertex).
    on_edge: BTreeMap<(u32, u32), Vec<(f64, u32)>>,
    /// Crossings of two cut lines of a chart: (chart, line, line) -> vertex.
    crossing: BTreeMap<(usize, u32, u32), u32>,
}

impl Verts {
    fn add(&mut self, p: DVec3) -> u32 {
        self.pos.push(p);
        self.pos.len() as u32 - 1
    }
}

/// Texel coordinates of a world point on chart `c` (walls: in the plane; roofs: plan x, y).
fn uv(c: &Chart, p: DVec3) -> (f64, f64) {
    c.uv_of(p.to_array())
}

/// The mesh of `mesh` with every charted triangle split along its chart plan's cut lines and
/// each piece given the plan's material at its centre; counts into `stats`.
fn split_object(
    mesh: &Mesh,
    charts: &ChartSet,
    plans: &[(usize, ChartPlan)],
    stats: &mut ApplyStats,
) -> Result<Mesh, String> {
    let n0 = mesh.positions.len();
    let mut verts = Verts {
        pos: mesh
            .positions
            .iter()
            .map(|p| DVec3::from(p.map(f64::from)))
            .collect(),
        on_edge: BTreeMap::new(),
        crossing: BTreeMap::new(),
    };
    let plan_of = plan_of_triangles(mesh, charts, plans);
    // Phase 1: where each chart's lines cross its triangles' edges, on those edges.
    let edge_pts = edge_crossings(mesh, charts, plans, &verts, stats);
    place_edge_points(edge_pts, &mut verts);
    // Phase 2: every triangle with the points on its edges, split by its chart's lines.
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(mesh.len());
    let mut mats: Vec<u8> = Vec::with_capacity(mesh.len());
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let poly = edge_polygon(tri, &verts);
        let original = mesh.materials.get(t).copied().unwrap_or(0);
        let pieces: Vec<(Vec<(u32, Carrier)>, u8)> = match plan_of[t] {
            usize::MAX => vec![(poly, original)],
            pi => split_by_plan(poly, &plans[pi], charts, &mut verts, original)?,
        };
        for (p, m) in pieces {
            for tr in triangulate(&p, &mut verts) {
                tris.push(tr);
                mats.push(m);
            }
        }
    }
    stats.vertices_added += (verts.pos.len() - n0) as u64;
    Ok(Mesh {
        positions: PodVec(
            verts
                .pos
                .iter()
                .map(|p| p.to_array().map(|x| x as f32))
                .collect(),
        ),
        triangles: PodVec(tris),
        materials: PodVec(mats),
    })
}

/// Triangle -> index into `plans` of its chart's plan (usize::MAX: uncharted). A step of its
/// own: the look-up phase 2 needs for every triangle.
fn plan_of_triangles(mesh: &Mesh, charts: &ChartSet, plans: &[(usize, ChartPlan)]) -> Vec<usize> {
    // Triangle -> (plan index) for charted triangles.
    let mut plan_of = vec![usize::MAX; mesh.len()];
    for (pi, (k, _)) in plans.iter().enumerate() {
        for &t in charts.charts[*k].triangles.iter() {
            plan_of[t as usize] = pi;
        }
    }
    plan_of
}

/// Phase 1, the crossings: for each (sorted) edge of a charted triangle, the parameters where
/// its chart's cut lines cross it, away from its ends; counts split charts and cut lines into
/// `stats`. A step of its own: it only finds the points, `place_edge_points` makes them.
fn edge_crossings(
    mesh: &Mesh,
    charts: &ChartSet,
    plans: &[(usize, ChartPlan)],
    verts: &Verts,
    stats: &mut ApplyStats,
) -> BTreeMap<(u32, u32), Vec<f64>> {
    let mut edge_pts: BTreeMap<(u32, u32), Vec<f64>> = BTreeMap::new();
    for (k, plan) in plans {
        let c = &charts.charts[*k];
        if plan.us.is_empty() && plan.vs.is_empty() {
            continue;
        }
        stats.charts_split += 1;
        stats.cut_lines += (plan.us.len() + plan.vs.len()) as u64;
        for &t in c.triangles.iter() {
            let tri = mesh.triangles[t as usize];
            for e in 0..3 {
                let (a, b) = (tri[e].min(tri[(e + 1) % 3]), tri[e].max(tri[(e + 1) % 3]));
                let (pa, pb) = (verts.pos[a as usize], verts.pos[b as usize]);
                let len = pa.distance(pb);
                if len <= 2.0 * TOL_M {
                    continue;
                }
                let (ua, ub) = (uv(c, pa), uv(c, pb));
                for (lines, axis) in [(&plan.us, 0), (&plan.vs, 1)] {
                    let (x0, x1) = if axis == 0 {
                        (ua.0, ub.0)
                    } else {
                        (ua.1, ub.1)
                    };
                    if x0 == x1 {
                        continue;
                    }
                    for &l in lines.iter() {
                        let s = (l - x0) / (x1 - x0);
                        if s * len > TOL_M && (1.0 - s) * len > TOL_M {
                            edge_pts.entry((a, b)).or_default().push(s);
                        }
                    }
                }
            }
        }
    }
    edge_pts
}

/// Phase 1, the vertices: each edge's crossings in order, those within TOL_M / 2 of the last
/// kept merged, made vertices and filed under the edge in `verts.on_edge`. A step of its own:
/// every triangle sharing an edge then shares its points.
fn place_edge_points(edge_pts: BTreeMap<(u32, u32), Vec<f64>>, verts: &mut Verts) {
    for ((a, b), mut ss) in edge_pts {
        ss.sort_by(f64::total_cmp);
        let (pa, pb) = (verts.pos[a as usize], verts.pos[b as usize]);
        let len = pa.distance(pb);
        let mut kept: Vec<(f64, u32)> = Vec::new();
        for s in ss {
            if kept
                .last()
                .is_some_and(|&(l, _)| (s - l) * len < TOL_M / 2.0)
            {
                continue;
            }
            let v = verts.add(pa.lerp_monotonic(pb, s));
            kept.push((s, v));
        }
        verts.on_edge.insert((a, b), kept);
    }
}

/// Phase 2's start: triangle `tri` as a polygon with the points on its edges, each vertex with
/// the edge leaving it. A step of its own: the same for charted and uncharted triangles.
fn edge_polygon(tri: &[u32; 3], verts: &Verts) -> Poly {
    let mut poly: Vec<(u32, Carrier)> = Vec::new();
    for e in 0..3 {
        let (a, b) = (tri[e], tri[(e + 1) % 3]);
        let key = (a.min(b), a.max(b));
        let carrier = Carrier::Edge(key.0, key.1);
        poly.push((a, carrier));
        if let Some(pts) = verts.on_edge.get(&key) {
            if a < b {
                poly.extend(pts.iter().map(|&(_, v)| (v, carrier)));
            } else {
                poly.extend(pts.iter().rev().map(|&(_, v)| (v, carrier)));
            }
        }
    }
    poly
}

/// Phase 2 for a charted triangle: polygon `poly` split by every cut line of plan `(k, plan)`
/// (u lines, then v lines), each piece with the plan's material at its centre (`original` where
/// the plan has none). A step of its own: the only part of phase 2 that reads the plan.
fn split_by_plan(
    poly: Poly,
    (k, plan): &(usize, ChartPlan),
    charts: &ChartSet,
    verts: &mut Verts,
    original: u8,
) -> Result<Vec<(Poly, u8)>, String> {
    let c = &charts.charts[*k];
    let mut pieces = vec![poly];
    let lines = plan
        .us
        .iter()
        .map(|&l| (0, l))
        .chain(plan.vs.iter().map(|&l| (1, l)));
    for (li, (axis, l)) in lines.enumerate() {
        let mut next = Vec::with_capacity(pieces.len() + 1);
        for p in pieces {
            let (lo, hi) = split(p, *k, c, verts, li as u32, axis, l)?;
            next.extend(lo);
            next.extend(hi);
        }
        pieces = next;
    }
    Ok(pieces
        .into_iter()
        .map(|p| {
            let (mut su, mut sv) = (0.0, 0.0);
            for &(v, _) in &p {
                let (u, w) = uv(c, verts.pos[v as usize]);
                su += u;
                sv += w;
            }
            let n = p.len() as f64;
            let m = plan.material_at(su / n, sv / n);
            (p, if m == NO_MATERIAL { original } else { m })
        })
        .collect())
}

type Poly = Vec<(u32, Carrier)>;

/// Splits convex polygon `p` (vertex, carrier of the edge leaving it) by line `li` of chart `k`
/// (`axis` 0: u = `l`, 1: v = `l`) into the parts below and above it; `None` for an empty part.
#[allow(clippy::too_many_arguments)]
fn split(
    p: Poly,
    k: usize,
    c: &Chart,
    verts: &mut Verts,
    li: u32,
    axis: usize,
    l: f64,
) -> Result<(Option<Poly>, Option<Poly>), String> {
    let tol = TOL_M / c.texel_m;
    let side = |verts: &Verts, v: u32| {
        let q = uv(c, verts.pos[v as usize]);
        let x = if axis == 0 { q.0 } else { q.1 };
        if x < l - tol {
            -1
        } else if x > l + tol {
            1
        } else {
            0
        }
    };
    let s: Vec<i32> = p.iter().map(|&(v, _)| side(verts, v)).collect();
    if s.iter().all(|&x| x <= 0) {
        return Ok((Some(p), None));
    }
    if s.iter().all(|&x| x >= 0) {
        return Ok((None, Some(p)));
    }
    // Insert the crossings.
    let n = p.len();
    let mut aug: Vec<(u32, Carrier, i32)> = Vec::with_capacity(n + 2);
    for i in 0..n {
        let (v, carrier) = p[i];
        aug.push((v, carrier, s[i]));
        let j = (i + 1) % n;
        if s[i] * s[j] < 0 {
            let x = crossing(verts, k, c, carrier, v, p[j].0, li, axis, l)?;
            aug.push((x, carrier, 0));
        }
    }
    normalize_zeros(&mut aug);
    let part = |want: i32| -> Option<Poly> {
        // The run of vertices on the wanted side, with the one on-line vertex at each end,
        // cyclically contiguous in a convex polygon; the edge closing it runs along the line.
        let m = aug.len();
        let start = (0..m).find(|&i| aug[i].2 * want > 0)?;
        let mut first = start;
        while aug[(first + m - 1) % m].2 * want >= 0 && (first + m - 1) % m != start {
            first = (first + m - 1) % m;
        }
        let mut out: Poly = Vec::new();
        let mut i = first;
        loop {
            out.push((aug[i].0, aug[i].1));
            let nx = (i + 1) % m;
            if aug[nx].2 * want < 0 || nx == first {
                break;
            }
            i = nx;
        }
        if let Some(last) = out.last_mut() {
            last.1 = Carrier::Line(li);
        }
        (out.len() >= 3).then_some(out)
    };
    Ok((part(-1), part(1)))
}

/// Within the tolerance band several vertices in a row may count as on the line: only the last
/// of a run between the two sides stays on it (the others join the side before), and a run
/// between vertices of one side joins that side, so the two parts share one vertex at each
/// crossing and every polygon edge goes to exactly one part.
fn normalize_zeros(aug: &mut [(u32, Carrier, i32)]) {
    let m = aug.len();
    let Some(anchor) = (0..m).find(|&i| aug[i].2 != 0) else {
        return;
    };
    let mut i = 1;
    while i <= m {
        let at = (anchor + i) % m;
        if aug[at].2 != 0 {
            i += 1;
            continue;
        }
        let before = aug[(anchor + i - 1) % m].2;
        let mut len = 0;
        while aug[(anchor + i + len) % m].2 == 0 {
            len += 1;
        }
        let after = aug[(anchor + i + len) % m].2;
        let keep = if before == after { len } else { len - 1 };
        for d in 0..keep {
            aug[(anchor + i + d) % m].2 = before;
        }
        i += len + 1;
    }
}

/// The vertex where line `li` crosses the polygon edge from `a` to `b` on `carrier`: on a mesh
/// edge, the point phase 1 put there; on another cut line, the two lines' crossing.
#[allow(clippy::too_many_arguments)]
fn crossing(
    verts: &mut Verts,
    k: usize,
    c: &Chart,
    carrier: Carrier,
    a: u32,
    b: u32,
    li: u32,
    axis: usize,
    l: f64,
) -> Result<u32, String> {
    let (pa, pb) = (verts.pos[a as usize], verts.pos[b as usize]);
    let (ua, ub) = (uv(c, pa), uv(c, pb));
    let (x0, x1) = if axis == 0 {
        (ua.0, ub.0)
    } else {
        (ua.1, ub.1)
    };
    let s = ((l - x0) / (x1 - x0)).clamp(0.0, 1.0);
    let p = pa.lerp_monotonic(pb, s);
    match carrier {
        Carrier::Edge(e0, e1) => {
            let pts = verts.on_edge.get(&(e0, e1));
            pts.and_then(|pts| {
                pts.iter()
                    .map(|&(_, v)| v)
                    .find(|&v| verts.pos[v as usize].distance(p) < 2.0 * TOL_M)
            })
            .ok_or_else(|| {
                format!(
                    "a cut line crosses mesh edge ({e0}, {e1}) at {:?} where no shared vertex was placed",
                    p.to_array()
                )
            })
        }
        Carrier::Line(other) => {
            let key = (k, li.min(other), li.max(other));
            if let Some(&v) = verts.crossing.get(&key) {
                return Ok(v);
            }
            let v = verts.add(p);
            verts.crossing.insert(key, v);
            Ok(v)
        }
    }
}

/// Triangles of a convex polygon whose vertices may include points on its sides: a fan from a
/// corner whose neighbours are both corners (no triangle of it is flat), else a fan from an
/// added centre vertex.
fn triangulate(p: &[(u32, Carrier)], verts: &mut Verts) -> Vec<[u32; 3]> {
    let n = p.len();
    if n == 3 {
        return vec![[p[0].0, p[1].0, p[2].0]];
    }
    let pos = |i: usize| verts.pos[p[i % n].0 as usize];
    let corner = |i: usize| {
        let (a, b, c) = (pos(i + n - 1), pos(i), pos(i + 1));
        let (e1, e2) = (b - a, c - b);
        let s = e1.cross(e2).length() / (e1.length() * e2.length()).max(1e-300);
        s > 1e-6
    };
    let corners: Vec<bool> = (0..n).map(corner).collect();
    if let Some(i) =
        (0..n).find(|&i| corners[i] && corners[(i + 1) % n] && corners[(i + n - 1) % n])
    {
        return (1..n - 1)
            .map(|k| [p[i].0, p[(i + k) % n].0, p[(i + k + 1) % n].0])
            .collect();
    }
    let mut centre = DVec3::ZERO;
    for i in 0..n {
        centre += pos(i) / n as f64;
    }
    let cv = verts.add(centre);
    (0..n).map(|i| [cv, p[i].0, p[(i + 1) % n].0]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Material;
    use crate::artifact::{MaterialSource, ObjectClass, SceneObject};
    use crate::geom::charts::{ChartSpec, building_charts};
    use crate::geom::mesh_build::cuboid;
    use crate::geom::mesh_check::check_solid;

    fn box_scene() -> Scene {
        Scene {
            objects: vec![SceneObject {
                id: "building-0".into(),
                class: ObjectClass::Building,
                mesh: cuboid([12.0, 21.5], [4.0, 3.0, 6.0], 0.3, 0.0, Material::Concrete),
            }],
        }
    }

    /// Every chart concrete, with a glass window [1, 2.5] x [2, 4] m on each wall, and a metal
    /// patch on the roof.
    fn painted(charts: &ChartSet) -> Vec<ChartMaterials> {
        charts
            .charts
            .iter()
            .map(|c| {
                let mut m = vec![NO_MATERIAL; c.len()];
                for j in 0..c.height {
                    for i in 0..c.width {
                        let k = (j * c.width + i) as usize;
                        if c.triangle_at[k] == u32::MAX {
                            continue;
                        }
                        let (x, y) = ((i as f64 + 0.5) * c.texel_m, (j as f64 + 0.5) * c.texel_m);
                        let window = (1.0..2.5).contains(&x) && (2.0..4.0).contains(&y);
                        let roof_patch = (0.5..1.5).contains(&x) && (0.5..1.5).contains(&y);
                        m[k] = match c.kind {
                            crate::artifact::ChartKind::Wall if window => Material::Glass as u8,
                            crate::artifact::ChartKind::Roof if roof_patch => Material::Metal as u8,
                            _ => Material::Concrete as u8,
                        };
                    }
                }
                ChartMaterials {
                    source: PodVec(vec![MaterialSource::Observed as u8; c.len()]),
                    material: PodVec(m),
                    dominant: Some(Material::Concrete as u8),
                }
            })
            .collect()
    }

    fn area_of(mesh: &Mesh, m: Material) -> f64 {
        mesh.triangles
            .iter()
            .zip(mesh.materials.iter())
            .filter(|(_, x)| **x == m as u8)
            .map(|(t, _)| {
                let [a, b, c] = t.map(|i| DVec3::from(mesh.positions[i as usize].map(f64::from)));
                (b - a).cross(c - a).length() / 2.0
            })
            .sum()
    }

    #[test]
    fn windows_become_glass_faces_and_the_solid_stays_closed() {
        let scene = box_scene();
        let charts = building_charts(&scene, &ChartSpec::default()).unwrap();
        let mats = painted(&charts);
        let (out, stats) = apply_materials(&scene, &charts, &mats, &ApplySpec::default()).unwrap();
        let mesh = &out.objects[0].mesh;
        check_solid(mesh).unwrap();
        assert!((mesh.volume() - scene.objects[0].mesh.volume()).abs() < 1e-3);
        // Four windows of 1.5 x 2 m (up to the texel grid's offset from the wall's corner).
        let glass = area_of(mesh, Material::Glass);
        assert!((glass - 12.0).abs() < 4.0 * 0.35, "glass {glass} m²");
        let metal = area_of(mesh, Material::Metal);
        assert!((metal - 1.0).abs() < 0.5, "metal {metal} m²");
        assert!(stats.charts_split == 5 && stats.triangles_after > stats.triangles_before);
    }

    #[test]
    fn a_uniform_chart_is_left_alone() {
        let scene = box_scene();
        let charts = building_charts(&scene, &ChartSpec::default()).unwrap();
        let mats: Vec<ChartMaterials> = charts
            .charts
            .iter()
            .map(|c| ChartMaterials {
                material: PodVec(
                    c.triangle_at
                        .iter()
                        .map(|&t| {
                            if t == u32::MAX {
                                NO_MATERIAL
                            } else {
                                Material::Brick as u8
                            }
                        })
                        .collect(),
                ),
                source: PodVec(vec![1; c.len()]),
                dominant: Some(Material::Brick as u8),
            })
            .collect();
        let (out, stats) = apply_materials(&scene, &charts, &mats, &ApplySpec::default()).unwrap();
        let mesh = &out.objects[0].mesh;
        assert_eq!(mesh.triangles, scene.objects[0].mesh.triangles);
        assert_eq!(stats.cut_lines, 0);
        // Walls and roof brick, the floor (no chart) as it was.
        let brick = mesh
            .materials
            .iter()
            .filter(|&&m| m == Material::Brick as u8)
            .count();
        assert_eq!(brick, mesh.len() - 2);
    }

    /// The fallback for a building whose split fails: its checked mesh, untouched, each charted
    /// triangle painted the plan's material at its centre (walls glass here, the roof concrete,
    /// the floor, uncharted, as it was), and a split that opens a closed solid is refused.
    #[test]
    fn a_building_kept_whole_is_painted_triangle_by_triangle() {
        let scene = box_scene();
        let charts = building_charts(&scene, &ChartSpec::default()).unwrap();
        let mats: Vec<ChartMaterials> = charts
            .charts
            .iter()
            .map(|c| {
                let m = match c.kind {
                    crate::artifact::ChartKind::Wall => Material::Glass as u8,
                    _ => Material::Metal as u8,
                };
                let on = |&t: &u32| if t == u32::MAX { NO_MATERIAL } else { m };
                ChartMaterials {
                    material: PodVec(c.triangle_at.iter().map(on).collect()),
                    source: PodVec(vec![1; c.len()]),
                    dominant: Some(m),
                }
            })
            .collect();
        let plans: Vec<(usize, ChartPlan)> = (0..charts.charts.len())
            .map(|k| {
                (
                    k,
                    plan_chart(&charts.charts[k], &mats[k], &ApplySpec::default()),
                )
            })
            .collect();
        let before = &scene.objects[0].mesh;
        let whole = painted_whole(before, &charts, &plans);
        assert_eq!(whole.positions, before.positions);
        assert_eq!(whole.triangles, before.triangles);
        check_solid(&whole).unwrap();
        let count = |m: Material| whole.materials.iter().filter(|&&x| x == m as u8).count();
        assert_eq!(count(Material::Glass), 8);
        assert_eq!(count(Material::Metal), 2);
        assert_eq!(count(Material::Concrete), 2);
        let mut open = before.clone();
        open.triangles.0.pop();
        open.materials.0.pop();
        let why = keeps_a_solid(before, open.clone()).unwrap_err();
        assert!(why.contains("not closed and manifold"), "{why}");
        // An object that was open to begin with is not this step's to refuse.
        assert!(keeps_a_solid(&open, open.clone()).is_ok());
    }

    #[test]
    fn small_regions_join_their_neighbours_and_lines_snap() {
        assert_eq!(snap(&[0, 3, 0, 5, 0, 0, 0, 1], 2), vec![3, 7]);
        let (w, h) = (6, 4);
        let on = vec![true; w * h];
        let mut g = vec![1u8; w * h];
        g[7] = 2; // a one-texel speck
        for k in [3, 4, 5, 9, 10, 11, 15, 16, 17, 21, 22, 23] {
            g[k] = 3; // a 3 x 4 block stays
        }
        remove_small_regions(&mut g, &on, w, h, 4);
        assert_eq!(g[7], 1);
        assert_eq!(g.iter().filter(|&&m| m == 3).count(), 12);
    }
}
