//! Writing float32 channels to ZIP-compressed OpenEXR files.

use std::path::Path;

use crate::atomic::write_atomic;
use crate::codecs::check_len;
use crate::error::{Error, Result};

/// Writes named float32 channels (each `w * h`, row-major) to an EXR file, ZIP-compressed
/// (`beauty.R` is channel `R` of layer `beauty`).
pub fn write_exr_channels(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<(&str, Vec<f32>)>,
) -> Result<()> {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Image as ExrImage, Layer, LayerAttributes,
        SmallVec, WritableImage,
    };
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = channels
        .into_iter()
        .map(|(name, v)| AnyChannel::new(name, FlatSamples::F32(v)))
        .collect();
    let layer = Layer::new(
        (width, height),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    let image = ExrImage::from_layer(layer);
    write_atomic(path, |w| {
        image
            .write()
            .non_parallel()
            .to_buffered(w)
            .map_err(|e| match e {
                exr::error::Error::Io(io) => Error::write(path, io),
                other => Error::encode(path, other),
            })
    })
}

/// Writes interleaved linear RGB (`width * height * 3` values) as a float32 OpenEXR file with
/// channels R, G, B; `NaN` and infinities are kept as they are.
pub fn write_exr_rgb(path: &Path, width: usize, height: usize, rgb: &[f32]) -> Result<()> {
    write_exr_interleaved(path, width, height, &["R", "G", "B"], rgb)
}

/// Writes interleaved float32 samples, `names.len()` (1 or 3) per pixel and named by `names`,
/// as a ZIP-compressed EXR. The encoder reads each pixel from `data` where it is: no planar
/// copy of the map is made (a 4096 x 4096 RGB map would take 200 MB more).
pub(crate) fn write_exr_interleaved(
    path: &Path,
    width: usize,
    height: usize,
    names: &[&str],
    data: &[f32],
) -> Result<()> {
    check_len(path, width, height, names.len(), data.len())?;
    let k = names.len();
    write_exr_pixels(path, width, height, names, &|x, y| {
        let i = k * (y * width + x);
        let mut v = [0.0; 3];
        v[..k].copy_from_slice(&data[i..i + k]);
        v
    })
}

/// Writes a ZIP-compressed float32 EXR of `names.len()` (1 or 3) channels named by `names`,
/// pixel `(x, y)` of which is `pixel(x, y)` (its first `names.len()` values). The encoder
/// runs on this thread and asks for the pixels block by block in increasing `y`, so a caller
/// can produce them a band of rows at a time.
pub(crate) fn write_exr_pixels(
    path: &Path,
    width: usize,
    height: usize,
    names: &[&str],
    pixel: &(dyn Fn(usize, usize) -> [f32; 3] + Sync),
) -> Result<()> {
    use exr::prelude::{
        Encoding, Image as ExrImage, Layer, LayerAttributes, SpecificChannels, Vec2, WritableImage,
    };
    let map_err = |e: exr::error::Error| match e {
        exr::error::Error::Io(io) => Error::write(path, io),
        other => Error::encode(path, other),
    };
    // One layer of the given channels, written through `write_atomic`.
    macro_rules! write_layer {
        ($channels:expr) => {{
            let layer = Layer::new(
                (width, height),
                LayerAttributes::default(),
                Encoding::SMALL_LOSSLESS,
                $channels,
            );
            let image = ExrImage::from_layer(layer);
            write_atomic(path, |w| {
                image.write().non_parallel().to_buffered(w).map_err(map_err)
            })
        }};
    }
    match *names {
        [a] => write_layer!(SpecificChannels::build()
            .with_channel(a)
            .with_pixel_fn(|p: Vec2<usize>| (pixel(p.x(), p.y())[0],))),
        [a, b, c] => write_layer!(SpecificChannels::build()
            .with_channel(a)
            .with_channel(b)
            .with_channel(c)
            .with_pixel_fn(|p: Vec2<usize>| {
                let v = pixel(p.x(), p.y());
                (v[0], v[1], v[2])
            })),
        _ => Err(Error::invalid(
            path,
            format!("EXR maps have 1 or 3 channels, not {}", names.len()),
        )),
    }
}
