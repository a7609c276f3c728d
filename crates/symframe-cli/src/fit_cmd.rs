//! `symframe fit`, `symframe relight` and `symframe view`: flags checked and turned into a job
//! configuration, one library call ([`symframe_job::fit`], [`symframe_job::relight`],
//! [`symframe_job::write_viewer`]), a summary line.

use anyhow::{bail, Result};
use glam::DVec3;
use symframe::FitParams;
use symframe_io::CacheOptions;
use symframe_job::{FitConfig, FitOutcome, RelightConfig, RelightOutcome, ViewConfig, ViewOutcome};

use crate::cli::{FitArgs, RelightArgs, ViewArgs};
use crate::progress;

/// The fit job the flags ask for.
pub fn config(args: &FitArgs) -> Result<FitConfig> {
    let decode = args.decode.options()?;
    if args.max_iterations == 0 {
        bail!("--max-iterations must be at least 1");
    }
    if !(args.max_peak_ratio >= 1.0 && args.max_peak_ratio.is_finite()) {
        bail!(
            "--max-peak-ratio must be finite and at least 1, got {}",
            args.max_peak_ratio
        );
    }
    if !(args.roughness_min > 0.0 && args.roughness_min <= 1.0) {
        bail!(
            "--roughness-min must be in (0, 1], got {}",
            args.roughness_min
        );
    }
    if args.holdout > 0 {
        // Checked here to name the flag (reading the light file is cheap).
        let n = symframe_io::open_dataset(&args.input)?.lights.len();
        FitParams::holdout_lights(n, args.holdout)
            .map_err(|e| anyhow::anyhow!("--holdout {}: {e}", args.holdout))?;
    }
    Ok(FitConfig {
        input: args.input.clone(),
        frames: args.frames.clone(),
        output: args.output.clone(),
        holdout: args.holdout,
        exposure: args.exposure.0,
        params: FitParams {
            model: args.model.model(),
            roughness_min: args.roughness_min,
            max_iterations: args.max_iterations,
            max_peak_ratio: args.max_peak_ratio,
            choice_radius: args.choice_radius,
            ..FitParams::default()
        },
        mask: args.mask.clone(),
        decode,
        cache: args.cache.config(CacheOptions::default()),
    })
}

/// Runs `symframe fit`.
pub fn run(args: &FitArgs) -> Result<FitOutcome> {
    let config = config(args)?;
    let bars = progress::Bars::new("fitting");
    let show = |p| bars.update(p);
    let done = symframe_job::fit(&config, &crate::control(&show, None))?;
    drop(bars);
    if progress::chatty() {
        let s = &done.maps.summary;
        let held = match (s.holdout_rms, s.holdout_psnr_db) {
            (Some(r), Some(p)) => format!("; held-out RMS {r:.4}, PSNR {p:.1} dB"),
            _ => String::new(),
        };
        let model = match (done.report.model, done.report.exposure) {
            ("auto", Some(e)) => format!(
                "Ward at {}, glTF at {}, clear coat at {}, woven at {} by validation lights, \
                 exposure {e:.4}",
                s.ward_pixels, s.gltf_pixels, s.clearcoat_pixels, s.woven_pixels
            ),
            (_, Some(e)) => format!("glTF, exposure {e:.4}"),
            ("clearcoat", None) => "clear coat".into(),
            (m, None) => m.replace("ward", "Ward"),
        };
        eprintln!(
            "symframe: {} pixels fitted ({model}; {} isotropic), {} without a frame, {} with too \
             few samples; training RMS {:.4}{held}; {:.1} s",
            s.anisotropic + s.isotropic,
            s.isotropic,
            s.no_frame,
            s.too_few_samples,
            s.train_rms,
            done.report.timings.total_s
        );
    }
    Ok(done)
}

/// The relight job the flags ask for.
pub fn relight_config(args: &RelightArgs) -> Result<RelightConfig> {
    for (flag, v) in [
        ("--specular-scale", args.specular_scale),
        ("--diffuse-scale", args.diffuse_scale),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            bail!("{flag} must be finite and >= 0, got {v}");
        }
    }
    if !(args.roughness_scale > 0.0 && args.roughness_scale.is_finite()) {
        bail!(
            "--roughness-scale must be finite and > 0, got {}",
            args.roughness_scale
        );
    }
    if !args.exposure.is_finite() {
        bail!("--exposure must be finite, got {}", args.exposure);
    }
    if args.rotate_tangents.is_some_and(|d| !d.is_finite()) {
        bail!("--rotate-tangents must be finite");
    }
    let mut lights: Vec<DVec3> = args.light.iter().map(|&l| DVec3::from_array(l)).collect();
    if let Some(p) = &args.lights {
        lights.extend(symframe_io::read_light_directions(p)?);
    }
    Ok(RelightConfig {
        fit_dir: args.fit_dir.clone(),
        output: args.output.clone(),
        lights,
        diffuse_scale: args.diffuse_scale,
        specular_scale: args.specular_scale,
        roughness_scale: args.roughness_scale,
        rotate_tangents: args.rotate_tangents,
        region: args.region.clone(),
        exposure: args.exposure,
        shadows: args.shadows.then(|| {
            args.depth
                .clone()
                .unwrap_or_else(|| args.fit_dir.join("depth.npy"))
        }),
        from_samples: match &args.from_samples {
            Some(capture) => Some((capture.clone(), args.decode.options()?)),
            None => None,
        },
    })
}

/// Runs `symframe relight`.
pub fn relight(args: &RelightArgs) -> Result<RelightOutcome> {
    let done = symframe_job::relight(&relight_config(args)?)?;
    for w in &done.warnings {
        eprintln!("warning: {w}");
    }
    if progress::chatty() {
        eprintln!(
            "symframe: {} pictures written into {}",
            done.pictures.len(),
            args.output.display()
        );
    }
    Ok(done)
}

/// The viewer the flags ask for.
pub fn view_config(args: &ViewArgs) -> Result<ViewConfig> {
    let mut config = ViewConfig::new(&args.fit_dir);
    if let Some(o) = &args.output {
        config.output = o.clone();
    }
    config.frames = args.frames.clone();
    config.pyramid_above = args.pyramid_above;
    config.tile_size = args.tile_size;
    config.samples = match &args.from_samples {
        Some(capture) => Some((capture.clone(), args.decode.options()?)),
        None => None,
    };
    Ok(config)
}

/// Runs `symframe view`: writes the page, prints its notes as warnings and a summary line.
pub fn view(args: &ViewArgs) -> Result<ViewOutcome> {
    let done = symframe_job::write_viewer(&view_config(args)?)?;
    for note in &done.notes {
        eprintln!("warning: {note}");
    }
    if progress::chatty() {
        eprintln!(
            "symframe: {} written ({} x {}, {:.1} MB; views: {})",
            done.path.display(),
            done.width,
            done.height,
            done.bytes as f64 / 1e6,
            done.views.join(", ")
        );
        if let Some(p) = &done.pyramid {
            eprintln!(
                "symframe: {} written ({} levels of {} px tiles, {} tiles, {:.1} MB)",
                p.dir.display(),
                p.levels,
                p.tile_size,
                p.tiles,
                p.bytes as f64 / 1e6
            );
        }
    }
    Ok(done)
}
