//! Canopy envelopes from the unassigned above-ground field (paper Sec. 4.2.4): connected regions
//! that are large, elevated and irregular (height roughness, or the share of multiple LiDAR
//! returns) become closed foliage volumes. The crown's upper surface is the field itself (its
//! local maximum, which reads through the gaps a few pulses find); its lower surface mirrors it
//! about the crown's widest level. With the LiDAR returns, that level is read from them (pulses
//! that go through a crown echo along their path in it, so each column's chord between the upper
//! surface and its lowest return is centred on it) and the mirror is averaged with the lowest
//! return; without, the level is read where the crown outline is (an ellipsoidal crown is widest
//! at its centre height, so the field on the outline is that height). With returns, crowns also
//! grow into the fringe the field leaves out beside buildings, through cells with vegetation
//! returns.
//! The envelope is a stack of prisms: per height slice, the outline of the cells the crown covers
//! there, simplified. Foliage volumes are `Material::Foliage` solids of class `Vegetation`: what
//! the tracer attenuates through (rf/foliage.rs).

use std::collections::BTreeMap;

use crate::artifact::Material;
use crate::artifact::{Grid, Metrics, ObjectClass, PodVec, PointSet, Raster, Scene, SceneObject};
use crate::geom::mesh_build::prism;
use crate::geom::mesh_check::check_solid;
use crate::geom::polygon::{simplify_polygon, trace};
use crate::raster::label::label_components;
use crate::raster::morph::close_within;

/// Knobs of the canopy extraction.
#[derive(Clone, Debug)]
pub struct CanopyConfig {
    /// Cells lower than this above ground are not canopy, metres.
    pub min_height_m: f64,
    /// Regions smaller than this are not canopy, m².
    pub min_area_m2: f64,
    /// Regions whose highest cell is lower than this are not canopy, metres.
    pub min_top_m: f64,
    /// Standard deviation of the heights in a region at or above which it is irregular, metres.
    pub min_roughness_m: f64,
    /// Share of multiple-return points at or above which a region is irregular (with points).
    pub min_multi_share: f64,
    /// Height slices of each envelope.
    pub slices: u32,
    /// Douglas-Peucker tolerance of the slice outlines, metres.
    pub simplify_m: f64,
    /// The lowest the crown's bottom may come, above ground, metres.
    pub min_clearance_m: f64,
    /// Quantile of the field on the outline taken as the crown's widest level (without points).
    pub edge_quantile: f64,
    /// Radius of the morphological closing of each crown's cells, in cells.
    pub close_cells: u32,
    /// How far, in cells, a crown grows into the cells the field leaves out beside it, through
    /// cells with vegetation returns (with points only).
    pub fringe_cells: u32,
}

impl Default for CanopyConfig {
    fn default() -> Self {
        CanopyConfig {
            min_height_m: 1.5,
            min_area_m2: 8.0,
            min_top_m: 4.0,
            min_roughness_m: 0.3,
            min_multi_share: 0.2,
            slices: 8,
            simplify_m: 0.3,
            min_clearance_m: 1.0,
            edge_quantile: 0.4,
            close_cells: 1,
            fringe_cells: 2,
        }
    }
}

/// One canopy: its cells' envelope and the checked closed solids of its slices.
#[derive(Clone, Debug)]
pub struct Canopy {
    /// Region label.
    pub label: u32,
    /// Area, m².
    pub area_m2: f64,
    /// Crown top and the mirror level, above ground, metres.
    pub top_m: f64,
    /// The widest level, above ground.
    pub mid_m: f64,
    /// One closed solid per slice polygon.
    pub shells: Vec<crate::artifact::Mesh>,
}

/// Canopies of `unassigned` (above-ground heights of cells no building claims, NaN elsewhere) on
/// `terrain`, with `points` for the multiple-return share when given. Returns the scene of
/// foliage volumes (`canopy-<n>`) and counts.
pub fn canopies(
    unassigned: &Raster,
    terrain: &Raster,
    points: Option<&PointSet>,
    cfg: &CanopyConfig,
) -> (Scene, Metrics) {
    let grown = points.map(|ps| grow_into_fringe(unassigned, terrain, ps, cfg));
    let unassigned = grown.as_ref().map_or(unassigned, |(r, _)| r);
    let g = unassigned.grid;
    let (w, h) = (g.width as usize, g.height as usize);
    let mask: Vec<bool> = unassigned
        .data
        .iter()
        .map(|&v| v.is_finite() && v as f64 >= cfg.min_height_m)
        .collect();
    let labels = label_components(&mask, g.width, g.height, 1);
    let mut cells: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (i, &l) in labels.iter().enumerate() {
        if l > 0 {
            cells.entry(l).or_default().push(i);
        }
    }
    // Multiple-return share per region.
    let mut multi: BTreeMap<u32, (usize, usize)> = BTreeMap::new();
    if let Some(ps) = points {
        for (k, p) in ps.xyz.iter().enumerate() {
            let Some((c, r)) = g.cell_of(p[0] as f64, p[1] as f64) else {
                continue;
            };
            let l = labels[r as usize * w + c as usize];
            if l == 0 {
                continue;
            }
            let e = multi.entry(l).or_default();
            e.0 += 1;
            if ps.number_of_returns.get(k).is_some_and(|&n| n > 1) {
                e.1 += 1;
            }
        }
    }
    let returns = points.zip(grown.as_ref()).map(|(ps, (_, fringe))| {
        LowestReturns::new(ps, &labels, g, terrain, cfg.min_height_m, fringe.clone())
    });
    let mut m = Metrics::default();
    let mut bump = |name: &str| {
        let v = m.get(name).unwrap_or(0.0);
        m.set(name, v + 1.0);
    };
    let cell_area = g.cell_m * g.cell_m;
    let mut objects = Vec::new();
    for (&l, idx) in &cells {
        bump("regions");
        let area = idx.len() as f64 * cell_area;
        let hs: Vec<f64> = idx.iter().map(|&i| unassigned.data[i] as f64).collect();
        let top = hs.iter().copied().fold(f64::MIN, f64::max);
        if area < cfg.min_area_m2 {
            bump("rejected_small");
            continue;
        }
        if top < cfg.min_top_m {
            bump("rejected_low");
            continue;
        }
        let mean = hs.iter().sum::<f64>() / hs.len() as f64;
        let sd = (hs.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / hs.len() as f64).sqrt();
        let share = multi
            .get(&l)
            .filter(|e| e.0 >= 10)
            .map(|e| e.1 as f64 / e.0 as f64);
        let irregular =
            sd >= cfg.min_roughness_m || share.is_some_and(|s| s >= cfg.min_multi_share);
        if !irregular {
            bump("rejected_regular");
            continue;
        }
        let mut failed = 0;
        let env = envelope(
            &mut failed,
            l,
            idx,
            &labels,
            unassigned,
            terrain,
            returns.as_ref(),
            cfg,
        );
        for _ in 0..failed {
            bump("slice_outlines_dropped");
        }
        match env {
            Some(c) if !c.shells.is_empty() => {
                bump("canopies");
                let mut mesh = crate::artifact::Mesh::default();
                for s in &c.shells {
                    mesh.append(s);
                }
                objects.push(SceneObject {
                    id: format!("canopy-{}", objects.len()),
                    class: ObjectClass::Vegetation,
                    mesh,
                });
            }
            _ => bump("rejected_no_envelope"),
        }
    }
    let _ = h;
    (Scene { objects }, m)
}

/// The envelope of region `l` (its cells `idx`): the ground under it, the window it stands in, its
/// top and widest level, its upper and lower surfaces per column, then the slices between.
fn envelope(
    failed: &mut usize,
    l: u32,
    idx: &[usize],
    labels: &[u32],
    a: &Raster,
    terrain: &Raster,
    returns: Option<&LowestReturns>,
    cfg: &CanopyConfig,
) -> Option<Canopy> {
    let g = a.grid;
    let gz = ground_under(idx, g, terrain)?;
    let window = CrownWindow::around(l, idx, labels, g);
    let outside = window.outside();
    let (top, outline_mid) = top_and_outline_level(l, idx, labels, a, cfg)?;
    let upper = window.upper_surface(&outside, a, top, cfg.close_cells);
    let lowest = window.lowest_returns(returns);
    let mid = widest_level(&upper, &lowest, outline_mid);
    let columns = CrownColumns {
        window: &window,
        upper,
        lowest,
        mid,
        returns,
        min_clearance_m: cfg.min_clearance_m,
    };
    let bottom = columns.bottom();
    if bottom >= top {
        return None;
    }
    let shells = columns.slice_shells(failed, gz, bottom, top, cfg);
    Some(Canopy {
        label: l,
        area_m2: idx.len() as f64 * g.cell_m * g.cell_m,
        top_m: top,
        mid_m: mid,
        shells,
    })
}

/// Ground under the crown: the median terrain height over its cells. A step of its own because
/// every height of the envelope is above ground and the slices stand on this one level.
fn ground_under(idx: &[usize], g: Grid, terrain: &Raster) -> Option<f64> {
    let w = g.width as usize;
    let mut ground: Vec<f64> = idx
        .iter()
        .filter_map(|&i| {
            let (x, y) = g.center((i % w) as u32, (i / w) as u32);
            terrain.bilinear(x, y)
        })
        .collect();
    crate::geom::theil_sen::median(&mut ground)
}

/// The crown's top and the field's level on its outline, or None when the crown is too flat
/// (half-height not above 0.25 m) to hold an envelope. A step of its own: both are read from the
/// region's cells on the whole field, before any window or surface is built.
///
/// The top is the 98.5th percentile of the field (returns inside the crown make it rough below
/// the top; a pole or sign standing in the crown pokes above it). The outline level stands for
/// the widest level where no returns read it: a lower quantile (`edge_quantile`) of the field on
/// the outline (an outline cell's highest return comes from the part of the crown inside it,
/// above the widest level).
fn top_and_outline_level(
    l: u32,
    idx: &[usize],
    labels: &[u32],
    a: &Raster,
    cfg: &CanopyConfig,
) -> Option<(f64, f64)> {
    let g = a.grid;
    let (w, h) = (g.width as usize, g.height as usize);
    let mut hs: Vec<f64> = idx.iter().map(|&i| a.data[i] as f64).collect();
    hs.sort_by(f64::total_cmp);
    let top = hs[((hs.len() - 1) as f64 * 0.985).round() as usize];
    let mut edge: Vec<f64> = idx
        .iter()
        .filter(|&&i| {
            let (c, r) = (i % w, i / w);
            c == 0
                || r == 0
                || c + 1 == w
                || r + 1 == h
                || labels[i - 1] != l
                || labels[i + 1] != l
                || labels[i - w] != l
                || labels[i + w] != l
        })
        .map(|&i| a.data[i] as f64)
        .collect();
    if edge.is_empty() {
        return None;
    }
    edge.sort_by(f64::total_cmp);
    let mid = edge[((edge.len() - 1) as f64 * cfg.edge_quantile).round() as usize];
    let half = top - mid;
    if !(half > 0.25) {
        return None;
    }
    Some((top, mid))
}

/// With returns, the widest level is read from them: the median over the crown of each
/// well-sampled column's midpoint between its upper surface and its lowest return (a crown
/// symmetric about its widest level has every vertical chord centred on it). Without, the field
/// on the outline (`outline_mid`) stands for it. A step of its own: the lower surface mirrors the
/// upper about this one level.
fn widest_level(upper: &[f64], lowest: &[(f64, u32)], outline_mid: f64) -> f64 {
    let mut midpoints: Vec<f64> = (0..upper.len())
        .filter(|&j| upper[j].is_finite() && lowest[j].1 >= MIN_MIDPOINT_RETURNS)
        .map(|j| (upper[j] + lowest[j].0) / 2.0)
        .collect();
    crate::geom::theil_sen::median(&mut midpoints).unwrap_or(outline_mid)
}

/// A crown's bounding box on the field's grid, one cell of margin: the window every per-column
/// step of [`envelope`] works in, its cells `j` numbered row by row.
struct CrownWindow<'a> {
    /// The crown's region label.
    l: u32,
    /// Region labels of the whole field.
    labels: &'a [u32],
    /// The field's width, cells.
    w: usize,
    /// The window's first column and row on the field.
    c0: usize,
    r0: usize,
    /// The window as a grid, and its width and height in cells.
    sub: Grid,
    sw: usize,
    sh: usize,
}

impl<'a> CrownWindow<'a> {
    /// The bounding box of region `l` (its cells `idx`) on `g`, one cell of margin, clipped to
    /// the field.
    fn around(l: u32, idx: &[usize], labels: &'a [u32], g: Grid) -> CrownWindow<'a> {
        let w = g.width as usize;
        let h = g.height as usize;
        let (mut c0, mut r0, mut c1, mut r1) = (usize::MAX, usize::MAX, 0, 0);
        for &i in idx {
            let (c, r) = (i % w, i / w);
            (c0, r0, c1, r1) = (c0.min(c), r0.min(r), c1.max(c), r1.max(r));
        }
        let (c0, r0) = (c0.saturating_sub(1), r0.saturating_sub(1));
        let (c1, r1) = ((c1 + 1).min(w - 1), (r1 + 1).min(h - 1));
        let sub = Grid {
            x0: g.x0 + c0 as f64 * g.cell_m,
            y0: g.y0 - r0 as f64 * g.cell_m,
            cell_m: g.cell_m,
            width: (c1 - c0 + 1) as u32,
            height: (r1 - r0 + 1) as u32,
        };
        let (sw, sh) = (sub.width as usize, sub.height as usize);
        CrownWindow {
            l,
            labels,
            w,
            c0,
            r0,
            sub,
            sw,
            sh,
        }
    }

    /// Cells in the window.
    fn len(&self) -> usize {
        self.sw * self.sh
    }

    /// The field's cell index of window cell `j`.
    fn cell(&self, j: usize) -> usize {
        (self.r0 + j / self.sw) * self.w + self.c0 + j % self.sw
    }

    /// Window cell `j` and its eight neighbours inside the window.
    fn neighbourhood(&self, j: usize) -> impl Iterator<Item = usize> {
        let (sw, sh) = (self.sw, self.sh);
        let (c, r) = (j % sw, j / sw);
        (r.saturating_sub(1)..(r + 2).min(sh))
            .flat_map(move |rr| (c.saturating_sub(1)..(c + 2).min(sw)).map(move |cc| rr * sw + cc))
    }

    /// Outside: the cells of other labels reachable from the box's border; the gaps inside the
    /// crown (returns that reached the ground) are crown. A step of its own: a flood fill, and
    /// what it leaves is the crown's footprint in the window.
    fn outside(&self) -> Vec<bool> {
        let (sw, sh) = (self.sw, self.sh);
        let other: Vec<bool> = (0..sw * sh)
            .map(|j| self.labels[self.cell(j)] != self.l)
            .collect();
        let mut outside = vec![false; sw * sh];
        let mut stack: Vec<usize> = (0..sw * sh)
            .filter(|&j| {
                let (c, r) = (j % sw, j / sw);
                other[j] && (c == 0 || r == 0 || c + 1 == sw || r + 1 == sh)
            })
            .collect();
        for &j in &stack {
            outside[j] = true;
        }
        while let Some(j) = stack.pop() {
            let (c, r) = (j % sw, j / sw);
            let mut visit = |k: usize| {
                if other[k] && !outside[k] {
                    outside[k] = true;
                    stack.push(k);
                }
            };
            if c > 0 {
                visit(j - 1);
            }
            if c + 1 < sw {
                visit(j + 1);
            }
            if r > 0 {
                visit(j - sw);
            }
            if r + 1 < sh {
                visit(j + sw);
            }
        }
        outside
    }

    /// The crown's upper surface per window cell (NaN outside the crown), capped at `top`: the
    /// highest return in the cell and its eight neighbours of the region. One cell alone is too
    /// rough (a cell whose few pulses went through a gap reads low); the 3 x 3 maximum reads the
    /// surface, and fills the crown's gaps, at the cost of a quarter-cell of width at the rim (a
    /// closing, max then min, lost a fifth of the volume). The crown's cells are closed by
    /// `close_cells` first: rim cells whose few pulses all missed the crown's edge leave notches
    /// in the outline.
    fn upper_surface(&self, outside: &[bool], a: &Raster, top: f64, close_cells: u32) -> Vec<f64> {
        let value = |j: usize| {
            let i = self.cell(j);
            (self.labels[i] == self.l).then(|| a.data[i] as f64)
        };
        let crown: Vec<bool> = outside.iter().map(|&o| !o).collect();
        let crown = close_within(&crown, self.sw as u32, self.sh as u32, close_cells as i64);
        (0..self.len())
            .map(|j| {
                if !crown[j] {
                    return f64::NAN;
                }
                let best = self
                    .neighbourhood(j)
                    .filter_map(value)
                    .fold(f64::NAN, f64::max);
                best.min(top)
            })
            .collect()
    }

    /// The lowest vegetation return over each window cell and its eight neighbours of the region,
    /// and how many returns there are (NaN and 0 without returns): pulses that go through the
    /// crown echo all along their path in it.
    fn lowest_returns(&self, returns: Option<&LowestReturns>) -> Vec<(f64, u32)> {
        (0..self.len())
            .map(|j| {
                let Some(lr) = returns else {
                    return (f64::NAN, 0);
                };
                self.neighbourhood(j)
                    .map(|k| self.cell(k))
                    .filter(|&i| self.labels[i] == self.l)
                    .fold((f64::NAN, 0), |(z, n), i| {
                        (z.min(lr.lowest[i] as f64), n + lr.count[i])
                    })
            })
            .collect()
    }
}

/// A crown's columns in its window: the upper surface, the lowest returns and the widest level
/// that together give each column's span, from which the slices are cut.
struct CrownColumns<'a> {
    window: &'a CrownWindow<'a>,
    /// Upper surface per window cell, above ground (NaN outside the crown).
    upper: Vec<f64>,
    /// Lowest return and return count per window cell.
    lowest: Vec<(f64, u32)>,
    /// The widest level, above ground.
    mid: f64,
    returns: Option<&'a LowestReturns>,
    /// The lowest the crown's bottom may come, above ground.
    min_clearance_m: f64,
}

impl CrownColumns<'_> {
    /// A cell the crown grew into from the fringe may lie over a building's roof: there the crown
    /// stops at the cell's own lowest return, above the roof.
    fn floor(&self, j: usize) -> f64 {
        let i = self.window.cell(j);
        self.returns
            .filter(|lr| lr.fringe[i])
            .map_or(f64::NEG_INFINITY, |lr| lr.lowest[i] as f64)
    }

    /// The column's crown from bottom to top, or None where it holds none. The lower surface
    /// mirrors the upper about the widest level; where returns reached below the top, it is the
    /// mean of that mirror and the lowest return (the lowest of a handful of echoes stops short
    /// of the crown's bottom, the mirror is off where the crown is not symmetric). A cell whose
    /// upper surface is not above the widest level and that has no return below it holds no
    /// crown.
    fn span(&self, j: usize) -> Option<(f64, f64)> {
        let t = self.upper[j];
        let mirror = 2.0 * self.mid - t;
        let (lo, _) = self.lowest[j];
        let b = if lo < t { (lo + mirror) / 2.0 } else { mirror };
        (t > self.mid || lo < t).then(|| (b.max(self.floor(j)).max(self.min_clearance_m), t))
    }

    /// The crown's bottom: the lowest of its columns' spans.
    fn bottom(&self) -> f64 {
        (0..self.window.len())
            .filter_map(|j| self.span(j))
            .map(|(b, _)| b)
            .fold(f64::MAX, f64::min)
    }

    /// The cells whose span holds height `zm`, pinches filled, as a 0/1 raster on the window; None
    /// when no column reaches it. A step of its own: what one slice's outlines are traced from.
    fn slice_cells(&self, zm: f64) -> Option<Raster> {
        let sub = self.window.sub;
        let mut data = vec![0f32; sub.len()];
        let mut any = false;
        for (j, cell) in data.iter_mut().enumerate() {
            if self.span(j).is_some_and(|(b, t)| b <= zm && zm <= t) {
                *cell = 1.0;
                any = true;
            }
        }
        if !any {
            return None;
        }
        fill_pinches(&mut data, sub.width as usize, sub.height as usize);
        Some(Raster {
            grid: sub,
            data: PodVec(data),
        })
    }

    /// The envelope as `cfg.slices` prisms from `bottom` to `top` (above the ground `gz`), one
    /// closed, checked shell per slice outline, simplified where the simplified outline still
    /// makes one; counts in `failed` the outlines that make none.
    fn slice_shells(
        &self,
        failed: &mut usize,
        gz: f64,
        bottom: f64,
        top: f64,
        cfg: &CanopyConfig,
    ) -> Vec<crate::artifact::Mesh> {
        let n = cfg.slices.max(1);
        let dz = (top - bottom) / n as f64;
        let mut shells = Vec::new();
        for k in 0..n {
            let (z0, z1) = (bottom + k as f64 * dz, bottom + (k + 1) as f64 * dz);
            let zm = (z0 + z1) / 2.0;
            let Some(lab) = self.slice_cells(zm) else {
                continue;
            };
            let polys = trace(&lab).remove(&1).unwrap_or_default();
            // Slices stop 1 cm short of each other so no two shells share a face.
            let (za, zb) = (gz + z0 + 0.005, gz + z1 - 0.005);
            for p in polys {
                let simplified = simplify_polygon(p.clone(), cfg.simplify_m);
                let shell = [simplified, p].into_iter().find_map(|q| {
                    prism(&q, za, zb, Material::Foliage, Material::Foliage)
                        .ok()
                        .filter(|m| check_solid(m).is_ok())
                });
                match shell {
                    Some(s) => shells.push(s),
                    None => *failed += 1,
                }
            }
        }
        shells
    }
}

/// Returns a column needs, over its 3 x 3 cells, for its midpoint to count toward the widest
/// level: a handful of echoes spread along the chord.
const MIN_MIDPOINT_RETURNS: u32 = 6;

/// Per cell of the field's grid, the lowest vegetation return above ground and how many there are.
struct LowestReturns {
    /// Height above the terrain of the lowest return, metres; NaN where none.
    lowest: Vec<f32>,
    /// Number of returns.
    count: Vec<u32>,
    /// Cells the crowns grew into from the field's fringe ([`grow_into_fringe`]).
    fringe: Vec<bool>,
}

impl LowestReturns {
    /// The vegetation returns (ASPRS 3-5 where the points are classified so, else any but ground,
    /// building, noise and water) in labelled cells of `g`, at least `min_height_m` above
    /// `terrain`.
    fn new(
        ps: &PointSet,
        labels: &[u32],
        g: Grid,
        terrain: &Raster,
        min_height_m: f64,
        fringe: Vec<bool>,
    ) -> LowestReturns {
        let mut lowest = vec![f32::NAN; g.len()];
        let mut count = vec![0u32; g.len()];
        for (i, z) in vegetation_heights(ps, g, terrain, min_height_m) {
            if labels[i] != 0 {
                lowest[i] = lowest[i].min(z);
                count[i] += 1;
            }
        }
        LowestReturns {
            lowest,
            count,
            fringe,
        }
    }
}

/// The vegetation returns (ASPRS 3-5 where the points are classified so, else any but ground,
/// building, noise and water) over `g`, as (cell index, height above `terrain`), at least
/// `min_height_m` high.
fn vegetation_heights<'a>(
    ps: &'a PointSet,
    g: Grid,
    terrain: &'a Raster,
    min_height_m: f64,
) -> impl Iterator<Item = (usize, f32)> + 'a {
    let classified = ps.class.iter().any(|c| (3..=5).contains(c));
    ps.xyz.iter().enumerate().filter_map(move |(k, p)| {
        let class = ps.class.get(k).copied().unwrap_or(0);
        let vegetation = if classified {
            (3..=5).contains(&class)
        } else {
            !matches!(class, 2 | 6 | 7 | 9 | 18)
        };
        let (x, y) = (p[0] as f64, p[1] as f64);
        let (c, r) = g.cell_of(x, y).filter(|_| vegetation)?;
        let z = p[2] as f64 - terrain.bilinear(x, y)?;
        (z >= min_height_m).then_some((r as usize * g.width as usize + c as usize, z as f32))
    })
}

/// `unassigned` with the crowns grown into the cells it leaves out beside them (the fringe
/// UnassignedAbove keeps from buildings, where a wall's returns would pass for a crown's): up to
/// `fringe_cells` steps from a canopy-high cell, through cells whose vegetation returns stand at
/// least `min_height_m` above the terrain, each taking the height of its highest such return.
/// Only vegetation-classified returns qualify where the points are classified, so a wall's
/// returns never do. Returns the grown field and which cells grew.
fn grow_into_fringe(
    unassigned: &Raster,
    terrain: &Raster,
    ps: &PointSet,
    cfg: &CanopyConfig,
) -> (Raster, Vec<bool>) {
    let g = unassigned.grid;
    let (w, h) = (g.width as usize, g.height as usize);
    let mut top = vec![f32::NAN; g.len()];
    for (i, z) in vegetation_heights(ps, g, terrain, cfg.min_height_m) {
        if !unassigned.data[i].is_finite() {
            top[i] = top[i].max(z);
        }
    }
    let mut out = unassigned.clone();
    let mut fringe = vec![false; g.len()];
    let high = |v: f32| v.is_finite() && v as f64 >= cfg.min_height_m;
    for _ in 0..cfg.fringe_cells {
        let next: Vec<usize> = (0..g.len())
            .filter(|&i| !out.data[i].is_finite() && top[i].is_finite())
            .filter(|&i| {
                let (c, r) = (i % w, i / w);
                (c > 0 && high(out.data[i - 1]))
                    || (c + 1 < w && high(out.data[i + 1]))
                    || (r > 0 && high(out.data[i - w]))
                    || (r + 1 < h && high(out.data[i + w]))
            })
            .collect();
        if next.is_empty() {
            break;
        }
        for i in next {
            out.data[i] = top[i];
            fringe[i] = true;
        }
    }
    (out, fringe)
}

/// Fills one cell of every 2 x 2 block whose set cells touch only diagonally, so traced outlines
/// never pinch at a vertex.
fn fill_pinches(data: &mut [f32], w: usize, h: usize) {
    for r in 0..h.saturating_sub(1) {
        for c in 0..w.saturating_sub(1) {
            let at = |data: &[f32], rr: usize, cc: usize| data[rr * w + cc] > 0.0;
            let (a, b, d, e) = (
                at(data, r, c),
                at(data, r, c + 1),
                at(data, r + 1, c),
                at(data, r + 1, c + 1),
            );
            if a && e && !b && !d {
                data[r * w + c + 1] = 1.0;
            } else if b && d && !a && !e {
                data[r * w + c] = 1.0;
            }
        }
    }
}
