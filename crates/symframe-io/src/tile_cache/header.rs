//! The cache file's header: its fixed fields, the input warnings it keeps, and the
//! fingerprint of the inputs that decides reuse.

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

use rayon::prelude::*;

use super::codes::{LightCodes, LIGHT_RECORD_BYTES};
#[cfg(any(test, feature = "fuzzing"))]
use super::verify;
use super::{CacheFormat, TileGrid};
use crate::codecs::DecodeOptions;
use crate::dataset::Dataset;
use crate::error::{Error, Result, Warning};
use crate::fingerprint::Fingerprint;

/// Format version of the cache file (bumped whenever the layout changes; 4: integer caches).
pub const CACHE_VERSION: u32 = 4;
pub(super) const MAGIC: &[u8; 8] = b"SYMFCACH";
pub(super) const HEADER_BYTES: usize = 4096;
pub(super) const ENDIAN_MARK: u32 = 0x0102_0304;

/// The fixed header fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Header {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) n_lights: usize,
    pub(super) tile: usize,
    pub(super) fingerprint: u64,
    pub(super) images_done: usize,
    pub(super) complete: bool,
    /// Lights per block inside a tile (the decoding batch).
    pub(super) light_block: usize,
    /// How samples are stored.
    pub(super) format: CacheFormat,
}

/// Bytes of the encoded header fields, checksum included.
pub(super) const FIELDS: usize = 96;
/// Bytes of the header fields that the header checksum covers.
pub(super) const SUMMED: usize = 88;

impl Header {
    pub(super) fn data_bytes(&self) -> u64 {
        (self.width as u64)
            .saturating_mul(self.height as u64)
            .saturating_mul(self.n_lights as u64)
            .saturating_mul(self.format.pixel_bytes() as u64)
    }

    /// Number of tiles.
    fn n_tiles(&self) -> u64 {
        (self.width.div_ceil(self.tile.max(1)) as u64)
            .saturating_mul(self.height.div_ceil(self.tile.max(1)) as u64)
    }

    /// Light blocks per tile.
    pub(super) fn n_blocks(&self) -> usize {
        self.n_lights.div_ceil(self.light_block.max(1))
    }

    /// Where the block checksum table starts.
    pub(super) fn table_offset(&self) -> u64 {
        (HEADER_BYTES as u64).saturating_add(self.data_bytes())
    }

    /// Where the table of block scale exponents starts (half-float caches only).
    pub(super) fn scales_offset(&self) -> u64 {
        self.table_offset().saturating_add(
            self.n_tiles()
                .saturating_mul(self.n_blocks() as u64)
                .saturating_mul(8),
        )
    }

    /// Where the table of the lights' records starts (integer caches only; after the
    /// checksums, where a half-float cache has its exponents).
    pub(super) fn lights_offset(&self) -> u64 {
        self.scales_offset()
    }

    /// The whole file's length: header, samples, checksum table, and for half floats the
    /// table of block scale exponents, for integer formats the table of the lights' records.
    pub(super) fn file_len(&self) -> u64 {
        let extra = match self.format {
            CacheFormat::F16 => self.n_tiles().saturating_mul(self.n_blocks() as u64) * 4,
            CacheFormat::U8 | CacheFormat::U16 => {
                (self.n_lights as u64).saturating_mul(LIGHT_RECORD_BYTES as u64)
            }
            CacheFormat::F32 | CacheFormat::Auto => 0,
        };
        self.scales_offset().saturating_add(extra)
    }

    /// The records of block `b`'s lights (integer caches; empty for float ones, or past the
    /// end of `file`): part of what the block's checksum covers.
    pub(super) fn block_lights<'a>(&self, file: &'a [u8], b: usize) -> &'a [u8] {
        if !matches!(self.format, CacheFormat::U8 | CacheFormat::U16) {
            return &[];
        }
        let first = b * self.light_block;
        let lights = self.light_block.min(self.n_lights.saturating_sub(first));
        let at = self.lights_offset() as usize + first * LIGHT_RECORD_BYTES;
        file.get(at..at + lights * LIGHT_RECORD_BYTES)
            .unwrap_or(&[])
    }

    /// Every light's record of an integer cache's `file`; `None` when one is not a record of
    /// this format (a file damaged or forged with valid checksums).
    pub(super) fn light_records(&self, file: &[u8]) -> Option<Vec<LightCodes>> {
        let bits = match self.format {
            CacheFormat::U8 => 8,
            CacheFormat::U16 => 16,
            _ => return None,
        };
        let at = self.lights_offset() as usize;
        let table = file.get(at..at + self.n_lights * LIGHT_RECORD_BYTES)?;
        table
            .chunks_exact(LIGHT_RECORD_BYTES)
            .map(|r| LightCodes::decode(r, bits))
            .collect()
    }

    /// The power-of-two exponent that scaled block `k` (`block * n_tiles + tile`) before it
    /// was stored as half floats (0 for other caches).
    pub(super) fn scale_exponent(&self, file: &[u8], k: usize) -> i32 {
        match self.format {
            CacheFormat::F32 | CacheFormat::U8 | CacheFormat::U16 | CacheFormat::Auto => 0,
            CacheFormat::F16 => {
                let at = self.scales_offset() as usize + 4 * k;
                file.get(at..at + 4)
                    .map_or(0, |b| i32::from_le_bytes(b.try_into().unwrap()))
            }
        }
    }

    /// Byte range (from the file's start) of tile `t`: its light blocks, one after another.
    pub(super) fn tile_range(&self, grid: &TileGrid, t: usize) -> (usize, usize) {
        let stride = self.n_lights * self.format.pixel_bytes();
        (
            HEADER_BYTES + grid.first_pixel(t) * stride,
            grid.tile_pixels(t) * stride,
        )
    }

    /// Byte range (from the file's start) of light block `b` of tile `t`.
    pub(super) fn block_range(&self, grid: &TileGrid, t: usize, b: usize) -> (usize, usize) {
        let np = grid.tile_pixels(t);
        let lights = self.light_block.min(self.n_lights - b * self.light_block);
        let px = self.format.pixel_bytes();
        (
            HEADER_BYTES
                + grid.first_pixel(t) * self.n_lights * px
                + b * self.light_block * np * px,
            np * lights * px,
        )
    }

    pub(super) fn encode(&self) -> [u8; FIELDS] {
        let mut b = [0u8; FIELDS];
        b[..8].copy_from_slice(MAGIC);
        b[8..12].copy_from_slice(&CACHE_VERSION.to_le_bytes());
        b[12..16].copy_from_slice(&ENDIAN_MARK.to_ne_bytes());
        let fields = [
            self.width as u64,
            self.height as u64,
            self.n_lights as u64,
            self.tile as u64,
            self.fingerprint,
            self.images_done as u64,
            self.complete as u64,
            self.light_block as u64,
            self.format.code(),
        ];
        for (k, v) in fields.iter().enumerate() {
            b[16 + 8 * k..24 + 8 * k].copy_from_slice(&v.to_le_bytes());
        }
        let sum = xxhash_rust::xxh3::xxh3_64(&b[..SUMMED]);
        b[SUMMED..FIELDS].copy_from_slice(&sum.to_le_bytes());
        b
    }

    /// Decodes a header; `None` when it is not a cache of this version and byte order, or
    /// when its checksum fails.
    pub(super) fn decode(b: &[u8]) -> Option<Self> {
        if b.len() < FIELDS || &b[..8] != MAGIC {
            return None;
        }
        let sum = u64::from_le_bytes(b[SUMMED..FIELDS].try_into().unwrap());
        if xxhash_rust::xxh3::xxh3_64(&b[..SUMMED]) != sum {
            return None;
        }
        let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        if u32_at(8) != CACHE_VERSION
            || u32::from_ne_bytes(b[12..16].try_into().unwrap()) != ENDIAN_MARK
        {
            return None;
        }
        let f = |k: usize| u64::from_le_bytes(b[16 + 8 * k..24 + 8 * k].try_into().unwrap());
        Some(Self {
            width: f(0) as usize,
            height: f(1) as usize,
            n_lights: f(2) as usize,
            tile: f(3) as usize,
            fingerprint: f(4),
            images_done: f(5) as usize,
            complete: f(6) == 1,
            light_block: f(7) as usize,
            format: CacheFormat::from_code(f(8))?,
        })
    }
}

/// Checks a whole cache file's bytes as a reuse would, for fuzzing the header, table and
/// warnings parsers: `None` if the header is refused, else the number of failing blocks.
#[cfg(any(test, feature = "fuzzing"))]
pub fn check_cache_bytes(b: &[u8]) -> Option<usize> {
    let h = Header::decode(b)?;
    if !(h.complete
        && h.width > 0
        && h.height > 0
        && h.tile > 0
        && (1..=h.n_lights).contains(&h.light_block)
        && b.len() as u64 == h.file_len())
    {
        return None;
    }
    if matches!(h.format, CacheFormat::U8 | CacheFormat::U16) {
        h.light_records(b)?;
    }
    let _ = read_warnings(b);
    Some(verify(b, &h, |_, _| {}).len())
}

/// Where the input warnings are kept in the header: length (`u32`), XXH3-64, JSON.
pub(super) const WARNINGS_AT: usize = 256;

/// Encodes warnings for the header (as many as fit in it).
pub(super) fn encode_warnings(warnings: &[Warning]) -> Vec<u8> {
    let mut kept = warnings.to_vec();
    loop {
        let json = serde_json::to_vec(&kept).unwrap_or_default();
        if WARNINGS_AT + 12 + json.len() <= HEADER_BYTES || kept.is_empty() {
            let mut b = (json.len() as u32).to_le_bytes().to_vec();
            b.extend_from_slice(&xxhash_rust::xxh3::xxh3_64(&json).to_le_bytes());
            b.extend_from_slice(&json);
            return b;
        }
        kept.pop();
    }
}

/// The warnings kept in a cache's header (none if absent or damaged).
pub(super) fn read_warnings(file: &[u8]) -> Vec<Warning> {
    let Some(b) = file.get(WARNINGS_AT..HEADER_BYTES) else {
        return Vec::new();
    };
    let len = u32::from_le_bytes(b[..4].try_into().unwrap()) as usize;
    let sum = u64::from_le_bytes(b[4..12].try_into().unwrap());
    match b.get(12..12 + len) {
        Some(json) if len > 0 && xxhash_rust::xxh3::xxh3_64(json) == sum => {
            serde_json::from_slice(json).unwrap_or_default()
        }
        _ => Vec::new(),
    }
}

/// XXH3-64 of a file's bytes, read in 1 MiB pieces.
pub fn file_content_hash(path: &Path) -> Result<u64> {
    use std::io::Read;
    let mut f = File::open(path).map_err(|e| Error::read(path, e))?;
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        match f.read(&mut buf) {
            Ok(0) => return Ok(h.digest()),
            Ok(k) => h.update(&buf[..k]),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::read(path, e)),
        }
    }
}

/// How the images enter an inputs fingerprint: their bytes, or only their size and
/// modification time (`--trust-mtime`: no file is read).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StampKind {
    /// XXH3-64 of each image file's bytes.
    Content,
    /// Each image file's size and modification time.
    SizeAndMtime,
}

/// The two fingerprints of a dataset, from one pass over its images.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fingerprints {
    /// What the tile cache is keyed on: the images' canonical paths and stamps, the light
    /// intensities, the decode options, the cache format and the crate version.
    pub cache: u64,
    /// The capture itself, wherever it lies: the images' sizes and stamps in light order, the
    /// light directions and intensities (no paths, no options). A copied dataset has the same;
    /// any changed image or light a different one. Recorded in `report.json` so that `fit`
    /// can tell frames estimated from another capture.
    pub inputs: u64,
    /// The cache format the fingerprint is for: the one asked for, or the one
    /// [`CacheFormat::Auto`] picks for these images ([`resolve_format`]).
    pub format: CacheFormat,
    /// How the images were stamped.
    pub kind: StampKind,
    /// Seconds spent computing them (reading and hashing every image unless `trust_mtime`).
    pub seconds: f64,
}

/// The fingerprint of a dataset's decoded samples (see [`Fingerprints::cache`]), the files
/// read in parallel ([`file_content_hash`]) unless `trust_mtime`.
pub fn inputs_fingerprint(
    ds: &Dataset,
    opts: &DecodeOptions,
    trust_mtime: bool,
    format: CacheFormat,
) -> Result<u64> {
    Ok(dataset_fingerprints(ds, opts, trust_mtime, format)?.cache)
}

/// Both fingerprints of a dataset (see [`Fingerprints`]): every image's size and content hash
/// ([`file_content_hash`], the files read in parallel) or, with `trust_mtime`, modification
/// time instead of content.
pub fn dataset_fingerprints(
    ds: &Dataset,
    opts: &DecodeOptions,
    trust_mtime: bool,
    format: CacheFormat,
) -> Result<Fingerprints> {
    // The first pass over the images: one of another size fails here, from its header,
    // before any is hashed or decoded.
    crate::stack::check_header_sizes(ds, opts)?;
    let t = std::time::Instant::now();
    let format = resolve_format(ds, format);
    let mut f = Fingerprint::new();
    f.str("symframe tile cache")
        .u64(CACHE_VERSION as u64)
        .u64(format.code())
        .str(env!("CARGO_PKG_VERSION"))
        .u64(ds.images.len() as u64)
        .u64(opts.gamma.code())
        .f64(opts.saturation as f64)
        .u64(trust_mtime as u64);
    // Only a layer named: the default layer's fingerprint is that of caches built without the
    // option, which stay valid.
    if let Some(layer) = &opts.exr_layer {
        f.str("exr layer").str(layer);
    }
    let kind = if trust_mtime {
        StampKind::SizeAndMtime
    } else {
        StampKind::Content
    };
    let mut g = Fingerprint::new();
    g.str("symframe inputs")
        .str(match kind {
            StampKind::Content => "content",
            StampKind::SizeAndMtime => "size and mtime",
        })
        .u64(ds.images.len() as u64);
    let per_image: Vec<Result<(PathBuf, u64, u64)>> = ds
        .images
        .par_iter()
        .map(|p| {
            let meta = fs::metadata(p).map_err(|e| Error::read(p, e))?;
            let stamp = if trust_mtime {
                meta.modified()
                    .ok()
                    .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
                    .map_or(0, |d| d.as_nanos() as u64)
            } else {
                file_content_hash(p)?
            };
            let canonical = fs::canonicalize(p).unwrap_or_else(|_| p.clone());
            Ok((canonical, meta.len(), stamp))
        })
        .collect();
    for r in per_image {
        let (p, len, stamp) = r?;
        f.path(&p).u64(len).u64(stamp);
        g.u64(len).u64(stamp);
    }
    for l in &ds.lights {
        g.f64(l.x).f64(l.y).f64(l.z);
    }
    for h in [&mut f, &mut g] {
        match &ds.intensities {
            None => h.u64(0),
            Some(v) => {
                h.u64(1);
                for k in v.iter().flatten() {
                    h.f64(*k as f64);
                }
                h
            }
        };
    }
    Ok(Fingerprints {
        cache: f.finish(),
        inputs: g.finish(),
        format,
        kind,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// The cache format to build for `ds`: `format` itself, or for [`CacheFormat::Auto`] the
/// smallest that holds every image's samples as its header declares them (read from its
/// first 64 KiB): `u8` when all are 8-bit, `u16` when all are 8- or 16-bit integers, else
/// `f32` (float images, or a header that does not say).
pub fn resolve_format(ds: &Dataset, format: CacheFormat) -> CacheFormat {
    if format != CacheFormat::Auto {
        return format;
    }
    let mut bits = 8;
    for p in &ds.images {
        let declared = std::fs::File::open(p)
            .ok()
            .and_then(|f| crate::read_at_most(f, p, 64 << 10).ok())
            .and_then(|prefix| crate::codecs::declared_bits(p, &prefix));
        match declared {
            Some(b) => bits = bits.max(b),
            None => return CacheFormat::F32,
        }
    }
    if bits == 8 {
        CacheFormat::U8
    } else {
        CacheFormat::U16
    }
}

/// The cache's file stem for a dataset: a readable name plus a hash of its canonical source, so
/// datasets sharing a cache folder do not collide and one dataset always maps to one file.
pub(super) fn cache_stem(ds: &Dataset) -> String {
    let src = fs::canonicalize(&ds.source).unwrap_or_else(|_| ds.source.clone());
    let name: String = src
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(40)
        .collect();
    let hash = Fingerprint::new().path(&src).finish();
    format!(
        "{}-{hash:016x}",
        if name.is_empty() { "stack" } else { &name }
    )
}

/// Reads a file's header, `None` if the file is missing, too short or not a regular file (a
/// link, FIFO, device or folder there is not a cache this tool wrote: it is never opened, as
/// opening a FIFO would wait forever, and it is replaced like a stale cache).
pub(super) fn read_header(path: &Path) -> Result<Option<(Header, u64)>> {
    use std::io::Read;
    let (mut f, len) = match crate::open_own_file(path) {
        Ok(Some(f)) => f,
        Ok(None) | Err(Error::Invalid { .. }) => return Ok(None),
        Err(e) => return Err(e),
    };
    let mut b = [0u8; FIELDS];
    if f.read_exact(&mut b).is_err() {
        return Ok(None);
    }
    Ok(Header::decode(&b).map(|h| (h, len)))
}

/// The format version of the cache file at `path` when it is a cache of another version than
/// this one's ([`CACHE_VERSION`]); `None` when it is not a cache, or of this version.
pub(super) fn other_version(path: &Path) -> Option<u32> {
    use std::io::Read;
    let (mut f, _) = crate::open_own_file(path).ok()??;
    let mut b = [0u8; 12];
    f.read_exact(&mut b).ok()?;
    let v = u32::from_le_bytes(b[8..12].try_into().unwrap());
    (&b[..8] == MAGIC && v != CACHE_VERSION).then_some(v)
}

/// Whether `h` (of a file `len` bytes long) is a cache of these inputs with this tile size.
pub(super) fn matches(
    h: &Header,
    len: u64,
    fingerprint: u64,
    tile: usize,
    n_lights: usize,
) -> bool {
    h.fingerprint == fingerprint
        && h.tile == tile
        && h.n_lights == n_lights
        && h.width > 0
        && h.height > 0
        && (1..=n_lights).contains(&h.light_block)
        && len == h.file_len()
}
