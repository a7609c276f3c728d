//! The tiled pipeline behind `symframe estimate` and `symframe merge`: estimation tile by tile
//! from the on-disk cache, one result file per finished tile (so a run can be interrupted and
//! resumed, or split into shards), and assembly of the tiles into full maps.
//!
//! Memory per worker thread: the mapped pages of the tile it estimates (released when done:
//! `tile^2 * lights * 12` bytes, 18.6 MB for 32-pixel tiles of 1,512 lights), a gather table
//! (16 bytes per light), one pixel's slice and the fast objective's light layouts (~72 bytes
//! per light), and the tile's records (40 bytes per pixel). Assembly holds the full
//! maps (33 bytes per pixel).

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::OnceLock;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use symframe::baseline::{baseline_pixel, Baseline, BaselineParams};
use symframe::estimate::PixelCounts;
use symframe::{
    estimate_pixels, BlockScratch, EstimateMaps, Estimator, EstimatorParams, PixelRecord, Rig,
};
use symframe_io::fingerprint::Fingerprint;
use symframe_io::{
    check_tile_result, read_tile_result, tile_result_path, write_tile_result, TileFile,
};
use symframe_io::{TileCache, TileGrid, TileView};

use crate::cli::MergeArgs;
use crate::progress;

/// Folder of the per-tile result files inside an output folder.
pub const TILES_DIR: &str = ".symframe-tiles";
/// Default folder of the tile cache inside an output folder.
pub const CACHE_DIR: &str = ".symframe-cache";
/// A shard's manifest, written once all its tiles are done.
pub const MANIFEST: &str = "shard.json";
const MANIFEST_FORMAT: &str = "symframe-shard";
const MANIFEST_VERSION: u32 = 1;

/// Set by Ctrl-C (or the testing aid `--stop-after-tiles`): no new image or tile is started.
pub static STOP: AtomicBool = AtomicBool::new(false);

/// Installs the Ctrl-C handler (once): the first Ctrl-C sets [`STOP`] so that the running tiles
/// finish and nothing new starts; a second one exits at once (tile files are written atomically,
/// so even that leaves no corrupt output).
pub fn install_interrupt_handler() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        let _ = ctrlc::set_handler(|| {
            if STOP.swap(true, Ordering::SeqCst) {
                eprintln!("\nsymframe: interrupted; run the same command again to resume");
                std::process::exit(130);
            }
            eprintln!(
                "\nsymframe: stopping after the images or tiles in progress (Ctrl-C again to quit now)"
            );
        });
    });
}

/// The run stopped early on request; what was done is kept.
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted; run the same command again to resume")
    }
}

impl std::error::Error for Interrupted {}

/// Maps the I/O crate's interruption to [`Interrupted`], other errors to themselves.
pub fn io_err(e: symframe_io::Error) -> anyhow::Error {
    match e {
        symframe_io::Error::Interrupted => Interrupted.into(),
        e => e.into(),
    }
}

/// The process's peak resident set size in bytes (`VmHWM` of `/proc/self/status`; Linux only).
pub fn peak_rss_bytes() -> Option<u64> {
    let s = fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// What estimates the tiles: the symmetry method on a rig, or a baseline on every light.
#[derive(Debug, Clone, Copy)]
pub enum Method<'a> {
    /// The symmetry method.
    Symmetry {
        /// The rig (lights inside the cone).
        rig: &'a Rig,
        /// The estimator's parameters.
        params: EstimatorParams,
    },
    /// A baseline.
    Baseline {
        /// Which.
        method: Baseline,
        /// Unit light directions, one per input light.
        lights: &'a [DVec3],
        /// Its parameters.
        params: BaselineParams,
    },
}

/// Per-thread buffers of [`Method::estimate_tile`].
enum Scratch {
    Symmetry(Box<BlockScratch>),
    Baseline { samples: Vec<f32>, buf: Vec<f64> },
}

impl Method<'_> {
    fn scratch(&self) -> Scratch {
        match self {
            Method::Symmetry { rig, .. } => Scratch::Symmetry(Box::new(BlockScratch::new(rig))),
            Method::Baseline { lights, .. } => Scratch::Baseline {
                samples: vec![0.0; lights.len() * 3],
                buf: Vec::with_capacity(lights.len()),
            },
        }
    }

    /// The records of one tile (pixel `k` estimated when `inside(k)`), computed exactly as the
    /// in-memory pipelines compute them.
    fn estimate_tile(
        &self,
        estimator: Option<&Estimator>,
        tile: TileView,
        inside: impl Fn(usize) -> bool,
        scratch: &mut Scratch,
    ) -> Vec<PixelRecord> {
        match (self, scratch) {
            (Method::Symmetry { rig, .. }, Scratch::Symmetry(scratch)) => {
                let gather = tile.gatherer(&rig.input_index);
                estimate_pixels(
                    estimator.expect("the symmetry method has an estimator"),
                    tile.n_pixels(),
                    inside,
                    |k, out| gather.pixel(k, out),
                    scratch,
                )
            }
            (
                &Method::Baseline {
                    method,
                    lights,
                    params,
                },
                Scratch::Baseline { samples, buf },
            ) => {
                let all: Vec<usize> = (0..lights.len()).collect();
                let gather = tile.gatherer(&all);
                (0..tile.n_pixels())
                    .map(|k| {
                        if !inside(k) {
                            return PixelRecord::MASKED;
                        }
                        gather.pixel(k, samples);
                        baseline_pixel(method, samples, lights, &params, buf).record()
                    })
                    .collect()
            }
            _ => unreachable!("scratch of another method"),
        }
    }
}

/// The fingerprint of everything a tile's results depend on: the cached inputs, the image and
/// tile sizes, the method with its lights and parameters, the mask and the versions.
pub fn job_fingerprint(cache: &TileCache, method: &Method, mask: Option<&[bool]>) -> Result<u64> {
    let g = cache.grid();
    let mut f = Fingerprint::new();
    f.str("symframe job")
        .str(env!("CARGO_PKG_VERSION"))
        .u64(symframe_io::tile_results::TILE_RESULT_VERSION as u64)
        .u64(cache.fingerprint())
        .u64(g.width as u64)
        .u64(g.height as u64)
        .u64(g.tile as u64);
    match method {
        Method::Symmetry { rig, params } => {
            let min_domain = Estimator::new(rig, *params).min_domain();
            f.str("symmetry")
                .f64(rig.theta_d_max_deg)
                // How the fast path reads the slice (results from an older lookup do not mix).
                .str("spherical-walk")
                .u64(rig.n_input as u64)
                .str(&serde_json::to_string(params)?)
                .u64(min_domain as u64);
            for &i in &rig.input_index {
                f.u64(i as u64);
            }
            for l in &rig.lights_in_camera {
                f.f64(l.x).f64(l.y).f64(l.z);
            }
        }
        Method::Baseline {
            method,
            lights,
            params,
        } => {
            f.str(method.name()).str(&serde_json::to_string(params)?);
            for l in lights.iter() {
                f.f64(l.x).f64(l.y).f64(l.z);
            }
        }
    }
    match mask {
        None => f.u64(0),
        Some(m) => {
            f.u64(1);
            for chunk in m.chunks(64) {
                let bits = chunk
                    .iter()
                    .enumerate()
                    .fold(0u64, |a, (k, &b)| a | ((b as u64) << k));
                f.u64(bits);
            }
            &mut f
        }
    };
    Ok(f.finish())
}

/// The tiles of shard `k` of `n` (1-based): `t % n == k - 1`.
pub fn shard_tiles(n_tiles: usize, k: usize, n: usize) -> Vec<usize> {
    (0..n_tiles).filter(|t| t % n == k - 1).collect()
}

/// What [`estimate_tiles`] did.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct TileCounts {
    /// Tiles estimated by this run.
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

/// Estimates `tiles` of the cache into result files in `dir`, skipping those already done for
/// this job. Stops starting tiles once [`STOP`] is set (then returns [`Interrupted`] if any
/// tile is left); `stop_after` sets it after that many tiles of this run.
pub fn estimate_tiles(
    cache: &TileCache,
    method: &Method,
    mask: Option<&[bool]>,
    job: u64,
    tiles: &[usize],
    dir: &Path,
    stop_after: Option<usize>,
) -> Result<TileCounts> {
    fs::create_dir_all(dir).with_context(|| format!("{}: cannot create folder", dir.display()))?;
    clean_temporaries(dir);
    let grid = *cache.grid();
    let mut todo = Vec::new();
    for &t in tiles {
        match check_tile_result(&tile_result_path(dir, t), job, t, grid.tile_pixels(t)) {
            TileFile::Done => {}
            TileFile::Corrupt(e) => {
                eprintln!("warning: {e}; recomputing the tile");
                todo.push(t);
            }
            TileFile::Missing | TileFile::Stale => todo.push(t),
        }
    }
    let reused = tiles.len() - todo.len();
    if stop_after == Some(0) {
        STOP.store(true, Ordering::SeqCst);
    }
    let estimator = match method {
        Method::Symmetry { rig, params } => Some(Estimator::new(rig, *params)),
        Method::Baseline { .. } => None,
    };
    let bar = progress::bar(tiles.len() as u64, "tiles");
    bar.inc(reused as u64);
    let finished = AtomicUsize::new(0);
    let results: Vec<Result<bool>> = todo
        .par_iter()
        .map_init(
            || method.scratch(),
            |scratch, &t| -> Result<bool> {
                if STOP.load(Ordering::SeqCst) {
                    return Ok(false);
                }
                let pixels: Vec<usize> = grid.pixels(t).collect();
                let records = method.estimate_tile(
                    estimator.as_ref(),
                    cache.tile(t),
                    |k| match mask {
                        Some(m) => m[pixels[k]],
                        None => true,
                    },
                    scratch,
                );
                cache.release(t);
                write_tile_result(&tile_result_path(dir, t), job, t, &records)?;
                bar.inc(1);
                let n = finished.fetch_add(1, Ordering::SeqCst) + 1;
                if stop_after.is_some_and(|s| n >= s) {
                    STOP.store(true, Ordering::SeqCst);
                }
                Ok(true)
            },
        )
        .collect();
    bar.finish_and_clear();
    let mut computed = 0;
    for r in results {
        computed += r? as usize;
    }
    if computed < todo.len() {
        return Err(Interrupted.into());
    }
    Ok(TileCounts { computed, reused })
}

/// Assembles full maps from the result files of every tile (`path_of(t)` gives tile `t`'s file).
pub fn assemble(
    grid: &TileGrid,
    job: u64,
    path_of: impl Fn(usize) -> PathBuf + Sync,
) -> Result<EstimateMaps> {
    let mut maps = EstimateMaps::empty(grid.width, grid.height);
    // Read in parallel, a row of tiles at a time (bounded memory), store in order.
    let per_row = grid.tiles_x();
    for row in 0..grid.tiles_y() {
        let tiles: Vec<usize> = (row * per_row..(row + 1) * per_row).collect();
        let recs: Vec<symframe_io::Result<Vec<PixelRecord>>> = tiles
            .par_iter()
            .map(|&t| read_tile_result(&path_of(t), job, t, grid.tile_pixels(t)))
            .collect();
        for (&t, r) in tiles.iter().zip(recs) {
            for (p, rec) in grid.pixels(t).zip(r?.iter()) {
                maps.put(p, rec);
            }
        }
    }
    Ok(maps)
}

/// Pixel counts and objective evaluations of `tiles`, read back from their result files.
pub fn count_tiles(
    grid: &TileGrid,
    job: u64,
    dir: &Path,
    tiles: &[usize],
) -> Result<(PixelCounts, u64)> {
    let mut counts = PixelCounts::default();
    let mut evals = 0;
    for &t in tiles {
        for r in read_tile_result(&tile_result_path(dir, t), job, t, grid.tile_pixels(t))? {
            counts.add(r.status, r.has_tangent());
            evals += r.evals as u64;
        }
    }
    Ok((counts, evals))
}

/// A finished shard's manifest (`shard.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardManifest {
    /// Always `symframe-shard`.
    pub format: String,
    /// Manifest format version.
    pub version: u32,
    /// The job's fingerprint (hex): shards of one job have the same.
    pub job: String,
    /// This shard's number, 1-based.
    pub shard: usize,
    /// Number of shards.
    pub of: usize,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Tile side.
    pub tile_size: usize,
    /// Number of tiles of the whole image.
    pub n_tiles: usize,
    /// The tiles this shard holds.
    pub tiles: Vec<usize>,
    /// The shard's own report (what `report.json` of a full run would say, for its tiles).
    pub report: serde_json::Value,
}

impl ShardManifest {
    /// The job fingerprint as a number.
    fn job_u64(&self, path: &Path) -> Result<u64> {
        u64::from_str_radix(&self.job, 16)
            .with_context(|| format!("{}: bad job fingerprint '{}'", path.display(), self.job))
    }
}

/// Writes a shard manifest atomically.
pub fn write_manifest(out: &Path, m: &ShardManifest) -> Result<()> {
    let path = out.join(MANIFEST);
    let tmp = out.join(format!(".{MANIFEST}.{}.tmp", std::process::id()));
    fs::write(&tmp, serde_json::to_string_pretty(m)? + "\n")
        .with_context(|| format!("{}: cannot write", tmp.display()))?;
    fs::rename(&tmp, &path).with_context(|| format!("{}: cannot write", path.display()))
}

/// A short list of tile numbers: the first few and how many more.
fn list_tiles(tiles: &[usize]) -> String {
    let shown: Vec<String> = tiles.iter().take(12).map(|t| t.to_string()).collect();
    if tiles.len() > shown.len() {
        format!(
            "{} and {} more",
            shown.join(", "),
            tiles.len() - shown.len()
        )
    } else {
        shown.join(", ")
    }
}

/// `symframe merge`: checks the shards belong to one job and cover every tile, assembles the
/// maps and writes the usual outputs.
pub fn merge(args: &MergeArgs) -> Result<()> {
    let t0 = Instant::now();
    let mut manifests: Vec<(PathBuf, ShardManifest)> = Vec::new();
    for dir in &args.shards {
        let path = dir.join(MANIFEST);
        if !dir.is_dir() {
            bail!("{}: no such shard folder", dir.display());
        }
        let text = match fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
                "{}: not a finished shard (no {MANIFEST}); run its `symframe estimate ... --tiles K/N` \
                 command again to finish it",
                dir.display()
            ),
            Err(e) => return Err(e).with_context(|| format!("{}: cannot read", path.display())),
        };
        let m: ShardManifest = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a shard manifest", path.display()))?;
        if m.format != MANIFEST_FORMAT || m.version != MANIFEST_VERSION {
            bail!(
                "{}: not a shard manifest of this version (format {} {})",
                path.display(),
                m.format,
                m.version
            );
        }
        manifests.push((dir.clone(), m));
    }
    let (first_dir, first) = &manifests[0];
    for (dir, m) in &manifests[1..] {
        if (m.width, m.height, m.tile_size, m.of)
            != (first.width, first.height, first.tile_size, first.of)
        {
            bail!(
                "{}: shard {}/{} of {}x{} pixels in {}-pixel tiles does not belong with {} \
                 (shard {}/{} of {}x{} in {}-pixel tiles)",
                dir.display(),
                m.shard,
                m.of,
                m.width,
                m.height,
                m.tile_size,
                first_dir.display(),
                first.shard,
                first.of,
                first.width,
                first.height,
                first.tile_size
            );
        }
        if m.job != first.job {
            bail!(
                "{}: belongs to another job than {} (different inputs or parameters: job {} vs {})",
                dir.display(),
                first_dir.display(),
                m.job,
                first.job
            );
        }
    }
    let job = first.job_u64(&first_dir.join(MANIFEST))?;
    let grid = TileGrid::new(first.width, first.height, first.tile_size);
    if grid.n_tiles() != first.n_tiles {
        bail!(
            "{}: {} tiles recorded, {} expected",
            first_dir.join(MANIFEST).display(),
            first.n_tiles,
            grid.n_tiles()
        );
    }
    // Which shard folder holds each tile.
    let mut owner: Vec<Option<usize>> = vec![None; grid.n_tiles()];
    for (i, (dir, m)) in manifests.iter().enumerate() {
        for &t in &m.tiles {
            if t >= owner.len() {
                bail!("{}: tile {t} does not exist", dir.join(MANIFEST).display());
            }
            owner[t].get_or_insert(i);
        }
    }
    let missing: Vec<usize> = (0..owner.len()).filter(|&t| owner[t].is_none()).collect();
    if !missing.is_empty() {
        let mut absent: Vec<usize> = missing.iter().map(|t| t % first.of + 1).collect();
        absent.sort_unstable();
        absent.dedup();
        let shards: Vec<String> = absent.iter().map(|k| format!("{k}/{}", first.of)).collect();
        bail!(
            "missing tiles {} of {}: shard{} {} not given",
            list_tiles(&missing),
            grid.n_tiles(),
            if shards.len() > 1 { "s" } else { "" },
            shards.join(", ")
        );
    }
    let bar = progress::bar(grid.n_tiles() as u64, "merging");
    let maps = assemble(&grid, job, |t| {
        bar.inc(1);
        let (dir, _) = &manifests[owner[t].expect("checked above")];
        tile_result_path(&dir.join(TILES_DIR), t)
    })?;
    bar.finish_and_clear();

    // The report: the first shard's, with the whole image's counts and the shards' timings.
    let mut report = first.report.clone();
    let shard_timings: Vec<serde_json::Value> = manifests
        .iter()
        .map(|(dir, m)| {
            serde_json::json!({
                "folder": dir,
                "shard": format!("{}/{}", m.shard, m.of),
                "tiles": m.report.get("tiles").cloned().unwrap_or_default(),
                "timings": m.report.get("timings").cloned().unwrap_or_default(),
            })
        })
        .collect();
    let estimate_s: f64 = manifests
        .iter()
        .filter_map(|(_, m)| m.report.pointer("/timings/estimate_s")?.as_f64())
        .sum();
    report["pixels"] = serde_json::to_value(maps.counts)?;
    report["evals_per_pixel"] =
        serde_json::json!(maps.evals as f64 / maps.counts.estimated.max(1) as f64);
    report["tiles"] = serde_json::json!({
        "size": grid.tile,
        "count": grid.n_tiles(),
        "shards": first.of,
    });
    report["shards"] = serde_json::Value::Array(shard_timings);
    let out = &args.output;
    crate::estimate::write_maps(out, &maps, |write_s| {
        report["timings"] = serde_json::json!({
            "estimate_s_all_shards": estimate_s,
            "merge_s": t0.elapsed().as_secs_f64() - write_s,
            "write_s": write_s,
            "total_s": t0.elapsed().as_secs_f64(),
            "peak_rss_bytes": peak_rss_bytes(),
        });
        Ok(serde_json::to_string_pretty(&report)?)
    })?;
    if progress::interactive() {
        let c = &maps.counts;
        eprintln!(
            "symframe: merged {} shards into {}: {} pixels estimated ({} with a tangent)",
            manifests.len(),
            out.display(),
            c.estimated,
            c.with_tangent
        );
    }
    Ok(())
}
