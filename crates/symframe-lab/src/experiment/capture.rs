//! Real-capture conditions: the estimator and every baseline on renders degraded the way
//! cameras and calibrations degrade them (8- to 16-bit quantisation in sRGB or linear, JPEG
//! compression of the 8-bit images at a given quality, a share of clipped samples, shot noise
//! of a given full well, light directions off by a given angle), over one-lobe, two-lobe,
//! woven, sheen and off-family materials, under a dense, a sparse and a narrow rig. Each axis
//! is swept about the reference capture (8-bit sRGB stored losslessly, 0.5% clipped,
//! 4,000-electron full well, 1° light error).
//!
//! A JPEG capture is a real round trip: each degraded 8-bit sRGB image is encoded by the
//! `image` crate's encoder and decoded by symframe-io's reader, the one `symframe estimate`
//! reads a `.jpg` with (its sRGB decoding and saturation rule).
//!
//! Materials marked held out were not looked at while the estimator's rules were chosen:
//! their figures check the rules, they did not shape them.

use std::path::Path;

use anyhow::{ensure, Context, Result};
use glam::DVec3;
use image::codecs::jpeg::JpegEncoder;
use image::ExtendedColorType;
use rayon::prelude::*;
use serde::Serialize;
use symframe::brdf::{Beckmann, Brdf, Ggx, Layered, Sheen, Woven};
use symframe::render::{diligent_lights, Degradation, Noise, Rng, Scene, TangentField};
use symframe::{
    estimate_stack, evaluate, uniform_cone_lights, Baseline, BaselineParams, EstimateMaps,
    EstimatorParams, Evaluation, NoiseModel, Quantisation, Rig, RigOptions, Stack,
};
use symframe_io::{decode_image, linear_to_srgb, DecodeOptions};

mod report;

pub use report::run;

/// One material of the sweep.
struct Material {
    name: &'static str,
    brdf: Box<dyn Brdf>,
    /// Its lobe (the stronger one) is at least 2:1 anisotropic: a tangent is expected.
    anisotropic: bool,
    /// Not looked at while the estimator's rules were chosen.
    held_out: bool,
}

fn materials(quick: bool) -> Vec<Material> {
    let brushed = || Ggx::new([0.02; 3], [0.91, 0.92, 0.92], 0.3, 0.08);
    let mut m = vec![
        Material {
            name: "glossy plastic",
            brdf: Box::new(Ggx::isotropic([0.45, 0.3, 0.2], [0.04; 3], 0.1)),
            anisotropic: false,
            held_out: false,
        },
        Material {
            name: "brushed aluminium",
            brdf: Box::new(brushed()),
            anisotropic: true,
            held_out: false,
        },
        Material {
            name: "car paint",
            brdf: Box::new(Layered::new(
                0.03,
                1.5,
                Box::new(Ggx::new([0.05, 0.08, 0.25], [0.5, 0.5, 0.6], 0.35, 0.12)),
            )),
            anisotropic: true,
            held_out: false,
        },
        // The isotropic control of the two-lobe rules: the same sharp coat over a base with no
        // preferred direction; a tangent there is a false one.
        Material {
            name: "clear-coated plastic",
            brdf: Box::new(Layered::new(
                0.03,
                1.5,
                Box::new(Ggx::isotropic([0.3, 0.12, 0.05], [0.3, 0.3, 0.3], 0.2)),
            )),
            anisotropic: false,
            held_out: false,
        },
        Material {
            name: "woven satin",
            brdf: Box::new(Woven::new([0.25, 0.08, 0.08], [0.05; 3], 0.35, 0.08, 0.5)),
            anisotropic: true,
            held_out: false,
        },
    ];
    if !quick {
        m.extend([
            Material {
                name: "lacquered brushed",
                brdf: Box::new(Layered::new(0.01, 1.5, Box::new(brushed()))),
                anisotropic: true,
                held_out: true,
            },
            Material {
                name: "brushed gold (Beckmann)",
                brdf: Box::new(Beckmann::new([0.0; 3], [1.0, 0.71, 0.29], 0.25, 0.06)),
                anisotropic: true,
                held_out: true,
            },
            // The held-out isotropic control: a rough metal of another distribution.
            Material {
                name: "rough steel (Beckmann)",
                brdf: Box::new(Beckmann::new([0.0; 3], [0.56, 0.57, 0.58], 0.18, 0.18)),
                anisotropic: false,
                held_out: true,
            },
            Material {
                name: "sheen fabric",
                brdf: Box::new(Sheen::new(
                    [0.35, 0.12, 0.1],
                    [0.4, 0.35, 0.35],
                    0.4,
                    Ggx::new([0.0; 3], [0.04; 3], 0.3, 0.15),
                )),
                anisotropic: true,
                held_out: true,
            },
        ]);
    }
    m
}

/// How a capture was degraded.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Condition {
    /// Bits of the stored samples (`None`: float).
    pub bits: Option<u32>,
    /// Quantised in the sRGB-encoded domain (8-bit PNG, JPEG).
    pub srgb: bool,
    /// Share of the object's samples at or above the white level (the exposure is set so).
    pub clipped: f64,
    /// Electrons at the white level (shot noise); `None`: no noise.
    pub full_well: Option<f64>,
    /// Angle each light direction is off by in the calibration given to the methods, degrees.
    pub light_error_deg: f64,
    /// Quality the 8-bit sRGB images are saved at as JPEG (`None`: stored losslessly, as a
    /// PNG). Only with 8-bit sRGB.
    pub jpeg_quality: Option<u8>,
}

/// The reference capture: 8-bit sRGB, 0.5% clipped, 4,000 electrons, 1 degree.
pub const REFERENCE: Condition = Condition {
    bits: Some(8),
    srgb: true,
    clipped: 0.005,
    full_well: Some(4000.0),
    light_error_deg: 1.0,
    jpeg_quality: None,
};

impl Condition {
    /// A short label for tables.
    pub fn label(&self) -> String {
        let fmt = match (self.bits, self.srgb, self.jpeg_quality) {
            (None, _, _) => "float".to_string(),
            (Some(b), true, Some(q)) => format!("{b}-bit sRGB JPEG q{q}"),
            (Some(b), true, None) => format!("{b}-bit sRGB"),
            (Some(b), false, _) => format!("{b}-bit linear"),
        };
        let noise = self
            .full_well
            .map_or("no noise".to_string(), |e| format!("{e:.0} e-"));
        format!(
            "{fmt}, {:.1}% clipped, {noise}, {}° lights",
            100.0 * self.clipped,
            self.light_error_deg
        )
    }

    /// The degradation, for images whose `quantile`-th sample (the clip point) is `at`. A JPEG
    /// capture is quantised and marked by its round trip ([`render_stack_jpeg`]) instead: its
    /// `quantise_bits` and `saturation` say what that round trip does.
    fn degradation(&self, at: f32, seed: u64) -> Degradation {
        let exposure = 1.0 / at.max(1e-9);
        let integer = self.bits.is_some();
        Degradation {
            exposure,
            noise: self
                .full_well
                .map_or(Noise::None, |photons| Noise::Shot { photons }),
            clip: (integer || self.clipped > 0.0).then_some(1.0),
            quantise_bits: self.bits,
            srgb: self.srgb,
            // The reader's rule for integer files: a raw value at 99.5% of the maximum.
            saturation: (integer && std::env::var_os("SYMFRAME_CAPTURE_NOSAT").is_none()).then(
                || {
                    if self.srgb {
                        ((0.995f32 + 0.055) / 1.055).powf(2.4)
                    } else {
                        0.995
                    }
                },
            ),
            seed,
        }
    }
}

/// The sweeps: each axis varied about [`REFERENCE`], plus the clean float render.
fn conditions(quick: bool) -> Vec<(&'static str, Condition)> {
    let r = REFERENCE;
    let clean = Condition {
        bits: None,
        srgb: false,
        clipped: 0.0,
        full_well: None,
        light_error_deg: 0.0,
        jpeg_quality: None,
    };
    let mut v = vec![("reference", r), ("clean", clean)];
    if quick {
        // One JPEG condition, so that the quick run goes through the round trip.
        v.push((
            "jpeg",
            Condition {
                jpeg_quality: Some(90),
                ..r
            },
        ));
        return v;
    }
    for (bits, srgb) in [(None, false), (Some(16), false), (Some(12), false)] {
        v.push(("bits", Condition { bits, srgb, ..r }));
    }
    for full_well in [None, Some(16000.0), Some(1000.0)] {
        v.push(("noise", Condition { full_well, ..r }));
    }
    for clipped in [0.0, 0.02] {
        v.push(("clipped", Condition { clipped, ..r }));
    }
    for light_error_deg in [0.0, 0.5, 2.0] {
        v.push((
            "lights",
            Condition {
                light_error_deg,
                ..r
            },
        ));
    }
    for q in [75, 90, 100] {
        v.push((
            "jpeg",
            Condition {
                jpeg_quality: Some(q),
                ..r
            },
        ));
    }
    v
}

/// One degraded image as a camera's JPEG reaches the tool: `linear` (exposed, noisy and
/// clipped, not yet quantised) quantised to 8-bit sRGB, encoded as JPEG at `quality`, and
/// decoded as `symframe estimate` decodes a `.jpg` (sRGB to linear; a pixel with a channel at
/// or above `opts.saturation` of 255 censored, `+inf` in all three channels).
fn jpeg_round_trip(
    linear: &[f32],
    width: usize,
    height: usize,
    quality: u8,
    opts: &DecodeOptions,
) -> Result<Vec<f32>> {
    // Quantised as `render::quantise_srgb` quantises an 8-bit sRGB (PNG) capture.
    let bytes: Vec<u8> = linear
        .iter()
        .map(|&v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round() as u8)
        .collect();
    let mut jpeg = Vec::new();
    // The encoder has no subsampling option: it writes every component at full resolution
    // (4:4:4, whatever its doc says), so its chroma loses less than a camera's 4:2:0.
    JpegEncoder::new_with_quality(&mut jpeg, quality)
        .encode(&bytes, width as u32, height as u32, ExtendedColorType::Rgb8)
        .context("JPEG encoding")?;
    drop(bytes);
    let img = decode_image(Path::new("capture.jpg"), &jpeg, opts)?;
    ensure!(
        (img.width, img.height) == (width, height),
        "JPEG round trip changed the size"
    );
    Ok(img.into_rgb())
}

/// Images per batch of [`render_stack_jpeg`]: those in memory besides the stack.
const JPEG_BATCH: usize = 32;

/// The stack of a JPEG capture: each image rendered and degraded by `camera` (exposure, noise,
/// clip; no quantisation), then through [`jpeg_round_trip`]. Images go into the stack a batch
/// at a time, so that the whole stack is not held twice.
fn render_stack_jpeg(
    scene: &Scene,
    brdf: &dyn Brdf,
    lights: &[DVec3],
    camera: &Degradation,
    quality: u8,
    opts: &DecodeOptions,
) -> Result<Stack> {
    let mut stack = Stack::zeros(scene.width, scene.height, lights.len());
    for start in (0..lights.len()).step_by(JPEG_BATCH) {
        let end = (start + JPEG_BATCH).min(lights.len());
        let images: Vec<Vec<f32>> = (start..end)
            .into_par_iter()
            .map(|i| {
                let img = scene.render_degraded(brdf, lights[i], i, camera);
                jpeg_round_trip(&img, scene.width, scene.height, quality, opts)
            })
            .collect::<Result<_>>()?;
        for (i, img) in (start..end).zip(&images) {
            stack.set_image(i, img);
        }
    }
    Ok(stack)
}

/// The rigs: dense (1,000 lights over a 130-degree cap), sparse (200), narrow (the DiLiGenT-like
/// 96-light grid within 45 degrees).
fn rig_lights(name: &str, quick: bool) -> Vec<DVec3> {
    match name {
        "dense" => uniform_cone_lights(if quick { 300 } else { 1000 }, 65.0),
        "sparse" => uniform_cone_lights(200, 65.0),
        _ => diligent_lights(),
    }
}

/// The methods, in column order.
pub const METHODS: [&str; 3] = ["symmetry", "highlight-centroid", "max-reflectance"];

/// One method's figures on one set.
#[derive(Debug, Clone, Serialize)]
pub struct Cell {
    /// Mean normal error over pixels within 60° of the view (NaN: none estimated).
    pub normal_mean: f64,
    /// Share of those pixels estimated.
    pub coverage: f64,
    /// Share of estimated pixels with a tangent.
    pub tangent_share: f64,
    /// Mean tangent-axis error.
    pub tangent_mean: f64,
    /// The same when the tangent and binormal may swap (judges the frame, not the rule that
    /// picks which axis is the tangent).
    pub tangent_swap_free: f64,
    /// Pixels with confidence at least 0.9 (the estimator only).
    pub confident: usize,
    /// Share of those within 1° of the truth.
    pub confident_within_1: f64,
    /// Pixels with a tangent whose tangent confidence is at least 0.9 (the estimator on
    /// anisotropic materials only).
    pub tangent_confident: usize,
    /// Share of those whose tangent's axes are within [`TANGENT_WITHIN_DEG`] of the truth's
    /// (tangent and binormal may swap: the confidence measures how clearly the axes stand
    /// out, not which of them is the wider).
    pub tangent_confident_within: f64,
    /// Share of the estimated pixels (within 60°) per source code (`source.npy`'s codes).
    pub sources: [f64; 5],
}

/// One material under one condition and rig.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Material name.
    pub material: &'static str,
    /// A tangent is expected (lobe at least 2:1).
    pub anisotropic: bool,
    /// Not looked at while tuning.
    pub held_out: bool,
    /// The sweep this set belongs to (`reference`, `clean`, `bits`, ...).
    pub sweep: &'static str,
    /// The degradation.
    pub condition: Condition,
    /// `dense`, `sparse` or `narrow`.
    pub rig: &'static str,
    /// Per method of [`METHODS`].
    pub cells: Vec<Cell>,
}

/// A confident tangent counts as right within this many degrees.
pub const TANGENT_WITHIN_DEG: f64 = 2.5;

fn cell(scene: &Scene, maps: &EstimateMaps, gt_t: &[f32], anisotropic: bool) -> Cell {
    let e: Evaluation = evaluate(
        &maps.normals,
        &maps.tangents,
        &scene.gt_normals(),
        anisotropic.then_some(gt_t),
        Some(&scene.mask),
        60.0,
        None,
    );
    let gt = scene.gt_normals();
    let (mut confident, mut within) = (0usize, 0usize);
    let (mut t_confident, mut t_within) = (0usize, 0usize);
    let mut sources = [0usize; 5];
    for p in 0..scene.n_pixels() {
        if let (true, Some(t), Some(g), Some(gn)) = (
            anisotropic && scene.mask[p] && maps.tangent_confidence[p] >= 0.9,
            EstimateMaps::vec_at(&maps.tangents, p),
            EstimateMaps::vec_at(gt_t, p),
            EstimateMaps::vec_at(&gt, p),
        ) {
            if gn.z >= 0.5 {
                // The axes' error: the tangent against the true tangent or binormal.
                let b = gn.cross(g).normalize_or_zero();
                let cos = t.dot(g).abs().max(t.dot(b).abs()).min(1.0);
                t_confident += 1;
                t_within += (cos.acos().to_degrees() <= TANGENT_WITHIN_DEG) as usize;
            }
        }
        if scene.mask[p]
            && EstimateMaps::vec_at(&maps.normals, p).is_some()
            && gt.get(3 * p + 2).is_some_and(|z| *z >= 0.5)
        {
            sources[(maps.source[p] as usize).min(4)] += 1;
        }
        let (Some(n), Some(g)) = (
            EstimateMaps::vec_at(&maps.normals, p),
            EstimateMaps::vec_at(&gt, p),
        ) else {
            continue;
        };
        let sure = maps.confidence[p] >= 0.9; // false for NaN
        if !scene.mask[p] || g.z < 0.5 || !sure {
            continue;
        }
        confident += 1;
        within += (n.angle_between(g).to_degrees() <= 1.0) as usize;
    }
    Cell {
        normal_mean: e.normal_error.mean,
        coverage: e.coverage,
        tangent_share: e.tangent_coverage,
        tangent_mean: e.tangent_error.mean,
        tangent_swap_free: e.tangent_error_swap_free.mean,
        confident,
        confident_within_1: within as f64 / confident.max(1) as f64,
        tangent_confident: t_confident,
        tangent_confident_within: t_within as f64 / t_confident.max(1) as f64,
        sources: {
            let n = sources.iter().sum::<usize>().max(1) as f64;
            sources.map(|c| c as f64 / n)
        },
    }
}

/// How many times the sets' size the images the noise is estimated from are: four, as a
/// 48-pixel sphere becomes a 192-pixel one, its shading's curvature per pixel sixteen times
/// smaller.
const NOISE_SCALE: usize = 4;

/// Renders, degrades and estimates every set; the rows in job order.
pub fn compute(quick: bool, size: usize) -> Result<Vec<Row>> {
    let mats = materials(quick);
    let conds = conditions(quick);
    let scene = Scene::sphere(size, TangentField::Circular);
    // The noise is estimated on the same capture at NOISE_SCALE times the size: the
    // estimator reads a small sphere's shading curvature as noise, where a real capture's
    // object spans hundreds of pixels (docs/validation.md, "Real-capture conditions").
    let noise_scene = Scene::sphere(NOISE_SCALE * size, TangentField::Circular);
    let gt_t = scene.gt_tangents();
    let mut jobs: Vec<(usize, usize, &'static str)> = Vec::new();
    for m in 0..mats.len() {
        for (c, (sweep, _)) in conds.iter().enumerate() {
            let rigs: &[&'static str] = match (*sweep, quick) {
                ("reference", false) => &["dense", "sparse", "narrow"],
                ("reference", true) | ("clean", _) => &["dense", "sparse"],
                // A development aid: `SYMFRAME_CAPTURE_SPARSE=1` runs the sweeps on the sparse
                // rig too.
                _ if std::env::var_os("SYMFRAME_CAPTURE_SPARSE").is_some() => &["dense", "sparse"],
                _ => &["dense"],
            };
            jobs.extend(rigs.iter().map(|&r| (m, c, r)));
        }
    }
    // A development aid: `SYMFRAME_CAPTURE_ONLY=car,woven/clean,reference/sparse` keeps the
    // sets whose material, sweep and rig contain one of the comma-separated words of each
    // slash-separated part (an empty or missing part keeps all).
    if let Ok(only) = std::env::var("SYMFRAME_CAPTURE_ONLY") {
        let parts: Vec<Vec<String>> = only
            .split('/')
            .map(|p| {
                p.split(',')
                    .filter(|w| !w.is_empty())
                    .map(String::from)
                    .collect()
            })
            .collect();
        let keeps = |i: usize, name: &str| {
            parts
                .get(i)
                .is_none_or(|ws| ws.is_empty() || ws.iter().any(|w| name.contains(w.as_str())))
        };
        jobs.retain(|&(m, c, r)| keeps(0, mats[m].name) && keeps(1, conds[c].0) && keeps(2, r));
    }
    jobs.par_iter()
        .map(|&(m, c, rig_name)| {
            let mat = &mats[m];
            let (sweep, cond) = conds[c];
            let lights = rig_lights(rig_name, quick);
            let clean = scene.render_stack(mat.brdf.as_ref(), &lights);
            let at = symframe::render::Degradation::clip_point(&clean, &scene.mask, cond.clipped);
            drop(clean);
            // A development aid: `SYMFRAME_CAPTURE_SEED=N` draws another realisation of every
            // set's noise and light errors (a set's confidence figures come from one draw of
            // its lights' errors, shared by neighbouring pixels).
            let realisation = std::env::var("SYMFRAME_CAPTURE_SEED")
                .ok()
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or(0);
            let seed = 17 + 1000 * m as u64 + c as u64 + 1_000_003 * realisation;
            let d = cond.degradation(at, seed);
            let capture = |scene: &Scene, lights: &[DVec3]| -> Result<_> {
                Ok(match cond.jpeg_quality {
                    None => scene.render_stack_degraded(mat.brdf.as_ref(), lights, &d),
                    Some(q) => {
                        ensure!(
                            (cond.bits, cond.srgb) == (Some(8), true),
                            "a JPEG capture is 8-bit sRGB: {}",
                            cond.label()
                        );
                        // Quantisation and the saturation rule are the round trip's.
                        let camera = Degradation {
                            quantise_bits: None,
                            saturation: None,
                            ..d
                        };
                        // The reader's defaults (its saturation rule is the one `degradation`
                        // copies); above 1 where that rule is off: no sample counts as saturated.
                        let mut opts = DecodeOptions::default();
                        if d.saturation.is_none() {
                            opts.saturation = 2.0;
                        }
                        render_stack_jpeg(scene, mat.brdf.as_ref(), lights, &camera, q, &opts)?
                    }
                })
            };
            let stack = capture(&scene, &lights)?;
            // The methods get the lights as a calibration knows them.
            let known = if cond.light_error_deg > 0.0 {
                jitter_lights(&lights, cond.light_error_deg, seed)
            } else {
                lights.clone()
            };
            let rig = Rig::new(&known, RigOptions::default())?;
            let mask = Some(&scene.mask[..]);
            // What the decoder tells the estimator: the clip level of integer files, and for
            // a JPEG its 8-bit sRGB samples (the compression is not known to it); the shot and
            // read noise estimated from four of the images as `estimate` does
            // (`symframe_io::capture_noise`), and with them a float capture's clip level where
            // the samples show a clipped plateau; and what the lights' calibration reports:
            // their RMS error.
            let told = NoiseModel {
                clip_level: d.saturation,
                quantisation: match (cond.bits, cond.srgb) {
                    (None, _) => Quantisation::Float,
                    (Some(b), true) => Quantisation::Srgb(b),
                    (Some(b), false) => Quantisation::Linear(b),
                },
                ..NoiseModel::default()
            };
            let n = lights.len();
            let probe_lights: Vec<DVec3> = (0..4).map(|k| lights[k * (n - 1) / 3]).collect();
            let probe = capture(&noise_scene, &probe_lights)?;
            let picks: Vec<Vec<f32>> = (0..4).map(|k| probe.image(k)).collect();
            let estimated = told.estimate(picks.iter().map(|v| &v[..]), probe.width, None);
            let params = EstimatorParams {
                noise: NoiseModel {
                    light_error_deg: cond.light_error_deg,
                    ..estimated
                },
                ..EstimatorParams::default()
            };
            let ours = estimate_stack(&stack, &rig, mask, params, &|_| {})?;
            // A development aid: `SYMFRAME_CAPTURE_DUMP=DIR` writes one TSV per set into DIR,
            // a row per pixel within 60 degrees of the view: pixel index, normal error
            // (degrees), confidence, source code, the estimated normal and the true one (x y z
            // each), for calibration studies of the confidence.
            if let Ok(dir) = std::env::var("SYMFRAME_CAPTURE_DUMP") {
                let gt = scene.gt_normals();
                let mut out = String::new();
                for p in 0..scene.n_pixels() {
                    if let (true, Some(n), Some(g)) = (
                        scene.mask[p],
                        EstimateMaps::vec_at(&ours.normals, p),
                        EstimateMaps::vec_at(&gt, p),
                    ) {
                        if g.z >= 0.5 {
                            out +=
                                &format!(
                                "{p}\t{:.4}\t{:.4}\t{}\t{:.5}\t{:.5}\t{:.5}\t{:.5}\t{:.5}\t{:.5}\n",
                                n.angle_between(g).to_degrees(),
                                ours.confidence[p],
                                ours.source[p],
                                n.x, n.y, n.z, g.x, g.y, g.z
                            );
                        }
                    }
                }
                let name = format!("{}_{}_{}_{}", mat.name, sweep, c, rig_name).replace(' ', "-");
                std::fs::write(format!("{dir}/{name}.tsv"), out).ok();
            }
            let mut cells = vec![cell(&scene, &ours, &gt_t, mat.anisotropic)];
            for b in [Baseline::HighlightCentroid, Baseline::MaxReflectance] {
                let maps =
                    b.estimate_stack(&stack, &known, mask, BaselineParams::default(), &|_| {})?;
                let mut c = cell(&scene, &maps, &gt_t, mat.anisotropic);
                c.confident = 0;
                c.confident_within_1 = f64::NAN;
                c.tangent_confident = 0;
                c.tangent_confident_within = f64::NAN;
                cells.push(c);
            }
            Ok(Row {
                material: mat.name,
                anisotropic: mat.anisotropic,
                held_out: mat.held_out,
                sweep,
                condition: cond,
                rig: rig_name,
                cells,
            })
        })
        .collect()
}

/// Light directions as a calibration knows them: each of `lights` turned by `error_deg`
/// degrees about a random axis perpendicular to it (deterministic in `seed`), so every
/// direction is off by exactly that angle, each its own way.
fn jitter_lights(lights: &[glam::DVec3], error_deg: f64, seed: u64) -> Vec<glam::DVec3> {
    let mut rng = Rng::new(seed ^ 0x6c69_6768_7473);
    let a = error_deg.to_radians();
    lights
        .iter()
        .map(|&l| {
            let l = l.normalize();
            let (u, w) = l.any_orthonormal_pair();
            let phi = rng.range(0.0, std::f64::consts::TAU);
            let axis = u * phi.cos() + w * phi.sin();
            (l * a.cos() + axis * a.sin()).normalize()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn jitter_turns_every_light_by_the_asked_angle() {
        let lights = symframe::uniform_cone_lights(50, 65.0);
        let moved = super::jitter_lights(&lights, 1.0, 3);
        for (a, b) in lights.iter().zip(&moved) {
            let deg = a.normalize().angle_between(*b).to_degrees();
            assert!((deg - 1.0).abs() < 1e-9, "{deg}");
        }
        assert_ne!(super::jitter_lights(&lights, 1.0, 4), moved);
    }

    use super::*;

    /// Side of the test image.
    const N: usize = 64;

    /// Whether pixel `p` of the test image is near a highlight: within 8 of the disc or in
    /// the quarter holding the square.
    fn near_highlight(p: usize) -> bool {
        let (x, y) = ((p % N) as f32, (p / N) as f32);
        (x - 12.0).hypot(y - 12.0) <= 8.0 || (x >= 32.0 && y >= 32.0)
    }

    /// A smooth colour image (linear, within `[0.02, 0.8]`) with two clipped highlights: a
    /// disc of radius 3 about `(12, 12)` and the square `[40, 56)²`, whole JPEG blocks.
    fn smooth_with_highlights() -> Vec<f32> {
        let mut img = Vec::with_capacity(N * N * 3);
        for y in 0..N {
            for x in 0..N {
                let (u, v) = (x as f32 / N as f32, y as f32 / N as f32);
                let base = 0.02 + 0.5 * (0.5 + 0.5 * (6.0 * u).sin() * (4.0 * v).cos());
                let disc = (x as f32 - 12.0).hypot(y as f32 - 12.0) <= 3.0;
                let square = (40..56).contains(&x) && (40..56).contains(&y);
                if disc || square {
                    img.extend([1.0f32; 3]);
                } else {
                    img.extend([base, 0.8 * base + 0.1 * v, 0.6 * base + 0.2 * u]);
                }
            }
        }
        img
    }

    /// Max and mean absolute difference, in 8-bit sRGB steps, away from the highlights.
    fn steps(a: &[f32], b: &[f32]) -> (f32, f32) {
        let d: Vec<f32> = (0..N * N)
            .filter(|&p| !near_highlight(p))
            .flat_map(|p| 3 * p..3 * p + 3)
            .map(|i| 255.0 * (linear_to_srgb(a[i]) - linear_to_srgb(b[i])).abs())
            .collect();
        let max = d.iter().fold(0.0f32, |m, &v| m.max(v));
        (max, d.iter().sum::<f32>() / d.len() as f32)
    }

    #[test]
    fn jpeg_round_trip_is_close_at_q100_lossy_at_q75_and_keeps_highlights_censored() {
        let img = smooth_with_highlights();
        let opts = DecodeOptions::default();
        let trip = |q| jpeg_round_trip(&img, N, N, q, &opts).unwrap();
        let (q100, q75) = (trip(100), trip(75));
        let (max100, mean100) = steps(&img, &q100);
        let (max75, mean75) = steps(&img, &q75);
        // q100 within a few 8-bit steps of the unquantised input (half a step of it the
        // 8-bit rounding), q75 further (measured: docs/method.md, "What the tests measured").
        assert!(max100 <= 3.0 && mean100 <= 0.75, "q100: {max100} {mean100}");
        assert!(
            max75 >= 4.0 && mean75 >= 1.5 * mean100,
            "q75: {max75} {mean75}"
        );
        let in_square = |p: usize| (40..56).contains(&(p % N)) && (40..56).contains(&(p / N));
        let in_disc = |p: usize| ((p % N) as f32 - 12.0).hypot((p / N) as f32 - 12.0) <= 3.0;
        for (q, out) in [(100, &q100), (90, &trip(90)), (75, &q75)] {
            let px = |p: usize| &out[3 * p..3 * p + 3];
            // The square's pixels are censored in all three channels, as the reader marks
            // them; away from the highlights nothing is.
            for p in (0..N * N).filter(|&p| in_square(p)) {
                assert!(px(p).iter().all(|&v| v == f32::INFINITY), "q{q} {p}");
            }
            for p in (0..N * N).filter(|&p| !near_highlight(p)) {
                assert!(px(p).iter().all(|v| v.is_finite()), "q{q} {p}");
            }
            // The small disc's sharp edge rings: at low qualities some of its clipped pixels
            // come back below the saturation level, where the estimator takes them as measured;
            // at q100 none does.
            let lost = (0..N * N)
                .filter(|&p| in_disc(p) && px(p)[0].is_finite())
                .count();
            match q {
                100 => assert_eq!(lost, 0),
                75 => assert!(lost > 0),
                _ => {}
            }
        }
        // With the saturation rule off the square decodes to white.
        let off = DecodeOptions {
            saturation: 2.0,
            ..DecodeOptions::default()
        };
        let q90 = jpeg_round_trip(&img, N, N, 90, &off).unwrap();
        assert!(q90.iter().all(|v| v.is_finite()));
        assert!(q90[3 * (48 * N + 48)] > 0.99);
    }

    #[test]
    fn jpeg_conditions_are_labelled_and_swept_about_the_reference() {
        let c = Condition {
            jpeg_quality: Some(90),
            ..REFERENCE
        };
        assert!(
            c.label().starts_with("8-bit sRGB JPEG q90, 0.5% clipped"),
            "{}",
            c.label()
        );
        let qualities: Vec<Option<u8>> = conditions(false)
            .iter()
            .filter(|(s, _)| *s == "jpeg")
            .map(|(_, c)| c.jpeg_quality)
            .collect();
        assert_eq!(qualities, [Some(75), Some(90), Some(100)]);
        assert!(conditions(false)
            .iter()
            .all(|(s, c)| (*s == "jpeg") == c.jpeg_quality.is_some()));
    }
}
