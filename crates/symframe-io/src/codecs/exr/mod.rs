//! OpenEXR: decoding the radiance layer, and writing float32 channels.
//!
//! Which channels are radiance: those of one layer, `R`, `G`, `B` (colour) or else `Y` (grey).
//! A channel's layer is its name before the last `.` (`beauty.R` is `R` of layer `beauty`),
//! in a multi-part file prefixed by its part's name; the unnamed default layer (`R`, `G`, `B`
//! or `Y` of a single-part file) is read unless [`DecodeOptions::exr_layer`] names another.
//! No default layer (only `albedo.R`, ..., `beauty.R`, ...) is an error that lists the
//! layers; a file without any `R`, `G`, `B` or `Y` channel (only `Z`, only `A`) is an error
//! that lists its channels.

use std::path::Path;

mod blocks;
mod write;

use super::{io_err, DecodeOptions, Raw, RawImage};
use crate::error::{Error, Result};
use crate::limits;
use blocks::{decompress_block, BlockLayout};

pub use write::{write_exr_channels, write_exr_rgb};
pub(crate) use write::{write_exr_interleaved, write_exr_pixels};

/// One layer of an EXR file: its name (`""` for the default layer), its part and its channels
/// (index in the part's channel list, name without the layer).
struct ExrLayerChannels {
    name: String,
    part: usize,
    channels: Vec<(usize, String)>,
}

impl ExrLayerChannels {
    /// The radiance channels of the layer: `R`, `G`, `B` (in that order), else `Y`.
    fn radiance(&self) -> Option<Vec<usize>> {
        let find = |want: &str| {
            self.channels
                .iter()
                .find(|(_, n)| n.eq_ignore_ascii_case(want))
                .map(|&(i, _)| i)
        };
        match (find("R"), find("G"), find("B"), find("Y")) {
            (Some(r), Some(g), Some(b), _) => Some(vec![r, g, b]),
            (_, _, _, Some(y)) => Some(vec![y]),
            _ => None,
        }
    }

    /// How a message lists it: `beauty (R, G, B)`, `default layer (Z)`.
    fn describe(&self) -> String {
        let names: Vec<&str> = self.channels.iter().map(|(_, n)| n.as_str()).collect();
        let name = if self.name.is_empty() {
            "default layer"
        } else {
            &self.name
        };
        format!("{name} ({})", names.join(", "))
    }
}

/// The layers of the non-deep parts of an EXR file, in file order (a part's name prefixes its
/// layers when the file has several parts).
fn exr_layers(headers: &[exr::meta::header::Header]) -> Vec<ExrLayerChannels> {
    let multi = headers.len() > 1;
    let mut out: Vec<ExrLayerChannels> = Vec::new();
    for (part, h) in headers.iter().enumerate().filter(|(_, h)| !h.deep) {
        let part_name = h
            .own_attributes
            .layer_name
            .as_ref()
            .map(|t| t.to_string())
            .filter(|_| multi);
        for (i, c) in h.channels.list.iter().enumerate() {
            let full = c.name.to_string();
            let (prefix, base) = match full.rsplit_once('.') {
                Some((p, b)) => (p.to_string(), b.to_string()),
                None => (String::new(), full.clone()),
            };
            let name = match (&part_name, prefix.is_empty()) {
                (Some(p), true) => p.clone(),
                (Some(p), false) => format!("{p}.{prefix}"),
                (None, _) => prefix,
            };
            match out.iter_mut().find(|l| l.part == part && l.name == name) {
                Some(l) => l.channels.push((i, base)),
                None => out.push(ExrLayerChannels {
                    name,
                    part,
                    channels: vec![(i, base)],
                }),
            }
        }
    }
    out
}

/// The part and the channels (indices in that part's list) of the radiance to decode: the
/// layer `opts.exr_layer` names, else the default layer (see the module's documentation).
fn choose_layer(
    path: &Path,
    headers: &[exr::meta::header::Header],
    opts: &DecodeOptions,
) -> Result<(usize, Vec<usize>)> {
    if headers.iter().all(|h| h.deep) {
        return Err(Error::unsupported(path, "EXR with deep data only"));
    }
    let layers = exr_layers(headers);
    let listed = || {
        layers
            .iter()
            .map(ExrLayerChannels::describe)
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(want) = &opts.exr_layer {
        let Some(layer) = layers.iter().find(|l| &l.name == want) else {
            return Err(Error::invalid(
                path,
                format!("no EXR layer '{want}' (layers: {})", listed()),
            ));
        };
        return match layer.radiance() {
            Some(c) => Ok((layer.part, c)),
            None => Err(Error::invalid(
                path,
                format!(
                    "EXR layer {} has no radiance channel (R, G, B or Y)",
                    layer.describe()
                ),
            )),
        };
    }
    if let Some((layer, c)) = layers
        .iter()
        .filter(|l| l.name.is_empty())
        .find_map(|l| Some((l, l.radiance()?)))
    {
        return Ok((layer.part, c));
    }
    let with_radiance: Vec<&str> = layers
        .iter()
        .filter(|l| l.radiance().is_some())
        .map(|l| l.name.as_str())
        .collect();
    if with_radiance.is_empty() {
        return Err(Error::invalid(
            path,
            format!(
                "no radiance channel (R, G, B or Y) in the EXR (channels: {})",
                listed()
            ),
        ));
    }
    Err(Error::invalid(
        path,
        format!(
            "no default EXR layer (R, G, B or Y without a layer name); layers: {}; choose \
             the radiance with --exr-layer NAME (one of {})",
            listed(),
            with_radiance.join(", ")
        ),
    ))
}

/// The width and height of the layer an EXR file's radiance would be decoded from, read from
/// its headers alone (declared sizes checked as [`read_exr`] does).
pub(super) fn exr_size(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<(usize, usize)> {
    let meta = read_meta(path, bytes)?;
    let (part, _) = choose_layer(path, &meta.headers, opts)?;
    let size = meta.headers[part].layer_size;
    Ok((size.width(), size.height()))
}

/// The errors of the `exr` crate as this crate's, naming `path`.
fn exr_err(path: &Path, e: exr::error::Error) -> Error {
    match e {
        exr::error::Error::Io(io) => io_err(path, io),
        exr::error::Error::NotSupported(m) => Error::unsupported(path, format!("EXR {m}")),
        other => Error::decode(path, other),
    }
}

/// The headers of an EXR file, every part's declared size checked ([`crate::limits`]).
fn read_meta(path: &Path, bytes: &[u8]) -> Result<exr::meta::MetaData> {
    // The declared sizes first, from the headers as written (the block reader's own
    // validation would otherwise answer a forged size with a less useful error).
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| exr_err(path, e))?;
    check_sizes(path, &meta.headers, bytes.len() as u64)?;
    Ok(meta)
}

/// Checks every part's declared size against the limits and the file's length `len`.
fn check_sizes(path: &Path, headers: &[exr::meta::header::Header], len: u64) -> Result<()> {
    for h in headers.iter() {
        let size = h.layer_size;
        limits::check_image_size(
            path,
            "EXR header",
            size.width() as u64,
            size.height() as u64,
            len,
        )?;
    }
    Ok(())
}

/// Decodes an OpenEXR file's radiance layer (see the module's documentation) at full
/// resolution (single-threaded), after checking every part's declared size
/// ([`crate::limits`]).
///
/// Reads the file's blocks with `exr`'s block API and converts each decompressed block's lines
/// straight into the interleaved output, instead of building `exr`'s per-channel image first:
/// no per-channel sample vectors, no second copy (its gain: docs/performance.md, "Decoding").
pub(super) fn read_exr(path: &Path, bytes: &[u8], opts: &DecodeOptions) -> Result<RawImage> {
    use exr::block::reader::ChunksReader;
    use std::io::Cursor;
    let eerr = |e: exr::error::Error| exr_err(path, e);
    read_meta(path, bytes)?;
    let reader = exr::block::read(Cursor::new(bytes), false).map_err(eerr)?;
    let (layer, picked) = choose_layer(path, reader.headers(), opts)?;
    let header = &reader.headers()[layer];
    let (width, height) = (header.layer_size.width(), header.layer_size.height());
    let lines = BlockLayout::new(path, header, picked)?;
    let k = lines.picked.len();
    let mut data = vec![0.0f32; width * height * k];
    let chunks = reader
        .filter_chunks(false, |_, tile, block| {
            block.layer == layer && tile.is_largest_resolution_level()
        })
        .map_err(eerr)?;
    let mut chunks = chunks;
    while let Some(chunk) = chunks.read_next_chunk() {
        let block = decompress_block(chunk.map_err(eerr)?, chunks.meta_data()).map_err(eerr)?;
        lines
            .copy(&block, (width, height), &mut data, 0)
            .map_err(eerr)?;
    }
    Ok(RawImage {
        width,
        height,
        channels: k,
        raw: Raw::F32(data),
    })
}

/// An OpenEXR file's radiance layer read a row of blocks at a time from the file: a block of
/// scan lines (1 to 32 lines, by compression; 256 for DWAB) or a row of tiles. Each block is
/// found through the file's offset table (any line order), decompressed and converted as
/// [`read_exr`] converts it, and must be the block the table says it is. What it holds: the
/// part's offset table, one block as stored and decompressed, and the decoded row of blocks
/// ([`ExrRows::resident_bytes`]); a file of a few KB declaring a large image costs that, not
/// the image.
pub(crate) struct ExrRows {
    file: Positioned,
    meta: exr::meta::MetaData,
    part: usize,
    width: usize,
    height: usize,
    layout: BlockLayout,
    /// The part's offset table (level 0 first, in increasing y).
    offsets: Vec<u64>,
    /// Block width and height (the tile's; a scan-line block is the layer's width).
    block: (usize, usize),
    /// The decoded rows `[y0, y0 + rows)`, interleaved picked channels.
    rows: Vec<f32>,
    y0: usize,
    held: usize,
}

impl ExrRows {
    /// Opens the EXR file `path` (`len` bytes); `check(width, height)` is called with the
    /// chosen layer's size before any block is read. The same checks and errors as
    /// [`read_exr`] (declared sizes, layer choice, subsampled channels).
    pub(crate) fn open(
        path: &Path,
        file: std::fs::File,
        len: u64,
        opts: &DecodeOptions,
        check: &dyn Fn((usize, usize)) -> Result<()>,
    ) -> Result<Self> {
        use exr::meta::BlockDescription;
        use std::io::{BufReader, Seek, SeekFrom};
        let eerr = |e: exr::error::Error| exr_err(path, e);
        let mut file = BufReader::new(file);
        // The declared sizes first, as `read_meta` checks them.
        let meta = exr::meta::MetaData::read_from_buffered(&mut file, false).map_err(eerr)?;
        check_sizes(path, &meta.headers, len)?;
        let (part, picked) = choose_layer(path, &meta.headers, opts)?;
        let size = meta.headers[part].layer_size;
        check((size.width(), size.height()))?;
        // Then as `exr::block::read` reads them (validated), and the offset tables after them.
        file.seek(SeekFrom::Start(0))
            .map_err(|e| Error::read(path, e))?;
        let mut peek = exr::io::PeekRead::new(exr::io::Tracking::new(&mut file));
        let meta = exr::meta::MetaData::read_from_buffered(&mut peek, true).map_err(eerr)?;
        exr::meta::MetaData::validate(&meta.headers, false).map_err(eerr)?;
        let mut tables =
            exr::meta::MetaData::read_offset_tables(&mut peek, &meta.headers).map_err(eerr)?;
        let (part, picked) = match choose_layer(path, &meta.headers, opts)? {
            (p, c) if p == part && c == picked => (p, c),
            _ => return Err(Error::decode(path, "EXR headers read differently twice")),
        };
        let header = &meta.headers[part];
        let layout = BlockLayout::new(path, header, picked)?;
        let (width, height) = (header.layer_size.width(), header.layer_size.height());
        let block = match header.blocks {
            BlockDescription::ScanLines => (width, header.compression.scan_lines_per_block()),
            BlockDescription::Tiles(t) => (t.tile_size.width(), t.tile_size.height()),
        };
        if block.0 == 0 || block.1 == 0 {
            return Err(Error::decode(path, "EXR tiles of zero size"));
        }
        let offsets = std::mem::take(&mut tables[part]);
        let across = width.div_ceil(block.0);
        if offsets.len() < across * height.div_ceil(block.1) {
            return Err(Error::decode(
                path,
                "EXR offset table shorter than its blocks",
            ));
        }
        Ok(Self {
            file: Positioned {
                inner: file,
                pos: None,
            },
            meta,
            part,
            width,
            height,
            layout,
            offsets,
            block,
            rows: Vec::new(),
            y0: 0,
            held: 0,
        })
    }

    /// Width and height of the layer read.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Samples a pixel (3 or 1).
    pub(crate) fn channels(&self) -> usize {
        self.layout.picked.len()
    }

    /// What the reader holds: the offset table, one block stored and decompressed (every
    /// channel), and the decoded row of blocks.
    pub(crate) fn resident_bytes(&self) -> usize {
        let (bw, bh) = self.block;
        8 * self.offsets.len()
            + 2 * bw * bh * self.layout.pixel_bytes
            + 4 * self.width * bh * self.channels()
            + (8 << 10)
    }

    /// Row `y` (rows are asked for in increasing order): `width * channels` samples.
    pub(crate) fn row(&mut self, path: &Path, y: usize) -> Result<&[f32]> {
        if y >= self.y0 + self.held || y < self.y0 {
            self.read_block_row(path, y / self.block.1)?;
        }
        let n = self.width * self.channels();
        let at = (y - self.y0) * n;
        Ok(&self.rows[at..at + n])
    }

    /// Reads and decodes the blocks of block row `r`.
    fn read_block_row(&mut self, path: &Path, r: usize) -> Result<()> {
        let eerr = |e: exr::error::Error| exr_err(path, e);
        let (bw, bh) = self.block;
        let y0 = r * bh;
        let held = bh.min(self.height - y0);
        let k = self.channels();
        self.rows.clear();
        self.rows.resize(self.width * held * k, 0.0);
        let across = self.width.div_ceil(bw);
        for x in 0..across {
            self.file
                .seek_to(self.offsets[r * across + x])
                .map_err(|e| Error::read(path, e))?;
            let chunk = exr::block::chunk::Chunk::read(&mut self.file, &self.meta).map_err(eerr)?;
            let block = decompress_block(chunk, &self.meta).map_err(eerr)?;
            let want = (x * bw, y0, bw.min(self.width - x * bw), held);
            let got = &block.index;
            if got.layer != self.part
                || got.level.x() != 0
                || got.level.y() != 0
                || (
                    got.pixel_position.x(),
                    got.pixel_position.y(),
                    got.pixel_size.width(),
                    got.pixel_size.height(),
                ) != want
            {
                return Err(Error::decode(
                    path,
                    format!(
                        "the EXR offset table's block at ({}, {y0}) points at another block",
                        x * bw
                    ),
                ));
            }
            self.layout
                .copy(&block, (self.width, self.height), &mut self.rows, y0)
                .map_err(eerr)?;
        }
        self.y0 = y0;
        self.held = held;
        Ok(())
    }
}

/// A buffered file that knows its position, so that reading blocks stored one after the
/// other (as most files store them) costs no seek.
struct Positioned {
    inner: std::io::BufReader<std::fs::File>,
    /// The position, once known.
    pos: Option<u64>,
}

impl Positioned {
    /// Moves to byte `offset`: within the buffer or not at all when it can.
    fn seek_to(&mut self, offset: u64) -> std::io::Result<()> {
        use std::io::Seek;
        match self.pos {
            Some(p) if p == offset => {}
            Some(p) if offset > p && offset - p < (1 << 20) => {
                self.inner.seek_relative((offset - p) as i64)?
            }
            _ => {
                self.inner.seek(std::io::SeekFrom::Start(offset))?;
            }
        }
        self.pos = Some(offset);
        Ok(())
    }
}

impl std::io::Read for Positioned {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self.inner.read(buf) {
            Ok(n) => {
                if let Some(p) = &mut self.pos {
                    *p += n as u64;
                }
                Ok(n)
            }
            Err(e) => {
                self.pos = None;
                Err(e)
            }
        }
    }
}
