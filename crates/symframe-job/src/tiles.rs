//! Any [`PixelMethod`] run tile by tile from the on-disk cache, one result file per finished
//! tile (so a run can be interrupted and resumed, or split into shards), and the tiles read
//! back in pixel order.
//!
//! Memory per worker thread: the mapped pages of the tile it works on (released when done:
//! `tile^2 * lights * 12` bytes, 18.6 MB for 32-pixel tiles of 1,512 lights), a gather table
//! (16 bytes per light), one pixel's samples and the method's buffers (the symmetry
//! estimator's fast objective: ~72 bytes per light), and the tile's records.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use anyhow::{Context, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use symframe::{PixelMethod, PixelRecord};
use symframe_io::{TileCache, TileGrid};

use symframe_io::TileFile;

use crate::{Control, Interrupted, Progress, Stage};

/// Folder of the per-tile result files inside an output folder.
pub const TILES_DIR: &str = ".symframe-tiles";

/// Folder of an automatic fit's per-tile evidence (the pass that chooses each pixel's model)
/// inside its output folder, removed like [`TILES_DIR`] when the fit is done.
pub(crate) const EVIDENCE_DIR: &str = ".symframe-evidence-tiles";

/// A per-pixel result that can be stored in a tile result file.
pub(crate) trait TileRecord: Sized + Send {
    /// Writes tile `t`'s records atomically to `path`, tagged with the job's fingerprint.
    fn write(path: &Path, job: u64, t: usize, records: &[Self]) -> symframe_io::Result<()>;
    /// Whether `path` holds tile `t`'s `n` records of job `job` (or is missing, stale or
    /// corrupt).
    fn check(path: &Path, job: u64, t: usize, n: usize) -> TileFile;
    /// Reads tile `t`'s `n` records of job `job`.
    fn read(path: &Path, job: u64, t: usize, n: usize) -> symframe_io::Result<Vec<Self>>;
}

impl TileRecord for PixelRecord {
    fn write(path: &Path, job: u64, t: usize, records: &[Self]) -> symframe_io::Result<()> {
        symframe_io::write_tile_result(path, job, t, records)
    }
    fn check(path: &Path, job: u64, t: usize, n: usize) -> TileFile {
        symframe_io::check_tile_result(path, job, t, n)
    }
    fn read(path: &Path, job: u64, t: usize, n: usize) -> symframe_io::Result<Vec<Self>> {
        symframe_io::read_tile_result(path, job, t, n)
    }
}

/// The result file of tile `t` in `dir`.
pub(crate) fn tile_path(dir: &Path, t: usize) -> PathBuf {
    symframe_io::tile_result_path(dir, t)
}

/// Removes a finished job's tile folder: its tile result files (`tile-*.bin`, and the hidden
/// temporaries of their atomic writes), then the folder if that left it empty. Anything else
/// in it (a user's file, a folder) is left with the folder: only this tool's files go.
pub(crate) fn remove_tile_folder(dir: &Path) -> Result<()> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let ours = (name.starts_with("tile-") && name.ends_with(".bin"))
            || (name.starts_with(".tile-") && name.ends_with(".tmp"));
        if ours && e.file_type().is_ok_and(|t| !t.is_dir()) {
            fs::remove_file(e.path())
                .with_context(|| format!("{}: cannot remove", e.path().display()))?;
        }
    }
    let _ = fs::remove_dir(dir);
    Ok(())
}

/// The tiles of shard `k` of `n` (1-based): `t % n == k - 1`.
pub fn shard_tiles(n_tiles: usize, k: usize, n: usize) -> Vec<usize> {
    (0..n_tiles).filter(|t| t % n == k - 1).collect()
}

/// What a tiled run did with its tiles.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct TileCounts {
    /// Tiles computed by this run.
    pub computed: usize,
    /// Tiles found finished by an earlier run (same job), not recomputed.
    pub reused: usize,
}

/// Removes temporary files a hard-killed run may have left in a tiles folder.
fn clean_temporaries(dir: &Path) {
    if let Ok(rd) = fs::read_dir(dir) {
        for e in rd.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') && name.ends_with(".tmp") {
                let _ = fs::remove_file(e.path());
            }
        }
    }
}

/// Runs `method` on `tiles` of the cache into result files in `dir`, skipping those already
/// done for this job (pixels outside `mask` get [`PixelMethod::masked`]). Stops starting tiles
/// once the control's stop flag is set, and then returns [`Interrupted`] if any tile is left.
pub(crate) fn run_tiles<M>(
    cache: &TileCache,
    method: &M,
    mask: Option<&[bool]>,
    job: u64,
    tiles: &[usize],
    dir: &Path,
    ctl: &Control,
) -> Result<TileCounts>
where
    M: PixelMethod,
    M::Output: TileRecord,
{
    fs::create_dir_all(dir).with_context(|| format!("{}: cannot create folder", dir.display()))?;
    clean_temporaries(dir);
    let grid = *cache.grid();
    let mut todo = Vec::new();
    for &t in tiles {
        match M::Output::check(&tile_path(dir, t), job, t, grid.tile_pixels(t)) {
            TileFile::Done => {}
            TileFile::Corrupt(e) => {
                ctl.warn(&format!("{e}; recomputing the tile"));
                todo.push(t);
            }
            TileFile::Missing | TileFile::Stale => todo.push(t),
        }
    }
    let reused = tiles.len() - todo.len();
    // Set by the testing aid `stop_after_tiles` (the caller's flag stays the caller's).
    let stopped = AtomicBool::new(ctl.stop_after_tiles == Some(0));
    let lights: Vec<usize> = match method.lights() {
        Some(l) => l.to_vec(),
        None => (0..cache.n_lights()).collect(),
    };
    let total = tiles.len() as u64;
    let finished = AtomicUsize::new(0);
    ctl.report(Progress::new(Stage::Tiles, reused as u64, total));
    let results: Vec<Result<bool>> = todo
        .par_iter()
        .enumerate()
        .map_init(
            || (method.scratch(), vec![0.0; lights.len() * 3], Vec::new()),
            |(pixel_scratch, samples, scratch), (i, &t)| -> Result<bool> {
                if ctl.stop.load(Ordering::SeqCst) || stopped.load(Ordering::SeqCst) {
                    return Ok(false);
                }
                // Each thread walks a run of consecutive tiles: the next one's disk reads
                // overlap this one's estimation (docs/performance.md, "Paper scale").
                if let Some(&next) = todo.get(i + 1) {
                    cache.prefetch(next);
                }
                let view = cache.tile(t, scratch);
                let gather = view.gatherer(&lights);
                let records: Vec<M::Output> = grid
                    .pixels(t)
                    .enumerate()
                    .map(|(k, p)| {
                        if mask.is_some_and(|m| !m[p]) {
                            return method.masked();
                        }
                        gather.pixel(k, samples);
                        method.pixel(p, samples, pixel_scratch)
                    })
                    .collect();
                cache.release(t);
                M::Output::write(&tile_path(dir, t), job, t, &records)?;
                let n = finished.fetch_add(1, Ordering::SeqCst) + 1;
                ctl.report(Progress::new(Stage::Tiles, (reused + n) as u64, total));
                if ctl.stop_after_tiles.is_some_and(|s| n >= s) {
                    stopped.store(true, Ordering::SeqCst);
                }
                Ok(true)
            },
        )
        .collect();
    let mut computed = 0;
    for r in results {
        computed += r? as usize;
    }
    if computed < todo.len() {
        return Err(Interrupted.into());
    }
    Ok(TileCounts { computed, reused })
}

/// Reads the records of every tile (`path_of(t)` gives tile `t`'s file) and hands each pixel's
/// record to `put(p, record)` in tile order; tiles are read in parallel a row of tiles at a
/// time (bounded memory). `on_tile` is called once per tile read.
pub(crate) fn read_tiles<R: TileRecord>(
    grid: &TileGrid,
    job: u64,
    path_of: impl Fn(usize) -> PathBuf + Sync,
    mut put: impl FnMut(usize, R),
) -> Result<()> {
    let per_row = grid.tiles_x();
    for row in 0..grid.tiles_y() {
        let tiles: Vec<usize> = (row * per_row..(row + 1) * per_row).collect();
        let recs: Vec<symframe_io::Result<Vec<R>>> = tiles
            .par_iter()
            .map(|&t| R::read(&path_of(t), job, t, grid.tile_pixels(t)))
            .collect();
        for (&t, r) in tiles.iter().zip(recs) {
            for (p, rec) in grid.pixels(t).zip(r?) {
                put(p, rec);
            }
        }
    }
    Ok(())
}

/// The process's peak resident set size in bytes (`VmHWM` of `/proc/self/status`; Linux only).
pub fn peak_rss_bytes() -> Option<u64> {
    let s = fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The memory this process may still take, bytes: the smaller of the system's available
/// memory (`MemAvailable`) and what its address-space limit leaves (Linux; `None` elsewhere
/// or when neither is known).
pub(crate) fn memory_available_bytes() -> Option<u64> {
    let kb = |text: &str, key: &str| -> Option<u64> {
        let line = text.lines().find(|l| l.starts_with(key))?;
        Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
    };
    let free = fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| kb(&t, "MemAvailable:"));
    let limit = address_space_left(|| {
        fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|t| kb(&t, "VmSize:"))
    });
    match (free, limit) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// The address-space limit (`RLIMIT_AS`) less `in_use()`, when a limit is set.
#[cfg(unix)]
fn address_space_left(in_use: impl Fn() -> Option<u64>) -> Option<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes into the struct passed; no other memory is touched.
    let rc = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut lim) };
    if rc != 0 || lim.rlim_cur == libc::RLIM_INFINITY {
        return None;
    }
    #[allow(clippy::unnecessary_cast)] // rlim_t is not u64 on every unix
    let limit = lim.rlim_cur as u64;
    Some(limit.saturating_sub(in_use().unwrap_or(0)))
}

#[cfg(not(unix))]
fn address_space_left(_in_use: impl Fn() -> Option<u64>) -> Option<u64> {
    None
}
