//! `symframe demo`: renders a built-in anisotropic sphere, writes it as an `.lp` dataset, runs
//! the estimation job on it with every default (as `symframe estimate` does), and reports the
//! error against ground truth (the eval job: `eval.json` and the error pictures); then fits a Ward BRDF per pixel in the estimated frames (the fit
//! job, on the estimate's tile cache) and relights it under a new light, plain and with the
//! tangents turned by 90 degrees inside a letter-shaped region, as in the paper's Section 5.1;
//! and writes the fit's viewer page (`fit/viewer.html`).

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use symframe::brdf::{Brdf, Ward};
use symframe::render::{Scene, TangentField};
use symframe::uniform_cone_lights;
use symframe_io::ImageFormat;

use glam::DVec3;
use symframe_job::{
    EstimateConfig, EstimateOutcome, EvalConfig, FitConfig, RelightConfig, ViewConfig,
};

use crate::cli::DemoArgs;
use crate::progress;

/// `println!` unless `--quiet`.
macro_rules! say {
    ($($t:tt)*) => {
        if progress::chatty() {
            println!($($t)*);
        }
    };
}

/// `eprintln!` unless `--quiet`.
macro_rules! note {
    ($($t:tt)*) => {
        if progress::chatty() {
            eprintln!($($t)*);
        }
    };
}

/// Runs the demo.
pub fn run(args: &DemoArgs) -> Result<()> {
    if !(8..=2048).contains(&args.size) {
        anyhow::bail!("--size must be between 8 and 2048, got {}", args.size);
    }
    if !(16..=20000).contains(&args.lights) {
        anyhow::bail!("--lights must be between 16 and 20000, got {}", args.lights);
    }
    check_target(&args.output, args.force)?;
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("{}: cannot create the folder", args.output.display()))?;
    let marker = args.output.join(MARKER);
    symframe_io::write_bytes(
        &marker,
        b"Written by symframe demo: a later `symframe demo -o` may replace what it wrote here.\n",
    )?;
    let t0 = Instant::now();
    let brdf = Ward::new([0.5; 3], [0.5; 3], 0.1, 0.5);
    let scene = Scene::sphere(args.size, TangentField::Circular);
    let lights = uniform_cone_lights(args.lights, 65.0);
    note!(
        "symframe demo: rendering a {0}x{0} sphere of brushed material ({1}) under {2} lights",
        args.size,
        brdf.name(),
        args.lights
    );
    let bar = progress::bar(lights.len() as u64, "rendering", "images");
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
    note!(
        "symframe demo: estimating normals and tangents from {}",
        lp.display()
    );
    let bars = progress::Bars::default();
    let show = |p| bars.update(p);
    let ctl = crate::control(&show, None);
    let mut estimate = EstimateConfig::new(&lp, &estimate_dir);
    // Evaluated from the files below: nothing needs the whole maps in memory.
    estimate.keep_maps = false;
    let EstimateOutcome::Maps(_) = symframe_job::estimate(&estimate, &ctl)? else {
        unreachable!("the demo does not run shards");
    };
    // The eval job on the estimate and the dataset's ground truth: eval.json and the error
    // pictures with their colour bars, beside the maps.
    let report = symframe_job::evaluate_job(&EvalConfig::new(&dataset_dir, &estimate_dir), &ctl)?;
    let e = &report.evaluation;
    say!(
        "normal error (pixels within 60 deg of the view): mean {:.2} deg, median {:.2}, 90th pct {:.2}; coverage {:.1}%",
        e.normal_error.mean,
        e.normal_error.median,
        e.normal_error.p90,
        100.0 * e.coverage
    );
    say!(
        "tangent axis error: mean {:.2} deg, median {:.2}, 90th pct {:.2}; t/b swapped at {:.1}% of pixels",
        e.tangent_error.mean,
        e.tangent_error.median,
        e.tangent_error.p90,
        100.0 * e.swapped_share
    );
    say!("dataset:  {}", lp.display());
    say!(
        "pictures: {} and {} (also confidence, residual, source and lights; maps as .npy and .exr, report.json)",
        estimate_dir.join("normals.png").display(),
        estimate_dir.join("tangents.png").display()
    );
    say!(
        "errors:   {} and {} (angular error against the ground truth, colour bars in degrees)",
        estimate_dir.join("normal_error.png").display(),
        estimate_dir.join("tangent_error.png").display()
    );
    say!(
        "overview: {} (every picture with its legend, and the run's summary)",
        estimate_dir.join("index.html").display()
    );

    // Section 5.1: per-pixel Ward fit in the estimated frames, relit and edited.
    let fit_dir = args.output.join("fit");
    let mut fit_config = FitConfig::new(&lp, &estimate_dir, &fit_dir);
    fit_config.holdout = (args.lights / 50).max(1);
    // The paper's Ward fit, which the figures below compare with the rendered Ward material
    // (`symframe fit` chooses among four models by default).
    fit_config.params.model = symframe::FitModel::Ward;
    // The estimate's tile cache is read again here, then removed.
    fit_config.cache.remove_after = true;
    note!("symframe demo: fitting a Ward BRDF per pixel in the estimated frames");
    let fit = symframe_job::fit(&fit_config, &ctl)?.maps;
    drop(bars);
    let errs = fit_errors(&fit.ward, &scene, &brdf);
    say!(
        "Ward fit vs truth (median relative error within 60 deg): kd {:.1}%, ks {:.1}%, wide roughness {:.1}%, narrow {:.1}%",
        errs[0], errs[1], errs[2], errs[3]
    );
    if let (Some(rms), Some(psnr)) = (fit.summary.holdout_rms, fit.summary.holdout_psnr_db) {
        say!(
            "Ward fit on {} held-out lights: RMS {rms:.4}, PSNR {psnr:.1} dB",
            fit_config.holdout
        );
    }
    let region_path = args.output.join("region.png");
    let region = letter_region(scene.width, scene.height);
    let region_rgb: Vec<f32> = region.iter().flat_map(|&m| [m as u8 as f32; 3]).collect();
    symframe_io::write_png8_rgb(&region_path, scene.width, scene.height, &region_rgb, false)?;
    let new_light = [-0.25, 0.3, 0.92];
    let mut relight = RelightConfig::new(&fit_dir, args.output.join("relit"));
    relight.lights = vec![DVec3::from_array(new_light)];
    let relit = symframe_job::relight(&relight)?.pictures;
    relight.output = args.output.join("relit-edited");
    relight.rotate_tangents = Some(90.0);
    relight.region = Some(region_path.clone());
    let edited = symframe_job::relight(&relight)?.pictures;
    say!(
        "relit under a new light ({}, {}, {}): {}",
        new_light[0],
        new_light[1],
        new_light[2],
        relit[0].display()
    );
    say!(
        "edited (tangents turned 90 deg inside {}): {}",
        region_path.display(),
        edited[0].display()
    );
    // The interactive viewer of the fit (estimate maps included).
    let mut view = ViewConfig::new(&fit_dir);
    view.frames = Some(estimate_dir.clone());
    let viewer = symframe_job::write_viewer(&view)?;
    say!(
        "viewer:   {} (open it in a browser; drag the ball to move the light)",
        viewer.path.display()
    );
    say!("done in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// The file that marks a folder as the demo's: a later demo may replace what it wrote there.
const MARKER: &str = ".symframe-demo";

/// What the demo writes into its folder.
const OUTPUTS: [&str; 6] = [
    "dataset",
    "estimate",
    "fit",
    "relit",
    "relit-edited",
    "region.png",
];

/// Whether the demo may write into `dir`: yes if `dir` holds the [`MARKER`] of an earlier demo,
/// or none of the [`OUTPUTS`] is there but as an empty folder (or one holding only a job's lock
/// file); else an error naming the first one in the way (a user's folder or file, which must
/// not be replaced), unless `force`. The rule of `symframe synth` and its `.symframe-synth`.
fn check_target(dir: &Path, force: bool) -> Result<()> {
    if force || dir.join(MARKER).is_file() {
        return Ok(());
    }
    if dir.exists() && !dir.is_dir() {
        bail!("{}: exists and is not a folder", dir.display());
    }
    for name in OUTPUTS {
        let p = dir.join(name);
        let in_the_way = match std::fs::symlink_metadata(&p) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
            Err(e) => return Err(e).with_context(|| format!("{}: cannot read", p.display())),
            Ok(m) if m.is_dir() => std::fs::read_dir(&p)
                .with_context(|| format!("{}: cannot read", p.display()))?
                .flatten()
                .any(|e| e.file_name() != symframe_io::OUTPUT_LOCK_FILE),
            Ok(_) => true,
        };
        if in_the_way {
            bail!(
                "{}: not written by symframe demo (no {MARKER} in {}) and not empty: refusing \
                 to replace it; give a new or empty folder, or --force",
                p.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// A letter "T" over the middle of a `width x height` image, as the region of the tangent edit.
fn letter_region(width: usize, height: usize) -> Vec<bool> {
    let (w, h) = (width as f64, height as f64);
    (0..width * height)
        .map(|p| {
            let (x, y) = (
                ((p % width) as f64 + 0.5) / w,
                ((p / width) as f64 + 0.5) / h,
            );
            let bar = (0.2..0.8).contains(&x) && (0.2..0.36).contains(&y);
            let stem = (0.42..0.58).contains(&x) && (0.2..0.82).contains(&y);
            bar || stem
        })
        .collect()
}

/// Median relative errors (percent) of the fitted kd, ks, wide and narrow roughness against the
/// demo's material, over pixels within 60 degrees of the view (roughnesses compared sorted, so a
/// t/b swap of the estimated frame does not count).
fn fit_errors(maps: &symframe::WardMaps, scene: &Scene, brdf: &Ward) -> [f64; 4] {
    let cos60 = 0.5;
    let mut e: [Vec<f64>; 4] = Default::default();
    let (wide, narrow) = (
        brdf.alpha_x.max(brdf.alpha_y),
        brdf.alpha_x.min(brdf.alpha_y),
    );
    for p in 0..scene.n_pixels() {
        if !scene.mask[p] || scene.normals_in_camera[p].z < cos60 || maps.alpha_t[p].is_nan() {
            continue;
        }
        let rel = |v: f32, t: f64| 100.0 * (v as f64 / t - 1.0).abs();
        e[0].push(rel(maps.kd[p * 3 + 1], brdf.kd[1]));
        e[1].push(rel(maps.ks[p * 3 + 1], brdf.ks[1]));
        let (at, ab) = (maps.alpha_t[p], maps.alpha_b[p]);
        e[2].push(rel(at.max(ab), wide));
        e[3].push(rel(at.min(ab), narrow));
    }
    e.map(|mut v| {
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    })
}
