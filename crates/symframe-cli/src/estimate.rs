//! `symframe estimate`: a capture folder in, normal/tangent maps, pictures and a report out.
//!
//! The images are decoded once into an on-disk tile cache and estimated tile by tile (see
//! [`crate::tiled`]), so memory stays bounded whatever the stack's size, an interrupted run
//! resumes, and `--tiles K/N` splits the work into shards. The results equal those of the
//! in-memory pipeline ([`symframe::estimate_stack`]) bit for bit.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::baseline::{baseline_lights, Baseline, BaselineParams};
use symframe::estimate::PixelCounts;
use symframe::symmetry::CosineMode;
use symframe::{EstimateMaps, EstimatorParams, Interpolation, Rig, RigOptions};
use symframe_io::{CacheInfo, CacheOptions, Dataset, DecodeOptions, TileCache};

use crate::cli::{CosineArg, EstimateArgs, MethodArg};
use crate::outdir::Staging;
use crate::progress;
use crate::tiled::{self, Interrupted};

/// What `report.json` records about a run.
#[derive(Debug, Serialize)]
pub struct Report {
    /// symframe version.
    pub version: &'static str,
    /// The input as given.
    pub input: PathBuf,
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
    /// Mean symmetry-objective evaluations per estimated pixel.
    pub evals_per_pixel: f64,
    /// How the image was split into tiles and what this run did with them.
    pub tiles: TileReport,
    /// The on-disk tile cache of the decoded images.
    pub cache: CacheReport,
    /// Wall-clock seconds per stage, and peak memory.
    pub timings: Timings,
}

/// Tiles as recorded in the report.
#[derive(Debug, Serialize)]
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
#[derive(Debug, Serialize)]
pub struct CacheReport {
    /// Where it is, its size, whether it was reused (`hit`), what was decoded.
    #[serde(flatten)]
    pub info: CacheInfo,
    /// Whether it is kept after the run (`--no-keep-cache` removes it).
    pub kept: bool,
}

/// The parameters of whichever method ran, as recorded in the report.
#[derive(Debug, Serialize)]
#[serde(untagged)]
pub enum MethodParameters {
    /// The symmetry method's.
    Symmetry(Parameters),
    /// A baseline's.
    Baseline(BaselineParameters),
}

/// Baseline parameters as recorded in the report.
#[derive(Debug, Serialize)]
pub struct BaselineParameters {
    /// Shadow threshold, outlier rule.
    #[serde(flatten)]
    pub baseline: BaselineParams,
    /// 8-bit inputs read as linear.
    pub linear_8bit: bool,
    /// Saturation threshold (fraction of the integer maximum).
    pub saturation: f32,
}

/// Symmetry-method parameters as recorded in the report.
#[derive(Debug, Serialize)]
pub struct Parameters {
    /// Light cone half-angle in halfway space, degrees.
    pub theta_d_max_deg: f64,
    /// Estimator parameters.
    #[serde(flatten)]
    pub estimator: EstimatorParams,
    /// The domain threshold actually used.
    pub min_domain_used: u32,
    /// 8-bit inputs read as linear.
    pub linear_8bit: bool,
    /// Saturation threshold (fraction of the integer maximum).
    pub saturation: f32,
}

/// Light counts.
#[derive(Debug, Serialize)]
pub struct LightCounts {
    /// Lights in the input.
    pub input: usize,
    /// Lights used: inside the cone for the symmetry method, all of them for a baseline.
    pub used: usize,
    /// Lights outside the cone, dropped (0 for a baseline).
    pub dropped: usize,
}

/// Seconds per stage.
#[derive(Debug, Serialize)]
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

/// Checks the flags that clap cannot.
fn validate(args: &EstimateArgs) -> Result<()> {
    if !(args.theta_d_max > 0.0 && args.theta_d_max <= 90.0) {
        bail!(
            "--theta-d-max must be in (0, 90] degrees, got {}",
            args.theta_d_max
        );
    }
    if !(0.0..=1.0).contains(&args.min_confidence) {
        bail!(
            "--min-confidence must be in [0, 1], got {}",
            args.min_confidence
        );
    }
    if !(0.0..=1.0).contains(&args.min_anisotropy) {
        bail!(
            "--min-anisotropy must be in [0, 1], got {}",
            args.min_anisotropy
        );
    }
    if !(args.saturation > 0.0 && args.saturation <= 1.0) {
        bail!("--saturation must be in (0, 1], got {}", args.saturation);
    }
    if !(0.0..=1.0).contains(&args.cosine_power) {
        bail!(
            "--cosine-power must be in [0, 1], got {}",
            args.cosine_power
        );
    }
    if args.min_domain == Some(0) {
        bail!("--min-domain must be at least 1");
    }
    if !(1..=4096).contains(&args.tile_size) {
        bail!("--tile-size must be in [1, 4096], got {}", args.tile_size);
    }
    if args.decode_memory == 0 {
        bail!("--decode-memory must be at least 1 MiB");
    }
    Ok(())
}

/// What the estimation stage runs.
enum Plan {
    /// The symmetry method on this rig.
    Symmetry(Box<Rig>),
    /// A baseline, on every light (unit directions).
    Baseline(Baseline, Vec<glam::DVec3>),
}

/// What a run produced.
#[derive(Debug)]
pub enum Done {
    /// A full run: the maps and the report written.
    Maps(Box<(EstimateMaps, Report)>),
    /// A shard (`--tiles K/N`): tile results and a manifest, no maps.
    Shard,
}

/// Runs the command. On an error (not an interruption) an output folder this run created is
/// removed again, so a failed run leaves nothing behind; an interrupted run keeps its cache and
/// finished tiles for the rerun.
pub fn run(args: &EstimateArgs) -> Result<Done> {
    validate(args)?;
    let created = !args.output.exists();
    let result = run_tiled(args);
    if let Err(e) = &result {
        if created && !e.is::<Interrupted>() {
            let _ = std::fs::remove_dir_all(&args.output);
        }
    }
    result
}

/// The estimator parameters the flags ask for.
fn estimator_params(args: &EstimateArgs) -> EstimatorParams {
    EstimatorParams {
        cosine: match args.cosine {
            CosineArg::Cross => CosineMode::CrossMultiplied,
            CosineArg::Raw => CosineMode::Raw,
            CosineArg::Compensated => CosineMode::Compensated(args.cosine_power),
        },
        min_domain: args.min_domain,
        min_confidence: args.min_confidence,
        min_anisotropy: args.min_anisotropy,
        tangents: !args.no_tangents,
        interpolation: if args.reference {
            Interpolation::Exact
        } else {
            Interpolation::Fast
        },
        ..EstimatorParams::default()
    }
}

/// Decodes the images once into the tile cache (or reuses it), estimates tile by tile into
/// result files, then assembles and writes the maps (or, for a shard, its manifest).
fn run_tiled(args: &EstimateArgs) -> Result<Done> {
    let t0 = Instant::now();
    let ds: Dataset = symframe_io::open_dataset(&args.input)?;
    if let Ok(symframe_io::LpPaths::Windows) = symframe_io::lp_path_convention(&ds.source) {
        eprintln!(
            "symframe estimate: {}: {}",
            ds.source.display(),
            symframe_io::LpPaths::Windows
        );
    }
    // The rig (or the baseline's unit lights) before decoding, so a bad light file fails fast.
    let plan = match args.method {
        MethodArg::Symmetry => Plan::Symmetry(Box::new(
            Rig::new(
                &ds.lights,
                RigOptions {
                    theta_d_max_deg: args.theta_d_max,
                },
            )
            .with_context(|| ds.source.display().to_string())?,
        )),
        m => Plan::Baseline(
            match m {
                MethodArg::Woodham => Baseline::Woodham,
                MethodArg::WoodhamRobust => Baseline::WoodhamRobust,
                _ => Baseline::MaxReflectance,
            },
            baseline_lights(&ds.lights).with_context(|| ds.source.display().to_string())?,
        ),
    };
    let rig_s = t0.elapsed().as_secs_f64();
    tiled::install_interrupt_handler();

    let t_load = Instant::now();
    let opts = DecodeOptions {
        linear_8bit: args.linear,
        saturation: args.saturation,
    };
    let cache_dir = args
        .cache
        .clone()
        .unwrap_or_else(|| args.output.join(tiled::CACHE_DIR));
    let bar = progress::bar(ds.images.len() as u64, "decoding");
    let (cache, cache_info) = TileCache::open_or_build(
        &ds,
        &opts,
        &cache_dir,
        CacheOptions {
            tile: args.tile_size,
            batch_bytes: args.decode_memory << 20,
        },
        &tiled::STOP,
        &|| bar.inc(1),
    )
    .map_err(tiled::io_err)?;
    bar.finish_and_clear();
    let load_s = t_load.elapsed().as_secs_f64();
    let grid = *cache.grid();

    let mask_path = args.mask.clone().or_else(|| ds.mask.clone());
    let mask = match &mask_path {
        Some(p) => Some(symframe_io::read_mask(p, grid.width, grid.height)?),
        None => None,
    };
    let blame = || match &mask_path {
        Some(p) => p.display().to_string(),
        None => ds.source.display().to_string(),
    };
    let params = estimator_params(args);
    let baseline_params = BaselineParams::default();
    let method = match &plan {
        Plan::Symmetry(rig) => tiled::Method::Symmetry { rig, params },
        Plan::Baseline(b, lights) => {
            baseline_params.validate()?;
            tiled::Method::Baseline {
                method: *b,
                lights,
                params: baseline_params,
            }
        }
    };
    let n_expected = match &plan {
        Plan::Symmetry(rig) => rig.n_input,
        Plan::Baseline(_, lights) => lights.len(),
    };
    symframe::estimate::check_inputs(
        grid.width,
        grid.height,
        cache.n_lights(),
        n_expected,
        mask.as_deref(),
    )
    .with_context(blame)?;
    let job = tiled::job_fingerprint(&cache, &method, mask.as_deref())?;
    let tiles_dir = args.output.join(tiled::TILES_DIR);
    let my_tiles = match args.tiles {
        Some(s) => tiled::shard_tiles(grid.n_tiles(), s.k, s.n),
        None => (0..grid.n_tiles()).collect(),
    };
    if args.tiles.is_some() {
        // The manifest says "complete": an earlier one goes until this shard is.
        let m = args.output.join(tiled::MANIFEST);
        if m.exists() {
            std::fs::remove_file(&m).with_context(|| format!("{}: cannot remove", m.display()))?;
        }
    }
    let t_est = Instant::now();
    let counts = tiled::estimate_tiles(
        &cache,
        &method,
        mask.as_deref(),
        job,
        &my_tiles,
        &tiles_dir,
        args.stop_after_tiles,
    )?;
    let estimate_s = t_est.elapsed().as_secs_f64();
    let cache_path = cache.path().to_path_buf();
    drop(cache);

    let (parameters, lights) = match &plan {
        Plan::Symmetry(rig) => (
            MethodParameters::Symmetry(Parameters {
                theta_d_max_deg: args.theta_d_max,
                estimator: params,
                min_domain_used: symframe::Estimator::new(rig, params).min_domain(),
                linear_8bit: args.linear,
                saturation: args.saturation,
            }),
            LightCounts {
                input: rig.n_input,
                used: rig.n_used(),
                dropped: rig.n_dropped(),
            },
        ),
        Plan::Baseline(_, l) => (
            MethodParameters::Baseline(BaselineParameters {
                baseline: baseline_params,
                linear_8bit: args.linear,
                saturation: args.saturation,
            }),
            LightCounts {
                input: l.len(),
                used: l.len(),
                dropped: 0,
            },
        ),
    };
    let mut report = Report {
        version: env!("CARGO_PKG_VERSION"),
        input: args.input.clone(),
        mask: mask_path,
        method: match &plan {
            Plan::Symmetry(_) => "symmetry",
            Plan::Baseline(b, _) => b.name(),
        },
        parameters,
        lights,
        width: grid.width,
        height: grid.height,
        pixels: PixelCounts::default(),
        evals_per_pixel: 0.0,
        tiles: TileReport {
            size: grid.tile,
            count: grid.n_tiles(),
            shard: args.tiles.map(|s| s.to_string()),
            this_run: my_tiles.len(),
            computed: counts.computed,
            reused: counts.reused,
        },
        cache: CacheReport {
            info: cache_info,
            kept: !args.no_keep_cache,
        },
        timings: Timings {
            load_s,
            rig_s,
            estimate_s,
            write_s: 0.0,
            total_s: 0.0,
            peak_rss_bytes: None,
        },
    };
    let remove_cache = || -> Result<()> {
        if args.no_keep_cache {
            std::fs::remove_file(&cache_path)
                .with_context(|| format!("{}: cannot remove", cache_path.display()))?;
            // The folder too, when nothing else (another dataset's cache) is left in it.
            let lock = cache_path.with_extension("lock");
            let _ = std::fs::remove_file(lock);
            let _ = std::fs::remove_dir(&cache_dir);
        }
        Ok(())
    };

    if let Some(shard) = args.tiles {
        // Shard: the tile results stay; a manifest says they are complete. Its report counts
        // the shard's pixels.
        let (pixels, evals) = tiled::count_tiles(&grid, job, &tiles_dir, &my_tiles)?;
        report.pixels = pixels;
        report.evals_per_pixel = evals as f64 / pixels.estimated.max(1) as f64;
        report.timings.total_s = t0.elapsed().as_secs_f64();
        report.timings.peak_rss_bytes = tiled::peak_rss_bytes();
        let manifest = tiled::ShardManifest {
            format: "symframe-shard".into(),
            version: 1,
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
        tiled::write_manifest(&args.output, &manifest)?;
        remove_cache()?;
        if progress::interactive() {
            eprintln!(
                "symframe: shard {shard} done: {} tiles ({} computed now) in {}; combine the \
                 shards with `symframe merge`",
                manifest.tiles.len(),
                counts.computed,
                args.output.display()
            );
        }
        return Ok(Done::Shard);
    }

    let maps = tiled::assemble(&grid, job, |t| symframe_io::tile_result_path(&tiles_dir, t))?;
    report.pixels = maps.counts;
    report.evals_per_pixel = maps.evals as f64 / maps.counts.estimated.max(1) as f64;
    write_outputs(&args.output, &maps, &mut report, t0, args.normal_png.into())?;
    std::fs::remove_dir_all(&tiles_dir)
        .with_context(|| format!("{}: cannot remove", tiles_dir.display()))?;
    remove_cache()?;
    if progress::interactive() {
        let c = &maps.counts;
        eprintln!(
            "symframe ({}): {} pixels estimated ({} with a tangent), {} discarded, {} culled, {} without data; \
             {} of {} lights used; {:.1} s",
            report.method,
            c.estimated,
            c.with_tangent,
            c.discarded,
            c.culled,
            c.no_data,
            report.lights.used,
            report.lights.input,
            report.timings.total_s
        );
    }
    Ok(Done::Maps(Box::new((maps, report))))
}

/// Writes every output file into a staging folder, then moves them into `out` together.
/// The report's write and total timings and the peak memory are filled in just before it is
/// written.
pub fn write_outputs(
    out: &Path,
    maps: &EstimateMaps,
    report: &mut Report,
    t0: Instant,
    normal_png: symframe_io::NormalPng,
) -> Result<()> {
    write_maps_with(out, maps, normal_png, |write_s| {
        report.timings.write_s = write_s;
        report.timings.total_s = t0.elapsed().as_secs_f64();
        report.timings.peak_rss_bytes = tiled::peak_rss_bytes();
        Ok(serde_json::to_string_pretty(report)?)
    })
}

/// Writes the maps, pictures and `report.json` (the text `report` returns, given the seconds
/// spent writing the rest) into a staging folder, then moves them into `out` together.
pub fn write_maps(
    out: &Path,
    maps: &EstimateMaps,
    report: impl FnOnce(f64) -> Result<String>,
) -> Result<()> {
    write_maps_with(out, maps, symframe_io::NormalPng::OpenGl, report)
}

/// [`write_maps`] with the y convention of `normals.png`.
pub fn write_maps_with(
    out: &Path,
    maps: &EstimateMaps,
    normal_png: symframe_io::NormalPng,
    report: impl FnOnce(f64) -> Result<String>,
) -> Result<()> {
    let t_write = Instant::now();
    let (w, h) = (maps.width, maps.height);
    let staging = Staging::new(out)?;
    symframe_io::write_npy_f32(&staging.path("normals.npy"), &[h, w, 3], &maps.normals)?;
    symframe_io::write_npy_f32(&staging.path("tangents.npy"), &[h, w, 3], &maps.tangents)?;
    symframe_io::write_npy_f32(&staging.path("confidence.npy"), &[h, w], &maps.confidence)?;
    symframe_io::write_npy_f32(&staging.path("anisotropy.npy"), &[h, w], &maps.anisotropy)?;
    symframe_io::write_exr_map(&staging.path("normals.exr"), w, h, 3, &maps.normals)?;
    symframe_io::write_exr_map(&staging.path("tangents.exr"), w, h, 3, &maps.tangents)?;
    symframe_io::write_normal_png16(
        &staging.path("normals.png"),
        w,
        h,
        &maps.normals,
        normal_png,
    )?;
    symframe_io::write_png_rgb8(
        &staging.path("tangents.png"),
        w,
        h,
        &symframe_io::tangent_map_rgb8(&maps.tangents),
    )?;
    symframe_io::write_png_rgb8(
        &staging.path("confidence.png"),
        w,
        h,
        &symframe_io::gray_map_rgb8(&maps.confidence, 0.0, 1.0),
    )?;
    let json = report(t_write.elapsed().as_secs_f64())?;
    std::fs::write(staging.path("report.json"), json + "\n").context("cannot write report.json")?;
    staging.commit()
}
