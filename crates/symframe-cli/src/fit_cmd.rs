//! `symframe fit`: a capture and its estimated frames in, per-pixel anisotropic Ward parameters
//! out (paper Section 5.1), in a folder that `symframe relight` reads on its own.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::fit::{fit_stack, holdout_lights, FitMaps, FitParams, FitSummary};
use symframe_io::{Dataset, DecodeOptions};

use crate::cli::FitArgs;
use crate::outdir::Staging;
use crate::progress;

/// What `fit.json` records about a run.
#[derive(Debug, Serialize)]
pub struct FitReport {
    /// symframe version.
    pub version: &'static str,
    /// The input as given.
    pub input: PathBuf,
    /// The frames folder as given.
    pub frames: PathBuf,
    /// The mask used, if any.
    pub mask: Option<PathBuf>,
    /// The reflectance model fitted.
    pub model: &'static str,
    /// Fit parameters, including the held-out light indices.
    pub parameters: FitParams,
    /// Light counts.
    pub lights: FitLights,
    /// Image size.
    pub width: usize,
    /// Image size.
    pub height: usize,
    /// Pixel counts and error figures (RMS of the radiance over channels; PSNR in dB).
    pub fit: FitSummary,
    /// Wall-clock seconds per stage.
    pub timings: FitTimings,
}

/// Light counts of a fit.
#[derive(Debug, Serialize)]
pub struct FitLights {
    /// Lights in the input.
    pub input: usize,
    /// Lights the fit used.
    pub fitted: usize,
    /// Lights held out to judge the fit.
    pub held_out: usize,
}

/// Seconds per stage.
#[derive(Debug, Serialize)]
pub struct FitTimings {
    /// Decoding the images.
    pub load_s: f64,
    /// Fitting.
    pub fit_s: f64,
    /// Writing the outputs.
    pub write_s: f64,
    /// Everything.
    pub total_s: f64,
}

/// Reads an `H x W x 3` map of the frames folder and checks it against the images' size.
fn read_frame_map(path: &Path, width: usize, height: usize) -> Result<Vec<f32>> {
    let (shape, data) = symframe_io::read_npy_f32(path)?;
    if shape != [height, width, 3] {
        bail!(
            "{}: shape {shape:?} does not match the images ({height} x {width} x 3 expected)",
            path.display()
        );
    }
    Ok(data)
}

/// Checks the flags that clap cannot.
fn validate(args: &FitArgs) -> Result<()> {
    if !(args.saturation > 0.0 && args.saturation <= 1.0) {
        bail!("--saturation must be in (0, 1], got {}", args.saturation);
    }
    if args.max_iterations == 0 {
        bail!("--max-iterations must be at least 1");
    }
    if !(args.max_peak_ratio >= 1.0 && args.max_peak_ratio.is_finite()) {
        bail!(
            "--max-peak-ratio must be finite and at least 1, got {}",
            args.max_peak_ratio
        );
    }
    for name in ["normals.npy", "tangents.npy"] {
        let p = args.frames.join(name);
        if !p.is_file() {
            bail!(
                "{}: missing (--frames must be an output folder of symframe estimate)",
                p.display()
            );
        }
    }
    Ok(())
}

/// Runs the command; returns the maps and the report written.
pub fn run(args: &FitArgs) -> Result<(FitMaps, FitReport)> {
    validate(args)?;
    let t0 = Instant::now();
    let ds: Dataset = symframe_io::open_dataset(&args.input)?;
    let holdout = holdout_lights(ds.lights.len(), args.holdout)
        .map_err(|e| anyhow::anyhow!("--holdout {}: {e}", args.holdout))?;

    let opts = DecodeOptions {
        linear_8bit: args.linear,
        saturation: args.saturation,
    };
    let bar = progress::bar(ds.images.len() as u64, "loading");
    let (stack, warnings) = symframe_io::load_stack_with_warnings(&ds, &opts, &|| bar.inc(1))?;
    bar.finish_and_clear();
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let load_s = t0.elapsed().as_secs_f64();
    let (w, h) = (stack.width, stack.height);
    let normals = read_frame_map(&args.frames.join("normals.npy"), w, h)?;
    let tangents = read_frame_map(&args.frames.join("tangents.npy"), w, h)?;

    let mask_path = args.mask.clone().or_else(|| ds.mask.clone());
    let mask = match &mask_path {
        Some(p) => Some(symframe_io::read_mask(p, w, h)?),
        None => None,
    };

    let params = FitParams {
        holdout,
        max_iterations: args.max_iterations,
        max_peak_ratio: args.max_peak_ratio,
        ..FitParams::default()
    };
    let t_fit = Instant::now();
    let bar = progress::bar((w * h) as u64, "fitting");
    let maps = fit_stack(
        &stack,
        &ds.lights,
        &normals,
        &tangents,
        mask.as_deref(),
        &params,
        &|k| bar.inc(k as u64),
    )
    .with_context(|| ds.source.display().to_string())?;
    bar.finish_and_clear();
    drop(stack);
    let fit_s = t_fit.elapsed().as_secs_f64();

    let mut report = FitReport {
        version: env!("CARGO_PKG_VERSION"),
        input: args.input.clone(),
        frames: args.frames.clone(),
        mask: mask_path,
        model: "anisotropic Ward (Ward 1992, normalised form), frame x = t, y = n x t, z = n",
        lights: FitLights {
            input: ds.lights.len(),
            fitted: ds.lights.len() - params.holdout.len(),
            held_out: params.holdout.len(),
        },
        parameters: params,
        width: w,
        height: h,
        fit: maps.summary,
        timings: FitTimings {
            load_s,
            fit_s,
            write_s: 0.0,
            total_s: 0.0,
        },
    };
    write_outputs(&args.output, &maps, &mut report, t0)?;
    if progress::interactive() {
        let s = &maps.summary;
        let held = match (s.holdout_rms, s.holdout_psnr_db) {
            (Some(r), Some(p)) => format!("; held-out RMS {r:.4}, PSNR {p:.1} dB"),
            _ => String::new(),
        };
        eprintln!(
            "symframe: {} pixels fitted ({} isotropic), {} without a frame, {} with too few samples; \
             training RMS {:.4}{held}; {:.1} s",
            s.anisotropic + s.isotropic,
            s.isotropic,
            s.no_frame,
            s.too_few_samples,
            s.train_rms,
            report.timings.total_s
        );
    }
    Ok((maps, report))
}

/// Writes every output file into a staging folder, then moves them into `out` together.
fn write_outputs(out: &Path, maps: &FitMaps, report: &mut FitReport, t0: Instant) -> Result<()> {
    let t_write = Instant::now();
    let m = &maps.ward;
    let (w, h) = (m.width, m.height);
    let staging = Staging::new(out)?;
    let maps3: [(&str, &[f32]); 4] = [
        ("kd", &m.kd),
        ("ks", &m.ks),
        ("normals", &m.normals),
        ("tangents", &m.tangents),
    ];
    for (name, data) in maps3 {
        symframe_io::write_npy_f32(&staging.path(&format!("{name}.npy")), &[h, w, 3], data)?;
        symframe_io::write_exr_map(&staging.path(&format!("{name}.exr")), w, h, 3, data)?;
    }
    let maps1: [(&str, &[f32]); 4] = [
        ("alpha_t", &m.alpha_t),
        ("alpha_b", &m.alpha_b),
        ("residual", &maps.residual),
        ("holdout_residual", &maps.holdout_residual),
    ];
    for (name, data) in maps1 {
        if name == "holdout_residual" && report.parameters.holdout.is_empty() {
            continue;
        }
        symframe_io::write_npy_f32(&staging.path(&format!("{name}.npy")), &[h, w], data)?;
        symframe_io::write_exr_map(&staging.path(&format!("{name}.exr")), w, h, 1, data)?;
    }
    // Albedo pictures: clamped and sRGB-encoded, black where nothing was fitted.
    symframe_io::write_png8_rgb(&staging.path("kd.png"), w, h, &m.kd, true)?;
    symframe_io::write_png8_rgb(&staging.path("ks.png"), w, h, &m.ks, true)?;
    report.timings.write_s = t_write.elapsed().as_secs_f64();
    report.timings.total_s = t0.elapsed().as_secs_f64();
    let json = serde_json::to_string_pretty(report)?;
    std::fs::write(staging.path("fit.json"), json + "\n").context("cannot write fit.json")?;
    staging.commit()
}
