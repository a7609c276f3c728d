//! Flags that both programs pass to the tile cache: its sample type and the memory for decoding.

use anyhow::{bail, Result};
use clap::ValueEnum;

/// Sample type of the tile cache.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CacheFormatArg {
    /// The smallest exact one for the images: u8, u16 or f32.
    Auto,
    /// 32-bit floats (exact).
    F32,
    /// Half floats (half the size).
    F16,
    /// 8-bit images' codes (exact, a quarter of f32).
    U8,
    /// 8- or 16-bit images' codes (exact, half of f32).
    U16,
}

impl From<CacheFormatArg> for symframe_io::CacheFormat {
    fn from(a: CacheFormatArg) -> Self {
        match a {
            CacheFormatArg::F32 => symframe_io::CacheFormat::F32,
            CacheFormatArg::F16 => symframe_io::CacheFormat::F16,
            CacheFormatArg::Auto => symframe_io::CacheFormat::Auto,
            CacheFormatArg::U8 => symframe_io::CacheFormat::U8,
            CacheFormatArg::U16 => symframe_io::CacheFormat::U16,
        }
    }
}

/// The largest `--decode-memory`, in MiB (1 TiB): far above any machine's memory, and its
/// bytes fit a 64-bit size.
pub const MAX_DECODE_MEMORY_MIB: usize = 1 << 20;

/// The default of `--decode-memory`, in MiB: the tile cache's default batch.
pub fn default_decode_memory_mib() -> usize {
    symframe_io::CacheOptions::default().batch_bytes >> 20
}

/// The bytes of `--decode-memory MIB`, checked: 1 MiB to [`MAX_DECODE_MEMORY_MIB`] (a huge
/// value once wrapped around to a tiny batch).
pub fn decode_memory_bytes(mib: usize) -> Result<usize> {
    if !(1..=MAX_DECODE_MEMORY_MIB).contains(&mib) {
        bail!("--decode-memory must be in [1, {MAX_DECODE_MEMORY_MIB}] MiB (at most 1 TiB), got {mib}");
    }
    Ok(mib << 20)
}
