//! `symframe demo`: renders a built-in anisotropic sphere, writes it as an `.lp` dataset, runs
//! the same pipeline as `symframe estimate` on it, and reports the error against ground truth.

use std::time::Instant;

use anyhow::{Context, Result};
use rayon::prelude::*;
use symframe::brdf::ward::Ward;
use symframe::brdf::Brdf;
use symframe::eval::evaluate;
use symframe::render::{Scene, TangentField};
use symframe::rig::uniform_cone_lights;
use symframe_io::ImageFormat;

use crate::cli::{CosineArg, DemoArgs, EstimateArgs, MethodArg};
use crate::progress;

/// Runs the demo.
pub fn run(args: &DemoArgs) -> Result<()> {
    if !(8..=2048).contains(&args.size) {
        anyhow::bail!("--size must be between 8 and 2048, got {}", args.size);
    }
    if !(16..=20000).contains(&args.lights) {
        anyhow::bail!("--lights must be between 16 and 20000, got {}", args.lights);
    }
    let t0 = Instant::now();
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let scene = Scene::sphere(args.size, TangentField::Circular);
    let lights = uniform_cone_lights(args.lights, 65.0);
    eprintln!(
        "symframe demo: rendering a {0}x{0} sphere of brushed material ({1}) under {2} lights",
        args.size,
        brdf.name(),
        args.lights
    );
    let bar = progress::bar(lights.len() as u64, "rendering");
    let images: Vec<Vec<f32>> = lights
        .par_iter()
        .map(|&l| {
            let img = scene.render(&brdf, l);
            bar.inc(1);
            img
        })
        .collect();
    bar.finish_and_clear();
    let dataset_dir = args.output.join("dataset");
    let lp = symframe_io::write_lp_dataset(
        &dataset_dir,
        &lights,
        &images,
        scene.width,
        scene.height,
        ImageFormat::Exr,
        Some(&scene.gt_normals()),
        Some(&scene.gt_tangents()),
        Some(&scene.mask),
    )
    .context("writing the demo dataset")?;
    drop(images);

    let estimate_dir = args.output.join("estimate");
    let est_args = EstimateArgs {
        input: lp.clone(),
        output: estimate_dir.clone(),
        method: MethodArg::Symmetry,
        mask: None,
        theta_d_max: 65.0,
        min_confidence: 0.0,
        min_anisotropy: 0.6,
        min_domain: None,
        cosine: CosineArg::Cross,
        cosine_power: 0.5,
        linear: false,
        saturation: 0.995,
        no_tangents: false,
    };
    eprintln!(
        "symframe demo: estimating normals and tangents from {}",
        lp.display()
    );
    let (maps, _report) = crate::estimate::run(&est_args)?;
    let e = evaluate(
        &maps.normals,
        &maps.tangents,
        &scene.gt_normals(),
        Some(&scene.gt_tangents()),
        Some(&scene.mask),
        60.0,
    );
    let eval_path = estimate_dir.join("eval.json");
    std::fs::write(&eval_path, serde_json::to_string_pretty(&e)? + "\n")
        .with_context(|| format!("{}: cannot write", eval_path.display()))?;
    println!(
        "normal error (pixels within 60 deg of the view): mean {:.2} deg, median {:.2}, 90th pct {:.2}; coverage {:.1}%",
        e.normal_error.mean,
        e.normal_error.median,
        e.normal_error.p90,
        100.0 * e.coverage
    );
    println!(
        "tangent axis error: mean {:.2} deg, median {:.2}, 90th pct {:.2}; t/b swapped at {:.1}% of pixels",
        e.tangent_error.mean,
        e.tangent_error.median,
        e.tangent_error.p90,
        100.0 * e.swapped_share
    );
    println!("dataset:  {}", lp.display());
    println!(
        "pictures: {} and {} (also confidence.png; maps as .npy and .exr, report.json)",
        estimate_dir.join("normals.png").display(),
        estimate_dir.join("tangents.png").display()
    );
    println!("done in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}
