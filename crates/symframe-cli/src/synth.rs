//! `symframe synth`: flags to a [`SynthConfig`], the library's renderer, a summary. The
//! dataset is an `.lp` folder with ground truth and `scene.json`; `symframe estimate DIR`
//! reads it back.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use symframe_io::ImageFormat;
use symframe_job::{synth, synth_near, NearSynthConfig, RigSpec, SynthConfig, SynthShape};

use crate::cli::{FormatArg, ShapeArg, SynthArgs};
use crate::progress;

/// Checks the flags that clap cannot, and that shape-specific flags go with their shape.
fn validate(args: &SynthArgs) -> Result<()> {
    if !(8..=2048).contains(&args.size) {
        bail!("--size must be between 8 and 2048, got {}", args.size);
    }
    if !(0.0..1.0).contains(&args.intensity_spread) {
        bail!(
            "--intensity-spread must be in [0, 1), got {}",
            args.intensity_spread
        );
    }
    if !(args.exposure.is_finite() && args.exposure > 0.0) {
        bail!(
            "--exposure must be a positive number, got {}",
            args.exposure
        );
    }
    let plane_only = [
        ("--normal-angle", args.normal_angle),
        ("--normal-azimuth", args.normal_azimuth),
        ("--tangent-angle", args.tangent_angle),
    ];
    for (flag, value) in plane_only {
        if let Some(v) = value {
            if args.shape != ShapeArg::Plane {
                bail!("{flag} applies to --shape plane only");
            }
            if !v.is_finite() {
                bail!("{flag} must be a finite number of degrees, got {v}");
            }
        }
    }
    if let Some(a) = args.normal_angle {
        if !(0.0..90.0).contains(&a) {
            bail!("--normal-angle must be in [0, 90) degrees, got {a}");
        }
    }
    if args.tangent_angle.is_some() && args.tangent_field.is_some() {
        bail!("--tangent-angle and --tangent-field are exclusive: give one");
    }
    if args.shape != ShapeArg::Bumps && (args.bumps.is_some() || args.relief.is_some()) {
        bail!("--bumps and --relief apply to --shape bumps only");
    }
    if let Some(n) = args.bumps {
        if !(1..=1000).contains(&n) {
            bail!("--bumps must be between 1 and 1000, got {n}");
        }
    }
    if let Some(r) = args.relief {
        if !(r.is_finite() && r > 0.0) {
            bail!("--relief must be a positive number, got {r}");
        }
    }
    Ok(())
}

/// Runs the command; returns the path of the written `lights.lp`.
pub fn run(args: &SynthArgs) -> Result<PathBuf> {
    if args.near {
        return run_near(args);
    }
    validate(args)?;
    let t0 = Instant::now();
    let config = SynthConfig {
        output: args.output.clone(),
        force: args.force,
        shape: match args.shape {
            ShapeArg::Sphere => SynthShape::Sphere,
            ShapeArg::Cylinder => SynthShape::Cylinder,
            ShapeArg::Plane => SynthShape::Plane,
            ShapeArg::Bumps => SynthShape::Bumps,
        },
        size: args.size,
        model: args.model.clone(),
        tangent_field: args.tangent_field.clone(),
        rig: RigSpec::parse(&args.rig).map_err(|e| anyhow::anyhow!("--{e}"))?,
        normal_angle: args.normal_angle,
        normal_azimuth: args.normal_azimuth,
        tangent_angle: args.tangent_angle,
        bumps: args.bumps,
        relief: args.relief,
        noise: args.noise.clone(),
        format: match args.format {
            FormatArg::Exr => ImageFormat::Exr,
            FormatArg::Png16 => ImageFormat::Png16,
            FormatArg::Png8 => ImageFormat::Png8,
        },
        exposure: args.exposure,
        seed: args.seed,
        chrome_sphere: args.chrome_sphere,
        matte_sphere: args.matte_sphere,
        intensity_spread: args.intensity_spread,
    };
    let bars = progress::Bars::default();
    let done = synth(&config, &crate::control(&|p| bars.update(p), None))?;
    drop(bars);
    if progress::chatty() {
        eprintln!(
            "symframe synth: rendered a {0}x{0} {1:?} of {2} under {3} lights; wrote {3} images \
             to {4} in {5:.1} s",
            args.size,
            args.shape,
            done.model,
            done.lights,
            args.output.display(),
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(done.lp)
}

/// `synth --near`: the two-sphere near-light capture ([`NearSynthConfig`]).
fn run_near(args: &SynthArgs) -> Result<PathBuf> {
    let distant_only = [
        ("--shape", args.shape != ShapeArg::Sphere),
        ("--rig", args.rig != "cone:1000"),
        ("--tangent-field", args.tangent_field.is_some()),
        ("--normal-angle", args.normal_angle.is_some()),
        ("--normal-azimuth", args.normal_azimuth.is_some()),
        ("--tangent-angle", args.tangent_angle.is_some()),
        ("--bumps", args.bumps.is_some()),
        ("--relief", args.relief.is_some()),
        ("--matte-sphere", args.matte_sphere),
        ("--intensity-spread", args.intensity_spread != 0.0),
    ];
    if let Some((flag, _)) = distant_only.iter().find(|(_, given)| *given) {
        bail!("{flag} does not apply to --near (two spheres under a dome of point lights)");
    }
    let t0 = Instant::now();
    let mut config = NearSynthConfig::new(args.output.clone());
    if args.model != "ward" {
        config.models[0] = args.model.clone();
    }
    if let Some(m) = &args.second_model {
        config.models[1] = m.clone();
    }
    config.force = args.force;
    config.size = args.size;
    config.lights = args.dome_lights;
    config.dome_ratio = args.dome_ratio;
    config.camera_ratio = args.camera_ratio;
    config.noise = args.noise.clone();
    config.format = match args.format {
        FormatArg::Exr => ImageFormat::Exr,
        FormatArg::Png16 => ImageFormat::Png16,
        FormatArg::Png8 => ImageFormat::Png8,
    };
    config.exposure = args.exposure;
    config.seed = args.seed;
    config.chrome_spheres = args.chrome_sphere;
    let bars = progress::Bars::default();
    let done = synth_near(&config, &crate::control(&|p| bars.update(p), None))?;
    drop(bars);
    if progress::chatty() {
        eprintln!(
            "symframe synth --near: rendered {} under {} point lights; wrote {} images to {} in \
             {:.1} s",
            done.model,
            done.lights,
            done.lights,
            args.output.display(),
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(done.lp)
}
