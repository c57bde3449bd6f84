//! Camera models and resampling: provider images as pinhole views. A view straight from an image,
//! a fisheye (OpenSfM's model) resampled to a pinhole of the same focal length, level pinhole
//! views cut from an equirectangular panorama, and the EXIF orientations that turn a stored image
//! upright.

use glam::{DMat3, DVec3};
use image::RgbImage;
use rayon::prelude::*;

use super::provider::{MAX_VIEW_SIDE, PanoramaCut};
use super::rotation::{heading_deg, mat_vec};
use crate::artifact::{Intrinsics, PodVec, Pose, View};

/// A view with an image and no model outputs.
pub fn plain_view(
    id: String,
    img: RgbImage,
    f: f64,
    pose: Pose,
    captured_at: Option<String>,
) -> View {
    let (width, height) = img.dimensions();
    View {
        id,
        width,
        height,
        intrinsics: Intrinsics {
            fx: f,
            fy: f,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
        },
        pose,
        captured_at,
        pose_source: None,
        distortion: None,
        image: PodVec(img.pixels().map(|p| p.0).collect()),
        arch: None,
        clutter: None,
        material: None,
        depth: None,
        normal: None,
    }
}

/// An image of `w` x `h` whose pixel centre (u + 0.5, v + 0.5) takes `src` at `map(u + 0.5,
/// v + 0.5)` (continuous pixel coordinates, bilinear); outside `src` is black, unless `wrap`
/// (columns wrap around, rows clamp).
fn resample(
    src: &RgbImage,
    (w, h): (u32, u32),
    wrap: bool,
    map: impl Fn(f64, f64) -> Option<[f64; 2]> + Sync,
) -> RgbImage {
    let (sw, sh) = (src.width() as i64, src.height() as i64);
    let px = |x: i64, y: i64| -> [f64; 3] {
        let x = if wrap {
            x.rem_euclid(sw)
        } else {
            x.clamp(0, sw - 1)
        };
        let y = y.clamp(0, sh - 1);
        src.get_pixel(x as u32, y as u32).0.map(f64::from)
    };
    let rows: Vec<Vec<u8>> = (0..h)
        .into_par_iter()
        .map(|v| {
            let mut row = Vec::with_capacity(w as usize * 3);
            for u in 0..w {
                let rgb = map(u as f64 + 0.5, v as f64 + 0.5)
                    .filter(|[x, y]| {
                        wrap || (*x >= 0.0 && *y >= 0.0 && *x <= sw as f64 && *y <= sh as f64)
                    })
                    .map(|[x, y]| {
                        let (fx, fy) = (x - 0.5, y - 0.5);
                        let (x0, y0) = (fx.floor() as i64, fy.floor() as i64);
                        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
                        let (a, b) = (px(x0, y0), px(x0 + 1, y0));
                        let (c, d) = (px(x0, y0 + 1), px(x0 + 1, y0 + 1));
                        std::array::from_fn::<f64, 3, _>(|k| {
                            (a[k] * (1.0 - tx) + b[k] * tx) * (1.0 - ty)
                                + (c[k] * (1.0 - tx) + d[k] * tx) * ty
                        })
                    })
                    .unwrap_or([0.0; 3]);
                row.extend(rgb.map(|c| (c + 0.5).floor().clamp(0.0, 255.0) as u8));
            }
            row
        })
        .collect();
    RgbImage::from_raw(w, h, rows.concat()).unwrap_or_default()
}

/// A fisheye image (OpenSfM's model, focal `f` pixels, [k1, k2]) as a pinhole image of the same
/// size and focal length.
pub fn undistort_fisheye(src: &RgbImage, f: f64, k: [f64; 2]) -> RgbImage {
    let (cx, cy) = (src.width() as f64 / 2.0, src.height() as f64 / 2.0);
    resample(src, src.dimensions(), false, |u, v| {
        let (x, y) = ((u - cx) / f, (v - cy) / f);
        let l = x.hypot(y);
        if l < 1e-12 {
            return Some([cx, cy]);
        }
        let t = l.atan();
        let td = t * (1.0 + k[0] * t * t + k[1] * t.powi(4));
        Some([cx + f * td * x / l, cy + f * td * y / l])
    })
}

/// Level pinhole views cut from an equirectangular panorama whose camera-to-site rotation is
/// `c2s`: `cut.views` of them, evenly in heading from the panorama's forward heading, ids
/// `<id>-<k>`.
pub fn cut_panorama(
    pano: &RgbImage,
    id: &str,
    position: [f64; 3],
    c2s: &DMat3,
    cut: &PanoramaCut,
    captured_at: &Option<String>,
) -> Vec<View> {
    let (w, h) = pano.dimensions();
    let scale = w.max(h) as f64 / std::f64::consts::TAU;
    let tan = (cut.hfov_deg.to_radians() / 2.0).tan();
    let side = cut.size_px.unwrap_or_else(|| {
        (2.0 * scale * tan)
            .round()
            .clamp(16.0, MAX_VIEW_SIDE as f64) as u32
    });
    let f = side as f64 / 2.0 / tan;
    let heading0 = heading_deg(c2s).unwrap_or(0.0);
    let s2c = c2s.transpose();
    (0..cut.views)
        .map(|k| {
            let heading = heading0 + k as f64 * 360.0 / cut.views as f64;
            let pose = Pose::from_angles(position, heading.rem_euclid(360.0), 0.0, 0.0);
            let c = side as f64 / 2.0;
            let img = resample(pano, (side, side), true, |u, v| {
                let site = pose.to_site([(u - c) / f, (v - c) / f, 1.0]);
                let [x, y, z] = mat_vec(&s2c, site);
                let lon = x.atan2(z);
                let lat = (-y).atan2(x.hypot(z));
                Some([w as f64 / 2.0 + lon * scale, h as f64 / 2.0 - lat * scale])
            });
            plain_view(format!("{id}-{k}"), img, f, pose, captured_at.clone())
        })
        .collect()
}

/// The camera axes of the upright image in the stored image's camera frame (columns), for EXIF
/// orientations 1, 3, 6 and 8.
pub fn exif_axes(orientation: u8) -> DMat3 {
    match orientation {
        3 => DMat3::from_cols(DVec3::NEG_X, DVec3::NEG_Y, DVec3::Z),
        6 => DMat3::from_cols(DVec3::NEG_Y, DVec3::X, DVec3::Z),
        8 => DMat3::from_cols(DVec3::Y, DVec3::NEG_X, DVec3::Z),
        _ => DMat3::IDENTITY,
    }
}

/// The stored image turned upright for an EXIF orientation.
pub fn upright(img: RgbImage, orientation: u8) -> RgbImage {
    match orientation {
        3 => image::imageops::rotate180(&img),
        6 => image::imageops::rotate90(&img),
        8 => image::imageops::rotate270(&img),
        _ => img,
    }
}
