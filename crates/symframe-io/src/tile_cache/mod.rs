//! A pixel-major on-disk tile cache of a dataset's images, for stacks that do not fit in memory.
//!
//! Each image is decoded once and its samples are scattered into one cache file, laid out tile
//! by tile (tiles of `tile x tile` pixels, row-major over the tile grid, the right and bottom
//! tiles cropped; each tile one contiguous range of `pixels * lights * 12` bytes, so estimation
//! maps one tile at a time). Inside a tile the lights come in blocks of `light_block` lights
//! (the decoding batch; the last block shorter), each block pixel-major: the tile's pixels
//! row-major, each pixel's RGB under the block's lights contiguous. When one batch holds every
//! image (up to 1 GiB of decoded images by default: 1,365 images of 256x256, 85 of 1024x1024)
//! there is one block and a tile is exactly a [`symframe::Stack`] of its pixels.
//!
//! Why blocks: a batch then fills one contiguous range per tile, written with one positioned
//! write, so every page of the file is written once. With each pixel's samples under all lights
//! contiguous instead, a batch of 85 paper-size images writes 1 KB per pixel every 18 KB, and
//! each 4 KB page is rewritten by four batches. Measured at paper scale (1,512 RGB images of
//! 1024x1024, 85 per batch, 18 GB cache, 2 cores, virtual disk of 260-580 MB/s): scattering
//! took 161-202 s with pixel-contiguous tiles written through a memory map, 41-178 s with
//! blocked tiles through a memory map, 32-41 s with blocked tiles and positioned writes (this
//! module; decoding took another 25 s). Readers see no difference: [`TileView`] gathers a
//! pixel's samples in any light order.
//!
//! File: a 4,096-byte header (magic, format version, an endianness mark, width, height, lights,
//! tile size, the inputs' fingerprint, the number of images already scattered, a completion
//! flag, the light block, and an XXH3-64 checksum of these fields), then the samples in native
//! byte order (`f32`, so the tiled estimate equals the in-memory one bit for bit), then a table
//! of one XXH3-64 checksum per block of each tile (block-major: block 0 of every tile, then
//! block 1, ...; little-endian `u64`). The fingerprint covers every image's path, size and
//! content (XXH3-64 of the file's bytes; modification time instead of content with
//! [`CacheOptions::trust_mtime`]), the light intensities, the decode options and the crate
//! version: the cache is reused when they match and rebuilt when they do not.
//!
//! Integrity: a header whose checksum fails is not a cache (the whole file is rebuilt). A
//! complete cache is verified before every reuse, every block of every tile against the table
//! (one pass over the file at memory or disk speed, next to decoding every image); the lights of
//! the blocks that fail are decoded again and rewritten in place (one decoding batch per bad
//! block), and [`CacheInfo::blocks_repaired`] says how many.
//!
//! Memory: images are decoded in parallel in batches of `batch_bytes / (width * height * 12)`
//! images (at least one), and each batch is written into the file tile by tile with positioned
//! writes from a small per-thread buffer (the file is not mapped while it is built). So the
//! resident set holds one batch of decoded images, whatever the stack's size. Readers map the
//! complete file and release each tile's pages once read ([`TileCache::release`],
//! `madvise(MADV_DONTNEED)`: for a shared file mapping the data stays in the page cache), so
//! mapped pages do not accumulate either.
//!
//! Concurrency and interruption: a lock file beside the cache (`flock`, Unix) lets several
//! processes share one cache folder: one builds while the others wait, then all read (under a
//! shared lock, held while the cache is mapped; a process that must rebuild an outdated cache
//! waits until its readers are done). Building
//! writes `<name>.stack.partial`, records after every batch how many images it holds (so an
//! interrupted build resumes where it stopped), and is renamed to `<name>.stack` when complete.
//! The cache must not be modified by other programs while it is mapped.

use std::fs::{self, File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Instant, UNIX_EPOCH};

use memmap2::Mmap;
use rayon::prelude::*;

use crate::codecs::DecodeOptions;
use crate::dataset::Dataset;
use crate::error::Warning;
use crate::error::{Error, Result};
use crate::fingerprint::Fingerprint;
use crate::stack::{check_dataset, check_size, decode_stack_image, Notes};

/// Format version of the cache file (bumped whenever the layout changes).
pub const CACHE_VERSION: u32 = 2;
const MAGIC: &[u8; 8] = b"SYMFCACH";
const HEADER_BYTES: usize = 4096;
const ENDIAN_MARK: u32 = 0x0102_0304;

/// The tiles of a `width x height` image, `tile x tile` pixels each (the last column and row of
/// tiles cropped), numbered row-major over the tile grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileGrid {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Tile side in pixels.
    pub tile: usize,
}

/// A tile's pixel rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileRect {
    /// Left column.
    pub x0: usize,
    /// Top row.
    pub y0: usize,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl TileGrid {
    /// The grid of `tile`-pixel tiles over a `width x height` image.
    ///
    /// # Panics
    /// If `tile` is zero.
    pub fn new(width: usize, height: usize, tile: usize) -> Self {
        assert!(tile > 0, "tile size must be positive");
        Self {
            width,
            height,
            tile,
        }
    }

    /// Tiles per row of tiles.
    pub fn tiles_x(&self) -> usize {
        self.width.div_ceil(self.tile)
    }

    /// Rows of tiles.
    pub fn tiles_y(&self) -> usize {
        self.height.div_ceil(self.tile)
    }

    /// Number of tiles.
    pub fn n_tiles(&self) -> usize {
        self.tiles_x() * self.tiles_y()
    }

    /// The pixels of tile `t`.
    pub fn rect(&self, t: usize) -> TileRect {
        let (tx, ty) = (t % self.tiles_x(), t / self.tiles_x());
        let (x0, y0) = (tx * self.tile, ty * self.tile);
        TileRect {
            x0,
            y0,
            width: self.tile.min(self.width - x0),
            height: self.tile.min(self.height - y0),
        }
    }

    /// Number of pixels of tile `t`.
    pub fn tile_pixels(&self, t: usize) -> usize {
        let r = self.rect(t);
        r.width * r.height
    }

    /// Position of tile `t`'s first pixel in tile order (all pixels of the tiles before it).
    pub fn first_pixel(&self, t: usize) -> usize {
        if t >= self.n_tiles() {
            return self.width * self.height;
        }
        let r = self.rect(t);
        // Every row of tiles above is full height; the tiles to the left share this row's height.
        r.y0 * self.width + r.x0 * r.height
    }

    /// Image pixel indices (`y * width + x`) of tile `t`'s pixels, in tile order (row-major
    /// inside the tile).
    pub fn pixels(&self, t: usize) -> impl Iterator<Item = usize> {
        let r = self.rect(t);
        let w = self.width;
        (r.y0..r.y0 + r.height).flat_map(move |y| (r.x0..r.x0 + r.width).map(move |x| y * w + x))
    }
}

/// How the cache is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CacheOptions {
    /// Tile side in pixels.
    pub tile: usize,
    /// Memory budget of one batch of decoded images, in bytes (at least one image per batch).
    pub batch_bytes: usize,
    /// Fingerprint the images by path, size and modification time only, not by content
    /// (skips reading every image on a rerun; an image changed with its size and time kept,
    /// as `cp -p`, `rsync -a` or `tar x` do, then goes unnoticed).
    pub trust_mtime: bool,
}

impl Default for CacheOptions {
    /// 32-pixel tiles, 1 GiB batches.
    fn default() -> Self {
        Self {
            tile: 32,
            batch_bytes: 1 << 30,
            trust_mtime: false,
        }
    }
}

/// What opening the cache did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CacheInfo {
    /// The cache file.
    pub path: PathBuf,
    /// Its size in bytes.
    pub bytes: u64,
    /// Whether a complete cache for these inputs was found (no image decoded).
    pub hit: bool,
    /// Images decoded by this call.
    pub images_decoded: usize,
    /// Images already in a partial cache left by an interrupted build, reused.
    pub images_resumed: usize,
    /// Images per decoding batch.
    pub batch_images: usize,
    /// Seconds spent decoding images (wall clock, all threads together).
    pub decode_s: f64,
    /// Seconds spent scattering decoded images into the cache.
    pub scatter_s: f64,
    /// The inputs' fingerprint (hex).
    pub fingerprint: String,
    /// Seconds spent fingerprinting the images (reading and hashing every file unless
    /// [`CacheOptions::trust_mtime`]).
    pub fingerprint_s: f64,
    /// Seconds spent verifying the checksums of a reused (or resumed) cache.
    pub verify_s: f64,
    /// Blocks of tiles (tile, light block) of a reused cache that failed their checksum.
    pub blocks_corrupt: usize,
    /// Light blocks decoded again and rewritten because some tile's block failed its checksum.
    pub blocks_repaired: usize,
    /// Warnings about the inputs (mixed sample types, grey among RGB, negative samples), for
    /// the caller to print; found when the images were decoded and kept in the cache's header,
    /// so a reuse reports them again.
    pub warnings: Vec<Warning>,
}

/// A complete tile cache, memory-mapped read-only.
#[derive(Debug)]
pub struct TileCache {
    map: Mmap,
    grid: TileGrid,
    n_lights: usize,
    light_block: usize,
    fingerprint: u64,
    path: PathBuf,
    /// Held (shared) while the cache is mapped, so no other process rebuilds it meanwhile.
    _lock: CacheLock,
}

/// The fixed header fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Header {
    width: usize,
    height: usize,
    n_lights: usize,
    tile: usize,
    fingerprint: u64,
    images_done: usize,
    complete: bool,
    /// Lights per block inside a tile (the decoding batch).
    light_block: usize,
}

/// Bytes of the encoded header fields, checksum included.
const FIELDS: usize = 88;
/// Bytes of the header fields that the header checksum covers.
const SUMMED: usize = 80;

impl Header {
    fn data_bytes(&self) -> u64 {
        (self.width as u64)
            .saturating_mul(self.height as u64)
            .saturating_mul(self.n_lights as u64)
            .saturating_mul(12)
    }

    /// Light blocks per tile.
    fn n_blocks(&self) -> usize {
        self.n_lights.div_ceil(self.light_block.max(1))
    }

    /// Where the block checksum table starts.
    fn table_offset(&self) -> u64 {
        (HEADER_BYTES as u64).saturating_add(self.data_bytes())
    }

    /// The whole file's length: header, samples, checksum table.
    fn file_len(&self) -> u64 {
        let tiles = (self.width.div_ceil(self.tile.max(1)) as u64)
            .saturating_mul(self.height.div_ceil(self.tile.max(1)) as u64);
        self.table_offset().saturating_add(
            tiles
                .saturating_mul(self.n_blocks() as u64)
                .saturating_mul(8),
        )
    }

    /// Byte range (from the file's start) of light block `b` of tile `t`.
    fn block_range(&self, grid: &TileGrid, t: usize, b: usize) -> (usize, usize) {
        let np = grid.tile_pixels(t);
        let lights = self.light_block.min(self.n_lights - b * self.light_block);
        (
            HEADER_BYTES
                + grid.first_pixel(t) * self.n_lights * 12
                + b * self.light_block * np * 12,
            np * lights * 12,
        )
    }

    fn encode(&self) -> [u8; FIELDS] {
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
    fn decode(b: &[u8]) -> Option<Self> {
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
        })
    }
}

/// Checks a whole cache file's bytes as a reuse would, for fuzzing the header, table and
/// warnings parsers: `None` if the header is refused, else the number of failing blocks.
#[doc(hidden)]
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
    let _ = read_warnings(b);
    Some(verify(b, &h).len())
}

/// Where the input warnings are kept in the header: length (`u32`), XXH3-64, JSON.
const WARNINGS_AT: usize = 256;

/// Encodes warnings for the header (as many as fit in it).
fn encode_warnings(warnings: &[Warning]) -> Vec<u8> {
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
fn read_warnings(file: &[u8]) -> Vec<Warning> {
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

/// The fingerprint of a dataset's decoded samples: every image's path (canonical when
/// possible), size and content hash ([`file_content_hash`], the files read in parallel) or,
/// with `trust_mtime`, modification time instead of content; the light intensities, the
/// decode options, the cache format and the crate version.
pub fn inputs_fingerprint(ds: &Dataset, opts: &DecodeOptions, trust_mtime: bool) -> Result<u64> {
    let mut f = Fingerprint::new();
    f.str("symframe tile cache")
        .u64(CACHE_VERSION as u64)
        .str(env!("CARGO_PKG_VERSION"))
        .u64(ds.images.len() as u64)
        .u64(opts.linear_8bit as u64)
        .f64(opts.saturation as f64)
        .u64(trust_mtime as u64);
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
    }
    match &ds.intensities {
        None => f.u64(0),
        Some(v) => {
            f.u64(1);
            for k in v.iter().flatten() {
                f.f64(*k as f64);
            }
            &mut f
        }
    };
    Ok(f.finish())
}

/// The cache's file stem for a dataset: a readable name plus a hash of its canonical source, so
/// datasets sharing a cache folder do not collide and one dataset always maps to one file.
fn cache_stem(ds: &Dataset) -> String {
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

/// An advisory lock on a cache (a lock file beside it; `flock` on Unix, nothing elsewhere).
#[derive(Debug)]
struct CacheLock {
    file: File,
    path: PathBuf,
}

impl CacheLock {
    fn open(path: &Path) -> Result<Self> {
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(path)
            .map_err(|e| Error::write(path, e))?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
        })
    }

    #[cfg(unix)]
    fn set(&self, exclusive: bool) -> Result<()> {
        use std::os::unix::io::AsRawFd;
        let op = if exclusive {
            libc::LOCK_EX
        } else {
            libc::LOCK_SH
        };
        loop {
            // SAFETY: flock on a file descriptor we own.
            if unsafe { libc::flock(self.file.as_raw_fd(), op) } == 0 {
                return Ok(());
            }
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(Error::write(&self.path, e));
            }
        }
    }

    #[cfg(not(unix))]
    fn set(&self, _exclusive: bool) -> Result<()> {
        Ok(())
    }

    /// Takes the exclusive lock if no one else holds the lock; `false` if someone does (then
    /// this process holds no lock: a failed conversion gives up the shared one).
    #[cfg(unix)]
    fn try_exclusive(&self) -> Result<bool> {
        use std::os::unix::io::AsRawFd;
        loop {
            // SAFETY: flock on a file descriptor we own.
            if unsafe { libc::flock(self.file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
                return Ok(true);
            }
            let e = std::io::Error::last_os_error();
            match e.kind() {
                std::io::ErrorKind::Interrupted => continue,
                std::io::ErrorKind::WouldBlock => return Ok(false),
                _ => return Err(Error::write(&self.path, e)),
            }
        }
    }

    #[cfg(not(unix))]
    fn try_exclusive(&self) -> Result<bool> {
        Ok(true)
    }
}

/// Reads a file's header, `None` if the file is missing or too short.
fn read_header(path: &Path) -> Result<Option<(Header, u64)>> {
    use std::io::Read;
    let mut f = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::read(path, e)),
    };
    let len = f.metadata().map_err(|e| Error::read(path, e))?.len();
    let mut b = [0u8; FIELDS];
    if f.read_exact(&mut b).is_err() {
        return Ok(None);
    }
    Ok(Header::decode(&b).map(|h| (h, len)))
}

/// Whether `h` (of a file `len` bytes long) is a cache of these inputs with this tile size.
fn matches(h: &Header, len: u64, fingerprint: u64, tile: usize, n_lights: usize) -> bool {
    h.fingerprint == fingerprint
        && h.tile == tile
        && h.n_lights == n_lights
        && h.width > 0
        && h.height > 0
        && (1..=n_lights).contains(&h.light_block)
        && len == h.file_len()
}

/// The blocks of a complete cache whose checksum fails: `(tile, block)` pairs.
fn verify(map: &[u8], h: &Header) -> Vec<(usize, usize)> {
    let grid = TileGrid::new(h.width, h.height, h.tile);
    let nb = h.n_blocks();
    let table = h.table_offset() as usize;
    (0..grid.n_tiles() * nb)
        .into_par_iter()
        .filter_map(|k| {
            let (b, t) = (k / grid.n_tiles(), k % grid.n_tiles());
            let (o, len) = h.block_range(&grid, t, b);
            let want =
                u64::from_le_bytes(map[table + 8 * k..table + 8 * k + 8].try_into().unwrap());
            (xxhash_rust::xxh3::xxh3_64(&map[o..o + len]) != want).then_some((t, b))
        })
        .collect()
}

/// A complete cache of the wanted inputs, mapped and verified.
struct Found {
    map: Mmap,
    header: Header,
    /// `(tile, block)` pairs whose checksum failed.
    bad: Vec<(usize, usize)>,
    verify_s: f64,
}

/// Maps the file at `path` read-only, checking it is `len` bytes long.
fn map_file(path: &Path, len: u64) -> Result<Mmap> {
    let file = File::open(path).map_err(|e| Error::read(path, e))?;
    // SAFETY: the cache is only written by this module under the exclusive lock, which no
    // one can take while we hold the shared one (see the module docs).
    let map = unsafe { Mmap::map(&file) }.map_err(|e| Error::read(path, e))?;
    if map.len() as u64 != len {
        return Err(Error::invalid(path, "cache changed size while opening"));
    }
    Ok(map)
}

/// The complete cache of these inputs at `path`, mapped and verified; `None` if there is none
/// (missing, incomplete, stale or with a bad header).
fn open_complete(path: &Path, fingerprint: u64, tile: usize, n: usize) -> Result<Option<Found>> {
    let Some((header, len)) = read_header(path)? else {
        return Ok(None);
    };
    if !(header.complete && matches(&header, len, fingerprint, tile, n)) {
        return Ok(None);
    }
    let map = map_file(path, len)?;
    let t = Instant::now();
    let bad = verify(&map, &header);
    Ok(Some(Found {
        map,
        header,
        bad,
        verify_s: t.elapsed().as_secs_f64(),
    }))
}

impl TileCache {
    /// Opens the cache of `ds` in `dir` (created if needed), building it first when it is
    /// missing, incomplete or stale, and repairing the blocks of a complete one that fail their
    /// checksum. `stop` is polled between images: when it is set the build stops with
    /// [`Error::Interrupted`], keeping the images done for the next call.
    /// `on_image` is called once per decoded image (from worker threads).
    pub fn open_or_build(
        ds: &Dataset,
        opts: &DecodeOptions,
        dir: &Path,
        copts: CacheOptions,
        stop: &AtomicBool,
        on_image: &(dyn Fn() + Sync),
    ) -> Result<(TileCache, CacheInfo)> {
        check_dataset(ds)?;
        if copts.tile == 0 {
            return Err(Error::invalid(dir, "tile size must be positive"));
        }
        fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
        let t = Instant::now();
        let fingerprint = inputs_fingerprint(ds, opts, copts.trust_mtime)?;
        let fingerprint_s = t.elapsed().as_secs_f64();
        let stem = cache_stem(ds);
        let path = dir.join(format!("{stem}.stack"));
        let partial = dir.join(format!("{stem}.stack.partial"));
        let lock = CacheLock::open(&dir.join(format!("{stem}.lock")))?;
        let n = ds.images.len();
        let mut info = CacheInfo {
            path: path.clone(),
            bytes: 0,
            hit: false,
            images_decoded: 0,
            images_resumed: 0,
            batch_images: 0,
            decode_s: 0.0,
            scatter_s: 0.0,
            fingerprint: format!("{fingerprint:016x}"),
            fingerprint_s,
            verify_s: 0.0,
            blocks_corrupt: 0,
            blocks_repaired: 0,
            warnings: Vec::new(),
        };

        // A complete cache is read under a shared lock (taking it waits while another process
        // builds). Otherwise build (or repair) it under an exclusive lock, taken without
        // waiting: while others hold the shared lock (readers of a stale cache, or processes
        // here for the same reason), release and retry, so that exactly one process builds and
        // the others wait for it.
        let mut tries = 0u64;
        loop {
            lock.set(false)?;
            if let Some(found) = open_complete(&path, fingerprint, copts.tile, n)? {
                info.verify_s += found.verify_s;
                if found.bad.is_empty() {
                    info.hit = true;
                    info.warnings = read_warnings(&found.map);
                    return Ok(Self::from_found(found, path, lock, fingerprint, info));
                }
            }
            if lock.try_exclusive()? {
                break;
            }
            if stop.load(Ordering::Relaxed) {
                return Err(Error::Interrupted);
            }
            // Jittered, so that processes arriving together do not retry in lockstep.
            tries += 1;
            let jitter = (std::process::id() as u64 + tries * 7919) % 300;
            std::thread::sleep(std::time::Duration::from_millis(100 + jitter));
        }
        // Someone may have finished building (or repairing) between our check and the
        // exclusive lock.
        if let Some(found) = open_complete(&path, fingerprint, copts.tile, n)? {
            info.verify_s += found.verify_s;
            if found.bad.is_empty() {
                lock.set(false)?;
                info.hit = true;
                info.warnings = read_warnings(&found.map);
                return Ok(Self::from_found(found, path, lock, fingerprint, info));
            }
            let Found {
                map, header, bad, ..
            } = found;
            info.warnings = read_warnings(&map);
            drop(map);
            repair(ds, opts, &path, &header, &bad, stop, on_image, &mut info)?;
        } else {
            if path.exists() {
                fs::remove_file(&path).map_err(|e| Error::write(&path, e))?;
            }
            let built = build(ds, opts, &partial, fingerprint, copts, stop, on_image)?;
            fs::rename(&partial, &path).map_err(|e| Error::write(&path, e))?;
            info.images_decoded = built.decoded;
            info.images_resumed = built.resumed;
            info.batch_images = built.batch;
            info.decode_s = built.decode_s;
            info.scatter_s = built.scatter_s;
            info.warnings = built.warnings;
            // What an earlier, interrupted build wrote is verified like a reused cache.
            if built.resumed > 0 {
                if let Some(found) = open_complete(&path, fingerprint, copts.tile, n)? {
                    info.verify_s += found.verify_s;
                    let Found {
                        map, header, bad, ..
                    } = found;
                    drop(map);
                    repair(ds, opts, &path, &header, &bad, stop, on_image, &mut info)?;
                }
            }
        }
        lock.set(false)?;
        let (header, len) = read_header(&path)?
            .ok_or_else(|| Error::invalid(&path, "cache vanished after it was built"))?;
        let found = Found {
            map: map_file(&path, len)?,
            header,
            bad: Vec::new(),
            verify_s: 0.0,
        };
        Ok(Self::from_found(found, path, lock, fingerprint, info))
    }

    fn from_found(
        found: Found,
        path: PathBuf,
        lock: CacheLock,
        fingerprint: u64,
        mut info: CacheInfo,
    ) -> (TileCache, CacheInfo) {
        let h = found.header;
        info.bytes = found.map.len() as u64;
        (
            TileCache {
                map: found.map,
                grid: TileGrid::new(h.width, h.height, h.tile),
                n_lights: h.n_lights,
                light_block: h.light_block,
                fingerprint,
                path,
                _lock: lock,
            },
            info,
        )
    }

    /// The tile grid (image size and tile size).
    pub fn grid(&self) -> &TileGrid {
        &self.grid
    }

    /// Number of lights (images) per pixel.
    pub fn n_lights(&self) -> usize {
        self.n_lights
    }

    /// The inputs' fingerprint.
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// The cache file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Byte range of tile `t` in the file.
    fn range(&self, t: usize) -> (usize, usize) {
        let stride = self.n_lights * 12;
        let p0 = self.grid.first_pixel(t);
        (
            HEADER_BYTES + p0 * stride,
            self.grid.tile_pixels(t) * stride,
        )
    }

    /// Lights per block inside a tile (all of them when the cache was built in one batch).
    pub fn light_block(&self) -> usize {
        self.light_block
    }

    /// Tile `t`'s samples.
    pub fn tile(&self, t: usize) -> TileView<'_> {
        let (o, len) = self.range(t);
        TileView {
            data: bytemuck::cast_slice(&self.map[o..o + len]),
            n_pixels: self.grid.tile_pixels(t),
            n_lights: self.n_lights,
            light_block: self.light_block,
        }
    }

    /// Drops tile `t`'s pages from this process's mapping (they stay in the page cache), so
    /// the resident set does not grow with the number of tiles read. Reading the tile again
    /// after this is fine: its pages are read back from the file.
    pub fn release(&self, t: usize) {
        #[cfg(unix)]
        {
            let (o, len) = self.range(t);
            // SAFETY: a read-only shared file mapping: MADV_DONTNEED only unmaps the pages;
            // later accesses read the same bytes back from the file (page cache).
            let _ = unsafe {
                self.map
                    .unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, o, len)
            };
        }
        #[cfg(not(unix))]
        let _ = t;
    }
}

/// The samples of one tile: blocks of `light_block` lights (the last block shorter), each block
/// pixel-major (the tile's pixels in [`TileGrid::pixels`] order, each pixel's RGB under the
/// block's lights contiguous). With one block this is a [`symframe::Stack`] of the tile.
#[derive(Debug, Clone, Copy)]
pub struct TileView<'a> {
    data: &'a [f32],
    n_pixels: usize,
    n_lights: usize,
    light_block: usize,
}

impl<'a> TileView<'a> {
    /// Number of pixels of the tile.
    pub fn n_pixels(&self) -> usize {
        self.n_pixels
    }

    /// Where light `i`'s sample of pixel 0 is, and the step from one pixel to the next.
    fn locate(&self, i: usize) -> (usize, usize) {
        let b = i / self.light_block;
        let len = self.light_block.min(self.n_lights - b * self.light_block);
        (
            (b * self.light_block * self.n_pixels + (i - b * self.light_block)) * 3,
            len * 3,
        )
    }

    /// A gatherer of the samples of `lights` (input indices), in that order, pixel by pixel.
    pub fn gatherer(&self, lights: &[usize]) -> TileGather<'a> {
        TileGather {
            data: self.data,
            table: lights.iter().map(|&i| self.locate(i)).collect(),
        }
    }

    /// Every light's RGB at pixel `k` of the tile, in input order (`n_lights * 3` values).
    pub fn pixel(&self, k: usize, out: &mut [f32]) {
        for (i, o) in out.chunks_exact_mut(3).enumerate() {
            let (base, step) = self.locate(i);
            o.copy_from_slice(&self.data[base + k * step..base + k * step + 3]);
        }
    }
}

/// Gathers chosen lights' samples of a tile's pixels ([`TileView::gatherer`]).
#[derive(Debug, Clone)]
pub struct TileGather<'a> {
    data: &'a [f32],
    table: Vec<(usize, usize)>,
}

impl TileGather<'_> {
    /// The chosen lights' RGB at pixel `k` of the tile (`3` values per light, in `out`).
    #[inline]
    pub fn pixel(&self, k: usize, out: &mut [f32]) {
        for (&(base, step), o) in self.table.iter().zip(out.chunks_exact_mut(3)) {
            let at = base + k * step;
            o.copy_from_slice(&self.data[at..at + 3]);
        }
    }
}

/// What a build did.
struct Built {
    /// About the images decoded by this build.
    warnings: Vec<Warning>,
    decoded: usize,
    resumed: usize,
    batch: usize,
    decode_s: f64,
    scatter_s: f64,
}

/// Creates `path` of `len` bytes, reserving the disk space up front where the file system can
/// (so a full disk is an error here, not a fault while writing through the mapping).
fn create_sized(path: &Path, len: u64) -> Result<File> {
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(path)
        .map_err(|e| Error::write(path, e))?;
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::io::AsRawFd;
        // SAFETY: fallocate on a file descriptor we own.
        let r = unsafe { libc::fallocate(file.as_raw_fd(), 0, 0, len as libc::off_t) };
        if r != 0 {
            let e = std::io::Error::last_os_error();
            if e.raw_os_error() != Some(libc::EOPNOTSUPP) {
                return Err(Error::write(path, e));
            }
        }
    }
    file.set_len(len).map_err(|e| Error::write(path, e))?;
    Ok(file)
}

/// Builds (or resumes building) the partial cache at `partial`; on success it is complete.
fn build(
    ds: &Dataset,
    opts: &DecodeOptions,
    partial: &Path,
    fingerprint: u64,
    copts: CacheOptions,
    stop: &AtomicBool,
    on_image: &(dyn Fn() + Sync),
) -> Result<Built> {
    let n = ds.images.len();
    let notes = Notes::new(n);
    let decode_one = |i: usize| -> Result<(usize, usize, Vec<f32>)> {
        if stop.load(Ordering::Relaxed) {
            return Err(Error::Interrupted);
        }
        let r = decode_stack_image(ds, i, opts, &notes)?;
        on_image();
        Ok(r)
    };
    let mut decode_s = 0.0;
    let mut first: Option<Vec<f32>> = None;
    // Resume a partial build of the same inputs, else start afresh from the first image.
    let resumable = read_header(partial)?
        .filter(|(h, len)| !h.complete && matches(h, *len, fingerprint, copts.tile, n));
    let (mut header, file) = match resumable {
        Some((h, _)) => {
            let file = OpenOptions::new()
                .read(true)
                .write(true)
                .open(partial)
                .map_err(|e| Error::write(partial, e))?;
            (h, file)
        }
        None => {
            if partial.exists() {
                fs::remove_file(partial).map_err(|e| Error::write(partial, e))?;
            }
            let t = Instant::now();
            let (w, h, rgb) = decode_one(0)?;
            decode_s += t.elapsed().as_secs_f64();
            if w == 0 || h == 0 {
                return Err(Error::invalid(&ds.images[0], "image is empty"));
            }
            first = Some(rgb);
            let header = Header {
                width: w,
                height: h,
                n_lights: n,
                tile: copts.tile,
                fingerprint,
                images_done: 0,
                complete: false,
                light_block: (copts.batch_bytes / (w * h * 12)).clamp(1, n),
            };
            let file = create_sized(partial, header.file_len())?;
            (header, file)
        }
    };
    let write_header =
        |h: &Header| write_all_at(&file, &h.encode(), 0).map_err(|e| Error::write(partial, e));
    write_header(&header)?;

    let grid = TileGrid::new(header.width, header.height, header.tile);
    // One batch fills one block of lights in every tile (a resumed build keeps its blocks).
    let batch = header.light_block;
    let resumed = header.images_done;
    let mut decoded = first.is_some() as usize;
    let mut scatter_s = 0.0;
    let mut start = header.images_done;
    while start < n {
        if stop.load(Ordering::Relaxed) {
            return Err(Error::Interrupted);
        }
        let end = n.min(start + batch);
        let t = Instant::now();
        let from = if start == 0 && first.is_some() {
            1
        } else {
            start
        };
        let results: Vec<Result<(usize, usize, Vec<f32>)>> =
            (from..end).into_par_iter().map(decode_one).collect();
        decode_s += t.elapsed().as_secs_f64();
        let mut images = Vec::with_capacity(end - start);
        if from > start {
            images.extend(first.take());
        }
        // The first error in image order, as the in-memory loader reports it.
        for (j, r) in results.into_iter().enumerate() {
            let (w, h, rgb) = r?;
            check_size(ds, from + j, (w, h), (header.width, header.height))?;
            images.push(rgb);
        }
        decoded += end - from;
        let t = Instant::now();
        scatter(&file, partial, &grid, &header, start, &images)?;
        drop(images);
        scatter_s += t.elapsed().as_secs_f64();
        header.images_done = end;
        write_header(&header)?;
        start = end;
    }
    let warnings = notes.warnings(ds);
    write_all_at(&file, &encode_warnings(&warnings), WARNINGS_AT as u64)
        .map_err(|e| Error::write(partial, e))?;
    header.complete = true;
    write_header(&header)?;
    Ok(Built {
        warnings,
        decoded,
        resumed,
        batch,
        decode_s,
        scatter_s,
    })
}

/// Writes `buf` at `offset` of `file` (positioned write; the file's cursor is not used, so
/// threads can write different ranges at once).
fn write_all_at(file: &File, buf: &[u8], offset: u64) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileExt;
        file.write_all_at(buf, offset)
    }
    #[cfg(windows)]
    {
        use std::os::windows::fs::FileExt;
        let mut done = 0;
        while done < buf.len() {
            let n = file.seek_write(&buf[done..], offset + done as u64)?;
            if n == 0 {
                return Err(std::io::ErrorKind::WriteZero.into());
            }
            done += n;
        }
        Ok(())
    }
    #[cfg(not(any(unix, windows)))]
    {
        let _ = (file, buf, offset);
        Err(std::io::ErrorKind::Unsupported.into())
    }
}

/// Writes images `start..start + images.len()` (interleaved RGB, row-major; one block of
/// lights, every block before it full) into every tile of the cache file, and the block's
/// checksums into the table: per tile, the block is assembled in a per-thread buffer
/// (`pixels * images * 12` bytes, 1 MB for a 32-pixel tile and 85 images) and written with one
/// positioned write, so every page of the file is written once, by one batch, and nothing of
/// the file is mapped while building.
fn scatter(
    file: &File,
    path: &Path,
    grid: &TileGrid,
    h: &Header,
    start: usize,
    images: &[Vec<f32>],
) -> Result<()> {
    let stride = h.n_lights * 3;
    let b = images.len();
    let sums: Vec<u64> = (0..grid.n_tiles())
        .into_par_iter()
        .map_init(Vec::new, |buf: &mut Vec<f32>, t| {
            let np = grid.tile_pixels(t);
            buf.clear();
            buf.reserve(np * b * 3);
            for p in grid.pixels(t) {
                for img in images {
                    buf.extend_from_slice(&img[p * 3..p * 3 + 3]);
                }
            }
            let bytes: &[u8] = bytemuck::cast_slice(buf);
            let at = HEADER_BYTES + (grid.first_pixel(t) * stride + start * np * 3) * 4;
            write_all_at(file, bytes, at as u64).map_err(|e| Error::write(path, e))?;
            Ok(xxhash_rust::xxh3::xxh3_64(bytes))
        })
        .collect::<Result<_>>()?;
    let table: Vec<u8> = sums.iter().flat_map(|v| v.to_le_bytes()).collect();
    let block = start / h.light_block;
    let at = h.table_offset() + (block * grid.n_tiles() * 8) as u64;
    write_all_at(file, &table, at).map_err(|e| Error::write(path, e))
}

/// Decodes the lights of the light blocks that hold a failed `(tile, block)` of the complete
/// cache at `path` again and rewrites those blocks (in every tile) with their checksums, in
/// place. Called under the exclusive lock. An interruption leaves the cache complete with some
/// blocks still failing, which the next open repairs.
#[allow(clippy::too_many_arguments)]
fn repair(
    ds: &Dataset,
    opts: &DecodeOptions,
    path: &Path,
    h: &Header,
    bad: &[(usize, usize)],
    stop: &AtomicBool,
    on_image: &(dyn Fn() + Sync),
    info: &mut CacheInfo,
) -> Result<()> {
    let blocks: std::collections::BTreeSet<usize> = bad.iter().map(|&(_, b)| b).collect();
    info.blocks_corrupt += bad.len();
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .map_err(|e| Error::write(path, e))?;
    let grid = TileGrid::new(h.width, h.height, h.tile);
    let n = h.n_lights;
    for b in blocks {
        let (start, end) = (b * h.light_block, n.min((b + 1) * h.light_block));
        let t = Instant::now();
        let results: Vec<Result<(usize, usize, Vec<f32>)>> = (start..end)
            .into_par_iter()
            .map(|i| {
                if stop.load(Ordering::Relaxed) {
                    return Err(Error::Interrupted);
                }
                let r = decode_stack_image(ds, i, opts, &Notes::new(0))?;
                on_image();
                Ok(r)
            })
            .collect();
        info.decode_s += t.elapsed().as_secs_f64();
        let mut images = Vec::with_capacity(end - start);
        for (j, r) in results.into_iter().enumerate() {
            let (w, hh, rgb) = r?;
            check_size(ds, start + j, (w, hh), (h.width, h.height))?;
            images.push(rgb);
        }
        let t = Instant::now();
        scatter(&file, path, &grid, h, start, &images)?;
        info.scatter_s += t.elapsed().as_secs_f64();
        info.images_decoded += end - start;
        info.blocks_repaired += 1;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codecs::write_exr_rgb;
    use crate::stack::load_stack;
    use glam::DVec3;

    #[test]
    fn grid_orders_every_pixel_once() {
        for (w, h, t) in [(10, 7, 4), (8, 8, 8), (1, 5, 3), (33, 2, 32)] {
            let g = TileGrid::new(w, h, t);
            let mut seen = vec![false; w * h];
            let mut k = 0;
            for tile in 0..g.n_tiles() {
                assert_eq!(g.first_pixel(tile), k, "{w}x{h}/{t} tile {tile}");
                for p in g.pixels(tile) {
                    assert!(!seen[p]);
                    seen[p] = true;
                    k += 1;
                }
                assert_eq!(k - g.first_pixel(tile), g.tile_pixels(tile));
            }
            assert!(seen.iter().all(|&s| s));
            assert_eq!(g.first_pixel(g.n_tiles()), w * h);
        }
    }

    fn dataset(dir: &Path, w: usize, h: usize, n: usize) -> Dataset {
        let images: Vec<PathBuf> = (0..n)
            .map(|i| {
                let p = dir.join(format!("{i}.exr"));
                let rgb: Vec<f32> = (0..w * h * 3)
                    .map(|k| {
                        if (i + k) % 17 == 0 {
                            f32::NAN
                        } else {
                            (i * 1000 + k) as f32
                        }
                    })
                    .collect();
                write_exr_rgb(&p, w, h, &rgb).unwrap();
                p
            })
            .collect();
        Dataset {
            source: dir.join("test.lp"),
            lights: vec![DVec3::Z; n],
            images,
            intensities: Some((0..n).map(|i| [1.0, 2.0, 0.5 + i as f32]).collect()),
            mask: None,
        }
    }

    /// Checks every tile against the in-memory stack, bit for bit.
    fn same_as_stack(cache: &TileCache, ds: &Dataset) {
        let stack = load_stack(ds, &DecodeOptions::default(), &|| {}).unwrap();
        let g = cache.grid();
        assert_eq!(
            (g.width, g.height, cache.n_lights()),
            (stack.width, stack.height, stack.n_lights)
        );
        let mut a = vec![0.0f32; stack.n_lights * 3];
        let mut c = vec![0.0f32; stack.n_lights * 3];
        let reversed: Vec<usize> = (0..stack.n_lights).rev().collect();
        for t in 0..g.n_tiles() {
            let tile = cache.tile(t);
            let gather = tile.gatherer(&reversed);
            for (k, p) in g.pixels(t).enumerate() {
                tile.pixel(k, &mut a);
                let b = stack.pixel(p);
                gather.pixel(k, &mut c);
                for (i, rgb) in c.chunks_exact(3).enumerate() {
                    let j = stack.n_lights - 1 - i;
                    assert_eq!(
                        rgb.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        b[j * 3..j * 3 + 3]
                            .iter()
                            .map(|v| v.to_bits())
                            .collect::<Vec<_>>()
                    );
                }
                assert!(
                    a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                    "tile {t} px {p}"
                );
            }
            cache.release(t);
        }
    }

    #[test]
    fn builds_in_batches_reuses_resumes_and_rebuilds() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (11, 6, 9);
        let ds = dataset(d.path(), w, h, n);
        let dir = d.path().join("cache");
        let opts = DecodeOptions::default();
        // Batches of 2 images: 5 batches.
        let copts = copts_batches_of_2(w, h);
        let go = AtomicBool::new(false);
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(!info.hit);
        assert_eq!((info.images_decoded, info.batch_images), (n, 2));
        assert_eq!(cache.light_block(), 2);
        // Header, samples, one checksum per block (5) of each tile (3 x 2).
        assert_eq!(
            info.bytes,
            (HEADER_BYTES + w * h * n * 12 + 5 * 6 * 8) as u64
        );
        same_as_stack(&cache, &ds);
        drop(cache);

        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(info.hit && info.images_decoded == 0);
        same_as_stack(&cache, &ds);
        drop(cache);

        // Interrupted after 3 decoded images: the partial cache keeps whole batches.
        let stop = AtomicBool::new(false);
        let count = std::sync::atomic::AtomicUsize::new(0);
        let mut ds2 = ds.clone();
        ds2.intensities = None;
        let e = TileCache::open_or_build(&ds2, &opts, &dir, copts, &stop, &|| {
            if count.fetch_add(1, Ordering::SeqCst) + 1 >= 3 {
                stop.store(true, Ordering::SeqCst);
            }
        })
        .unwrap_err();
        assert!(matches!(e, Error::Interrupted), "{e}");
        let (cache, info) =
            TileCache::open_or_build(&ds2, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(!info.hit);
        assert!(info.images_resumed >= 2, "{info:?}");
        assert_eq!(info.images_resumed + info.images_decoded, n, "{info:?}");
        same_as_stack(&cache, &ds2);
        drop(cache);

        // A changed image invalidates it; a different tile size too.
        let rgb: Vec<f32> = (0..w * h * 3).map(|k| k as f32 * 0.5).collect();
        std::thread::sleep(std::time::Duration::from_millis(20));
        write_exr_rgb(&ds2.images[4], w, h, &rgb).unwrap();
        let (cache, info) =
            TileCache::open_or_build(&ds2, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(!info.hit && info.images_decoded == n);
        same_as_stack(&cache, &ds2);
        drop(cache);
        let copts3 = CacheOptions { tile: 3, ..copts };
        let (cache, info) =
            TileCache::open_or_build(&ds2, &opts, &dir, copts3, &go, &|| {}).unwrap();
        assert!(!info.hit);
        same_as_stack(&cache, &ds2);
        // One cache file per dataset, no partial left.
        let names: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| !n.ends_with(".lock"))
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        assert!(
            names[0].starts_with("test-") && names[0].ends_with(".stack"),
            "{names:?}"
        );
    }

    /// The cache file of `dir` (the one `.stack`).
    fn stack_file(dir: &Path) -> PathBuf {
        fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "stack"))
            .unwrap()
    }

    fn copts_batches_of_2(w: usize, h: usize) -> CacheOptions {
        CacheOptions {
            tile: 4,
            batch_bytes: 2 * w * h * 12 + 5,
            ..CacheOptions::default()
        }
    }

    /// A changed light-block field in the header was trusted (wrong samples, `hit: true`).
    #[test]
    fn a_changed_header_field_rebuilds_the_cache() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (11, 6, 9);
        let ds = dataset(d.path(), w, h, n);
        let dir = d.path().join("cache");
        let (opts, copts, go) = (
            DecodeOptions::default(),
            copts_batches_of_2(w, h),
            AtomicBool::new(false),
        );
        drop(TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap());
        let file = stack_file(&dir);
        let mut b = fs::read(&file).unwrap();
        // light_block (field 7) from 2 to 3.
        assert_eq!(b[16 + 8 * 7], 2);
        b[16 + 8 * 7] = 3;
        fs::write(&file, &b).unwrap();
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(!info.hit && info.images_decoded == n, "{info:?}");
        assert_eq!(cache.light_block(), 2);
        same_as_stack(&cache, &ds);
    }

    /// 3,000 changed floats of pixel data were trusted; now the failing blocks are decoded
    /// again and rewritten, the rest kept.
    #[test]
    fn changed_pixel_data_is_repaired() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (40, 30, 9);
        let ds = dataset(d.path(), w, h, n);
        let dir = d.path().join("cache");
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        let copts = CacheOptions {
            tile: 8,
            ..copts_batches_of_2(w, h)
        };
        drop(TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap());
        let file = stack_file(&dir);
        let mut b = fs::read(&file).unwrap();
        // 3,000 floats of tile 0 (8 x 8 pixels): its first 2-light block is 384 floats, so
        // these span the whole tile (9 lights x 64 pixels x 3 = 1,728 floats) and the next.
        let o = HEADER_BYTES;
        for k in 0..3000 {
            b[o + 4 * k..o + 4 * k + 4].copy_from_slice(&(k as f32 + 0.5).to_ne_bytes());
        }
        fs::write(&file, &b).unwrap();
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(!info.hit, "{info:?}");
        assert_eq!(info.blocks_repaired, 5, "{info:?}");
        assert!(info.blocks_corrupt >= 6, "{info:?}");
        assert_eq!(info.images_decoded, n, "{info:?}");
        same_as_stack(&cache, &ds);
        drop(cache);
        // Repaired: the next open is a hit.
        let (_, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(info.hit && info.blocks_corrupt == 0, "{info:?}");

        // One float in one block of one tile: only that block's 2 images are decoded.
        let mut b = fs::read(&file).unwrap();
        let g = TileGrid::new(w, h, 8);
        let at = HEADER_BYTES + g.first_pixel(7) * n * 12 + 2 * 64 * 12 + 20;
        b[at] ^= 1;
        fs::write(&file, &b).unwrap();
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert_eq!(
            (
                info.hit,
                info.blocks_corrupt,
                info.blocks_repaired,
                info.images_decoded
            ),
            (false, 1, 1, 2),
            "{info:?}"
        );
        same_as_stack(&cache, &ds);
    }

    /// An image replaced with the same size and modification time (`cp -p`) reused the stale
    /// cache; the content fingerprint notices it (`trust_mtime` does not, by design).
    #[test]
    fn same_size_and_mtime_but_new_content_rebuilds() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (6, 5, 4);
        // Uncompressed PFM images, so a changed sample keeps the file's size.
        let mut ds = dataset(d.path(), 1, 1, n);
        for (i, p) in ds.images.iter_mut().enumerate() {
            *p = d.path().join(format!("{i}.pfm"));
            let v: Vec<f32> = (0..w * h * 3).map(|k| (i * 100 + k) as f32).collect();
            crate::codecs::write_pfm(p, w, h, 3, &v).unwrap();
        }
        let dir = d.path().join("cache");
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        let copts = copts_batches_of_2(w, h);
        drop(TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap());
        let img = &ds.images[2];
        let (len, mtime) = {
            let m = fs::metadata(img).unwrap();
            (m.len(), m.modified().unwrap())
        };
        let mut rgb: Vec<f32> = (0..w * h * 3).map(|k| (200 + k) as f32).collect();
        rgb[7] += 1.0;
        crate::codecs::write_pfm(img, w, h, 3, &rgb).unwrap();
        File::options()
            .write(true)
            .open(img)
            .unwrap()
            .set_modified(mtime)
            .unwrap();
        let m = fs::metadata(img).unwrap();
        assert_eq!((m.len(), m.modified().unwrap()), (len, mtime));

        let trusting = CacheOptions {
            trust_mtime: true,
            ..copts
        };
        let (_, info) = TileCache::open_or_build(&ds, &opts, &dir, trusting, &go, &|| {}).unwrap();
        assert!(!info.hit, "another fingerprint kind: rebuilt once");
        let (_, info) = TileCache::open_or_build(&ds, &opts, &dir, trusting, &go, &|| {}).unwrap();
        assert!(info.hit, "trust_mtime: the documented blind spot");
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(!info.hit && info.images_decoded == n, "{info:?}");
        same_as_stack(&cache, &ds);
        drop(cache);
        // Rewritten with the same bytes and time: still a hit.
        crate::codecs::write_pfm(img, w, h, 3, &rgb).unwrap();
        File::options()
            .write(true)
            .open(img)
            .unwrap()
            .set_modified(mtime)
            .unwrap();
        let (_, info) = TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        assert!(info.hit, "{info:?}");
    }

    #[test]
    fn concurrent_openers_build_once() {
        let d = tempfile::tempdir().unwrap();
        let ds = dataset(d.path(), 9, 7, 12);
        let dir = d.path().join("cache");
        let opts = DecodeOptions::default();
        let copts = CacheOptions {
            tile: 4,
            batch_bytes: 3 * 9 * 7 * 12,
            ..CacheOptions::default()
        };
        let go = AtomicBool::new(false);
        let infos: Vec<CacheInfo> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..3)
                .map(|_| {
                    s.spawn(|| {
                        let (cache, info) =
                            TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
                        same_as_stack(&cache, &ds);
                        info
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(infos.iter().filter(|i| !i.hit).count(), 1, "{infos:?}");
        assert_eq!(infos.iter().map(|i| i.images_decoded).sum::<usize>(), 12);
    }

    #[test]
    fn size_mismatch_names_the_image() {
        let d = tempfile::tempdir().unwrap();
        let ds = dataset(d.path(), 4, 3, 5);
        write_exr_rgb(&ds.images[3], 3, 3, &[0.0; 27]).unwrap();
        let e = TileCache::open_or_build(
            &ds,
            &DecodeOptions::default(),
            &d.path().join("c"),
            CacheOptions::default(),
            &AtomicBool::new(false),
            &|| {},
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("3.exr: image is 3x3 but the first image"), "{e}");
    }
}
