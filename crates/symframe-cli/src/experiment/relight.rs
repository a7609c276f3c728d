//! Relighting evidence (the paper's Figures 8 and 9): per-pixel Ward fits in the
//! estimated frames, judged on lights left out of both the estimate and the fit, for Ward and
//! for models the fit cannot represent exactly; and a side-by-side picture (true render, relit
//! fit, edited fit) under a held-out light.

use std::fmt::Write as _;
use std::path::Path;

use super::{Ctx, Section};

use anyhow::Result;
use glam::DVec3;
use symframe::appearance::fit::{fit_stack, holdout_lights, FitParams};
use symframe::appearance::relight::{image_psnr, tone_map, Edits, Relighter};
use symframe::brdf::spec::parse_model;
use symframe::frames::rig::uniform_cone_lights;
use symframe::render::{Scene, TangentField};
use symframe::{estimate_stack, EstimatorParams, Rig, RigOptions, Stack};

/// Models compared: the fit's own family, then three it can only approximate.
const MODELS: [&str; 4] = [
    "ward:kd=0.4/0.3/0.2,ks=0.3/0.45/0.6,ax=0.08,ay=0.3",
    "ct:kd=0.3,ks=0.5,m=0.2,ior=1.5",
    "ggx:kd=0.1,f0=0.9,ax=0.3,ay=0.1",
    "as:rd=0.5,rs=0.05,nu=100,nv=10",
];

/// One model's figures.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// The model's name.
    pub model: String,
    /// RMS radiance error on the training samples.
    pub train_rms: f64,
    /// PSNR on the held-out samples of every fitted pixel, dB (estimated frames).
    pub holdout_psnr: f64,
    /// The same with the fit in the true frames: what the frames' errors cost.
    pub holdout_psnr_true_frames: f64,
    /// Mean PSNR of whole relit images under the held-out lights, dB.
    pub relit_psnr: f64,
}

/// Runs the experiment; writes `relight_side_by_side.png` into `out` and returns the markdown
/// section (the table printed to stdout too).
pub fn run(ctx: &Ctx) -> Result<Section<Vec<Row>>> {
    let (out, quick) = (ctx.out.as_path(), ctx.quick);
    let (size, n_lights, k) = if quick { (20, 300, 10) } else { (48, 800, 20) };
    let lights = uniform_cone_lights(n_lights, 65.0);
    let holdout = holdout_lights(n_lights, k)?;
    let train: Vec<usize> = (0..n_lights).filter(|i| !holdout.contains(i)).collect();
    let train_lights: Vec<DVec3> = train.iter().map(|&i| lights[i]).collect();
    let scene = Scene::sphere(size, TangentField::Circular);
    let cos60 = 60f64.to_radians().cos();
    let within: Vec<bool> = (0..scene.n_pixels())
        .map(|p| scene.mask[p] && scene.normals_in_camera[p].z >= cos60)
        .collect();
    let mut rows = Vec::new();
    let mut picture = None;
    for spec in MODELS {
        let brdf = parse_model(spec).map_err(anyhow::Error::msg)?;
        let stack = scene.render_stack(brdf.as_ref(), &lights);
        // Frames from the training lights only: the held-out lights are never seen.
        let mut train_stack = Stack::zeros(size, size, train.len());
        for (j, &i) in train.iter().enumerate() {
            train_stack.set_image(j, &stack.image(i));
        }
        let rig = Rig::new(&train_lights, RigOptions::default())?;
        let frames = estimate_stack(
            &train_stack,
            &rig,
            Some(&scene.mask),
            EstimatorParams::default(),
            &|_| {},
        )?;
        let params = FitParams {
            holdout: holdout.clone(),
            ..FitParams::default()
        };
        let fit = fit_stack(
            &stack,
            &lights,
            &frames.normals,
            &frames.tangents,
            Some(&scene.mask),
            &params,
            &|_| {},
        )?;
        let true_frames = fit_stack(
            &stack,
            &lights,
            &scene.gt_normals(),
            &scene.gt_tangents(),
            Some(&scene.mask),
            &params,
            &|_| {},
        )?;
        let relighter = Relighter::new(&fit.ward, &Edits::default())?;
        let psnrs: Vec<f64> = holdout
            .iter()
            .map(|&i| image_psnr(&relighter.render(lights[i]), &stack.image(i), Some(&within)))
            .collect();
        rows.push(Row {
            model: brdf.name(),
            train_rms: fit.summary.train_rms,
            holdout_psnr: fit.summary.holdout_psnr_db.unwrap_or(f64::NAN),
            holdout_psnr_true_frames: true_frames.summary.holdout_psnr_db.unwrap_or(f64::NAN),
            relit_psnr: psnrs.iter().sum::<f64>() / psnrs.len() as f64,
        });
        if picture.is_none() {
            // The paper's edit: tangents turned 90 degrees inside a region (a disc here).
            let c = size as f64 / 2.0;
            let region: Vec<bool> = (0..size * size)
                .map(|p| {
                    let (x, y) = ((p % size) as f64 + 0.5 - c, (p / size) as f64 + 0.5 - c);
                    x * x + y * y < (0.35 * size as f64).powi(2)
                })
                .collect();
            let edits = Edits {
                tangent_rotation_deg: 90.0,
                region: Some(region),
                ..Edits::default()
            };
            let edited = Relighter::new(&fit.ward, &edits)?;
            // The held-out light closest to 40 degrees from the view: a visible highlight.
            let &light = holdout
                .iter()
                .map(|&i| &lights[i])
                .min_by(|a, b| {
                    (a.z - 40f64.to_radians().cos())
                        .abs()
                        .total_cmp(&(b.z - 40f64.to_radians().cos()).abs())
                })
                .expect("held-out lights");
            picture = Some([
                scene.render(brdf.as_ref(), light),
                relighter.render(light),
                edited.render(light),
            ]);
        }
    }
    let mut md = String::new();
    writeln!(
        md,
        "## Relighting from per-pixel Ward fits (paper Section 5.1, Figures 8-9)\n"
    )?;
    writeln!(
        md,
        "A {size} x {size} sphere (circular tangent field) under {n_lights} lights uniform over the \
         65-degree cone; {k} evenly spread lights are held out of both the frame estimate \
         (symmetry method, default settings) and the fit. PSNR = `20 log10(peak / RMS)` with \
         the peak the largest true value; \"held-out samples\" is over every fitted pixel \
         (fitted in the estimated frames, and for comparison in the true ones), \"relit \
         images\" the mean over the held-out lights of whole relit images against true \
         renders, over pixels within 60 degrees of the view.\n"
    )?;
    writeln!(
        md,
        "| model | training RMS | held-out samples PSNR (dB) | the same, true frames (dB) | \
         relit images PSNR (dB) |"
    )?;
    writeln!(md, "| --- | --- | --- | --- | --- |")?;
    for r in &rows {
        writeln!(
            md,
            "| `{}` | {:.4} | {:.1} | {:.1} | {:.1} |",
            r.model, r.train_rms, r.holdout_psnr, r.holdout_psnr_true_frames, r.relit_psnr
        )?;
    }
    if let Some([truth, relit, edited]) = picture {
        let path = out.join("relight_side_by_side.png");
        write_side_by_side(&path, size, &[truth, relit, edited])?;
        writeln!(
            md,
            "\n![true, relit, edited]({}relight_side_by_side.png)\n\nLeft to right: true render \
             under a held-out light, the relit Ward fit, and the fit with its tangents turned 90 \
             degrees inside a disc (the paper's logo edit).\n",
            ctx.link
        )?;
    }
    print!("{md}");
    Ok(Section {
        markdown: md,
        figures: rows,
    })
}

/// Writes images side by side (tone-mapped, 4x enlarged, 8-pixel gaps) as one sRGB PNG.
fn write_side_by_side(path: &Path, size: usize, images: &[Vec<f32>]) -> Result<()> {
    let scale = 4;
    let gap = 8;
    let s = size * scale;
    let width = images.len() * s + (images.len() - 1) * gap;
    let mut rgb = vec![1.0f32; width * s * 3];
    let peak = images[0]
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f32, f32::max)
        .max(1e-6);
    let exposure = -(peak as f64).log2();
    for (k, img) in images.iter().enumerate() {
        let mapped = tone_map(img, exposure);
        for y in 0..s {
            for x in 0..s {
                let src = ((y / scale) * size + x / scale) * 3;
                let dst = (y * width + k * (s + gap) + x) * 3;
                rgb[dst..dst + 3].copy_from_slice(&mapped[src..src + 3]);
            }
        }
    }
    symframe_io::write_png8_rgb(path, width, s, &rgb, true)?;
    Ok(())
}
