//! `symframe calibrate`: flags to a [`CalibrateConfig`], the library's calibration, a summary.

use anyhow::{bail, Result};
use symframe_job::calibrate::{CircleDoesNotFit, SphereNotFound};
use symframe_job::{calibrate, CalibrateConfig, CalibrationReport, Control};

use crate::cli::CalibrateArgs;

/// Runs the command; returns the report (also written as JSON beside the `.lp`).
pub fn run(args: &CalibrateArgs) -> Result<CalibrationReport> {
    let decode = args.decode.options()?;
    if !(args.threshold > 0.0 && args.threshold < 1.0) {
        bail!("--threshold must be in (0, 1), got {}", args.threshold);
    }
    let config = CalibrateConfig {
        images: args.images.clone(),
        sphere: args.sphere,
        output: args.output.clone(),
        threshold: args.threshold,
        strict: args.strict,
        matte_sphere: args.matte_sphere,
        decode,
    };
    let ctl = Control {
        warning: &|line| eprintln!("symframe calibrate: warning: {line}"),
        ..crate::control(&|_| {}, None)
    };
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
        return Ok(report);
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
    Ok(report)
}
