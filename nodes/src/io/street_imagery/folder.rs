//! Provider download folders: the files under one (to a depth of 8), the record files among them,
//! their images by id, and decoding an image within bounds.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use image::RgbImage;

use crate::stage::StageError;

/// The largest image side read, pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;
/// How deep folders are searched for entities and images.
const MAX_DEPTH: usize = 8;

/// Every file under `dir`, to a depth of 8, in sorted path order; links to folders are not
/// followed.
pub fn files_under(dir: &Path) -> Result<Vec<PathBuf>, StageError> {
    fn walk(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> Result<(), StageError> {
        let entries = std::fs::read_dir(dir).map_err(|e| {
            StageError::bad_input(dir, "folder", format!("expected a readable folder: {e}"))
        })?;
        for entry in entries.flatten() {
            let p = entry.path();
            match entry.file_type() {
                Ok(t) if t.is_dir() && depth < MAX_DEPTH => walk(&p, depth + 1, out)?,
                Ok(t) if t.is_file() || (t.is_symlink() && p.is_file()) => out.push(p),
                _ => {}
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, 0, &mut out)?;
    out.sort();
    Ok(out)
}

/// The texts of the files under `folder` whose extension is one of `exts`, in path order, and
/// the images there.
pub fn scan_folder(
    folder: &Path,
    exts: &[&str],
) -> Result<(Vec<(PathBuf, String)>, ImageIndex), StageError> {
    let files = files_under(folder)?;
    let texts = files
        .iter()
        .filter(|f| exts.contains(&extension(f).as_str()))
        .map(|f| {
            crate::io::open::read_regular_to_string(f)
                .map(|t| (f.clone(), t))
                .map_err(|e| StageError::bad_input(f, "open", e.to_string()))
        })
        .collect::<Result<_, _>>()?;
    Ok((texts, ImageIndex::new(&files)))
}

/// The lower-case extension of a path.
pub fn extension(p: &Path) -> String {
    p.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// The images (jpg, jpeg, png, webp) under a folder, by file stem.
pub struct ImageIndex(BTreeMap<String, Vec<PathBuf>>);

impl ImageIndex {
    /// The images among `files` (sorted, so each stem's paths are too).
    pub fn new(files: &[PathBuf]) -> ImageIndex {
        let mut m: BTreeMap<String, Vec<PathBuf>> = BTreeMap::new();
        for f in files {
            if ["jpg", "jpeg", "png", "webp"].contains(&extension(f).as_str())
                && let Some(stem) = f.file_stem()
            {
                m.entry(stem.to_string_lossy().into_owned())
                    .or_default()
                    .push(f.clone());
            }
        }
        ImageIndex(m)
    }

    /// The image of `id`: in `near` if there is one there, else in a folder named `folder_name`,
    /// else the first in path order.
    pub fn find(&self, id: &str, near: Option<&Path>, folder_name: Option<&str>) -> Option<&Path> {
        let list = self.0.get(id)?;
        let in_dir = |d: &Path| list.iter().find(|p| p.parent() == Some(d));
        let named = |n: &str| {
            list.iter()
                .find(|p| p.parent().and_then(Path::file_name).is_some_and(|f| f == n))
        };
        near.and_then(in_dir)
            .or_else(|| folder_name.and_then(named))
            .or_else(|| list.first())
            .map(PathBuf::as_path)
    }
}

/// Decodes an image as RGB, refusing empty images and sides over [`MAX_IMAGE_SIDE`].
pub fn load_image(path: &Path) -> Result<RgbImage, StageError> {
    let bad = |e: String| {
        StageError::bad_input(
            path,
            "image",
            format!("expected a readable JPEG/PNG/WebP: {e}"),
        )
    };
    let mut reader = image::ImageReader::open(path)
        .map_err(|e| bad(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| bad(e.to_string()))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(2 << 30);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| bad(e.to_string()))?.into_rgb8();
    if img.width() == 0 || img.height() == 0 {
        return Err(bad("the image is empty".into()));
    }
    Ok(img)
}

/// True when (w, h) and (w2, h2) have the same aspect to within a pixel.
pub fn same_aspect((w, h): (u32, u32), (w2, h2): (u32, u32)) -> bool {
    let (w, h, w2, h2) = (w as f64, h as f64, w2 as f64, h2 as f64);
    (w * h2 - h * w2).abs() <= w.max(h).max(w2.max(h2))
}
