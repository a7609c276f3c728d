//! TIFF decoding: 8/16-bit unsigned and 16/32/64-bit float, grey or RGB; whole, or a row of
//! strips or tiles at a time ([`TiffRows`]).

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

/// A TIFF decoder over `reader` with the crate's decoding-buffer limit.
fn decoder<R: std::io::Read + std::io::Seek>(
    path: &Path,
    reader: R,
) -> Result<tiff::decoder::Decoder<R>> {
    let mut lim = tiff::decoder::Limits::default();
    lim.decoding_buffer_size = limits::MAX_DECODED_BYTES as usize;
    Ok(tiff::decoder::Decoder::new(reader)
        .map_err(|e| tiff_err(path, e))?
        .with_limits(lim))
}

/// The channels and bits per sample of a TIFF colour type the readers take (grey, grey+alpha,
/// RGB or RGBA, of 8, 16, 32 or 64 bits); an error naming `path` for any other.
fn layout(path: &Path, ct: tiff::ColorType) -> Result<(usize, u8)> {
    use tiff::ColorType;
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
    Ok((channels, bits))
}

/// Decodes a TIFF (8/16-bit unsigned or 16/32/64-bit float; grey, grey+alpha, RGB or RGBA);
/// returns its ICC profile too, when it has one.
pub(super) fn read_tiff(path: &Path, bytes: &[u8]) -> Result<(RawImage, Option<Vec<u8>>)> {
    use tiff::decoder::DecodingResult;
    use tiff::tags::Tag;
    let terr = |e| tiff_err(path, e);
    let mut dec = decoder(path, std::io::Cursor::new(bytes))?;
    let (w, h) = dec.dimensions().map_err(terr)?;
    limits::check_image_size(path, "TIFF header", w as u64, h as u64, bytes.len() as u64)?;
    let (channels, bits) = layout(path, dec.colortype().map_err(terr)?)?;
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

/// A TIFF read a row of its chunks (a strip, or a row of tiles; of every plane when planar)
/// at a time from the file, each chunk decoded by the `tiff` crate as [`read_tiff`] decodes the
/// whole image, to the same samples: what it holds is one row of chunks in the file's sample
/// type and one chunk being decoded ([`TiffRows::resident_bytes`]), not the image (a file whose
/// strip is the whole image, written as one strip, still costs its image).
pub(crate) struct TiffRows {
    dec: tiff::decoder::Decoder<std::io::BufReader<std::fs::File>>,
    width: usize,
    height: usize,
    channels: usize,
    bits: usize,
    planar: bool,
    tiled: bool,
    /// Chunk width and height (a strip: the image's width; its height at most the image's).
    chunk: (usize, usize),
    /// The decoded rows `[y0, y0 + held)`.
    band: Raw,
    y0: usize,
    held: usize,
}

/// The errors of the `tiff` crate as this crate's, naming `path`.
fn tiff_err(path: &Path, e: tiff::TiffError) -> Error {
    use tiff::TiffError;
    match e {
        TiffError::IoError(io) => io_err(path, io),
        TiffError::UnsupportedError(u) => Error::unsupported(path, format!("TIFF {u}")),
        TiffError::LimitsExceeded => Error::limits(path, "TIFF exceeds the decoder's limits"),
        other => Error::decode(path, other),
    }
}

impl TiffRows {
    /// Opens the TIFF file `path` (`len` bytes): `check(width, height)` is called with its
    /// declared size before anything else is read; then the same checks as [`read_tiff`], and
    /// its first row of chunks is decoded (its sample type decides the reader's). Returns the
    /// reader and the file's ICC profile, when it has one.
    pub(crate) fn open(
        path: &Path,
        file: std::fs::File,
        len: u64,
        check: &dyn Fn((usize, usize)) -> Result<()>,
    ) -> Result<(Self, Option<Vec<u8>>)> {
        use tiff::tags::Tag;
        let terr = |e| tiff_err(path, e);
        let mut dec = decoder(path, std::io::BufReader::new(file))?;
        let (w, h) = dec.dimensions().map_err(terr)?;
        check((w as usize, h as usize))?;
        limits::check_image_size(path, "TIFF header", w as u64, h as u64, len)?;
        let (channels, bits) = layout(path, dec.colortype().map_err(terr)?)?;
        let planar = channels > 1
            && matches!(
                dec.find_tag_unsigned::<u16>(Tag::PlanarConfiguration),
                Ok(Some(2))
            );
        let icc = dec.get_tag_u8_vec(Tag::IccProfile).ok();
        let tiled = dec.get_chunk_type() == tiff::decoder::ChunkType::Tile;
        let (cw, ch) = dec.chunk_dimensions();
        let (width, height) = (w as usize, h as usize);
        let chunk = (cw as usize, (ch as usize).min(height));
        if chunk.0 == 0 || chunk.1 == 0 {
            return Err(Error::decode(path, "TIFF chunks of zero size"));
        }
        let mut rows = Self {
            dec,
            width,
            height,
            channels,
            bits: bits as usize,
            planar,
            tiled,
            chunk,
            band: Raw::U8(Vec::new()),
            y0: 0,
            held: 0,
        };
        if width > 0 && height > 0 {
            rows.read_chunk_row(path, 0)?;
        }
        Ok((rows, icc))
    }

    /// Width and height.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Samples a pixel.
    pub(crate) fn channels(&self) -> usize {
        self.channels
    }

    /// The sample type the rows are given in.
    pub(crate) fn sample_type(&self) -> super::SampleType {
        self.band.sample_type()
    }

    /// What the reader holds: its row of chunks, and one chunk as decoded and as converted.
    pub(crate) fn resident_bytes(&self) -> usize {
        let (cw, ch) = self.chunk;
        let per_pixel = if self.planar { 1 } else { self.channels };
        let band = match &self.band {
            Raw::U8(_) => 1,
            Raw::U16(_) => 2,
            Raw::F32(_) => 4,
        } * self.width
            * ch
            * self.channels;
        band + cw * ch * per_pixel * (self.bits / 8 + 4) + (8 << 10)
    }

    /// Row `y` (rows are asked for in increasing order), `width * channels` samples.
    pub(crate) fn row(&mut self, path: &Path, y: usize) -> Result<super::RawRun<'_>> {
        if y < self.y0 || y >= self.y0 + self.held {
            self.read_chunk_row(path, y / self.chunk.1)?;
        }
        let n = self.width * self.channels;
        let at = (y - self.y0) * n;
        Ok(self.band.run(at..at + n))
    }

    /// Decodes row `r` of chunks (of every plane) into the band.
    fn read_chunk_row(&mut self, path: &Path, r: usize) -> Result<()> {
        use tiff::decoder::DecodingResult as D;
        let (cw, ch) = self.chunk;
        let y0 = r * ch;
        let held = ch.min(self.height - y0);
        let across = self.width.div_ceil(cw);
        let per_plane = across * self.height.div_ceil(ch);
        let (planes, per_pixel) = if self.planar {
            (self.channels, 1)
        } else {
            (1, self.channels)
        };
        let len = self.width * held * self.channels;
        for x in 0..across {
            let dw = cw.min(self.width - x * cw);
            for p in 0..planes {
                let index = p * per_plane + r * across + x;
                let index = u32::try_from(index)
                    .map_err(|_| Error::decode(path, "TIFF chunk index overflows"))?;
                let got = self.dec.read_chunk(index).map_err(|e| tiff_err(path, e))?;
                // A tile is stored whole, padded; the decoder gives its rows inside the image,
                // or all of them (the last row of tiles of a planar file's later planes).
                let tile_rows = self.tiled.then_some(ch);
                let place = Place {
                    width: self.width,
                    channels: self.channels,
                    x0: x * cw,
                    w: dw,
                    h: held,
                    tile_rows,
                    per_pixel,
                    plane: p,
                };
                let first = x == 0 && p == 0;
                let ok = match (got, &mut self.band) {
                    (D::U8(v), Raw::U8(b)) => place.copy(&v, b, len, first, |s| s),
                    (D::U16(v), Raw::U16(b)) => place.copy(&v, b, len, first, |s| s),
                    (D::F16(v), Raw::F32(b)) => place.copy(&v, b, len, first, f32::from),
                    (D::F32(v), Raw::F32(b)) => place.copy(&v, b, len, first, |s| s),
                    (D::F64(v), Raw::F32(b)) => place.copy(&v, b, len, first, |s| s as f32),
                    (got, band) if r == 0 && first => {
                        // The first chunk decides the sample type.
                        *band = match got {
                            D::U8(_) => Raw::U8(Vec::new()),
                            D::U16(_) => Raw::U16(Vec::new()),
                            D::F16(_) | D::F32(_) | D::F64(_) => Raw::F32(Vec::new()),
                            _ => {
                                return Err(Error::unsupported(
                                    path,
                                    format!(
                                        "TIFF sample format ({}-bit signed or 32/64-bit integer)",
                                        self.bits
                                    ),
                                ))
                            }
                        };
                        return self.read_chunk_row(path, r);
                    }
                    _ => Err("of another sample type than the first"),
                };
                ok.map_err(|m| Error::decode(path, format!("TIFF chunk {index}: {m}")))?;
            }
        }
        self.y0 = y0;
        self.held = held;
        Ok(())
    }
}

/// Where a decoded chunk goes in a band of rows.
struct Place {
    /// The band's width and samples a pixel.
    width: usize,
    channels: usize,
    /// The chunk's first column, width and height.
    x0: usize,
    w: usize,
    h: usize,
    /// A tile's height, when the chunk is a tile (see [`Place::copy`]).
    tile_rows: Option<usize>,
    /// The chunk's samples a pixel (1 for a plane of a planar file) and its plane.
    per_pixel: usize,
    plane: usize,
}

impl Place {
    /// Copies the chunk `src` (`h` rows of `w * per_pixel` samples; a tile's rows below the
    /// image too, as the decoder gives them for the last row of tiles of a planar file's later
    /// planes) into `band` (resized to `len` samples first when `first`), converting each
    /// sample with `f`.
    fn copy<S: Copy, T: Copy + Default>(
        &self,
        src: &[S],
        band: &mut Vec<T>,
        len: usize,
        first: bool,
        f: impl Fn(S) -> T,
    ) -> std::result::Result<(), &'static str> {
        if first {
            band.clear();
            band.resize(len, T::default());
        }
        let row = self.w * self.per_pixel;
        let whole_tile = self
            .tile_rows
            .is_some_and(|r| src.len() == row * r && r >= self.h);
        if (src.len() != row * self.h && !whole_tile) || band.len() != len {
            return Err("not the size its place in the image implies");
        }
        for (y, s) in src.chunks_exact(row).take(self.h).enumerate() {
            let at = (y * self.width + self.x0) * self.channels;
            let dst = &mut band[at..at + self.w * self.channels];
            if self.per_pixel == self.channels {
                for (d, &v) in dst.iter_mut().zip(s) {
                    *d = f(v);
                }
            } else {
                for (d, &v) in dst
                    .iter_mut()
                    .skip(self.plane)
                    .step_by(self.channels)
                    .zip(s)
                {
                    *d = f(v);
                }
            }
        }
        Ok(())
    }
}
