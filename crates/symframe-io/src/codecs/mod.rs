//! Image decoders behind one interface, and the few image writers the project needs.
//!
//! Every decoder returns linear `f32` samples in which untrustworthy pixels are already `NaN`:
//! a pixel with any channel saturated (integer formats) or non-finite (float formats) has all
//! its channels set to `NaN`, so the estimator simply skips that light at that pixel.
//!
//! Formats, chosen by extension (case-insensitive):
//! - `.exr`: OpenEXR, half/float/uint; `R,G,B` (others such as `A` ignored), else `Y`, else the
//!   single non-alpha channel. Linear; first valid layer, full resolution level.
//! - `.png`, `.jpg`/`.jpeg`, `.tif`/`.tiff`: 8-bit is sRGB-decoded unless
//!   [`DecodeOptions::linear_8bit`]; 16-bit is `value / 65535`; TIFF 16/32/64-bit float is
//!   linear. Grey or RGB, alpha dropped.
//! - `.hdr`: Radiance RGBE, linear.
//! - `.pfm`: portable float map (`PF` RGB, `Pf` grey), linear.
//!
//! Limits (see [`crate::limits`]): every decoder reads the size a file declares first and
//! refuses more than 65,536 pixels per side or 134 million pixels, or more pixels than the
//! file's length can encode, before allocating; the decoder libraries run with allocation
//! limits of their own (2 GiB per image). Not supported: deep or multi-part-only EXR data
//! beyond the first valid layer, subsampled EXR channels, palette or 1/2/4-bit images other
//! than what the PNG decoder expands to 8 bits, signed-integer or 32/64-bit integer TIFF,
//! CMYK or other colour spaces, more than 4 channels. A file is read into memory whole, then
//! decoded; a decoder that panics on a hostile file is caught and reported as a decode error.

use std::io::Write;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::limits;

/// A decoded image: linear samples, row-major (row 0 at the top), channels interleaved.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Channels per pixel: 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// `width * height * channels` linear samples; `NaN` marks saturated or non-finite pixels.
    pub data: Vec<f32>,
    /// What the file stored and how it was made linear.
    pub kind: SampleKind,
}

/// The sample type of an image file, and so how its values were made linear.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum SampleKind {
    /// 8-bit, sRGB-decoded.
    Srgb8,
    /// 8-bit taken as linear (`value / 255`).
    Linear8,
    /// 16-bit, linear (`value / 65535`).
    U16,
    /// Floating point, linear as stored.
    Float,
}

impl SampleKind {
    /// How a message names it.
    pub fn describe(self) -> &'static str {
        match self {
            SampleKind::Srgb8 => "8-bit (sRGB-decoded)",
            SampleKind::Linear8 => "8-bit (linear)",
            SampleKind::U16 => "16-bit (linear)",
            SampleKind::Float => "float (linear)",
        }
    }
}

impl Image {
    /// The samples as interleaved RGB, grey replicated to three channels (what a stack needs).
    pub fn into_rgb(self) -> Vec<f32> {
        if self.channels == 3 {
            return self.data;
        }
        self.data.iter().flat_map(|&v| [v, v, v]).collect()
    }
}

/// How integer images are turned into linear radiance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecodeOptions {
    /// Treat 8-bit images as already linear (`value / 255`) instead of sRGB-decoding them.
    pub linear_8bit: bool,
    /// Fraction of an integer format's maximum at or above which a raw sample counts as
    /// saturated (its pixel becomes `NaN`); a value above 1 disables the test.
    pub saturation: f32,
}

impl Default for DecodeOptions {
    /// sRGB-decoded 8-bit, saturation at 99.5% of the format's maximum.
    fn default() -> Self {
        Self {
            linear_8bit: false,
            saturation: 0.995,
        }
    }
}

/// The sRGB transfer function's inverse: an encoded value in `[0, 1]` to linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB transfer function: a linear value in `[0, 1]` to its encoded value.
pub fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Decodes the image at `path` (format from its extension) into linear `f32`, with saturated and
/// non-finite pixels set to `NaN`. Corrupt or truncated files give an error naming the file,
/// never a panic.
pub fn read_image(path: &Path, opts: &DecodeOptions) -> Result<Image> {
    // An unknown extension is named without reading the file.
    extension(path)?;
    let bytes = std::fs::read(path).map_err(|e| Error::read(path, e))?;
    decode_image(path, &bytes, opts)
}

/// Decodes `bytes`, the content of the image file `path` (its extension picks the format; the
/// path names the file in errors), as [`read_image`] does.
pub fn decode_image(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<Image> {
    let ext = extension(path)?;
    let run = || -> Result<Image> {
        let (raw, srgb8) = match ext.as_str() {
            "exr" => (read_exr(path, bytes)?, false),
            "tif" | "tiff" => (read_tiff(path, bytes)?, true),
            "pfm" => (pfm_raw(path, bytes)?, false),
            "png" => (
                read_with_image(path, bytes, ::image::ImageFormat::Png)?,
                true,
            ),
            "jpg" | "jpeg" => (
                read_with_image(path, bytes, ::image::ImageFormat::Jpeg)?,
                true,
            ),
            _ => (
                read_with_image(path, bytes, ::image::ImageFormat::Hdr)?,
                false,
            ),
        };
        finish(path, raw, opts, srgb8)
    };
    // Belt and braces: a decoder bug on a hostile file must not take down a whole stack load.
    catch_unwind(AssertUnwindSafe(run))
        .unwrap_or_else(|_| Err(Error::decode(path, "decoder panicked (corrupt file?)")))
}

/// The lower-case extension of `path` if it is an image format this module reads.
fn extension(path: &Path) -> Result<String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "exr" | "tif" | "tiff" | "pfm" | "png" | "jpg" | "jpeg" | "hdr" => Ok(ext),
        _ => Err(Error::unsupported(
            path,
            format!(
                "unknown image extension '{ext}' (expected exr, png, tif, tiff, pfm, hdr, jpg \
                 or jpeg)"
            ),
        )),
    }
}

/// Raw decoded samples before conversion to linear `f32`.
enum Raw {
    U8(Vec<u8>),
    U16(Vec<u16>),
    F32(Vec<f32>),
}

/// A decoded image in its file's sample type, `channels` interleaved samples per pixel.
struct RawImage {
    width: usize,
    height: usize,
    channels: usize,
    raw: Raw,
}

/// Keeps grey or RGB (dropping alpha), converts to linear and marks bad pixels `NaN`.
fn finish(path: &Path, img: RawImage, opts: &DecodeOptions, srgb8: bool) -> Result<Image> {
    let RawImage {
        width,
        height,
        channels: ch,
        raw,
    } = img;
    let take = match ch {
        1 | 2 => 1,
        3 | 4 => 3,
        _ => return Err(Error::unsupported(path, format!("{ch}-channel image"))),
    };
    let n = width
        .checked_mul(height)
        .and_then(|p| p.checked_mul(ch))
        .ok_or_else(|| Error::decode(path, "image dimensions overflow"))?;
    let len = match &raw {
        Raw::U8(v) => v.len(),
        Raw::U16(v) => v.len(),
        Raw::F32(v) => v.len(),
    };
    if len != n {
        return Err(Error::decode(
            path,
            format!("expected {n} samples for {width}x{height}x{ch}, decoded {len}"),
        ));
    }
    let mut data = Vec::with_capacity(width * height * take);
    let nan = [f32::NAN; 3];
    let kind = match &raw {
        Raw::U8(_) if srgb8 && !opts.linear_8bit => SampleKind::Srgb8,
        Raw::U8(_) => SampleKind::Linear8,
        Raw::U16(_) => SampleKind::U16,
        Raw::F32(_) => SampleKind::Float,
    };
    match raw {
        Raw::U8(v) => {
            let lut: Vec<f32> = (0..256)
                .map(|i| {
                    let x = i as f32 / 255.0;
                    if srgb8 && !opts.linear_8bit {
                        srgb_to_linear(x)
                    } else {
                        x
                    }
                })
                .collect();
            let sat = opts.saturation * 255.0;
            for px in v.chunks_exact(ch) {
                let px = &px[..take];
                if px.iter().any(|&s| s as f32 >= sat) {
                    data.extend_from_slice(&nan[..take]);
                } else {
                    data.extend(px.iter().map(|&s| lut[s as usize]));
                }
            }
        }
        Raw::U16(v) => {
            let sat = opts.saturation * 65535.0;
            for px in v.chunks_exact(ch) {
                let px = &px[..take];
                if px.iter().any(|&s| s as f32 >= sat) {
                    data.extend_from_slice(&nan[..take]);
                } else {
                    data.extend(px.iter().map(|&s| s as f32 / 65535.0));
                }
            }
        }
        Raw::F32(v) => {
            for px in v.chunks_exact(ch) {
                let px = &px[..take];
                if px.iter().any(|s| !s.is_finite()) {
                    data.extend_from_slice(&nan[..take]);
                } else {
                    data.extend_from_slice(px);
                }
            }
        }
    }
    Ok(Image {
        width,
        height,
        channels: take,
        data,
        kind,
    })
}

/// Maps an I/O error met while decoding: end-of-file means a truncated file.
fn io_err(path: &Path, e: std::io::Error) -> Error {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        Error::decode(path, format!("truncated file ({e})"))
    } else {
        Error::read(path, e)
    }
}

/// Decodes PNG, JPEG or Radiance HDR with the `image` crate: the declared size is checked
/// first ([`crate::limits`]), then the image decoded under the same limits.
fn read_with_image(path: &Path, bytes: &[u8], fmt: ::image::ImageFormat) -> Result<RawImage> {
    use ::image::{DynamicImage as D, ImageError};
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
    let img = reader.decode().map_err(ierr)?;
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
    Ok(RawImage {
        width,
        height,
        channels,
        raw,
    })
}

/// The part of an EXR channel name after the last `.` (drops a legacy layer prefix).
fn base_name(name: &str) -> &str {
    name.rsplit('.').next().unwrap_or(name)
}

/// Decodes an OpenEXR file's first valid layer at full resolution (single-threaded), after
/// checking every part's declared size ([`crate::limits`]).
fn read_exr(path: &Path, bytes: &[u8]) -> Result<RawImage> {
    use exr::prelude::traits::*;
    use exr::prelude::{read, FlatSamples};
    use std::io::Cursor;
    let eerr = |e: exr::error::Error| match e {
        exr::error::Error::Io(io) => io_err(path, io),
        exr::error::Error::NotSupported(m) => Error::unsupported(path, format!("EXR {m}")),
        other => Error::decode(path, other),
    };
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(eerr)?;
    for h in meta.headers.iter() {
        let size = h.layer_size;
        limits::check_image_size(
            path,
            "EXR header",
            size.width() as u64,
            size.height() as u64,
            bytes.len() as u64,
        )?;
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(eerr)?;
    let layer = image.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
    let names: Vec<String> = list.iter().map(|c| c.name.to_string()).collect();
    let find = |want: &str| {
        names
            .iter()
            .position(|n| base_name(n).eq_ignore_ascii_case(want))
    };
    let picked: Vec<usize> = if let (Some(r), Some(g), Some(b)) = (find("R"), find("G"), find("B"))
    {
        vec![r, g, b]
    } else if let Some(y) = find("Y") {
        vec![y]
    } else {
        let non_alpha: Vec<usize> = (0..names.len())
            .filter(|&i| !base_name(&names[i]).eq_ignore_ascii_case("A"))
            .collect();
        if non_alpha.len() != 1 {
            return Err(Error::unsupported(
                path,
                format!(
                    "{}-channel EXR without R,G,B channels (channels: {})",
                    names.len(),
                    names.join(",")
                ),
            ));
        }
        non_alpha
    };
    let n = width * height;
    let k = picked.len();
    let mut data = vec![0.0f32; n * k];
    for (j, &ci) in picked.iter().enumerate() {
        let samples = &list[ci].sample_data;
        if samples.len() != n {
            return Err(Error::unsupported(
                path,
                format!("subsampled EXR channel {}", names[ci]),
            ));
        }
        match samples {
            FlatSamples::F16(v) => {
                for (p, s) in v.iter().enumerate() {
                    data[p * k + j] = s.to_f32();
                }
            }
            FlatSamples::F32(v) => {
                for (p, s) in v.iter().enumerate() {
                    data[p * k + j] = *s;
                }
            }
            FlatSamples::U32(v) => {
                for (p, s) in v.iter().enumerate() {
                    data[p * k + j] = *s as f32;
                }
            }
        }
    }
    Ok(RawImage {
        width,
        height,
        channels: k,
        raw: Raw::F32(data),
    })
}

/// Reorders planar samples (all of channel 0, then channel 1, ...) into interleaved pixels.
fn interleave<T: Copy>(v: Vec<T>, ch: usize) -> Vec<T> {
    let n = v.len() / ch;
    (0..n)
        .flat_map(|p| (0..ch).map(move |c| (p, c)))
        .map(|(p, c)| v[c * n + p])
        .collect()
}

/// Decodes a TIFF (8/16-bit unsigned or 16/32/64-bit float; grey, grey+alpha, RGB or RGBA).
fn read_tiff(path: &Path, bytes: &[u8]) -> Result<RawImage> {
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
    Ok(RawImage {
        width: w as usize,
        height: h as usize,
        channels,
        raw,
    })
}

/// A decoded PFM: size, channels (1 or 3) and linear samples, row 0 at the top.
type Pfm = (usize, usize, usize, Vec<f32>);

/// Reads the next whitespace-delimited header token of a PFM, at most 64 bytes long.
fn pfm_token<'a>(bytes: &'a [u8], pos: &mut usize) -> std::result::Result<&'a str, String> {
    while *pos < bytes.len() && bytes[*pos].is_ascii_whitespace() {
        *pos += 1;
    }
    let start = *pos;
    while *pos < bytes.len() && !bytes[*pos].is_ascii_whitespace() {
        *pos += 1;
        if *pos - start > 64 {
            return Err("header token too long".into());
        }
    }
    if start == *pos {
        return Err("truncated header".into());
    }
    std::str::from_utf8(&bytes[start..*pos]).map_err(|_| "header is not ASCII".to_string())
}

/// Parses a whole PFM file from memory. Header: `PF` (RGB) or `Pf` (grey), width, height and
/// scale (negative: little-endian; its magnitude is ignored), one whitespace byte, then rows
/// of 32-bit floats stored bottom to top.
fn parse_pfm(bytes: &[u8]) -> std::result::Result<Pfm, String> {
    let mut pos = 0;
    let channels = match pfm_token(bytes, &mut pos)? {
        "PF" => 3,
        "Pf" => 1,
        other => {
            return Err(format!(
                "not a PFM file: magic '{}' (expected PF or Pf)",
                other.escape_default()
            ))
        }
    };
    let dim = |pos: &mut usize, what: &str| -> std::result::Result<usize, String> {
        let t = pfm_token(bytes, pos)?;
        match t.parse::<usize>() {
            Ok(v) if v > 0 => Ok(v),
            _ => Err(format!("bad {what} '{}'", t.escape_default())),
        }
    };
    let width = dim(&mut pos, "width")?;
    let height = dim(&mut pos, "height")?;
    if width > limits::MAX_SIDE || height > limits::MAX_SIDE || width * height > limits::MAX_PIXELS
    {
        return Err(format!(
            "exceeds limits: PFM header declares {width}x{height} pixels (at most {} per \
             side, {} in all)",
            limits::MAX_SIDE,
            limits::MAX_PIXELS
        ));
    }
    let t = pfm_token(bytes, &mut pos)?;
    let scale: f32 = t
        .parse()
        .map_err(|_| format!("bad scale '{}'", t.escape_default()))?;
    if !scale.is_finite() || scale == 0.0 {
        return Err(format!("bad scale {scale} (must be finite and non-zero)"));
    }
    if pos >= bytes.len() {
        return Err("truncated header".into());
    }
    pos += 1; // the single whitespace byte after the scale
    let little = scale < 0.0;
    let count = width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels))
        .ok_or("image dimensions overflow")?;
    let body = &bytes[pos..];
    let truncated = match count.checked_mul(4) {
        Some(need) => body.len() < need,
        None => true,
    };
    if truncated {
        return Err(format!(
            "truncated: {width}x{height}x{channels} needs {} bytes of pixels, file has {}",
            count.saturating_mul(4),
            body.len()
        ));
    }
    let row = width * channels;
    let mut data = vec![0.0f32; count];
    for (i, b) in body[..count * 4].chunks_exact(4).enumerate() {
        let b = [b[0], b[1], b[2], b[3]];
        let v = if little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        };
        let (file_row, col) = (i / row, i % row);
        data[(height - 1 - file_row) * row + col] = v;
    }
    Ok((width, height, channels, data))
}

/// Reads a PFM as a raw float image.
fn read_pfm_raw(path: &Path) -> Result<RawImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::read(path, e))?;
    pfm_raw(path, &bytes)
}

/// Decodes a PFM file's bytes as a raw float image.
fn pfm_raw(path: &Path, bytes: &[u8]) -> Result<RawImage> {
    let (width, height, channels, data) =
        parse_pfm(bytes).map_err(|m| match m.strip_prefix("exceeds limits: ") {
            Some(m) => Error::limits(path, m),
            None => Error::decode(path, m),
        })?;
    Ok(RawImage {
        width,
        height,
        channels,
        raw: Raw::F32(data),
    })
}

/// Reads a PFM file exactly as stored (no `NaN` marking): `(width, height, channels, data)`,
/// row 0 at the top. Use [`read_image`] for stack input.
pub fn read_pfm(path: &Path) -> Result<(usize, usize, usize, Vec<f32>)> {
    let img = read_pfm_raw(path)?;
    match img.raw {
        Raw::F32(d) => Ok((img.width, img.height, img.channels, d)),
        _ => unreachable!("PFM is always float"),
    }
}

/// Checks that `data` holds `w * h * channels` values, so writers never write a torn image.
pub(crate) fn check_len(
    path: &Path,
    w: usize,
    h: usize,
    channels: usize,
    len: usize,
) -> Result<()> {
    if w == 0 || h == 0 || w.checked_mul(h).and_then(|n| n.checked_mul(channels)) != Some(len) {
        return Err(Error::invalid(
            path,
            format!("cannot write a {w}x{h}x{channels} image from {len} values"),
        ));
    }
    Ok(())
}

/// Writes a little-endian PFM (`PF` for 3 channels, `Pf` for 1), rows bottom to top as the
/// format requires; `data` is row-major with row 0 at the top.
pub fn write_pfm(
    path: &Path,
    width: usize,
    height: usize,
    channels: usize,
    data: &[f32],
) -> Result<()> {
    if channels != 1 && channels != 3 {
        return Err(Error::invalid(path, "PFM needs 1 or 3 channels"));
    }
    check_len(path, width, height, channels, data.len())?;
    let magic = if channels == 3 { "PF" } else { "Pf" };
    write_atomic(path, |w| {
        let e = |e| Error::write(path, e);
        write!(w, "{magic}\n{width} {height}\n-1.0\n").map_err(e)?;
        let row = width * channels;
        for r in (0..height).rev() {
            for v in &data[r * row..(r + 1) * row] {
                w.write_all(&v.to_le_bytes()).map_err(e)?;
            }
        }
        Ok(())
    })
}

/// Writes named float32 channels (each `w * h`, row-major) to an EXR file, ZIP-compressed.
pub(crate) fn write_exr_channels(
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

/// Splits interleaved samples into planes.
pub(crate) fn planes(data: &[f32], channels: usize) -> Vec<Vec<f32>> {
    (0..channels)
        .map(|c| data.iter().skip(c).step_by(channels).copied().collect())
        .collect()
}

/// Writes interleaved linear RGB (`width * height * 3` values) as a float32 OpenEXR file with
/// channels R, G, B; `NaN` and infinities are kept as they are.
pub fn write_exr_rgb(path: &Path, width: usize, height: usize, rgb: &[f32]) -> Result<()> {
    check_len(path, width, height, 3, rgb.len())?;
    let mut p = planes(rgb, 3).into_iter();
    let (r, g, b) = (p.next().unwrap(), p.next().unwrap(), p.next().unwrap());
    write_exr_channels(path, width, height, vec![("R", r), ("G", g), ("B", b)])
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::fs::File;
    use std::path::PathBuf;

    fn tmp(d: &tempfile::TempDir, name: &str) -> PathBuf {
        d.path().join(name)
    }

    fn opts() -> DecodeOptions {
        DecodeOptions::default()
    }

    /// Asserts `pixel` (all channels) is NaN.
    fn assert_nan_px(img: &Image, p: usize) {
        let c = img.channels;
        assert!(img.data[p * c..(p + 1) * c].iter().all(|v| v.is_nan()));
    }

    #[test]
    fn exr_rgb_float_round_trip_and_non_finite() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "a.EXR");
        let mut rgb: Vec<f32> = (0..3 * 4 * 3).map(|i| i as f32 * 0.37 - 2.0).collect();
        rgb[4] = f32::NAN; // pixel 1, channel 1
        rgb[9] = f32::INFINITY; // pixel 3, channel 0
        write_exr_rgb(&p, 4, 3, &rgb).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (4, 3, 3));
        for (i, (a, b)) in img.data.iter().zip(&rgb).enumerate() {
            if (3..6).contains(&i) || (9..12).contains(&i) {
                assert!(a.is_nan(), "sample {i}");
            } else {
                assert_eq!(a, b, "sample {i}");
            }
        }
        assert_nan_px(&img, 1);
        assert_nan_px(&img, 3);
        // No saturation test for float data, however large.
        let big = vec![1e6f32; 3];
        write_exr_rgb(&p, 1, 1, &big).unwrap();
        assert_eq!(read_image(&p, &opts()).unwrap().data, big);
    }

    #[test]
    fn exr_half_rgba_drops_alpha() {
        use exr::prelude::*;
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "half.exr");
        let (w, h) = (3usize, 2usize);
        let ch = |f: f32| -> Vec<f16> { (0..w * h).map(|i| f16::from_f32(f + i as f32)).collect() };
        let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::from_vec(vec![
            AnyChannel::new("R", FlatSamples::F16(ch(0.5))),
            AnyChannel::new("G", FlatSamples::F16(ch(10.0))),
            AnyChannel::new("B", FlatSamples::F16(ch(20.25))),
            AnyChannel::new("A", FlatSamples::F16(ch(100.0))),
        ]);
        let layer = Layer::new(
            (w, h),
            LayerAttributes::default(),
            Encoding::FAST_LOSSLESS,
            AnyChannels::sort(list),
        );
        Image::from_layer(layer).write().to_file(&p).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (3, 2, 3));
        assert_eq!(&img.data[..3], &[0.5, 10.0, 20.25]);
        assert_eq!(&img.data[15..18], &[5.5, 15.0, 25.25]);
    }

    #[test]
    fn exr_single_channel_y_and_other_names() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "y.exr");
        let v = vec![0.25f32, 1.5, -3.0, 7.0, 0.0, 2.0];
        write_exr_channels(&p, 2, 3, vec![("Y", v.clone())]).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (2, 3, 1));
        assert_eq!(img.data, v);
        let rgb = img.into_rgb();
        assert_eq!(&rgb[3..6], &[1.5, 1.5, 1.5]);

        // Any single channel is read as grey, alpha ignored.
        write_exr_channels(&p, 2, 3, vec![("depth", v.clone()), ("A", v.clone())]).unwrap();
        assert_eq!(read_image(&p, &opts()).unwrap().data, v);

        // Two channels without R,G,B or Y cannot be interpreted.
        write_exr_channels(&p, 2, 3, vec![("U", v.clone()), ("V", v)]).unwrap();
        let e = read_image(&p, &opts()).unwrap_err().to_string();
        assert!(
            e.contains("y.exr: unsupported: 2-channel EXR without R,G,B"),
            "{e}"
        );
    }

    #[test]
    fn png16_round_trip_and_saturation() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "a.png");
        let rgb: Vec<f32> = (0..12).map(|i| i as f32 * 1000.0 / 65535.0).collect();
        let mut with_sat = rgb.clone();
        with_sat[7] = 1.0; // pixel 2 saturated
        write_png16_rgb(&p, 2, 2, &with_sat).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (2, 2, 3));
        for i in (0..6).chain(9..12) {
            assert_relative_eq!(img.data[i], rgb[i], max_relative = 1e-6);
        }
        assert_nan_px(&img, 2);
        // Saturation above 1 disables the test.
        let o = DecodeOptions {
            saturation: 2.0,
            ..opts()
        };
        assert_eq!(read_image(&p, &o).unwrap().data[7], 1.0);
    }

    #[test]
    fn png8_srgb_decode_linear_and_saturation() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "g.png");
        let bytes = [128u8, 0, 253, 254, 255, 64];
        write_png(&p, 3, 2, &bytes, ::image::ExtendedColorType::L8).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (3, 2, 1));
        assert_relative_eq!(img.data[0], 0.215_860_5, max_relative = 1e-5);
        assert_eq!(img.data[1], 0.0);
        assert_relative_eq!(img.data[2], srgb_to_linear(253.0 / 255.0));
        assert!(img.data[3].is_nan() && img.data[4].is_nan());
        let lin = DecodeOptions {
            linear_8bit: true,
            ..opts()
        };
        let img = read_image(&p, &lin).unwrap();
        assert_relative_eq!(img.data[0], 128.0 / 255.0);
        assert_relative_eq!(img.data[5], 64.0 / 255.0);

        // RGB: one saturated channel blanks the whole pixel; sRGB encode/decode round trips.
        let rgb = [0.2158605f32, 0.5, 0.0, 0.1, 1.0, 0.3];
        write_png8_rgb(&p, 2, 1, &rgb, true).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_relative_eq!(img.data[0], 0.215_860_5, max_relative = 1e-4);
        assert!((img.data[1] - 0.5).abs() < 0.005);
        assert_nan_px(&img, 1);
    }

    #[test]
    fn png_with_alpha_drops_alpha() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "rgba.png");
        write_png(
            &p,
            1,
            1,
            &[10, 20, 30, 255],
            ::image::ExtendedColorType::Rgba8,
        )
        .unwrap();
        let lin = DecodeOptions {
            linear_8bit: true,
            ..opts()
        };
        let img = read_image(&p, &lin).unwrap();
        assert_eq!(img.channels, 3);
        assert_relative_eq!(img.data[2], 30.0 / 255.0);
    }

    #[test]
    fn tiff_float_grey_rgb_and_16bit() {
        use tiff::encoder::{colortype, TiffEncoder};
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "f.tif");
        let grey = vec![0.5f32, -1.0, 3.25, f32::NAN, 1e5, 0.0];
        let f = File::create(&p).unwrap();
        TiffEncoder::new(f)
            .unwrap()
            .write_image::<colortype::Gray32Float>(3, 2, &grey)
            .unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (3, 2, 1));
        assert_eq!(&img.data[..3], &grey[..3]);
        assert!(img.data[3].is_nan());
        assert_eq!(&img.data[4..], &grey[4..]);

        let p = tmp(&d, "rgb.TIFF");
        let rgb: Vec<f32> = (0..6).map(|i| i as f32 / 4.0).collect();
        TiffEncoder::new(File::create(&p).unwrap())
            .unwrap()
            .write_image::<colortype::RGB32Float>(2, 1, &rgb)
            .unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (2, 1, 3));
        assert_eq!(img.data, rgb);

        let p = tmp(&d, "s.tif");
        let v16 = [0u16, 32768, 65535, 100, 200, 300];
        TiffEncoder::new(File::create(&p).unwrap())
            .unwrap()
            .write_image::<colortype::RGB16>(2, 1, &v16)
            .unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_nan_px(&img, 0);
        assert_relative_eq!(img.data[4], 200.0 / 65535.0);
    }

    #[test]
    fn pfm_round_trip_rgb_and_grey() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "a.pfm");
        let rgb: Vec<f32> = (0..2 * 3 * 3).map(|i| i as f32 - 4.5).collect();
        write_pfm(&p, 2, 3, 3, &rgb).unwrap();
        assert_eq!(read_pfm(&p).unwrap(), (2, 3, 3, rgb.clone()));
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (2, 3, 3));
        assert_eq!(img.data, rgb);

        let grey = vec![1.0f32, 2.0, 3.0, f32::INFINITY];
        write_pfm(&p, 4, 1, 1, &grey).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!(img.channels, 1);
        assert_eq!(&img.data[..3], &grey[..3]);
        assert!(img.data[3].is_nan());
        assert!(write_pfm(&p, 4, 1, 1, &grey[..3]).is_err());
    }

    #[test]
    fn pfm_rows_are_bottom_to_top_and_endianness_from_scale() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "rows.pfm");
        // Little-endian, 1x2 grey: the first stored row is the bottom of the image.
        let mut bytes = b"Pf\n1 2\n-1.0\n".to_vec();
        bytes.extend(1.0f32.to_le_bytes());
        bytes.extend(2.0f32.to_le_bytes());
        std::fs::write(&p, &bytes).unwrap();
        assert_eq!(read_pfm(&p).unwrap().3, vec![2.0, 1.0]);
        // Written files follow the same rule: the top row is stored last.
        write_pfm(&p, 1, 2, 1, &[5.0, 6.0]).unwrap();
        let raw = std::fs::read(&p).unwrap();
        assert_eq!(&raw[raw.len() - 4..], &5.0f32.to_le_bytes());
        // Big-endian (positive scale), header split over odd whitespace.
        let mut bytes = b"PF 1\n1 4.0\n".to_vec();
        for v in [0.5f32, 0.25, 0.125] {
            bytes.extend(v.to_be_bytes());
        }
        std::fs::write(&p, &bytes).unwrap();
        assert_eq!(read_pfm(&p).unwrap(), (1, 1, 3, vec![0.5, 0.25, 0.125]));
        // Truncated pixel data is an error naming the file.
        std::fs::write(&p, &bytes[..bytes.len() - 1]).unwrap();
        let e = read_image(&p, &opts()).unwrap_err();
        assert!(e.to_string().ends_with("rows.pfm: cannot decode"), "{e}");
        let cause = std::error::Error::source(&e).map(|c| c.to_string());
        assert!(cause.is_some_and(|c| c.starts_with("truncated")), "{e:?}");
        std::fs::write(&p, b"P6\n1 1\n255\n").unwrap();
        assert!(read_pfm(&p).is_err());
    }

    proptest::proptest! {
        #[test]
        fn pfm_parser_never_panics(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..64)) {
            let _ = parse_pfm(&bytes);
        }

        #[test]
        fn pfm_header_fuzz_never_panics(
            magic in "P[fF]|[A-Za-z]{0,3}",
            w in "[0-9-]{0,22}",
            h in "[0-9 ]{0,22}",
            scale in "-?[0-9.eEinfNa]{0,8}",
            sep in "[ \t\n]{0,2}",
            body in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..48),
        ) {
            let mut bytes = format!("{magic}\n{w} {h}\n{scale}{sep}").into_bytes();
            bytes.extend(body);
            if let Ok((w, h, c, data)) = parse_pfm(&bytes) {
                proptest::prop_assert_eq!(w * h * c, data.len());
            }
        }
    }

    #[test]
    fn hdr_reads_linear_float() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "a.hdr");
        let px = [
            ::image::Rgb([0.5f32, 1.0, 2.0]),
            ::image::Rgb([3.0, 0.75, 1.5]),
        ];
        let f = std::io::BufWriter::new(File::create(&p).unwrap());
        ::image::codecs::hdr::HdrEncoder::new(f)
            .encode(&px, 2, 1)
            .unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (2, 1, 3));
        let want = [0.5, 1.0, 2.0, 3.0, 0.75, 1.5];
        for (a, b) in img.data.iter().zip(want) {
            assert!((a - b).abs() <= b * 0.01 + 1e-6, "{a} vs {b}");
        }
    }

    #[test]
    fn jpeg_is_srgb_decoded() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "a.JPG");
        let f = std::io::BufWriter::new(File::create(&p).unwrap());
        let bytes = vec![128u8; 8 * 8 * 3];
        ::image::ImageEncoder::write_image(
            ::image::codecs::jpeg::JpegEncoder::new_with_quality(f, 100),
            &bytes,
            8,
            8,
            ::image::ExtendedColorType::Rgb8,
        )
        .unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (8, 8, 3));
        for v in img.data {
            assert!((v - 0.2158605).abs() < 0.005, "{v}");
        }
    }

    #[test]
    fn truncated_and_corrupt_files_are_errors() {
        let d = tempfile::tempdir().unwrap();
        let rgb: Vec<f32> = (0..64 * 64 * 3).map(|i| (i % 97) as f32 / 97.0).collect();
        let png = tmp(&d, "t.png");
        write_png16_rgb(&png, 64, 64, &rgb).unwrap();
        let exr = tmp(&d, "t.exr");
        write_exr_rgb(&exr, 64, 64, &rgb).unwrap();
        let tif = tmp(&d, "t.tif");
        {
            use tiff::encoder::{colortype, TiffEncoder};
            TiffEncoder::new(File::create(&tif).unwrap())
                .unwrap()
                .write_image::<colortype::RGB32Float>(64, 64, &rgb)
                .unwrap();
        }
        for p in [&png, &exr, &tif] {
            let full = std::fs::read(p).unwrap();
            for keep in [0, 7, 40, full.len() / 2, full.len() - 20] {
                std::fs::write(p, &full[..keep]).unwrap();
                let e = read_image(p, &opts())
                    .expect_err(&format!("{} cut to {keep} bytes", p.display()));
                let name = p.file_name().unwrap().to_str().unwrap();
                assert!(e.to_string().contains(name), "{e}");
            }
            // Garbage of plausible size.
            let junk: Vec<u8> = (0..full.len()).map(|i| (i * 31 % 251) as u8).collect();
            std::fs::write(p, junk).unwrap();
            assert!(read_image(p, &opts()).is_err());
        }
        let e = read_image(&tmp(&d, "none.png"), &opts())
            .unwrap_err()
            .to_string();
        assert!(e.contains("none.png: cannot read"), "{e}");
        let e = read_image(&tmp(&d, "x.bmp"), &opts())
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.bmp: unsupported"), "{e}");
    }

    #[test]
    fn srgb_functions_invert() {
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert_relative_eq!(srgb_to_linear(linear_to_srgb(v)), v, epsilon = 1e-6);
        }
        assert_relative_eq!(
            srgb_to_linear(128.0 / 255.0),
            0.215_860_5,
            max_relative = 1e-6
        );
    }

    #[test]
    fn writers_reject_wrong_lengths_and_leave_no_temp_files() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "w.png");
        let e = write_png16_rgb(&p, 2, 2, &[0.0; 11])
            .unwrap_err()
            .to_string();
        assert!(e.contains("w.png") && e.contains("2x2x3"), "{e}");
        assert!(write_exr_rgb(&tmp(&d, "w.exr"), 0, 2, &[]).is_err());
        write_png8_rgb(&p, 1, 1, &[f32::NAN, 2.0, -1.0], false).unwrap();
        let lin = DecodeOptions {
            linear_8bit: true,
            saturation: 2.0,
        };
        assert_eq!(read_image(&p, &lin).unwrap().data, vec![0.0, 1.0, 0.0]);
        let names: Vec<_> = std::fs::read_dir(d.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("w.png")]);
        let e = write_exr_rgb(&d.path().join("no/such/dir.exr"), 1, 1, &[0.0; 3])
            .unwrap_err()
            .to_string();
        assert!(e.contains("dir.exr: cannot write"), "{e}");
    }
}
