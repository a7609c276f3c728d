//! Images read a band of rows at a time, converted as [`super::decode_image`] converts them
//! (through [`Convert`]), to the same samples:
//! - a PNG is decoded row by row from its file's bytes;
//! - a PFM is read from its file a band at a time;
//! - an EXR is read from its file a row of blocks at a time (a block of 1 to 32 scan lines by
//!   its compression, 256 for DWAB, or a row of tiles), each block found through the file's
//!   offset table, whatever the line order ([`ExrRows`]);
//! - a TIFF is read from its file a row of chunks at a time (a strip, or a row of tiles; every
//!   plane of a planar file) ([`TiffRows`]);
//! - a Radiance HDR is read from its file a scan line at a time ([`HdrRows`]);
//! - JPEG and interlaced PNG are decoded whole but kept in their file's sample type (a
//!   64-megapixel 8-bit JPEG holds 192 MB, not the 768 MB of its `f32` RGB) and converted a
//!   band at a time.
//!
//! What a reader holds is [`Rows::resident_bytes`]: the memory of a stack's loader is set by
//! its band (and, for EXR and TIFF, the file's own row of blocks: a TIFF written as a single
//! strip is decoded whole), not by the images' declared size.

use std::io::{Cursor, Read, Seek, SeekFrom};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use super::colour::PngChunks;
use super::exr::ExrRows;
use super::hdr::HdrRows;
use super::pfm::{pfm_error, pfm_size, PfmHeader};
use super::tiff::TiffRows;
use super::{
    declared_size, decode_tagged, extension, io_err, read_image_file, ColourTag, Convert,
    DecodeOptions, Raw, RawRun, SampleKind, SampleType,
};
use crate::error::{Error, Result};
use crate::limits;

/// What a PNG decoder holds besides the file's bytes, by estimate: inflate state and window,
/// and a few rows.
const PNG_STATE_BYTES: usize = 128 << 10;

/// Bytes read of a PFM for its header (a longer header, of odd whitespace, is read whole).
const PFM_HEADER_BYTES: u64 = 4096;

/// An image read from the top a band of rows at a time.
pub(crate) struct Rows {
    path: PathBuf,
    width: usize,
    height: usize,
    conv: Convert,
    colour: Option<ColourTag>,
    /// The next row to read.
    next: usize,
    /// Negative samples met so far (float formats).
    negative: usize,
    source: Source,
}

/// Where the rows come from.
enum Source {
    /// A non-interlaced PNG decoded row by row, from the file's bytes.
    Png {
        reader: Box<::png::Reader<Cursor<Vec<u8>>>>,
        file_bytes: usize,
        sixteen: bool,
        /// One row of 16-bit samples in native order.
        row16: Vec<u16>,
    },
    /// A PFM, read from its file a band at a time (stored bottom to top).
    Pfm {
        /// The file, opened once.
        file: std::fs::File,
        header: PfmHeader,
        /// The band's stored bytes, and one row of its samples.
        bytes: Vec<u8>,
        row: Vec<f32>,
    },
    /// An EXR's radiance layer, read a row of blocks at a time.
    Exr(Box<ExrRows>),
    /// A TIFF, read a row of strips or tiles at a time.
    Tiff(Box<TiffRows>),
    /// A Radiance HDR, read a scan line at a time.
    Hdr(Box<HdrRows>),
    /// An image decoded whole, in its file's sample type.
    Whole(Raw),
}

/// A PNG decoder's error as this crate's, naming `path`.
fn png_error(path: &Path, e: ::png::DecodingError) -> Error {
    match e {
        ::png::DecodingError::IoError(io) => io_err(path, io),
        ::png::DecodingError::LimitsExceeded => {
            Error::limits(path, "PNG exceeds the decoder's memory limit")
        }
        other => Error::decode(path, other),
    }
}

/// The error of a decoder that panicked (a decoder bug on a hostile file).
fn panicked(path: &Path) -> Error {
    Error::decode(path, "decoder panicked (corrupt file?)")
}

/// Runs a decoder step, a panic reported as a decoding error.
fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|_| Err(panicked(path)))
}

impl Rows {
    /// Opens the image file `path` (format by extension) to be read a band of rows at a time.
    /// `check(width, height)` is called with the size its header declares before any pixel is
    /// decoded (a header that cannot be read is left for the decoder to report), and its error
    /// returned.
    pub(crate) fn open(
        path: &Path,
        opts: &DecodeOptions,
        check: &dyn Fn((usize, usize)) -> Result<()>,
    ) -> Result<Rows> {
        let ext = extension(path)?;
        if ext == "pfm" {
            if let Some(rows) = Self::open_pfm(path, opts, check)? {
                return Ok(rows);
            }
        }
        if matches!(ext.as_str(), "exr" | "tif" | "tiff" | "hdr") {
            return guarded(path, || Self::open_file(path, &ext, opts, check));
        }
        let bytes = read_image_file(path)?;
        if let Ok(size) = declared_size(path, &bytes, opts) {
            check(size)?;
        }
        if ext == "png" && !png_interlaced(&bytes) {
            return guarded(path, || Self::open_png(path, bytes, opts));
        }
        guarded(path, || {
            let (raw, colour, integer) = decode_tagged(path, &ext, &bytes, opts)?;
            drop(bytes);
            let conv = Convert::new(path, raw.channels, raw.raw.sample_type(), integer, opts)?;
            raw.check_len(path)?;
            Ok(Rows {
                path: path.to_path_buf(),
                width: raw.width,
                height: raw.height,
                conv,
                colour,
                next: 0,
                negative: 0,
                source: Source::Whole(raw.raw),
            })
        })
    }

    /// An EXR, TIFF or HDR file read from the file a row of its blocks at a time (see the
    /// module's documentation): the same checks, errors and samples as a whole decode.
    fn open_file(
        path: &Path,
        ext: &str,
        opts: &DecodeOptions,
        check: &dyn Fn((usize, usize)) -> Result<()>,
    ) -> Result<Rows> {
        let (file, len) = super::open_image_file(path)?;
        let rows = |(width, height), conv, colour, source| Rows {
            path: path.to_path_buf(),
            width,
            height,
            conv,
            colour,
            next: 0,
            negative: 0,
            source,
        };
        Ok(match ext {
            "exr" => {
                let r = ExrRows::open(path, file, len, opts, check)?;
                let conv = Convert::new(path, r.channels(), SampleType::F32, false, opts)?;
                rows(r.size(), conv, None, Source::Exr(Box::new(r)))
            }
            "hdr" => {
                let r = HdrRows::open(path, file, len, check)?;
                let conv = Convert::new(path, 3, SampleType::F32, false, opts)?;
                rows(r.size(), conv, None, Source::Hdr(Box::new(r)))
            }
            _ => {
                let (r, icc) = TiffRows::open(path, file, len, check)?;
                let conv = Convert::new(path, r.channels(), r.sample_type(), true, opts)?;
                let colour = icc.as_deref().and_then(super::colour::icc_tag);
                rows(r.size(), conv, colour, Source::Tiff(Box::new(r)))
            }
        })
    }

    /// A PNG decoded row by row: as `image` decodes it (the same decoder, limits and
    /// transformations: bit depths under 8 and palettes expanded, transparency as alpha).
    fn open_png(path: &Path, bytes: Vec<u8>, opts: &DecodeOptions) -> Result<Rows> {
        let chunks = PngChunks::read(&bytes);
        let file_bytes = bytes.len();
        let lim = ::png::Limits {
            bytes: limits::MAX_DECODED_BYTES as usize,
        };
        let mut dec = ::png::Decoder::new_with_limits(Cursor::new(bytes), lim);
        dec.set_ignore_text_chunk(false);
        let info = dec.read_header_info().map_err(|e| png_error(path, e))?;
        let (w, h) = (info.width as u64, info.height as u64);
        limits::check_image_size(path, "PNG header", w, h, file_bytes as u64)?;
        dec.set_transformations(::png::Transformations::EXPAND);
        let reader = dec.read_info().map_err(|e| png_error(path, e))?;
        use ::png::{BitDepth, ColorType};
        let (ct, depth) = reader.output_color_type();
        let ch = match ct {
            ColorType::Grayscale => 1,
            ColorType::GrayscaleAlpha => 2,
            ColorType::Rgb => 3,
            ColorType::Rgba => 4,
            ColorType::Indexed => 0,
        };
        let sixteen = match depth {
            BitDepth::Eight => false,
            BitDepth::Sixteen => true,
            _ => {
                return Err(Error::unsupported(
                    path,
                    format!("pixel layout {ct:?} of {depth:?} bits"),
                ))
            }
        };
        if ch == 0 {
            return Err(Error::unsupported(path, "pixel layout of a palette"));
        }
        let ty = if sixteen {
            SampleType::U16
        } else {
            SampleType::U8
        };
        let conv = Convert::new(path, ch, ty, true, opts)?;
        let colour = chunks.tag(reader.info().icc_profile.as_deref());
        Ok(Rows {
            path: path.to_path_buf(),
            width: w as usize,
            height: h as usize,
            conv,
            colour,
            next: 0,
            negative: 0,
            source: Source::Png {
                reader: Box::new(reader),
                file_bytes,
                sixteen,
                row16: Vec::new(),
            },
        })
    }

    /// A PFM read from its file a band at a time; `None` when its header is not in its first
    /// [`PFM_HEADER_BYTES`] as expected (then it is read whole, so a malformed header gets the
    /// whole-file reader's errors).
    fn open_pfm(
        path: &Path,
        opts: &DecodeOptions,
        check: &dyn Fn((usize, usize)) -> Result<()>,
    ) -> Result<Option<Rows>> {
        let len = crate::check_regular_file(path)?;
        let file = std::fs::File::open(path).map_err(|e| Error::read(path, e))?;
        let f = file.try_clone().map_err(|e| Error::read(path, e))?;
        let prefix = crate::read_at_most(f, path, PFM_HEADER_BYTES)?;
        if let Ok(size) = pfm_size(path, &prefix) {
            check(size)?;
        }
        let Ok(header) = PfmHeader::parse(&prefix) else {
            return Ok(None);
        };
        header
            .check_body(len.saturating_sub(header.data_at as u64))
            .map_err(|m| pfm_error(path, m))?;
        let conv = Convert::new(path, header.channels, SampleType::F32, false, opts)?;
        Ok(Some(Rows {
            path: path.to_path_buf(),
            width: header.width,
            height: header.height,
            conv,
            colour: None,
            next: 0,
            negative: 0,
            source: Source::Pfm {
                file,
                header,
                bytes: Vec::new(),
                row: Vec::new(),
            },
        }))
    }

    /// Width and height.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// What the file stores and how it is made linear.
    pub(crate) fn kind(&self) -> SampleKind {
        self.conv.kind()
    }

    /// The first integer code at or above the saturation level ([`Convert::first_saturated`]).
    pub(crate) fn first_saturated(&self) -> u32 {
        self.conv.first_saturated()
    }

    /// Whether the image is grey (one channel kept).
    pub(crate) fn grey(&self) -> bool {
        self.conv.take() == 1
    }

    /// The file's colour tag, when it has one.
    pub(crate) fn colour(&self) -> Option<&ColourTag> {
        self.colour.as_ref()
    }

    /// Negative samples in the rows read so far (a grey one counted once).
    pub(crate) fn negative(&self) -> usize {
        self.negative
    }

    /// What the reader holds in memory, besides the band it is given: the file's bytes and
    /// the decoder's state (PNG), the samples in the file's type (formats decoded whole),
    /// `band_rows` of stored bytes (PFM), a row of the file's blocks (EXR, TIFF) or a scan
    /// line (HDR).
    pub(crate) fn resident_bytes(&self, band_rows: usize) -> usize {
        let row = self.width * self.conv.channels();
        match &self.source {
            Source::Png { file_bytes, .. } => file_bytes + PNG_STATE_BYTES + 6 * row,
            Source::Pfm { .. } => 4 * row * (band_rows + 1),
            Source::Exr(r) => r.resident_bytes(),
            Source::Tiff(r) => r.resident_bytes(),
            Source::Hdr(r) => r.resident_bytes(),
            Source::Whole(raw) => raw.bytes(),
        }
    }

    /// Reads the next `out.len() / (width * out_ch)` rows into `out`, `out_ch` samples a pixel
    /// (1 for a grey image's own samples, or 3: RGB, grey replicated).
    pub(crate) fn read(&mut self, out: &mut [f32], out_ch: usize) -> Result<()> {
        let w = self.width;
        let rows = out.len() / (w * out_ch).max(1);
        if self.next + rows > self.height {
            return Err(Error::invalid(&self.path, "read past the image's last row"));
        }
        match catch_unwind(AssertUnwindSafe(|| self.read_rows(out, rows, out_ch))) {
            Ok(r) => r?,
            Err(_) => return Err(panicked(&self.path)),
        }
        self.next += rows;
        Ok(())
    }

    fn read_rows(&mut self, out: &mut [f32], rows: usize, out_ch: usize) -> Result<()> {
        let (w, ch, y0) = (self.width, self.conv.channels(), self.next);
        let path = &self.path;
        let out_row = w * out_ch;
        match &mut self.source {
            Source::Whole(raw) => {
                let run = raw.run(y0 * w * ch..(y0 + rows) * w * ch);
                self.negative += self.conv.run(run, out, out_ch);
            }
            Source::Exr(r) => {
                for (k, o) in out.chunks_exact_mut(out_row).enumerate() {
                    let row = r.row(path, y0 + k)?;
                    self.negative += self.conv.run(RawRun::F32(row), o, out_ch);
                }
            }
            Source::Tiff(r) => {
                for (k, o) in out.chunks_exact_mut(out_row).enumerate() {
                    let row = r.row(path, y0 + k)?;
                    self.negative += self.conv.run(row, o, out_ch);
                }
            }
            Source::Hdr(r) => {
                for o in out.chunks_exact_mut(out_row) {
                    let row = r.next_row(path)?;
                    self.negative += self.conv.run(RawRun::F32(row), o, out_ch);
                }
            }
            Source::Png {
                reader,
                sixteen,
                row16,
                ..
            } => {
                for o in out.chunks_exact_mut(out_row) {
                    let run = next_png_row(path, reader, *sixteen, row16, w * ch)?;
                    self.negative += self.conv.run(run, o, out_ch);
                }
            }
            Source::Pfm {
                file,
                header,
                bytes,
                row,
            } => {
                // Stored bottom to top: the band's rows are one range, the last row first.
                let stored = 4 * w * ch;
                let first = self.height - y0 - rows;
                let f = file;
                f.seek(SeekFrom::Start((header.data_at + first * stored) as u64))
                    .map_err(|e| Error::read(path, e))?;
                bytes.resize(rows * stored, 0);
                f.read_exact(bytes).map_err(|e| io_err(path, e))?;
                row.resize(w * ch, 0.0);
                for (k, o) in out.chunks_exact_mut(out_row).enumerate() {
                    let src = &bytes[(rows - 1 - k) * stored..(rows - k) * stored];
                    for (v, b) in row.iter_mut().zip(src.chunks_exact(4)) {
                        *v = header.value(b);
                    }
                    self.negative += self.conv.run(RawRun::F32(row), o, out_ch);
                }
            }
        }
        Ok(())
    }

    /// Reads the next `out.len() / (3 * width)` rows into `out` as the file's integer codes,
    /// 3 a pixel (grey replicated, alpha dropped; see [`Convert::codes`]). An image of float
    /// samples is refused, naming the file.
    pub(crate) fn read_codes(&mut self, out: &mut [u16]) -> Result<()> {
        let w = self.width;
        let rows = out.len() / (w * 3).max(1);
        if self.next + rows > self.height {
            return Err(Error::invalid(&self.path, "read past the image's last row"));
        }
        match catch_unwind(AssertUnwindSafe(|| self.read_code_rows(out, rows))) {
            Ok(Ok(true)) => {}
            Ok(Ok(false)) => {
                return Err(Error::invalid(
                    &self.path,
                    format!(
                        "{} samples do not fit an integer tile cache; use --cache-format f32",
                        self.conv.kind().describe()
                    ),
                ))
            }
            Ok(Err(e)) => return Err(e),
            Err(_) => return Err(panicked(&self.path)),
        }
        self.next += rows;
        Ok(())
    }

    /// [`Self::read_codes`] of `rows` rows: `false` for float samples.
    fn read_code_rows(&mut self, out: &mut [u16], rows: usize) -> Result<bool> {
        let (w, ch, y0) = (self.width, self.conv.channels(), self.next);
        let path = &self.path;
        let out_row = w * 3;
        match &mut self.source {
            Source::Whole(raw) => Ok(self
                .conv
                .codes(raw.run(y0 * w * ch..(y0 + rows) * w * ch), out)),
            Source::Tiff(r) => {
                for (k, o) in out.chunks_exact_mut(out_row).enumerate() {
                    let row = r.row(path, y0 + k)?;
                    if !self.conv.codes(row, o) {
                        return Ok(false);
                    }
                }
                Ok(true)
            }
            Source::Png {
                reader,
                sixteen,
                row16,
                ..
            } => {
                for o in out.chunks_exact_mut(out_row) {
                    let run = next_png_row(path, reader, *sixteen, row16, w * ch)?;
                    self.conv.codes(run, o);
                }
                Ok(true)
            }
            Source::Exr(_) | Source::Hdr(_) | Source::Pfm { .. } => Ok(false),
        }
    }

    /// Ends the reading, every row read: a PNG's image data is read to its end, as a whole
    /// decode reads it (so a file that a whole decode refuses is refused here too).
    pub(crate) fn finish(&mut self) -> Result<()> {
        if self.next != self.height {
            return Err(Error::invalid(&self.path, "rows of the image left unread"));
        }
        let path = &self.path;
        if let Source::Png { reader, .. } = &mut self.source {
            let end = catch_unwind(AssertUnwindSafe(|| reader.next_row().map(|r| r.is_none())));
            match end {
                Ok(Ok(true)) => {}
                Ok(Ok(false)) => {
                    return Err(Error::decode(path, "more rows than the header declares"))
                }
                Ok(Err(e)) => return Err(png_error(path, e)),
                Err(_) => return Err(panicked(path)),
            }
        }
        Ok(())
    }
}

/// The next row of a PNG decoded row by row (`samples` a row), checked for its length, as a
/// run of its samples (16-bit ones put in `row16`, native order).
fn next_png_row<'a>(
    path: &Path,
    reader: &'a mut ::png::Reader<Cursor<Vec<u8>>>,
    sixteen: bool,
    row16: &'a mut Vec<u16>,
    samples: usize,
) -> Result<RawRun<'a>> {
    let want = samples * if sixteen { 2 } else { 1 };
    let row = reader
        .next_row()
        .map_err(|e| png_error(path, e))?
        .ok_or_else(|| Error::decode(path, "image data ends early"))?;
    let data = row.data();
    if data.len() != want {
        return Err(Error::decode(
            path,
            format!("a row of {} bytes, expected {want}", data.len()),
        ));
    }
    Ok(if sixteen {
        row16.clear();
        row16.extend(
            data.chunks_exact(2)
                .map(|b| u16::from_be_bytes([b[0], b[1]])),
        );
        RawRun::U16(row16)
    } else {
        RawRun::U8(data)
    })
}

/// What [`read_image_grey`] gives each band to: its first row, grey values and RGB samples.
pub type GreyBand<'a> = dyn FnMut(usize, &[f32], &[f32]) + 'a;

/// Decodes the image at `path` as [`super::read_image`] does, but a band of rows at a time,
/// giving each band to `band(y, grey, rgb)`: its first row `y`, one grey value a pixel (the
/// mean of the image's channels, as a whole decode's samples give it: `NaN` or `+inf` where a
/// channel is) and its interleaved RGB samples (grey replicated). Nothing the size of the
/// image is held but what its format's reader holds (see `Rows`): what calibration needs of
/// a possibly large picture. Returns the image's width and height.
pub fn read_image_grey(
    path: &Path,
    opts: &DecodeOptions,
    band: &mut GreyBand<'_>,
) -> Result<(usize, usize)> {
    let mut rows = Rows::open(path, opts, &|_| Ok(()))?;
    let (w, h) = rows.size();
    // The mean of the image's own channels (the one of a grey image).
    let k = if rows.grey() { 1 } else { 3 };
    let n_rows = ((1 << 16) / (3 * w).max(1)).clamp(1, h.max(1));
    let mut rgb = vec![0.0f32; n_rows * w * 3];
    let mut grey = vec![0.0f32; n_rows * w];
    let mut y = 0;
    while y < h {
        let n = n_rows.min(h - y);
        let (rgb, grey) = (&mut rgb[..n * w * 3], &mut grey[..n * w]);
        rows.read(rgb, 3)?;
        for (g, p) in grey.iter_mut().zip(rgb.chunks_exact(3)) {
            *g = p[..k].iter().sum::<f32>() / k as f32;
        }
        band(y, grey, rgb);
        y += n;
    }
    rows.finish()?;
    Ok((w, h))
}

/// Whether the PNG file `bytes` is interlaced (Adam7: its rows come in seven passes, so it is
/// decoded whole); `false` when its header cannot be read (the decoder reports it).
fn png_interlaced(bytes: &[u8]) -> bool {
    let mut dec = ::png::Decoder::new(Cursor::new(bytes));
    dec.read_header_info().is_ok_and(|i| i.interlaced)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codecs::{read_image, write_exr_channels};
    use crate::stack::fixture::Rng;

    /// Reads `path` through [`Rows`] in bands of 1, 2, 3, ... rows and checks that it gives a
    /// whole decode's samples bit for bit, with its size, kind and colour tag; returns what
    /// the reader holds besides its band.
    fn rows_equal_whole(path: &Path, opts: &DecodeOptions) -> usize {
        let whole = read_image(path, opts).unwrap();
        let mut rows = Rows::open(path, opts, &|_| Ok(())).unwrap();
        let name = path.display();
        assert_eq!(rows.size(), (whole.width, whole.height), "{name}");
        assert_eq!(rows.kind(), whole.kind, "{name}");
        assert_eq!(rows.colour(), whole.colour.as_ref(), "{name}");
        let ch = whole.channels;
        assert_eq!(rows.grey(), ch == 1, "{name}");
        let resident = rows.resident_bytes(1);
        let (mut got, mut band, mut y) = (Vec::new(), 1, 0);
        while y < whole.height {
            let n = band.min(whole.height - y);
            let mut out = vec![0.0; n * whole.width * ch];
            rows.read(&mut out, ch).unwrap();
            got.extend(out);
            (y, band) = (y + n, band + 1);
        }
        rows.finish().unwrap();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(bits(&got) == bits(&whole.data), "{name}: samples differ");
        let negative = whole.data.iter().filter(|v| **v < 0.0).count();
        if negative == 0 {
            assert_eq!(rows.negative(), 0, "{name}");
        } else {
            assert!(rows.negative() > 0, "{name}");
        }
        resident
    }

    /// An error and its causes, as the command line prints them.
    fn chain(e: &Error) -> String {
        let mut s = e.to_string();
        let mut cause = std::error::Error::source(e);
        while let Some(c) = cause {
            s += &format!(": {c}");
            cause = c.source();
        }
        s
    }

    /// Floats with negative, infinite and NaN samples, and runs (for run-length encoders).
    fn floats(rng: &mut Rng, n: usize) -> Vec<f32> {
        let mut v = Vec::with_capacity(n);
        while v.len() < n {
            let x = match rng.next() % 60 {
                0 => f32::NAN,
                1 => f32::INFINITY,
                2 => -0.25,
                k => (rng.next() % 100_000) as f32 / 1e4 + k as f32,
            };
            let run = if rng.next().is_multiple_of(5) {
                1 + rng.next() % 9
            } else {
                1
            };
            for _ in 0..run {
                v.push(x);
            }
        }
        v.truncate(n);
        v
    }

    /// EXR of every block layout, line order and sample type, layered and multi-part: read a
    /// row of blocks at a time, the samples of a whole decode.
    #[test]
    fn exr_rows_equal_a_whole_decode() {
        use ::exr::prelude::*;
        let d = tempfile::tempdir().unwrap();
        let mut rng = Rng(0x5eed_0e4e_0001);
        let (w, h) = (37usize, 29usize);
        let encodings = [
            (Compression::ZIP16, Blocks::ScanLines, LineOrder::Increasing),
            (Compression::ZIP1, Blocks::ScanLines, LineOrder::Decreasing),
            (Compression::RLE, Blocks::ScanLines, LineOrder::Increasing),
            (Compression::PIZ, Blocks::ScanLines, LineOrder::Decreasing),
            (Compression::PXR24, Blocks::ScanLines, LineOrder::Increasing),
            (
                Compression::Uncompressed,
                Blocks::ScanLines,
                LineOrder::Increasing,
            ),
            (
                Compression::RLE,
                Blocks::Tiles(Vec2(16, 8)),
                LineOrder::Increasing,
            ),
            (
                Compression::ZIP16,
                Blocks::Tiles(Vec2(5, 7)),
                LineOrder::Decreasing,
            ),
            (
                Compression::ZIP1,
                Blocks::Tiles(Vec2(64, 64)),
                LineOrder::Unspecified,
            ),
            (
                Compression::PIZ,
                Blocks::Tiles(Vec2(8, 3)),
                LineOrder::Unspecified,
            ),
        ];
        for (i, (compression, blocks, line_order)) in encodings.into_iter().enumerate() {
            let p = d.path().join(format!("e{i}.exr"));
            let v = floats(&mut rng, 4 * w * h);
            let c = |k: usize| v[k * w * h..(k + 1) * w * h].to_vec();
            let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::from_vec(vec![
                AnyChannel::new(
                    "A",
                    FlatSamples::F16(c(0).iter().map(|&x| f16::from_f32(x)).collect()),
                ),
                AnyChannel::new("B", FlatSamples::F32(c(1))),
                AnyChannel::new(
                    "G",
                    FlatSamples::F16(c(2).iter().map(|&x| f16::from_f32(x)).collect()),
                ),
                AnyChannel::new(
                    "R",
                    FlatSamples::U32(c(3).iter().map(|&x| x.abs().min(1e9) as u32).collect()),
                ),
            ]);
            let enc = Encoding {
                compression,
                blocks,
                line_order,
            };
            let layer = Layer::new(
                (w, h),
                LayerAttributes::default(),
                enc,
                AnyChannels::sort(list),
            );
            Image::from_layer(layer).write().to_file(&p).unwrap();
            rows_equal_whole(&p, &DecodeOptions::default());
        }

        // Grey (Y), layered in one part, and layers in two parts.
        let p = d.path().join("y.exr");
        write_exr_channels(&p, w, h, vec![("Y", floats(&mut rng, w * h))]).unwrap();
        rows_equal_whole(&p, &DecodeOptions::default());
        let p = d.path().join("layered.exr");
        let ch: Vec<(&str, Vec<f32>)> = ["albedo.B", "albedo.G", "albedo.R", "beauty.B"]
            .into_iter()
            .chain(["beauty.G", "beauty.R", "Z"])
            .map(|n| (n, floats(&mut rng, w * h)))
            .collect();
        write_exr_channels(&p, w, h, ch).unwrap();
        for layer in ["albedo", "beauty"] {
            let opts = DecodeOptions {
                exr_layer: Some(layer.into()),
                ..Default::default()
            };
            rows_equal_whole(&p, &opts);
        }
        let p = d.path().join("parts.exr");
        let part = |name: &str, rng: &mut Rng| {
            let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = ["B", "G", "R"]
                .into_iter()
                .map(|c| AnyChannel::new(c, FlatSamples::F32(floats(rng, w * h))))
                .collect();
            Layer::new(
                (w, h),
                LayerAttributes::named(name),
                Encoding::SMALL_LOSSLESS,
                AnyChannels::sort(list),
            )
        };
        let layers =
            SmallVec::from_vec(vec![part("diffuse", &mut rng), part("specular", &mut rng)]);
        Image::from_layers(
            ImageAttributes::new(IntegerBounds::from_dimensions((w, h))),
            layers,
        )
        .write()
        .to_file(&p)
        .unwrap();
        for layer in ["diffuse", "specular"] {
            let opts = DecodeOptions {
                exr_layer: Some(layer.into()),
                ..Default::default()
            };
            rows_equal_whole(&p, &opts);
        }
        // What a reader holds is a row of blocks, not the image.
        let (w, h) = (400, 300);
        let p = d.path().join("large.exr");
        crate::codecs::write_exr_rgb(&p, w, h, &floats(&mut rng, 3 * w * h)).unwrap();
        let resident = rows_equal_whole(&p, &DecodeOptions::default());
        assert!(resident < w * h * 12 / 4, "{resident}");
    }

    /// A forged offset table (every entry at the first block) is an error naming the file,
    /// not the first block read over and over.
    #[test]
    fn an_exr_offset_table_pointing_elsewhere_is_an_error() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("f.exr");
        let (w, h) = (8, 40);
        crate::codecs::write_exr_rgb(&p, w, h, &vec![0.5; w * h * 3]).unwrap();
        let mut b = std::fs::read(&p).unwrap();
        // ZIP16 scan lines: 3 blocks; the table is the 24 bytes before the first block.
        let meta =
            ::exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(&b[..]), false).unwrap();
        assert_eq!(meta.headers[0].chunk_count, 3);
        let first = (0..b.len() - 24)
            .find(|&i| {
                let at =
                    |k: usize| u64::from_le_bytes(b[i + 8 * k..i + 8 * k + 8].try_into().unwrap());
                at(0) as usize == i + 24 && at(1) > at(0) && at(2) > at(1)
            })
            .unwrap();
        let start = b[first..first + 8].to_vec();
        b[first + 8..first + 16].copy_from_slice(&start);
        std::fs::write(&p, &b).unwrap();
        let mut rows = Rows::open(&p, &DecodeOptions::default(), &|_| Ok(())).unwrap();
        let mut out = vec![0.0; w * h * 3];
        let e = chain(&rows.read(&mut out, 3).unwrap_err());
        assert!(
            e.contains(
                "f.exr: cannot decode: the EXR offset table's block at (0, 16) points at \
                 another block"
            ),
            "{e}"
        );
    }

    /// TIFF of every sample type, strips and tiles, chunky and planar: read a row of chunks at
    /// a time, the samples of a whole decode.
    #[test]
    fn tiff_rows_equal_a_whole_decode() {
        use ::tiff::encoder::{colortype, Compression, DeflateLevel, TiffEncoder};
        use std::fs::File;
        let d = tempfile::tempdir().unwrap();
        let mut rng = Rng(0x5eed_7177_0002);
        let (w, h) = (37u32, 29u32);
        let n = (w * h) as usize;
        let bytes =
            |rng: &mut Rng, n: usize| -> Vec<u8> { (0..n).map(|_| rng.next() as u8).collect() };
        let p = |name: &str| d.path().join(name);
        macro_rules! tiff {
            ($name:expr, $ct:ty, $data:expr, $rps:expr, $comp:expr) => {{
                let mut enc = TiffEncoder::new(File::create(p($name)).unwrap())
                    .unwrap()
                    .with_compression($comp);
                let mut img = enc.new_image::<$ct>(w, h).unwrap();
                img.rows_per_strip($rps).unwrap();
                img.write_data(&$data).unwrap();
                rows_equal_whole(&p($name), &DecodeOptions::default());
            }};
        }
        tiff!(
            "rgb8.tif",
            colortype::RGB8,
            bytes(&mut rng, 3 * n),
            3,
            Compression::Deflate(DeflateLevel::default())
        );
        tiff!(
            "grey8.tif",
            colortype::Gray8,
            bytes(&mut rng, n),
            1,
            Compression::Lzw
        );
        let u16s = |rng: &mut Rng, n: usize| -> Vec<u16> {
            (0..n).map(|_| (rng.next() >> 48) as u16).collect()
        };
        tiff!(
            "rgba16.tif",
            colortype::RGBA16,
            u16s(&mut rng, 4 * n),
            7,
            Compression::Packbits
        );
        tiff!(
            "grey16.tif",
            colortype::Gray16,
            u16s(&mut rng, n),
            29,
            Compression::Uncompressed
        );
        tiff!(
            "rgbf.tif",
            colortype::RGB32Float,
            floats(&mut rng, 3 * n),
            5,
            Compression::Deflate(DeflateLevel::default())
        );
        tiff!(
            "greyf.tif",
            colortype::Gray32Float,
            floats(&mut rng, n),
            100,
            Compression::Uncompressed
        );
        let f64s: Vec<f64> = floats(&mut rng, 4 * n)
            .into_iter()
            .map(|x| x as f64 * 1.000001)
            .collect();
        tiff!(
            "rgbaf64.tif",
            colortype::RGBA64Float,
            f64s,
            4,
            Compression::Lzw
        );

        // Tiles and planes, written by hand: half floats in tiles of 16 x 8, chunky and planar,
        // 8-bit planar strips.
        let planar_half: Vec<u16> = floats(&mut rng, 3 * n)
            .into_iter()
            .map(|x| ::half::f16::from_f32(x).to_bits())
            .collect();
        for (name, planar, tile) in [
            ("tiles.tif", false, Some((16u32, 8u32))),
            ("strips-planar.tif", true, None),
        ] {
            write_raw_tiff(&p(name), (w, h), &planar_half, 16, 3, planar, tile);
            rows_equal_whole(&p(name), &DecodeOptions::default());
        }
        // Planar tiles, which the `tiff` crate cannot decode whole (it sizes the last row of
        // tiles of planes after the first as full tiles): the samples of the same image in
        // chunky tiles.
        write_raw_tiff(
            &p("tiles-planar.tif"),
            (w, h),
            &planar_half,
            16,
            3,
            true,
            Some((16, 16)),
        );
        assert!(read_image(&p("tiles-planar.tif"), &DecodeOptions::default()).is_err());
        let want = read_image(&p("tiles.tif"), &DecodeOptions::default()).unwrap();
        let opts = DecodeOptions::default();
        let mut rows = Rows::open(&p("tiles-planar.tif"), &opts, &|_| Ok(())).unwrap();
        let mut got = vec![0.0; want.data.len()];
        rows.read(&mut got, 3).unwrap();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(bits(&got) == bits(&want.data));
        let rgb8 = bytes(&mut rng, 3 * n);
        let as16: Vec<u16> = rgb8.iter().map(|&b| b as u16).collect();
        write_raw_tiff(&p("planar8.tif"), (w, h), &as16, 8, 1, true, None);
        rows_equal_whole(&p("planar8.tif"), &DecodeOptions::default());
    }

    /// Writes an uncompressed little-endian TIFF of `samples` (`w * h * 3`, interleaved; each
    /// stored in `bits` = 8 or 16 bits, sample format `format`: 1 unsigned, 3 float), chunky or
    /// planar, in strips of 5 rows or tiles.
    fn write_raw_tiff(
        path: &Path,
        (w, h): (u32, u32),
        samples: &[u16],
        bits: u16,
        format: u16,
        planar: bool,
        tile: Option<(u32, u32)>,
    ) {
        let (cw, ch) = tile.unwrap_or((w, 5));
        let (across, down) = (w.div_ceil(cw), h.div_ceil(ch));
        let planes = if planar { 3 } else { 1 };
        let per = if planar { 1 } else { 3 };
        let mut data: Vec<u8> = Vec::new();
        let (mut offsets, mut counts) = (Vec::new(), Vec::new());
        let header = 8u32;
        for plane in 0..planes {
            for ty in 0..down {
                for tx in 0..across {
                    let start = data.len();
                    // Tiles are padded to full size; strips end at the image's last row.
                    let rows = if tile.is_some() {
                        ch
                    } else {
                        ch.min(h - ty * ch)
                    };
                    for y in ty * ch..ty * ch + rows {
                        for x in tx * cw..tx * cw + cw {
                            for c in 0..per {
                                let c = if planar { plane } else { c };
                                let v = if x < w && y < h {
                                    samples[((y * w + x) * 3 + c) as usize]
                                } else {
                                    0
                                };
                                if bits == 8 {
                                    data.push(v as u8);
                                } else {
                                    data.extend(v.to_le_bytes());
                                }
                            }
                        }
                    }
                    offsets.push(header + start as u32);
                    counts.push((data.len() - start) as u32);
                }
            }
        }
        // Entries: (tag, type 3 = SHORT or 4 = LONG, values).
        let mut entries: Vec<(u16, u16, Vec<u32>)> = vec![
            (256, 4, vec![w]),
            (257, 4, vec![h]),
            (258, 3, vec![bits as u32; 3]),
            (259, 3, vec![1]),
            (262, 3, vec![2]),
            (277, 3, vec![3]),
            (284, 3, vec![if planar { 2 } else { 1 }]),
            (339, 3, vec![format as u32; 3]),
        ];
        match tile {
            Some((tw, th)) => entries.extend([
                (322, 4, vec![tw]),
                (323, 4, vec![th]),
                (324, 4, offsets),
                (325, 4, counts),
            ]),
            None => entries.extend([(273, 4, offsets), (278, 4, vec![ch]), (279, 4, counts)]),
        }
        entries.sort_by_key(|e| e.0);
        let ifd = header + data.len() as u32;
        let mut extra_at = ifd + 2 + 12 * entries.len() as u32 + 4;
        let mut out = b"II*\0".to_vec();
        out.extend(ifd.to_le_bytes());
        out.extend(&data);
        out.extend((entries.len() as u16).to_le_bytes());
        let mut extra = Vec::new();
        for (tag, ty, vals) in &entries {
            out.extend(tag.to_le_bytes());
            out.extend(ty.to_le_bytes());
            out.extend((vals.len() as u32).to_le_bytes());
            let mut bytes: Vec<u8> = Vec::new();
            for v in vals {
                if *ty == 3 {
                    bytes.extend((*v as u16).to_le_bytes());
                } else {
                    bytes.extend(v.to_le_bytes());
                }
            }
            if bytes.len() <= 4 {
                bytes.resize(4, 0);
                out.extend(bytes);
            } else {
                out.extend(extra_at.to_le_bytes());
                extra_at += bytes.len() as u32;
                extra.extend(bytes);
            }
        }
        out.extend(0u32.to_le_bytes());
        out.extend(extra);
        std::fs::write(path, out).unwrap();
    }

    /// Radiance files with run-length encoded, flat and old run-length scan lines: read a
    /// scan line at a time, the samples of a whole decode; a truncated one is an error.
    #[test]
    fn hdr_rows_equal_a_whole_decode() {
        let d = tempfile::tempdir().unwrap();
        let mut rng = Rng(0x5eed_0bd2_0003);
        for (i, (w, h)) in [(37usize, 29usize), (5, 3), (200, 2)]
            .into_iter()
            .enumerate()
        {
            let p = d.path().join(format!("h{i}.hdr"));
            let px: Vec<::image::Rgb<f32>> = floats(&mut rng, 3 * w * h)
                .chunks_exact(3)
                .map(|c| {
                    ::image::Rgb(
                        [c[0], c[1], c[2]].map(|v| if v.is_finite() { v.abs() } else { 3.0 }),
                    )
                })
                .collect();
            let f = std::io::BufWriter::new(std::fs::File::create(&p).unwrap());
            ::image::codecs::hdr::HdrEncoder::new(f)
                .encode(&px, w, h)
                .unwrap();
            rows_equal_whole(&p, &DecodeOptions::default());
        }
        // Old run-length scan lines: a pixel, a marker repeating it 3 times, another pixel;
        // consecutive markers (3 + 1 * 256 would overrun: a shorter pair here), exponents 0
        // and 1.
        let p = d.path().join("old.hdr");
        let mut b = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 6\n".to_vec();
        b.extend([9, 20, 30, 129, 1, 1, 1, 3, 7, 7, 7, 0, 200, 100, 50, 1]);
        b.extend([
            4, 5, 6, 140, 1, 1, 1, 2, 1, 1, 1, 0, 8, 8, 8, 128, 9, 9, 9, 255,
        ]);
        b.extend([10, 10, 10, 130]);
        std::fs::write(&p, &b).unwrap();
        rows_equal_whole(&p, &DecodeOptions::default());
        std::fs::write(&p, &b[..b.len() - 3]).unwrap();
        let mut rows = Rows::open(&p, &DecodeOptions::default(), &|_| Ok(())).unwrap();
        let mut out = vec![0.0; 2 * 6 * 3];
        let e = chain(&rows.read(&mut out, 3).unwrap_err());
        assert!(e.contains("old.hdr: cannot decode: truncated file"), "{e}");
    }
}
