//! `symframe bench-paper` (hidden): the paper-scale benchmark. Generates a synthetic stack once
//! (a brushed-metal sphere, anisotropic Ward, under lights uniform over the 65-degree cone; RGB
//! float EXR images and an `.lp` file, reused by later runs), then runs the estimation job on it
//! ([`symframe_job::estimate`], as `symframe estimate` does) and prints wall time, decoding and
//! estimation time, pixels per second and peak resident memory, read from the run's report.
//! The baseline `woodham` then runs on the same cache and the time ratio is printed. The
//! process's peak-memory mark is reset before each run, so each run's peak is its own.
//!
//! The paper's captures are 1,512 lights at 1024x1024 (the defaults): about 10 GB of images,
//! an 18 GB cache, and hours of estimation on two cores. `--size 256 --lights 380` is a quick
//! try. `symframe bench-scaling` ([`scaling`]) sweeps size, lights and threads with the same
//! dataset and run code.

pub mod scaling;

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use symframe::baselines::{Baseline, BaselineParams};
use symframe::brdf::ward::Ward;
use symframe::frames::rig::uniform_cone_lights;
use symframe::render::{Scene, TangentField};
use symframe_job::{EstimateConfig, EstimateOutcome, MethodConfig};

use crate::cli::{BenchArgs, CacheFormatArg};
use crate::progress;

/// Renders the dataset into `dir` unless a complete one is there; returns the `.lp` path.
pub(crate) fn dataset(dir: &Path, size: usize, n: usize) -> Result<PathBuf> {
    let lp = dir.join("lights.lp");
    if lp.is_file() {
        eprintln!("bench: reusing the dataset in {}", dir.display());
        return Ok(lp);
    }
    let images = dir.join("images");
    fs::create_dir_all(&images)
        .with_context(|| format!("{}: cannot create folder", images.display()))?;
    let scene = Scene::sphere(size, TangentField::Circular);
    let lights = uniform_cone_lights(n, 65.0);
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    eprintln!(
        "bench: rendering {n} images of {size}x{size} into {} (once)",
        dir.display()
    );
    let t = Instant::now();
    let bar = progress::bar(n as u64, "rendering", "images");
    // One image per task: at most one image per thread in memory. Images already written by
    // an interrupted generation are kept (they are written atomically).
    (0..n).into_par_iter().try_for_each(|i| -> Result<()> {
        let p = images.join(format!("img_{i:04}.exr"));
        if !p.is_file() {
            // Exposure 0.5, as the tests do.
            let img: Vec<f32> = scene
                .render(&brdf, lights[i])
                .iter()
                .map(|v| 0.5 * v)
                .collect();
            symframe_io::write_exr_rgb(&p, size, size, &img)?;
        }
        bar.inc(1);
        Ok(())
    })?;
    bar.finish_and_clear();
    let mask: Vec<f32> = scene
        .mask
        .iter()
        .flat_map(|&m| [m as u8 as f32; 3])
        .collect();
    symframe_io::write_png8_rgb(&dir.join("mask.png"), size, size, &mask, false)?;
    // The light file last: its presence marks a complete dataset.
    let mut text = format!("{n}\n");
    for (i, l) in lights.iter().enumerate() {
        writeln!(text, "images/img_{i:04}.exr {:?} {:?} {:?}", l.x, l.y, l.z)?;
    }
    let tmp = dir.join(".lights.lp.tmp");
    fs::write(&tmp, text).with_context(|| format!("{}: cannot write", tmp.display()))?;
    fs::rename(&tmp, &lp).with_context(|| format!("{}: cannot write", lp.display()))?;
    eprintln!("bench: rendered in {:.1} s", t.elapsed().as_secs_f64());
    Ok(lp)
}

/// The figures of one timed estimation run, read from its report: what `bench-paper` prints and
/// `bench-scaling` records and fits.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Figures {
    /// Wall time of the whole job, seconds.
    pub wall_s: f64,
    /// Decoding the images into the tile cache (or opening it), seconds.
    pub decode_s: f64,
    /// Estimating, seconds.
    pub estimate_s: f64,
    /// Pixels in the mask (estimated, culled, discarded or without data).
    pub mask_pixels: f64,
    /// Pixels estimated.
    pub estimated: f64,
    /// Peak resident memory of the run, bytes (NaN off Linux).
    pub peak_rss_bytes: f64,
    /// Size of the tile cache, bytes.
    pub cache_bytes: f64,
    /// Whether the cache was reused (nothing decoded).
    pub cache_hit: bool,
    /// Images per decoding batch.
    pub batch_images: f64,
    /// CPU seconds of the process during the run, all threads (user + system; NaN off Unix):
    /// on a shared machine a steadier measure of the work than the wall time.
    pub cpu_s: f64,
}

impl Figures {
    /// The figures of a run that took `wall_s` and wrote `report`.
    fn from_report(wall_s: f64, cpu_s: f64, report: &serde_json::Value) -> Self {
        let num = |p: &str| {
            report
                .pointer(p)
                .and_then(|v| v.as_f64())
                .unwrap_or(f64::NAN)
        };
        Figures {
            wall_s,
            decode_s: num("/timings/load_s"),
            estimate_s: num("/timings/estimate_s"),
            mask_pixels: ["estimated", "culled", "discarded", "no_data"]
                .iter()
                .map(|k| num(&format!("/pixels/{k}")))
                .sum(),
            estimated: num("/pixels/estimated"),
            peak_rss_bytes: num("/timings/peak_rss_bytes"),
            cache_bytes: num("/cache/bytes"),
            cache_hit: report
                .pointer("/cache/hit")
                .and_then(|v| v.as_bool())
                .unwrap_or(false),
            batch_images: num("/cache/batch_images"),
            cpu_s,
        }
    }

    /// Pixels of the mask per second of estimation.
    pub fn pixels_per_s(&self) -> f64 {
        self.mask_pixels / self.estimate_s
    }
}

/// Resets the process's peak resident memory mark (`VmHWM`) to the current use (Linux: writing
/// 5 to `/proc/self/clear_refs`), so that a run's report records its own peak.
fn reset_peak_rss() {
    let _ = fs::write("/proc/self/clear_refs", "5");
}

/// CPU seconds (user + system) used by this process so far, all threads; NaN off Unix.
fn cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        // SAFETY: `rusage` is plain integers, for which all-zero bytes are a valid value.
        let mut u: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: getrusage writes only into the struct it is given.
        if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } == 0 {
            let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
            return s(u.ru_utime) + s(u.ru_stime);
        }
    }
    f64::NAN
}

/// Removes `path` (a folder) if it exists.
pub(crate) fn remove_dir(path: &Path) -> Result<()> {
    if path.exists() {
        fs::remove_dir_all(path).with_context(|| format!("{}: cannot remove", path.display()))?;
    }
    Ok(())
}

/// Runs the estimation job of `config` from a fresh output folder (finished tiles of an earlier
/// bench run would be reused, not timed), on the current rayon pool.
pub(crate) fn run_estimate(config: &EstimateConfig) -> Result<Figures> {
    remove_dir(&config.output)?;
    reset_peak_rss();
    let bars = progress::Bars::default();
    let show = |p| bars.update(p);
    let (t, cpu) = (Instant::now(), cpu_seconds());
    let outcome = symframe_job::estimate(config, &crate::control(&show, None))?;
    let (wall_s, cpu_s) = (t.elapsed().as_secs_f64(), cpu_seconds() - cpu);
    let report = match outcome {
        EstimateOutcome::Maps(done) => serde_json::to_value(&done.report)?,
        EstimateOutcome::Shard(report) => serde_json::to_value(&report)?,
    };
    Ok(Figures::from_report(wall_s, cpu_s, &report))
}

/// The symmetry job on the dataset `lp`, output into `out`, with its tile cache in `cache`
/// (deleted first when `cold`, so that decoding is timed).
pub(crate) fn symmetry_config(
    lp: &Path,
    out: PathBuf,
    cache: PathBuf,
    cold: bool,
    decode_memory_mib: usize,
    cache_format: CacheFormatArg,
) -> Result<EstimateConfig> {
    if cold {
        remove_dir(&cache)?;
    }
    let mut config = EstimateConfig::new(lp, out);
    config.cache.dir = Some(cache);
    config.cache.options.batch_bytes = crate::estimate::decode_memory_bytes(decode_memory_mib)?;
    config.cache.options.format = cache_format.into();
    Ok(config)
}

fn print_figures(name: &str, f: &Figures) {
    println!(
        "{name:>9}: wall {:.1} s | decode {:.1} s{} ({:.2} GiB cache, {:.0} images per batch) | \
         estimate {:.1} s | {:.0} pixels/s ({:.0} estimated of {:.0} in the mask) | peak RSS \
         {:.0} MiB",
        f.wall_s,
        f.decode_s,
        if f.cache_hit { " (cache hit)" } else { "" },
        f.cache_bytes / (1u64 << 30) as f64,
        f.batch_images,
        f.estimate_s,
        f.pixels_per_s(),
        f.estimated,
        f.mask_pixels,
        f.peak_rss_bytes / (1u64 << 20) as f64
    );
}

/// Runs the benchmark.
pub fn run(args: &BenchArgs) -> Result<()> {
    if !(8..=4096).contains(&args.size) || !(16..=20000).contains(&args.lights) {
        bail!("--size must be in [8, 4096] and --lights in [16, 20000]");
    }
    let tag = format!("{}px-{}lights", args.size, args.lights);
    let data = args.dir.join(format!("data-{tag}"));
    let lp = dataset(&data, args.size, args.lights)?;
    let mut config = symmetry_config(
        &lp,
        args.dir.join(format!("out-{tag}-symmetry")),
        args.dir.join(format!("cache-{tag}")),
        args.cold,
        args.decode_memory,
        args.cache_format,
    )?;
    config.shard = args.tiles;
    let sym = run_estimate(&config)?;
    println!(
        "bench: {0}x{0} pixels, {1} lights, {2} threads{3}",
        args.size,
        args.lights,
        rayon::current_num_threads(),
        args.tiles
            .map_or(String::new(), |s| format!(", tiles of shard {s} only"))
    );
    print_figures("symmetry", &sym);
    if args.no_baseline {
        return Ok(());
    }
    config.output = args.dir.join(format!("out-{tag}-woodham"));
    config.method = MethodConfig::Baseline {
        method: Baseline::Woodham,
        params: BaselineParams::default(),
    };
    let base = run_estimate(&config)?;
    print_figures("woodham", &base);
    println!(
        "    ratio: symmetry / woodham estimation time {:.1}x",
        sym.estimate_s / base.estimate_s
    );
    // End to end: the baseline ran on the cache the first run built, so its job from the
    // images would have cost that decoding too.
    println!(
        "    ratio: symmetry / woodham end to end (decoding counted in both) {:.1}x",
        sym.wall_s / (base.wall_s + sym.decode_s)
    );
    Ok(())
}
