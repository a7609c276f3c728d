//! PNG writing: 8-bit (optionally sRGB-encoded) and 16-bit linear RGB.

use std::path::Path;

use super::{check_len, linear_to_srgb};
use crate::atomic::write_atomic;
use crate::error::{Error, Result};

/// Encodes raw pixel bytes as PNG (`bytes` native-endian for 16-bit types).
pub(crate) fn write_png(
    path: &Path,
    width: usize,
    height: usize,
    bytes: &[u8],
    color: ::image::ExtendedColorType,
) -> Result<()> {
    use ::image::ImageEncoder;
    let (w, h) = (
        u32::try_from(width).map_err(|_| Error::invalid(path, "image too wide for PNG"))?,
        u32::try_from(height).map_err(|_| Error::invalid(path, "image too tall for PNG"))?,
    );
    write_atomic(path, |out| {
        ::image::codecs::png::PngEncoder::new(out)
            .write_image(bytes, w, h, color)
            .map_err(|e| match e {
                ::image::ImageError::IoError(io) => Error::write(path, io),
                other => Error::encode(path, other),
            })
    })
}

/// Converts a value to an integer code in `[0, max]`: `NaN` becomes 0, others are clamped.
fn quantise(v: f32, max: f32) -> f32 {
    if v.is_nan() {
        0.0
    } else {
        (v.clamp(0.0, 1.0) * max).round()
    }
}

/// Writes interleaved linear RGB in `[0, 1]` (clamped; `NaN` as 0) as a 16-bit linear PNG.
pub fn write_png16_rgb(path: &Path, width: usize, height: usize, rgb: &[f32]) -> Result<()> {
    check_len(path, width, height, 3, rgb.len())?;
    let bytes: Vec<u8> = rgb
        .iter()
        .flat_map(|&v| (quantise(v, 65535.0) as u16).to_ne_bytes())
        .collect();
    write_png(
        path,
        width,
        height,
        &bytes,
        ::image::ExtendedColorType::Rgb16,
    )
}

/// Writes interleaved RGB in `[0, 1]` (clamped; `NaN` as 0) as an 8-bit PNG, sRGB-encoding
/// linear values first when `srgb_encode` is set.
pub fn write_png8_rgb(
    path: &Path,
    width: usize,
    height: usize,
    rgb: &[f32],
    srgb_encode: bool,
) -> Result<()> {
    check_len(path, width, height, 3, rgb.len())?;
    let bytes: Vec<u8> = rgb
        .iter()
        .map(|&v| {
            let v = if srgb_encode && !v.is_nan() {
                linear_to_srgb(v.clamp(0.0, 1.0))
            } else {
                v
            };
            quantise(v, 255.0) as u8
        })
        .collect();
    write_png(
        path,
        width,
        height,
        &bytes,
        ::image::ExtendedColorType::Rgb8,
    )
}
