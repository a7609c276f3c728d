//! Image decoders behind one interface, and the few image writers the project needs.
//!
//! Every decoder returns linear `f32` samples in which untrustworthy pixels are already marked:
//! a pixel with any channel saturated (integer formats) has all its channels set to `+inf`
//! (censored: known only to be at least the white level; the estimator reads it at the clip
//! level, every other reader skips it as it skips `NaN`), one with a non-finite channel (float
//! formats) has all its channels `NaN`.
//!
//! Formats, chosen by extension (case-insensitive):
//! - `.exr`: OpenEXR, half/float/uint; `R,G,B` (others such as `A` ignored), else `Y`, of the
//!   unnamed default layer, or of the layer [`DecodeOptions::exr_layer`] names (`beauty` for
//!   `beauty.R`, `beauty.G`, `beauty.B`). Linear; full resolution level. A file without a
//!   default layer, or without any radiance channel (only `Z`, only `A`), is an error listing
//!   what it has.
//! - `.png`, `.jpg`/`.jpeg`, `.tif`/`.tiff`: by [`DecodeOptions::gamma`], 8-bit is
//!   sRGB-decoded and 16-bit is `value / 65535` unless told otherwise ([`Gamma`]); TIFF
//!   16/32/64-bit float is linear. Grey or RGB, alpha dropped. Their colour tags (PNG `sRGB`,
//!   `gAMA`, `iCCP`; the ICC profile of JPEG and TIFF) are read into [`Image::colour`], not
//!   applied.
//! - `.hdr`: Radiance RGBE, linear.
//! - `.pfm`: portable float map (`PF` RGB, `Pf` grey), linear.
//!
//! Limits (see [`crate::limits`]): every decoder reads the size a file declares first and
//! refuses more than 65,536 pixels per side or 134 million pixels, or more pixels than the
//! file's length can encode, before allocating; the decoder libraries run with allocation
//! limits of their own (2 GiB per image). Not supported: deep EXR data, EXR radiance other
//! than `R`, `G`, `B` or `Y` of one layer (a depth `Z` or alpha `A` alone is not radiance;
//! the layers of a file without a default layer are not guessed), subsampled EXR channels, palette or 1/2/4-bit images other
//! than what the PNG decoder expands to 8 bits, signed-integer or 32/64-bit integer TIFF,
//! CMYK or other colour spaces, more than 4 channels. A file is read into memory whole, then
//! decoded; a decoder that panics on a hostile file is caught and reported as a decode error.
//! A stack's images are read a band of rows at a time instead (`rows`: PNG row by row; PFM, EXR,
//! TIFF and HDR from their files a row of their own blocks at a time; JPEG decoded whole in its
//! 8-bit samples), converted by the same code (`convert`), to the same samples.
//!
//! One module per codec: `exr`, `tiff`, `pfm`, `png` (writing), `hdr` (Radiance scan lines read
//! one at a time), `jpeg` (zune-jpeg, the decoder `image` uses, called directly), and
//! `image_rs` (PNG and Radiance HDR decoding through the `image` crate); this one holds the
//! common types, the dispatch by extension and the conversion to linear samples.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use crate::error::{Error, Result};

mod colour;
mod convert;
mod exr;
mod exr_dwa;
mod exr_piz;
mod hdr;
mod image_rs;
mod jpeg;
mod pfm;
mod png;
mod rows;
mod tiff;

pub use colour::ColourTag;
pub(crate) use convert::{linear_table, Convert, RawRun, SampleType};
use exr::read_exr;
pub use exr::{write_exr_channels, write_exr_rgb};
pub(crate) use exr::{write_exr_interleaved, write_exr_pixels};
use image_rs::read_with_image;
use pfm::{pfm_raw, pfm_size};
pub use pfm::{read_pfm, write_pfm};
pub(crate) use png::{rgb16_row, write_png, write_png16_rgb_with, PngLayout};
pub use png::{write_png16_rgb, write_png8_rgb, PngRows};
pub(crate) use rows::Rows;
pub use rows::{read_image_grey, GreyBand};
use tiff::read_tiff;

/// A decoded image: linear samples, row-major (row 0 at the top), channels interleaved.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Channels per pixel: 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// `width * height * channels` linear samples; `+inf` marks saturated pixels, `NaN`
    /// non-finite ones.
    pub data: Vec<f32>,
    /// What the file stored and how it was made linear.
    pub kind: SampleKind,
    /// The file's colour tag, when it has one (integer formats only).
    pub colour: Option<ColourTag>,
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
    /// 16-bit, sRGB-decoded.
    Srgb16,
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
            SampleKind::Srgb16 => "16-bit (sRGB-decoded)",
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

/// How the integer samples of PNG, JPEG and TIFF files are made linear (float formats are
/// always linear).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Gamma {
    /// 8-bit sRGB-decoded, 16-bit linear: what cameras' JPEGs and linear 16-bit exports are.
    #[default]
    Auto,
    /// 8- and 16-bit sRGB-decoded (16-bit files from raw converters are often gamma-encoded).
    Srgb,
    /// 8- and 16-bit taken as linear (`value / max`).
    Linear,
}

impl Gamma {
    /// Whether samples of `bits` (8 or 16) are sRGB-decoded.
    pub fn srgb(self, bits: u32) -> bool {
        match self {
            Gamma::Auto => bits == 8,
            Gamma::Srgb => true,
            Gamma::Linear => false,
        }
    }

    /// The value in the cache fingerprint (`Auto` 0 and `Linear` 1 as the former
    /// "8-bit linear" switch, so existing caches stay valid).
    pub fn code(self) -> u64 {
        match self {
            Gamma::Auto => 0,
            Gamma::Linear => 1,
            Gamma::Srgb => 2,
        }
    }

    /// The name in reports (`auto`, `srgb`, `linear`).
    pub fn name(self) -> &'static str {
        match self {
            Gamma::Auto => "auto",
            Gamma::Srgb => "srgb",
            Gamma::Linear => "linear",
        }
    }
}

/// How images are turned into linear radiance.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodeOptions {
    /// The transfer curve of the integer formats.
    pub gamma: Gamma,
    /// Fraction of an integer format's maximum at or above which a raw sample counts as
    /// saturated (its pixel becomes `NaN`); a value above 1 disables the test.
    pub saturation: f32,
    /// The EXR layer holding the radiance (`beauty` for channels `beauty.R`, `beauty.G`,
    /// `beauty.B`; in a multi-part file its part's name first); `None`: the default layer
    /// (channels without a layer name). Other formats ignore it.
    pub exr_layer: Option<String>,
}

impl Default for DecodeOptions {
    /// sRGB-decoded 8-bit, linear 16-bit, saturation at 99.5% of the format's maximum, the
    /// default EXR layer.
    fn default() -> Self {
        Self {
            gamma: Gamma::Auto,
            saturation: 0.995,
            exr_layer: None,
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
    let bytes = read_image_file(path)?;
    decode_image(path, &bytes, opts)
}

/// The bytes of the image file `path`, bounded ([`crate::read_bounded`]).
pub(crate) fn read_image_file(path: &Path) -> Result<Vec<u8>> {
    crate::read_bounded(path, "an image file", crate::limits::MAX_IMAGE_FILE_BYTES)
}

/// The image file `path` opened to be read in parts, checked as [`read_image_file`] checks it
/// (a regular file of at most the image cap); returns it and its length.
pub(crate) fn open_image_file(path: &Path) -> Result<(std::fs::File, u64)> {
    let f =
        crate::bounded::open_checked(path, "an image file", crate::limits::MAX_IMAGE_FILE_BYTES)?;
    let len = f.metadata().map_err(|e| Error::read(path, e))?.len();
    Ok((f, len))
}

/// Decodes `bytes`, the content of the image file `path` (its extension picks the format; the
/// path names the file in errors), as [`read_image`] does.
pub fn decode_image(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<Image> {
    let ext = extension(path)?;
    let run = || -> Result<Image> {
        let (raw, colour, integer) = decode_tagged(path, &ext, bytes, opts)?;
        let mut img = finish(path, raw, opts, integer)?;
        img.colour = colour;
        Ok(img)
    };
    // Belt and braces: a decoder bug on a hostile file must not take down a whole stack load.
    catch_unwind(AssertUnwindSafe(run))
        .unwrap_or_else(|_| Err(Error::decode(path, "decoder panicked (corrupt file?)")))
}

/// Decodes `bytes` of format `ext` into the file's own samples ([`decode_raw`]); returns them,
/// the file's colour tag (integer formats) and whether its integer samples may be
/// gamma-encoded.
fn decode_tagged(
    path: &Path,
    ext: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<(RawImage, Option<ColourTag>, bool)> {
    let ((raw, icc), integer) = decode_raw(path, ext, bytes, opts)?;
    let colour = match ext {
        "png" => colour::png_tag(bytes, icc.as_deref()),
        _ if integer => icc.as_deref().and_then(colour::icc_tag),
        _ => None,
    };
    Ok((raw, colour, integer))
}

/// A decoded image in its file's samples, and its ICC profile when it has one.
type Decoded = (RawImage, Option<Vec<u8>>);

/// Decodes `bytes` of format `ext` into the file's own samples, every channel kept; returns
/// them, the ICC profile (when there is one) and whether the format's integer samples may be
/// gamma-encoded.
fn decode_raw(
    path: &Path,
    ext: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<(Decoded, bool)> {
    Ok(match ext {
        "exr" => ((read_exr(path, bytes, opts)?, None), false),
        "tif" | "tiff" => (read_tiff(path, bytes)?, true),
        "pfm" => ((pfm_raw(path, bytes)?, None), false),
        "png" => (
            read_with_image(path, bytes, ::image::ImageFormat::Png)?,
            true,
        ),
        "jpg" | "jpeg" => (jpeg::read_jpeg(path, bytes)?, true),
        _ => (
            read_with_image(path, bytes, ::image::ImageFormat::Hdr)?,
            false,
        ),
    })
}

/// The width and height of the image file `path` whose content is `bytes`, from its header
/// alone (for an EXR, of the layer `opts` picks), without decoding its pixels: how a stack
/// compares an image's size with the first image's before decoding it. Errors as
/// [`decode_image`] would give them for a header that cannot be read.
pub fn declared_size(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<(usize, usize)> {
    use std::io::Cursor;
    let ext = extension(path)?;
    let run = || -> Result<(usize, usize)> {
        let fmt = match ext.as_str() {
            "exr" => return exr::exr_size(path, bytes, opts),
            "pfm" => return pfm_size(path, bytes),
            "tif" | "tiff" => {
                let mut dec = ::tiff::decoder::Decoder::new(Cursor::new(bytes))
                    .map_err(|e| Error::decode(path, e))?;
                let (w, h) = dec.dimensions().map_err(|e| Error::decode(path, e))?;
                return Ok((w as usize, h as usize));
            }
            "png" => ::image::ImageFormat::Png,
            "jpg" | "jpeg" => ::image::ImageFormat::Jpeg,
            _ => ::image::ImageFormat::Hdr,
        };
        let (w, h) = ::image::ImageReader::with_format(Cursor::new(bytes), fmt)
            .into_dimensions()
            .map_err(|e| Error::decode(path, e))?;
        Ok((w as usize, h as usize))
    };
    catch_unwind(AssertUnwindSafe(run))
        .unwrap_or_else(|_| Err(Error::decode(path, "decoder panicked (corrupt file?)")))
}

/// An 8-bit image's width, height, channels and interleaved samples ([`decode_8bit`]).
pub type Samples8 = (usize, usize, usize, Vec<u8>);

/// The samples of the 8-bit image file `path` (content `bytes`) as its decoder gives them
/// (width, height, channels, every channel interleaved), before anything is made linear: what
/// an integer tile cache stores. For timing and comparing decoders; `None` for an image of
/// other samples.
pub fn decode_8bit(path: &Path, bytes: &[u8]) -> Result<Option<Samples8>> {
    let ext = extension(path)?;
    let run = || -> Result<Option<Samples8>> {
        let ((raw, _), _) = decode_raw(path, &ext, bytes, &DecodeOptions::default())?;
        Ok(match raw.raw {
            Raw::U8(v) => Some((raw.width, raw.height, raw.channels, v)),
            _ => None,
        })
    };
    catch_unwind(AssertUnwindSafe(run))
        .unwrap_or_else(|_| Err(Error::decode(path, "decoder panicked (corrupt file?)")))
}

/// The bits of the integer samples the image file `path` (whose first bytes are `prefix`)
/// declares in its header, as its decoder gives them: 8 for JPEG and for PNG under 16 bits (a
/// palette, or fewer bits, expanded to 8), 16 for 16-bit PNG, 8 or 16 for unsigned-integer
/// TIFF; `None` for float formats and headers that do not say (then the samples are taken as
/// float).
pub(crate) fn declared_bits(path: &Path, prefix: &[u8]) -> Option<u32> {
    let ext = extension(path).ok()?;
    match ext.as_str() {
        "jpg" | "jpeg" => Some(8),
        "png" => {
            // Signature, then the IHDR chunk: length, type, width, height, bit depth.
            if prefix.len() < 26 || &prefix[12..16] != b"IHDR" {
                return None;
            }
            Some(if prefix[24] == 16 { 16 } else { 8 })
        }
        "tif" | "tiff" => {
            let run = || -> Option<u32> {
                use ::tiff::tags::Tag;
                let mut dec = ::tiff::decoder::Decoder::new(std::io::Cursor::new(prefix)).ok()?;
                let unsigned = matches!(dec.find_tag_unsigned::<u16>(Tag::SampleFormat), Ok(None))
                    || dec
                        .get_tag_u16_vec(Tag::SampleFormat)
                        .is_ok_and(|v| v.iter().all(|&f| f == 1));
                let bits = match dec.colortype().ok()? {
                    ::tiff::ColorType::Gray(b)
                    | ::tiff::ColorType::GrayA(b)
                    | ::tiff::ColorType::RGB(b)
                    | ::tiff::ColorType::RGBA(b) => b,
                    _ => return None,
                };
                (unsigned && (bits == 8 || bits == 16)).then_some(bits as u32)
            };
            catch_unwind(AssertUnwindSafe(run)).ok().flatten()
        }
        _ => None,
    }
}

/// Reads the mask image `path` (any format [`read_image`] reads): width, height and which
/// pixels are inside. A pixel is inside when any of its colour channels (grey, or red, green
/// and blue) is non-zero and, when the image has alpha, its alpha is non-zero too: a black and
/// white mask, a pure blue or red and green one, and one transparent outside with colour
/// everywhere all mean what they show. Raw samples decide: no sRGB decoding or saturation test.
pub(crate) fn read_mask_pixels(path: &Path) -> Result<(usize, usize, Vec<bool>)> {
    let ext = extension(path)?;
    let bytes = read_image_file(path)?;
    let run = || -> Result<(usize, usize, Vec<bool>)> {
        let ((raw, _), _) = decode_raw(path, &ext, &bytes, &DecodeOptions::default())?;
        mask_of(path, raw)
    };
    catch_unwind(AssertUnwindSafe(run))
        .unwrap_or_else(|_| Err(Error::decode(path, "decoder panicked (corrupt file?)")))
}

/// The pixels inside of a decoded mask (see [`read_mask_pixels`]).
fn mask_of(path: &Path, img: RawImage) -> Result<(usize, usize, Vec<bool>)> {
    let ch = img.channels;
    let (colour, alpha) = match ch {
        1 => (1, false),
        2 => (1, true),
        3 => (3, false),
        4 => (3, true),
        _ => return Err(Error::unsupported(path, format!("{ch}-channel mask"))),
    };
    fn inside<T: Copy>(px: &[T], colour: usize, alpha: bool, on: impl Fn(T) -> bool) -> bool {
        px[..colour].iter().any(|&v| on(v)) && (!alpha || on(px[colour]))
    }
    let n = img.width * img.height;
    let mask: Vec<bool> = match &img.raw {
        Raw::U8(v) => v
            .chunks_exact(ch)
            .map(|px| inside(px, colour, alpha, |s| s != 0))
            .collect(),
        Raw::U16(v) => v
            .chunks_exact(ch)
            .map(|px| inside(px, colour, alpha, |s| s != 0))
            .collect(),
        Raw::F32(v) => v
            .chunks_exact(ch)
            .map(|px| inside(px, colour, alpha, |s: f32| s != 0.0 && !s.is_nan()))
            .collect(),
    };
    if mask.len() != n {
        return Err(Error::decode(
            path,
            format!("expected {n} pixels, decoded {}", mask.len()),
        ));
    }
    Ok((img.width, img.height, mask))
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

impl Raw {
    /// The sample type.
    fn sample_type(&self) -> SampleType {
        match self {
            Raw::U8(_) => SampleType::U8,
            Raw::U16(_) => SampleType::U16,
            Raw::F32(_) => SampleType::F32,
        }
    }

    /// Samples held.
    fn len(&self) -> usize {
        match self {
            Raw::U8(v) => v.len(),
            Raw::U16(v) => v.len(),
            Raw::F32(v) => v.len(),
        }
    }

    /// Bytes held.
    fn bytes(&self) -> usize {
        match self {
            Raw::U8(v) => v.len(),
            Raw::U16(v) => 2 * v.len(),
            Raw::F32(v) => 4 * v.len(),
        }
    }

    /// Samples `range` as a run to convert.
    fn run(&self, range: std::ops::Range<usize>) -> RawRun<'_> {
        match self {
            Raw::U8(v) => RawRun::U8(&v[range]),
            Raw::U16(v) => RawRun::U16(&v[range]),
            Raw::F32(v) => RawRun::F32(&v[range]),
        }
    }
}

impl RawImage {
    /// Checks that the image holds `width * height * channels` samples.
    fn check_len(&self, path: &Path) -> Result<()> {
        let (width, height, ch) = (self.width, self.height, self.channels);
        let n = width
            .checked_mul(height)
            .and_then(|p| p.checked_mul(ch))
            .ok_or_else(|| Error::decode(path, "image dimensions overflow"))?;
        let len = self.raw.len();
        if len != n {
            return Err(Error::decode(
                path,
                format!("expected {n} samples for {width}x{height}x{ch}, decoded {len}"),
            ));
        }
        Ok(())
    }
}

/// Keeps grey or RGB (dropping alpha), converts to linear (`integer`: a format whose integer
/// samples may be gamma-encoded, decoded by `opts.gamma`) and marks bad pixels (see
/// [`Convert`]).
fn finish(path: &Path, img: RawImage, opts: &DecodeOptions, integer: bool) -> Result<Image> {
    let conv = Convert::new(path, img.channels, img.raw.sample_type(), integer, opts)?;
    img.check_len(path)?;
    let take = conv.take();
    let RawImage {
        width,
        height,
        channels,
        raw,
    } = img;
    let data = match raw {
        // Float samples with no channel to drop are marked in place: no second buffer.
        Raw::F32(mut v) if take == channels => {
            // Tested 64 pixels at a time without branching (the compiler vectorises the
            // fold), pixel by pixel only where one is not finite: a per-pixel loop alone is a
            // noticeable share of a half-float decode (docs/performance.md, "Decoding, every
            // compression").
            for block in v.chunks_mut(64 * take) {
                if !block.iter().fold(true, |all, s| all & s.is_finite()) {
                    for px in block.chunks_exact_mut(take) {
                        convert::mark_non_finite(px);
                    }
                }
            }
            v
        }
        raw => {
            let mut data = vec![0.0; width * height * take];
            conv.run(raw.run(0..raw.len()), &mut data, take);
            data
        }
    };
    Ok(Image {
        width,
        height,
        channels: take,
        data,
        kind: conv.kind(),
        colour: None,
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

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::fs::File;
    use std::path::PathBuf;

    use super::pfm::parse_pfm;

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

    /// Asserts `pixel` (all channels) is censored (`+inf`): a saturated sample.
    fn assert_clipped_px(img: &Image, p: usize) {
        let c = img.channels;
        let px = &img.data[p * c..(p + 1) * c];
        assert!(px.iter().all(|v| *v == f32::INFINITY), "{px:?}");
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

    /// The block-level reader against `exr`'s own image reader: mixed sample types, an odd
    /// size (partial last block), scan lines and tiles, every lossless compression.
    #[test]
    fn exr_blocks_match_the_crate_reader() {
        use ::exr::prelude::*;
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (37usize, 21usize);
        let v = |c: usize| -> Vec<f32> {
            (0..w * h)
                .map(|i| ((i * 7 + c * 13) % 101) as f32 * 0.37 - 5.0)
                .collect()
        };
        let encodings = [
            (Compression::ZIP16, Blocks::ScanLines),
            (Compression::ZIP1, Blocks::ScanLines),
            (Compression::RLE, Blocks::Tiles(Vec2(16, 8))),
            (Compression::PIZ, Blocks::ScanLines),
            (Compression::PIZ, Blocks::Tiles(Vec2(16, 8))),
            (Compression::PIZ, Blocks::Tiles(Vec2(1, 3))),
            // Channels DWA leaves to its RLE and unknown sections: the `exr` crate decodes
            // these blocks, their AC section recoded (codecs/exr_dwa.rs).
            (Compression::DWAA(None), Blocks::ScanLines),
            (Compression::DWAB(None), Blocks::Tiles(Vec2(16, 8))),
            (Compression::Uncompressed, Blocks::ScanLines),
        ];
        for (k, (compression, blocks)) in encodings.into_iter().enumerate() {
            let p = tmp(&d, &format!("m{k}.exr"));
            let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::from_vec(vec![
                AnyChannel::new(
                    "A",
                    FlatSamples::F16(v(0).iter().map(|&x| f16::from_f32(x)).collect()),
                ),
                AnyChannel::new("B", FlatSamples::F32(v(1))),
                AnyChannel::new(
                    "G",
                    FlatSamples::F16(v(2).iter().map(|&x| f16::from_f32(x)).collect()),
                ),
                AnyChannel::new(
                    "R",
                    FlatSamples::U32(v(3).iter().map(|&x| x.abs() as u32).collect()),
                ),
            ]);
            let enc = Encoding {
                compression,
                blocks,
                line_order: LineOrder::Increasing,
            };
            let layer = Layer::new(
                (w, h),
                LayerAttributes::default(),
                enc,
                AnyChannels::sort(list),
            );
            Image::from_layer(layer).write().to_file(&p).unwrap();
            let want = read_all_flat_layers_from_file(&p).unwrap();
            let ch = &want.layer_data[0].channel_data.list;
            let got = read_image(&p, &opts()).unwrap();
            assert_eq!((got.width, got.height, got.channels), (w, h, 3));
            for (j, name) in ["R", "G", "B"].into_iter().enumerate() {
                let c = ch.iter().find(|c| c.name.to_string() == name).unwrap();
                for i in 0..w * h {
                    let want = match &c.sample_data {
                        FlatSamples::F16(s) => s[i].to_f32(),
                        FlatSamples::F32(s) => s[i],
                        FlatSamples::U32(s) => s[i] as f32,
                    };
                    assert_eq!(got.data[i * 3 + j], want, "{compression:?} {name} {i}");
                }
            }
        }
    }

    /// DWA blocks of half R, G, B (all lossy: our own decoder) against the `exr` crate's
    /// reader, to the bit: scan lines of 32 and 256 lines, 16 x 8 tiles, an odd size.
    #[test]
    fn exr_dwa_rgb_matches_the_crate_reader() {
        use ::exr::prelude::*;
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (45usize, 37usize);
        let v = |c: usize| -> Vec<f16> {
            (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    f16::from_f32((x * 0.1 + c as f32).sin() * (y * 0.07).cos() * 4.0 + 4.5)
                })
                .collect()
        };
        for (k, (compression, blocks)) in [
            (Compression::DWAA(None), Blocks::ScanLines),
            (Compression::DWAB(None), Blocks::ScanLines),
            (Compression::DWAA(None), Blocks::Tiles(Vec2(16, 8))),
        ]
        .into_iter()
        .enumerate()
        {
            let p = tmp(&d, &format!("dwa{k}.exr"));
            let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::from_vec(vec![
                AnyChannel::new("B", FlatSamples::F16(v(2))),
                AnyChannel::new("G", FlatSamples::F16(v(1))),
                AnyChannel::new("R", FlatSamples::F16(v(0))),
            ]);
            let enc = Encoding {
                compression,
                blocks,
                line_order: LineOrder::Increasing,
            };
            let layer = Layer::new(
                (w, h),
                LayerAttributes::default(),
                enc,
                AnyChannels::sort(list),
            );
            Image::from_layer(layer).write().to_file(&p).unwrap();
            let want = read_all_flat_layers_from_file(&p).unwrap();
            let ch = &want.layer_data[0].channel_data.list;
            let got = read_image(&p, &opts()).unwrap();
            for (j, name) in ["R", "G", "B"].into_iter().enumerate() {
                let c = ch.iter().find(|c| c.name.to_string() == name).unwrap();
                let FlatSamples::F16(s) = &c.sample_data else {
                    panic!("{name} not half")
                };
                for (i, s) in s.iter().enumerate() {
                    assert_eq!(
                        got.data[i * 3 + j].to_bits(),
                        s.to_f32().to_bits(),
                        "{compression:?} {name} {i}"
                    );
                }
            }
        }
    }

    #[test]
    fn exr_half_rgba_drops_alpha() {
        use ::exr::prelude::*;
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

        // A depth or alpha channel alone is no radiance: an error listing the channels.
        write_exr_channels(&p, 2, 3, vec![("Z", v.clone())]).unwrap();
        let e = read_image(&p, &opts()).unwrap_err().to_string();
        assert!(
            e.ends_with("y.exr: no radiance channel (R, G, B or Y) in the EXR (channels: default layer (Z))"),
            "{e}"
        );
        write_exr_channels(&p, 2, 3, vec![("depth", v.clone()), ("A", v.clone())]).unwrap();
        let e = read_image(&p, &opts()).unwrap_err().to_string();
        assert!(
            e.contains("no radiance channel") && e.contains("(A, depth)"),
            "{e}"
        );
        write_exr_channels(&p, 2, 3, vec![("U", v.clone()), ("V", v)]).unwrap();
        let e = read_image(&p, &opts()).unwrap_err().to_string();
        assert!(e.contains("y.exr: no radiance channel"), "{e}");
    }

    /// A layered EXR (`albedo.R/G/B`, `beauty.R/G/B`) is not read from its first layer without
    /// a word, nor a depth-only EXR taken as radiance.
    #[test]
    fn exr_layers_are_chosen_by_name_never_guessed() {
        let d = tempfile::tempdir().unwrap();
        let p = tmp(&d, "layers.exr");
        let plane = |v: f32| vec![v; 4];
        let layered = |with_default: bool| {
            let mut ch = vec![
                ("albedo.R", plane(0.1)),
                ("albedo.G", plane(0.2)),
                ("albedo.B", plane(0.3)),
                ("beauty.R", plane(1.0)),
                ("beauty.G", plane(2.0)),
                ("beauty.B", plane(3.0)),
                ("Z", plane(9.0)),
            ];
            if with_default {
                ch.push(("Y", plane(5.0)));
            }
            write_exr_channels(&p, 2, 2, ch).unwrap();
        };
        layered(false);
        let e = read_image(&p, &opts()).unwrap_err().to_string();
        assert!(
            e.contains("layers.exr: no default EXR layer")
                && e.contains("albedo (B, G, R)")
                && e.contains("--exr-layer NAME (one of albedo, beauty)"),
            "{e}"
        );
        let pick = |name: &str| DecodeOptions {
            exr_layer: Some(name.into()),
            ..opts()
        };
        let img = read_image(&p, &pick("beauty")).unwrap();
        assert_eq!((img.channels, &img.data[..3]), (3, &[1.0, 2.0, 3.0][..]));
        assert_eq!(read_image(&p, &pick("albedo")).unwrap().data[2], 0.3);
        let e = read_image(&p, &pick("diffuse")).unwrap_err().to_string();
        assert!(e.contains("no EXR layer 'diffuse' (layers: "), "{e}");
        // The default layer when there is one (here Y; Z beside it is not radiance).
        layered(true);
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.channels, img.data[0]), (1, 5.0));
        assert_eq!(
            declared_size(&p, &std::fs::read(&p).unwrap(), &pick("beauty")).unwrap(),
            (2, 2)
        );
    }

    /// Every format's size is read from its header, so an image whose size disagrees with the
    /// stack's is refused without being decoded.
    #[test]
    fn declared_sizes_come_from_the_headers_of_every_format() {
        let d = tempfile::tempdir().unwrap();
        let rgb = vec![0.25f32; 5 * 3 * 3];
        let cases: Vec<PathBuf> = ["s.exr", "s.png", "s.pfm", "s.tif"]
            .iter()
            .map(|n| tmp(&d, n))
            .collect();
        write_exr_rgb(&cases[0], 5, 3, &rgb).unwrap();
        write_png16_rgb(&cases[1], 5, 3, &rgb).unwrap();
        write_pfm(&cases[2], 5, 3, 3, &rgb).unwrap();
        {
            use ::tiff::encoder::{colortype, TiffEncoder};
            TiffEncoder::new(File::create(&cases[3]).unwrap())
                .unwrap()
                .write_image::<colortype::RGB32Float>(5, 3, &rgb)
                .unwrap();
        }
        for p in &cases {
            let b = std::fs::read(p).unwrap();
            assert_eq!(declared_size(p, &b, &opts()).unwrap(), (5, 3), "{p:?}");
            // The header alone is enough.
            let head = &b[..b.len().min(200)];
            if ["png", "pfm"].contains(&p.extension().unwrap().to_str().unwrap()) {
                assert_eq!(declared_size(p, head, &opts()).unwrap(), (5, 3), "{p:?}");
            }
        }
        assert!(declared_size(&cases[1], b"junk", &opts()).is_err());
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
        assert_clipped_px(&img, 2);
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
        write_png(&p, 3, 2, &bytes, crate::codecs::PngLayout::L8).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_eq!((img.width, img.height, img.channels), (3, 2, 1));
        assert_relative_eq!(img.data[0], 0.215_860_5, max_relative = 1e-5);
        assert_eq!(img.data[1], 0.0);
        assert_relative_eq!(img.data[2], srgb_to_linear(253.0 / 255.0));
        assert!(img.data[3] == f32::INFINITY && img.data[4] == f32::INFINITY);
        let lin = DecodeOptions {
            gamma: Gamma::Linear,
            ..opts()
        };
        let img = read_image(&p, &lin).unwrap();
        assert_relative_eq!(img.data[0], 128.0 / 255.0);
        assert_relative_eq!(img.data[5], 64.0 / 255.0);

        // RGB: one saturated channel censors the whole pixel; sRGB encode/decode round trips.
        let rgb = [0.2158605f32, 0.5, 0.0, 0.1, 1.0, 0.3];
        write_png8_rgb(&p, 2, 1, &rgb, true).unwrap();
        let img = read_image(&p, &opts()).unwrap();
        assert_relative_eq!(img.data[0], 0.215_860_5, max_relative = 1e-4);
        assert!((img.data[1] - 0.5).abs() < 0.005);
        assert_clipped_px(&img, 1);
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
            crate::codecs::PngLayout::Rgba8,
        )
        .unwrap();
        let lin = DecodeOptions {
            gamma: Gamma::Linear,
            ..opts()
        };
        let img = read_image(&p, &lin).unwrap();
        assert_eq!(img.channels, 3);
        assert_relative_eq!(img.data[2], 30.0 / 255.0);
    }

    #[test]
    fn tiff_float_grey_rgb_and_16bit() {
        use ::tiff::encoder::{colortype, TiffEncoder};
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
        assert_clipped_px(&img, 0);
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
            use ::tiff::encoder::{colortype, TiffEncoder};
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
            gamma: Gamma::Linear,
            saturation: 2.0,
            exr_layer: None,
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
