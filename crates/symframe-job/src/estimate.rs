//! The estimation job: a capture in, normal/tangent maps, pictures and a report out (or, for a
//! shard, its tile results and manifest).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{Context, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};
use symframe::{
    check_inputs, Baseline, BaselineMethod, BaselineParams, EstimateMaps, Estimator,
    EstimatorParams, PixelCounts, Rig, RigOptions,
};
use symframe_io::fingerprint::Fingerprint;
use symframe_io::{
    CacheInfo, CacheOptions, Dataset, DecodeOptions, Fingerprints, Gamma, NormalPng, StampKind,
    TileCache, TileGrid,
};

use crate::estimate_near::{run_near_rounds, LightModel, NearOptions, NearReport};
use crate::maps_out::{
    result_warnings, write_estimate_outputs, Sources, TileResults, WriteOptions,
};
use crate::merge::{write_manifest, ShardManifest, MANIFEST, MANIFEST_FORMAT, MANIFEST_VERSION};
use crate::outdir::OutputDir;
use crate::pictures::LightsPlot;
use crate::tiles::{peak_rss_bytes, run_tiles, shard_tiles, tile_path, TILES_DIR};
use crate::{Checkpoint, Control, Interrupted, Progress, Stage};

/// Default folder of the tile cache inside an output folder.
pub const CACHE_DIR: &str = ".symframe-cache";

/// Which method estimates the frames, with its parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MethodConfig {
    /// The symmetry method: normals and tangents, any material.
    Symmetry {
        /// The light cone.
        rig: RigOptions,
        /// The estimator's parameters.
        params: EstimatorParams,
    },
    /// A baseline the paper compares against: normals only, every light.
    Baseline {
        /// Which.
        method: Baseline,
        /// Its parameters.
        params: BaselineParams,
    },
}

impl Default for MethodConfig {
    /// The symmetry method with the default cone and parameters.
    fn default() -> Self {
        MethodConfig::Symmetry {
            rig: RigOptions::default(),
            params: EstimatorParams::default(),
        }
    }
}

impl MethodConfig {
    /// The method's name as in reports (`symmetry`, `woodham`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            MethodConfig::Symmetry { .. } => "symmetry",
            MethodConfig::Baseline { method, .. } => method.name(),
        }
    }
}

/// Where the decoded images are cached and how.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CacheConfig {
    /// Cache folder (`None`: `.symframe-cache` inside the output folder). A cache of the same
    /// inputs there is reused; several jobs (shards) may share one folder.
    pub dir: Option<PathBuf>,
    /// Remove the cache once the job has finished (default: keep it for reruns).
    pub remove_after: bool,
    /// Tile size and decoding memory.
    pub options: CacheOptions,
}

/// One shard of a sharded job: the K-th (1-based) of N disjoint sets of tiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// 1-based shard number.
    pub k: usize,
    /// Number of shards.
    pub n: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;
    /// Parses `K/N` with `1 <= K <= N`.
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("expected K/N with 1 <= K <= N (e.g. 3/32), got '{s}'");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (k, n): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if k == 0 || k > n {
            return Err(bad());
        }
        Ok(Self { k, n })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

/// Everything an estimation job needs.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateConfig {
    /// A `.lp` light file, a folder holding one, or a DiLiGenT-style folder.
    pub input: PathBuf,
    /// Output folder (created; same-named files in it are replaced).
    pub output: PathBuf,
    /// The method.
    pub method: MethodConfig,
    /// Mask image (`None`: the dataset's `mask.png`, if any).
    pub mask: Option<PathBuf>,
    /// How images are decoded.
    pub decode: DecodeOptions,
    /// The tile cache.
    pub cache: CacheConfig,
    /// Only this shard's tiles (tile results and a manifest, no maps).
    pub shard: Option<Shard>,
    /// The y convention of `normals.png` (16-bit, `(n + 1) / 2` per channel).
    pub normal_png: NormalPng,
    /// Return the whole maps in memory ([`Done::maps`]) as well as writing them (42 bytes per
    /// pixel); off, the outputs are written a band of tiles at a time and memory stays bounded
    /// whatever the image size (the CLI).
    pub keep_maps: bool,
    /// The light model, and how near lights are estimated.
    pub near: NearOptions,
}

impl EstimateConfig {
    /// The symmetry method with every default, from `input` into `output`.
    pub fn new(input: impl Into<PathBuf>, output: impl Into<PathBuf>) -> Self {
        Self {
            input: input.into(),
            output: output.into(),
            method: MethodConfig::default(),
            mask: None,
            decode: DecodeOptions::default(),
            cache: CacheConfig::default(),
            shard: None,
            normal_png: NormalPng::OpenGl,
            keep_maps: true,
            near: NearOptions::default(),
        }
    }

    /// The cache folder in force.
    pub fn cache_dir(&self) -> PathBuf {
        cache_dir(&self.cache, &self.output)
    }
}

/// The cache folder of `cache` for a job writing into `output`.
pub(crate) fn cache_dir(cache: &CacheConfig, output: &Path) -> PathBuf {
    cache.dir.clone().unwrap_or_else(|| output.join(CACHE_DIR))
}

/// What `report.json` records about a run.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// symframe version.
    pub version: &'static str,
    /// The input as given.
    pub input: PathBuf,
    /// The capture's fingerprint, which `fit` checks its own input against.
    pub inputs: InputsRecord,
    /// The mask used, if any.
    pub mask: Option<PathBuf>,
    /// The estimation method: `symmetry`, `woodham`, `woodham-robust` or `max-reflectance`.
    pub method: &'static str,
    /// Parameters in force (the method's own).
    pub parameters: MethodParameters,
    /// Light counts.
    pub lights: LightCounts,
    /// Image size.
    pub width: usize,
    /// Image size.
    pub height: usize,
    /// What happened to the pixels.
    pub pixels: PixelCounts,
    /// Which measure each pixel's normal comes from (`source.npy`): the legend and counts.
    pub sources: Sources,
    /// Mean symmetry-objective evaluations per estimated pixel.
    pub evals_per_pixel: f64,
    /// How the image was split into tiles and what this run did with them.
    pub tiles: TileReport,
    /// The on-disk tile cache of the decoded images.
    pub cache: CacheReport,
    /// Wall-clock seconds per stage, and peak memory.
    pub timings: Timings,
    /// Every warning of the run, as printed (inputs, recomputed tiles, suspicious results).
    pub warnings: Vec<String>,
    /// The camera and light model of a near-light run (absent for distant lights).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub near: Option<NearReport>,
}

/// The capture a job read, as its report records it: the path-free inputs fingerprint (see
/// [`Fingerprints::inputs`]), so that a later job on the maps can tell whether it reads the
/// same capture (a copy of it included).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputsRecord {
    /// The fingerprint (hex).
    pub fingerprint: String,
    /// How the images entered it: by `content` or by `size_and_mtime` (`--trust-mtime`).
    pub images_by: StampKind,
}

impl InputsRecord {
    /// The record of `f`.
    pub fn of(f: &Fingerprints) -> Self {
        Self {
            fingerprint: format!("{:016x}", f.inputs),
            images_by: f.kind,
        }
    }
}

/// Tiles as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct TileReport {
    /// Tile side in pixels.
    pub size: usize,
    /// Tiles of the whole image.
    pub count: usize,
    /// `K/N` for a shard, else absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<String>,
    /// Tiles this run was asked for (all, or the shard's).
    pub this_run: usize,
    /// Tiles estimated by this run.
    pub computed: usize,
    /// Tiles found finished by an interrupted earlier run of the same job and reused.
    pub reused: usize,
}

/// The tile cache as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct CacheReport {
    /// Where it is, its size, whether it was reused (`hit`), what was decoded.
    #[serde(flatten)]
    pub info: CacheInfo,
    /// Whether it is kept after the run.
    pub kept: bool,
}

/// The parameters of whichever method ran, as recorded in the report.
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum MethodParameters {
    /// The symmetry method's.
    Symmetry(SymmetryParameters),
    /// A baseline's.
    Baseline(BaselineParameters),
}

/// Baseline parameters as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct BaselineParameters {
    /// Shadow threshold, outlier rule.
    #[serde(flatten)]
    pub baseline: BaselineParams,
    /// 8-bit inputs read as linear.
    pub linear_8bit: bool,
    /// The transfer curve of integer inputs (`auto`: 8-bit sRGB, 16-bit linear).
    pub gamma: Gamma,
    /// Saturation threshold (fraction of the integer maximum).
    pub saturation: f32,
    /// The EXR layer read (absent: the default layer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exr_layer: Option<String>,
}

/// Symmetry-method parameters as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct SymmetryParameters {
    /// Light cone half-angle in halfway space, degrees.
    pub theta_d_max_deg: f64,
    /// Estimator parameters.
    #[serde(flatten)]
    pub estimator: EstimatorParams,
    /// The domain threshold actually used.
    pub min_domain_used: u32,
    /// 8-bit inputs read as linear.
    pub linear_8bit: bool,
    /// The transfer curve of integer inputs (`auto`: 8-bit sRGB, 16-bit linear).
    pub gamma: Gamma,
    /// Saturation threshold (fraction of the integer maximum).
    pub saturation: f32,
    /// The EXR layer read (absent: the default layer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exr_layer: Option<String>,
}

/// Light counts.
#[derive(Debug, Clone, Serialize)]
pub struct LightCounts {
    /// Lights in the input.
    pub input: usize,
    /// Lights used: inside the cone for the symmetry method, all of them for a baseline.
    pub used: usize,
    /// Lights outside the cone, dropped (0 for a baseline).
    pub dropped: usize,
}

/// Seconds per stage.
#[derive(Debug, Clone, Serialize)]
pub struct Timings {
    /// Decoding the images into the tile cache, or opening it.
    pub load_s: f64,
    /// Building the rig (0 for a baseline: it has none).
    pub rig_s: f64,
    /// Estimating.
    pub estimate_s: f64,
    /// Writing the outputs.
    pub write_s: f64,
    /// Everything.
    pub total_s: f64,
    /// Peak resident memory of the process in bytes (`VmHWM`; Linux only).
    pub peak_rss_bytes: Option<u64>,
}

/// A finished job's maps and report.
#[derive(Debug, Clone)]
pub struct Done {
    /// The maps written, when [`EstimateConfig::keep_maps`] asked for them (the report has
    /// the counts either way).
    pub maps: Option<EstimateMaps>,
    /// The report written.
    pub report: Report,
}

/// What an estimation job produced.
#[derive(Debug, Clone)]
pub enum EstimateOutcome {
    /// A full run: the maps and the report, written.
    Maps(Box<Done>),
    /// A shard: its tile results and manifest written, no maps; the shard's own report.
    Shard(Box<Report>),
}

/// The method built for a dataset: the estimator's rig, or a baseline with its lights.
enum Plan {
    Symmetry(Box<Rig>, EstimatorParams),
    Baseline(BaselineMethod),
}

impl Plan {
    /// Builds the rig (or the baseline's unit lights) before decoding, so a bad light file
    /// fails fast.
    fn new(method: &MethodConfig, ds: &Dataset) -> Result<Self> {
        let blame = || ds.source.display().to_string();
        Ok(match *method {
            MethodConfig::Symmetry { rig, params } => Plan::Symmetry(
                Box::new(Rig::new(&ds.lights, rig).with_context(blame)?),
                params,
            ),
            MethodConfig::Baseline { method, params } => {
                Plan::Baseline(BaselineMethod::new(method, &ds.lights, params).with_context(blame)?)
            }
        })
    }

    fn n_input(&self) -> usize {
        match self {
            Plan::Symmetry(rig, _) => rig.n_input(),
            Plan::Baseline(b) => b.unit_lights().len(),
        }
    }
}

/// Runs `method` over `tiles`: the one place the plan's two kinds meet the generic driver.
fn run_plan(
    plan: &Plan,
    cache: &TileCache,
    mask: Option<&[bool]>,
    job: u64,
    tiles: &[usize],
    dir: &Path,
    ctl: &Control,
) -> Result<crate::TileCounts> {
    match plan {
        Plan::Symmetry(rig, params) => run_tiles(
            cache,
            &Estimator::new(rig, *params),
            mask,
            job,
            tiles,
            dir,
            ctl,
        ),
        Plan::Baseline(b) => run_tiles(cache, b, mask, job, tiles, dir, ctl),
    }
}

/// Feeds a mask (or its absence) into a fingerprint.
pub(crate) fn fingerprint_mask(f: &mut Fingerprint, mask: Option<&[bool]>) {
    match mask {
        None => {
            f.u64(0);
        }
        Some(m) => {
            f.u64(1);
            for chunk in m.chunks(64) {
                let bits = chunk
                    .iter()
                    .enumerate()
                    .fold(0u64, |a, (k, &b)| a | ((b as u64) << k));
                f.u64(bits);
            }
        }
    }
}

/// Feeds light directions into a fingerprint.
pub(crate) fn fingerprint_lights<'a>(
    f: &mut Fingerprint,
    lights: impl IntoIterator<Item = &'a DVec3>,
) {
    for l in lights {
        f.f64(l.x).f64(l.y).f64(l.z);
    }
}

/// The fingerprint of everything a tile's results depend on: the cached inputs, the image and
/// tile sizes, the method with its lights and parameters, the mask and the versions.
fn job_fingerprint(cache: &TileCache, plan: &Plan, mask: Option<&[bool]>) -> Result<u64> {
    let g = cache.grid();
    let mut f = Fingerprint::new();
    f.str("symframe job")
        .str(env!("CARGO_PKG_VERSION"))
        .u64(symframe_io::tile_results::TILE_RESULT_VERSION as u64)
        .u64(cache.fingerprint())
        .u64(g.width as u64)
        .u64(g.height as u64)
        .u64(g.tile as u64);
    match plan {
        Plan::Symmetry(rig, params) => {
            let min_domain = Estimator::new(rig, *params).min_domain();
            f.str("symmetry")
                .f64(rig.theta_d_max_deg())
                // How the fast path reads the slice (results from an older lookup do not mix).
                .str("spherical-walk")
                .u64(rig.n_input() as u64)
                .str(&serde_json::to_string(params)?)
                .u64(min_domain as u64);
            for &i in rig.input_index() {
                f.u64(i as u64);
            }
            fingerprint_lights(&mut f, rig.lights_in_camera());
        }
        Plan::Baseline(b) => {
            f.str(b.method().name())
                .str(&serde_json::to_string(b.params())?);
            fingerprint_lights(&mut f, b.unit_lights());
        }
    }
    fingerprint_mask(&mut f, mask);
    Ok(f.finish())
}

/// Opens (or builds) the tile cache of `ds` in `dir`, reporting decoding progress and the
/// loader's warnings about the inputs. The dataset's fingerprints are computed first and given
/// to `check`, so a job can refuse its inputs before anything is decoded.
pub(crate) fn open_cache(
    ds: &Dataset,
    decode: &DecodeOptions,
    dir: &Path,
    options: CacheOptions,
    ctl: &Control,
    check: &dyn Fn(&Fingerprints) -> Result<()>,
) -> Result<(TileCache, CacheInfo, Fingerprints)> {
    // Image sizes are compared from the headers first (`dataset_fingerprints`): one of another
    // size fails before any is read whole.
    let fps = symframe_io::dataset_fingerprints(ds, decode, options.trust_mtime, options.format)?;
    check(&fps)?;
    let decoded = AtomicU64::new(0);
    let total = ds.images.len() as u64;
    let (cache, info) =
        TileCache::open_or_build_with(ds, decode, dir, options, Some(fps), ctl.stop, &|| {
            let n = decoded.fetch_add(1, Ordering::SeqCst) + 1;
            ctl.report(Progress::new(Stage::Decoding, n, total));
        })
        .map_err(|e| match e {
            symframe_io::Error::Interrupted => anyhow::Error::from(Interrupted),
            e => e.into(),
        })?;
    for w in &info.warnings {
        ctl.warn(&w.to_string());
    }
    Ok((cache, info, fps))
}

/// Reads the mask of a job (`mask`, else the dataset's) at the cache's image size.
pub(crate) fn read_mask(
    mask: &Option<PathBuf>,
    ds: &Dataset,
    grid: &TileGrid,
) -> Result<(Option<PathBuf>, Option<Vec<bool>>)> {
    let path = mask.clone().or_else(|| ds.mask.clone());
    let mask = match &path {
        Some(p) => Some(symframe_io::read_mask(p, grid.width, grid.height)?),
        None => None,
    };
    Ok((path, mask))
}

/// Removes the cache file of a finished job (and its folder, when nothing else is left in it).
pub(crate) fn remove_cache(cache_path: &Path, dir: &Path) -> Result<()> {
    std::fs::remove_file(cache_path)
        .with_context(|| format!("{}: cannot remove", cache_path.display()))?;
    let _ = std::fs::remove_file(cache_path.with_extension("lock"));
    let _ = std::fs::remove_dir(dir);
    Ok(())
}

/// Runs an estimation job: decodes the images once into the tile cache (or reuses it),
/// estimates tile by tile into result files, then writes the maps from them a row of tiles at
/// a time (or, for a shard, its manifest). The output folder is locked for the whole job (a second job into it
/// is refused). On an error the finished tiles and the cache are kept, so the same call
/// resumes; only what this job created and holds nothing to resume from is removed again.
pub fn estimate(config: &EstimateConfig, ctl: &Control) -> Result<EstimateOutcome> {
    let out = OutputDir::lock(&config.output)?;
    (ctl.checkpoint)(Checkpoint::OutputLocked);
    let warnings = Mutex::new(Vec::new());
    let warn = |line: &str| {
        lock_warnings(&warnings).push(line.to_string());
        ctl.warn(line);
    };
    let counted = Control {
        stop: ctl.stop,
        progress: ctl.progress,
        stop_after_tiles: ctl.stop_after_tiles,
        warning: &warn,
        checkpoint: ctl.checkpoint,
    };
    for w in out.warnings() {
        warn(w);
    }
    let result = run(config, &counted, &out, &warnings);
    if let Err(e) = &result {
        if !e.is::<Interrupted>() {
            out.discard_unfinished();
        }
    }
    result
}

/// The warnings collected so far (a poisoned lock still holds them).
pub(crate) fn lock_warnings(w: &Mutex<Vec<String>>) -> std::sync::MutexGuard<'_, Vec<String>> {
    w.lock().unwrap_or_else(|e| e.into_inner())
}

/// The near-light geometry the job uses: the dataset's positions and camera unless the
/// distant model is asked for; an error where the near model is asked for and the dataset has
/// none, or a shard of a near-light job is (its rounds need every tile's normals).
fn near_geometry(
    config: &EstimateConfig,
    ds: &Dataset,
    ctl: &Control,
) -> Result<Option<symframe_io::NearGeometry>> {
    if config.near.model == LightModel::Distant {
        return Ok(None);
    }
    let geometry = symframe_io::open_near_geometry(ds)?;
    let Some(g) = geometry else {
        if config.near.model == LightModel::Near {
            anyhow::bail!(
                "{}: near lights need light_positions.txt and K.txt beside the dataset",
                ds.source.display()
            );
        }
        return Ok(None);
    };
    if !matches!(config.method, MethodConfig::Symmetry { .. }) {
        ctl.warn(&format!(
            "{}: the baselines take the lights as distant (the directions of the light file); \
             its light positions are not used",
            ds.source.display()
        ));
        return Ok(None);
    }
    if config.shard.is_some() {
        anyhow::bail!(
            "near lights are estimated in rounds over the whole image: run them as one job \
             (no --tiles K/N), or --light-model distant"
        );
    }
    for w in &g.warnings {
        ctl.warn(&w.to_string());
    }
    Ok(Some(g))
}

fn run(
    config: &EstimateConfig,
    ctl: &Control,
    out: &OutputDir,
    warnings: &Mutex<Vec<String>>,
) -> Result<EstimateOutcome> {
    let t0 = Instant::now();
    let mut ds: Dataset = symframe_io::open_dataset(&config.input)?;
    for w in &ds.warnings {
        ctl.warn(&w.to_string());
    }
    let geometry = near_geometry(config, &ds, ctl)?;
    // The mask in force is checked with the cache, before the images are decoded.
    ds.mask = config.mask.clone().or(ds.mask);
    out.guard_inputs(
        dataset_files(&ds),
        "report.json",
        &|n| ESTIMATE_FILES.contains(&n) || n == MANIFEST,
        &|_| false,
    )?;
    let mut plan = Plan::new(&config.method, &ds)?;
    if let Plan::Symmetry(_, params) = &mut plan {
        // The capture's noise model, unless the caller gave one: its clip level censors the
        // clipped samples (docs/method.md, "Noise model"); report.json records it.
        // The lights' uncertainty is the caller's (`--light-error`): the images cannot tell it.
        let light_error_deg = params.noise.light_error_deg;
        let told = symframe::NoiseModel {
            light_error_deg: 0.0,
            ..params.noise
        };
        if told == symframe::NoiseModel::default() {
            params.noise = symframe::NoiseModel {
                light_error_deg,
                ..symframe_io::capture_noise(&ds, &config.decode)?
            };
        }
    }
    let rig_s = t0.elapsed().as_secs_f64();

    let t_load = Instant::now();
    let cache_dir = config.cache_dir();
    let (cache, cache_info, fps) = open_cache(
        &ds,
        &config.decode,
        &cache_dir,
        config.cache.options,
        ctl,
        &|_| Ok(()),
    )?;
    let load_s = t_load.elapsed().as_secs_f64();
    let grid = *cache.grid();
    let (mask_path, mask) = read_mask(&config.mask, &ds, &grid)?;
    let blame = || match &mask_path {
        Some(p) => p.display().to_string(),
        None => ds.source.display().to_string(),
    };
    check_inputs(
        grid.width,
        grid.height,
        cache.n_lights(),
        plan.n_input(),
        mask.as_deref(),
    )
    .with_context(blame)?;
    let job = job_fingerprint(&cache, &plan, mask.as_deref())?;
    let tiles_dir = config.output.join(TILES_DIR);
    if let Some(s) = config.shard.filter(|s| s.n > grid.n_tiles()) {
        anyhow::bail!(
            "--tiles {}/{}: the image has {} tiles of {} px, so at most {} shards (or a smaller \
             --tile-size)",
            s.k,
            s.n,
            grid.n_tiles(),
            grid.tile,
            grid.n_tiles()
        );
    }
    let my_tiles = match config.shard {
        Some(s) => shard_tiles(grid.n_tiles(), s.k, s.n),
        None => (0..grid.n_tiles()).collect(),
    };
    if config.shard.is_some() {
        // The manifest says "complete": an earlier one goes until this shard is.
        let m = config.output.join(MANIFEST);
        if m.exists() {
            std::fs::remove_file(&m).with_context(|| format!("{}: cannot remove", m.display()))?;
        }
    }
    let t_est = Instant::now();
    let (counts, job, near) = match (&geometry, &plan) {
        (Some(g), Plan::Symmetry(rig, params)) => {
            let rig_options = RigOptions {
                theta_d_max_deg: rig.theta_d_max_deg(),
            };
            let run = run_near_rounds(
                &cache,
                g,
                &config.near,
                rig_options,
                *params,
                mask.as_deref(),
                job,
                &my_tiles,
                &tiles_dir,
                ctl,
            )?;
            (run.counts, run.job, Some((run.report, run.depth)))
        }
        _ => {
            let counts = run_plan(
                &plan,
                &cache,
                mask.as_deref(),
                job,
                &my_tiles,
                &tiles_dir,
                ctl,
            )?;
            (counts, job, None)
        }
    };
    let estimate_s = t_est.elapsed().as_secs_f64();
    let cache_path = cache.path().to_path_buf();
    drop(cache);

    let (decode, method) = (&config.decode, &config.method);
    let (parameters, lights) = match &plan {
        Plan::Symmetry(rig, params) => (
            MethodParameters::Symmetry(SymmetryParameters {
                theta_d_max_deg: rig.theta_d_max_deg(),
                estimator: *params,
                min_domain_used: Estimator::new(rig, *params).min_domain(),
                linear_8bit: !decode.gamma.srgb(8),
                gamma: decode.gamma,
                saturation: decode.saturation,
                exr_layer: decode.exr_layer.clone(),
            }),
            LightCounts {
                input: rig.n_input(),
                used: rig.n_used(),
                dropped: rig.n_dropped(),
            },
        ),
        Plan::Baseline(b) => (
            MethodParameters::Baseline(BaselineParameters {
                baseline: *b.params(),
                linear_8bit: !decode.gamma.srgb(8),
                gamma: decode.gamma,
                saturation: decode.saturation,
                exr_layer: decode.exr_layer.clone(),
            }),
            LightCounts {
                input: b.unit_lights().len(),
                used: b.unit_lights().len(),
                dropped: 0,
            },
        ),
    };
    let mut report = Report {
        version: env!("CARGO_PKG_VERSION"),
        input: config.input.clone(),
        inputs: InputsRecord::of(&fps),
        mask: mask_path,
        method: method.name(),
        parameters,
        lights,
        width: grid.width,
        height: grid.height,
        pixels: PixelCounts::default(),
        sources: Sources(Vec::new()),
        evals_per_pixel: 0.0,
        tiles: TileReport {
            size: grid.tile,
            count: grid.n_tiles(),
            shard: config.shard.map(|s| s.to_string()),
            this_run: my_tiles.len(),
            computed: counts.computed,
            reused: counts.reused,
        },
        cache: CacheReport {
            info: cache_info,
            kept: !config.cache.remove_after,
        },
        timings: Timings {
            load_s,
            rig_s,
            estimate_s,
            write_s: 0.0,
            total_s: 0.0,
            peak_rss_bytes: None,
        },
        warnings: Vec::new(),
        near: near.as_ref().map(|(r, _)| r.clone()),
    };

    if let Some(shard) = config.shard {
        // Shard: the tile results stay; a manifest says they are complete. Its report counts
        // the shard's pixels.
        let mut pixels = PixelCounts::default();
        let mut evals = 0u64;
        let mut source = Vec::new();
        for &t in &my_tiles {
            let path = tile_path(&tiles_dir, t);
            for r in symframe_io::read_tile_result(&path, job, t, grid.tile_pixels(t))? {
                pixels.add(r.status, r.has_tangent());
                evals += r.evals as u64;
                source.push(r.source as u8);
            }
        }
        report.pixels = pixels;
        report.sources = Sources::of(&source);
        report.evals_per_pixel = evals as f64 / pixels.estimated.max(1) as f64;
        report.timings.total_s = t0.elapsed().as_secs_f64();
        report.timings.peak_rss_bytes = peak_rss_bytes();
        report.warnings = lock_warnings(warnings).clone();
        let manifest = ShardManifest {
            format: MANIFEST_FORMAT.into(),
            version: MANIFEST_VERSION,
            job: format!("{job:016x}"),
            shard: shard.k,
            of: shard.n,
            width: grid.width,
            height: grid.height,
            tile_size: grid.tile,
            n_tiles: grid.n_tiles(),
            tiles: my_tiles,
            report: serde_json::to_value(&report)?,
        };
        write_manifest(&config.output, &manifest)?;
        if config.cache.remove_after {
            remove_cache(&cache_path, &cache_dir)?;
        }
        return Ok(EstimateOutcome::Shard(Box::new(report)));
    }

    let path_of = |t| tile_path(&tiles_dir, t);
    let covered = |n: DVec3| match &plan {
        Plan::Symmetry(rig, _) => rig.covered(n),
        Plan::Baseline(_) => true,
    };
    // The rig for `lights.png`: every input light, used or dropped.
    let used: Vec<bool> = match &plan {
        Plan::Symmetry(rig, _) => {
            let mut used = vec![false; ds.lights.len()];
            for &i in rig.input_index() {
                used[i] = true;
            }
            used
        }
        Plan::Baseline(_) => vec![true; ds.lights.len()],
    };
    let lights_plot = LightsPlot {
        lights: &ds.lights,
        used: &used,
        theta_d_max_deg: match &plan {
            Plan::Symmetry(rig, _) => Some(rig.theta_d_max_deg()),
            Plan::Baseline(_) => None,
        },
    };
    let opts = WriteOptions {
        normal_png: config.normal_png,
        keep_maps: config.keep_maps,
        // Near lights: each tile has its own rig, so the distant rig's reach says nothing.
        covered: (matches!(plan, Plan::Symmetry(..)) && near.is_none())
            .then_some(&covered as &(dyn Fn(DVec3) -> bool + Sync)),
        on_tiles: &|_| {},
        lights: Some(&lights_plot),
    };
    let tiles = TileResults {
        grid,
        job,
        path_of: &path_of,
    };
    let (_, maps) = write_estimate_outputs(out, &tiles, &opts, ctl, |write_s, summary| {
        report.pixels = summary.counts;
        report.sources = summary.sources.clone();
        report.evals_per_pixel = summary.evals as f64 / summary.counts.estimated.max(1) as f64;
        for w in result_warnings(&report.pixels, summary.beyond_reach, summary.light_axes) {
            ctl.warn(&w);
        }
        report.warnings = lock_warnings(warnings).clone();
        report.timings.write_s = write_s;
        report.timings.total_s = t0.elapsed().as_secs_f64();
        report.timings.peak_rss_bytes = peak_rss_bytes();
        Ok(serde_json::to_value(&report)?)
    })?;
    if let Some((_, depth)) = &near {
        symframe_io::write_npy_f32(
            &config.output.join("depth.npy"),
            &[grid.height, grid.width],
            depth,
        )?;
    }
    crate::tiles::remove_tile_folder(&tiles_dir)?;
    if config.cache.remove_after {
        remove_cache(&cache_path, &cache_dir)?;
    }
    Ok(EstimateOutcome::Maps(Box::new(Done { maps, report })))
}

/// The files of an estimate's output set (`write_estimate_outputs`), the report last.
pub(crate) const ESTIMATE_FILES: [&str; 22] = [
    "normals.npy",
    "tangents.npy",
    "confidence.npy",
    "anisotropy.npy",
    "tangent_confidence.npy",
    "residual.npy",
    "source.npy",
    "normals.exr",
    "tangents.exr",
    "normals.png",
    "tangents.png",
    "confidence.png",
    "source.png",
    "residual.png",
    "tangents_gltf.png",
    "lights.png",
    "confidence_legend.png",
    "source_legend.png",
    "tangents_legend.png",
    "residual_legend.png",
    "index.html",
    "report.json",
];

/// Every file a dataset reads: its light file (or folder), images and mask.
pub(crate) fn dataset_files(ds: &Dataset) -> impl Iterator<Item = &Path> {
    std::iter::once(ds.source.as_path())
        .chain(ds.images.iter().map(PathBuf::as_path))
        .chain(ds.mask.iter().map(PathBuf::as_path))
}
