//! `symframe estimate`: a capture folder in, normal/tangent maps, pictures and a report out.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::baseline::{estimate_stack_baseline_with, Baseline, BaselineParams};
use symframe::estimate::PixelCounts;
use symframe::symmetry::CosineMode;
use symframe::{estimate_stack, EstimateMaps, EstimatorParams, Rig, RigOptions};
use symframe_io::{Dataset, DecodeOptions};

use crate::cli::{CosineArg, EstimateArgs, MethodArg};
use crate::outdir::Staging;
use crate::progress;

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
    /// Wall-clock seconds per stage.
    pub timings: Timings,
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
    /// Decoding the images.
    pub load_s: f64,
    /// Building the rig (0 for a baseline: it has none).
    pub rig_s: f64,
    /// Estimating.
    pub estimate_s: f64,
    /// Writing the outputs.
    pub write_s: f64,
    /// Everything.
    pub total_s: f64,
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
    Ok(())
}

/// What the estimation stage will run.
enum Plan {
    /// The symmetry method on this rig (built before loading, so a bad light file fails fast).
    Symmetry(Box<Rig>),
    /// A baseline, on every light.
    Baseline(Baseline),
}

/// Runs the command; returns the maps and the report written.
pub fn run(args: &EstimateArgs) -> Result<(EstimateMaps, Report)> {
    validate(args)?;
    let t0 = Instant::now();
    let ds: Dataset = symframe_io::open_dataset(&args.input)?;
    let plan = match args.method {
        MethodArg::Symmetry => Plan::Symmetry(Box::new(
            Rig::new(
                &ds.lights,
                RigOptions {
                    theta_d_max_deg: args.theta_d_max,
                    ..RigOptions::default()
                },
            )
            .with_context(|| ds.source.display().to_string())?,
        )),
        MethodArg::Woodham => Plan::Baseline(Baseline::Woodham),
        MethodArg::WoodhamRobust => Plan::Baseline(Baseline::WoodhamRobust),
        MethodArg::MaxReflectance => Plan::Baseline(Baseline::MaxReflectance),
    };
    let rig_s = t0.elapsed().as_secs_f64();

    let t_load = Instant::now();
    let opts = DecodeOptions {
        linear_8bit: args.linear,
        saturation: args.saturation,
    };
    let bar = progress::bar(ds.images.len() as u64, "loading");
    let stack = symframe_io::load_stack(&ds, &opts, &|| bar.inc(1))?;
    bar.finish_and_clear();
    let load_s = t_load.elapsed().as_secs_f64();

    let mask_path = args.mask.clone().or_else(|| ds.mask.clone());
    let mask = match &mask_path {
        Some(p) => Some(symframe_io::read_mask(p, stack.width, stack.height)?),
        None => None,
    };
    // Errors of the estimation stage are about the mask when one is given, else the dataset.
    let blame = || match &mask_path {
        Some(p) => p.display().to_string(),
        None => ds.source.display().to_string(),
    };

    let t_est = Instant::now();
    let n_todo = stack.n_pixels().max(1);
    let bar = progress::bar(n_todo as u64, "estimating");
    let (maps, parameters, lights) = match &plan {
        Plan::Symmetry(rig) => {
            let params = EstimatorParams {
                cosine: match args.cosine {
                    CosineArg::Cross => CosineMode::CrossMultiplied,
                    CosineArg::Raw => CosineMode::Raw,
                    CosineArg::Compensated => CosineMode::Compensated(args.cosine_power),
                },
                min_domain: args.min_domain,
                min_confidence: args.min_confidence,
                min_anisotropy: args.min_anisotropy,
                tangents: !args.no_tangents,
                ..EstimatorParams::default()
            };
            let min_domain_used = symframe::Estimator::new(rig, params).min_domain();
            let maps = estimate_stack(&stack, rig, mask.as_deref(), params, &|k| bar.inc(k as u64))
                .with_context(blame)?;
            let parameters = MethodParameters::Symmetry(Parameters {
                theta_d_max_deg: args.theta_d_max,
                estimator: params,
                min_domain_used,
                linear_8bit: args.linear,
                saturation: args.saturation,
            });
            let lights = LightCounts {
                input: rig.n_input,
                used: rig.n_used(),
                dropped: rig.n_dropped(),
            };
            (maps, parameters, lights)
        }
        &Plan::Baseline(method) => {
            let params = BaselineParams::default();
            let maps = estimate_stack_baseline_with(
                &stack,
                &ds.lights,
                mask.as_deref(),
                method,
                params,
                &|k| bar.inc(k as u64),
            )
            .with_context(blame)?;
            let parameters = MethodParameters::Baseline(BaselineParameters {
                baseline: params,
                linear_8bit: args.linear,
                saturation: args.saturation,
            });
            let lights = LightCounts {
                input: ds.lights.len(),
                used: ds.lights.len(),
                dropped: 0,
            };
            (maps, parameters, lights)
        }
    };
    bar.finish_and_clear();
    drop(stack);
    let estimate_s = t_est.elapsed().as_secs_f64();

    let mut report = Report {
        version: env!("CARGO_PKG_VERSION"),
        input: args.input.clone(),
        mask: mask_path,
        method: match plan {
            Plan::Symmetry(_) => "symmetry",
            Plan::Baseline(b) => b.name(),
        },
        parameters,
        lights,
        width: maps.width,
        height: maps.height,
        pixels: maps.counts,
        evals_per_pixel: maps.evals as f64 / maps.counts.estimated.max(1) as f64,
        timings: Timings {
            load_s,
            rig_s,
            estimate_s,
            write_s: 0.0,
            total_s: 0.0,
        },
    };
    write_outputs(&args.output, &maps, &mut report, t0)?;
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
    Ok((maps, report))
}

/// Writes every output file into a staging folder, then moves them into `out` together.
/// The report's write and total timings are filled in just before it is written.
pub fn write_outputs(
    out: &Path,
    maps: &EstimateMaps,
    report: &mut Report,
    t0: Instant,
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
    symframe_io::write_png_rgb8(
        &staging.path("normals.png"),
        w,
        h,
        &symframe_io::normal_map_rgb8(&maps.normals),
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
    report.timings.write_s = t_write.elapsed().as_secs_f64();
    report.timings.total_s = t0.elapsed().as_secs_f64();
    let json = serde_json::to_string_pretty(report)?;
    std::fs::write(staging.path("report.json"), json + "\n").context("cannot write report.json")?;
    staging.commit()
}
