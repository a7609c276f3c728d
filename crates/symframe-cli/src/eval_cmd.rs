//! `symframe eval`: flags to an [`EvalConfig`], the library's evaluation, a summary table.

use anyhow::{bail, Result};
use symframe::ErrorStats;
use symframe_job::{evaluate_job, EvalConfig, EvalReport};

use crate::cli::EvalArgs;

/// One row of the summary table.
fn row(name: &str, s: &ErrorStats, share: Option<f64>) -> String {
    let f = |v: f64| {
        if v.is_finite() {
            format!("{v:>8.3}")
        } else {
            format!("{:>8}", "-")
        }
    };
    let share = share.map_or(format!("{:>9}", "-"), |c| format!("{:>8.1}%", 100.0 * c));
    format!(
        "{name:<22}{:>8}{share}{}{}{}{}",
        s.count,
        f(s.mean),
        f(s.median),
        f(s.p90),
        f(s.max)
    )
}

/// Runs the command; returns what was written to `eval.json`.
pub fn run(args: &EvalArgs) -> Result<EvalReport> {
    if !(args.max_angle > 0.0 && args.max_angle <= 90.0) {
        bail!(
            "--max-angle must be in (0, 90] degrees, got {}",
            args.max_angle
        );
    }
    if let Some(s) = args.scale_max {
        if !(s > 0.0 && s.is_finite()) {
            bail!("--scale-max must be a positive number of degrees, got {s}");
        }
    }
    let report = evaluate_job(
        &EvalConfig {
            dataset: args.dataset.clone(),
            estimate: args.estimate.clone(),
            max_angle: args.max_angle,
            scale_max: args.scale_max,
        },
        &crate::control(&|_| {}, None),
    )?;
    if !crate::progress::chatty() {
        return Ok(report);
    }
    let est = &args.estimate;
    let tangents = report.tangent_scale_max_deg.is_some();
    let e = &report.evaluation;
    println!(
        "{} against {} (pixels within {} deg of the view: {}){}",
        est.display(),
        report.dataset.display(),
        e.max_normal_angle_deg,
        e.pixels,
        report
            .method
            .as_ref()
            .map_or(String::new(), |m| format!(", method {m}"))
    );
    println!(
        "{:<22}{:>8}{:>9}{:>8}{:>8}{:>8}{:>8}",
        "error (deg)", "pixels", "share", "mean", "median", "p90", "max"
    );
    println!("{}", row("normal", &e.normal_error, Some(e.coverage)));
    if tangents {
        println!(
            "{}",
            row("tangent axis", &e.tangent_error, Some(e.tangent_coverage))
        );
        println!(
            "{}",
            row("tangent, t/b free", &e.tangent_error_swap_free, None)
        );
        println!(
            "t and b swapped at {:.1}% of the pixels with a tangent",
            100.0 * e.swapped_share
        );
    } else {
        println!("(no gt_tangents.npy: tangents not evaluated)");
    }
    println!(
        "wrote {} and {}{}",
        est.join("eval.json").display(),
        est.join("normal_error.png").display(),
        if tangents { ", tangent_error.png" } else { "" }
    );
    Ok(report)
}
