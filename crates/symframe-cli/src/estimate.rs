//! `symframe estimate` and `symframe merge`: flags checked and turned into a job configuration,
//! one library call ([`symframe_job::estimate`], [`symframe_job::merge`]), a summary line.

use anyhow::{bail, Result};
use symframe::{Baseline, BaselineParams, EstimatorParams, Interpolation, RigOptions};
use symframe_console::flags::decode_memory_bytes;
use symframe_io::CacheOptions;
use symframe_job::{EstimateConfig, EstimateOutcome, LightModel, MethodConfig, NearOptions};

use crate::cli::{EstimateArgs, LightModelArg, MergeArgs, MethodArg};
use crate::progress;

/// Checks the flags that clap cannot.
fn validate(args: &EstimateArgs) -> Result<()> {
    let unit = 0.0..=1.0;
    if !(args.theta_d_max > 0.0 && args.theta_d_max <= 90.0) {
        bail!(
            "--theta-d-max must be in (0, 90] degrees, got {}",
            args.theta_d_max
        );
    }
    for (flag, v) in [
        ("--min-confidence", args.min_confidence),
        ("--min-anisotropy", args.min_anisotropy),
    ] {
        if !unit.contains(&v) {
            bail!("{flag} must be in [0, 1], got {v}");
        }
    }
    if !(0.0..=10.0).contains(&args.light_error) {
        bail!(
            "--light-error must be in [0, 10] degrees, got {}",
            args.light_error
        );
    }
    args.decode.options()?;
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
    if let Some(d) = args.distance {
        if !(d.is_finite() && d > 0.0) {
            bail!("--distance must be a positive depth, got {d}");
        }
    }
    if !(1..=1024).contains(&args.rig_tile) {
        bail!(
            "--rig-tile must be in [1, 1024] pixels, got {}",
            args.rig_tile
        );
    }
    if !(1..=100).contains(&args.rounds) {
        bail!("--rounds must be in [1, 100], got {}", args.rounds);
    }
    decode_memory_bytes(args.decode_memory)?;
    Ok(())
}

/// The job the flags ask for.
pub fn config(args: &EstimateArgs) -> Result<EstimateConfig> {
    validate(args)?;
    let method = match args.method {
        MethodArg::Symmetry => MethodConfig::Symmetry {
            rig: RigOptions {
                theta_d_max_deg: args.theta_d_max,
            },
            params: EstimatorParams {
                cosine: args.cosine.mode(args.cosine_power),
                fallback: args.fallback.rule(),
                min_domain: args.min_domain,
                min_confidence: args.min_confidence,
                min_anisotropy: args.min_anisotropy,
                noise: symframe::NoiseModel {
                    light_error_deg: args.light_error,
                    ..symframe::NoiseModel::default()
                },
                tangents: !args.no_tangents,
                interpolation: if args.reference {
                    Interpolation::Exact
                } else {
                    Interpolation::Fast
                },
                ..EstimatorParams::default()
            },
        },
        m => MethodConfig::Baseline {
            method: match m {
                MethodArg::Woodham => Baseline::Woodham,
                MethodArg::WoodhamRobust => Baseline::WoodhamRobust,
                MethodArg::HighlightCentroid => Baseline::HighlightCentroid,
                _ => Baseline::MaxReflectance,
            },
            params: BaselineParams::default(),
        },
    };
    Ok(EstimateConfig {
        input: args.input.clone(),
        output: args.output.clone(),
        method,
        mask: args.mask.clone(),
        decode: args.decode.options()?,
        cache: args.cache.config(CacheOptions {
            tile: args.tile_size,
            batch_bytes: decode_memory_bytes(args.decode_memory)?,
            trust_mtime: args.trust_mtime,
            format: args.cache_format.into(),
        }),
        shard: args.tiles,
        keep_maps: false,
        normal_png: args.normal_png.into(),
        near: NearOptions {
            model: match args.light_model {
                LightModelArg::Auto => LightModel::Auto,
                LightModelArg::Distant => LightModel::Distant,
                LightModelArg::Near => LightModel::Near,
            },
            distance: args.distance,
            tile: args.rig_tile,
            max_iterations: args.rounds,
            ..NearOptions::default()
        },
    })
}

/// Runs `symframe estimate`.
pub fn run(args: &EstimateArgs) -> Result<EstimateOutcome> {
    let config = config(args)?;
    if let Some(ds) = progress::chatty()
        .then(|| symframe_io::open_dataset(&args.input).ok())
        .flatten()
    {
        if let Ok(symframe_io::LpPaths::Windows) = symframe_io::lp_path_convention(&ds.source) {
            eprintln!(
                "symframe estimate: {}: {}",
                ds.source.display(),
                symframe_io::LpPaths::Windows
            );
        }
    }
    let bars = progress::Bars::new("estimating");
    let show = |p| bars.update(p);
    let outcome = symframe_job::estimate(&config, &crate::control(&show, args.stop_after_tiles))
        .map_err(flag_hint)?;
    drop(bars);
    if progress::chatty() {
        match &outcome {
            EstimateOutcome::Maps(done) => {
                let (c, r) = (&done.report.pixels, &done.report);
                eprintln!(
                    "symframe ({}): {} pixels estimated ({} with a tangent), {} discarded, {} \
                     culled, {} without data; {} of {} lights used; {:.1} s",
                    r.method,
                    c.estimated,
                    c.with_tangent,
                    c.discarded,
                    c.culled,
                    c.no_data,
                    r.lights.used,
                    r.lights.input,
                    r.timings.total_s
                );
                eprintln!(
                    "symframe: answered by {}; maps and report.json in {}",
                    answered_by(&r.sources),
                    args.output.display()
                );
            }
            EstimateOutcome::Shard(r) => eprintln!(
                "symframe: shard {} done: {} tiles ({} computed now) in {}; combine the shards \
                 with `symframe merge`",
                r.tiles.shard.as_deref().unwrap_or_default(),
                r.tiles.this_run,
                r.tiles.computed,
                args.output.display()
            ),
        }
    }
    Ok(outcome)
}

/// Names the flag that fixes an error, where one does.
fn flag_hint(e: anyhow::Error) -> anyhow::Error {
    match e.downcast_ref::<symframe::Error>() {
        Some(symframe::Error::AllLightsOutsideCone { .. }) => {
            anyhow::anyhow!("{e:#} (--theta-d-max sets the cone)")
        }
        _ => e,
    }
}

/// Runs `symframe merge`.
pub fn merge(args: &MergeArgs) -> Result<()> {
    let bars = progress::Bars::default();
    let show = |p| bars.update(p);
    let done = symframe_job::merge(
        &args.shards,
        &args.output,
        false,
        &crate::control(&show, None),
    )?;
    drop(bars);
    if progress::chatty() {
        let c = &done.pixels;
        eprintln!(
            "symframe: merged {} shards into {}: {} pixels estimated ({} with a tangent)",
            done.shards,
            args.output.display(),
            c.estimated,
            c.with_tangent
        );
    }
    Ok(())
}

/// Which measures answered, largest share first: `lobe 62% · symmetry 30% · lambertian 8%`
/// (shares of the pixels with an answer; `none` left out), or `no pixel`.
fn answered_by(sources: &symframe_job::Sources) -> String {
    let mut counts: Vec<(&str, usize)> = sources
        .0
        .iter()
        .filter(|s| s.name != "none" && s.pixels > 0)
        .map(|s| (s.name, s.pixels))
        .collect();
    let total: usize = counts.iter().map(|c| c.1).sum();
    if total == 0 {
        return "no pixel".into();
    }
    counts.sort_by_key(|c| std::cmp::Reverse(c.1));
    counts
        .iter()
        .map(|(name, n)| format!("{name} {:.0}%", 100.0 * *n as f64 / total as f64))
        .collect::<Vec<_>>()
        .join(" · ")
}
