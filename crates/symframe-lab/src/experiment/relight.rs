//! Relighting evidence (the paper's Figures 8 and 9): per-pixel Ward, glTF and two-lobe fits in
//! the estimated frames, judged on lights left out of both the estimate and the fit, on models
//! a fit represents exactly and on models none does; and a side-by-side picture (true render,
//! relit fit, edited fit) under a held-out light.
//!
//! `SYMFRAME_RELIGHT_MATERIALS` (comma-separated words) limits a run to the materials whose
//! label contains one of them, for a quicker look at a few (e.g. `car paint,woven`).

use std::fmt::Write as _;
use std::path::Path;

use super::{Ctx, Section};

use anyhow::Result;
use glam::DVec3;
use symframe::brdf::{parse_model, Brdf, Ggx, Layered, Woven};
use symframe::render::{BumpParams, Scene, TangentField};
use symframe::{
    estimate_stack, uniform_cone_lights, DepthMap, Edits, EstimatorParams, FitMaps, FitModel,
    FitParams, IntegrateParams, PixelData, Relighter, Rig, RigOptions, SampleRelighter, Stack,
};

/// Models rendered on the sphere: a brushed Ward material (the Ward fit's own family), two GGX
/// plastics, a glTF plastic and a brushed glTF metal (the glTF fit's family), and five that
/// neither fit represents exactly (a brushed GGX metal with a diffuse base, Cook-Torrance,
/// Ashikhmin-Shirley, Beckmann brushed gold and a rougher GGX plastic).
const MODELS: [&str; 10] = [
    "ward:kd=0.4/0.3/0.2,ks=0.3/0.45/0.6,ax=0.08,ay=0.3",
    "ggx:kd=0.5/0.3/0.2,f0=0.04,alpha=0.15",
    "ggx:kd=0.5/0.3/0.2,f0=0.04,alpha=0.05",
    "gltf:base=0.6/0.35/0.2,metallic=0,roughness=0.4",
    "gltf:base=0.9/0.75/0.5,metallic=1,roughness=0.3,anisotropy=0.6",
    "ggx:kd=0.1,f0=0.9,ax=0.3,ay=0.1",
    "ct:kd=0.3,ks=0.5,m=0.2,ior=1.5",
    "as:rd=0.5,rs=0.05,nu=100,nv=10",
    "beckmann:kd=0,f0=1/0.71/0.29,ax=0.25,ay=0.06",
    "ggx:kd=0.4/0.25/0.15,f0=0.04,alpha=0.3",
];

/// One material of the experiment: a label, its BRDF, whether it is rendered on the bumpy
/// surface (with cast shadows) instead of the sphere, and whether the fit leaves out the
/// samples the relief integrated from the estimated normals shadows.
struct Material {
    label: String,
    brdf: Box<dyn Brdf>,
    bumpy: bool,
    drop_shadowed: bool,
}

/// Every material: [`MODELS`] on the sphere, then the two-lobe and woven materials of the
/// capture sweep (car paint: a sharp isotropic clear coat over a brushed metallic base; woven
/// satin: two perpendicular anisotropic lobes over a diffuse base) on the sphere, and a
/// brushed GGX metal with a diffuse base on the bumpy surface, shadows on.
fn materials() -> Result<Vec<Material>> {
    let mut m = Vec::new();
    for spec in MODELS {
        let brdf = parse_model(spec).map_err(anyhow::Error::msg)?;
        m.push(Material {
            label: format!("`{}`", brdf.name()),
            brdf,
            bumpy: false,
            drop_shadowed: false,
        });
    }
    m.push(Material {
        label: "car paint (coat 0.03 over brushed GGX 0.35 / 0.12)".into(),
        brdf: Box::new(Layered::new(
            0.03,
            1.5,
            Box::new(Ggx::new([0.05, 0.08, 0.25], [0.5, 0.5, 0.6], 0.35, 0.12)),
        )),
        bumpy: false,
        drop_shadowed: false,
    });
    m.push(Material {
        label: "woven satin (lobes 0.35 / 0.08 and 0.08 / 0.35, weft 0.5)".into(),
        brdf: Box::new(Woven::new([0.25, 0.08, 0.08], [0.05; 3], 0.35, 0.08, 0.5)),
        bumpy: false,
        drop_shadowed: false,
    });
    let bumpy = || Box::new(Ggx::new([0.3, 0.22, 0.15], [0.5; 3], 0.3, 0.08));
    m.push(Material {
        label: "bumps, brushed GGX 0.3 / 0.08 (kd 0.3, f0 0.5), every sample".into(),
        brdf: bumpy(),
        bumpy: true,
        drop_shadowed: false,
    });
    m.push(Material {
        label: "the same, shadowed samples left out".into(),
        brdf: bumpy(),
        bumpy: true,
        drop_shadowed: true,
    });
    if let Ok(only) = std::env::var("SYMFRAME_RELIGHT_MATERIALS") {
        let words: Vec<&str> = only
            .split(',')
            .map(str::trim)
            .filter(|w| !w.is_empty())
            .collect();
        m.retain(|mat| words.iter().any(|w| mat.label.contains(w)));
    }
    Ok(m)
}

/// The fits compared on every model: the single models, then the automatic choice (last).
const FITS: [FitModel; 5] = [
    FitModel::Ward,
    FitModel::Gltf,
    FitModel::Clearcoat,
    FitModel::Woven,
    FitModel::Auto,
];

/// The bumpy surface: the bumps of the materials experiment.
const BUMPS: BumpParams = BumpParams {
    count: 10,
    relief: 1.0,
    seed: 5,
};

/// One model's figures.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// The model's name.
    pub model: String,
    /// The model fitted: `ward`, `gltf`, `clearcoat`, `woven` or `auto`.
    pub fit: String,
    /// The light intensity of the glTF part, as `symframe fit` chooses it (1 is true).
    pub exposure: Option<f64>,
    /// Pixels whose model is Ward, glTF, the clear coat and the woven lobes.
    pub pixels: [usize; 4],
    /// RMS radiance error on the training samples.
    pub train_rms: f64,
    /// PSNR on the held-out samples of every fitted pixel, dB (estimated frames).
    pub holdout_psnr: f64,
    /// The same with the fit in the true frames: what the frames' errors cost.
    pub holdout_psnr_true_frames: f64,
    /// Mean PSNR of whole relit images under the held-out lights, dB.
    pub relit_psnr: f64,
    /// Held-out lights judged (those that light some of the judged pixels).
    pub lights_judged: usize,
    /// The lowest of those PSNRs (the worst held-out light), dB.
    pub relit_worst: f64,
    /// The largest relit value over the brightest training sample of its pixel.
    pub relit_over_brightest: f64,
    /// The same of the true renders: how far the truth itself rises above what the training
    /// lights saw (a sharp highlight falling between them).
    pub truth_over_brightest: f64,
}

/// Runs the experiment; writes `relight_side_by_side.png` into `out` and returns the markdown
/// section (the table printed to stdout too).
pub fn run(ctx: &Ctx) -> Result<Section<Vec<Row>>> {
    let (out, quick) = (ctx.out.as_path(), ctx.quick);
    let (size, n_lights, k) = if quick { (20, 300, 10) } else { (48, 800, 20) };
    let lights = uniform_cone_lights(n_lights, 65.0);
    let holdout = FitParams::holdout_lights(n_lights, k)?;
    let train: Vec<usize> = (0..n_lights).filter(|i| !holdout.contains(i)).collect();
    let train_lights: Vec<DVec3> = train.iter().map(|&i| lights[i]).collect();
    let sphere = Scene::sphere(size, TangentField::Circular);
    let bumps = Scene::bumps(size, &BUMPS, TangentField::Swirl(30.0));
    let cos60 = 60f64.to_radians().cos();
    let mut rows = Vec::new();
    // Per material, relit from the samples (no model): mean and worst PSNR, max / brightest.
    let mut sample_rows: Vec<(f64, f64, f64)> = Vec::new();
    let mut picture = None;
    let mut ward_fit: Option<FitMaps> = None;
    let materials = materials()?;
    for mat in &materials {
        let (scene, brdf) = (if mat.bumpy { &bumps } else { &sphere }, &mat.brdf);
        let within: Vec<bool> = (0..scene.n_pixels())
            .map(|p| scene.mask[p] && scene.normals_in_camera[p].z >= cos60)
            .collect();
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
        // The bumpy surface's cast shadows, as `symframe relight --shadows` casts them: from
        // the relief integrated from the estimated normals.
        let heights: Option<Vec<f64>> = if mat.bumpy {
            let depth = DepthMap::integrate(
                size,
                size,
                &frames.normals,
                Some(&frames.confidence),
                &IntegrateParams::default(),
            )?;
            Some(depth.depth.iter().map(|&z| z as f64).collect())
        } else {
            None
        };
        // The samples fitted: on the bumps, optionally without those the relief hides from
        // their light (a shadowed sample measures the relief, not the reflectance).
        let mut samples = stack.clone();
        if let (true, Some(hf)) = (mat.drop_shadowed, &heights) {
            for (i, &l) in lights.iter().enumerate() {
                let mut img = samples.image(i);
                let shadowed = Scene::cast_shadows(hf, size, size, l);
                for (px, _) in img.chunks_exact_mut(3).zip(&shadowed).filter(|p| *p.1) {
                    px.fill(f32::NAN);
                }
                samples.set_image(i, &img);
            }
        }
        // Each pixel's brightest training sample.
        let brightest: Vec<f32> = (0..scene.n_pixels())
            .map(|p| {
                let px = stack.pixel(p);
                train
                    .iter()
                    .flat_map(|&i| px[3 * i..3 * i + 3].iter().copied())
                    .fold(0.0, f32::max)
            })
            .collect();
        let peak = brightest.iter().copied().fold(0.0, f32::max);
        let judge = |render: &dyn Fn(DVec3) -> Vec<f32>| {
            let (mut over, mut truth_over) = (0.0f64, 0.0f64);
            // The held-out lights that light some of the judged pixels (on the bumps, a light
            // below the plane's horizon lights nothing: its PSNR is undefined).
            let psnrs: Vec<f64> = holdout
                .iter()
                .filter(|&&i| {
                    let truth = stack.image(i);
                    (0..scene.n_pixels())
                        .any(|p| within[p] && truth[3 * p..3 * p + 3].iter().any(|&v| v > 0.0))
                })
                .map(|&i| {
                    let mut relit = render(lights[i]);
                    if let Some(hf) = &heights {
                        let shadowed = Scene::cast_shadows(hf, size, size, lights[i]);
                        for (px, _) in relit.chunks_exact_mut(3).zip(&shadowed).filter(|p| *p.1) {
                            px.fill(0.0);
                        }
                    }
                    let truth = stack.image(i);
                    for (p, (px, tx)) in
                        relit.chunks_exact(3).zip(truth.chunks_exact(3)).enumerate()
                    {
                        if within[p] {
                            let bound = brightest[p].max(1e-3 * peak) as f64;
                            for (&v, &t) in px.iter().zip(tx) {
                                over = over.max(v as f64 / bound);
                                truth_over = truth_over.max(t as f64 / bound);
                            }
                        }
                    }
                    Relighter::image_psnr(&relit, &truth, Some(&within))
                })
                .collect();
            (psnrs, over, truth_over)
        };
        for model in FITS {
            // The exposure chosen as `symframe fit` chooses it (the renders' is 1).
            let mut params = FitParams {
                holdout: holdout.clone(),
                model,
                ..FitParams::default()
            };
            if model.uses_gltf() {
                let pixels: Vec<PixelData> = (0..scene.n_pixels())
                    .filter(|&p| scene.mask[p])
                    .filter_map(|p| {
                        Some(PixelData {
                            normal: symframe::EstimateMaps::vec_at(&frames.normals, p)?,
                            tangent: symframe::EstimateMaps::vec_at(&frames.tangents, p),
                            rgb: samples.pixel(p).to_vec(),
                        })
                    })
                    .collect();
                params.exposure =
                    symframe::ExposureChoice::select(&lights, &params, &pixels)?.exposure;
            }
            let fit = params.fit_stack(
                &samples,
                &lights,
                &frames.normals,
                &frames.tangents,
                Some(&scene.mask),
                &|_| {},
            )?;
            let true_frames = params.fit_stack(
                &samples,
                &lights,
                &scene.gt_normals(),
                &scene.gt_tangents(),
                Some(&scene.mask),
                &|_| {},
            )?;
            let mut relighter = Relighter::of_fit(&fit.ward, fit.gltf.as_ref(), &Edits::default())?;
            if let Some(l) = &fit.lobes {
                relighter = relighter.with_lobes(l, &Edits::default())?;
            }
            let (psnrs, over, truth_over) = judge(&|l| relighter.render(l));
            rows.push(Row {
                model: mat.label.clone(),
                fit: model.name().into(),
                exposure: model.uses_gltf().then_some(params.exposure),
                pixels: [
                    fit.summary.ward_pixels,
                    fit.summary.gltf_pixels,
                    fit.summary.clearcoat_pixels,
                    fit.summary.woven_pixels,
                ],
                train_rms: fit.summary.train_rms,
                holdout_psnr: fit.summary.holdout_psnr_db.unwrap_or(f64::NAN),
                holdout_psnr_true_frames: true_frames.summary.holdout_psnr_db.unwrap_or(f64::NAN),
                relit_psnr: psnrs.iter().sum::<f64>() / psnrs.len() as f64,
                lights_judged: psnrs.len(),
                relit_worst: psnrs.iter().copied().fold(f64::INFINITY, f64::min),
                relit_over_brightest: over,
                truth_over_brightest: truth_over,
            });
            if model == FitModel::Ward {
                ward_fit = Some(fit);
            }
        }
        // Relit from the samples themselves, no model (`SampleRelighter`): the training
        // images as the fits saw them, in the same estimated frames.
        let mut fitted = Stack::zeros(size, size, train.len());
        for (j, &i) in train.iter().enumerate() {
            fitted.set_image(j, &samples.image(i));
        }
        let from_samples = SampleRelighter::new(
            &fitted,
            rig.clone(),
            &frames.normals,
            &frames.tangents,
            Some(&scene.mask),
        )?;
        let (psnrs, over, _) = judge(&|l| from_samples.render(l));
        sample_rows.push((
            psnrs.iter().sum::<f64>() / psnrs.len() as f64,
            psnrs.iter().copied().fold(f64::INFINITY, f64::min),
            over,
        ));
        let fit = ward_fit.take().expect("the Ward fit ran");
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
            let relighter = Relighter::new(&fit.ward, &Edits::default())?;
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
        "## Relighting from per-pixel Ward and glTF fits (paper Section 5.1, Figures 8-9)\n"
    )?;
    writeln!(
        md,
        "A {size} x {size} sphere (circular tangent field) under {n_lights} lights uniform over the \
         65-degree cone; {k} evenly spread lights are held out of both the frame estimate \
         (symmetry method, default settings) and the fit. After the ten single-lobe models: car \
         paint (a sharp isotropic clear coat over a brushed metallic base) and woven satin (two \
         perpendicular anisotropic lobes), then a brushed material on a {size} x {size} bumpy \
         surface ({} bumps, relief {}, swirling tangents) with cast shadows in the training \
         images and the true renders, its relit images shadowed by the relief integrated from \
         the estimated normals (Poisson), as `symframe relight --shadows` shadows them; the \
         bumps are fitted on every sample, then without the samples that relief shadows (a \
         shadowed sample is dark whatever the reflectance). Each material is fitted five times: \
         anisotropic Ward (`symframe fit --model ward`), glTF metallic-roughness with \
         `KHR_materials_anisotropy` (`--model gltf`), a clear coat over an anisotropic GGX base \
         (`--model clearcoat`), two perpendicular anisotropic GGX lobes (`--model woven`) and \
         the automatic choice (`--model auto`, the default: per pixel, whichever of the four \
         predicts the validation lights, one training light in five, best over the pixel's \
         7 x 7 neighbourhood, in geometric mean of the errors), the glTF \
         part's light intensity chosen as `symframe fit` chooses it (by validation \
         lights; the renders' is 1). PSNR = `20 log10(peak / RMS)` with the peak the largest \
         true value; \"held-out samples\" is over every fitted pixel (fitted in the estimated \
         frames, and for comparison in the true ones), \"relit\" over whole relit images \
         against true renders under the held-out lights (pixels within 60 degrees of the \
         view), each image with its own peak: their mean and the worst light. \"max / \
         brightest\" is the largest relit value over the brightest training sample of its \
         pixel (at least 0.1% of the brightest anywhere).\n",
        BUMPS.count, BUMPS.relief
    )?;
    writeln!(
        md,
        "| material | fit | exposure | Ward / glTF / coat / woven pixels | training RMS | held-out samples PSNR \
         (dB) | the same, true frames (dB) | relit PSNR mean (dB) | relit, worst light (dB) | \
         max / brightest |"
    )?;
    writeln!(
        md,
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    )?;
    for r in &rows {
        let exposure = r.exposure.map_or("-".into(), |e| format!("{e:.3}"));
        writeln!(
            md,
            "| {} | {} | {exposure} | {} / {} / {} / {} | {:.4} | {:.1} | {:.1} | {:.1} | {:.1} | \
             {:.2} |",
            r.model,
            r.fit,
            r.pixels[0],
            r.pixels[1],
            r.pixels[2],
            r.pixels[3],
            r.train_rms,
            r.holdout_psnr,
            r.holdout_psnr_true_frames,
            r.relit_psnr,
            r.relit_worst,
            r.relit_over_brightest
        )?;
    }
    let bump_lights = rows
        .iter()
        .zip(materials.iter().flat_map(|m| [m.bumpy; FITS.len()]))
        .filter(|(_, bumpy)| *bumpy)
        .map(|(r, _)| r.lights_judged)
        .min();
    if let Some(n) = bump_lights {
        writeln!(
            md,
            "\nThe bumpy surface is judged under the {n} of the {k} held-out lights that light it \
             (the others are below its plane's horizon: every pixel in shadow, true and relit)."
        )?;
    }
    let mean = |fit: &str| {
        let v: Vec<f64> = rows
            .iter()
            .filter(|r| r.fit == fit)
            .map(|r| r.relit_psnr)
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    // Per material: the automatic choice against the best single model, and how far each
    // fit's worst light falls below its mean.
    writeln!(
        md,
        "\nPer material, the automatic choice (the default) against the best single model, \
         and each fit's worst held-out light below its own mean:\n"
    )?;
    writeln!(
        md,
        "| material | best single (dB) | auto, mean / worst light (dB) | auto - best (dB) | \
         worst below mean: Ward / glTF / coat / woven / auto (dB) | max / brightest: auto, \
         truth |"
    )?;
    writeln!(md, "| --- | --- | --- | --- | --- | --- |")?;
    let auto = FITS.len() - 1;
    let (mut within_1db, mut worst_gap) = (0, f64::NEG_INFINITY);
    for m in rows.chunks_exact(FITS.len()) {
        let best = m[..auto]
            .iter()
            .map(|r| r.relit_psnr)
            .fold(f64::NEG_INFINITY, f64::max);
        let gap = best - m[auto].relit_psnr;
        within_1db += usize::from(gap <= 1.0);
        worst_gap = worst_gap.max(gap);
        let drops: Vec<String> = m
            .iter()
            .map(|r| format!("{:.1}", r.relit_psnr - r.relit_worst))
            .collect();
        writeln!(
            md,
            "| {} | {best:.1} | {:.1} / {:.1} | {:+.1} | {} | {:.2}, {:.2} |",
            m[auto].model,
            m[auto].relit_psnr,
            m[auto].relit_worst,
            -gap,
            drops.join(" / "),
            m[auto].relit_over_brightest,
            m[auto].truth_over_brightest
        )?;
    }
    let over = rows
        .iter()
        .map(|r| r.relit_over_brightest)
        .fold(0.0, f64::max);
    // Relit values above twice the brightest training sample where the truth stays lower.
    let fireflies = rows
        .iter()
        .filter(|r| r.relit_over_brightest > 2.0f64.max(r.truth_over_brightest))
        .count();
    let steady = rows
        .chunks_exact(FITS.len())
        .filter(|m| m[auto].relit_psnr - m[auto].relit_worst <= 6.0)
        .count();
    let default = symframe::FitModel::DEFAULT.name();
    writeln!(
        md,
        "\nMean relit PSNR over the materials: Ward {:.1} dB, glTF {:.1} dB, clear coat {:.1} dB, \
         woven {:.1} dB, automatic {:.1} dB. The automatic choice is within 1 dB of the best \
         single model on {within_1db} of the \
         {} materials (at most {worst_gap:.1} dB below it), and its worst light is within 6 dB \
         of its mean on {steady}. No relit value is above {over:.2} times the brightest \
         training sample of its pixel; {fireflies} of the {} fits relight a value above twice \
         that sample where the true renders stay lower (a sharp highlight falling between the \
         training lights takes the truth itself above it). `symframe fit --model` defaults to \
         `{default}`.",
        mean("ward"),
        mean("gltf"),
        mean("clearcoat"),
        mean("woven"),
        mean("auto"),
        materials.len(),
        rows.len()
    )?;
    // Relit from the samples themselves, beside the automatic choice.
    writeln!(
        md,
        "\nRelit from the samples themselves, with no model (`SampleRelighter`, docs/method.md, \
         \"Relighting from the samples\": each pixel's slice interpolated on the rig's \
         triangulation, read at its mirror images where the rig has no data), beside the \
         automatic choice:\n"
    )?;
    writeln!(
        md,
        "| material | samples: mean / worst light (dB) | auto: mean / worst light (dB) | \
         samples - auto (dB) | max / brightest: samples |"
    )?;
    writeln!(md, "| --- | --- | --- | --- | --- |")?;
    for (m, &(mean, worst, over)) in rows.chunks_exact(FITS.len()).zip(&sample_rows) {
        let a = &m[auto];
        writeln!(
            md,
            "| {} | {mean:.1} / {worst:.1} | {:.1} / {:.1} | {:+.1} | {over:.2} |",
            a.model,
            a.relit_psnr,
            a.relit_worst,
            mean - a.relit_psnr
        )?;
    }
    let better = rows
        .chunks_exact(FITS.len())
        .zip(&sample_rows)
        .filter(|(m, s)| s.0 > m[auto].relit_psnr)
        .count();
    let highest = sample_rows.iter().map(|s| s.2).fold(0.0, f64::max);
    writeln!(
        md,
        "\nThe samples relight better than the automatic choice on {better} of the {} \
         materials, and no relit value is above {highest:.2} times the brightest training \
         sample of its pixel (the slice is interpolated between the samples; only the new \
         light's larger n.l can raise it above them).",
        materials.len()
    )?;
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
        let mapped = Relighter::tone_map(img, exposure);
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
