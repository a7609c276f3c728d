//! Images read a band of rows at a time, converted as [`super::decode_image`] converts them
//! (through [`Convert`]): a PNG is decoded row by row from its file's bytes, a PFM read from its
//! file a band at a time, other formats (JPEG, TIFF, EXR, HDR, interlaced PNG) decoded whole
//! but kept in their file's sample type (a 64-megapixel 8-bit JPEG holds 192 MB, not the
//! 768 MB of its `f32` RGB) and converted a band at a time. What a reader holds is
//! [`Rows::resident_bytes`]: the memory of a stack's loader is set by its band, not by the
//! images' declared size.

use std::io::{Cursor, Read, Seek, SeekFrom};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use super::colour::PngChunks;
use super::pfm::{pfm_error, pfm_size, PfmHeader};
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
    /// [`PFM_HEADER_BYTES`] as expected (then it is read whole, as before: the same errors).
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
    /// the decoder's state (PNG), the samples in the file's type (formats decoded whole), or
    /// `band_rows` of stored bytes (PFM).
    pub(crate) fn resident_bytes(&self, band_rows: usize) -> usize {
        let row = self.width * self.conv.channels();
        match &self.source {
            Source::Png { file_bytes, .. } => file_bytes + PNG_STATE_BYTES + 6 * row,
            Source::Pfm { .. } => 4 * row * (band_rows + 1),
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
            Source::Png {
                reader,
                sixteen,
                row16,
                ..
            } => {
                let want = w * ch * if *sixteen { 2 } else { 1 };
                for o in out.chunks_exact_mut(out_row) {
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
                    let run = if *sixteen {
                        row16.clear();
                        row16.extend(
                            data.chunks_exact(2)
                                .map(|b| u16::from_be_bytes([b[0], b[1]])),
                        );
                        RawRun::U16(row16)
                    } else {
                        RawRun::U8(data)
                    };
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

/// Whether the PNG file `bytes` is interlaced (Adam7: its rows come in seven passes, so it is
/// decoded whole); `false` when its header cannot be read (the decoder reports it).
fn png_interlaced(bytes: &[u8]) -> bool {
    let mut dec = ::png::Decoder::new(Cursor::new(bytes));
    dec.read_header_info().is_ok_and(|i| i.interlaced)
}
