//! PNG and Radiance HDR decoding through the `image` crate (image-rs).

use std::path::Path;

use super::{io_err, Raw, RawImage};
use crate::error::{Error, Result};
use crate::limits;

/// Decodes PNG or Radiance HDR with the `image` crate: the declared size is checked
/// first ([`crate::limits`]), then the image decoded under the same limits. Returns its ICC
/// profile too, when it has one.
pub(super) fn read_with_image(
    path: &Path,
    bytes: &[u8],
    fmt: ::image::ImageFormat,
) -> Result<(RawImage, Option<Vec<u8>>)> {
    use ::image::{DynamicImage as D, ImageDecoder, ImageError};
    use std::io::Cursor;
    let ierr = |e: ImageError| match e {
        ImageError::IoError(io) => io_err(path, io),
        ImageError::Unsupported(u) => Error::unsupported(path, u.to_string()),
        ImageError::Limits(l) => Error::limits(path, l.to_string()),
        other => Error::decode(path, other),
    };
    let what = match fmt {
        ::image::ImageFormat::Png => "PNG header",
        ::image::ImageFormat::Jpeg => "JPEG header",
        _ => "HDR header",
    };
    let (w, h) = ::image::ImageReader::with_format(Cursor::new(bytes), fmt)
        .into_dimensions()
        .map_err(ierr)?;
    limits::check_image_size(path, what, w as u64, h as u64, bytes.len() as u64)?;
    let mut reader = ::image::ImageReader::with_format(Cursor::new(bytes), fmt);
    let mut lim = ::image::Limits::default();
    lim.max_image_width = Some(limits::MAX_SIDE as u32);
    lim.max_image_height = Some(limits::MAX_SIDE as u32);
    lim.max_alloc = Some(limits::MAX_DECODED_BYTES);
    reader.limits(lim);
    let mut decoder = reader.into_decoder().map_err(ierr)?;
    // A profile that cannot be read is no reason to refuse the pixels.
    let icc = decoder.icc_profile().ok().flatten();
    let img = D::from_decoder(decoder).map_err(ierr)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let (channels, raw) = match img {
        D::ImageLuma8(b) => (1, Raw::U8(b.into_raw())),
        D::ImageLumaA8(b) => (2, Raw::U8(b.into_raw())),
        D::ImageRgb8(b) => (3, Raw::U8(b.into_raw())),
        D::ImageRgba8(b) => (4, Raw::U8(b.into_raw())),
        D::ImageLuma16(b) => (1, Raw::U16(b.into_raw())),
        D::ImageLumaA16(b) => (2, Raw::U16(b.into_raw())),
        D::ImageRgb16(b) => (3, Raw::U16(b.into_raw())),
        D::ImageRgba16(b) => (4, Raw::U16(b.into_raw())),
        D::ImageRgb32F(b) => (3, Raw::F32(b.into_raw())),
        D::ImageRgba32F(b) => (4, Raw::F32(b.into_raw())),
        other => {
            return Err(Error::unsupported(
                path,
                format!("pixel layout {:?}", other.color()),
            ))
        }
    };
    Ok((
        RawImage {
            width,
            height,
            channels,
            raw,
        },
        icc,
    ))
}
