//! An EXR block decompressed (PIZ and DWA with this crate's decoders, the others with `exr`'s)
//! and its lines converted into interleaved float radiance channels.

use std::path::Path;

use crate::error::{Error, Result};

/// How the lines of a decompressed EXR block are laid out: every channel's sample type and
/// size, in the part's channel order, and the radiance channels picked from them.
pub(super) struct BlockLayout {
    pub(super) picked: Vec<usize>,
    sizes: Vec<usize>,
    types: Vec<exr::meta::attribute::SampleType>,
    pub(super) pixel_bytes: usize,
}

impl BlockLayout {
    /// The layout of `header`'s blocks with `picked` channels read; subsampled channels are
    /// refused (the line layout assumes one sample per pixel).
    pub(super) fn new(
        path: &Path,
        header: &exr::meta::header::Header,
        picked: Vec<usize>,
    ) -> Result<Self> {
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
    pub(super) fn copy(
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
            return crate::codecs::exr_dwa::decode(bytes, plan, (bw, bh), |group, y, rows| {
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
        // half floats), which converting straight into every k-th output sample is not.
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
/// has it: faster than converting sample by sample; docs/performance.md, "Decoding, every
/// compression").
fn half_to_f32(src: &[u16], out: &mut [f32]) {
    use half::slice::{HalfBitsSliceExt, HalfFloatSliceExt};
    let n = src.len().min(out.len());
    src[..n]
        .reinterpret_cast::<half::f16>()
        .convert_to_f32_slice(&mut out[..n]);
}

/// A decompressed block: where it lies and its samples.
pub(super) struct Block {
    pub(super) index: exr::block::BlockIndex,
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
    Dwa(Vec<u8>, crate::codecs::exr_dwa::Plan),
}

/// Decompresses `chunk` of the file described by `meta`: PIZ blocks with [`crate::codecs::exr_piz`],
/// DWAA/DWAB blocks with their AC section decoded by [`crate::codecs::exr_dwa`] first, the others (and
/// blocks stored uncompressed) with the `exr` crate.
pub(super) fn decompress_block(
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
        let channels: Vec<crate::codecs::exr_dwa::DwaChannel> = list
            .iter()
            .map(|c| {
                let name = c.name.to_string();
                let cut = name.rfind('.').map_or(0, |i| i + 1);
                crate::codecs::exr_dwa::DwaChannel {
                    prefix: name[..cut].to_string(),
                    suffix: name[cut..].to_string(),
                    sample_type: c.sample_type,
                    linear: c.quantize_linearly,
                }
            })
            .collect();
        match crate::codecs::exr_dwa::plan(bytes, &channels, (bw, bh)) {
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
        if let Some(recoded) = crate::codecs::exr_dwa::recode_ac(bytes, samples) {
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
    let planes = crate::codecs::exr_piz::decompress(bytes, &words, (bw, bh))
        .map_err(|m| exr::error::Error::Invalid(format!("PIZ-compressed data ({m})").into()))?;
    Ok(Block {
        index,
        data: BlockData::Planes(planes),
    })
}
