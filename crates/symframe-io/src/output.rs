//! Writers of result maps (NPY, float EXR) and their colour-coded pictures (8-bit PNG).
//!
//! Every writer writes to a temporary file in the destination folder and renames it, so an
//! interrupted or failed write never leaves half a file behind.

use std::path::Path;

use ndarray::{ArrayD, ArrayViewD, IxDyn};
use ndarray_npy::{ReadNpyExt, WriteNpyExt};

use crate::atomic::{write_atomic, TempFile};
use crate::codecs::{write_png, PngLayout};
use crate::error::{Error, Result};

/// Writes `data` (row-major, C order) as a little-endian `float32` `.npy` array of `shape`,
/// e.g. `[H, W, 3]` for normals or `[H, W]` for a confidence map.
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    let fits = shape
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b))
        .is_some_and(|n| n == data.len());
    let view = ArrayViewD::from_shape(IxDyn(shape), data)
        .ok()
        .filter(|_| fits)
        .ok_or_else(|| {
            Error::invalid(
                path,
                format!("cannot write shape {shape:?} from {} values", data.len()),
            )
        })?;
    write_atomic(path, |w| {
        view.write_npy(w).map_err(|e| Error::encode(path, e))
    })
}

/// An `.npy` array written a piece at a time in row-major order (`T`: `f32` or `u8`), renamed
/// into place by [`NpyRows::finish`] once every value is in (dropped unfinished, nothing is
/// left behind): the same bytes as [`write_npy_f32`] and [`write_npy_u8`] write.
pub struct NpyRows<T> {
    path: std::path::PathBuf,
    guard: TempFile,
    w: std::io::BufWriter<std::fs::File>,
    left: usize,
    item: std::marker::PhantomData<T>,
}

impl<T: ndarray_npy::WritableElement> NpyRows<T> {
    /// Starts the array of `shape` (its header written).
    pub fn create(path: &Path, shape: &[usize]) -> Result<Self> {
        let left = shape
            .iter()
            .try_fold(1usize, |a, &b| a.checked_mul(b))
            .ok_or_else(|| Error::invalid(path, format!("shape {shape:?} too large")))?;
        let header = ndarray_npy::npy::header::Header {
            type_descriptor: T::type_descriptor(),
            layout: ndarray_npy::npy::header::Layout::Standard,
            shape: shape.to_vec(),
        }
        .to_bytes()
        .map_err(|e| Error::encode(path, e))?;
        let (guard, file) = TempFile::create(path)?;
        let mut w = std::io::BufWriter::new(file);
        std::io::Write::write_all(&mut w, &header).map_err(|e| Error::write(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            guard,
            w,
            left,
            item: std::marker::PhantomData,
        })
    }

    /// Appends `values`, the next ones in row-major order.
    pub fn push(&mut self, values: &[T]) -> Result<()> {
        if values.len() > self.left {
            return Err(Error::invalid(
                &self.path,
                "more values than the array's shape",
            ));
        }
        T::write_slice(values, &mut self.w).map_err(|e| Error::encode(&self.path, e))?;
        self.left -= values.len();
        Ok(())
    }

    /// Ends the array (every value written) and renames it into place.
    pub fn finish(self) -> Result<()> {
        if self.left > 0 {
            return Err(Error::invalid(
                &self.path,
                format!("{} values of the array not written", self.left),
            ));
        }
        let file = self
            .w
            .into_inner()
            .map_err(|e| Error::write(&self.path, e.into_error()))?;
        drop(file);
        self.guard.commit()
    }
}

/// Reads a `float32` `.npy` array: its shape and its values in row-major (C) order. The
/// header's shape is checked against [`crate::limits::MAX_NPY_VALUES`] and the file's length
/// before the array is allocated.
pub fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>)> {
    let bytes = read_npy_file(path)?;
    decode_npy_f32(path, &bytes)
}

/// The bytes of the `.npy` file `path`, bounded ([`crate::read_bounded`]).
fn read_npy_file(path: &Path) -> Result<Vec<u8>> {
    crate::read_bounded(path, "a .npy file", crate::limits::MAX_NPY_FILE_BYTES)
}

/// [`read_npy_f32`] of a file's content `bytes` (`path` names it in errors).
pub fn decode_npy_f32(path: &Path, bytes: &[u8]) -> Result<(Vec<usize>, Vec<f32>)> {
    check_npy_header(path, bytes)?;
    let arr =
        ArrayD::<f32>::read_npy(std::io::Cursor::new(bytes)).map_err(|e| Error::decode(path, e))?;
    Ok((arr.shape().to_vec(), arr.iter().copied().collect()))
}

/// Reads a `uint8` `.npy` array (the source map): its shape and values in row-major order,
/// with the same header checks as [`read_npy_f32`].
pub fn read_npy_u8(path: &Path) -> Result<(Vec<usize>, Vec<u8>)> {
    let bytes = read_npy_file(path)?;
    check_npy_header(path, &bytes)?;
    let arr = ArrayD::<u8>::read_npy(std::io::Cursor::new(&bytes[..]))
        .map_err(|e| Error::decode(path, e))?;
    Ok((arr.shape().to_vec(), arr.iter().copied().collect()))
}

/// Checks an `.npy` header: magic, header length, and that the declared shape times the item
/// size is within the limits and fits in the file.
fn check_npy_header(path: &Path, b: &[u8]) -> Result<()> {
    if b.len() < 10 || &b[..6] != b"\x93NUMPY" {
        return Err(Error::decode(path, "not a .npy file (bad magic)"));
    }
    let (start, hlen): (usize, usize) = match b[6] {
        1 => (10, u16::from_le_bytes([b[8], b[9]]) as usize),
        2 | 3 if b.len() >= 12 => (
            12,
            u32::from_le_bytes(b[8..12].try_into().unwrap()) as usize,
        ),
        v => return Err(Error::decode(path, format!("unsupported .npy version {v}"))),
    };
    let Some(header) = b.get(start..start.saturating_add(hlen)) else {
        return Err(Error::decode(path, "truncated .npy header"));
    };
    let header = String::from_utf8_lossy(header);
    let after = |key: &str| header.find(key).map(|i| &header[i + key.len()..]);
    let shape_text = after("'shape'")
        .and_then(|r| {
            let open = r.find('(')? + 1;
            Some(&r[open..open + r[open..].find(')')?])
        })
        .ok_or_else(|| Error::decode(path, "no shape in the .npy header"))?;
    let mut values: u128 = 1;
    for t in shape_text
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
    {
        let d: u128 = t
            .parse()
            .map_err(|_| Error::decode(path, format!("bad .npy shape ({shape_text})")))?;
        values = values.saturating_mul(d);
    }
    if values > crate::limits::MAX_NPY_VALUES as u128 {
        return Err(Error::limits(
            path,
            format!(
                ".npy header declares shape ({shape_text}), more than {} values",
                crate::limits::MAX_NPY_VALUES
            ),
        ));
    }
    // The item size: the digits closing the descr ('<f4': 4); 1 if unreadable (the reader
    // refuses a wrong type itself).
    let item: u128 = after("'descr'")
        .and_then(|r| r.split('\'').nth(1))
        .and_then(|d| {
            let digits: String = d.chars().rev().take_while(|c| c.is_ascii_digit()).collect();
            digits.chars().rev().collect::<String>().parse().ok()
        })
        .unwrap_or(1);
    let have = (b.len() - (start + hlen)) as u128;
    if values.saturating_mul(item) > have {
        return Err(Error::decode(
            path,
            format!(
                "truncated: shape ({shape_text}) needs {} bytes of data, the file has {have}",
                values * item
            ),
        ));
    }
    Ok(())
}

/// The channel names of an EXR map of `channels` values per pixel: 1 is Y, 3 are R, G, B.
fn exr_map_channels(path: &Path, channels: usize) -> Result<&'static [&'static str]> {
    match channels {
        1 => Ok(&["Y"]),
        3 => Ok(&["R", "G", "B"]),
        _ => Err(Error::invalid(
            path,
            format!("EXR maps have 1 or 3 channels, not {channels}"),
        )),
    }
}

/// Writes a float32 OpenEXR map of `channels` interleaved values per pixel: 3 channels are
/// named R, G, B and 1 channel Y. `NaN` is kept, marking pixels without a result.
pub fn write_exr_map(
    path: &Path,
    width: usize,
    height: usize,
    channels: usize,
    data: &[f32],
) -> Result<()> {
    let names = exr_map_channels(path, channels)?;
    crate::codecs::write_exr_interleaved(path, width, height, names, data)
}

/// Writes a float32 OpenEXR map of `channels` (1: Y, 3: R, G, B) values per pixel, pixel
/// `(x, y)` being the first `channels` values of `pixel(x, y)`, asked for in increasing `y`
/// (a map produced a band of rows at a time); the same bytes as [`write_exr_map`] writes.
pub fn write_exr_map_with(
    path: &Path,
    width: usize,
    height: usize,
    channels: usize,
    pixel: &(dyn Fn(usize, usize) -> [f32; 3] + Sync),
) -> Result<()> {
    let names = exr_map_channels(path, channels)?;
    crate::codecs::write_exr_pixels(path, width, height, names, pixel)
}

/// Clamps to `[0, 1]` and scales to a byte.
fn byte(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Colours unit normals (`H x W x 3`, `NaN` = no result) the way normal maps are stored:
/// `(r, g, b) = ((nx+1)/2, (ny+1)/2, (nz+1)/2)` (OpenGL convention, y up), written as bytes
/// directly (a data map, not sRGB-encoded); `NaN` pixels black. See [`normal_map_values`] for
/// the 16-bit map and the DirectX (y down) convention.
pub fn normal_map_rgb8(normals: &[f32]) -> Vec<u8> {
    normal_map_values(normals, NormalPng::OpenGl)
        .into_iter()
        .map(|v| byte(v as f64))
        .collect()
}

/// The y convention of a normal-map picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormalPng {
    /// Green = up (`+y`): OpenGL, glTF, Blender.
    OpenGl,
    /// Green = down (`-y`): DirectX, Unreal.
    DirectX,
}

/// One normal's picture value in `[0, 1]`: `(n + 1) / 2` per channel, y negated for
/// [`NormalPng::DirectX`]; a `NaN` normal 0 (black).
fn normal_map_value(n: [f32; 3], convention: NormalPng) -> [f32; 3] {
    let sy = match convention {
        NormalPng::OpenGl => 1.0,
        NormalPng::DirectX => -1.0,
    };
    if n.iter().any(|v| v.is_nan()) {
        return [0.0; 3];
    }
    [
        (n[0] + 1.0) / 2.0,
        (sy * n[1] + 1.0) / 2.0,
        (n[2] + 1.0) / 2.0,
    ]
}

/// Normal-map values in `[0, 1]`: `(n + 1) / 2` per channel, y negated for
/// [`NormalPng::DirectX`]; `NaN` pixels 0 (black).
pub fn normal_map_values(normals: &[f32], convention: NormalPng) -> Vec<f32> {
    normals
        .chunks_exact(3)
        .flat_map(|n| normal_map_value([n[0], n[1], n[2]], convention))
        .collect()
}

/// Writes a normal map as a 16-bit PNG: `(n + 1) / 2` in each channel (see
/// [`normal_map_values`]), black where there is no normal; converted a row at a time.
pub fn write_normal_png16(
    path: &Path,
    width: usize,
    height: usize,
    normals: &[f32],
    convention: NormalPng,
) -> Result<()> {
    crate::codecs::write_png16_rgb_with(path, width, height, normals, &|n| {
        normal_map_value(n, convention)
    })
}

/// One row of the 16-bit normal map [`write_normal_png16`] writes (big-endian RGB, 6 bytes
/// per pixel) from that row's normals.
pub fn normal_png16_row(normals: &[f32], convention: NormalPng, row: &mut [u8]) {
    crate::codecs::rgb16_row(normals, &|n| normal_map_value(n, convention), row)
}

/// HSV with saturation and value 1 to RGB bytes; `hue` in turns (`[0, 1)`, wrapped).
fn hue_rgb8(hue: f64) -> [u8; 3] {
    let h = hue.rem_euclid(1.0) * 6.0;
    let sector = (h.floor() as usize).min(5);
    let f = h - sector as f64;
    let (r, g, b) = match sector {
        0 => (1.0, f, 0.0),
        1 => (1.0 - f, 1.0, 0.0),
        2 => (0.0, 1.0, f),
        3 => (0.0, 1.0 - f, 1.0),
        4 => (f, 0.0, 1.0),
        _ => (1.0, 0.0, 1.0 - f),
    };
    [byte(r), byte(g), byte(b)]
}

/// Colours tangents (`H x W x 3`) by the angle `phi` of their image-plane projection from the
/// x axis: HSV hue `2 * phi` (so `t` and `-t` get the same colour), saturation 1, value 1.
/// `NaN` pixels are black; a tangent along z (no projection) gets hue 0 (red).
pub fn tangent_map_rgb8(tangents: &[f32]) -> Vec<u8> {
    tangents
        .chunks_exact(3)
        .flat_map(|t| {
            if t.iter().any(|v| v.is_nan()) {
                return [0, 0, 0];
            }
            let phi = (t[1] as f64).atan2(t[0] as f64);
            hue_rgb8(2.0 * phi / std::f64::consts::TAU)
        })
        .collect()
}

/// The viridis colour map at `t` in `[0, 1]` (polynomial fit, within about 1% of matplotlib's).
fn viridis(t: f64) -> [u8; 3] {
    const C: [[f64; 3]; 7] = [
        [
            0.277_727_327_223_417_7,
            0.005_407_344_544_966_578,
            0.334_099_805_335_306_1,
        ],
        [
            0.105_093_043_108_577_4,
            1.404_613_529_898_575,
            1.384_590_162_594_685,
        ],
        [
            -0.330_861_828_725_556_3,
            0.214_847_559_468_213,
            0.095_095_163_028_236_59,
        ],
        [
            -4.634_230_498_983_486,
            -5.799_100_973_351_585,
            -19.332_440_956_279_87,
        ],
        [
            6.228_269_936_347_081,
            14.179_933_366_805_09,
            56.690_552_600_681_05,
        ],
        [
            4.776_384_997_670_288,
            -13.745_145_377_746_01,
            -65.353_032_633_372_34,
        ],
        [
            -5.435_455_855_934_631,
            4.645_852_612_178_535,
            26.312_435_249_583_2,
        ],
    ];
    let t = t.clamp(0.0, 1.0);
    let mut out = [0u8; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let v = C.iter().rev().fold(0.0, |acc, k| acc * t + k[c]);
        *o = byte(v);
    }
    out
}

/// Colours scalar values (confidence, error) with the perceptual viridis map, `lo` dark purple
/// to `hi` yellow, clamped outside; `NaN` pixels black. If `hi <= lo` every value maps to `lo`.
pub fn gray_map_rgb8(values: &[f32], lo: f32, hi: f32) -> Vec<u8> {
    let range = hi as f64 - lo as f64;
    values
        .iter()
        .flat_map(|&v| {
            if v.is_nan() {
                return [0, 0, 0];
            }
            let t = if range > 0.0 {
                (v as f64 - lo as f64) / range
            } else {
                0.0
            };
            viridis(t)
        })
        .collect()
}

/// Colours of the source map's codes (`symframe::PixelSource`): none black, symmetry blue,
/// Lambertian orange, highlight green, lobe purple; unknown codes magenta. Fixed, so pictures
/// of different runs compare.
pub const SOURCE_PALETTE: [[u8; 3]; 5] = [
    [0, 0, 0],
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [148, 103, 189],
];

/// Colours a per-pixel source-code map with [`SOURCE_PALETTE`].
pub fn source_map_rgb8(codes: &[u8]) -> Vec<u8> {
    codes
        .iter()
        .flat_map(|&c| {
            SOURCE_PALETTE
                .get(c as usize)
                .copied()
                .unwrap_or([255, 0, 255])
        })
        .collect()
}

/// Writes `data` (row-major) as a `uint8` `.npy` array of `shape`, e.g. `[H, W]` for the
/// source map.
pub fn write_npy_u8(path: &Path, shape: &[usize], data: &[u8]) -> Result<()> {
    let view = ArrayViewD::from_shape(IxDyn(shape), data).map_err(|_| {
        Error::invalid(
            path,
            format!("cannot write shape {shape:?} from {} values", data.len()),
        )
    })?;
    write_atomic(path, |w| {
        view.write_npy(w).map_err(|e| Error::encode(path, e))
    })
}

/// Writes 8-bit RGB bytes (`width * height * 3`, e.g. from the colour maps above) as a PNG.
pub fn write_png_rgb8(path: &Path, width: usize, height: usize, rgb: &[u8]) -> Result<()> {
    if width.checked_mul(height).and_then(|n| n.checked_mul(3)) != Some(rgb.len()) {
        return Err(Error::invalid(
            path,
            format!(
                "cannot write a {width}x{height} RGB picture from {} bytes",
                rgb.len()
            ),
        ));
    }
    write_png(path, width, height, rgb, PngLayout::Rgb8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codecs::{read_image, DecodeOptions};

    #[test]
    fn npy_round_trip_and_shape_check() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("n.npy");
        let v: Vec<f32> = (0..2 * 3 * 3).map(|i| i as f32 * 0.5).collect();
        write_npy_f32(&p, &[2, 3, 3], &v).unwrap();
        assert_eq!(read_npy_f32(&p).unwrap(), (vec![2, 3, 3], v.clone()));
        let mut c = v[..6].to_vec();
        c[2] = f32::NAN;
        write_npy_f32(&p, &[2, 3], &c).unwrap();
        let (shape, back) = read_npy_f32(&p).unwrap();
        assert_eq!(shape, vec![2, 3]);
        assert!(back[2].is_nan() && back[5] == 2.5);
        let e = write_npy_f32(&p, &[4, 4], &v).unwrap_err().to_string();
        assert!(e.contains("n.npy") && e.contains("[4, 4]"), "{e}");
        std::fs::write(&p, b"\x93NUMPY garbage").unwrap();
        assert!(read_npy_f32(&p).unwrap_err().to_string().contains("n.npy"));
    }

    #[test]
    fn u8_npy_round_trip_and_type_check() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("source.npy");
        write_npy_u8(&p, &[2, 3], &[0, 1, 2, 3, 255, 7]).unwrap();
        assert_eq!(
            read_npy_u8(&p).unwrap(),
            (vec![2, 3], vec![0, 1, 2, 3, 255, 7])
        );
        // A float map is not a source map: an error naming the file, no panic.
        write_npy_f32(&p, &[2], &[0.5, 1.0]).unwrap();
        assert!(read_npy_u8(&p)
            .unwrap_err()
            .to_string()
            .contains("source.npy"));
    }

    #[test]
    fn exr_maps_keep_nan_and_name_channels() {
        use exr::prelude::*;
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("c.exr");
        let v = [0.5f32, f32::NAN, 2.0, -1.0];
        write_exr_map(&p, 2, 2, 1, &v).unwrap();
        let img = read_first_flat_layer_from_file(&p).unwrap();
        let names: Vec<String> = img
            .layer_data
            .channel_data
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        assert_eq!(names, vec!["Y"]);
        let back: Vec<f32> = img.layer_data.channel_data.list[0]
            .sample_data
            .values_as_f32()
            .collect();
        assert_eq!(back[0], 0.5);
        assert!(back[1].is_nan());
        assert_eq!(&back[2..], &v[2..]);

        let n = [0.0f32, 0.0, 1.0, f32::NAN, f32::NAN, f32::NAN];
        write_exr_map(&p, 2, 1, 3, &n).unwrap();
        let img = read_first_flat_layer_from_file(&p).unwrap();
        let names: Vec<String> = img
            .layer_data
            .channel_data
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        assert_eq!(names, vec!["B", "G", "R"]);
        // The stack reader sees the NaN pixel as invalid, the other exactly.
        let r = read_image(&p, &DecodeOptions::default()).unwrap();
        assert_eq!(&r.data[..3], &[0.0, 0.0, 1.0]);
        assert!(r.data[3..].iter().all(|x| x.is_nan()));
        assert!(write_exr_map(&p, 2, 1, 2, &[0.0; 4]).is_err());
    }

    #[test]
    fn normal_map_colours() {
        let s = 0.5f32.sqrt();
        let n = [
            0.0,
            0.0,
            1.0, //
            1.0,
            0.0,
            0.0, //
            -s,
            s,
            0.0, //
            f32::NAN,
            0.0,
            1.0,
        ];
        assert_eq!(
            normal_map_rgb8(&n),
            vec![128, 128, 255, 255, 128, 128, 37, 218, 128, 0, 0, 0]
        );
        // 16-bit, both conventions: y flips, x and z do not.
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("n.png");
        let opts = crate::codecs::DecodeOptions {
            saturation: 2.0,
            ..Default::default()
        };
        for (conv, g) in [(NormalPng::OpenGl, s), (NormalPng::DirectX, -s)] {
            write_normal_png16(&p, 4, 1, &n, conv).unwrap();
            let img = read_image(&p, &opts).unwrap();
            let want = [(1.0 - s) / 2.0, (1.0 + g) / 2.0, 0.5];
            for (got, w) in img.data[6..9].iter().zip(want) {
                assert!((got - w).abs() < 1e-4, "{conv:?}: {:?}", &img.data[6..9]);
            }
            assert!(img.data[9..12].iter().all(|&v| v == 0.0));
        }
    }

    #[test]
    fn tangent_map_colours_are_axis_symmetric() {
        let s = 0.5f32.sqrt();
        let t = [
            1.0,
            0.0,
            0.0, // phi 0 -> red
            0.0,
            1.0,
            0.0, // phi 90 -> hue 180 -> cyan
            s,
            s,
            0.0, // phi 45 -> hue 90 -> (0.5, 1, 0)
            f32::NAN,
            0.0,
            0.0,
        ];
        let c = tangent_map_rgb8(&t);
        assert_eq!(c, vec![255, 0, 0, 0, 255, 255, 128, 255, 0, 0, 0, 0]);
        for k in 0..50 {
            let a = k as f32 * 0.37;
            let v = [a.cos() * 0.8, a.sin() * 0.8, 0.6];
            let m = [-v[0], -v[1], -v[2]];
            assert_eq!(tangent_map_rgb8(&v), tangent_map_rgb8(&m));
        }
        // Perpendicular axes differ (hue 180 degrees apart).
        assert_ne!(
            tangent_map_rgb8(&[1.0, 0.0, 0.0]),
            tangent_map_rgb8(&[0.0, 1.0, 0.0])
        );
    }

    #[test]
    fn gray_map_is_viridis() {
        let c = gray_map_rgb8(&[0.0, 10.0, f32::NAN, -5.0, 99.0], 0.0, 10.0);
        let near = |a: &[u8], b: [u8; 3]| a.iter().zip(b).all(|(&x, y)| x.abs_diff(y) <= 4);
        assert!(near(&c[0..3], [68, 1, 84]), "{:?}", &c[0..3]);
        assert!(near(&c[3..6], [253, 231, 37]), "{:?}", &c[3..6]);
        assert_eq!(&c[6..9], &[0, 0, 0]);
        assert_eq!(&c[9..12], &c[0..3]);
        assert_eq!(&c[12..15], &c[3..6]);
        // Luminance increases monotonically.
        let vals: Vec<f32> = (0..=100).map(|i| i as f32 / 100.0).collect();
        let m = gray_map_rgb8(&vals, 0.0, 1.0);
        let lum: Vec<f32> = m
            .chunks(3)
            .map(|p| 0.2126 * p[0] as f32 + 0.7152 * p[1] as f32 + 0.0722 * p[2] as f32)
            .collect();
        assert!(lum.windows(2).all(|w| w[1] >= w[0] - 0.5), "{lum:?}");
        assert_eq!(
            gray_map_rgb8(&[3.0], 1.0, 1.0),
            gray_map_rgb8(&[0.0], 0.0, 1.0)
        );
    }

    #[test]
    fn png_rgb8_writes_bytes_verbatim() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("pic.png");
        let bytes = [1u8, 2, 3, 250, 251, 252];
        write_png_rgb8(&p, 2, 1, &bytes).unwrap();
        let img = ::image::open(&p).unwrap().to_rgb8();
        assert_eq!(img.into_raw(), bytes.to_vec());
        let e = write_png_rgb8(&p, 2, 2, &bytes).unwrap_err().to_string();
        assert!(e.contains("pic.png"), "{e}");
    }
}
