//! TIFF decoding: 8/16-bit unsigned and 16/32/64-bit float, grey or RGB.

use std::path::Path;

use super::{io_err, Raw, RawImage};
use crate::error::{Error, Result};
use crate::limits;

/// Reorders planar samples (all of channel 0, then channel 1, ...) into interleaved pixels.
pub(super) fn interleave<T: Copy>(v: Vec<T>, ch: usize) -> Vec<T> {
    let n = v.len() / ch;
    (0..n)
        .flat_map(|p| (0..ch).map(move |c| (p, c)))
        .map(|(p, c)| v[c * n + p])
        .collect()
}

/// Decodes a TIFF (8/16-bit unsigned or 16/32/64-bit float; grey, grey+alpha, RGB or RGBA);
/// returns its ICC profile too, when it has one.
pub(super) fn read_tiff(path: &Path, bytes: &[u8]) -> Result<(RawImage, Option<Vec<u8>>)> {
    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::tags::Tag;
    use tiff::{ColorType, TiffError};
    let terr = |e: TiffError| match e {
        TiffError::IoError(io) => io_err(path, io),
        TiffError::UnsupportedError(u) => Error::unsupported(path, format!("TIFF {u}")),
        TiffError::LimitsExceeded => Error::limits(path, "TIFF exceeds the decoder's limits"),
        other => Error::decode(path, other),
    };
    let mut lim = tiff::decoder::Limits::default();
    lim.decoding_buffer_size = limits::MAX_DECODED_BYTES as usize;
    let mut dec = Decoder::new(std::io::Cursor::new(bytes))
        .map_err(terr)?
        .with_limits(lim);
    let (w, h) = dec.dimensions().map_err(terr)?;
    limits::check_image_size(path, "TIFF header", w as u64, h as u64, bytes.len() as u64)?;
    let ct = dec.colortype().map_err(terr)?;
    let (channels, bits) = match ct {
        ColorType::Gray(b) => (1, b),
        ColorType::GrayA(b) => (2, b),
        ColorType::RGB(b) => (3, b),
        ColorType::RGBA(b) => (4, b),
        other => {
            return Err(Error::unsupported(
                path,
                format!("TIFF colour type {other:?} (expected grey or RGB)"),
            ))
        }
    };
    if ![8, 16, 32, 64].contains(&bits) {
        return Err(Error::unsupported(path, format!("{bits}-bit TIFF")));
    }
    let planar = matches!(
        dec.find_tag_unsigned::<u16>(Tag::PlanarConfiguration),
        Ok(Some(2))
    );
    let icc = dec.get_tag_u8_vec(Tag::IccProfile).ok();
    let mut buf = DecodingResult::U8(Vec::new());
    dec.read_image_to_buffer(&mut buf).map_err(terr)?;
    let raw = match buf {
        DecodingResult::U8(v) => Raw::U8(v),
        DecodingResult::U16(v) => Raw::U16(v),
        DecodingResult::F16(v) => Raw::F32(v.into_iter().map(f32::from).collect()),
        DecodingResult::F32(v) => Raw::F32(v),
        DecodingResult::F64(v) => Raw::F32(v.into_iter().map(|x| x as f32).collect()),
        _ => {
            return Err(Error::unsupported(
                path,
                format!("TIFF sample format ({bits}-bit signed or 32/64-bit integer)"),
            ))
        }
    };
    let expected = w as usize * h as usize * channels;
    let raw = if planar && channels > 1 {
        let ok = |len: usize| {
            if len == expected {
                Ok(())
            } else {
                Err(Error::unsupported(path, "planar TIFF with missing planes"))
            }
        };
        match raw {
            Raw::U8(v) => {
                ok(v.len())?;
                Raw::U8(interleave(v, channels))
            }
            Raw::U16(v) => {
                ok(v.len())?;
                Raw::U16(interleave(v, channels))
            }
            Raw::F32(v) => {
                ok(v.len())?;
                Raw::F32(interleave(v, channels))
            }
        }
    } else {
        raw
    };
    Ok((
        RawImage {
            width: w as usize,
            height: h as usize,
            channels,
            raw,
        },
        icc,
    ))
}
