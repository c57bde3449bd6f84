//! A scene seen obliquely from the south-west in ITU-class false colours (the glb's and
//! report.html's colours), ray cast orthographically with simple Lambert shading: the figure that
//! shows which material every wall, roof and window of the twin got.

use glam::DVec3;
use plotters::coord::Shift;
use plotters::prelude::*;
use rayon::prelude::*;

use super::{Background, Draw, FONT, plot_err, rgb};
use crate::artifact::Material;
use crate::artifact::Scene;
use crate::geom::raycast::SceneRays;
use crate::io::export::material_color;

const IMAGE: (u32, u32) = (1300, 940);
const TOP: u32 = 60;

/// The rendered scene and its legend.
pub struct MaterialRender {
    title: String,
    background: Background,
    legend: Vec<(String, [u8; 3])>,
}

fn colour(m: Material) -> [u8; 3] {
    material_color(m).map(|c| (c * 255.0).round() as u8)
}

impl MaterialRender {
    /// Renders `scene` looking north-east, `elevation_deg` above the horizon.
    pub fn new(title: String, scene: &Scene, elevation_deg: f64) -> MaterialRender {
        let rays = SceneRays::new(scene);
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for p in scene.objects.iter().flat_map(|o| o.mesh.positions.iter()) {
            let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let (w, h) = IMAGE;
        let mut rgb_px = vec![[255u8; 3]; (w * h) as usize];
        let mut used = [false; Material::ALL.len()];
        if lo.x <= hi.x {
            let el = elevation_deg.to_radians();
            let az = 45f64.to_radians();
            let dir = DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin());
            let right = dir.cross(DVec3::Z).normalize();
            let up = right.cross(dir);
            let centre = (lo + hi) / 2.0;
            let corners = (0..8).map(|k| {
                DVec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                ) - centre
            });
            let (mut ur, mut vr) = (0.0f64, 0.0f64);
            for c in corners {
                ur = ur.max(c.dot(right).abs());
                vr = vr.max(c.dot(up).abs());
            }
            let scale = (ur * 2.0 / w as f64).max(vr * 2.0 / h as f64) * 1.04;
            let back = (hi - lo).length() + 10.0;
            let light = DVec3::new(-0.4, -0.6, 0.7).normalize();
            let hits: Vec<Option<([u8; 3], usize)>> = (0..w * h)
                .into_par_iter()
                .map(|i| {
                    let (px, py) = (
                        (i % w) as f64 + 0.5 - w as f64 / 2.0,
                        h as f64 / 2.0 - (i / w) as f64 - 0.5,
                    );
                    let o = centre + right * px * scale + up * py * scale - dir * back;
                    let hit = rays.cast(
                        o.as_vec3().to_array(),
                        dir.as_vec3().to_array(),
                        0.0,
                        (back * 2.0) as f32,
                    )?;
                    let obj = &scene.objects[hit.object].mesh;
                    let m = obj
                        .materials
                        .get(hit.triangle)
                        .and_then(|&m| Material::from_u8(m))
                        .unwrap_or(Material::Concrete);
                    let n = DVec3::new(
                        hit.normal[0] as f64,
                        hit.normal[1] as f64,
                        hit.normal[2] as f64,
                    );
                    let shade = 0.45 + 0.55 * n.dot(light).abs();
                    let c = colour(m).map(|c| (c as f64 * shade).round().min(255.0) as u8);
                    Some((c, m as usize))
                })
                .collect();
            for (px, hit) in rgb_px.iter_mut().zip(&hits) {
                if let Some((c, m)) = hit {
                    *px = *c;
                    used[*m] = true;
                }
            }
        }
        let legend = Material::ALL
            .iter()
            .filter(|m| used[**m as usize])
            .map(|&m| {
                let name = m
                    .itu_type()
                    .map(str::to_string)
                    .unwrap_or_else(|| "foliage".into());
                (name.replace('_', " "), colour(m))
            })
            .collect();
        MaterialRender {
            title,
            background: Background {
                at: (0, TOP),
                width: w,
                height: h,
                rgb: rgb_px,
            },
            legend,
        }
    }
}

impl Draw for MaterialRender {
    fn background(&self) -> Option<&Background> {
        Some(&self.background)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        root.draw(&Text::new(self.title.clone(), (30, 16), (FONT, 32)))
            .map_err(plot_err)?;
        let x = IMAGE.0 as i32 + 30;
        let mut y = TOP as i32 + 20;
        root.draw(&Text::new("ITU-R P.2040 class", (x, y), (FONT, 24)))
            .map_err(plot_err)?;
        y += 44;
        for (name, c) in &self.legend {
            root.draw(&Rectangle::new(
                [(x, y), (x + 30, y + 22)],
                rgb(*c).filled(),
            ))
            .map_err(plot_err)?;
            root.draw(&Text::new(name.clone(), (x + 42, y), (FONT, 22)))
                .map_err(plot_err)?;
            y += 34;
        }
        Ok(())
    }
}
