//! OpenEXR: decoding the first valid layer, and writing float32 channels.

use std::path::Path;

use super::{check_len, io_err, planes, Raw, RawImage};
use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::limits;

/// The part of an EXR channel name after the last `.` (drops a legacy layer prefix).
pub(super) fn base_name(name: &str) -> &str {
    name.rsplit('.').next().unwrap_or(name)
}

/// Decodes an OpenEXR file's first valid (non-deep) layer at full resolution (single-threaded),
/// after checking every part's declared size ([`crate::limits`]).
///
/// Reads the file's blocks with `exr`'s block API and converts each decompressed block's lines
/// straight into the interleaved output, instead of building `exr`'s per-channel image first:
/// no per-channel sample vectors, no second copy. Measured on one
/// thread with float RGB ZIP files: 1.2x faster at 128x128 (5.59 -> 4.87 million instructions
/// per image), 1.3-1.45x at 1024x1024 (docs/performance.md, "Decoding").
pub(super) fn read_exr(path: &Path, bytes: &[u8]) -> Result<RawImage> {
    use exr::block::reader::ChunksReader;
    use exr::meta::attribute::SampleType;
    use std::io::Cursor;
    let eerr = |e: exr::error::Error| match e {
        exr::error::Error::Io(io) => io_err(path, io),
        exr::error::Error::NotSupported(m) => Error::unsupported(path, format!("EXR {m}")),
        other => Error::decode(path, other),
    };
    // The declared sizes first, from the headers as written (the block reader's own
    // validation would otherwise answer a forged size with a less useful error).
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(eerr)?;
    for h in meta.headers.iter() {
        let size = h.layer_size;
        limits::check_image_size(
            path,
            "EXR header",
            size.width() as u64,
            size.height() as u64,
            bytes.len() as u64,
        )?;
    }
    let reader = exr::block::read(Cursor::new(bytes), false).map_err(eerr)?;
    let Some(layer) = reader.headers().iter().position(|h| !h.deep) else {
        return Err(Error::unsupported(path, "EXR with deep data only"));
    };
    let header = &reader.headers()[layer];
    let (width, height) = (header.layer_size.width(), header.layer_size.height());
    let list = &header.channels.list;
    let names: Vec<String> = list.iter().map(|c| c.name.to_string()).collect();
    let find = |want: &str| {
        names
            .iter()
            .position(|n| base_name(n).eq_ignore_ascii_case(want))
    };
    let picked: Vec<usize> = if let (Some(r), Some(g), Some(b)) = (find("R"), find("G"), find("B"))
    {
        vec![r, g, b]
    } else if let Some(y) = find("Y") {
        vec![y]
    } else {
        let non_alpha: Vec<usize> = (0..names.len())
            .filter(|&i| !base_name(&names[i]).eq_ignore_ascii_case("A"))
            .collect();
        if non_alpha.len() != 1 {
            return Err(Error::unsupported(
                path,
                format!(
                    "{}-channel EXR without R,G,B channels (channels: {})",
                    names.len(),
                    names.join(",")
                ),
            ));
        }
        non_alpha
    };
    // Every channel's samples per pixel of a line, in file order (all must be unsampled: the
    // line layout below assumes one sample per pixel).
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
    let types: Vec<SampleType> = list.iter().map(|c| c.sample_type).collect();
    let pixel_bytes: usize = sizes.iter().sum();
    let k = picked.len();
    let mut data = vec![0.0f32; width * height * k];
    let chunks = reader
        .filter_chunks(false, |_, tile, block| {
            block.layer == layer && tile.is_largest_resolution_level()
        })
        .map_err(eerr)?;
    chunks
        .decompress_sequential(false, |_, block| {
            let (x0, y0) = (
                block.index.pixel_position.x(),
                block.index.pixel_position.y(),
            );
            let (bw, bh) = (
                block.index.pixel_size.width(),
                block.index.pixel_size.height(),
            );
            let line = bw * pixel_bytes;
            if x0 + bw > width || y0 + bh > height || block.data.len() != line * bh {
                return Err(exr::error::Error::Invalid("block size".into()));
            }
            for (dy, row) in block.data.chunks_exact(line).enumerate() {
                let out =
                    &mut data[((y0 + dy) * width + x0) * k..((y0 + dy) * width + x0 + bw) * k];
                for (j, &ci) in picked.iter().enumerate() {
                    let at = bw * sizes[..ci].iter().sum::<usize>();
                    let src = &row[at..at + bw * sizes[ci]];
                    let dst = out.iter_mut().skip(j).step_by(k);
                    match types[ci] {
                        SampleType::F32 => {
                            for (o, s) in dst.zip(src.chunks_exact(4)) {
                                *o = f32::from_ne_bytes([s[0], s[1], s[2], s[3]]);
                            }
                        }
                        SampleType::F16 => {
                            for (o, s) in dst.zip(src.chunks_exact(2)) {
                                *o = exr::prelude::f16::from_ne_bytes([s[0], s[1]]).to_f32();
                            }
                        }
                        SampleType::U32 => {
                            for (o, s) in dst.zip(src.chunks_exact(4)) {
                                *o = u32::from_ne_bytes([s[0], s[1], s[2], s[3]]) as f32;
                            }
                        }
                    }
                }
            }
            Ok(())
        })
        .map_err(eerr)?;
    Ok(RawImage {
        width,
        height,
        channels: k,
        raw: Raw::F32(data),
    })
}

/// Writes named float32 channels (each `w * h`, row-major) to an EXR file, ZIP-compressed.
pub(crate) fn write_exr_channels(
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
    check_len(path, width, height, 3, rgb.len())?;
    let mut p = planes(rgb, 3).into_iter();
    let (r, g, b) = (p.next().unwrap(), p.next().unwrap(), p.next().unwrap());
    write_exr_channels(path, width, height, vec![("R", r), ("G", g), ("B", b)])
}
