//! Per-pixel reflectance fits in the estimated frames (paper Section 5.1): the models, their
//! parameters and maps, and the driver that collects each pixel's samples, holds lights out,
//! chooses between models and sums the figures. Each model's fit is its own module:
//! anisotropic Ward ([`super::ward_fit`], the paper's), glTF 2.0 metallic-roughness with
//! `KHR_materials_anisotropy` ([`super::gltf_fit`]), and the two-lobe models sharing the frame
//! ([`super::lobe_fit`]: a clear coat over an anisotropic base, two perpendicular lobes).
//!
//! # Held-out lights
//!
//! [`FitParams::holdout_lights`] picks `K` evenly spaced light indices; with them in
//! [`FitParams::holdout`], the fit never sees those images and [`FitSummary`] reports the RMS
//! error and PSNR of the prediction on them (same sample rules: valid, `n.l > 0`). PSNR is
//! `20 log10(peak / RMS)` with `peak` the largest held-out measurement used.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::method::run_stack;
use crate::stack::Stack;

mod exposure;
mod maps;
mod pixel;

pub use exposure::{ExposureChoice, PixelData};
pub use maps::{FitMaps, GltfMaps, LobeMaps, WardMaps};
pub(crate) use pixel::{check_frame_maps, squared_errors, LogEvidence};
pub use pixel::{FitMethod, HoldoutError, ModelEvidence, PixelFitter, PixelOutcome, WardFit};

/// The reflectance model a fit estimates per pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FitModel {
    /// Anisotropic Ward (the paper's model): `kd`, `ks`, `alpha_t`, `alpha_b`.
    Ward,
    /// glTF 2.0 metallic-roughness GGX with `KHR_materials_anisotropy`: base colour,
    /// metallic, roughness, anisotropy strength (`appearance/gltf_fit.rs`).
    Gltf,
    /// Per pixel, whichever of the candidates (Ward, glTF, clear coat, woven) predicts the
    /// validation lights of the pixel's neighbourhood best (a share of the training lights set
    /// aside, `validation_lights`; [`FitParams::choose_models`]); the chosen model is then
    /// refitted on every training light.
    Auto,
    /// A sharp isotropic clear coat over an anisotropic GGX base, sharing the frame
    /// (`appearance/clearcoat.rs`): `kd`, `ks`, coat reflectance `kc`, `alpha_t`, `alpha_b`,
    /// coat roughness.
    Clearcoat,
    /// Two perpendicular anisotropic GGX lobes over a diffuse base, sharing the frame
    /// (`appearance/woven.rs`): `kd`, warp and weft reflectances, `alpha_t`, `alpha_b`.
    Woven,
}

impl FitModel {
    /// The name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            FitModel::Ward => "ward",
            FitModel::Gltf => "gltf",
            FitModel::Auto => "auto",
            FitModel::Clearcoat => "clearcoat",
            FitModel::Woven => "woven",
        }
    }

    /// One line on the model and its frame, for reports.
    pub fn description(self) -> &'static str {
        match self {
            FitModel::Ward => {
                "anisotropic Ward (Ward 1992, normalised form), frame x = t, y = n x t, z = n"
            }
            FitModel::Gltf => {
                "glTF 2.0 metallic-roughness (Appendix B) with KHR_materials_anisotropy, \
                 anisotropy direction = t, frame x = t, y = n x t, z = n"
            }
            FitModel::Auto => {
                "per pixel, anisotropic Ward, glTF 2.0 metallic-roughness with \
                 KHR_materials_anisotropy, a clear coat over an anisotropic GGX base or two \
                 perpendicular anisotropic GGX lobes, whichever predicts the pixel's validation \
                 lights best, frame x = t, y = n x t, z = n"
            }
            FitModel::Clearcoat => {
                "a sharp isotropic GGX clear coat (index 1.5) over an anisotropic GGX base with \
                 a diffuse term, frame x = t, y = n x t, z = n"
            }
            FitModel::Woven => {
                "two perpendicular anisotropic GGX lobes (warp along t, weft along n x t) over \
                 a diffuse term, frame x = t, y = n x t, z = n"
            }
        }
    }

    /// Whether the fit has glTF parameters at some pixels (and so needs an exposure).
    pub fn uses_gltf(self) -> bool {
        matches!(self, FitModel::Gltf | FitModel::Auto)
    }

    /// Whether the fit has two-lobe parameters at some pixels ([`LobeMaps`]).
    pub fn uses_lobes(self) -> bool {
        matches!(self, FitModel::Clearcoat | FitModel::Woven | FitModel::Auto)
    }
}

impl std::str::FromStr for FitModel {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "ward" => Ok(FitModel::Ward),
            "gltf" => Ok(FitModel::Gltf),
            "auto" => Ok(FitModel::Auto),
            "clearcoat" => Ok(FitModel::Clearcoat),
            "woven" => Ok(FitModel::Woven),
            other => Err(format!(
                "unknown fit model '{other}' (valid: ward, gltf, auto, clearcoat, woven)"
            )),
        }
    }
}

impl FitModel {
    /// The model fitted unless one is asked for (`symframe fit`, the fit job, the Python
    /// package, [`FitParams::default`], [`FitModel::default`]): the automatic choice, which
    /// predicts held-out lights within 1 dB of the best single model on every material of the
    /// validation scenes (docs/validation.md, "Relighting").
    pub const DEFAULT: FitModel = FitModel::Auto;
}

impl Default for FitModel {
    /// [`FitModel::DEFAULT`].
    fn default() -> Self {
        FitModel::DEFAULT
    }
}

/// Parameters of the per-pixel fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitParams {
    /// The model fitted ([`FitModel::DEFAULT`] by default).
    #[serde(default)]
    pub model: FitModel,
    /// glTF model: the intensity of every light, in the units of the measurements (a white
    /// Lambertian surface facing a light of intensity `E` has radiance `E / pi`). Base colours
    /// are bounded to `[0, 1]`, so photographs of an arbitrary exposure need it: relighting and
    /// export use the same value. Unused by the Ward fit, whose albedos absorb any scale.
    #[serde(default = "unit")]
    pub exposure: f64,
    /// glTF model: the smallest roughness the fit may return.
    #[serde(default = "default_roughness_min")]
    pub roughness_min: f64,
    /// Light indices (into the stack) left out of the fit, to judge it on.
    pub holdout: Vec<usize>,
    /// Levenberg-Marquardt iterations at most.
    pub max_iterations: u32,
    /// Smallest roughness the fit may return.
    pub alpha_min: f64,
    /// Largest roughness the fit may return.
    pub alpha_max: f64,
    /// Pixels with fewer usable samples are not fitted.
    pub min_samples: usize,
    /// The lobe's peak radiance (at the mirror direction) is at most this many times the
    /// pixel's brightest measurement.
    pub max_peak_ratio: f64,
    /// Automatic fit: each pixel's model is chosen from the evidence of the pixels within this
    /// many rows and columns of it ([`FitParams::choose_models`]). Higher is steadier where a
    /// material is uniform (more validation lights judge it) and blurs the line between two
    /// materials; 0 judges each pixel alone.
    #[serde(default = "default_choice_radius")]
    pub choice_radius: usize,
}

fn default_choice_radius() -> usize {
    3
}

fn unit() -> f64 {
    1.0
}

fn default_roughness_min() -> f64 {
    0.07
}

impl Default for FitParams {
    fn default() -> Self {
        Self {
            model: FitModel::DEFAULT,
            exposure: 1.0,
            roughness_min: default_roughness_min(),
            holdout: Vec::new(),
            max_iterations: 60,
            alpha_min: 0.005,
            alpha_max: 2.0,
            min_samples: 8,
            max_peak_ratio: 8.0,
            choice_radius: default_choice_radius(),
        }
    }
}

impl FitParams {
    fn validate(&self, n_lights: usize) -> Result<()> {
        if !(self.alpha_min > 0.0 && self.alpha_min < self.alpha_max && self.alpha_max.is_finite())
        {
            return Err(Error::BadParameter(format!(
                "roughness bounds must satisfy 0 < alpha_min < alpha_max < inf, got {} and {}",
                self.alpha_min, self.alpha_max
            )));
        }
        if let Some(&i) = self.holdout.iter().find(|&&i| i >= n_lights) {
            return Err(Error::BadParameter(format!(
                "held-out light {i} does not exist (there are {n_lights} lights)"
            )));
        }
        if self.max_peak_ratio.is_nan() || self.max_peak_ratio < 1.0 {
            return Err(Error::BadParameter(format!(
                "max_peak_ratio must be at least 1, got {}",
                self.max_peak_ratio
            )));
        }
        check_exposure(self.exposure)?;
        if !(self.roughness_min > 0.0 && self.roughness_min <= 1.0) {
            return Err(Error::BadParameter(format!(
                "roughness_min must be in (0, 1], got {}",
                self.roughness_min
            )));
        }
        if self.min_samples < 3 {
            return Err(Error::BadParameter(format!(
                "min_samples must be at least 3, got {}",
                self.min_samples
            )));
        }
        Ok(())
    }
}

/// The automatic choice keeps a two-lobe model only where its squared error on the validation
/// lights is below this share of the better single-lobe model's (in geometric mean over the
/// pixels pooled): the price of its extra parameters. The two-lobe models nearly contain a
/// single GGX lobe, so on a one-lobe material they predict the validation lights about as
/// well; on a two-lobe material their error is several times smaller (docs/method.md, "The
/// automatic choice").
pub(crate) const TWO_LOBE_GAIN: f64 = 0.75;

/// Squared errors are compared with this share of the squared signal (the sum of the squared
/// samples judged on) added to each: where both models predict the pixel to better than 40 dB
/// their difference is not evidence for the model with more parameters.
pub(crate) const TWO_LOBE_FLOOR: f64 = 1e-4;

/// One training light in this many is a validation light ([`validation_lights`]).
pub(crate) const VALIDATION_EVERY: usize = 5;

/// Which lights choose between fits (the exposure of a glTF fit, the model of an automatic
/// fit): one in [`VALIDATION_EVERY`] of the lights not in `holdout`, counted in input order
/// (the third of every five), so deterministic and spread over the rig like the held-out
/// lights. A fit that chooses fits its candidates on the other training lights and keeps the
/// one with the smallest squared error on these.
pub(crate) fn validation_lights(n_lights: usize, holdout: &[usize]) -> Vec<bool> {
    let mut held = vec![false; n_lights];
    for &i in holdout {
        if i < n_lights {
            held[i] = true;
        }
    }
    let mut out = vec![false; n_lights];
    let mut j = 0;
    for (i, h) in held.iter().enumerate() {
        if !h {
            out[i] = j % VALIDATION_EVERY == VALIDATION_EVERY / 2;
            j += 1;
        }
    }
    out
}

impl FitParams {
    /// `k` light indices spread evenly over `0..n_lights` (the centres of `k` equal blocks),
    /// for [`FitParams::holdout`]. Deterministic; empty when `k == 0`.
    ///
    /// # Errors
    /// When more than half of the lights would be held out.
    pub fn holdout_lights(n_lights: usize, k: usize) -> Result<Vec<usize>> {
        if 2 * k > n_lights {
            return Err(Error::BadParameter(format!(
                "cannot hold out {k} of {n_lights} lights: at most half may be held out"
            )));
        }
        Ok((0..k).map(|j| (2 * j + 1) * n_lights / (2 * k)).collect())
    }
}

/// Counts and error figures of a whole-stack fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FitSummary {
    /// Pixels fitted with two roughnesses.
    pub anisotropic: usize,
    /// Pixels fitted with one roughness.
    pub isotropic: usize,
    /// Pixels outside the mask.
    pub masked: usize,
    /// Pixels without a usable frame.
    pub no_frame: usize,
    /// Pixels with too few usable samples.
    pub too_few_samples: usize,
    /// Training samples (pixel-light pairs) used.
    pub train_samples: usize,
    /// RMS error of the predicted radiance on the training samples (over channels).
    pub train_rms: f64,
    /// Held-out samples (pixel-light pairs) evaluated.
    pub holdout_samples: usize,
    /// RMS error on the held-out samples; `None` without held-out lights.
    pub holdout_rms: Option<f64>,
    /// The largest held-out measurement (the PSNR's peak).
    pub holdout_peak: Option<f64>,
    /// `20 log10(holdout_peak / holdout_rms)`, dB.
    pub holdout_psnr_db: Option<f64>,
    /// Mean Levenberg-Marquardt iterations per fitted pixel.
    pub mean_iterations: f64,
    /// Fitted pixels whose model is Ward (every one of a Ward fit; an automatic fit's choice).
    #[serde(default)]
    pub ward_pixels: usize,
    /// Fitted pixels whose model is glTF.
    #[serde(default)]
    pub gltf_pixels: usize,
    /// Fitted pixels whose model is the clear coat.
    #[serde(default)]
    pub clearcoat_pixels: usize,
    /// Fitted pixels whose model is the woven one.
    #[serde(default)]
    pub woven_pixels: usize,
}

/// [`FitMaps::model`] where a pixel was not fitted.
pub(crate) const MODEL_NONE: u8 = FitMaps::MODEL_NONE;
/// [`FitMaps::model`] where a pixel's model is Ward.
pub(crate) const MODEL_WARD: u8 = FitMaps::MODEL_WARD;
/// [`FitMaps::model`] where a pixel's model is glTF.
pub(crate) const MODEL_GLTF: u8 = FitMaps::MODEL_GLTF;
/// [`FitMaps::model`] where a pixel's model is the clear coat.
pub(crate) const MODEL_CLEARCOAT: u8 = FitMaps::MODEL_CLEARCOAT;
/// [`FitMaps::model`] where a pixel's model is the woven one.
pub(crate) const MODEL_WOVEN: u8 = FitMaps::MODEL_WOVEN;

impl FitParams {
    /// Fits every pixel of a stack (inside `mask` when given) in its frame with these
    /// parameters: `normals` and `tangents` are `H x W x 3` maps as [`crate::estimate_stack`]
    /// returns them (NaN tangent = isotropic), `lights` the stack's light directions. Parallel
    /// over row bands; `progress` is called with the number of pixels finished by each band.
    pub fn fit_stack(
        &self,
        stack: &Stack,
        lights: &[DVec3],
        normals: &[f32],
        tangents: &[f32],
        mask: Option<&[bool]>,
        progress: &(dyn Fn(usize) + Sync),
    ) -> Result<FitMaps> {
        let (w, h) = (stack.width, stack.height);
        Stack::check_inputs(w, h, stack.n_lights, lights.len(), mask)?;
        let method = FitMethod::new(lights, self, normals, tangents, w * h)?;
        let choices = match method.evidence_pass() {
            Some(pass) => {
                Some(self.choose_models(&run_stack(&pass, stack, mask, &|_| {}), w, h)?)
            }
            None => None,
        };
        let method = match &choices {
            Some(c) => method.with_choices(c)?,
            None => method,
        };
        let outcomes = run_stack(&method, stack, mask, progress);
        Ok(FitMaps::from_outcomes(
            w, h, normals, tangents, self, outcomes,
        ))
    }
}

impl FitParams {
    /// The model of each pixel of an automatic fit (`H x W` model codes of
    /// [`FitMaps::model`]) from the evidence of its square neighbourhood of radius
    /// [`FitParams::choice_radius`]: the candidates compared on the geometric mean of their
    /// validation errors' ratios over the pixels there (`LogEvidence`, where the rule and its
    /// reasons are), so that one material's pixels choose together while each pixel counts
    /// by its errors' ratios, not its brightness; [`FitMaps::MODEL_NONE`] where the pixel has
    /// no evidence (it is not fitted).
    ///
    /// # Errors
    /// When `evidence` is not `width * height` long.
    pub fn choose_models(
        &self,
        evidence: &[Option<ModelEvidence>],
        width: usize,
        height: usize,
    ) -> Result<Vec<u8>> {
        if evidence.len() != width * height {
            return Err(Error::BadParameter(format!(
                "{} pixels of evidence for a {width} x {height} image",
                evidence.len()
            )));
        }
        Ok(pool_choices(evidence, width, height, self.choice_radius))
    }
}

/// [`FitParams::choose_models`] on checked sizes: box sums through a summed-area table of the
/// pixels' [`LogEvidence`] (one pass, whatever the radius).
fn pool_choices(evidence: &[Option<ModelEvidence>], w: usize, h: usize, r: usize) -> Vec<u8> {
    // A window wider than the image is the image (and `x + r + 1` cannot overflow).
    let r = r.min(w.max(h));
    // table[y * (w + 1) + x]: the sum over rows < y and columns < x.
    let mut table = vec![LogEvidence::default(); (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = LogEvidence::default();
        for x in 0..w {
            if let Some(e) = &evidence[y * w + x] {
                row = row.add(LogEvidence::of(e));
            }
            table[(y + 1) * (w + 1) + x + 1] = table[y * (w + 1) + x + 1].add(row);
        }
    }
    let at = |x: usize, y: usize| table[y * (w + 1) + x];
    (0..w * h)
        .map(|p| {
            if evidence[p].is_none() {
                return MODEL_NONE;
            }
            let (x, y) = (p % w, p / w);
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
            let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
            let sum = at(x1, y1).add(at(x0, y0)).sub(at(x0, y1)).sub(at(x1, y0));
            sum.choice()
        })
        .collect()
}

/// Checks that `exposure`, a glTF fit's light intensity, is positive and finite: the one rule
/// for the parameters and the maps.
pub(crate) fn check_exposure(exposure: f64) -> Result<()> {
    if !(exposure > 0.0 && exposure.is_finite()) {
        return Err(Error::BadParameter(format!(
            "exposure must be positive and finite, got {exposure}"
        )));
    }
    Ok(())
}

/// RMS error of the squared errors `sse` over `samples` RGB samples (none counted as one): the
/// one formula of every model's fit and of the summary.
pub(crate) fn rms(sse: f64, samples: usize) -> f64 {
    (sse / (3 * samples.max(1)) as f64).sqrt()
}

/// `20 log10(peak / rms)`, infinite for a zero error.
pub(crate) fn psnr_db(peak: f64, rms: f64) -> f64 {
    20.0 * (peak / rms).log10()
}

/// What the fits' tests share: one pixel fitted, a rendered scene fitted and judged relit.
#[cfg(test)]
pub(crate) mod testutil {
    use glam::DVec3;

    use super::{ExposureChoice, FitMaps, FitParams, PixelData, PixelFitter, PixelOutcome};
    use crate::appearance::relight::Relighter;
    use crate::eval::vec_at;
    use crate::render::Scene;
    use crate::stack::Stack;

    /// The outcome of one pixel (`n`, `t`, samples `rgb`) fitted with `params` under `lights`.
    pub(crate) fn fit_one(
        lights: &[DVec3],
        params: &FitParams,
        n: DVec3,
        t: Option<DVec3>,
        rgb: &[f32],
    ) -> PixelOutcome {
        PixelFitter::new(lights, params).unwrap().fit(n, t, rgb)
    }

    /// The exposure [`ExposureChoice::select`] gives `stack`, a render of `scene` under
    /// `lights`, from the pixels inside the mask in their true frames.
    pub(crate) fn choose_exposure(
        lights: &[DVec3],
        params: &FitParams,
        scene: &Scene,
        stack: &Stack,
    ) -> ExposureChoice {
        let (normals, tangents) = (scene.gt_normals(), scene.gt_tangents());
        let pixels: Vec<PixelData> = (0..scene.n_pixels())
            .filter(|&p| scene.mask[p])
            .map(|p| PixelData {
                normal: vec_at(&normals, p).unwrap(),
                tangent: vec_at(&tangents, p),
                rgb: stack.pixel(p).to_vec(),
            })
            .collect();
        ExposureChoice::select(lights, params, &pixels).unwrap()
    }

    /// `stack`, a render of `scene` under `lights`, fitted with `params` in the true frames
    /// inside the mask.
    pub(crate) fn fit_scene(
        params: &FitParams,
        scene: &Scene,
        stack: &Stack,
        lights: &[DVec3],
    ) -> FitMaps {
        let (normals, tangents) = (scene.gt_normals(), scene.gt_tangents());
        params
            .fit_stack(
                stack,
                lights,
                &normals,
                &tangents,
                Some(&scene.mask),
                &|_| {},
            )
            .unwrap()
    }

    /// Under the `holdout` lights, over the mask of `scene`: the largest relit and true values
    /// over each pixel's brightest training sample (floored for pixels the training lights
    /// leave dark), and the mean PSNR of the relit images against `stack`.
    pub(crate) fn judge_relit(
        relighter: &Relighter,
        scene: &Scene,
        stack: &Stack,
        lights: &[DVec3],
        holdout: &[usize],
    ) -> (f32, f32, f64) {
        let np = scene.n_pixels();
        let brightest: Vec<f32> = (0..np)
            .map(|p| {
                let px = stack.pixel(p);
                (0..stack.n_lights)
                    .filter(|i| !holdout.contains(i))
                    .flat_map(|i| px[3 * i..3 * i + 3].iter().copied())
                    .fold(0.0, f32::max)
            })
            .collect();
        let peak = brightest.iter().copied().fold(0.0, f32::max);
        let (mut relit_ratio, mut truth_ratio, mut psnr) = (0.0f32, 0.0f32, 0.0);
        for &i in holdout {
            let (relit, truth) = (relighter.render(lights[i]), stack.image(i));
            psnr += Relighter::image_psnr(&relit, &truth, Some(&scene.mask)) / holdout.len() as f64;
            for p in (0..np).filter(|&p| scene.mask[p]) {
                let bound = brightest[p].max(1e-3 * peak);
                for c in 0..3 {
                    relit_ratio = relit_ratio.max(relit[3 * p + c] / bound);
                    truth_ratio = truth_ratio.max(truth[3 * p + c] / bound);
                }
            }
        }
        (relit_ratio, truth_ratio, psnr)
    }
}

#[cfg(test)]
mod tests {
    use super::testutil::{choose_exposure, fit_scene, judge_relit};
    use super::*;
    use crate::frames::rig::uniform_cone_lights;

    /// Beckmann brushed gold (a lobe outside the glTF family, a coloured metal) under 800
    /// lights, 12 of them held out: the exposure chosen by validation lights is the true one
    /// to within a factor of 2.83 (one and a half of the search's steps), and no relit pixel of
    /// the glTF or automatic fit under the held-out lights exceeds twice the brightest training
    /// sample of its pixel (the true renders stay below that); the free-scale reading alone is
    /// far off on both counts (docs/method.md, "Choosing the exposure").
    #[test]
    fn beckmann_gold_relit_without_fireflies() {
        use crate::appearance::relight::{Edits, Relighter};
        use crate::brdf::Beckmann;
        use crate::render::{Scene, TangentField};
        let lights = uniform_cone_lights(800, 65.0);
        let holdout = FitParams::holdout_lights(800, 12).unwrap();
        let scene = Scene::sphere(24, TangentField::Circular);
        let gold = Beckmann::new([0.0; 3], [1.0, 0.71, 0.29], 0.25, 0.06);
        let stack = scene.render_stack(&gold, &lights);
        for model in [FitModel::Gltf, FitModel::Auto] {
            let mut params = FitParams {
                model,
                holdout: holdout.clone(),
                ..FitParams::default()
            };
            let choice = choose_exposure(&lights, &params, &scene, &stack);
            // The free-scale reading alone is 60 times off. The validation lights tell 2 to 18
            // times the true intensity apart by under 1% here, and predict 22% worse at 1.1
            // times: the glTF lobe fits this Beckmann gold best a little above its true
            // intensity, and the lowest of the near-best is 2.2.
            assert!((0.5..2.83).contains(&choice.exposure), "{choice:?}");
            params.exposure = choice.exposure;
            let fit = fit_scene(&params, &scene, &stack, &lights);
            let relighter =
                Relighter::of_fit(&fit.ward, fit.gltf.as_ref(), &Edits::default()).unwrap();
            // The largest relit and true values over the brightest training sample.
            let (relit_ratio, truth_ratio, _) =
                judge_relit(&relighter, &scene, &stack, &lights, &holdout);
            assert!(
                truth_ratio <= 1.5 && relit_ratio <= 2.0,
                "{model:?}: relit {relit_ratio}, truth {truth_ratio}"
            );
        }
    }

    #[test]
    fn one_default_model() {
        assert_eq!(FitModel::default(), FitModel::DEFAULT);
        assert_eq!(FitParams::default().model, FitModel::DEFAULT);
        assert_eq!(FitModel::DEFAULT, FitModel::Auto);
    }

    #[test]
    fn neighbourhoods_choose_together_and_keep_their_borders() {
        // A 12 x 4 image: the clear coat predicts the left half's validation lights at a
        // tenth of glTF's error, glTF the right half's at a tenth of the coat's. Two pixels
        // disagree with their side: a bright one on the left, whose glTF error is 3x smaller
        // than the coat's but 100x the others' in absolute terms (a sum of squared errors
        // would follow it), and a dim one on the right.
        let (w, h) = (12, 4);
        let ev = |g: f64, c: f64| ModelEvidence {
            sse: [g, 2.0 * g.max(c), c, 2.0 * g.max(c)],
            signal: 1e3,
        };
        let mut evidence: Vec<Option<ModelEvidence>> = (0..w * h)
            .map(|p| {
                Some(if p % w < 6 {
                    ev(1.0, 0.1)
                } else {
                    ev(0.1, 1.0)
                })
            })
            .collect();
        evidence[w + 2] = Some(ev(100.0, 300.0));
        evidence[2 * w + 9] = Some(ev(0.5, 0.05));
        evidence[3 * w] = None;
        let params = |r| FitParams {
            choice_radius: r,
            ..FitParams::default()
        };
        // Alone, each pixel takes its own evidence.
        let alone = params(0).choose_models(&evidence, w, h).unwrap();
        assert_eq!(alone[w + 2], MODEL_GLTF);
        assert_eq!(alone[2 * w + 9], MODEL_CLEARCOAT);
        assert_eq!(alone[3 * w], MODEL_NONE);
        // Pooled over radius 2, both follow their side; the border stays where it is.
        let pooled = params(2).choose_models(&evidence, w, h).unwrap();
        for (p, &got) in pooled.iter().enumerate() {
            let want = match p {
                p if p == 3 * w => MODEL_NONE,
                p if p % w < 6 => MODEL_CLEARCOAT,
                _ => MODEL_GLTF,
            };
            assert_eq!(got, want, "pixel {p}");
        }
        // The summed-area table gives what a direct sum over each window gives.
        let xy = |p: usize| ((p % w) as i64, (p / w) as i64);
        for (p, &got) in pooled.iter().enumerate() {
            if evidence[p].is_none() {
                continue;
            }
            let (x, y) = xy(p);
            let sum = evidence
                .iter()
                .enumerate()
                .filter(|&(q, _)| {
                    let (qx, qy) = xy(q);
                    (qx - x).abs() <= 2 && (qy - y).abs() <= 2
                })
                .filter_map(|(_, e)| e.as_ref())
                .fold(LogEvidence::default(), |s, e| s.add(LogEvidence::of(e)));
            assert_eq!(sum.choice(), got, "pixel {p}");
        }
        assert!(params(2).choose_models(&evidence, w, h + 1).is_err());
        // Any radius is taken (a window wider than the image is the image).
        let all = params(usize::MAX).choose_models(&evidence, w, h).unwrap();
        assert_eq!(all, params(w).choose_models(&evidence, w, h).unwrap());
    }

    #[test]
    fn validation_lights_skip_the_held_out_ones() {
        let v = validation_lights(12, &[1, 6]);
        // Training lights 0, 2, 3, 4, 5, 7, 8, 9, 10, 11: the third of every five.
        let chosen: Vec<usize> = (0..12).filter(|&i| v[i]).collect();
        assert_eq!(chosen, vec![3, 9]);
    }

    #[test]
    fn holdout_indices_are_spread_and_bounded() {
        assert_eq!(FitParams::holdout_lights(10, 2).unwrap(), vec![2, 7]);
        assert_eq!(
            FitParams::holdout_lights(100, 0).unwrap(),
            Vec::<usize>::new()
        );
        let h = FitParams::holdout_lights(1000, 25).unwrap();
        assert_eq!(h.len(), 25);
        assert!(h.windows(2).all(|w| w[1] - w[0] == 40));
        assert!(FitParams::holdout_lights(10, 6).is_err());
    }
}
