//! Reading an `.npy` map a band of rows at a time (`float32` or `uint8`, C order), so that the
//! viewer's tile pyramid of a large estimate is written without holding whole maps in memory.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

/// The element types the maps use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Dtype {
    /// Little-endian `float32` (`<f4`).
    F32,
    /// `uint8` (`|u1`).
    U8,
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::U8 => 1,
        }
    }
}

/// An open `.npy` file of shape `[H, W]` or `[H, W, C]`, read by rows.
pub(super) struct NpyBands {
    path: PathBuf,
    file: BufReader<File>,
    data_start: u64,
    dtype: Dtype,
    /// `[H, W, C]` (`C` = 1 for a two-dimensional array).
    shape: [usize; 3],
    buf: Vec<u8>,
}

impl NpyBands {
    /// Opens `path`, which must hold `dtype` values of shape `[h, w]` (`channels` = 1) or
    /// `[h, w, channels]`; errors name the file.
    pub(super) fn open(
        path: &Path,
        dtype: Dtype,
        h: usize,
        w: usize,
        channels: usize,
    ) -> Result<Self> {
        let r = Self::open_any(path, dtype)?;
        let want: Vec<usize> = if channels == 1 {
            vec![h, w]
        } else {
            vec![h, w, channels]
        };
        let got: Vec<usize> = if r.shape[2] == 1 && channels == 1 {
            r.shape[..2].to_vec()
        } else {
            r.shape.to_vec()
        };
        if got != want {
            bail!(
                "{}: shape {got:?} does not match the other maps ({want:?} expected)",
                path.display()
            );
        }
        Ok(r)
    }

    /// Opens `path` as an array of `dtype` of any two- or three-dimensional shape.
    pub(super) fn open_any(path: &Path, dtype: Dtype) -> Result<Self> {
        let file = File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
        let len = file
            .metadata()
            .with_context(|| format!("{}: cannot read", path.display()))?
            .len();
        let mut file = BufReader::with_capacity(1 << 20, file);
        let bad =
            |what: &str| anyhow::anyhow!("{}: not a readable .npy map ({what})", path.display());
        let mut head = [0u8; 10];
        file.read_exact(&mut head)
            .map_err(|_| bad("shorter than a header"))?;
        if &head[..6] != b"\x93NUMPY" {
            return Err(bad("bad magic"));
        }
        let (hlen, start) = if head[6] == 1 {
            (usize::from(u16::from_le_bytes([head[8], head[9]])), 10)
        } else {
            let mut more = [0u8; 2];
            file.read_exact(&mut more)
                .map_err(|_| bad("short header"))?;
            let n = u32::from_le_bytes([head[8], head[9], more[0], more[1]]);
            (n as usize, 12)
        };
        if hlen > 1 << 16 {
            return Err(bad("header too long"));
        }
        let mut text = vec![0u8; hlen];
        file.read_exact(&mut text)
            .map_err(|_| bad("short header"))?;
        let text = String::from_utf8_lossy(&text).into_owned();
        let field = |key: &str| -> Option<String> {
            let at = text.find(&format!("'{key}'"))? + key.len() + 2;
            let rest = text[at..].trim_start().strip_prefix(':')?.trim_start();
            let end = if rest.starts_with('(') {
                rest.find(')')? + 1
            } else {
                rest.find([',', '}'])?
            };
            Some(rest[..end].trim().to_string())
        };
        let descr = field("descr").ok_or_else(|| bad("no descr"))?;
        let descr = descr.trim_matches(['\'', '"']);
        let ok_type = match dtype {
            Dtype::F32 => descr == "<f4" || descr == "f4",
            Dtype::U8 => descr == "|u1" || descr == "u1" || descr == "<u1",
        };
        if !ok_type {
            bail!(
                "{}: values of type {descr}, {} expected",
                path.display(),
                match dtype {
                    Dtype::F32 => "float32 (<f4)",
                    Dtype::U8 => "uint8 (|u1)",
                }
            );
        }
        if field("fortran_order").as_deref() != Some("False") {
            return Err(bad("Fortran order"));
        }
        let shape_text = field("shape").ok_or_else(|| bad("no shape"))?;
        let dims: Vec<usize> = shape_text
            .trim_matches(['(', ')'])
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad("bad shape"))?;
        let shape = match dims[..] {
            [h, w] => [h, w, 1],
            [h, w, c] => [h, w, c],
            _ => bail!(
                "{}: shape {dims:?} is not a two- or three-dimensional map",
                path.display()
            ),
        };
        let data_start = (start + hlen) as u64;
        let need = shape
            .iter()
            .try_fold(dtype.size() as u64, |a, &b| a.checked_mul(b as u64))
            .ok_or_else(|| bad("shape too large"))?;
        if len < data_start + need {
            bail!(
                "{}: truncated ({len} bytes; the shape {dims:?} needs {})",
                path.display(),
                data_start + need
            );
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            data_start,
            dtype,
            shape,
            buf: Vec::new(),
        })
    }

    /// `[H, W, C]`.
    pub(super) fn shape(&self) -> [usize; 3] {
        self.shape
    }

    fn read_bytes(&mut self, y0: usize, y1: usize) -> Result<&[u8]> {
        let row = self.shape[1] * self.shape[2] * self.dtype.size();
        self.buf.resize((y1 - y0) * row, 0);
        let at = self.data_start + (y0 * row) as u64;
        // A seek within the buffer is cheap; reading on in order never seeks the file.
        self.file
            .seek(SeekFrom::Start(at))
            .and_then(|_| self.file.read_exact(&mut self.buf))
            .with_context(|| format!("{}: cannot read rows {y0}..{y1}", self.path.display()))?;
        Ok(&self.buf)
    }

    /// Rows `y0..y1` of a `float32` map, values in C order.
    pub(super) fn rows_f32(&mut self, y0: usize, y1: usize, out: &mut Vec<f32>) -> Result<()> {
        debug_assert_eq!(self.dtype, Dtype::F32);
        let bytes = self.read_bytes(y0, y1)?;
        out.clear();
        out.extend(
            bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
        Ok(())
    }

    /// Rows `y0..y1` of a `uint8` map.
    pub(super) fn rows_u8(&mut self, y0: usize, y1: usize, out: &mut Vec<u8>) -> Result<()> {
        debug_assert_eq!(self.dtype, Dtype::U8);
        let bytes = self.read_bytes(y0, y1)?;
        out.clear();
        out.extend_from_slice(bytes);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_bands_of_what_symframe_io_writes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        let data: Vec<f32> = (0..5 * 3 * 2).map(|v| v as f32 * 0.5).collect();
        symframe_io::write_npy_f32(&path, &[5, 3, 2], &data).unwrap();
        let mut r = NpyBands::open(&path, Dtype::F32, 5, 3, 2).unwrap();
        let mut out = Vec::new();
        r.rows_f32(2, 4, &mut out).unwrap();
        assert_eq!(out, data[12..24]);
        r.rows_f32(0, 1, &mut out).unwrap();
        assert_eq!(out, data[..6]);
        let e = NpyBands::open(&path, Dtype::F32, 5, 3, 3).err().unwrap();
        assert!(e.to_string().contains("a.npy: shape [5, 3, 2]"), "{e}");
        let e = NpyBands::open(&path, Dtype::U8, 5, 3, 2).err().unwrap();
        assert!(e.to_string().contains("values of type <f4"), "{e}");

        let codes = dir.path().join("s.npy");
        symframe_io::write_npy_u8(&codes, &[2, 2], &[1, 2, 3, 4]).unwrap();
        let mut r = NpyBands::open(&codes, Dtype::U8, 2, 2, 1).unwrap();
        let mut out = Vec::new();
        r.rows_u8(1, 2, &mut out).unwrap();
        assert_eq!(out, [3, 4]);

        // Cut short: an error naming the file, before anything is read.
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 4]).unwrap();
        let e = NpyBands::open(&path, Dtype::F32, 5, 3, 2).err().unwrap();
        assert!(e.to_string().contains("a.npy: truncated"), "{e}");
    }
}
