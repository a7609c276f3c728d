//! `symframe integrate`: flags to an [`IntegrateConfig`], the library's integrate job, a
//! summary.

use anyhow::{bail, Result};
use symframe::{DepthMap, IntegrateParams, Solver};
use symframe_job::{integrate_job, IntegrateConfig, IntegrateReport};

use crate::cli::{IntegrateArgs, IntegrateSolverArg};

/// Runs the command; returns the height map and the report written.
pub fn run(args: &IntegrateArgs) -> Result<(DepthMap, IntegrateReport)> {
    if !(args.max_jump.is_finite() && args.max_jump > 0.0) {
        bail!(
            "--max-jump must be a positive number, got {}",
            args.max_jump
        );
    }
    if !(args.k.is_finite() && args.k > 0.0) {
        bail!("--k must be a positive number, got {}", args.k);
    }
    if !(args.tolerance > 0.0 && args.tolerance < 1.0) {
        bail!("--tolerance must be in (0, 1), got {}", args.tolerance);
    }
    let solver = match args.solver {
        IntegrateSolverArg::Poisson => Solver::Poisson,
        IntegrateSolverArg::Bilateral => Solver::Bilateral {
            k: args.k,
            max_iterations: args.max_iterations,
            tolerance: 1e-4,
        },
    };
    let config = IntegrateConfig {
        estimate: args.estimate.clone(),
        output: args.output.clone(),
        params: IntegrateParams {
            solver,
            cg_tolerance: args.tolerance,
            ..IntegrateParams::default()
        },
        use_confidence: !args.no_confidence,
        max_jump: args.max_jump,
        camera: args.camera.clone(),
        distance: args.distance,
    };
    let (depth, report) = integrate_job(&config)?;
    if !crate::progress::chatty() {
        return Ok((depth, report));
    }
    println!(
        "symframe integrate: {} pixels ({} region(s)) by {}{} in {:.2} s ({} CG iterations{}), \
         mesh {} vertices, {} triangles ({} dropped at discontinuities), peak memory {} MiB; \
         wrote {}",
        report.pixels,
        report.regions,
        report.solver,
        if report.camera.is_some() {
            " through the pinhole camera"
        } else {
            ""
        },
        report.integrate_s,
        report.cg_iterations,
        if report.reweight_iterations > 0 {
            format!(", {} reweightings", report.reweight_iterations)
        } else {
            String::new()
        },
        report.vertices,
        report.triangles,
        report.triangles_dropped,
        report.peak_rss_bytes.unwrap_or(0) >> 20,
        args.output.display()
    );
    Ok((depth, report))
}
