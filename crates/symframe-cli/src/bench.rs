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
//! try.

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

use crate::cli::BenchArgs;
use crate::progress;

/// Renders the dataset into `dir` unless a complete one is there; returns the `.lp` path.
fn dataset(dir: &Path, size: usize, n: usize) -> Result<PathBuf> {
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
    let bar = progress::bar(n as u64, "rendering");
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

/// One timed estimation run.
struct RunFigures {
    wall_s: f64,
    report: serde_json::Value,
}

/// Resets the process's peak resident memory mark (`VmHWM`) to the current use (Linux: writing
/// 5 to `/proc/self/clear_refs`), so that a run's report records its own peak.
fn reset_peak_rss() {
    let _ = fs::write("/proc/self/clear_refs", "5");
}

/// Runs the estimation job of `config` from a fresh output folder (finished tiles of an earlier
/// bench run would be reused, not timed).
fn run_estimate(config: &EstimateConfig) -> Result<RunFigures> {
    let out = &config.output;
    if out.exists() {
        fs::remove_dir_all(out).with_context(|| format!("{}: cannot remove", out.display()))?;
    }
    reset_peak_rss();
    let bars = progress::Bars::default();
    let show = |p| bars.update(p);
    let t = Instant::now();
    let outcome = symframe_job::estimate(config, &crate::control(&show, None))?;
    let wall_s = t.elapsed().as_secs_f64();
    let report = match outcome {
        EstimateOutcome::Maps(done) => serde_json::to_value(&done.report)?,
        EstimateOutcome::Shard(report) => serde_json::to_value(&report)?,
    };
    Ok(RunFigures { wall_s, report })
}

fn print_figures(name: &str, f: &RunFigures) {
    let r = &f.report;
    let num = |p: &str| r.pointer(p).and_then(|v| v.as_f64()).unwrap_or(f64::NAN);
    let estimated = num("/pixels/estimated");
    let looked_at = ["estimated", "culled", "discarded", "no_data"]
        .iter()
        .map(|k| num(&format!("/pixels/{k}")))
        .sum::<f64>();
    let est_s = num("/timings/estimate_s");
    let rss = num("/timings/peak_rss_bytes") / (1u64 << 20) as f64;
    let hit = r
        .pointer("/cache/hit")
        .and_then(|v| v.as_bool())
        .unwrap_or(false);
    let cache_gib = num("/cache/bytes") / (1u64 << 30) as f64;
    println!(
        "{name:>9}: wall {:.1} s | decode {:.1} s{} ({:.2} GiB cache, {:.0} images per batch) | \
         estimate {:.1} s | {:.0} pixels/s ({:.0} estimated of {:.0} in the mask) | peak RSS \
         {:.0} MiB",
        f.wall_s,
        num("/timings/load_s"),
        if hit { " (cache hit)" } else { "" },
        cache_gib,
        num("/cache/batch_images"),
        est_s,
        looked_at / est_s,
        estimated,
        looked_at,
        rss
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
    let cache = args.dir.join(format!("cache-{tag}"));
    if args.cold && cache.exists() {
        fs::remove_dir_all(&cache)
            .with_context(|| format!("{}: cannot remove", cache.display()))?;
    }
    let mut config = EstimateConfig::new(&lp, args.dir.join(format!("out-{tag}-symmetry")));
    config.cache.dir = Some(cache);
    config.cache.options.batch_bytes = crate::estimate::decode_memory_bytes(args.decode_memory)?;
    config.cache.options.format = args.cache_format.into();
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
    let est = |f: &RunFigures| {
        f.report
            .pointer("/timings/estimate_s")
            .and_then(|v| v.as_f64())
            .unwrap_or(f64::NAN)
    };
    println!(
        "    ratio: symmetry / woodham estimation time {:.1}x",
        est(&sym) / est(&base)
    );
    // End to end: the baseline ran on the cache the first run built, so its job from the
    // images would have cost that decoding too.
    let decode = sym
        .report
        .pointer("/timings/load_s")
        .and_then(|v| v.as_f64())
        .unwrap_or(f64::NAN);
    println!(
        "    ratio: symmetry / woodham end to end (decoding counted in both) {:.1}x",
        sym.wall_s / (base.wall_s + decode)
    );
    Ok(())
}
