//! `symframe calibrate`: flags to a [`CalibrateConfig`] (light directions from one mirror
//! sphere) or, with `--K`, a [`NearCalibrateConfig`] (light positions from two or more), the
//! library's calibration (with `--matte-sphere`, the lights' intensities too), a summary.

use anyhow::{bail, Result};
use symframe_job::calibrate::{CircleDoesNotFit, SphereNotFound};
use symframe_job::{calibrate, calibrate_near, CalibrateConfig, Control, NearCalibrateConfig};

use crate::cli::CalibrateArgs;

/// Runs the command (the report is written as JSON beside the `.lp` or the positions).
pub fn run(args: &CalibrateArgs) -> Result<()> {
    let decode = args.decode.options()?;
    if !(args.threshold > 0.0 && args.threshold < 1.0) {
        bail!("--threshold must be in (0, 1), got {}", args.threshold);
    }
    if let Some(k) = &args.k {
        return run_near(args, k, decode);
    }
    if args.sphere.len() > 1 {
        bail!(
            "--sphere is given {} times: several spheres place the lights' positions, which \
             needs the camera (--K K.txt --sphere-radius R)",
            args.sphere.len()
        );
    }
    let config = CalibrateConfig {
        images: args.images.clone(),
        sphere: args.sphere.first().copied(),
        output: args.output.clone(),
        threshold: args.threshold,
        strict: args.strict,
        matte_sphere: args.matte_sphere,
        decode,
    };
    let ctl = calibrate_control();
    let report =
        calibrate(&config, &ctl).map_err(|e| match e.downcast_ref::<SphereNotFound>() {
            Some(nf) => anyhow::anyhow!("{nf}; give its circle with --sphere CX,CY,R"),
            None => match e.downcast_ref::<CircleDoesNotFit>() {
                Some(c) if c.sphere == "matte" => anyhow::anyhow!("--matte-sphere: {c}"),
                Some(c) => anyhow::anyhow!("--sphere: {c}"),
                None => e,
            },
        })?;
    if !crate::progress::chatty() {
        return Ok(());
    }
    let c = &report.sphere;
    if let Some(d) = &report.detection {
        println!(
            "symframe calibrate: found the sphere at ({:.2}, {:.2}), radius {:.2} px \
             (holds the brightest spot of {:.0}% of the images; roundness {:.3})",
            c.cx,
            c.cy,
            c.r,
            100.0 * d.highlight_share,
            d.roundness
        );
    }
    let [lp, pic, json] = &report.written;
    println!(
        "symframe calibrate: {} of {} lights from the sphere at ({:.2}, {:.2}), radius \
         {:.2} px; wrote {}, {} and {}",
        report.used,
        report.images,
        c.cx,
        c.cy,
        c.r,
        lp.display(),
        pic.display(),
        json.display()
    );
    if let (Some(path), Some(mean)) = (&report.intensities_file, report.intensity_mean_raw) {
        println!(
            "symframe calibrate: light intensities from the matte sphere (mean {mean:.4} before \
             normalising to 1): wrote {}",
            path.display()
        );
    }
    Ok(())
}

/// `calibrate --K`: light positions from two or more chrome spheres.
fn run_near(
    args: &CalibrateArgs,
    k: &std::path::Path,
    decode: symframe_io::DecodeOptions,
) -> Result<()> {
    let Some(radius) = args.sphere_radius else {
        bail!("--K needs the chrome spheres' radius: --sphere-radius R");
    };
    let config = NearCalibrateConfig {
        images: args.images.clone(),
        k_file: k.to_path_buf(),
        radius,
        spheres: args.sphere.clone(),
        output: args.output.clone(),
        threshold: args.threshold,
        strict: args.strict,
        matte_sphere: args.matte_sphere,
        matte_radius: args.matte_radius,
        decode,
    };
    let ctl = calibrate_control();
    let report = calibrate_near(&config, &ctl)?;
    if !crate::progress::chatty() {
        return Ok(());
    }
    for (i, s) in report.spheres.iter().enumerate() {
        println!(
            "symframe calibrate: sphere {} ({}): circle ({:.2}, {:.2}), radius {:.2} px; centre \
             ({:.4}, {:.4}, {:.4}) from {} points of its outline",
            i + 1,
            s.circle_source,
            s.circle.cx,
            s.circle.cy,
            s.circle.r,
            s.centre[0],
            s.centre[1],
            s.centre[2],
            s.outline_points
        );
    }
    let written: Vec<String> = report
        .written
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    println!(
        "symframe calibrate: {} light positions ({} triangulated, rms distance to their rays: \
         median {:.3e}, max {:.3e}); wrote {}",
        report.images,
        report.triangulated,
        report.residual_rms_median,
        report.residual_rms_max,
        written.join(", ")
    );
    if let Some(m) = &report.matte {
        println!(
            "symframe calibrate: light intensities from the matte sphere at ({:.4}, {:.4}, \
             {:.4}), radius {}, with each light's 1/r^2 (mean {:.4} before normalising to 1)",
            m.centre[0], m.centre[1], m.centre[2], m.radius, m.intensity_mean_raw
        );
    }
    Ok(())
}

/// The calibrations' job control: warnings on stderr, no progress display.
fn calibrate_control() -> Control<'static> {
    Control {
        warning: &|line| eprintln!("symframe calibrate: warning: {line}"),
        ..crate::control(&|_| {}, None)
    }
}
