//! OpenEXR images of f32 channels (depth maps, normals), through the `exr` crate.

use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec,
    WritableImage,
};

use crate::stage::StageError;

/// Encodes `channels` (name, row-major samples) of a `width` x `height` image as an EXR file,
/// run-length compressed (fast; small where the image is flat).
pub fn write_exr(
    width: usize,
    height: usize,
    channels: Vec<(&str, Vec<f32>)>,
) -> Result<Vec<u8>, String> {
    encode_exr(width, height, channels, Encoding::FAST_LOSSLESS)
}

/// [`write_exr`] deflate-compressed (ZIP, 16 lines a block): slower, and several times smaller
/// where the samples vary texel by texel.
pub fn write_exr_zip(
    width: usize,
    height: usize,
    channels: Vec<(&str, Vec<f32>)>,
) -> Result<Vec<u8>, String> {
    encode_exr(width, height, channels, Encoding::SMALL_LOSSLESS)
}

fn encode_exr(
    width: usize,
    height: usize,
    channels: Vec<(&str, Vec<f32>)>,
    encoding: Encoding,
) -> Result<Vec<u8>, String> {
    let list: Vec<AnyChannel<FlatSamples>> = channels
        .into_iter()
        .map(|(name, v)| AnyChannel::new(name, FlatSamples::F32(v)))
        .collect();
    let layer = Layer::new(
        (width, height),
        LayerAttributes::default(),
        // Blocks in file order: with the default unspecified order, the parallel compressor writes
        // them as they finish, and the same image gives different bytes run to run.
        Encoding {
            line_order: exr::meta::attribute::LineOrder::Increasing,
            ..encoding
        },
        AnyChannels::sort(SmallVec::from_vec(list)),
    );
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .map_err(|e| format!("EXR encoding failed: {e}"))?;
    Ok(out.into_inner())
}

/// Named f32 channels of an image.
pub type Channels = Vec<(String, Vec<f32>)>;

fn exr_error(path: &Path, e: exr::error::Error) -> StageError {
    StageError::bad_input(
        path,
        "EXR",
        format!("expected a readable OpenEXR image: {e}"),
    )
}

/// The most an EXR's pixels may expand from the file that holds them: deflate's limit is 1,032
/// to 1, and run-length and wavelet codings of a flat image stay below this.
pub const MAX_EXPANSION: u64 = 4096;

/// Whether a file of `file_len` bytes can hold `width` x `height` pixels of `channels` f32
/// samples: the decoder allocates the whole image from the header before reading a chunk, and a
/// 300-byte file claimed 8 GB (found by AFL++).
fn check_expansion(
    width: usize,
    height: usize,
    channels: usize,
    file_len: u64,
) -> Result<(), String> {
    let decoded = (width as u64)
        .saturating_mul(height as u64)
        .saturating_mul(channels as u64 * 4);
    if decoded > file_len.max(1).saturating_mul(MAX_EXPANSION) {
        return Err(format!(
            "{width} x {height} pixels of {channels} channels ({decoded} bytes decoded) from a \
             file of {file_len} bytes, more than any EXR compression expands to \
             ({MAX_EXPANSION} to 1)"
        ));
    }
    Ok(())
}

/// The first layer of an EXR file: width, height and every channel as f32, by name.
pub fn read_exr(path: &Path) -> Result<(usize, usize, Channels), StageError> {
    read_exr_expecting(path, |_, _| Ok(()))
}

/// [`read_exr`], with the size its header gives the first layer checked against the memory
/// budget and handed to `expect` before anything is decoded: a compressed file of a few bytes
/// can declare any size, and a caller that knows the size it wants (a view's) refuses another
/// first.
pub fn read_exr_expecting(
    path: &Path,
    expect: impl FnOnce(usize, usize) -> Result<(), StageError>,
) -> Result<(usize, usize, Channels), StageError> {
    use std::io::{BufReader, Seek};
    let file = crate::io::open::open_regular(path)
        .map_err(|e| exr_error(path, exr::error::Error::Io(e)))?;
    let file_len = file.metadata().map_or(0, |m| m.len());
    let mut reader = BufReader::new(file);
    let meta = exr::meta::MetaData::read_from_buffered(&mut reader, false)
        .map_err(|e| exr_error(path, e))?;
    // Every layer, since the decoder takes the first valid one, not necessarily the first.
    for h in &meta.headers {
        let size = h.layer_size;
        let (w, ht, channels) = (size.width(), size.height(), h.channels.list.len().max(1));
        crate::params::check_cells(w as f64, ht as f64, 4 * channels)
            .map_err(|m| StageError::bad_input(path, "EXR header", m))?;
        check_expansion(w, ht, channels, file_len)
            .map_err(|m| StageError::bad_input(path, "EXR header", m))?;
    }
    let (w, ht) = meta
        .headers
        .first()
        .map_or((0, 0), |h| (h.layer_size.width(), h.layer_size.height()));
    expect(w, ht)?;
    reader
        .rewind()
        .map_err(|e| exr_error(path, exr::error::Error::Io(e)))?;
    use exr::prelude::{ReadChannels, ReadLayers};
    // On this thread, so that a panic of the decoder on a malformed block (the exr crate's B44
    // arithmetic overflows on some, found by AFL++) is this file's error, not a worker thread's.
    let img = StageError::catch_decoder_panic(
        path,
        "EXR",
        "expected a well-formed OpenEXR image (its decoder failed",
        || {
            exr::prelude::read()
                .no_deep_data()
                .largest_resolution_level()
                .all_channels()
                .first_valid_layer()
                .all_attributes()
                .non_parallel()
                .from_buffered(reader)
        },
    )?
    .map_err(|e| exr_error(path, e))?;
    let layer = img.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let channels = layer
        .channel_data
        .list
        .into_iter()
        .map(|c| {
            let v: Vec<f32> = match c.sample_data {
                FlatSamples::F32(v) => v,
                FlatSamples::F16(v) => v.into_iter().map(|x| x.to_f32()).collect(),
                FlatSamples::U32(v) => v.into_iter().map(|x| x as f32).collect(),
            };
            (c.name.to_string(), v)
        })
        .collect();
    Ok((w, h, channels))
}
