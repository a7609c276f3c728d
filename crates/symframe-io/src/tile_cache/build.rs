//! Building the cache: reading a batch of images in lockstep, a band of tile rows at a time,
//! and scattering each band's tiles into the file with positioned writes; repairing the blocks
//! that fail their checksum.

use std::fs::{self, File, OpenOptions};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use super::codes::{LightCodes, LIGHT_RECORD_BYTES};
use super::header::{encode_warnings, matches, read_header, Header, HEADER_BYTES, WARNINGS_AT};
use super::{block_sum, pow2, CacheFormat, CacheInfo, CacheOptions, TileGrid};
use crate::codecs::DecodeOptions;
use crate::codecs::SampleKind;
use crate::dataset::Dataset;
use crate::error::{Error, Result, Warning};
use crate::stack::{open_stack_image, Notes, StackImage};

/// What a build did.
pub(super) struct Built {
    /// About the images decoded by this build.
    pub(super) warnings: Vec<Warning>,
    pub(super) decoded: usize,
    pub(super) resumed: usize,
    pub(super) batch: usize,
    pub(super) decode_s: f64,
    pub(super) scatter_s: f64,
}

/// Creates `path` of `len` bytes, reserving the disk space up front where the file system can
/// (so a full disk is an error here, not a fault while writing through the mapping).
pub(super) fn create_sized(path: &Path, len: u64) -> Result<File> {
    let file = crate::atomic::open_no_follow(
        OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true),
        path,
    )
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

/// What one image of a decoding batch holds in memory while the cache is built: its reader
/// (a PNG's file and decoder, a PFM's band of stored bytes, a row of an EXR's or TIFF's blocks,
/// an HDR scan line, or a JPEG's samples decoded whole, in the file's type), its band of decoded
/// rows (`width x tile` RGB `f32`, or `u16` codes for an integer cache), and its
/// share of the per-thread buffers that assemble a tile's block. `--decode-memory` divided by
/// it is the batch, so a small file declaring a large image costs its band, not its image.
pub(super) fn image_cost(img: &StackImage, copts: &CacheOptions) -> usize {
    let (w, h) = img.size();
    let rows = copts.tile.min(h);
    let tile_pixels = copts.tile.min(w) * rows;
    let (band, assemble) = match copts.format {
        CacheFormat::F16 => (12, 18),
        CacheFormat::U8 => (6, 3),
        CacheFormat::U16 => (6, 6),
        CacheFormat::F32 | CacheFormat::Auto => (12, 12),
    };
    img.resident_bytes(rows)
        + w * rows * band
        + rayon::current_num_threads() * tile_pixels * assemble
}

/// How many images a decoding batch may hold open at once: most images (PFM, EXR, TIFF, HDR)
/// are read from their open file a band at a time, so a batch is at most the process's limit
/// on open files (`RLIMIT_NOFILE`, the soft one) less 128 for everything else, at least 16 (a
/// batch of 1,512 EXR images failed with "Too many open files" under the common limit of
/// 1,024).
fn open_file_budget() -> usize {
    #[cfg(unix)]
    {
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: getrlimit writes into the struct we own.
        if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) } == 0
            && lim.rlim_cur != libc::RLIM_INFINITY
        {
            return usize::try_from(lim.rlim_cur)
                .unwrap_or(usize::MAX)
                .saturating_sub(128)
                .max(16);
        }
    }
    usize::MAX
}

/// Refuses a tile size whose band of rows (one row of tiles of one image, decoded) is larger
/// than the decoding memory, `--tile-size` at least as large as the image making the band the
/// whole image; the default tile size is always accepted (one band of it is at most 25 MB).
fn check_band(first: &Path, w: usize, h: usize, copts: &CacheOptions) -> Result<()> {
    let band = w * copts.tile.min(h) * 12;
    if band <= copts.batch_bytes || copts.tile <= CacheOptions::default().tile {
        return Ok(());
    }
    let size = |b: usize| crate::bounded::show_size(b as u64);
    Err(Error::invalid(
        first,
        format!(
            "tiles of {} pixels are decoded a row of tiles at a time, {} rows of this \
             {w}-pixel-wide image: {}, more than the {} of decoding memory; use a smaller \
             --tile-size or a larger --decode-memory",
            copts.tile,
            copts.tile.min(h),
            size(band),
            size(copts.batch_bytes)
        ),
    ))
}

/// Builds (or resumes building) the partial cache at `partial`; on success it is complete.
/// `size_ok` checks the images' size (against the mask) once it is known: from a resumed
/// header, or from the first image's header before the file is created and any pixel decoded.
#[allow(clippy::too_many_arguments)]
pub(super) fn build(
    ds: &Dataset,
    opts: &DecodeOptions,
    partial: &Path,
    fingerprint: u64,
    copts: CacheOptions,
    size_ok: &dyn Fn(usize, usize) -> Result<()>,
    stop: &AtomicBool,
    on_image: &(dyn Fn() + Sync),
) -> Result<Built> {
    let n = ds.images.len();
    let notes = Notes::new(n);
    let mut times = Times::default();
    let mut first: Option<StackImage> = None;
    // Resume a partial build of the same inputs, else start afresh from the first image.
    let resumable = read_header(partial)?
        .filter(|(h, len)| !h.complete && matches(h, *len, fingerprint, copts.tile, n));
    let (mut header, file) = match resumable {
        Some((h, _)) => {
            size_ok(h.width, h.height)?;
            let file =
                crate::atomic::open_no_follow(OpenOptions::new().read(true).write(true), partial)
                    .map_err(|e| Error::write(partial, e))?;
            (h, file)
        }
        None => {
            if partial.exists() {
                fs::remove_file(partial).map_err(|e| Error::write(partial, e))?;
            }
            if stop.load(Ordering::Relaxed) {
                return Err(Error::Interrupted);
            }
            let t = Instant::now();
            let img = open_stack_image(ds, 0, opts, None)?;
            times.decode += t.elapsed().as_secs_f64();
            let (w, h) = img.size();
            if w == 0 || h == 0 {
                return Err(Error::invalid(&ds.images[0], "image is empty"));
            }
            size_ok(w, h)?;
            check_band(&ds.images[0], w, h, &copts)?;
            let light_block = (copts.batch_bytes / image_cost(&img, &copts))
                .min(open_file_budget())
                .clamp(1, n);
            first = Some(img);
            let header = Header {
                width: w,
                height: h,
                n_lights: n,
                tile: copts.tile,
                fingerprint,
                images_done: 0,
                complete: false,
                light_block,
                format: copts.format,
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
    let mut decoded = 0;
    let mut start = header.images_done;
    let reader = Batch {
        ds,
        opts,
        notes: &notes,
        stop,
        on_image,
    };
    while start < n {
        if stop.load(Ordering::Relaxed) {
            return Err(Error::Interrupted);
        }
        let end = n.min(start + batch);
        let target = Target {
            file: &file,
            path: partial,
            grid: &grid,
            header: &header,
        };
        reader.fill(&target, start..end, first.take(), &mut times)?;
        decoded += end - start;
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
        decode_s: times.decode,
        scatter_s: times.scatter,
    })
}

/// Seconds spent decoding and scattering.
#[derive(Debug, Default)]
struct Times {
    decode: f64,
    scatter: f64,
}

/// The cache file being written and its layout.
struct Target<'a> {
    file: &'a File,
    path: &'a Path,
    grid: &'a TileGrid,
    header: &'a Header,
}

/// What a batch of images is read with.
struct Batch<'a> {
    ds: &'a Dataset,
    opts: &'a DecodeOptions,
    notes: &'a Notes,
    stop: &'a AtomicBool,
    on_image: &'a (dyn Fn() + Sync),
}

impl Batch<'_> {
    /// Reads images `lights` (one block of lights; `first`: its first image, already opened)
    /// in lockstep, a band of tile rows at a time (each image its band, in parallel), and
    /// writes each band's tiles into `to` ([`scatter`]): what is held is the images' readers
    /// and one band of each, never a whole decoded image. An image whose header declares
    /// another size than the stack's is refused before it is decoded. `on_image` is called
    /// once per image, spread over the bands.
    fn fill(
        &self,
        to: &Target,
        lights: std::ops::Range<usize>,
        first: Option<StackImage>,
        times: &mut Times,
    ) -> Result<()> {
        let (grid, size) = (to.grid, (to.header.width, to.header.height));
        let t = Instant::now();
        let from = lights.start + first.is_some() as usize;
        let opened: Vec<Result<StackImage>> = (from..lights.end)
            .into_par_iter()
            .map(|i| {
                if self.stop.load(Ordering::Relaxed) {
                    return Err(Error::Interrupted);
                }
                open_stack_image(self.ds, i, self.opts, Some(size))
            })
            .collect();
        let mut images: Vec<StackImage> = Vec::with_capacity(lights.len());
        images.extend(first);
        // The first error in image order, as the in-memory loader reports it.
        for r in opened {
            images.push(r?);
        }
        times.decode += t.elapsed().as_secs_f64();
        let band_len = grid.width * grid.tile.min(grid.height) * 3;
        let (mut bands, records) = if to.header.format.integer() {
            let records = self.write_records(to, lights.start, &images)?;
            (Bands::Codes(vec![0; images.len() * band_len]), records)
        } else {
            (Bands::Float(vec![0.0; images.len() * band_len]), Vec::new())
        };
        let bands_y = grid.tiles_y();
        let mut reported = 0;
        for band in 0..bands_y {
            if self.stop.load(Ordering::Relaxed) {
                return Err(Error::Interrupted);
            }
            let t = Instant::now();
            let rows = grid.tile.min(grid.height - band * grid.tile);
            let last = band + 1 == bands_y;
            let n = rows * grid.width * 3;
            let done = |img: &mut StackImage| if last { img.finish(self.notes) } else { Ok(()) };
            let read: Vec<Result<()>> = match &mut bands {
                Bands::Float(b) => images
                    .par_iter_mut()
                    .zip(b.par_chunks_mut(band_len))
                    .map(|(img, buf)| {
                        img.read_rgb(&mut buf[..n])?;
                        done(img)
                    })
                    .collect(),
                Bands::Codes(b) => images
                    .par_iter_mut()
                    .zip(b.par_chunks_mut(band_len))
                    .map(|(img, buf)| {
                        img.read_codes(&mut buf[..n])?;
                        done(img)
                    })
                    .collect(),
            };
            read.into_iter().collect::<Result<()>>()?;
            times.decode += t.elapsed().as_secs_f64();
            let t = Instant::now();
            scatter(to, lights.start, band, &bands, band_len, &records)?;
            times.scatter += t.elapsed().as_secs_f64();
            let done = images.len() * (band + 1) / bands_y;
            while reported < done {
                (self.on_image)();
                reported += 1;
            }
        }
        Ok(())
    }
}

impl Batch<'_> {
    /// Writes the records of images `start..` (opened) of an integer cache: how each one's
    /// codes become samples. An image whose samples the format cannot hold (a float image, or
    /// a 16-bit one in a `u8` cache) is refused, naming it. Returns the records' bytes.
    fn write_records(&self, to: &Target, start: usize, images: &[StackImage]) -> Result<Vec<u8>> {
        let mut table = Vec::with_capacity(images.len() * LIGHT_RECORD_BYTES);
        for (j, img) in images.iter().enumerate() {
            let (kind, first_saturated, intensity) = img.code_decoding();
            let fits = match kind {
                SampleKind::Srgb8 | SampleKind::Linear8 => true,
                SampleKind::U16 | SampleKind::Srgb16 => to.header.format == CacheFormat::U16,
                SampleKind::Float => false,
            };
            if !fits {
                let format = serde_json::to_string(&to.header.format).unwrap_or_default();
                return Err(Error::invalid(
                    &self.ds.images[start + j],
                    format!(
                        "{} samples do not fit a {} tile cache; use --cache-format f32",
                        kind.describe(),
                        format.trim_matches('"')
                    ),
                ));
            }
            let record = LightCodes {
                kind,
                first_saturated,
                intensity,
            };
            table.extend_from_slice(&record.encode());
        }
        let at = to.header.lights_offset() + (start * LIGHT_RECORD_BYTES) as u64;
        write_all_at(to.file, &table, at).map_err(|e| Error::write(to.path, e))?;
        Ok(table)
    }
}

/// One band of each image of a batch, interleaved RGB: linear samples for a float cache,
/// the files' codes for an integer one.
enum Bands {
    Float(Vec<f32>),
    Codes(Vec<u16>),
}

/// Appends tile `t`'s pixels of the band (its first pixel `offset`) of each image in `bands`
/// (`band_len` samples apart) to `buf`: pixel-major, each pixel's RGB under the images.
fn gather_tile<T: Copy>(
    grid: &TileGrid,
    t: usize,
    offset: usize,
    bands: &[T],
    band_len: usize,
    buf: &mut Vec<T>,
) {
    buf.clear();
    buf.reserve(grid.tile_pixels(t) * (bands.len() / band_len) * 3);
    for p in grid.pixels(t) {
        let q = (p - offset) * 3;
        for img in bands.chunks_exact(band_len) {
            buf.extend_from_slice(&img[q..q + 3]);
        }
    }
}

/// Writes `buf` at `offset` of `file` (positioned write; the file's cursor is not used, so
/// threads can write different ranges at once).
pub(super) fn write_all_at(file: &File, buf: &[u8], offset: u64) -> std::io::Result<()> {
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

/// Writes one band of tile rows (`band`: a row of tiles) of images `start..` (one block of
/// lights, every block before it full) into each of the band's tiles, and the blocks'
/// checksums (and, for half floats, scale exponents) into the tables: `bands` holds each
/// image's band (interleaved RGB, row-major, `band_len` samples apart; an integer cache's
/// codes, whose block checksums cover `records`, the block's lights' records, too). Per tile,
/// the block is assembled in a per-thread buffer (`pixels * images * 12` bytes for floats, 1 MB
/// for a 32-pixel tile and 85 images; converted to half floats or bytes in a second one for
/// those formats) and written with
/// one positioned write, so every page of the file is written once, by one batch, and nothing
/// of the file is mapped while building.
fn scatter(
    to: &Target,
    start: usize,
    band: usize,
    bands: &Bands,
    band_len: usize,
    records: &[u8],
) -> Result<()> {
    let (grid, h) = (to.grid, to.header);
    let px = h.format.pixel_bytes();
    // Image pixel index of the band's first pixel; the band's tiles, a run of tile numbers.
    let offset = band * grid.tile * grid.width;
    let tiles = band * grid.tiles_x()..(band + 1) * grid.tiles_x();
    let sums: Vec<(u64, i32)> = tiles
        .clone()
        .into_par_iter()
        .map_init(Buffers::default, |bufs, t| {
            let np = grid.tile_pixels(t);
            let (bytes, e): (&[u8], i32) = match bands {
                Bands::Float(b) => {
                    gather_tile(grid, t, offset, b, band_len, &mut bufs.floats);
                    let buf = &mut bufs.floats;
                    match h.format {
                        CacheFormat::F16 => {
                            use half::slice::HalfFloatSliceExt;
                            let e = half_exponent(buf);
                            if e != 0 {
                                let f = pow2(e);
                                for v in buf.iter_mut() {
                                    *v *= f;
                                }
                            }
                            bufs.halves.clear();
                            bufs.halves.resize(buf.len(), half::f16::ZERO);
                            bufs.halves.convert_from_f32_slice(buf);
                            let bits: &[u16] = bufs.halves.reinterpret_cast();
                            (bytemuck::cast_slice(bits), e)
                        }
                        _ => (bytemuck::cast_slice(buf), 0),
                    }
                }
                Bands::Codes(b) => {
                    gather_tile(grid, t, offset, b, band_len, &mut bufs.codes);
                    if h.format == CacheFormat::U8 {
                        bufs.bytes.clear();
                        bufs.bytes.extend(bufs.codes.iter().map(|&c| c as u8));
                        (&bufs.bytes[..], 0)
                    } else {
                        (bytemuck::cast_slice(&bufs.codes), 0)
                    }
                }
            };
            let at = HEADER_BYTES + grid.first_pixel(t) * h.n_lights * px + start * np * px;
            write_all_at(to.file, bytes, at as u64).map_err(|e| Error::write(to.path, e))?;
            Ok((block_sum(bytes, e, records), e))
        })
        .collect::<Result<_>>()?;
    // Block-major tables: the band's tiles of this block are one run.
    let k = start / h.light_block * grid.n_tiles() + tiles.start;
    let table: Vec<u8> = sums.iter().flat_map(|v| v.0.to_le_bytes()).collect();
    write_all_at(to.file, &table, h.table_offset() + (k * 8) as u64)
        .map_err(|e| Error::write(to.path, e))?;
    if h.format == CacheFormat::F16 {
        let scales: Vec<u8> = sums.iter().flat_map(|v| v.1.to_le_bytes()).collect();
        write_all_at(to.file, &scales, h.scales_offset() + (k * 4) as u64)
            .map_err(|e| Error::write(to.path, e))?;
    }
    Ok(())
}

/// A thread's buffers for assembling a tile's block: its samples (floats or codes) and their
/// stored form (half floats, bytes).
#[derive(Default)]
struct Buffers {
    floats: Vec<f32>,
    halves: Vec<half::f16>,
    codes: Vec<u16>,
    bytes: Vec<u8>,
}

/// The power-of-two exponent `e` that puts the largest finite magnitude of `v` times `2^e` in
/// [32768, 65504] (half floats' largest binade); 0 when `v` holds no finite non-zero value.
fn half_exponent(v: &[f32]) -> i32 {
    let max = v
        .iter()
        .filter(|x| x.is_finite())
        .fold(0.0f32, |m, x| m.max(x.abs()));
    if max == 0.0 {
        return 0;
    }
    // max = m * 2^k with m in [1, 2): m * 2^(k + e) in [32768, 65536) for e = 15 - k, and the
    // values that round up to 65536 (above 65504) take one less.
    let k = ((max.to_bits() >> 23) & 0xff) as i32 - 127;
    let mut e = (15 - k).clamp(-125, 126);
    if max * pow2(e) > 65504.0 {
        e -= 1;
    }
    e
}

/// How many other hard links the file `path` has (0 off Unix).
pub(super) fn other_links(path: &Path) -> Result<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let meta = std::fs::symlink_metadata(path).map_err(|e| Error::read(path, e))?;
        Ok(meta.nlink().saturating_sub(1))
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        Ok(0)
    }
}

/// Decodes the lights of the light blocks that hold a failed `(tile, block)` of the complete
/// cache at `path` again and rewrites those blocks (in every tile) with their checksums, in
/// place. Called under the exclusive lock. An interruption leaves the cache complete with some
/// blocks still failing, which the next open repairs.
#[allow(clippy::too_many_arguments)]
pub(super) fn repair(
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
    // Repaired in place: a file with other hard links (a backup made by `cp -al`) would
    // change under its other names too, outside this folder. The caller builds such a cache
    // anew; here it is refused, never written.
    let links = other_links(path)?;
    if links > 0 {
        return Err(Error::invalid(
            path,
            format!(
                "has {links} other hard links, so its corrupt blocks are not repaired in \
                 place; remove it (or the other links) and run again"
            ),
        ));
    }
    let file = crate::atomic::open_no_follow(OpenOptions::new().read(true).write(true), path)
        .map_err(|e| Error::write(path, e))?;
    let grid = TileGrid::new(h.width, h.height, h.tile);
    let target = Target {
        file: &file,
        path,
        grid: &grid,
        header: h,
    };
    let notes = Notes::new(0);
    let batch = Batch {
        ds,
        opts,
        notes: &notes,
        stop,
        on_image,
    };
    for b in blocks {
        let lights = b * h.light_block..h.n_lights.min((b + 1) * h.light_block);
        let mut times = Times::default();
        batch.fill(&target, lights.clone(), None, &mut times)?;
        info.decode_s += times.decode;
        info.scatter_s += times.scatter;
        info.images_decoded += lights.len();
        info.blocks_repaired += 1;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codecs::Gamma;
    use crate::stack::fixture;

    /// The cache of a stack of every kind of image, light blocks of 3, tiles of 8, as decoding
    /// whole images and then scattering them writes it, which reading a band at a time (PNG and
    /// PFM row by row) must reproduce:
    /// the bytes after the header (samples, checksums, half-float exponents) are pinned by
    /// their XXH3-64, and the warnings about the inputs by their text.
    #[test]
    fn the_cache_of_every_kind_of_image_is_pinned() {
        let d = tempfile::tempdir().unwrap();
        let ds = fixture::every_kind(d.path());
        let pinned = [
            (Gamma::Auto, CacheFormat::F32, 178420, 0x1223e85790a591f5),
            (Gamma::Auto, CacheFormat::F16, 91978, 0x1f13c32aeed2ab5d),
            (Gamma::Srgb, CacheFormat::F32, 178420, 0x8b964c96b0aacfda),
            (Gamma::Linear, CacheFormat::F16, 91978, 0x76a305c19569a9b2),
        ];
        for (gamma, format, len, hash) in pinned {
            let opts = DecodeOptions {
                gamma,
                ..Default::default()
            };
            let partial = d.path().join(format!("{gamma:?}-{format:?}.partial"));
            let mut copts = CacheOptions {
                tile: 8,
                batch_bytes: 0,
                trust_mtime: false,
                format,
            };
            copts.batch_bytes =
                3 * image_cost(&open_stack_image(&ds, 0, &opts, None).unwrap(), &copts);
            let stop = AtomicBool::new(false);
            let built = build(
                &ds,
                &opts,
                &partial,
                0,
                copts,
                &|_, _| Ok(()),
                &stop,
                &|| {},
            )
            .unwrap();
            let bytes = std::fs::read(&partial).unwrap();
            let (h, _) = read_header(&partial).unwrap().unwrap();
            assert_eq!(h.light_block, 3);
            assert_eq!(bytes.len(), len, "{gamma:?} {format:?}");
            let sum = xxhash_rust::xxh3::xxh3_64(&bytes[HEADER_BYTES..]);
            assert_eq!(sum, hash, "{gamma:?} {format:?}: {sum:#018x}");
            let warnings: Vec<String> = built
                .warnings
                .iter()
                .map(|w| w.to_string().replace(d.path().to_str().unwrap(), "DIR"))
                .collect();
            assert!(
                warnings[0].starts_with("DIR/rgb16.png: 16-bit")
                    && warnings[1].starts_with("DIR/rgb.pfm: float (linear) image among")
                    && warnings[2].starts_with("DIR/grey8.png: grey image among RGB ones (6 such")
                    && warnings[3].starts_with("DIR/rgb.pfm: 120 negative samples in 3 images"),
                "{warnings:?}"
            );
            let tagged = warnings
                .iter()
                .any(|w| w.starts_with("DIR/srgb16.png: its PNG sRGB chunk"));
            assert_eq!(tagged, gamma != Gamma::Srgb, "{warnings:?}");
        }
    }
}
