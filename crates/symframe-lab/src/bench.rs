//! `symframe-lab bench`: the paper-scale benchmark. Generates a synthetic stack once
//! (a brushed-metal sphere, anisotropic Ward, under lights uniform over the 65-degree cone; RGB
//! float EXR images and an `.lp` file, reused by later runs), then runs the estimation job on it
//! ([`symframe_job::estimate`], as `symframe estimate` does) and prints wall time, decoding and
//! estimation time, pixels per second and peak resident memory, read from the run's report.
//! The baseline `woodham` then runs on the same cache and the time ratio is printed. The
//! process's peak-memory mark is reset before each run, so each run's peak is its own.
//!
//! The paper's captures are 1,512 lights at 1024x1024 (the defaults): gigabytes of images, an
//! 18 GB cache, and minutes of estimation on two cores (docs/performance.md, "Paper scale").
//! `--size 256 --lights 380` is a quick try. `--width W --height H --format jpeg|png16`
//! benchmarks another layout (the sphere as large as the shorter side, the rest background;
//! 8-bit sRGB JPEG as cameras write them, or 16-bit linear PNG), whose tile cache is then `u8`
//! or `u16` by default. The figures are also
//! written to `bench.json` in `--dir` (`total_s`, `decode_s`, `estimate_s`, `peak_rss_bytes`,
//! `load_peak_rss_bytes` (the peak after decoding: which phase sets it), `cache_bytes`,
//! `woodham_s`, ...). `symframe-lab bench scaling` ([`scaling`]) sweeps size,
//! lights and threads with the same dataset and run code. `--near` ([`run_near`]) times the
//! near-light estimate of a dome capture against the same scene under distant lights, a
//! distant-light capture of as many pixels (in wall and CPU time) and, unless
//! `--no-baseline`, the distant-light model on the same images.

pub mod scaling;

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use symframe::brdf::Ward;
use symframe::render::{Scene, TangentField};
use symframe::{uniform_cone_lights, Baseline, BaselineParams};
use symframe_console::flags::{decode_memory_bytes, CacheFormatArg};
use symframe_console::progress;
use symframe_job::{EstimateConfig, EstimateOutcome, LightModel, MethodConfig, NearSynthConfig};

use crate::cli::{BenchArgs, BenchFormat};

/// Renders the dataset into `dir` unless a complete one is there; returns the `.lp` path.
pub(crate) fn dataset(dir: &Path, size: usize, n: usize) -> Result<PathBuf> {
    dataset_layout(dir, size, size, n, BenchFormat::Exr)
}

/// The scene of a `width x height` capture: the brushed sphere of the paper's layout, as large
/// as the shorter side, centred, the rest background outside the mask.
fn layout_scene(width: usize, height: usize) -> Scene {
    let side = width.min(height);
    let sphere = Scene::sphere(side, TangentField::Circular);
    if width == height {
        return sphere;
    }
    let (x0, y0) = ((width - side) / 2, (height - side) / 2);
    let n = width * height;
    let mut scene = Scene {
        width,
        height,
        mask: vec![false; n],
        normals_in_camera: vec![glam::DVec3::Z; n],
        tangents_in_camera: vec![glam::DVec3::X; n],
        heights: None,
    };
    for y in 0..side {
        for x in 0..side {
            let (p, q) = ((y0 + y) * width + x0 + x, y * side + x);
            scene.mask[p] = sphere.mask[q];
            scene.normals_in_camera[p] = sphere.normals_in_camera[q];
            scene.tangents_in_camera[p] = sphere.tangents_in_camera[q];
        }
    }
    scene
}

/// Writes one rendered image (linear RGB) in `format`: float EXR, 8-bit sRGB JPEG of quality
/// 90, or 16-bit linear PNG (both clamped to [0, 1]).
fn write_image(p: &Path, w: usize, h: usize, img: &[f32], format: BenchFormat) -> Result<()> {
    match format {
        BenchFormat::Exr => symframe_io::write_exr_rgb(p, w, h, img)?,
        BenchFormat::Png16 => symframe_io::write_png16_rgb(p, w, h, img)?,
        BenchFormat::Jpeg => {
            let bytes: Vec<u8> = img
                .iter()
                .map(|&v| (symframe_io::linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round() as u8)
                .collect();
            // Written aside and renamed, so that an interrupted generation leaves no torn file.
            let tmp = p.with_extension("jpg.tmp");
            let f = std::io::BufWriter::new(
                fs::File::create(&tmp)
                    .with_context(|| format!("{}: cannot write", tmp.display()))?,
            );
            image::ImageEncoder::write_image(
                image::codecs::jpeg::JpegEncoder::new_with_quality(f, 90),
                &bytes,
                w as u32,
                h as u32,
                image::ExtendedColorType::Rgb8,
            )
            .with_context(|| format!("{}: cannot encode", tmp.display()))?;
            fs::rename(&tmp, p).with_context(|| format!("{}: cannot write", p.display()))?;
        }
    }
    Ok(())
}

/// Renders a `width x height` dataset of `n` lights in `format` into `dir` unless a complete
/// one is there ([`layout_scene`]; the paper's when square and EXR); returns the `.lp` path.
pub(crate) fn dataset_layout(
    dir: &Path,
    width: usize,
    height: usize,
    n: usize,
    format: BenchFormat,
) -> Result<PathBuf> {
    let lp = dir.join("lights.lp");
    if lp.is_file() {
        eprintln!("bench: reusing the dataset in {}", dir.display());
        return Ok(lp);
    }
    let images = dir.join("images");
    fs::create_dir_all(&images)
        .with_context(|| format!("{}: cannot create folder", images.display()))?;
    let scene = layout_scene(width, height);
    let lights = uniform_cone_lights(n, 65.0);
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let ext = match format {
        BenchFormat::Exr => "exr",
        BenchFormat::Jpeg => "jpg",
        BenchFormat::Png16 => "png",
    };
    eprintln!(
        "bench: rendering {n} images of {width}x{height} into {} (once)",
        dir.display()
    );
    let t = Instant::now();
    let bar = progress::bar(n as u64, "rendering", "images");
    // One image per task: at most one image per thread in memory. Images already written by
    // an interrupted generation are kept (they are written atomically).
    (0..n).into_par_iter().try_for_each(|i| -> Result<()> {
        let p = images.join(format!("img_{i:04}.{ext}"));
        if !p.is_file() {
            // Exposure 0.5, as the tests do.
            let img: Vec<f32> = scene
                .render(&brdf, lights[i])
                .iter()
                .map(|v| 0.5 * v)
                .collect();
            write_image(&p, width, height, &img, format)?;
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
    symframe_io::write_png8_rgb(&dir.join("mask.png"), width, height, &mask, false)?;
    // The light file last: its presence marks a complete dataset.
    let mut text = format!("{n}\n");
    for (i, l) in lights.iter().enumerate() {
        writeln!(
            text,
            "images/img_{i:04}.{ext} {:?} {:?} {:?}",
            l.x, l.y, l.z
        )?;
    }
    let tmp = dir.join(".lights.lp.tmp");
    fs::write(&tmp, text).with_context(|| format!("{}: cannot write", tmp.display()))?;
    fs::rename(&tmp, &lp).with_context(|| format!("{}: cannot write", lp.display()))?;
    eprintln!("bench: rendered in {:.1} s", t.elapsed().as_secs_f64());
    Ok(lp)
}

/// The figures of one timed estimation run, read from its report: what `bench` prints and
/// `bench scaling` records and fits.
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
    /// The peak as it stood after decoding, bytes (NaN off Linux).
    pub load_peak_rss_bytes: f64,
    /// Size of the tile cache, bytes.
    pub cache_bytes: f64,
    /// Whether the cache was reused (nothing decoded).
    pub cache_hit: bool,
    /// Of building the cache: decoding the images, and scattering them into the cache,
    /// seconds (all threads' wall clock together; 0 on a cache hit).
    pub cache_decode_s: f64,
    pub cache_scatter_s: f64,
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
            load_peak_rss_bytes: num("/timings/load_peak_rss_bytes"),
            cache_bytes: num("/cache/bytes"),
            cache_hit: report
                .pointer("/cache/hit")
                .and_then(|v| v.as_bool())
                .unwrap_or(false),
            batch_images: num("/cache/batch_images"),
            cache_decode_s: num("/cache/decode_s"),
            cache_scatter_s: num("/cache/scatter_s"),
            cpu_s,
        }
    }

    /// Pixels of the mask per second of estimation.
    pub fn pixels_per_s(&self) -> f64 {
        self.mask_pixels / self.estimate_s
    }

    /// This run's time per pixel of the mask over `other`'s: in estimation (wall) time, and in
    /// CPU time of the whole run (all threads: steadier where other programs share the cores).
    fn per_pixel_over(&self, other: &Figures) -> (f64, f64) {
        (
            self.pixels_per_s().recip() / other.pixels_per_s().recip(),
            (self.cpu_s / self.mask_pixels) / (other.cpu_s / other.mask_pixels),
        )
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
    let outcome = symframe_job::estimate(config, &symframe_console::control(&show, None))?;
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
    // As `symframe estimate`: the maps are written band by band, not also kept whole in
    // memory, which the peak would count (docs/performance.md, "Memory model").
    config.keep_maps = false;
    config.cache.dir = Some(cache);
    config.cache.options.batch_bytes = decode_memory_bytes(decode_memory_mib)?;
    config.cache.options.format = cache_format.into();
    Ok(config)
}

fn print_figures(name: &str, f: &Figures) {
    println!(
        "{name:>9}: wall {:.1} s | decode {:.1} s{} ({:.2} GiB cache, {:.0} images per batch) | \
         estimate {:.1} s | {:.0} pixels/s ({:.0} estimated of {:.0} in the mask) | peak RSS \
         {:.0} MiB ({:.0} MiB after decoding)",
        f.wall_s,
        f.decode_s,
        if f.cache_hit { " (cache hit)" } else { "" },
        f.cache_bytes / (1u64 << 30) as f64,
        f.batch_images,
        f.estimate_s,
        f.pixels_per_s(),
        f.estimated,
        f.mask_pixels,
        f.peak_rss_bytes / (1u64 << 20) as f64,
        f.load_peak_rss_bytes / (1u64 << 20) as f64
    );
}

/// Runs the benchmark.
pub fn run(args: &BenchArgs) -> Result<()> {
    if args.near {
        return run_near(args);
    }
    let (width, height) = (
        args.width.unwrap_or(args.size),
        args.height.unwrap_or(args.size),
    );
    if ![width, height].iter().all(|s| (8..=65536).contains(s))
        || !(16..=20000).contains(&args.lights)
    {
        bail!("--size, --width and --height must be in [8, 65536] and --lights in [16, 20000]");
    }
    // The paper's layout keeps its folder names, so existing datasets and caches are reused.
    let tag = if width == height && args.format == BenchFormat::Exr {
        format!("{width}px-{}lights", args.lights)
    } else {
        let format = format!("{:?}", args.format).to_lowercase();
        format!("{width}x{height}-{}lights-{format}", args.lights)
    };
    let data = args.dir.join(format!("data-{tag}"));
    let lp = dataset_layout(&data, width, height, args.lights, args.format)?;
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
        "bench: {width}x{height} pixels, {} lights, {:?} images, {} threads{}",
        args.lights,
        args.format,
        rayon::current_num_threads(),
        args.tiles
            .map_or(String::new(), |s| format!(", tiles of shard {s} only"))
    );
    print_figures("symmetry", &sym);
    let samples = (width * height * args.lights) as f64;
    let mut json = serde_json::json!({
        "width": width,
        "height": height,
        "lights": args.lights,
        "format": format!("{:?}", args.format).to_lowercase(),
        "threads": rayon::current_num_threads(),
        "cold": args.cold,
        "cache_hit": sym.cache_hit,
        "total_s": sym.wall_s,
        "decode_s": sym.decode_s,
        "cache_decode_s": sym.cache_decode_s,
        "cache_scatter_s": sym.cache_scatter_s,
        "estimate_s": sym.estimate_s,
        "pixels_per_s": sym.pixels_per_s(),
        "peak_rss_bytes": sym.peak_rss_bytes,
        "load_peak_rss_bytes": sym.load_peak_rss_bytes,
        "cache_bytes": sym.cache_bytes,
        "cache_bytes_per_pixel_per_light": (sym.cache_bytes / samples * 100.0).round() / 100.0,
        "woodham_s": serde_json::Value::Null,
    });
    if !args.no_baseline {
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
        json["woodham_s"] = base.estimate_s.into();
    }
    let out = args.dir.join("bench.json");
    fs::write(&out, serde_json::to_string_pretty(&json)? + "\n")
        .with_context(|| format!("{}: cannot write", out.display()))?;
    println!("    figures written to {}", out.display());
    Ok(())
}

/// One run of the dome capture in `data` with the light `model`, output into
/// `out-{tag}-{name}` (its tile cache `cache-{tag}` deleted first when `cold`).
fn near_run(
    args: &BenchArgs,
    (data, tag): (&Path, &str),
    name: &str,
    model: LightModel,
    cold: bool,
) -> Result<Figures> {
    let mut config = symmetry_config(
        data,
        args.dir.join(format!("out-{tag}-{name}")),
        args.dir.join(format!("cache-{tag}")),
        cold,
        args.decode_memory,
        args.cache_format,
    )?;
    config.near.model = model;
    run_estimate(&config)
}

/// The dome and camera distances of the near benchmark's capture, in the pair's widths: the
/// near one of `symframe synth --near`, and one where the lights are distant and the camera
/// orthographic (the largest `synth_near` takes).
const NEAR_DOME: [f64; 2] = [2.0, 3.0];
const FAR_DOME: [f64; 2] = [1000.0, 1000.0];

/// Renders the dome capture of `symframe synth --near` (`width` pixels wide, `n` lights, the
/// dome's radius and the camera's distance `[dome, camera]` in the pair's widths) into `data`,
/// unless it is there already.
fn dome_capture(data: &Path, width: usize, n: usize, [dome, camera]: [f64; 2]) -> Result<()> {
    if data.join("light_positions.txt").is_file() {
        eprintln!("bench: reusing the dataset in {}", data.display());
        return Ok(());
    }
    eprintln!(
        "bench: rendering {n} dome images into {} (once)",
        data.display()
    );
    let capture = NearSynthConfig {
        size: width,
        lights: n,
        force: true,
        dome_ratio: dome,
        camera_ratio: camera,
        ..NearSynthConfig::new(data)
    };
    let bars = progress::Bars::default();
    let show = |p| bars.update(p);
    symframe_job::synth_near(&capture, &symframe_console::control(&show, None))?;
    Ok(())
}

/// The near-light benchmark: renders the dome capture of `symframe synth --near` once (`--size`
/// wide, `--lights` lights), then times its estimate with near lights (rounds of per-tile rigs
/// and depth), the same scene under distant lights, the paper's distant-light sphere of about
/// as many pixels under as many lights, and (unless `--no-baseline`) the near images with
/// distant lights (`--light-model distant`) on the same tile cache.
pub fn run_near(args: &BenchArgs) -> Result<()> {
    let (width, n) = (args.size, args.lights);
    if !(16..=2048).contains(&width) || !(16..=10_000).contains(&n) {
        bail!("with --near, --size must be in [16, 2048] and --lights in [16, 10000]");
    }
    let tag = format!("near-{width}px-{n}lights");
    let data = args.dir.join(format!("data-{tag}"));
    dome_capture(&data, width, n, NEAR_DOME)?;
    // The same scene with the dome and the camera so far away that its lights are distant
    // and its camera orthographic (to 0.03 degrees across the pair): the same materials,
    // pixels and light directions, estimated with distant lights.
    let far_tag = format!("far-{width}px-{n}lights");
    let far_data = args.dir.join(format!("data-{far_tag}"));
    dome_capture(&far_data, width, n, FAR_DOME)?;
    // The near run, then the distant captures right after it (the machine's load changes less
    // between them than over the long distant-model run), then the distant model.
    let near = near_run(args, (&data, &tag), "near", LightModel::Near, args.cold)?;
    let same = near_run(
        args,
        (&far_data, &far_tag),
        "distant",
        LightModel::Distant,
        args.cold,
    )?;
    // A distant-light capture of about as many pixels: the paper's brushed sphere, its side
    // chosen so that its disc holds the near capture's mask, under as many lights.
    let side = ((near.mask_pixels * 4.0 / std::f64::consts::PI)
        .sqrt()
        .round() as usize)
        .max(8);
    let sphere_tag = format!("{side}px-{n}lights");
    let lp = dataset(&args.dir.join(format!("data-{sphere_tag}")), side, n)?;
    let config = symmetry_config(
        &lp,
        args.dir.join(format!("out-{sphere_tag}-symmetry")),
        args.dir.join(format!("cache-{sphere_tag}")),
        args.cold,
        args.decode_memory,
        args.cache_format,
    )?;
    let sphere = run_estimate(&config)?;
    // The distant model on the near images (--no-baseline skips it: it costs several times the
    // near run, the lights not fitting these images).
    let far = if args.no_baseline {
        None
    } else {
        Some(near_run(
            args,
            (&data, &tag),
            "distant",
            LightModel::Distant,
            false,
        )?)
    };
    let near = &near;
    println!(
        "bench --near: {width}x{} pixels, {n} lights on a dome, {} threads",
        width / 2,
        rayon::current_num_threads()
    );
    print_figures("near", near);
    if let Some(far) = &far {
        print_figures("distant", far);
    }
    print_figures("same scene distant", &same);
    print_figures("sphere", &sphere);
    let (same_wall_ratio, same_ratio) = near.per_pixel_over(&same);
    println!(
        "    ratio: near / the same scene under distant lights (dome and camera at {} widths) \
         time per pixel {same_wall_ratio:.2}x, in CPU time {same_ratio:.2}x",
        FAR_DOME[0]
    );
    let ratio = far.as_ref().map(|f| near.estimate_s / f.estimate_s);
    if let Some(ratio) = ratio {
        println!("    ratio: near / distant estimation time on the same images {ratio:.2}x");
    }
    let (capture_ratio, cpu_ratio) = near.per_pixel_over(&sphere);
    println!(
        "    ratio: near / a distant-light capture ({side}x{side} sphere, {n} lights) time per \
         pixel {capture_ratio:.2}x"
    );
    println!(
        "    ratio: the same in CPU time per pixel {cpu_ratio:.2}x (near {:.1} s, sphere {:.1} s)",
        near.cpu_s, sphere.cpu_s
    );
    // What each run's time is made of: the near rounds, and the estimator's work per pixel
    // (the distant model's lights do not fit these images, which costs it more per pixel).
    let report_at = |out: &str| -> Result<serde_json::Value> {
        let p = args.dir.join(out).join("report.json");
        let text =
            fs::read_to_string(&p).with_context(|| format!("{}: cannot read", p.display()))?;
        Ok(serde_json::from_str(&text)?)
    };
    let rn = report_at(&format!("out-{tag}-near"))?;
    let rf = match far {
        Some(_) => Some(report_at(&format!("out-{tag}-distant"))?),
        None => None,
    };
    let rounds = rn.pointer("/near/iterations").and_then(|v| v.as_u64());
    let evals = |r: &serde_json::Value| r["evals_per_pixel"].as_f64().unwrap_or(f64::NAN);
    println!(
        "    near: {} rounds, {:.0} objective evaluations per pixel in the last{}",
        rounds.unwrap_or(0),
        evals(&rn),
        rf.as_ref().map_or(String::new(), |r| format!(
            "; distant: {:.0} per pixel",
            evals(r)
        ))
    );
    let json = serde_json::json!({
        "near": true,
        "width": width,
        "height": width / 2,
        "lights": n,
        "threads": rayon::current_num_threads(),
        "near_estimate_s": near.estimate_s,
        "distant_estimate_s": far.as_ref().map(|f| f.estimate_s),
        "near_total_s": near.wall_s,
        "distant_total_s": far.as_ref().map(|f| f.wall_s),
        "near_peak_rss_bytes": near.peak_rss_bytes,
        "distant_peak_rss_bytes": far.as_ref().map(|f| f.peak_rss_bytes),
        "near_over_distant": ratio,
        "near_rounds": rounds,
        "near_evals_per_pixel_last_round": evals(&rn),
        "distant_evals_per_pixel": rf.as_ref().map(evals),
        "sphere_side": side,
        "sphere_estimate_s": sphere.estimate_s,
        "sphere_evals_per_pixel": evals(&report_at(&format!("out-{sphere_tag}-symmetry"))?),
        "near_over_distant_capture_per_pixel": capture_ratio,
        "near_cpu_s": near.cpu_s,
        "sphere_cpu_s": sphere.cpu_s,
        "near_over_distant_capture_cpu_per_pixel": cpu_ratio,
        "same_scene_distant_estimate_s": same.estimate_s,
        "same_scene_distant_cpu_s": same.cpu_s,
        "same_scene_distant_evals_per_pixel": evals(&report_at(&format!("out-{far_tag}-distant"))?),
        "near_over_same_scene_distant_per_pixel": same_wall_ratio,
        "near_over_same_scene_distant_cpu_per_pixel": same_ratio,
    });
    let out = args.dir.join("bench.json");
    fs::write(&out, serde_json::to_string_pretty(&json)? + "\n")
        .with_context(|| format!("{}: cannot write", out.display()))?;
    println!("    figures written to {}", out.display());
    Ok(())
}
