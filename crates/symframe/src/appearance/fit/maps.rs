//! The per-pixel parameter maps a fit produces ([`WardMaps`], [`GltfMaps`], [`LobeMaps`]) and
//! their collection from the pixels' outcomes ([`FitMaps`]).

use super::{
    check_exposure, psnr_db, rms, FitParams, FitSummary, PixelOutcome, MODEL_CLEARCOAT, MODEL_GLTF,
    MODEL_NONE, MODEL_WARD, MODEL_WOVEN,
};
use crate::appearance::lobe_fit::{LobeKind, LobeModel};
use crate::error::{Error, Result};

/// Per-pixel anisotropic Ward parameters and the frames they live in: what relighting needs.
/// All maps are row-major, row 0 at the top; NaN where there is no value.
#[derive(Debug, Clone, PartialEq)]
pub struct WardMaps {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Unit normals, `H x W x 3`, camera frame.
    pub normals: Vec<f32>,
    /// Unit tangents (axis of `alpha_t`), `H x W x 3`; NaN where isotropic.
    pub tangents: Vec<f32>,
    /// Diffuse albedo, `H x W x 3`.
    pub kd: Vec<f32>,
    /// Specular albedo, `H x W x 3`.
    pub ks: Vec<f32>,
    /// Roughness along the tangent, `H x W`.
    pub alpha_t: Vec<f32>,
    /// Roughness along the binormal `n x t`, `H x W`.
    pub alpha_b: Vec<f32>,
}

impl WardMaps {
    /// Checks that every map has the size `width x height` implies.
    pub fn check(&self) -> Result<()> {
        check_sizes(
            self.width,
            self.height,
            &[
                ("normals", self.normals.len(), 3),
                ("tangents", self.tangents.len(), 3),
                ("kd", self.kd.len(), 3),
                ("ks", self.ks.len(), 3),
                ("alpha_t", self.alpha_t.len(), 1),
                ("alpha_b", self.alpha_b.len(), 1),
            ],
        )
    }
}

/// Per-pixel glTF metallic-roughness parameters with `KHR_materials_anisotropy`, the frames
/// they live in and the light intensity they were fitted under: what relighting and export
/// need. Row-major, row 0 at the top; NaN where there is no value.
#[derive(Debug, Clone, PartialEq)]
pub struct GltfMaps {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Unit normals, `H x W x 3`, camera frame.
    pub normals: Vec<f32>,
    /// Unit tangents (the anisotropy direction), `H x W x 3`; NaN where isotropic.
    pub tangents: Vec<f32>,
    /// Base colour, `H x W x 3`, in `[0, 1]`.
    pub base_color: Vec<f32>,
    /// Metalness, `H x W`.
    pub metallic: Vec<f32>,
    /// Perceptual roughness, `H x W`.
    pub roughness: Vec<f32>,
    /// Anisotropy strength, `H x W`.
    pub anisotropy: Vec<f32>,
    /// The light intensity of the fit ([`FitParams::exposure`]).
    pub exposure: f64,
}

impl GltfMaps {
    /// Checks that every map has the size `width x height` implies and the exposure is usable.
    pub fn check(&self) -> Result<()> {
        check_sizes(
            self.width,
            self.height,
            &[
                ("normals", self.normals.len(), 3),
                ("tangents", self.tangents.len(), 3),
                ("base_color", self.base_color.len(), 3),
                ("metallic", self.metallic.len(), 1),
                ("roughness", self.roughness.len(), 1),
                ("anisotropy_strength", self.anisotropy.len(), 1),
            ],
        )?;
        check_exposure(self.exposure)
    }
}

/// Per-pixel parameters of the two-lobe models ([`LobeModel`]) and the frames they live in:
/// what relighting and export need. Row-major, row 0 at the top; NaN where a pixel has no
/// two-lobe model.
#[derive(Debug, Clone, PartialEq)]
pub struct LobeMaps {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Unit normals, `H x W x 3`, camera frame.
    pub normals: Vec<f32>,
    /// Unit tangents (axis of `alpha_t`), `H x W x 3`; NaN where isotropic.
    pub tangents: Vec<f32>,
    /// Per pixel, [`FitMaps::MODEL_CLEARCOAT`], [`FitMaps::MODEL_WOVEN`] or 0 (no two-lobe
    /// model), `H x W`.
    pub kind: Vec<u8>,
    /// Diffuse albedo, `H x W x 3`.
    pub kd: Vec<f32>,
    /// The first lobe's reflectance (the clear coat's base, the woven warp), `H x W x 3`.
    pub ka: Vec<f32>,
    /// The second lobe's (the coat at normal incidence, the weft), `H x W x 3`.
    pub kb: Vec<f32>,
    /// Roughness along the tangent, `H x W`.
    pub alpha_t: Vec<f32>,
    /// Roughness along the binormal, `H x W`.
    pub alpha_b: Vec<f32>,
    /// The coat's roughness, `H x W` (NaN at woven pixels).
    pub alpha_c: Vec<f32>,
}

impl LobeMaps {
    /// Empty maps (no pixel has a model) in the frames `normals`, `tangents`.
    pub fn empty(width: usize, height: usize, normals: &[f32], tangents: &[f32]) -> Self {
        let n = width * height;
        Self {
            width,
            height,
            normals: normals.to_vec(),
            tangents: tangents.to_vec(),
            kind: vec![MODEL_NONE; n],
            kd: vec![f32::NAN; n * 3],
            ka: vec![f32::NAN; n * 3],
            kb: vec![f32::NAN; n * 3],
            alpha_t: vec![f32::NAN; n],
            alpha_b: vec![f32::NAN; n],
            alpha_c: vec![f32::NAN; n],
        }
    }

    /// Checks that every map has the size `width x height` implies.
    pub fn check(&self) -> Result<()> {
        check_sizes(
            self.width,
            self.height,
            &[
                ("normals", self.normals.len(), 3),
                ("tangents", self.tangents.len(), 3),
                ("kind", self.kind.len(), 1),
                ("kd", self.kd.len(), 3),
                ("ka", self.ka.len(), 3),
                ("kb", self.kb.len(), 3),
                ("alpha_t", self.alpha_t.len(), 1),
                ("alpha_b", self.alpha_b.len(), 1),
                ("alpha_c", self.alpha_c.len(), 1),
            ],
        )
    }

    /// The model of pixel `p`, if it has a valid one.
    pub fn model(&self, p: usize) -> Option<LobeModel> {
        let kind = match *self.kind.get(p)? {
            MODEL_CLEARCOAT => LobeKind::Clearcoat,
            MODEL_WOVEN => LobeKind::Woven,
            _ => return None,
        };
        let rgb = |v: &[f32]| -> [f64; 3] { std::array::from_fn(|c| v[3 * p + c] as f64) };
        let m = LobeModel {
            kind,
            kd: rgb(&self.kd),
            ka: rgb(&self.ka),
            kb: rgb(&self.kb),
            alpha_t: self.alpha_t[p] as f64,
            alpha_b: self.alpha_b[p] as f64,
            alpha_c: self.alpha_c[p] as f64,
        };
        m.is_valid().then_some(m)
    }

    /// Stores `m` as pixel `p`'s model.
    pub fn set(&mut self, p: usize, m: &LobeModel) {
        self.kind[p] = match m.kind {
            LobeKind::Clearcoat => MODEL_CLEARCOAT,
            LobeKind::Woven => MODEL_WOVEN,
        };
        for c in 0..3 {
            self.kd[3 * p + c] = m.kd[c] as f32;
            self.ka[3 * p + c] = m.ka[c] as f32;
            self.kb[3 * p + c] = m.kb[c] as f32;
        }
        self.alpha_t[p] = m.alpha_t as f32;
        self.alpha_b[p] = m.alpha_b as f32;
        self.alpha_c[p] = m.alpha_c as f32;
    }
}

/// The result of [`FitParams::fit_stack`].
#[derive(Debug, Clone, PartialEq)]
pub struct FitMaps {
    /// The frames used and, for a Ward fit, the fitted parameters (NaN for a glTF fit).
    pub ward: WardMaps,
    /// The fitted parameters of a glTF or automatic fit (`None` for a Ward fit).
    pub gltf: Option<GltfMaps>,
    /// The fitted parameters of a two-lobe or automatic fit (`None` otherwise).
    pub lobes: Option<LobeMaps>,
    /// Per pixel, the model fitted there: [`FitMaps::MODEL_NONE`], [`FitMaps::MODEL_WARD`],
    /// [`FitMaps::MODEL_GLTF`], [`FitMaps::MODEL_CLEARCOAT`] or [`FitMaps::MODEL_WOVEN`] (an
    /// automatic fit's choice), `H x W`.
    pub model: Vec<u8>,
    /// RMS error of the fit on each pixel's training samples, `H x W`.
    pub residual: Vec<f32>,
    /// RMS error on each pixel's held-out samples, `H x W` (NaN without any).
    pub holdout_residual: Vec<f32>,
    /// Counts and error figures.
    pub summary: FitSummary,
}

impl FitMaps {
    /// [`FitMaps::model`] where a pixel was not fitted.
    pub const MODEL_NONE: u8 = 0;
    /// [`FitMaps::model`] where a pixel's model is Ward.
    pub const MODEL_WARD: u8 = 1;
    /// [`FitMaps::model`] where a pixel's model is glTF.
    pub const MODEL_GLTF: u8 = 2;
    /// [`FitMaps::model`] where a pixel's model is the clear coat.
    pub const MODEL_CLEARCOAT: u8 = 3;
    /// [`FitMaps::model`] where a pixel's model is the woven one.
    pub const MODEL_WOVEN: u8 = 4;

    /// The maps and summary of `width x height` pixels fitted in the frames `normals` and
    /// `tangents` with `params`, from their outcomes in row-major order (`None`: outside the
    /// mask).
    pub fn from_outcomes(
        width: usize,
        height: usize,
        normals: &[f32],
        tangents: &[f32],
        params: &FitParams,
        outcomes: impl IntoIterator<Item = Option<PixelOutcome>>,
    ) -> Self {
        let (w, h) = (width, height);
        let n = w * h;
        let mut maps = FitMaps {
            ward: WardMaps {
                width: w,
                height: h,
                normals: normals.to_vec(),
                tangents: tangents.to_vec(),
                kd: vec![f32::NAN; n * 3],
                ks: vec![f32::NAN; n * 3],
                alpha_t: vec![f32::NAN; n],
                alpha_b: vec![f32::NAN; n],
            },
            lobes: params
                .model
                .uses_lobes()
                .then(|| LobeMaps::empty(w, h, normals, tangents)),
            gltf: params.model.uses_gltf().then(|| GltfMaps {
                width: w,
                height: h,
                normals: normals.to_vec(),
                tangents: tangents.to_vec(),
                base_color: vec![f32::NAN; n * 3],
                metallic: vec![f32::NAN; n],
                roughness: vec![f32::NAN; n],
                anisotropy: vec![f32::NAN; n],
                exposure: params.exposure,
            }),
            residual: vec![f32::NAN; n],
            holdout_residual: vec![f32::NAN; n],
            model: vec![MODEL_NONE; n],
            summary: FitSummary::default(),
        };
        let (mut train_sse, mut hold_sse, mut hold_peak, mut iters) = (0.0, 0.0, 0.0f64, 0u64);
        for (p, outcome) in outcomes.into_iter().enumerate() {
            let s = &mut maps.summary;
            // (isotropic, sse, samples, iterations, held-out error) of a fitted pixel.
            let fitted = match outcome {
                None => {
                    s.masked += 1;
                    continue;
                }
                Some(PixelOutcome::NoFrame) => {
                    s.no_frame += 1;
                    continue;
                }
                Some(PixelOutcome::TooFewSamples) => {
                    s.too_few_samples += 1;
                    continue;
                }
                Some(PixelOutcome::Fitted(fit, hold)) => {
                    let wm = &mut maps.ward;
                    for c in 0..3 {
                        wm.kd[p * 3 + c] = fit.kd[c] as f32;
                        wm.ks[p * 3 + c] = fit.ks[c] as f32;
                    }
                    wm.alpha_t[p] = fit.alpha_t as f32;
                    wm.alpha_b[p] = fit.alpha_b as f32;
                    maps.model[p] = MODEL_WARD;
                    s.ward_pixels += 1;
                    (fit.isotropic, fit.sse, fit.samples, fit.iterations, hold)
                }
                Some(PixelOutcome::FittedLobes(fit, hold)) => {
                    if let Some(l) = maps.lobes.as_mut() {
                        l.set(p, &fit.model);
                        if fit.isotropic {
                            l.tangents[p * 3..p * 3 + 3].fill(f32::NAN);
                        }
                    }
                    maps.model[p] = match fit.model.kind {
                        LobeKind::Clearcoat => {
                            s.clearcoat_pixels += 1;
                            MODEL_CLEARCOAT
                        }
                        LobeKind::Woven => {
                            s.woven_pixels += 1;
                            MODEL_WOVEN
                        }
                    };
                    (fit.isotropic, fit.sse, fit.samples, fit.iterations, hold)
                }
                Some(PixelOutcome::FittedGltf(fit, hold)) => {
                    if let Some(g) = maps.gltf.as_mut() {
                        for c in 0..3 {
                            g.base_color[p * 3 + c] = fit.base_color[c] as f32;
                        }
                        g.metallic[p] = fit.metallic as f32;
                        g.roughness[p] = fit.roughness as f32;
                        g.anisotropy[p] = fit.anisotropy as f32;
                        if fit.isotropic {
                            g.tangents[p * 3..p * 3 + 3].fill(f32::NAN);
                        }
                    }
                    maps.model[p] = MODEL_GLTF;
                    s.gltf_pixels += 1;
                    (fit.isotropic, fit.sse, fit.samples, fit.iterations, hold)
                }
            };
            let (isotropic, fit_sse, samples, iterations, hold) = fitted;
            if isotropic {
                // The frame used has no tangent: keep the map saying so.
                maps.ward.tangents[p * 3..p * 3 + 3].fill(f32::NAN);
            }
            maps.residual[p] = rms(fit_sse, samples) as f32;
            train_sse += fit_sse;
            s.train_samples += samples;
            iters += iterations as u64;
            if hold.samples > 0 {
                maps.holdout_residual[p] = rms(hold.sse, hold.samples) as f32;
                hold_sse += hold.sse;
                hold_peak = hold_peak.max(hold.peak);
                s.holdout_samples += hold.samples;
            }
            if isotropic {
                s.isotropic += 1;
            } else {
                s.anisotropic += 1;
            }
        }
        let s = &mut maps.summary;
        let fitted = s.anisotropic + s.isotropic;
        s.train_rms = rms(train_sse, s.train_samples);
        s.mean_iterations = iters as f64 / fitted.max(1) as f64;
        if s.holdout_samples > 0 {
            let rms = rms(hold_sse, s.holdout_samples);
            s.holdout_rms = Some(rms);
            s.holdout_peak = Some(hold_peak);
            s.holdout_psnr_db = Some(psnr_db(hold_peak, rms));
        }
        maps
    }
}

/// Checks that each map `(name, len, per)` holds `per` values for each of `width x height`
/// pixels.
fn check_sizes(width: usize, height: usize, maps: &[(&str, usize, usize)]) -> Result<()> {
    let n = width * height;
    for &(name, len, per) in maps {
        if len != n * per {
            return Err(Error::BadParameter(format!(
                "{name} map has {len} values, expected {} for {width}x{height}",
                n * per
            )));
        }
    }
    Ok(())
}
