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

/// Decodes an OpenEXR file's first valid layer at full resolution (single-threaded), after
/// checking every part's declared size ([`crate::limits`]).
pub(super) fn read_exr(path: &Path, bytes: &[u8]) -> Result<RawImage> {
    use exr::prelude::traits::*;
    use exr::prelude::{read, FlatSamples};
    use std::io::Cursor;
    let eerr = |e: exr::error::Error| match e {
        exr::error::Error::Io(io) => io_err(path, io),
        exr::error::Error::NotSupported(m) => Error::unsupported(path, format!("EXR {m}")),
        other => Error::decode(path, other),
    };
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
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(eerr)?;
    let layer = image.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
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
    let n = width * height;
    let k = picked.len();
    let mut data = vec![0.0f32; n * k];
    for (j, &ci) in picked.iter().enumerate() {
        let samples = &list[ci].sample_data;
        if samples.len() != n {
            return Err(Error::unsupported(
                path,
                format!("subsampled EXR channel {}", names[ci]),
            ));
        }
        match samples {
            FlatSamples::F16(v) => {
                for (p, s) in v.iter().enumerate() {
                    data[p * k + j] = s.to_f32();
                }
            }
            FlatSamples::F32(v) => {
                for (p, s) in v.iter().enumerate() {
                    data[p * k + j] = *s;
                }
            }
            FlatSamples::U32(v) => {
                for (p, s) in v.iter().enumerate() {
                    data[p * k + j] = *s as f32;
                }
            }
        }
    }
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
