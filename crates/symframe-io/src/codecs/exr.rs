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

use super::{check_len, io_err, DecodeOptions, Raw, RawImage};
use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::limits;

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

/// How the lines of a decompressed EXR block are laid out: every channel's sample type and
/// size, in the part's channel order, and the radiance channels picked from them.
struct BlockLayout {
    picked: Vec<usize>,
    sizes: Vec<usize>,
    types: Vec<exr::meta::attribute::SampleType>,
    pixel_bytes: usize,
}

impl BlockLayout {
    /// The layout of `header`'s blocks with `picked` channels read; subsampled channels are
    /// refused (the line layout assumes one sample per pixel).
    fn new(path: &Path, header: &exr::meta::header::Header, picked: Vec<usize>) -> Result<Self> {
        use exr::compression::Compression;
        // Every compression OpenEXR 3.1 writes is decoded; the HTJ2K ones of OpenEXR 3.4 and
        // later are refused here, by name, before any block is read.
        if let Compression::HTJ2K32 | Compression::HTJ2K256 = header.compression {
            let lines = header.compression.scan_lines_per_block();
            return Err(Error::unsupported(
                path,
                format!(
                    "EXR compression HTJ2K{lines} (High-Throughput JPEG 2000, OpenEXR 3.4 and \
                     later) is not supported; rewrite the file with another compression \
                     (none, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A, DWAA or DWAB)"
                ),
            ));
        }
        let list = &header.channels.list;
        if let Some(c) = list
            .iter()
            .find(|c| c.sampling.x() != 1 || c.sampling.y() != 1)
        {
            return Err(Error::unsupported(
                path,
                format!("subsampled EXR channel {}", c.name),
            ));
        }
        let sizes: Vec<usize> = list
            .iter()
            .map(|c| c.sample_type.bytes_per_sample())
            .collect();
        let pixel_bytes = sizes.iter().sum();
        Ok(Self {
            picked,
            sizes,
            types: list.iter().map(|c| c.sample_type).collect(),
            pixel_bytes,
        })
    }

    /// Converts the lines of `block` into `out`, interleaved rows of the layer's width of the
    /// picked channels, with row `block_y0 - out_y0` of `out` the block's first line;
    /// `(width, height)`: the layer's size, which the block must lie inside.
    fn copy(
        &self,
        block: &Block,
        (width, height): (usize, usize),
        out: &mut [f32],
        out_y0: usize,
    ) -> exr::error::Result<()> {
        let k = self.picked.len();
        let (x0, y0) = (
            block.index.pixel_position.x(),
            block.index.pixel_position.y(),
        );
        let (bw, bh) = (
            block.index.pixel_size.width(),
            block.index.pixel_size.height(),
        );
        let (stored, want) = match &block.data {
            BlockData::Lines(d) => (d.len(), bw * bh * self.pixel_bytes),
            BlockData::Planes(w) => (2 * w.len(), bw * bh * self.pixel_bytes),
            BlockData::Dwa(..) => (0, 0),
        };
        if x0 + bw > width
            || y0 + bh > height
            || y0 < out_y0
            || stored != want
            || (y0 - out_y0 + bh) * width * k > out.len()
        {
            return Err(exr::error::Error::Invalid("block size".into()));
        }
        if let BlockData::Dwa(bytes, plan) = &block.data {
            // Each decoded row of an 8 x 8 block written where its picked channel goes.
            let slot: Vec<Option<usize>> = (0..self.sizes.len())
                .map(|ci| self.picked.iter().position(|&p| p == ci))
                .collect();
            let base = y0 - out_y0;
            return super::exr_dwa::decode(bytes, plan, (bw, bh), |group, y, rows| {
                let at = ((base + y) * width + x0) * k;
                let out = &mut out[at..at + bw * k];
                let slots: Vec<Option<usize>> = group.iter().map(|&c| slot[c]).collect();
                if k == 3 && slots == [Some(0), Some(1), Some(2)] {
                    // R, G, B in one pass, as `copy` interleaves lines.
                    for (((o, r), g), b) in out
                        .chunks_exact_mut(3)
                        .zip(rows[0])
                        .zip(rows[1])
                        .zip(rows[2])
                    {
                        o.copy_from_slice(&[*r, *g, *b]);
                    }
                    return;
                }
                for (s, row) in slots.iter().zip(rows) {
                    if let Some(j) = s {
                        for (o, v) in out[*j..].iter_mut().step_by(k).zip(row.iter()) {
                            *o = *v;
                        }
                    }
                }
            })
            .map_err(|m| exr::error::Error::Invalid(format!("DWA-compressed data ({m})").into()));
        }
        // Each picked channel's line converted into a row of `rows`, then the rows
        // interleaved into the output: contiguous loops the compiler vectorises (F16C for
        // half floats), where converting straight into every k-th output sample did not.
        let mut rows = vec![0.0f32; k * bw];
        for dy in 0..bh {
            for (&ci, row) in self.picked.iter().zip(rows.chunks_exact_mut(bw)) {
                let before = self.sizes[..ci].iter().sum::<usize>();
                let size = self.sizes[ci];
                match &block.data {
                    BlockData::Lines(d) => {
                        let at = dy * bw * self.pixel_bytes + bw * before;
                        line_to_f32(self.types[ci], &d[at..at + bw * size], row);
                    }
                    BlockData::Planes(w) => {
                        // Words: channel planes one after the other, lines within each.
                        let at = (bh * bw * before + dy * bw * size) / 2;
                        words_to_f32(self.types[ci], &w[at..at + bw * size / 2], row);
                    }
                    BlockData::Dwa(..) => {}
                }
            }
            let at = (y0 - out_y0 + dy) * width + x0;
            let out = &mut out[at * k..(at + bw) * k];
            match k {
                3 => {
                    let (r, gb) = rows.split_at(bw);
                    let (g, b) = gb.split_at(bw);
                    for (((o, r), g), b) in out.chunks_exact_mut(3).zip(r).zip(g).zip(b) {
                        o.copy_from_slice(&[*r, *g, *b]);
                    }
                }
                1 => out.copy_from_slice(&rows),
                _ => {
                    for (j, row) in rows.chunks_exact(bw).enumerate() {
                        for (o, v) in out.iter_mut().skip(j).step_by(k).zip(row) {
                            *o = *v;
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// Converts one line of one channel, native-order bytes of `ty` samples, into `out`.
fn line_to_f32(ty: exr::meta::attribute::SampleType, src: &[u8], out: &mut [f32]) {
    use exr::meta::attribute::SampleType;
    match ty {
        SampleType::F32 => {
            for (o, s) in out.iter_mut().zip(src.chunks_exact(4)) {
                *o = f32::from_ne_bytes([s[0], s[1], s[2], s[3]]);
            }
        }
        SampleType::U32 => {
            for (o, s) in out.iter_mut().zip(src.chunks_exact(4)) {
                *o = u32::from_ne_bytes([s[0], s[1], s[2], s[3]]) as f32;
            }
        }
        SampleType::F16 => match bytemuck::try_cast_slice::<u8, u16>(src) {
            // Aligned (as a line of a block's buffer is): converted where it is.
            Ok(words) => half_to_f32(words, out),
            Err(_) => {
                let mut words = [0u16; 256];
                for (src, out) in src.chunks(512).zip(out.chunks_mut(256)) {
                    let w = &mut words[..src.len() / 2];
                    for (w, s) in w.iter_mut().zip(src.chunks_exact(2)) {
                        *w = u16::from_ne_bytes([s[0], s[1]]);
                    }
                    half_to_f32(w, out);
                }
            }
        },
    }
}

/// Converts one line of one channel, 16-bit words as PIZ decodes them (a 32-bit sample as
/// two, low half first), into `out`.
fn words_to_f32(ty: exr::meta::attribute::SampleType, src: &[u16], out: &mut [f32]) {
    use exr::meta::attribute::SampleType;
    let pair = |s: &[u16]| u32::from(s[0]) | (u32::from(s[1]) << 16);
    match ty {
        SampleType::F32 => {
            for (o, s) in out.iter_mut().zip(src.chunks_exact(2)) {
                *o = f32::from_bits(pair(s));
            }
        }
        SampleType::U32 => {
            for (o, s) in out.iter_mut().zip(src.chunks_exact(2)) {
                *o = pair(s) as f32;
            }
        }
        SampleType::F16 => half_to_f32(src, out),
    }
}

/// Half floats given as bits into floats, with `half`'s slice conversion (F16C where the CPU
/// has it: 3x faster than converting sample by sample, docs/performance.md).
fn half_to_f32(src: &[u16], out: &mut [f32]) {
    use half::slice::{HalfBitsSliceExt, HalfFloatSliceExt};
    let n = src.len().min(out.len());
    src[..n]
        .reinterpret_cast::<half::f16>()
        .convert_to_f32_slice(&mut out[..n]);
}

/// A decompressed block: where it lies and its samples.
struct Block {
    index: exr::block::BlockIndex,
    data: BlockData,
}

/// How a decompressed block's samples are laid out.
enum BlockData {
    /// As the `exr` crate gives them: native-order bytes, line after line, every channel's
    /// samples of a line one after the other.
    Lines(Vec<u8>),
    /// As PIZ decodes them: 16-bit words, channel after channel, each channel's lines one
    /// after the other, a 32-bit sample as two words (low half first).
    Planes(Vec<u16>),
    /// A DWA block still compressed, with how to decode it: decoded by [`BlockLayout::copy`]
    /// straight into the image (no block-sized buffer of samples).
    Dwa(Vec<u8>, super::exr_dwa::Plan),
}

/// Decompresses `chunk` of the file described by `meta`: PIZ blocks with [`super::exr_piz`],
/// DWAA/DWAB blocks with their AC section decoded by [`super::exr_dwa`] first, the others (and
/// blocks stored uncompressed) with the `exr` crate.
fn decompress_block(
    mut chunk: exr::block::chunk::Chunk,
    meta: &exr::meta::MetaData,
) -> exr::error::Result<Block> {
    use exr::block::chunk::CompressedBlock;
    use exr::compression::Compression;
    let header = meta
        .headers
        .get(chunk.layer_index)
        .ok_or_else(|| exr::error::Error::Invalid("chunk layer index".into()))?;
    let ours = matches!(
        header.compression,
        Compression::PIZ | Compression::DWAA(_) | Compression::DWAB(_)
    );
    let crate_block = |chunk| -> exr::error::Result<Block> {
        let block = exr::block::UncompressedBlock::decompress_chunk(chunk, meta, false)?;
        Ok(Block {
            index: block.index,
            data: BlockData::Lines(block.data),
        })
    };
    let flat = matches!(
        chunk.compressed_block,
        CompressedBlock::ScanLine(_) | CompressedBlock::Tile(_)
    );
    if !ours || !flat {
        return crate_block(chunk);
    }
    let tile = header.get_block_data_indices(&chunk.compressed_block)?;
    let bounds = header.get_absolute_block_pixel_coordinates(tile)?;
    bounds.validate(Some(header.layer_size))?;
    let bytes = match &mut chunk.compressed_block {
        CompressedBlock::ScanLine(b) => &mut b.compressed_pixels_le,
        CompressedBlock::Tile(b) => &mut b.compressed_pixels_le,
        _ => return crate_block(chunk),
    };
    let (bw, bh) = (bounds.size.width(), bounds.size.height());
    let list = &header.channels.list;
    let raw = bw * bh * header.channels.bytes_per_pixel;
    if bytes.len() == raw
        || list
            .iter()
            .any(|c| c.sampling.x() != 1 || c.sampling.y() != 1)
    {
        // Stored as it is (compressing did not make it smaller), or subsampled (refused
        // later): `exr`'s path.
        return crate_block(chunk);
    }
    let index = exr::block::BlockIndex {
        layer: chunk.layer_index,
        pixel_position: bounds.position.to_usize("data indices start")?,
        level: tile.level_index,
        pixel_size: bounds.size,
    };
    if header.compression != Compression::PIZ {
        let channels: Vec<super::exr_dwa::DwaChannel> = list
            .iter()
            .map(|c| {
                let name = c.name.to_string();
                let cut = name.rfind('.').map_or(0, |i| i + 1);
                super::exr_dwa::DwaChannel {
                    prefix: name[..cut].to_string(),
                    suffix: name[cut..].to_string(),
                    sample_type: c.sample_type,
                    linear: c.quantize_linearly,
                }
            })
            .collect();
        match super::exr_dwa::plan(bytes, &channels, (bw, bh)) {
            Some(Ok(plan)) => {
                // Decoded by `copy`, straight into the image.
                return Ok(Block {
                    index,
                    data: BlockData::Dwa(std::mem::take(bytes), plan),
                });
            }
            Some(Err(m)) => {
                return Err(exr::error::Error::Invalid(
                    format!("DWA-compressed data ({m})").into(),
                ))
            }
            None => {}
        }
        // Channels that our decoder leaves to `exr`: their AC section recoded.
        // At most one AC value per sample of the block's 8 x 8 blocks.
        let samples = list.len() * bw.next_multiple_of(8) * bh.next_multiple_of(8);
        if let Some(recoded) = super::exr_dwa::recode_ac(bytes, samples) {
            // (A block exactly as long as its raw samples would be read as raw.)
            if recoded.len() != raw {
                *bytes = recoded;
            }
        }
        return crate_block(chunk);
    }
    let words: Vec<usize> = list
        .iter()
        .map(|c| c.sample_type.bytes_per_sample() / 2)
        .collect();
    let planes = super::exr_piz::decompress(bytes, &words, (bw, bh))
        .map_err(|m| exr::error::Error::Invalid(format!("PIZ-compressed data ({m})").into()))?;
    Ok(Block {
        index,
        data: BlockData::Planes(planes),
    })
}

/// Decodes an OpenEXR file's radiance layer (see the module's documentation) at full
/// resolution (single-threaded), after checking every part's declared size
/// ([`crate::limits`]).
///
/// Reads the file's blocks with `exr`'s block API and converts each decompressed block's lines
/// straight into the interleaved output, instead of building `exr`'s per-channel image first:
/// no per-channel sample vectors, no second copy. Measured on one
/// thread with float RGB ZIP files: 1.2x faster at 128x128 (5.59 -> 4.87 million instructions
/// per image), 1.3-1.45x at 1024x1024 (docs/performance.md, "Decoding").
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

/// Writes named float32 channels (each `w * h`, row-major) to an EXR file, ZIP-compressed
/// (`beauty.R` is channel `R` of layer `beauty`).
pub fn write_exr_channels(
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

/// Writes interleaved linear RGB (`width * height * 3` values) as a float32 OpenEXR file with
/// channels R, G, B; `NaN` and infinities are kept as they are.
pub fn write_exr_rgb(path: &Path, width: usize, height: usize, rgb: &[f32]) -> Result<()> {
    write_exr_interleaved(path, width, height, &["R", "G", "B"], rgb)
}

/// Writes interleaved float32 samples, `names.len()` (1 or 3) per pixel and named by `names`,
/// as a ZIP-compressed EXR. The encoder reads each pixel from `data` where it is: no planar
/// copy of the map is made (a 4096 x 4096 RGB map would take 200 MB more).
pub(crate) fn write_exr_interleaved(
    path: &Path,
    width: usize,
    height: usize,
    names: &[&str],
    data: &[f32],
) -> Result<()> {
    check_len(path, width, height, names.len(), data.len())?;
    let k = names.len();
    write_exr_pixels(path, width, height, names, &|x, y| {
        let i = k * (y * width + x);
        let mut v = [0.0; 3];
        v[..k].copy_from_slice(&data[i..i + k]);
        v
    })
}

/// Writes a ZIP-compressed float32 EXR of `names.len()` (1 or 3) channels named by `names`,
/// pixel `(x, y)` of which is `pixel(x, y)` (its first `names.len()` values). The encoder
/// runs on this thread and asks for the pixels block by block in increasing `y`, so a caller
/// can produce them a band of rows at a time.
pub(crate) fn write_exr_pixels(
    path: &Path,
    width: usize,
    height: usize,
    names: &[&str],
    pixel: &(dyn Fn(usize, usize) -> [f32; 3] + Sync),
) -> Result<()> {
    use exr::prelude::{
        Encoding, Image as ExrImage, Layer, LayerAttributes, SpecificChannels, Vec2, WritableImage,
    };
    let map_err = |e: exr::error::Error| match e {
        exr::error::Error::Io(io) => Error::write(path, io),
        other => Error::encode(path, other),
    };
    // One layer of the given channels, written through `write_atomic`.
    macro_rules! write_layer {
        ($channels:expr) => {{
            let layer = Layer::new(
                (width, height),
                LayerAttributes::default(),
                Encoding::SMALL_LOSSLESS,
                $channels,
            );
            let image = ExrImage::from_layer(layer);
            write_atomic(path, |w| {
                image.write().non_parallel().to_buffered(w).map_err(map_err)
            })
        }};
    }
    match *names {
        [a] => write_layer!(SpecificChannels::build()
            .with_channel(a)
            .with_pixel_fn(|p: Vec2<usize>| (pixel(p.x(), p.y())[0],))),
        [a, b, c] => write_layer!(SpecificChannels::build()
            .with_channel(a)
            .with_channel(b)
            .with_channel(c)
            .with_pixel_fn(|p: Vec2<usize>| {
                let v = pixel(p.x(), p.y());
                (v[0], v[1], v[2])
            })),
        _ => Err(Error::invalid(
            path,
            format!("EXR maps have 1 or 3 channels, not {}", names.len()),
        )),
    }
}
