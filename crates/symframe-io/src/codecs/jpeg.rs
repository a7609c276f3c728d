//! JPEG decoding with zune-jpeg, the decoder the `image` crate uses, called directly with the
//! options `image` gives it (so the samples are the same to the bit) but without `image`'s
//! copy of the file, and with the output's memory taken in 2 MiB pages where the system allows:
//! paging in a large fresh output 4 KiB at a time costs about as much as decoding the image
//! (docs/performance.md, "JPEG decoding").

use std::path::Path;

use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;
use zune_jpeg::errors::DecodeErrors;
use zune_jpeg::JpegDecoder;

use super::{Raw, RawImage};
use crate::error::{Error, Result};
use crate::limits;

/// A zune-jpeg error as this crate's, naming `path` (as `image` sorts them: unsupported
/// features, dimension limits, decoding errors).
fn jpeg_error(path: &Path, e: DecodeErrors) -> Error {
    match e {
        DecodeErrors::Unsupported(u) => Error::unsupported(path, format!("{u:?}")),
        DecodeErrors::LargeDimensions(_) => Error::limits(path, "JPEG dimensions too large"),
        other => Error::decode(path, other),
    }
}

/// Decodes the JPEG file `path` whose content is `bytes`: grey, grey and alpha, RGB or RGBA
/// kept as stored, any other colour space (YCbCr, CMYK) converted to RGB; the declared size is
/// checked first ([`crate::limits`]). Returns its ICC profile too, when it has one.
pub(super) fn read_jpeg(path: &Path, bytes: &[u8]) -> Result<(RawImage, Option<Vec<u8>>)> {
    let options = DecoderOptions::default()
        .set_strict_mode(false)
        .set_max_width(usize::MAX)
        .set_max_height(usize::MAX);
    let mut dec = JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    dec.decode_headers().map_err(|e| jpeg_error(path, e))?;
    let (width, height) = dec
        .dimensions()
        .ok_or_else(|| Error::decode(path, "JPEG header without dimensions"))?;
    limits::check_image_size(
        path,
        "JPEG header",
        width as u64,
        height as u64,
        bytes.len() as u64,
    )?;
    let out = match dec.input_colorspace() {
        Some(c @ (ColorSpace::RGB | ColorSpace::RGBA | ColorSpace::Luma | ColorSpace::LumaA)) => c,
        _ => ColorSpace::RGB,
    };
    dec.set_options(dec.options().jpeg_set_out_colorspace(out));
    let icc = dec.icc_profile();
    let channels = out.num_components();
    let len = width * height * channels;
    if len as u64 > limits::MAX_DECODED_BYTES {
        return Err(Error::limits(
            path,
            "JPEG exceeds the decoder's memory limit",
        ));
    }
    let mut buf = zeroed(len);
    dec.decode_into(&mut buf).map_err(|e| jpeg_error(path, e))?;
    Ok((
        RawImage {
            width,
            height,
            channels,
            raw: Raw::U8(buf),
        },
        icc,
    ))
}

/// `len` zero bytes (what a truncated file leaves undecoded, as with `image`), their memory
/// advised to be backed by 2 MiB pages on Linux (one page fault per 2 MiB rather than per
/// 4 KiB when the buffer is first written).
fn zeroed(len: usize) -> Vec<u8> {
    const HUGE: usize = 2 << 20;
    let mut v: Vec<u8> = Vec::with_capacity(len);
    #[cfg(target_os = "linux")]
    if len >= 4 * HUGE {
        let base = v.as_mut_ptr() as usize;
        let start = (base + HUGE - 1) & !(HUGE - 1);
        let end = (base + len) & !(HUGE - 1);
        if end > start {
            // SAFETY: advice on whole pages inside this vector's own allocation; the content
            // is unaffected (it is written below) and errors are only a lost hint.
            unsafe {
                libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
            }
        }
    }
    v.resize(len, 0);
    v
}
