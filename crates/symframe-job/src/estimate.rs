//! The estimation job: a capture in, normal/tangent maps, pictures and a report out (or, for a
//! shard, its tile results and manifest).

mod cache;
mod report;

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{Context, Result};
use glam::DVec3;
use symframe::{
    Baseline, BaselineMethod, BaselineParams, Estimator, EstimatorParams, PixelCounts, Rig,
    RigOptions, Stack,
};
use symframe_io::fingerprint::Fingerprint;
use symframe_io::{Dataset, DecodeOptions, NormalPng, TileCache, TileGrid};

pub(crate) use cache::{
    cache_dir, fingerprint_lights, fingerprint_mask, open_cache, read_mask, remove_cache,
};
pub use cache::{CacheConfig, CACHE_DIR};
pub use report::{
    BaselineParameters, CacheReport, EstimateOutcome, FinishedEstimate, InputsRecord, LightCounts,
    MethodParameters, Report, SymmetryParameters, TileReport, Timings,
};

use crate::estimate_near::{run_near_rounds, LightModel, NearOptions, NearReport};
use crate::maps_out::{
    result_warnings, write_estimate_outputs, Sources, TileResults, WriteOptions,
};
use crate::merge::{write_manifest, ShardManifest, MANIFEST, MANIFEST_FORMAT, MANIFEST_VERSION};
use crate::outdir::{in_locked_output, lock_warnings, OutputDir};
use crate::pictures::LightsPlot;
use crate::tiles::{peak_rss_bytes, run_tiles, shard_tiles, tile_path, TILES_DIR};
use crate::Control;

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
    /// Return the whole maps in memory ([`FinishedEstimate::maps`]) as well as writing them
    /// (42 bytes per pixel); off, the outputs are written a band of tiles at a time and memory
    /// stays bounded whatever the image size (the CLI).
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

    /// Gives the estimator the capture's noise model, unless the caller gave one: its clip
    /// level censors the clipped samples (docs/method.md, "Noise model"); report.json records
    /// it. The lights' uncertainty is the caller's (`--light-error`): the images cannot tell it.
    fn take_capture_noise(
        &mut self,
        ds: &Dataset,
        decode: &DecodeOptions,
        ctl: &Control,
    ) -> Result<()> {
        if let Plan::Symmetry(_, params) = self {
            let light_error_deg = params.noise.light_error_deg;
            let told = symframe::NoiseModel {
                light_error_deg: 0.0,
                ..params.noise
            };
            if told == symframe::NoiseModel::default() {
                params.noise = symframe::NoiseModel {
                    light_error_deg,
                    ..symframe_io::capture_noise(ds, decode)?
                };
                if let (symframe::Quantisation::Float, Some(c)) =
                    (params.noise.quantisation, params.noise.clip_level)
                {
                    ctl.warn(&format!(
                        "the float images clip: samples pile up at {c} (docs/method.md, \
                         \"Noise model\"); samples at that level are taken as censored, known \
                         only to be at least that bright"
                    ));
                }
            }
        }
        Ok(())
    }

    /// What `report.json` records of the method: its parameters (with the decoding's) and the
    /// lights it used.
    fn record(&self, decode: &DecodeOptions) -> (MethodParameters, LightCounts) {
        match self {
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
        }
    }

    /// Which of the dataset's `n` lights the method uses: the rig's (the others are outside
    /// its cone), or every one for a baseline.
    fn used_lights(&self, n: usize) -> Vec<bool> {
        match self {
            Plan::Symmetry(rig, _) => {
                let mut used = vec![false; n];
                for &i in rig.input_index() {
                    used[i] = true;
                }
                used
            }
            Plan::Baseline(_) => vec![true; n],
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

/// Runs an estimation job: decodes the images once into the tile cache (or reuses it),
/// estimates tile by tile into result files, then writes the maps from them a row of tiles at
/// a time (or, for a shard, its manifest). The output folder is locked for the whole job (a second job into it
/// is refused). On an error the finished tiles and the cache are kept, so the same call
/// resumes; only what this job created and holds nothing to resume from is removed again.
pub fn estimate(config: &EstimateConfig, ctl: &Control) -> Result<EstimateOutcome> {
    in_locked_output(&config.output, ctl, |ctl, out, warnings| {
        run(config, ctl, out, warnings)
    })
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
    plan.take_capture_noise(&ds, &config.decode, ctl)?;
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
    let load_peak_rss_bytes = peak_rss_bytes();
    let grid = *cache.grid();
    let (mask_path, mask) = read_mask(&config.mask, &ds, &grid)?;
    let blame = || match &mask_path {
        Some(p) => p.display().to_string(),
        None => ds.source.display().to_string(),
    };
    Stack::check_inputs(
        grid.width,
        grid.height,
        cache.n_lights(),
        plan.n_input(),
        mask.as_deref(),
    )
    .with_context(blame)?;
    let job = job_fingerprint(&cache, &plan, mask.as_deref())?;
    let tiles_dir = config.output.join(TILES_DIR);
    let my_tiles = tiles_of_run(config, &grid)?;
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

    let (parameters, lights) = plan.record(&config.decode);
    let mut report = Report {
        version: env!("CARGO_PKG_VERSION"),
        input: config.input.clone(),
        inputs: InputsRecord::of(&fps),
        mask: mask_path,
        method: config.method.name(),
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
            load_peak_rss_bytes,
        },
        warnings: Vec::new(),
        near: near.as_ref().map(|(r, _)| r.clone()),
    };

    if let Some(shard) = config.shard {
        // Shard: the tile results stay; a manifest says they are complete. Its report counts
        // the shard's pixels.
        (report.pixels, report.sources, report.evals_per_pixel) =
            shard_summary(&tiles_dir, job, &grid, &my_tiles)?;
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
    let used = plan.used_lights(ds.lights.len());
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
    Ok(EstimateOutcome::Maps(Box::new(FinishedEstimate {
        maps,
        report,
    })))
}

/// The tiles this run estimates: a shard's share (an error where there are fewer tiles than
/// shards), else every tile. A shard's earlier manifest is removed first: a manifest says its
/// tiles are complete.
fn tiles_of_run(config: &EstimateConfig, grid: &TileGrid) -> Result<Vec<usize>> {
    let Some(s) = config.shard else {
        return Ok((0..grid.n_tiles()).collect());
    };
    if s.n > grid.n_tiles() {
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
    let tiles = shard_tiles(grid.n_tiles(), s.k, s.n);
    let m = config.output.join(MANIFEST);
    if m.exists() {
        std::fs::remove_file(&m).with_context(|| format!("{}: cannot remove", m.display()))?;
    }
    Ok(tiles)
}

/// A shard's pixel counts, sources and evaluations per estimated pixel, from its tile results.
fn shard_summary(
    tiles_dir: &Path,
    job: u64,
    grid: &TileGrid,
    tiles: &[usize],
) -> Result<(PixelCounts, Sources, f64)> {
    let mut pixels = PixelCounts::default();
    let mut evals = 0u64;
    let mut source = Vec::new();
    for &t in tiles {
        let path = tile_path(tiles_dir, t);
        for r in symframe_io::read_tile_result(&path, job, t, grid.tile_pixels(t))? {
            pixels.add(r.status, r.has_tangent());
            evals += r.evals as u64;
            source.push(r.source as u8);
        }
    }
    let per_pixel = evals as f64 / pixels.estimated.max(1) as f64;
    Ok((pixels, Sources::of(&source), per_pixel))
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
