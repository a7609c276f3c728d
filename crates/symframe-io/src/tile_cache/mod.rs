//! A pixel-major on-disk tile cache of a dataset's images, for stacks that do not fit in memory.
//!
//! Each image is decoded once and its samples are scattered into one cache file, laid out tile by
//! tile (tiles of `tile x tile` pixels, row-major over the tile grid, the right and bottom tiles
//! cropped; each tile one contiguous range of `pixels * lights * 12` bytes (6 for half floats and
//! 16-bit codes, 3 for 8-bit codes: [`CacheFormat`]), so
//! estimation maps one tile at a time). Inside a tile the lights come in blocks of `light_block`
//! lights (the decoding batch; the last block shorter), each block pixel-major: the tile's pixels
//! row-major, each pixel's RGB under the block's lights contiguous. When one batch holds every
//! image (see Memory below: by default, on 2 threads, 1,180 float EXR images of 256x256, 82 of
//! 1024x1024, and far more PNGs) there is one block and a tile is exactly a [`symframe::Stack`]
//! of its pixels.
//!
//! Why blocks: a batch then fills one contiguous range per tile, written with one positioned
//! write, so every page of the file is written once. With each pixel's samples under all lights
//! contiguous instead, a batch of 85 paper-size images writes 1 KB per pixel every 18 KB, and
//! each 4 KB page is rewritten by four batches. Blocked tiles written with positioned writes
//! also scatter faster than either layout written through a memory map (docs/performance.md,
//! "Tile cache layout"). Readers see no difference: [`TileView`] gathers a pixel's samples in
//! any light order.
//!
//! File: a 4,096-byte header (magic, format version, an endianness mark, width, height, lights,
//! tile size, the inputs' fingerprint, the number of images already scattered, a completion flag,
//! the light block, the sample format, and an XXH3-64 checksum of these fields), then the samples
//! in native byte order (`f32`, or the images' own `u8`/`u16` codes, so the tiled estimate equals
//! the in-memory one bit for bit; half floats with [`CacheFormat::F16`]), then a table of one
//! XXH3-64 checksum per block of each tile (block-major: block 0 of every tile, then block 1, ...;
//! little-endian `u64`; seeded with the block's scale exponent; for codes, of the block's bytes
//! followed by its lights' records), and for half floats a table of the blocks' power-of-two scale
//! exponents in the same order (little-endian `i32`), for codes a table of each light's record
//! of how its codes become samples (sample kind, first saturated code, intensity; 32 bytes). The fingerprint covers every image's path,
//! size and content (XXH3-64 of the file's bytes; modification time instead of content with
//! [`CacheOptions::trust_mtime`]), the light intensities, the decode options, the sample format and
//! the crate version: the cache is reused when they match and rebuilt when they do not.
//!
//! Integrity: a header whose checksum fails is not a cache (the whole file is rebuilt). A
//! complete cache is verified before every reuse, every block of every tile against the table
//! (one pass over the file at memory or disk speed, next to decoding every image); the lights of
//! the blocks that fail are decoded again and rewritten in place (one decoding batch per bad
//! block), and [`CacheInfo::blocks_repaired`] says how many. A file with other hard links is
//! never written in place: it is built anew as a new file (the other links keep the old one),
//! with a warning in [`CacheInfo::warnings`].
//!
//! Memory: a batch of images is read in lockstep, one band of tile rows at a time (each image its
//! band, in parallel: a PNG decoded row by row from its file's bytes; a PFM, EXR, TIFF or HDR read
//! from its file a row of its own blocks at a time; a JPEG decoded whole but kept in its 8-bit
//! samples), and each
//! band's tiles are written into the file with positioned writes from a small per-thread buffer
//! (the file is not mapped while it is built). A batch holds `batch_bytes` over what one image
//! costs (its reader, its band of `width x tile` decoded pixels, its share of the per-thread
//! buffers; at least one image), so the resident set is about `batch_bytes` whatever the stack's
//! size or the size the images declare; a tile size whose band alone exceeds it is refused
//! (beyond the default tile size). Readers map the
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

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use memmap2::Mmap;
use rayon::prelude::*;

use crate::codecs::DecodeOptions;
use crate::dataset::Dataset;
use crate::error::Warning;
use crate::error::{Error, Result};
use crate::stack::{check_dataset, check_mask_size, read_mask_any_size};

mod build;
mod codes;
mod grid;
mod header;
mod lock;
mod view;

use build::{build, repair};
use codes::CodeTables;
pub use grid::{TileGrid, TileRect};
#[cfg(any(test, feature = "fuzzing"))]
pub use header::check_cache_bytes;
use header::{cache_stem, matches, read_header, read_warnings, Header};
pub use header::{
    dataset_fingerprints, file_content_hash, inputs_fingerprint, resolve_format, Fingerprints,
    StampKind, CACHE_VERSION,
};
use lock::CacheLock;
use view::Samples;
pub use view::{TileGather, TileView};

/// How the cache stores samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CacheFormat {
    /// The smallest exact format for the images ([`resolve_format`]): `u8` for 8-bit images,
    /// `u16` for 8- and 16-bit ones, else `f32`.
    #[default]
    Auto,
    /// 32-bit floats, 12 bytes per pixel per light: the samples exactly as decoded, so a tiled
    /// estimate equals the in-memory one bit for bit.
    F32,
    /// Half floats, 6 bytes per pixel per light: half the disk and I/O. Each block of a tile
    /// (its pixels under one decoding batch of lights) is scaled by a power of two so that its
    /// largest finite magnitude lands in [32768, 65504] before rounding, so any HDR range
    /// survives; samples keep 11 significant bits (relative error at most 2^-11) down to
    /// 2^-29 of the block's largest, and lose precision gradually below (half-float
    /// subnormals) to 2^-39 of it, under which they read as 0. `NaN` (missing) stays `NaN`.
    F16,
    /// The 8-bit images' own codes, 3 bytes per pixel per light, made linear (transfer curve,
    /// saturation, intensity) when read: the same samples as `f32`, bit for bit.
    U8,
    /// The 8- or 16-bit images' own codes, 6 bytes per pixel per light, made linear when
    /// read: the same samples as `f32`, bit for bit.
    U16,
}

impl CacheFormat {
    /// Bytes of one pixel's RGB under one light (`Auto`: as `f32`, before it is resolved).
    pub fn pixel_bytes(self) -> usize {
        match self {
            CacheFormat::F32 | CacheFormat::Auto => 12,
            CacheFormat::F16 | CacheFormat::U16 => 6,
            CacheFormat::U8 => 3,
        }
    }

    /// The header's code for it (`Auto` is never stored).
    pub(super) fn code(self) -> u64 {
        match self {
            CacheFormat::F32 => 0,
            CacheFormat::F16 => 1,
            CacheFormat::U8 => 2,
            CacheFormat::U16 => 3,
            CacheFormat::Auto => 255,
        }
    }

    pub(super) fn from_code(c: u64) -> Option<Self> {
        match c {
            0 => Some(CacheFormat::F32),
            1 => Some(CacheFormat::F16),
            2 => Some(CacheFormat::U8),
            3 => Some(CacheFormat::U16),
            _ => None,
        }
    }

    /// Whether the cache stores the images' integer codes.
    pub(super) fn integer(self) -> bool {
        matches!(self, CacheFormat::U8 | CacheFormat::U16)
    }
}

/// How the cache is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CacheOptions {
    /// Tile side in pixels.
    pub tile: usize,
    /// Memory for decoding, in bytes: a batch of images is read in lockstep a band of tile rows
    /// at a time, as many as this holds, each costing its reader (a PNG's file and decoder, a
    /// PFM's band, a whole-decoded format's samples in its own type) and its band of decoded
    /// rows; at least one image per batch.
    pub batch_bytes: usize,
    /// Fingerprint the images by path, size and modification time only, not by content
    /// (skips reading every image on a rerun; an image changed with its size and time kept,
    /// as `cp -p`, `rsync -a` or `tar x` do, then goes unnoticed).
    pub trust_mtime: bool,
    /// How samples are stored (a cache of another format is rebuilt); [`CacheFormat::Auto`]
    /// picks the smallest exact one for the images.
    pub format: CacheFormat,
}

impl Default for CacheOptions {
    /// 32-pixel tiles, 1 GiB batches, the format picked for the images.
    fn default() -> Self {
        Self {
            tile: 32,
            batch_bytes: 1 << 30,
            trust_mtime: false,
            format: CacheFormat::Auto,
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
    /// How it stores samples (never `Auto`: the format picked).
    pub format: CacheFormat,
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
    header: Header,
    grid: TileGrid,
    n_lights: usize,
    light_block: usize,
    fingerprint: u64,
    path: PathBuf,
    /// How an integer cache's codes become samples (`None` for float caches).
    codes: Option<CodeTables>,
    /// Held (shared) while the cache is mapped, so no other process rebuilds it meanwhile.
    _lock: CacheLock,
}

/// The checksum of a block's bytes: XXH3-64 seeded with its scale exponent (0 but for half
/// floats, so plain XXH3-64 there), so that a damaged exponent fails the block too; for an
/// integer cache, of the bytes followed by the records of the block's lights (`lights`), so
/// that a damaged record fails its blocks.
pub(super) fn block_sum(bytes: &[u8], exponent: i32, lights: &[u8]) -> u64 {
    if lights.is_empty() {
        return xxhash_rust::xxh3::xxh3_64_with_seed(bytes, exponent as u32 as u64);
    }
    let mut h = xxhash_rust::xxh3::Xxh3::with_seed(exponent as u32 as u64);
    h.update(bytes);
    h.update(lights);
    h.digest()
}

/// The blocks of a complete cache whose checksum fails: `(tile, block)` pairs. Tile by tile
/// (a tile's blocks are contiguous in the file, its checksums `n_tiles` apart in the table);
/// `done(o, len)` is called with each tile's byte range once its blocks are summed. A tile at a
/// time, not a light block of every tile at a time: the system maps the pages around each one
/// read (fault-around), and released a block at a time in the table's order the pages of each
/// tile's next blocks stayed mapped until their turn, most of the cache at once
/// (docs/performance.md, "Memory model").
fn verify(map: &[u8], h: &Header, done: impl Fn(usize, usize) + Sync) -> Vec<(usize, usize)> {
    let grid = TileGrid::new(h.width, h.height, h.tile);
    let nb = h.n_blocks();
    let table = h.table_offset() as usize;
    (0..grid.n_tiles())
        .into_par_iter()
        .flat_map_iter(|t| {
            let bad: Vec<(usize, usize)> = (0..nb)
                .filter(|&b| {
                    let k = b * grid.n_tiles() + t;
                    let (o, len) = h.block_range(&grid, t, b);
                    let want = u64::from_le_bytes(
                        map[table + 8 * k..table + 8 * k + 8].try_into().unwrap(),
                    );
                    let sum = block_sum(
                        &map[o..o + len],
                        h.scale_exponent(map, k),
                        h.block_lights(map, b),
                    );
                    sum != want
                })
                .map(|b| (t, b))
                .collect();
            let (o, len) = h.tile_range(&grid, t);
            done(o, len);
            bad
        })
        .collect()
}

/// A complete cache of the wanted inputs, mapped and verified.
struct VerifiedCache {
    map: Mmap,
    header: Header,
    /// How an integer cache's codes become samples.
    codes: Option<CodeTables>,
    /// `(tile, block)` pairs whose checksum failed.
    bad: Vec<(usize, usize)>,
    verify_s: f64,
}

/// Maps the file at `path` read-only, checking it is `len` bytes long.
fn map_file(path: &Path, len: u64) -> Result<Mmap> {
    let (file, _) = crate::open_own_file(path)?
        .ok_or_else(|| Error::invalid(path, "cache vanished while opening"))?;
    // SAFETY: the cache is only written by this module under the exclusive lock, which no
    // one can take while we hold the shared one (see the module docs).
    let map = unsafe { Mmap::map(&file) }.map_err(|e| Error::read(path, e))?;
    if map.len() as u64 != len {
        return Err(Error::invalid(path, "cache changed size while opening"));
    }
    Ok(map)
}

/// How the codes of the cache `file` (its header `h`) become samples: `Some(None)` for a
/// float cache, `None` when an integer cache's light records are not valid.
fn code_tables(h: &Header, file: &[u8]) -> Option<Option<CodeTables>> {
    let codes = match h.format {
        CacheFormat::U8 => 256,
        CacheFormat::U16 => 65536,
        _ => return Some(None),
    };
    let records = h.light_records(file)?;
    Some(Some(CodeTables::new(&records, codes)))
}

/// The complete cache of these inputs at `path`, mapped and verified; `None` if there is none
/// (missing, incomplete, stale or with a bad header).
fn open_complete(
    path: &Path,
    fingerprint: u64,
    tile: usize,
    n: usize,
) -> Result<Option<VerifiedCache>> {
    let Some((header, len)) = read_header(path)? else {
        return Ok(None);
    };
    if !(header.complete && matches(&header, len, fingerprint, tile, n)) {
        return Ok(None);
    }
    let map = map_file(path, len)?;
    // Records that are not an integer cache's (a forged file: valid checksums) are no cache.
    let Some(codes) = code_tables(&header, &map) else {
        return Ok(None);
    };
    let t = Instant::now();
    // Each tile's pages are unmapped once its blocks are summed, so verifying does not hold the
    // whole cache resident, however large (docs/performance.md, "Memory model").
    let bad = verify(&map, &header, |o, len| {
        #[cfg(unix)]
        {
            // SAFETY: a read-only shared file mapping: MADV_DONTNEED only unmaps the pages;
            // later accesses read the same bytes back from the file (page cache).
            let _ =
                unsafe { map.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, o, len) };
        }
        #[cfg(not(unix))]
        let _ = (o, len);
    });
    Ok(Some(VerifiedCache {
        map,
        header,
        codes,
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
    ///
    /// The dataset's mask (`ds.mask`), if any, is read first and must have a pixel inside and
    /// the images' size: checked against the cache's header, or against the first image
    /// before any other is decoded and before the cache file is created.
    pub fn open_or_build(
        ds: &Dataset,
        opts: &DecodeOptions,
        dir: &Path,
        copts: CacheOptions,
        stop: &AtomicBool,
        on_image: &(dyn Fn() + Sync),
    ) -> Result<(TileCache, CacheInfo)> {
        Self::open_or_build_with(ds, opts, dir, copts, None, stop, on_image)
    }

    /// [`TileCache::open_or_build`] with the dataset's fingerprints already computed by
    /// [`dataset_fingerprints`] (with `copts.trust_mtime`), so a caller that checks them first
    /// does not read every image twice; `None` computes them.
    pub fn open_or_build_with(
        ds: &Dataset,
        opts: &DecodeOptions,
        dir: &Path,
        mut copts: CacheOptions,
        known: Option<Fingerprints>,
        stop: &AtomicBool,
        on_image: &(dyn Fn() + Sync),
    ) -> Result<(TileCache, CacheInfo)> {
        check_dataset(ds)?;
        if copts.tile == 0 {
            return Err(Error::invalid(dir, "tile size must be positive"));
        }
        // The mask is one image: a bad one fails here, not after decoding the stack. Its size
        // and the first image's are compared from their headers first, so a mask of another
        // size is never decoded (a small file may declare a huge image: docs/performance.md,
        // "Memory model").
        let mask = match &ds.mask {
            Some(p) => {
                let header = |q: &Path, o: &DecodeOptions| crate::stack::read_image_size(q, o);
                if let (Ok(m), Ok(i)) = (
                    header(p, &DecodeOptions::default()),
                    header(&ds.images[0], opts),
                ) {
                    check_mask_size(p, m, i)?;
                }
                let (w, h, _) = read_mask_any_size(p)?;
                Some((p.as_path(), (w, h)))
            }
            None => None,
        };
        let fps = match known {
            Some(f) => f,
            None => dataset_fingerprints(ds, opts, copts.trust_mtime, copts.format)?,
        };
        let (fingerprint, fingerprint_s) = (fps.cache, fps.seconds);
        if copts.format == CacheFormat::Auto {
            copts.format = fps.format;
        }
        let fits_mask = |w: usize, h: usize| match mask {
            Some((p, size)) => check_mask_size(p, size, (w, h)),
            None => Ok(()),
        };
        fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
        let stem = cache_stem(ds);
        let path = dir.join(format!("{stem}.stack"));
        let partial = dir.join(format!("{stem}.stack.partial"));
        let lock = CacheLock::open(&dir.join(format!("{stem}.lock")))?;
        // A cache of another format version is never read: said once it is rebuilt.
        let other_version = header::other_version(&path).map(|v| Warning {
            path: path.clone(),
            message: format!(
                "a tile cache of format version {v} (written by another version of symframe): \
                 not read, rebuilt in format version {CACHE_VERSION}"
            ),
        });
        let n = ds.images.len();
        let mut info = CacheInfo {
            path: path.clone(),
            bytes: 0,
            format: copts.format,
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
            // Waiting here while another process builds: Ctrl-C (`stop`) ends the wait.
            if !lock.shared_unless_stopped(stop)? {
                return Err(Error::Interrupted);
            }
            if let Some(found) = open_complete(&path, fingerprint, copts.tile, n)? {
                fits_mask(found.header.width, found.header.height)?;
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
        let mut rebuilt = None;
        let mut build_anew = true;
        if let Some(found) = open_complete(&path, fingerprint, copts.tile, n)? {
            fits_mask(found.header.width, found.header.height)?;
            info.verify_s += found.verify_s;
            if found.bad.is_empty() {
                lock.set(false)?;
                info.hit = true;
                info.warnings = read_warnings(&found.map);
                return Ok(Self::from_found(found, path, lock, fingerprint, info));
            }
            let VerifiedCache {
                map, header, bad, ..
            } = found;
            info.warnings = read_warnings(&map);
            drop(map);
            let links = build::other_links(&path)?;
            if links == 0 {
                repair(ds, opts, &path, &header, &bad, stop, on_image, &mut info)?;
                build_anew = false;
            } else {
                // Repairing in place would change the file under its other names too (a backup
                // made by `cp -al`): a new file is built instead, the other links keep the old.
                info.blocks_corrupt += bad.len();
                rebuilt = Some(Warning {
                    path: path.clone(),
                    message: format!(
                        "{} corrupt blocks, and {links} other hard links to the file: rebuilt \
                         as a new file rather than repaired in place (the other links keep \
                         the old content)",
                        bad.len()
                    ),
                });
            }
        }
        if build_anew {
            // Unlinked, not truncated: other hard links keep their content.
            if path.symlink_metadata().is_ok() {
                fs::remove_file(&path).map_err(|e| Error::write(&path, e))?;
            }
            let built = build(
                ds,
                opts,
                &partial,
                fingerprint,
                copts,
                &fits_mask,
                stop,
                on_image,
            )?;
            fs::rename(&partial, &path).map_err(|e| Error::write(&path, e))?;
            info.images_decoded = built.decoded;
            info.images_resumed = built.resumed;
            info.batch_images = built.batch;
            info.decode_s = built.decode_s;
            info.scatter_s = built.scatter_s;
            info.warnings = built.warnings;
            info.warnings.extend(rebuilt);
            info.warnings.extend(other_version);
            // What an earlier, interrupted build wrote is verified like a reused cache.
            if built.resumed > 0 {
                if let Some(found) = open_complete(&path, fingerprint, copts.tile, n)? {
                    info.verify_s += found.verify_s;
                    let VerifiedCache {
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
        let map = map_file(&path, len)?;
        let codes = code_tables(&header, &map)
            .ok_or_else(|| Error::invalid(&path, "cache's light records are not valid"))?;
        let found = VerifiedCache {
            map,
            header,
            codes,
            bad: Vec::new(),
            verify_s: 0.0,
        };
        Ok(Self::from_found(found, path, lock, fingerprint, info))
    }

    fn from_found(
        found: VerifiedCache,
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
                header: h,
                grid: TileGrid::new(h.width, h.height, h.tile),
                n_lights: h.n_lights,
                light_block: h.light_block,
                fingerprint,
                path,
                codes: found.codes,
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

    /// How the cache stores samples.
    pub fn format(&self) -> CacheFormat {
        self.header.format
    }

    /// Byte range of tile `t` in the file.
    fn range(&self, t: usize) -> (usize, usize) {
        self.header.tile_range(&self.grid, t)
    }

    /// Lights per block inside a tile (all of them when the cache was built in one batch).
    pub fn light_block(&self) -> usize {
        self.light_block
    }

    /// Tile `t`'s samples, read in place; for a half-float cache `scratch` holds the factors
    /// that undo each light block's scale (converted to floats pixel by pixel when read); an
    /// integer cache's codes are made linear pixel by pixel when read.
    pub fn tile<'a>(&'a self, t: usize, scratch: &'a mut Vec<f32>) -> TileView<'a> {
        let (o, len) = self.range(t);
        let bytes = &self.map[o..o + len];
        // (Codes are there exactly for integer caches: [`code_tables`].)
        let data = match (&self.codes, self.header.format) {
            (Some(codes), CacheFormat::U16) => Samples::U16(bytemuck::cast_slice(bytes), codes),
            (Some(codes), _) => Samples::U8(bytes, codes),
            (None, CacheFormat::F16) => {
                scratch.clear();
                scratch.extend((0..self.header.n_blocks()).map(|b| {
                    pow2(
                        -self
                            .header
                            .scale_exponent(&self.map, b * self.grid.n_tiles() + t),
                    )
                }));
                Samples::F16(bytemuck::cast_slice(bytes), scratch)
            }
            (None, _) => Samples::F32(bytemuck::cast_slice(bytes)),
        };
        TileView {
            data,
            n_pixels: self.grid.tile_pixels(t),
            n_lights: self.n_lights,
            light_block: self.light_block,
        }
    }

    /// Asks the system to start reading tile `t` from disk (`madvise(MADV_WILLNEED)`) so that
    /// it is in memory by the time it is read: a reader that calls this for its next tile
    /// overlaps that tile's disk reads with its work on the current one. Only a hint: nothing
    /// is read where the pages are resident already, and errors are ignored.
    pub fn prefetch(&self, t: usize) {
        #[cfg(unix)]
        {
            let (o, len) = self.range(t);
            let _ = self.map.advise_range(memmap2::Advice::WillNeed, o, len);
        }
        #[cfg(not(unix))]
        let _ = t;
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

/// `2^e` for `e` in [-126, 127] (exact).
pub(super) fn pow2(e: i32) -> f32 {
    f32::from_bits(((127 + e.clamp(-126, 127)) as u32) << 23)
}

/// Whether the cache folder `dir` holds work worth keeping after a failed run: a complete
/// cache, or a partial build that holds at least one batch of images (a rerun resumes it).
pub fn cache_holds_work(dir: &Path) -> bool {
    let Ok(rd) = fs::read_dir(dir) else {
        return false;
    };
    rd.flatten().any(|e| {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.ends_with(".stack") {
            return true;
        }
        name.ends_with(".stack.partial")
            && read_header(&e.path()).is_ok_and(|h| h.is_some_and(|(h, _)| h.images_done > 0))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codecs::{write_exr_rgb, Gamma};
    use crate::stack::load_stack;
    use glam::DVec3;
    use header::HEADER_BYTES;

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
        dataset_scaled(dir, w, h, n, 1.0)
    }

    /// Images of samples `(i * 1000 + k) * scale`, some `NaN`.
    fn dataset_scaled(dir: &Path, w: usize, h: usize, n: usize, scale: f32) -> Dataset {
        let images: Vec<PathBuf> = (0..n)
            .map(|i| {
                let p = dir.join(format!("{i}.exr"));
                let rgb: Vec<f32> = (0..w * h * 3)
                    .map(|k| {
                        if (i + k) % 17 == 0 {
                            f32::NAN
                        } else {
                            (i * 1000 + k) as f32 * scale
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
            warnings: Vec::new(),
        }
    }

    /// Checks every tile against the in-memory stack, bit for bit (each read after a prefetch).
    fn same_as_stack(cache: &TileCache, ds: &Dataset) {
        same_as_stack_with(cache, ds, &DecodeOptions::default())
    }

    /// [`same_as_stack`] with the stack decoded with `opts`.
    fn same_as_stack_with(cache: &TileCache, ds: &Dataset, opts: &DecodeOptions) {
        let stack = load_stack(ds, opts, &|| {}).unwrap();
        let g = cache.grid();
        assert_eq!(
            (g.width, g.height, cache.n_lights()),
            (stack.width, stack.height, stack.n_lights)
        );
        let mut a = vec![0.0f32; stack.n_lights * 3];
        let mut c = vec![0.0f32; stack.n_lights * 3];
        let reversed: Vec<usize> = (0..stack.n_lights).rev().collect();
        for t in 0..g.n_tiles() {
            // As the tile driver does: a hint for the next tile (past the last: none).
            if t + 1 < g.n_tiles() {
                cache.prefetch(t + 1);
            }
            let mut scratch = Vec::new();
            let tile = cache.tile(t, &mut scratch);
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
        let copts = copts_batches_of_2(&ds);
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

    /// Verifying a reused cache releases its pages tile by tile: one range per tile, together
    /// the whole of the samples with no gap or overlap (a block at a time in the file's
    /// light-block order left the pages mapped around each block resident: docs/performance.md,
    /// "Memory model").
    #[test]
    fn verifying_releases_each_tile_s_whole_range_once() {
        let d = tempfile::tempdir().unwrap();
        let ds = dataset(d.path(), 11, 6, 9);
        let dir = d.path().join("cache");
        let go = AtomicBool::new(false);
        let copts = copts_batches_of_2(&ds);
        let (cache, _) =
            TileCache::open_or_build(&ds, &DecodeOptions::default(), &dir, copts, &go, &|| {})
                .unwrap();
        assert!(
            cache.light_block() < cache.n_lights(),
            "several light blocks a tile"
        );
        drop(cache);
        let path = stack_file(&dir);
        let (header, _) = read_header(&path).unwrap().unwrap();
        let bytes = fs::read(&path).unwrap();
        let released = std::sync::Mutex::new(Vec::new());
        let bad = verify(&bytes, &header, |o, len| {
            released.lock().unwrap().push((o, len))
        });
        assert!(bad.is_empty());
        let mut released = released.into_inner().unwrap();
        released.sort();
        let grid = TileGrid::new(header.width, header.height, header.tile);
        assert_eq!(released.len(), grid.n_tiles());
        let mut end = HEADER_BYTES;
        for (o, len) in released {
            assert_eq!(o, end, "contiguous, one range a tile");
            end = o + len;
        }
        assert_eq!(end as u64, header.table_offset());
    }

    /// The cache file of `dir` (the one `.stack`).
    fn stack_file(dir: &Path) -> PathBuf {
        fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "stack"))
            .unwrap()
    }

    /// Tiles of `tile` pixels, the decoding memory of `k` of `ds`'s images a batch.
    fn batches_of(k: usize, ds: &Dataset, format: CacheFormat, tile: usize) -> CacheOptions {
        let mut copts = CacheOptions {
            tile,
            format,
            ..CacheOptions::default()
        };
        let first = crate::stack::open_stack_image(ds, 0, &DecodeOptions::default(), None).unwrap();
        copts.batch_bytes = k * build::image_cost(&first, &copts) + 5;
        copts
    }

    fn copts_batches_of_2(ds: &Dataset) -> CacheOptions {
        batches_of(2, ds, CacheFormat::F32, 4)
    }

    /// A changed light-block field in the header is not trusted (its samples would be wrong,
    /// with `hit: true`): the cache is rebuilt.
    #[test]
    fn a_changed_header_field_rebuilds_the_cache() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (11, 6, 9);
        let ds = dataset(d.path(), w, h, n);
        let dir = d.path().join("cache");
        let (opts, copts, go) = (
            DecodeOptions::default(),
            copts_batches_of_2(&ds),
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

    /// 3,000 changed floats of pixel data fail their blocks' checksums: those blocks are decoded
    /// again and rewritten, the rest kept.
    #[test]
    fn changed_pixel_data_is_repaired() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (40, 30, 9);
        let ds = dataset(d.path(), w, h, n);
        let dir = d.path().join("cache");
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        let copts = batches_of(2, &ds, CacheFormat::F32, 8);
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

    /// An image replaced with the same size and modification time (`cp -p`) does not reuse the
    /// stale cache: the content fingerprint notices it (`trust_mtime` does not, by design).
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
        let copts = copts_batches_of_2(&ds);
        drop(TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap());
        let img = &ds.images[2];
        let (len, mtime) = {
            let m = fs::metadata(img).unwrap();
            (m.len(), m.modified().unwrap())
        };
        let mut rgb: Vec<f32> = (0..w * h * 3).map(|k| (200 + k) as f32).collect();
        rgb[7] += 1.0;
        crate::codecs::write_pfm(img, w, h, 3, &rgb).unwrap();
        fs::File::options()
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
        fs::File::options()
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
        let copts = batches_of(3, &ds, CacheFormat::F32, 4);
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

    /// The inputs fingerprint names the capture, not where it lies: a copy elsewhere has the
    /// same (the cache fingerprint, keyed on paths, differs); a changed image or light does not.
    #[test]
    fn inputs_fingerprint_follows_content_not_paths() {
        let d = tempfile::tempdir().unwrap();
        fs::create_dir_all(d.path().join("a")).unwrap();
        let a = dataset(&d.path().join("a"), 3, 2, 4);
        let copy_dir = d.path().join("copy");
        fs::create_dir_all(&copy_dir).unwrap();
        let mut copy = a.clone();
        for p in &mut copy.images {
            let q = copy_dir.join(p.file_name().unwrap());
            fs::copy(&*p, &q).unwrap();
            *p = q;
        }
        let fp = |ds: &Dataset, mtime: bool| {
            dataset_fingerprints(ds, &DecodeOptions::default(), mtime, CacheFormat::default())
                .unwrap()
        };
        let (fa, fc) = (fp(&a, false), fp(&copy, false));
        assert_eq!(fa.inputs, fc.inputs);
        assert_ne!(fa.cache, fc.cache);
        assert_eq!(fa.kind, StampKind::Content);
        assert_eq!(fp(&a, true).kind, StampKind::SizeAndMtime);
        assert_ne!(fp(&a, true).inputs, fa.inputs);
        let mut moved = copy.clone();
        moved.lights[1] = DVec3::X;
        assert_ne!(fp(&moved, false).inputs, fa.inputs);
        write_exr_rgb(&copy.images[2], 3, 2, &[0.5; 18]).unwrap();
        assert_ne!(fp(&copy, false).inputs, fa.inputs);
    }

    /// The dataset's mask is checked before the stack is decoded: a wrong size leaves no
    /// cache file behind.
    #[test]
    fn a_wrong_size_mask_fails_before_the_cache_file_is_created() {
        let d = tempfile::tempdir().unwrap();
        let mut ds = dataset(d.path(), 4, 3, 5);
        let mask = d.path().join("mask.png");
        crate::codecs::write_png8_rgb(&mask, 3, 4, &[1.0; 36], false).unwrap();
        ds.mask = Some(mask);
        let dir = d.path().join("cache");
        let stop = AtomicBool::new(false);
        let e = TileCache::open_or_build(
            &ds,
            &DecodeOptions::default(),
            &dir,
            Default::default(),
            &stop,
            &|| {},
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("mask.png: mask is 3x4 but the images are 4x3"),
            "{e}"
        );
        // (Refused from the headers, before the cache's folder is made.)
        let files: Vec<_> = fs::read_dir(&dir)
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".stack"))
            .collect();
        assert!(files.is_empty(), "{files:?}");
    }

    /// Every sample of a half-float cache against the in-memory stack: `NaN` where it is
    /// `NaN`, else within half a unit in the 11th significant bit.
    fn close_to_stack(cache: &TileCache, ds: &Dataset) {
        let stack = load_stack(ds, &DecodeOptions::default(), &|| {}).unwrap();
        let g = cache.grid();
        let mut a = vec![0.0f32; stack.n_lights * 3];
        let mut scratch = Vec::new();
        let all: Vec<usize> = (0..stack.n_lights).collect();
        let reversed: Vec<usize> = all.iter().rev().copied().collect();
        let mut c = vec![0.0f32; stack.n_lights * 3];
        for t in 0..g.n_tiles() {
            let tile = cache.tile(t, &mut scratch);
            for (k, p) in g.pixels(t).enumerate() {
                tile.pixel(k, &mut a);
                // In order (converted run by run) and reversed (light by light): the same.
                tile.gatherer(&all).pixel(k, &mut c);
                assert!(a.iter().zip(&c).all(|(x, y)| x.to_bits() == y.to_bits()));
                tile.gatherer(&reversed).pixel(k, &mut c);
                for (i, rgb) in c.chunks_exact(3).enumerate() {
                    let j = stack.n_lights - 1 - i;
                    assert!(rgb
                        .iter()
                        .zip(&a[j * 3..j * 3 + 3])
                        .all(|(x, y)| x.to_bits() == y.to_bits()));
                }
                for (x, y) in a.iter().zip(stack.pixel(p)) {
                    assert_eq!(x.is_nan(), y.is_nan(), "tile {t} px {p}");
                    assert!(
                        y.is_nan() || (x - y).abs() <= y.abs() / 2048.0,
                        "{x} vs {y}"
                    );
                }
            }
        }
    }

    fn f16_options(ds: &Dataset) -> CacheOptions {
        batches_of(2, ds, CacheFormat::F16, 4)
    }

    #[test]
    fn half_float_cache_records_its_format_and_a_change_rebuilds() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (11, 6, 9);
        let ds = dataset(d.path(), w, h, n);
        let dir = d.path().join("cache");
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        let f32s = copts_batches_of_2(&ds);
        let f16s = f16_options(&ds);
        drop(TileCache::open_or_build(&ds, &opts, &dir, f32s, &go, &|| {}).unwrap());
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, f16s, &go, &|| {}).unwrap();
        assert!(!info.hit && info.images_decoded == n, "{info:?}");
        assert_eq!(
            (info.format, cache.format()),
            (CacheFormat::F16, CacheFormat::F16)
        );
        // Header, 6 bytes per pixel per light, a checksum and a scale per block of each tile.
        assert_eq!(
            info.bytes,
            (HEADER_BYTES + w * h * n * 6 + 5 * 6 * 8 + 5 * 6 * 4) as u64
        );
        let b = fs::read(stack_file(&dir)).unwrap();
        assert_eq!(b[16 + 8 * 8], 1, "format field");
        close_to_stack(&cache, &ds);
        drop(cache);
        let (_, info) = TileCache::open_or_build(&ds, &opts, &dir, f16s, &go, &|| {}).unwrap();
        assert!(info.hit, "{info:?}");
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, f32s, &go, &|| {}).unwrap();
        assert!(!info.hit && info.format == CacheFormat::F32, "{info:?}");
        same_as_stack(&cache, &ds);
        drop(cache);
        // A header whose format field alone was changed (checksum redone) is not trusted:
        // the fingerprint differs, so the cache is rebuilt.
        let file = stack_file(&dir);
        let mut b = fs::read(&file).unwrap();
        b[16 + 8 * 8] = 1;
        let sum = xxhash_rust::xxh3::xxh3_64(&b[..header::SUMMED]);
        b[header::SUMMED..header::FIELDS].copy_from_slice(&sum.to_le_bytes());
        fs::write(&file, &b).unwrap();
        let (cache, info) = TileCache::open_or_build(&ds, &opts, &dir, f32s, &go, &|| {}).unwrap();
        assert!(!info.hit, "{info:?}");
        same_as_stack(&cache, &ds);
    }

    /// Samples far above half floats' largest value (65504) keep their range, and a power of
    /// two scales the cache exactly.
    #[test]
    fn half_float_cache_keeps_the_hdr_range() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (11, 6, 9);
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        for sub in ["a", "b"] {
            fs::create_dir(d.path().join(sub)).unwrap();
        }
        let small = dataset(&d.path().join("a"), w, h, n);
        let big = dataset_scaled(&d.path().join("b"), w, h, n, 1048576.0);
        let f16s = f16_options(&small);
        let (c1, _) =
            TileCache::open_or_build(&small, &opts, &d.path().join("c1"), f16s, &go, &|| {})
                .unwrap();
        let (c2, _) =
            TileCache::open_or_build(&big, &opts, &d.path().join("c2"), f16s, &go, &|| {}).unwrap();
        close_to_stack(&c2, &big);
        let (mut s1, mut s2) = (Vec::new(), Vec::new());
        for t in 0..c1.grid().n_tiles() {
            let (a, b) = (c1.tile(t, &mut s1), c2.tile(t, &mut s2));
            let mut x = vec![0.0f32; n * 3];
            let mut y = vec![0.0f32; n * 3];
            for k in 0..a.n_pixels() {
                a.pixel(k, &mut x);
                b.pixel(k, &mut y);
                for (u, v) in x.iter().zip(&y) {
                    assert!((u * 1048576.0).to_bits() == v.to_bits() || u.is_nan() && v.is_nan());
                }
            }
        }
    }

    #[test]
    fn corrupt_half_float_block_or_scale_is_detected_and_repaired() {
        let d = tempfile::tempdir().unwrap();
        let (w, h, n) = (40, 30, 9);
        let ds = dataset(d.path(), w, h, n);
        let dir = d.path().join("cache");
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        let copts = batches_of(2, &ds, CacheFormat::F16, 8);
        drop(TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap());
        let file = stack_file(&dir);
        let clean = fs::read(&file).unwrap();
        let g = TileGrid::new(w, h, 8);
        // One byte of light block 1 of tile 7; then one byte of the scale of block 0 of tile 3.
        let data_at = HEADER_BYTES + g.first_pixel(7) * n * 6 + 2 * 64 * 6 + 20;
        let (hd, _) = read_header(&file).unwrap().unwrap();
        let scale_at = hd.scales_offset() as usize + 4 * 3;
        for at in [data_at, scale_at] {
            let mut b = clean.clone();
            b[at] ^= 1;
            fs::write(&file, &b).unwrap();
            let (cache, info) =
                TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
            assert_eq!(
                (
                    info.hit,
                    info.blocks_corrupt,
                    info.blocks_repaired,
                    info.images_decoded
                ),
                (false, 1, 1, 2),
                "byte {at}: {info:?}"
            );
            close_to_stack(&cache, &ds);
            drop(cache);
            assert_eq!(
                fs::read(&file).unwrap(),
                clean,
                "repaired in place, byte {at}"
            );
        }
    }

    /// A tile size as large as the image would make one band the whole decoded image, whatever
    /// the decoding memory: a band larger than it is refused beyond the default tile size.
    #[test]
    fn a_tile_band_larger_than_the_decoding_memory_is_refused() {
        let d = tempfile::tempdir().unwrap();
        let ds = dataset(d.path(), 100, 70, 3);
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        let copts = |tile, batch_bytes| CacheOptions {
            tile,
            batch_bytes,
            ..CacheOptions::default()
        };
        // 64 rows of 100 pixels: 75 KiB a band.
        let e = TileCache::open_or_build(
            &ds,
            &opts,
            &d.path().join("a"),
            copts(64, 50_000),
            &go,
            &|| {},
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains(
                "0.exr: tiles of 64 pixels are decoded a row of tiles at a time, 64 rows of \
                 this 100-pixel-wide image: 75 KiB, more than the 48.8 KiB of decoding memory; use \
                 a smaller --tile-size or a larger --decode-memory"
            ),
            "{e}"
        );
        assert!(!d.path().join("a").read_dir().unwrap().any(|e| e
            .unwrap()
            .path()
            .to_string_lossy()
            .contains(".stack")));
        let (cache, info) = TileCache::open_or_build(
            &ds,
            &opts,
            &d.path().join("b"),
            copts(64, 80_000),
            &go,
            &|| {},
        )
        .unwrap();
        assert_eq!(info.batch_images, 1);
        same_as_stack(&cache, &ds);
        // The default tile size is always accepted: batches of one image.
        let (cache, info) = TileCache::open_or_build(
            &ds,
            &opts,
            &d.path().join("c"),
            copts(32, 1000),
            &go,
            &|| {},
        )
        .unwrap();
        assert_eq!(info.batch_images, 1);
        same_as_stack(&cache, &ds);
    }

    /// The fixture of every kind of image (see `stack::fixture`) cut to the images whose
    /// names `keep` accepts.
    fn every_kind_but(dir: &Path, keep: impl Fn(&str) -> bool) -> Dataset {
        let mut ds = crate::stack::fixture::every_kind(dir);
        let kept: Vec<usize> = (0..ds.images.len())
            .filter(|&i| keep(ds.images[i].file_name().unwrap().to_str().unwrap()))
            .collect();
        ds.images = kept.iter().map(|&i| ds.images[i].clone()).collect();
        ds.lights = kept.iter().map(|&i| ds.lights[i]).collect();
        ds.intensities = ds.intensities.map(|v| kept.iter().map(|&i| v[i]).collect());
        ds
    }

    fn eight_bit(name: &str) -> bool {
        !(name.contains("16") || name.ends_with(".pfm") || name.ends_with(".exr"))
    }

    fn integer(name: &str) -> bool {
        !(name.ends_with(".pfm") || name.ends_with(".exr"))
    }

    /// 8-bit images (PNG of every layout, JPEG) in a `u8` cache, and 8- and 16-bit ones (PNG,
    /// TIFF) in a `u16` one, picked automatically: 3 and 6 bytes per pixel per light, and the
    /// samples read are the float path's bit for bit under every transfer curve, saturated
    /// pixels and intensities included.
    #[test]
    fn integer_caches_read_the_float_samples_bit_for_bit() {
        let d = tempfile::tempdir().unwrap();
        for (sub, keep, want) in [
            ("a", eight_bit as fn(&str) -> bool, CacheFormat::U8),
            ("b", integer, CacheFormat::U16),
        ] {
            let sub = d.path().join(sub);
            fs::create_dir(&sub).unwrap();
            let ds = every_kind_but(&sub, keep);
            let n = ds.images.len();
            assert!(n >= 10, "{n}");
            assert_eq!(resolve_format(&ds, CacheFormat::Auto), want);
            for gamma in [Gamma::Auto, Gamma::Srgb, Gamma::Linear] {
                let opts = DecodeOptions {
                    gamma,
                    saturation: 0.9,
                    ..Default::default()
                };
                let dir = sub.join(format!("cache-{gamma:?}"));
                let copts = batches_of(3, &ds, CacheFormat::Auto, 8);
                let go = AtomicBool::new(false);
                let (cache, info) =
                    TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
                assert_eq!((info.format, cache.format()), (want, want));
                let (w, h) = (cache.grid().width, cache.grid().height);
                let (tiles, blocks) = (cache.grid().n_tiles(), n.div_ceil(3));
                assert_eq!(
                    info.bytes as usize,
                    HEADER_BYTES + w * h * n * want.pixel_bytes() + tiles * blocks * 8 + n * 32,
                    "{want:?}"
                );
                assert_eq!(
                    want.pixel_bytes(),
                    [3, 6][(want == CacheFormat::U16) as usize]
                );
                same_as_stack_with(&cache, &ds, &opts);
                drop(cache);
                let (cache, info) =
                    TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
                assert!(info.hit, "{info:?}");
                same_as_stack_with(&cache, &ds, &opts);
            }
        }
        // Float images: f32.
        let all = crate::stack::fixture::every_kind(&d.path().join("a"));
        assert_eq!(resolve_format(&all, CacheFormat::Auto), CacheFormat::F32);
        assert_eq!(resolve_format(&all, CacheFormat::U8), CacheFormat::U8);
    }

    /// A format forced on images it cannot hold is refused, naming the image.
    #[test]
    fn an_integer_cache_refuses_images_it_cannot_hold() {
        let d = tempfile::tempdir().unwrap();
        let ds = crate::stack::fixture::every_kind(d.path());
        let go = AtomicBool::new(false);
        for (format, name, what) in [
            (
                CacheFormat::U8,
                "rgb16.png",
                "16-bit (linear) samples do not fit a u8 tile cache",
            ),
            (
                CacheFormat::U16,
                "rgb.pfm",
                "float (linear) samples do not fit a u16 tile cache",
            ),
        ] {
            let copts = CacheOptions {
                format,
                ..CacheOptions::default()
            };
            let dir = d.path().join(format!("{format:?}"));
            let e =
                TileCache::open_or_build(&ds, &DecodeOptions::default(), &dir, copts, &go, &|| {})
                    .unwrap_err()
                    .to_string();
            assert!(
                e.contains(&format!("{name}: {what}; use --cache-format f32")),
                "{e}"
            );
        }
    }

    /// A damaged light record is detected like damaged samples (its blocks repaired, or the
    /// cache rebuilt when the record is not one at all); a truncated cache or one of the
    /// former format version is rebuilt (the latter said in a warning); no byte flipped
    /// anywhere makes the cache reader panic.
    #[test]
    fn damaged_truncated_or_old_integer_caches_are_repaired_or_rebuilt() {
        let d = tempfile::tempdir().unwrap();
        let ds = every_kind_but(d.path(), eight_bit);
        let n = ds.images.len();
        let dir = d.path().join("cache");
        let (opts, go) = (DecodeOptions::default(), AtomicBool::new(false));
        let copts = batches_of(3, &ds, CacheFormat::U8, 8);
        drop(TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap());
        let file = stack_file(&dir);
        let clean = fs::read(&file).unwrap();
        let (hd, _) = read_header(&file).unwrap().unwrap();
        let records = hd.lights_offset() as usize;
        assert_eq!(clean.len(), records + n * 32);
        let reopen = || TileCache::open_or_build(&ds, &opts, &dir, copts, &go, &|| {}).unwrap();
        // Light 4's intensity (block 1): that block is decoded again.
        let mut b = clean.clone();
        b[records + 4 * 32 + 13] ^= 1;
        fs::write(&file, &b).unwrap();
        let (cache, info) = reopen();
        assert_eq!(
            (info.hit, info.blocks_repaired, info.images_decoded),
            (false, 1, 3),
            "{info:?}"
        );
        same_as_stack(&cache, &ds);
        drop(cache);
        assert_eq!(fs::read(&file).unwrap(), clean, "repaired in place");
        // Light 2's kind not a kind: no cache; rebuilt.
        let mut b = clean.clone();
        b[records + 2 * 32] = 9;
        fs::write(&file, &b).unwrap();
        let (cache, info) = reopen();
        assert!(!info.hit && info.images_decoded == n, "{info:?}");
        same_as_stack(&cache, &ds);
        drop(cache);
        // Truncated: rebuilt.
        fs::write(&file, &clean[..clean.len() - 1]).unwrap();
        let (cache, info) = reopen();
        assert!(!info.hit && info.images_decoded == n, "{info:?}");
        same_as_stack(&cache, &ds);
        drop(cache);
        // Written by the former format version: rebuilt, with a warning.
        let mut b = clean.clone();
        b[8..12].copy_from_slice(&3u32.to_le_bytes());
        fs::write(&file, &b).unwrap();
        let (cache, info) = reopen();
        assert!(!info.hit && info.images_decoded == n, "{info:?}");
        let said = info
            .warnings
            .iter()
            .map(|w| w.to_string())
            .collect::<Vec<_>>();
        assert!(
            said.iter().any(|w| w.ends_with(
                "a tile cache of format version 3 (written by another version of symframe): \
                 not read, rebuilt in format version 4"
            )),
            "{said:?}"
        );
        same_as_stack(&cache, &ds);
        drop(cache);
        // Every byte of the header's fields and of the tables flipped, and truncations: the
        // reader's checks give an answer, never a panic.
        assert_eq!(header::check_cache_bytes(&clean), Some(0));
        let table = hd.table_offset() as usize;
        let spots = (0..header::FIELDS).chain(table..clean.len());
        for at in spots {
            let mut b = clean.clone();
            b[at] ^= 0x81;
            let _ = header::check_cache_bytes(&b);
        }
        for len in [
            0,
            12,
            header::FIELDS,
            HEADER_BYTES,
            records,
            clean.len() - 1,
        ] {
            assert_eq!(header::check_cache_bytes(&clean[..len]), None, "{len}");
        }
    }
}
