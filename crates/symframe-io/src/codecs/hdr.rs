//! Radiance RGBE (`.hdr`) read a scan line at a time: the header is read by the `image`
//! crate's decoder (the same checks and errors as a whole decode), the scan lines here, as that
//! decoder reads them (flat, run-length encoded per component, or the old run-length form), and
//! converted to the same `f32` samples bit for bit.

use std::io::{BufReader, Read};
use std::path::Path;

use super::io_err;
use crate::error::{Error, Result};
use crate::limits;

/// A Radiance file read a scan line at a time: what it holds is its file buffer, one scan line
/// of RGBE pixels and one of `f32` RGB.
pub(crate) struct HdrRows {
    file: BufReader<std::fs::File>,
    width: usize,
    height: usize,
    line: Vec<[u8; 4]>,
    row: Vec<f32>,
}

/// The errors of the `image` crate as this crate's, naming `path`.
fn image_err(path: &Path, e: ::image::ImageError) -> Error {
    use ::image::ImageError;
    match e {
        ImageError::IoError(io) => io_err(path, io),
        ImageError::Unsupported(u) => Error::unsupported(path, u.to_string()),
        ImageError::Limits(l) => Error::limits(path, l.to_string()),
        other => Error::decode(path, other),
    }
}

impl HdrRows {
    /// Opens the Radiance file `path` (`len` bytes): its header is read, `check(width,
    /// height)` called with the size it declares, then the size checked against the limits.
    pub(crate) fn open(
        path: &Path,
        file: std::fs::File,
        len: u64,
        check: &dyn Fn((usize, usize)) -> Result<()>,
    ) -> Result<Self> {
        use ::image::ImageDecoder;
        let mut file = BufReader::new(file);
        // The header is read byte by byte: the file is left at the first scan line.
        let (w, h) = ::image::codecs::hdr::HdrDecoder::new(&mut file)
            .map_err(|e| image_err(path, e))?
            .dimensions();
        check((w as usize, h as usize))?;
        limits::check_image_size(path, "HDR header", w as u64, h as u64, len)?;
        Ok(Self {
            file,
            width: w as usize,
            height: h as usize,
            line: Vec::new(),
            row: Vec::new(),
        })
    }

    /// Width and height.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// What the reader holds: its file buffer and a scan line twice.
    pub(crate) fn resident_bytes(&self) -> usize {
        (8 << 10) + 16 * self.width
    }

    /// The next scan line, as `width * 3` linear RGB samples.
    pub(crate) fn next_row(&mut self, path: &Path) -> Result<&[f32]> {
        let w = self.width;
        self.line.resize(w, [0; 4]);
        read_scanline(&mut self.file, &mut self.line).map_err(|e| match e {
            LineError::Io(io) => io_err(path, io),
            LineError::Bad(m) => Error::decode(path, m),
        })?;
        self.row.resize(3 * w, 0.0);
        for (o, p) in self.row.chunks_exact_mut(3).zip(&self.line) {
            o.copy_from_slice(&rgbe_to_f32(*p));
        }
        Ok(&self.row)
    }
}

/// An RGBE pixel as linear RGB, as the `image` crate converts it: `c * 2^(e - 136)`, 0 for
/// `e = 0`.
fn rgbe_to_f32([r, g, b, e]: [u8; 4]) -> [f32; 3] {
    // 2^(e - 128) built directly (e = 1 is subnormal; e = 0 gives 0), then divided by 256.
    let exp = f32::from_bits(if e > 1 {
        ((e - 1) as u32) << 23
    } else {
        (e as u32) << 22
    }) * 0.003_906_25;
    [exp * r as f32, exp * g as f32, exp * b as f32]
}

/// Why a scan line could not be read.
enum LineError {
    Io(std::io::Error),
    Bad(String),
}

impl From<std::io::Error> for LineError {
    fn from(e: std::io::Error) -> Self {
        LineError::Io(e)
    }
}

/// A scan line's wrong length, as the message names it.
fn wrong_length(got: usize, width: usize) -> LineError {
    LineError::Bad(format!(
        "wrong length of a decoded scan line: {got}, expected {width}"
    ))
}

fn read_byte<R: Read>(r: &mut R) -> std::io::Result<u8> {
    let mut b = [0u8];
    r.read_exact(&mut b)?;
    Ok(b[0])
}

fn read_rgbe<R: Read>(r: &mut R) -> std::io::Result<[u8; 4]> {
    let mut b = [0u8; 4];
    r.read_exact(&mut b)?;
    Ok(b)
}

/// Reads one scan line into `buf` (not empty): per-component run-length encoded when it starts
/// with `2, 2, x < 128`, else flat or in the old run-length form.
fn read_scanline<R: Read>(r: &mut R, buf: &mut [[u8; 4]]) -> std::result::Result<(), LineError> {
    let first = read_rgbe(r)?;
    if first[0] == 2 && first[1] == 2 && first[2] < 128 {
        for c in 0..4 {
            decode_component(r, buf, c)?;
        }
        Ok(())
    } else {
        decode_old_rle(r, first, buf)
    }
}

/// One component of a run-length encoded scan line: a count up to 128 of literal bytes, or
/// `128 + n` and a byte repeated `n` times.
fn decode_component<R: Read>(
    r: &mut R,
    buf: &mut [[u8; 4]],
    c: usize,
) -> std::result::Result<(), LineError> {
    let width = buf.len();
    let mut bytes = [0u8; 128];
    let mut pos = 0;
    while pos < width {
        let rl = read_byte(r)? as usize;
        if rl <= 128 {
            if pos + rl > width {
                return Err(wrong_length(pos + rl, width));
            }
            r.read_exact(&mut bytes[..rl])?;
            for (px, &v) in buf[pos..pos + rl].iter_mut().zip(&bytes[..rl]) {
                px[c] = v;
            }
            pos += rl;
        } else {
            let rl = rl - 128;
            if pos + rl > width {
                return Err(wrong_length(pos + rl, width));
            }
            let v = read_byte(r)?;
            for px in &mut buf[pos..pos + rl] {
                px[c] = v;
            }
            pos += rl;
        }
    }
    Ok(())
}

/// A scan line flat or in the old run-length form: a pixel `1, 1, 1, n` repeats the previous
/// one `n` times, consecutive markers multiplying by 256.
fn decode_old_rle<R: Read>(
    r: &mut R,
    first: [u8; 4],
    buf: &mut [[u8; 4]],
) -> std::result::Result<(), LineError> {
    let width = buf.len();
    let marker = |p: [u8; 4]| (p[..3] == [1, 1, 1]).then_some(p[3] as usize);
    if marker(first).is_some() {
        return Err(LineError::Bad(
            "the first pixel of a scan line is a run-length marker".into(),
        ));
    }
    buf[0] = first;
    let (mut x, mut mult, mut prev) = (1usize, 1usize, first);
    while x < width {
        let p = read_rgbe(r)?;
        if let Some(rl) = marker(p) {
            let rl = rl.saturating_mul(mult);
            mult = mult.saturating_mul(256);
            let end = x.saturating_add(rl);
            if end > width {
                return Err(wrong_length(end, width));
            }
            buf[x..end].fill(prev);
            x = end;
        } else {
            mult = 1;
            prev = p;
            buf[x] = p;
            x += 1;
        }
    }
    Ok(())
}
