//! PNG writing: 8-bit (optionally sRGB-encoded) and 16-bit linear RGB.

use std::cell::RefCell;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::rc::Rc;

use super::{check_len, linear_to_srgb};
use crate::atomic::{write_atomic, TempFile};
use crate::error::{Error, Result};

/// The PNG pixel layouts symframe writes: channels and bits per channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PngLayout {
    /// 8-bit grey.
    L8,
    /// 8-bit RGB.
    Rgb8,
    /// 8-bit RGBA (the tests' masks).
    #[cfg_attr(not(test), allow(dead_code))]
    Rgba8,
    /// 16-bit grey and alpha (the tests' masks).
    #[cfg_attr(not(test), allow(dead_code))]
    La16,
    /// 16-bit RGB.
    Rgb16,
}

impl PngLayout {
    fn png(self) -> (::png::ColorType, ::png::BitDepth) {
        use ::png::{BitDepth::*, ColorType::*};
        match self {
            PngLayout::L8 => (Grayscale, Eight),
            PngLayout::Rgb8 => (Rgb, Eight),
            PngLayout::Rgba8 => (Rgba, Eight),
            PngLayout::La16 => (GrayscaleAlpha, Sixteen),
            PngLayout::Rgb16 => (Rgb, Sixteen),
        }
    }

    /// Bytes per pixel.
    fn pixel_bytes(self) -> usize {
        match self {
            PngLayout::L8 => 1,
            PngLayout::Rgb8 => 3,
            PngLayout::Rgba8 | PngLayout::La16 => 4,
            PngLayout::Rgb16 => 6,
        }
    }
}

/// Encodes a PNG row by row: `fill(y, row)` writes row `y`'s bytes (big-endian for 16-bit
/// layouts) into a buffer of one row, so no copy of the whole image is ever made (a 4096 x
/// 4096 16-bit map would need 100 MB twice over through `image`'s encoder, which converts the
/// whole buffer to big-endian and filters it in one go). Settings as `image`'s default
/// encoder: fast deflate, adaptive filtering.
pub(crate) fn write_png_rows(
    path: &Path,
    width: usize,
    height: usize,
    layout: PngLayout,
    fill: &mut dyn FnMut(usize, &mut [u8]),
) -> Result<()> {
    let (w, h) = (
        u32::try_from(width).map_err(|_| Error::invalid(path, "image too wide for PNG"))?,
        u32::try_from(height).map_err(|_| Error::invalid(path, "image too tall for PNG"))?,
    );
    let encode = |e: ::png::EncodingError| match e {
        ::png::EncodingError::IoError(io) => Error::write(path, io),
        other => Error::encode(path, other),
    };
    write_atomic(path, |out| {
        let mut encoder = ::png::Encoder::new(out, w, h);
        let (colour, depth) = layout.png();
        encoder.set_color(colour);
        encoder.set_depth(depth);
        encoder.set_compression(::png::Compression::Fast);
        encoder.set_filter(::png::Filter::Adaptive);
        let mut writer = encoder.write_header().map_err(encode)?;
        let mut stream = writer.stream_writer().map_err(encode)?;
        let mut row = vec![0u8; width * layout.pixel_bytes()];
        for y in 0..height {
            fill(y, &mut row);
            std::io::Write::write_all(&mut stream, &row).map_err(|e| Error::write(path, e))?;
        }
        stream.finish().map_err(encode)?;
        writer.finish().map_err(encode)
    })
}

/// The file under a [`PngRows`] encoder: writes through a buffer and keeps the first error,
/// the closing ones included (the encoder's owned writer ends the file when dropped, where an
/// error would otherwise be lost).
struct Sink {
    w: BufWriter<File>,
    error: Rc<RefCell<Option<std::io::Error>>>,
}

impl Sink {
    fn keep<T>(&self, r: std::io::Result<T>) -> std::io::Result<T> {
        if let Err(e) = &r {
            let mut slot = self.error.borrow_mut();
            if slot.is_none() {
                *slot = Some(std::io::Error::new(e.kind(), e.to_string()));
            }
        }
        r
    }
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let r = self.w.write(buf);
        self.keep(r)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        let r = self.w.flush();
        self.keep(r)
    }
}

impl Drop for Sink {
    fn drop(&mut self) {
        let r = self.w.flush();
        let _ = self.keep(r);
    }
}

/// A PNG written a row at a time, top to bottom, and renamed into place by
/// [`PngRows::finish`] (dropped unfinished, nothing is left behind): a picture of a map that
/// is never whole in memory. Encoded as `write_png_rows` does, to the same bytes.
pub struct PngRows {
    path: PathBuf,
    guard: Option<TempFile>,
    stream: Option<::png::StreamWriter<'static, Sink>>,
    error: Rc<RefCell<Option<std::io::Error>>>,
    row: Vec<u8>,
    rows_left: usize,
}

impl PngRows {
    /// An 8-bit RGB picture (rows of `3 * width` bytes).
    pub fn rgb8(path: &Path, width: usize, height: usize) -> Result<Self> {
        Self::create(path, width, height, PngLayout::Rgb8)
    }

    /// A 16-bit RGB picture (rows of `6 * width` bytes, big-endian).
    pub fn rgb16(path: &Path, width: usize, height: usize) -> Result<Self> {
        Self::create(path, width, height, PngLayout::Rgb16)
    }

    fn create(path: &Path, width: usize, height: usize, layout: PngLayout) -> Result<Self> {
        let (w, h) = (
            u32::try_from(width).map_err(|_| Error::invalid(path, "image too wide for PNG"))?,
            u32::try_from(height).map_err(|_| Error::invalid(path, "image too tall for PNG"))?,
        );
        let (guard, file) = TempFile::create(path)?;
        let error = Rc::new(RefCell::new(None));
        let sink = Sink {
            w: BufWriter::new(file),
            error: error.clone(),
        };
        let encode = |e| png_error(path, e);
        let mut encoder = ::png::Encoder::new(sink, w, h);
        let (colour, depth) = layout.png();
        encoder.set_color(colour);
        encoder.set_depth(depth);
        encoder.set_compression(::png::Compression::Fast);
        encoder.set_filter(::png::Filter::Adaptive);
        let stream = encoder
            .write_header()
            .and_then(|w| w.into_stream_writer())
            .map_err(encode)?;
        Ok(Self {
            path: path.to_path_buf(),
            guard: Some(guard),
            stream: Some(stream),
            error,
            row: vec![0u8; width * layout.pixel_bytes()],
            rows_left: height,
        })
    }

    /// Writes the next row: `fill` sets its bytes (all of them: the buffer holds the previous
    /// row's).
    pub fn push(&mut self, fill: impl FnOnce(&mut [u8])) -> Result<()> {
        let Some(stream) = self.stream.as_mut().filter(|_| self.rows_left > 0) else {
            return Err(Error::invalid(
                &self.path,
                "more rows than the PNG's height",
            ));
        };
        fill(&mut self.row);
        stream
            .write_all(&self.row)
            .map_err(|e| Error::write(&self.path, e))?;
        self.rows_left -= 1;
        Ok(())
    }

    /// Ends the PNG (every row written) and renames it into place.
    pub fn finish(mut self) -> Result<()> {
        if self.rows_left > 0 {
            return Err(Error::invalid(
                &self.path,
                format!("{} rows of the PNG not written", self.rows_left),
            ));
        }
        if let Some(stream) = self.stream.take() {
            // Ends the data and, dropping the owned writer, the file (closed by now).
            stream.finish().map_err(|e| png_error(&self.path, e))?;
        }
        if let Some(e) = self.error.borrow_mut().take() {
            return Err(Error::write(&self.path, e));
        }
        match self.guard.take() {
            Some(g) => g.commit(),
            None => Ok(()),
        }
    }
}

/// An encoder error as this crate's, naming `path`.
fn png_error(path: &Path, e: ::png::EncodingError) -> Error {
    match e {
        ::png::EncodingError::IoError(io) => Error::write(path, io),
        other => Error::encode(path, other),
    }
}

/// Encodes raw pixel bytes as PNG (`bytes` native-endian for 16-bit layouts).
pub(crate) fn write_png(
    path: &Path,
    width: usize,
    height: usize,
    bytes: &[u8],
    layout: PngLayout,
) -> Result<()> {
    let row = width * layout.pixel_bytes();
    check_len(path, width, height, layout.pixel_bytes(), bytes.len())?;
    let sixteen = matches!(layout, PngLayout::La16 | PngLayout::Rgb16);
    write_png_rows(path, width, height, layout, &mut |y, out| {
        let src = &bytes[y * row..(y + 1) * row];
        if sixteen {
            for (o, i) in out.chunks_exact_mut(2).zip(src.chunks_exact(2)) {
                o.copy_from_slice(&u16::from_ne_bytes([i[0], i[1]]).to_be_bytes());
            }
        } else {
            out.copy_from_slice(src);
        }
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
    write_png16_rgb_with(path, width, height, rgb, &|v| v)
}

/// Writes interleaved RGB as a 16-bit linear PNG of `value(rgb)` per pixel (clamped to
/// `[0, 1]`; `NaN` as 0), converted a row at a time.
pub(crate) fn write_png16_rgb_with(
    path: &Path,
    width: usize,
    height: usize,
    rgb: &[f32],
    value: &dyn Fn([f32; 3]) -> [f32; 3],
) -> Result<()> {
    check_len(path, width, height, 3, rgb.len())?;
    write_png_rows(path, width, height, PngLayout::Rgb16, &mut |y, row| {
        rgb16_row(&rgb[y * width * 3..(y + 1) * width * 3], value, row)
    })
}

/// One row of a 16-bit RGB PNG (big-endian) of `value(rgb)` per pixel of the interleaved
/// `src`, clamped to `[0, 1]` (`NaN` as 0).
pub(crate) fn rgb16_row(src: &[f32], value: &dyn Fn([f32; 3]) -> [f32; 3], row: &mut [u8]) {
    for (o, p) in row.chunks_exact_mut(6).zip(src.chunks_exact(3)) {
        let v = value([p[0], p[1], p[2]]);
        for c in 0..3 {
            let q = quantise(v[c], 65535.0) as u16;
            o[2 * c..2 * c + 2].copy_from_slice(&q.to_be_bytes());
        }
    }
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
    write_png_rows(path, width, height, PngLayout::Rgb8, &mut |y, row| {
        let src = &rgb[y * width * 3..(y + 1) * width * 3];
        for (o, &v) in row.iter_mut().zip(src) {
            let v = if srgb_encode && !v.is_nan() {
                linear_to_srgb(v.clamp(0.0, 1.0))
            } else {
                v
            };
            *o = quantise(v, 255.0) as u8;
        }
    })
}
