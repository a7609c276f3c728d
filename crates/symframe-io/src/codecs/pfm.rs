//! PFM (portable float map): parsing, reading and writing.

use std::io::Write;
use std::path::Path;

use super::{check_len, Raw, RawImage};
use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::limits;

/// A decoded PFM: size, channels (1 or 3) and linear samples, row 0 at the top.
pub(super) type Pfm = (usize, usize, usize, Vec<f32>);

/// Reads the next whitespace-delimited header token of a PFM, at most 64 bytes long.
pub(super) fn pfm_token<'a>(
    bytes: &'a [u8],
    pos: &mut usize,
) -> std::result::Result<&'a str, String> {
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

/// A PFM header: size, channels (1 or 3), byte order, and where the pixel data starts.
#[derive(Debug, Clone, Copy)]
pub(super) struct PfmHeader {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) channels: usize,
    pub(super) little: bool,
    pub(super) data_at: usize,
}

impl PfmHeader {
    /// Parses the header at the start of `bytes`: `PF` (RGB) or `Pf` (grey), width, height and
    /// scale (negative: little-endian; its magnitude is ignored), then one whitespace byte.
    pub(super) fn parse(bytes: &[u8]) -> std::result::Result<Self, String> {
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
        if width > limits::MAX_SIDE
            || height > limits::MAX_SIDE
            || width * height > limits::MAX_PIXELS
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
        Ok(Self {
            width,
            height,
            channels,
            little: scale < 0.0,
            // The single whitespace byte after the scale.
            data_at: pos + 1,
        })
    }

    /// Samples of the image.
    pub(super) fn samples(&self) -> std::result::Result<usize, String> {
        self.width
            .checked_mul(self.height)
            .and_then(|n| n.checked_mul(self.channels))
            .ok_or_else(|| "image dimensions overflow".to_string())
    }

    /// Checks that `body` bytes of pixel data hold every sample.
    pub(super) fn check_body(&self, body: u64) -> std::result::Result<(), String> {
        let count = self.samples()?;
        let truncated = match count.checked_mul(4) {
            Some(need) => body < need as u64,
            None => true,
        };
        if truncated {
            let (w, h, c) = (self.width, self.height, self.channels);
            return Err(format!(
                "truncated: {w}x{h}x{c} needs {} bytes of pixels, file has {body}",
                count.saturating_mul(4),
            ));
        }
        Ok(())
    }

    /// A stored sample's value.
    pub(super) fn value(&self, b: &[u8]) -> f32 {
        let b = [b[0], b[1], b[2], b[3]];
        if self.little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    }
}

/// Parses a whole PFM file from memory ([`PfmHeader`], then rows of 32-bit floats stored
/// bottom to top).
pub(super) fn parse_pfm(bytes: &[u8]) -> std::result::Result<Pfm, String> {
    let hd = PfmHeader::parse(bytes)?;
    let count = hd.samples()?;
    let body = &bytes[hd.data_at..];
    hd.check_body(body.len() as u64)?;
    let (height, row) = (hd.height, hd.width * hd.channels);
    let mut data = vec![0.0f32; count];
    for (i, b) in body[..count * 4].chunks_exact(4).enumerate() {
        let (file_row, col) = (i / row, i % row);
        data[(height - 1 - file_row) * row + col] = hd.value(b);
    }
    Ok((hd.width, height, hd.channels, data))
}

/// A PFM message as this crate's error: "exceeds limits: ..." a limits error, others decoding.
pub(super) fn pfm_error(path: &Path, m: String) -> Error {
    match m.strip_prefix("exceeds limits: ") {
        Some(m) => Error::limits(path, m),
        None => Error::decode(path, m),
    }
}

/// The width and height a PFM file's header declares (header only; no pixel is read).
pub(super) fn pfm_size(path: &Path, bytes: &[u8]) -> Result<(usize, usize)> {
    let mut pos = 0;
    let mut next = || pfm_token(bytes, &mut pos).map_err(|m| Error::decode(path, m));
    if !matches!(next()?, "PF" | "Pf") {
        return Err(Error::decode(path, "not a PFM file"));
    }
    let mut dim = || -> Result<usize> {
        let t = next()?;
        t.parse::<usize>()
            .ok()
            .filter(|&v| v > 0)
            .ok_or_else(|| Error::decode(path, format!("bad size '{}'", t.escape_default())))
    };
    let w = dim()?;
    Ok((w, dim()?))
}

/// Reads a PFM as a raw float image.
pub(super) fn read_pfm_raw(path: &Path) -> Result<RawImage> {
    let bytes = super::read_image_file(path)?;
    pfm_raw(path, &bytes)
}

/// Decodes a PFM file's bytes as a raw float image.
pub(super) fn pfm_raw(path: &Path, bytes: &[u8]) -> Result<RawImage> {
    let (width, height, channels, data) = parse_pfm(bytes).map_err(|m| pfm_error(path, m))?;
    Ok(RawImage {
        width,
        height,
        channels,
        raw: Raw::F32(data),
    })
}

/// Reads a PFM file exactly as stored (no `NaN` marking): `(width, height, channels, data)`,
/// row 0 at the top. Use [`read_image`](super::read_image) for stack input.
pub fn read_pfm(path: &Path) -> Result<(usize, usize, usize, Vec<f32>)> {
    let img = read_pfm_raw(path)?;
    match img.raw {
        Raw::F32(d) => Ok((img.width, img.height, img.channels, d)),
        _ => unreachable!("PFM is always float"),
    }
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
