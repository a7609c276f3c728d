//! One pixel's fit ([`PixelFitter`]): its samples split into fitting and validation lights,
//! each model fitted and the automatic choice between them; and the fit of a whole stack as a
//! [`PixelMethod`] ([`FitMethod`]).

use glam::DVec3;
use std::f64::consts::PI;

use super::{
    rms, validation_lights, FitModel, FitParams, MODEL_CLEARCOAT, MODEL_GLTF, MODEL_WARD,
    MODEL_WOVEN, TWO_LOBE_FLOOR, TWO_LOBE_GAIN,
};
use crate::appearance::gltf_fit::{self, GltfFit, GltfSample};
use crate::appearance::lobe_fit::{self, LobeFit, LobeKind};
use crate::appearance::ward_fit::{self, fit_samples, sse, Sample};
use crate::error::{Error, Result};
use crate::eval::vec_at;
use crate::geometry::tangent_basis;
use crate::method::PixelMethod;

/// The fitted Ward parameters of one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WardFit {
    /// Diffuse albedo per channel.
    pub kd: [f64; 3],
    /// Specular albedo per channel.
    pub ks: [f64; 3],
    /// Roughness along the tangent.
    pub alpha_t: f64,
    /// Roughness along the binormal.
    pub alpha_b: f64,
    /// Whether one roughness was fitted (no tangent given).
    pub isotropic: bool,
    /// Training samples used.
    pub samples: usize,
    /// Sum of squared errors over the training samples and channels.
    pub sse: f64,
    /// Levenberg-Marquardt iterations.
    pub iterations: u32,
}

impl WardFit {
    /// RMS error over the training samples and channels.
    pub fn rms(&self) -> f64 {
        rms(self.sse, self.samples)
    }
}

/// Held-out error sums of one pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HoldoutError {
    /// Sum of squared errors over the held-out samples and channels.
    pub sse: f64,
    /// Held-out samples evaluated.
    pub samples: usize,
    /// Largest held-out measurement.
    pub peak: f64,
}

impl HoldoutError {
    /// The error of `samples` held-out samples from their `(sse, peak)` as each model's `sse`
    /// returns them: one constructor for every model's `holdout`.
    pub(crate) fn of((sse, peak): (f64, f64), samples: usize) -> Self {
        HoldoutError { sse, samples, peak }
    }
}

/// The outcome of fitting one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PixelOutcome {
    /// Fitted: the parameters and the held-out error.
    Fitted(WardFit, HoldoutError),
    /// Fitted with the glTF model: the parameters and the held-out error.
    FittedGltf(GltfFit, HoldoutError),
    /// Fitted with a two-lobe model: the parameters and the held-out error.
    FittedLobes(LobeFit, HoldoutError),
    /// No normal, or it faces away from the view.
    NoFrame,
    /// Too few usable samples.
    TooFewSamples,
}

/// Sum of squared errors of the predicted against the measured RGB radiance over `samples`
/// (`pair(s)` gives both), and the largest measurement: the figures of either model's fit.
pub(crate) fn squared_errors<S>(
    samples: &[S],
    pair: impl Fn(&S) -> ([f64; 3], [f64; 3]),
) -> (f64, f64) {
    let mut sum = 0.0;
    let mut peak = 0.0f64;
    for s in samples {
        let (predicted, measured) = pair(s);
        for (f, i) in predicted.into_iter().zip(measured) {
            sum += (f - i).powi(2);
            peak = peak.max(i);
        }
    }
    (sum, peak)
}

/// What the automatic choice reads at a pixel: each candidate's squared error on the
/// pixel's validation samples, fitted on its other training samples ([`FitParams::holdout`]
/// apart; fitted and judged on every training sample where the pixel has too few), and the
/// squared signal judged. [`FitParams::choose_models`] pools it over neighbourhoods.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ModelEvidence {
    /// Squared errors of glTF, Ward, the clear coat and the woven lobes, in that order.
    pub sse: [f64; 4],
    /// The sum of the squared samples judged on.
    pub signal: f64,
}

impl ModelEvidence {
    /// The model this pixel's errors alone choose ([`LogEvidence::choice`]), a model code of
    /// [`FitMaps::model`](super::FitMaps::model).
    pub(crate) fn choice(&self) -> u8 {
        LogEvidence::of(self).choice()
    }
}

/// Evidence in the form it is pooled over pixels: per candidate, the sum over pixels of the
/// logarithm of its squared validation error (raised by [`TWO_LOBE_FLOOR`] of the pixel's
/// signal), and the number of pixels summed.
///
/// Why logarithms: under Gaussian errors of a variance each pixel has and no one knows, a
/// model's log-likelihood at a pixel is `-n/2 ln(SSE / n)` (the variance profiled out), so the
/// sum of `ln SSE` over pixels compares the models on the pooled evidence of every pixel, and
/// each pixel counts by the ratio of the models' errors there, not by its brightness: a few
/// pixels a model fits badly (a specular pixel fitted in a wrong minimum) cannot outvote the
/// rest, as they do in a sum of squared errors.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct LogEvidence {
    log_sse: [f64; 4],
    pixels: f64,
}

impl LogEvidence {
    /// One pixel's evidence.
    pub(crate) fn of(e: &ModelEvidence) -> Self {
        let floor = TWO_LOBE_FLOOR * e.signal;
        Self {
            log_sse: e.sse.map(|v| (v + floor).max(f64::MIN_POSITIVE).ln()),
            pixels: 1.0,
        }
    }

    /// The model chosen ([`FitMaps::MODEL_GLTF`](super::FitMaps::MODEL_GLTF) and the others):
    /// the single-lobe model (Ward or glTF) with the smaller pooled error, glTF on a tie,
    /// unless the better two-lobe model's (the clear coat on a tie) is below
    /// [`TWO_LOBE_GAIN`] times it in geometric mean over the pixels pooled. A pixel with no
    /// evidence (`pixels == 0`) gets glTF.
    pub(crate) fn choice(&self) -> u8 {
        let e = &self.log_sse;
        let single = if e[1] < e[0] { 1 } else { 0 };
        let two = if e[3] < e[2] { 3 } else { 2 };
        let k = if e[two] - e[single] < self.pixels * TWO_LOBE_GAIN.ln() {
            two
        } else {
            single
        };
        [MODEL_GLTF, MODEL_WARD, MODEL_CLEARCOAT, MODEL_WOVEN][k]
    }

    /// The sum of two pieces of evidence.
    pub(crate) fn add(self, o: Self) -> Self {
        self.combine(o, 1.0)
    }

    /// The difference of two sums of evidence.
    pub(crate) fn sub(self, o: Self) -> Self {
        self.combine(o, -1.0)
    }

    fn combine(self, o: Self, sign: f64) -> Self {
        let mut log_sse = self.log_sse;
        for (a, b) in log_sse.iter_mut().zip(o.log_sse) {
            *a += sign * b;
        }
        Self {
            log_sse,
            pixels: self.pixels + sign * o.pixels,
        }
    }
}

/// Fits pixels one at a time, reusing its sample buffers (one per thread).
#[derive(Debug, Clone)]
pub struct PixelFitter<'a> {
    lights: &'a [DVec3],
    params: &'a FitParams,
    held_out: Vec<bool>,
    /// Per light: a validation light ([`validation_lights`]).
    validation: Vec<bool>,
    /// The samples of the Ward fit.
    wsamples: Samples<Sample>,
    /// The samples of the glTF and two-lobe fits.
    gsamples: Samples<GltfSample>,
    gscratch: gltf_fit::Scratch,
    lscratch: lobe_fit::Scratch,
    /// The split of the training samples for a choice: fitted on, judged on.
    wfit: Vec<Sample>,
    wval: Vec<Sample>,
    gfit: Vec<GltfSample>,
    gval: Vec<GltfSample>,
}

impl<'a> PixelFitter<'a> {
    /// A fitter for a stack lit by `lights` (unit, camera frame, surface toward light).
    pub fn new(lights: &'a [DVec3], params: &'a FitParams) -> Result<Self> {
        params.validate(lights.len())?;
        Ok(Self::checked(lights, params))
    }

    /// [`PixelFitter::new`] for parameters already validated against `lights`.
    pub(super) fn checked(lights: &'a [DVec3], params: &'a FitParams) -> Self {
        let mut held_out = vec![false; lights.len()];
        for &i in &params.holdout {
            held_out[i] = true;
        }
        Self {
            lights,
            params,
            validation: validation_lights(lights.len(), &params.holdout),
            held_out,
            wsamples: Samples::default(),
            gsamples: Samples::default(),
            gscratch: gltf_fit::Scratch::default(),
            lscratch: lobe_fit::Scratch::default(),
            wfit: Vec::new(),
            wval: Vec::new(),
            gfit: Vec::new(),
            gval: Vec::new(),
        }
    }

    /// Fits one pixel: `normal` and `tangent` (camera frame; `tangent = None` fits one
    /// roughness), `rgb` the pixel's samples (`3 * lights.len()` values, NaN = invalid).
    pub fn fit(&mut self, normal: DVec3, tangent: Option<DVec3>, rgb: &[f32]) -> PixelOutcome {
        self.fit_as(None, normal, tangent, rgb)
    }

    /// [`PixelFitter::fit`], where `chosen` (a model code of [`super::FitMaps::model`]
    /// (super::FitMaps::model)) stands for an automatic fit's own choice at the pixel.
    fn fit_as(
        &mut self,
        chosen: Option<u8>,
        normal: DVec3,
        tangent: Option<DVec3>,
        rgb: &[f32],
    ) -> PixelOutcome {
        let Some((n, t, iso)) = pixel_frame(normal, tangent) else {
            return PixelOutcome::NoFrame;
        };
        let b = n.cross(t);
        match self.params.model {
            FitModel::Gltf => self.fit_gltf(n, t, b, iso, rgb),
            FitModel::Ward => self.fit_ward(n, t, b, iso, rgb),
            FitModel::Auto => match chosen {
                Some(c) => self.fit_chosen(c, n, t, b, iso, rgb),
                None => self.fit_auto(n, t, b, iso, rgb),
            },
            FitModel::Clearcoat => self.fit_lobes(LobeKind::Clearcoat, n, t, b, iso, rgb),
            FitModel::Woven => self.fit_lobes(LobeKind::Woven, n, t, b, iso, rgb),
        }
    }

    /// The automatic choice's evidence at one pixel (frame and samples as for
    /// [`PixelFitter::fit`]); `None` where it would not be fitted.
    fn evidence(
        &mut self,
        normal: DVec3,
        tangent: Option<DVec3>,
        rgb: &[f32],
    ) -> Option<ModelEvidence> {
        let (n, t, iso) = pixel_frame(normal, tangent)?;
        self.auto_evidence(n, t, n.cross(t), iso, rgb)
    }
}

/// The frame of a pixel with `normal` and `tangent` (camera frame): the unit normal, the unit
/// tangent (made up where there is none) and whether there was none; `None` without a normal
/// facing the view. The one reading of a pixel's frame for every fit.
fn pixel_frame(normal: DVec3, tangent: Option<DVec3>) -> Option<(DVec3, DVec3, bool)> {
    let n = normal.try_normalize().filter(|n| n.z > 0.0)?;
    let t = tangent
        .map(|t| t - t.dot(n) * n)
        .and_then(|t| t.try_normalize());
    let iso = t.is_none();
    let t = t.unwrap_or_else(|| tangent_basis(n).0);
    Some((n, t, iso))
}

/// One pixel's usable samples for one family of models.
#[derive(Debug, Clone)]
struct Samples<S> {
    /// The samples of the training lights.
    train: Vec<S>,
    /// Per sample of `train`: from a validation light.
    train_val: Vec<bool>,
    /// The samples of the held-out lights.
    test: Vec<S>,
}

impl<S> Default for Samples<S> {
    fn default() -> Self {
        Self {
            train: Vec::new(),
            train_val: Vec::new(),
            test: Vec::new(),
        }
    }
}

impl<S> Samples<S> {
    /// Replaces the samples with `make(l, rgb)` of each light `l` whose `rgb` in the pixel's
    /// samples is finite (`None`: not usable), split by `held_out` and flagged by `validation`:
    /// the same split for every model.
    fn collect(
        &mut self,
        lights: &[DVec3],
        held_out: &[bool],
        validation: &[bool],
        rgb: &[f32],
        mut make: impl FnMut(DVec3, [f64; 3]) -> Option<S>,
    ) {
        self.train.clear();
        self.train_val.clear();
        self.test.clear();
        for (i, (l, px)) in lights.iter().zip(rgb.chunks_exact(3)).enumerate() {
            if !px.iter().all(|v| v.is_finite()) {
                continue;
            }
            let Some(s) = make(*l, [px[0] as f64, px[1] as f64, px[2] as f64]) else {
                continue;
            };
            if held_out[i] {
                self.test.push(s);
            } else {
                self.train.push(s);
                self.train_val.push(validation[i]);
            }
        }
    }
}

impl<S: Copy> Samples<S> {
    /// Splits the training samples into `(fit, val)`: those not from validation lights and
    /// those from them.
    fn split(&self, fit: &mut Vec<S>, val: &mut Vec<S>) {
        fit.clear();
        val.clear();
        for (s, &f) in self.train.iter().zip(&self.train_val) {
            if f {
                val.push(*s);
            } else {
                fit.push(*s);
            }
        }
    }
}

impl PixelFitter<'_> {
    /// Collects the usable samples of one pixel for the Ward fit in the frame `(t, b, n)`.
    fn ward_samples(&mut self, n: DVec3, t: DVec3, b: DVec3, rgb: &[f32]) {
        let nv = n.z;
        let (lights, held_out, validation) = (self.lights, &self.held_out, &self.validation);
        self.wsamples
            .collect(lights, held_out, validation, rgb, |l, rgb| {
                let nl = n.dot(l);
                if nl <= 0.0 {
                    return None;
                }
                let h = (l + DVec3::Z).normalize();
                let hn = h.dot(n);
                if hn <= 0.0 {
                    return None;
                }
                Some(Sample {
                    diffuse: nl / PI,
                    spec: (nl / nv).sqrt(),
                    xt: (h.dot(t) / hn).powi(2),
                    xb: (h.dot(b) / hn).powi(2),
                    rgb,
                })
            });
    }

    /// The Ward fit of one pixel in the frame `(t, b, n)`.
    fn fit_ward(&mut self, n: DVec3, t: DVec3, b: DVec3, iso: bool, rgb: &[f32]) -> PixelOutcome {
        self.ward_samples(n, t, b, rgb);
        if self.wsamples.train.len() < self.params.min_samples {
            return PixelOutcome::TooFewSamples;
        }
        self.ward_outcome(iso, None)
    }

    /// The Ward outcome of the pixel whose samples were collected: `fit`, or where `None` the
    /// fit on every training sample, judged on the held-out ones (a forced model's fit and an
    /// automatic choice's alike).
    fn ward_outcome(&mut self, iso: bool, fit: Option<WardFit>) -> PixelOutcome {
        let fit = match fit {
            Some(fit) => fit,
            None => fit_samples(&self.wsamples.train, iso, self.params),
        };
        let hold = ward_fit::holdout(&fit, &self.wsamples.test);
        PixelOutcome::Fitted(fit, hold)
    }
}

impl PixelFitter<'_> {
    /// Collects the usable samples of one pixel for the glTF fit in the frame `(t, b, n)`;
    /// returns the view in that frame.
    fn gltf_samples(&mut self, n: DVec3, t: DVec3, b: DVec3, rgb: &[f32]) -> DVec3 {
        let local = |d: DVec3| DVec3::new(d.dot(t), d.dot(b), d.dot(n));
        let (lights, held_out, validation) = (self.lights, &self.held_out, &self.validation);
        self.gsamples
            .collect(lights, held_out, validation, rgb, |l, rgb| {
                if n.dot(l) <= 0.0 {
                    return None;
                }
                Some(GltfSample { l: local(l), rgb })
            });
        local(DVec3::Z)
    }

    /// The automatic choice at one pixel judged alone (a [`PixelFitter::fit`] of one pixel;
    /// a whole image pools its neighbourhoods' evidence, [`FitParams::choose_models`]): the
    /// model its own [`ModelEvidence`] chooses, refitted on every training sample.
    fn fit_auto(&mut self, n: DVec3, t: DVec3, b: DVec3, iso: bool, rgb: &[f32]) -> PixelOutcome {
        let Some(evidence) = self.auto_evidence(n, t, b, iso, rgb) else {
            return PixelOutcome::TooFewSamples;
        };
        self.fit_chosen(evidence.choice(), n, t, b, iso, rgb)
    }

    /// The automatic choice's evidence at one pixel in the frame `(t, b, n)`: every candidate
    /// fitted on the training samples that are not from validation lights and judged on the
    /// validation samples (without a validation sample, or with too few others, fitted and
    /// judged on every training sample); `None` where the pixel has too few samples.
    fn auto_evidence(
        &mut self,
        n: DVec3,
        t: DVec3,
        b: DVec3,
        iso: bool,
        rgb: &[f32],
    ) -> Option<ModelEvidence> {
        let v = self.gltf_samples(n, t, b, rgb);
        self.ward_samples(n, t, b, rgb);
        let min = self.params.min_samples;
        if self.wsamples.train.len() < min || self.gsamples.train.len() < min {
            return None;
        }
        let e = self.params.exposure;
        self.wsamples.split(&mut self.wfit, &mut self.wval);
        self.gsamples.split(&mut self.gfit, &mut self.gval);
        let by_validation = !self.wval.is_empty()
            && !self.gval.is_empty()
            && self.wfit.len() >= min
            && self.gfit.len() >= min;
        let (wtrain, gtrain, judged) = if by_validation {
            (&self.wfit, &self.gfit, &self.gval)
        } else {
            (
                &self.wsamples.train,
                &self.gsamples.train,
                &self.gsamples.train,
            )
        };
        let params = self.params;
        let ward = fit_samples(wtrain, iso, params);
        let gltf = gltf_fit::fit_samples(gtrain, v, iso, params, &mut self.gscratch);
        let lobes = [LobeKind::Clearcoat, LobeKind::Woven]
            .map(|k| lobe_fit::fit_samples(k, gtrain, v, iso, params, &mut self.lscratch));
        let sse = if by_validation {
            [
                gltf_fit::sse(&gltf, &self.gval, v, e).0,
                sse(&ward, &self.wval).0,
                lobe_fit::sse(&lobes[0], &self.gval, v).0,
                lobe_fit::sse(&lobes[1], &self.gval, v).0,
            ]
        } else {
            [gltf.sse, ward.sse, lobes[0].sse, lobes[1].sse]
        };
        let signal: f64 = judged.iter().flat_map(|s| s.rgb).map(|v| v * v).sum();
        Some(ModelEvidence { sse, signal })
    }

    /// The fit of one pixel in the frame `(t, b, n)` with the model `choice`
    /// ([`FitMaps::MODEL_WARD`](super::FitMaps::MODEL_WARD) and the others), on every training
    /// sample.
    fn fit_chosen(
        &mut self,
        choice: u8,
        n: DVec3,
        t: DVec3,
        b: DVec3,
        iso: bool,
        rgb: &[f32],
    ) -> PixelOutcome {
        match choice {
            MODEL_WARD => self.fit_ward(n, t, b, iso, rgb),
            MODEL_CLEARCOAT => self.fit_lobes(LobeKind::Clearcoat, n, t, b, iso, rgb),
            MODEL_WOVEN => self.fit_lobes(LobeKind::Woven, n, t, b, iso, rgb),
            MODEL_GLTF => self.fit_gltf(n, t, b, iso, rgb),
            _ => PixelOutcome::TooFewSamples,
        }
    }

    /// A two-lobe fit of one pixel in the frame `(t, b, n)`.
    fn fit_lobes(
        &mut self,
        kind: LobeKind,
        n: DVec3,
        t: DVec3,
        b: DVec3,
        iso: bool,
        rgb: &[f32],
    ) -> PixelOutcome {
        let v = self.gltf_samples(n, t, b, rgb);
        if self.gsamples.train.len() < self.params.min_samples {
            return PixelOutcome::TooFewSamples;
        }
        self.lobe_outcome(kind, v, iso, None)
    }

    /// The two-lobe outcome of the pixel whose samples were collected (`v` the view in its
    /// frame): `fit`, or where `None` the `kind` fit on every training sample, judged on the
    /// held-out ones (a forced model's fit and an automatic choice's alike).
    fn lobe_outcome(
        &mut self,
        kind: LobeKind,
        v: DVec3,
        iso: bool,
        fit: Option<LobeFit>,
    ) -> PixelOutcome {
        let (train, params) = (&self.gsamples.train, self.params);
        let fit = match fit {
            Some(fit) => fit,
            None => lobe_fit::fit_samples(kind, train, v, iso, params, &mut self.lscratch),
        };
        let hold = lobe_fit::holdout(&fit, &self.gsamples.test, v);
        PixelOutcome::FittedLobes(fit, hold)
    }

    /// The squared error on the validation samples (`validation_lights`) of a glTF fit at
    /// `exposure` made on the pixel's other training samples, and the number of validation
    /// values (3 per sample); `None` where the pixel would not be fitted or has no validation
    /// sample. What [`super::ExposureChoice::select`] sums over pixels.
    pub fn gltf_validation_error(
        &mut self,
        normal: DVec3,
        tangent: Option<DVec3>,
        rgb: &[f32],
        exposure: f64,
    ) -> Option<(f64, usize)> {
        let (n, t, iso) = pixel_frame(normal, tangent)?;
        let v = self.gltf_samples(n, t, n.cross(t), rgb);
        self.gsamples.split(&mut self.gfit, &mut self.gval);
        if self.gfit.len() < self.params.min_samples || self.gval.is_empty() {
            return None;
        }
        let params = FitParams {
            exposure,
            ..self.params.clone()
        };
        let fit = gltf_fit::fit_samples(&self.gfit, v, iso, &params, &mut self.gscratch);
        Some((
            gltf_fit::sse(&fit, &self.gval, v, exposure).0,
            3 * self.gval.len(),
        ))
    }

    /// The glTF fit of one pixel in the frame `(t, b, n)`.
    fn fit_gltf(&mut self, n: DVec3, t: DVec3, b: DVec3, iso: bool, rgb: &[f32]) -> PixelOutcome {
        let v = self.gltf_samples(n, t, b, rgb);
        if self.gsamples.train.len() < self.params.min_samples {
            return PixelOutcome::TooFewSamples;
        }
        self.gltf_outcome(v, iso, None)
    }

    /// The glTF outcome of the pixel whose samples were collected (`v` the view in its
    /// frame): `fit`, or where `None` the fit on every training sample, judged on the held-out
    /// ones (a forced model's fit and an automatic choice's alike).
    fn gltf_outcome(&mut self, v: DVec3, iso: bool, fit: Option<GltfFit>) -> PixelOutcome {
        let (train, params) = (&self.gsamples.train, self.params);
        let fit = match fit {
            Some(fit) => fit,
            None => gltf_fit::fit_samples(train, v, iso, params, &mut self.gscratch),
        };
        let hold = gltf_fit::holdout(&fit, &self.gsamples.test, v, params.exposure);
        PixelOutcome::FittedGltf(fit, hold)
    }

    /// A free-scale glTF fit of one pixel (its own light intensity), on the training samples,
    /// for choosing the exposure ([`gltf_fit::choose_exposure`]); `None` where the pixel would
    /// not be fitted.
    pub(crate) fn scale(
        &mut self,
        normal: DVec3,
        tangent: Option<DVec3>,
        rgb: &[f32],
    ) -> Option<gltf_fit::PixelScale> {
        let (n, t, iso) = pixel_frame(normal, tangent)?;
        let v = self.gltf_samples(n, t, n.cross(t), rgb);
        if self.gsamples.train.len() < self.params.min_samples {
            return None;
        }
        Some(gltf_fit::fit_exposure(
            &self.gsamples.train,
            v,
            iso,
            self.params,
            &mut self.gscratch,
        ))
    }
}

/// The Ward fit as a [`PixelMethod`]: every pixel fitted in its frame of the `normals` and
/// `tangents` maps (`H x W x 3`, NaN tangent = isotropic); `None` outside the mask.
#[derive(Debug, Clone, Copy)]
pub struct FitMethod<'a> {
    lights: &'a [DVec3],
    params: &'a FitParams,
    normals: &'a [f32],
    tangents: &'a [f32],
    /// An automatic fit's model per pixel, chosen from the evidence of its neighbourhood
    /// ([`FitMethod::with_choices`]); `None`: each pixel's own evidence.
    choices: Option<&'a [u8]>,
}

impl<'a> FitMethod<'a> {
    /// Checks `params` against the `lights` (unit, camera frame, one per input light) and the
    /// frame maps against the image size `n_pixels`.
    pub fn new(
        lights: &'a [DVec3],
        params: &'a FitParams,
        normals: &'a [f32],
        tangents: &'a [f32],
        n_pixels: usize,
    ) -> Result<Self> {
        check_frame_maps(normals, tangents, n_pixels)?;
        params.validate(lights.len())?;
        Ok(Self {
            lights,
            params,
            normals,
            tangents,
            choices: None,
        })
    }

    /// The pass that gathers an automatic fit's evidence, pixel by pixel
    /// ([`FitParams::choose_models`] turns it into the model of each pixel); `None` where the
    /// fit does not choose (a forced model).
    pub fn evidence_pass(
        &self,
    ) -> Option<impl PixelMethod<Scratch = PixelFitter<'a>, Output = Option<ModelEvidence>> + 'a>
    {
        (self.params.model == FitModel::Auto).then_some(EvidenceMethod(*self))
    }

    /// This fit with an automatic fit's model at each pixel given by `choices` (`H x W`, from
    /// [`FitParams::choose_models`]).
    ///
    /// # Errors
    /// When `choices` is not one per pixel.
    pub fn with_choices(self, choices: &'a [u8]) -> Result<Self> {
        if choices.len() * 3 != self.normals.len() {
            return Err(Error::BadParameter(format!(
                "{} model choices for {} pixels",
                choices.len(),
                self.normals.len() / 3
            )));
        }
        Ok(Self {
            choices: Some(choices),
            ..self
        })
    }
}

/// Checks that the `normals` and `tangents` maps (`H x W x 3`) are of images of `n_pixels`
/// pixels: the one check of every reader of frame maps beside a stack.
pub(crate) fn check_frame_maps(normals: &[f32], tangents: &[f32], n_pixels: usize) -> Result<()> {
    for (name, len) in [("normal", normals.len()), ("tangent", tangents.len())] {
        if len != n_pixels * 3 {
            return Err(Error::BadParameter(format!(
                "the {name} map has {len} values but the images have {n_pixels} pixels \
                 ({} values expected)",
                n_pixels * 3
            )));
        }
    }
    Ok(())
}

/// The evidence pass of an automatic fit ([`FitMethod::evidence_pass`]) as a
/// [`PixelMethod`]: each pixel's [`ModelEvidence`]; `None` outside the mask or where the
/// pixel would not be fitted.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EvidenceMethod<'a>(FitMethod<'a>);

impl<'a> PixelMethod for EvidenceMethod<'a> {
    type Scratch = PixelFitter<'a>;
    type Output = Option<ModelEvidence>;

    fn lights(&self) -> Option<&[usize]> {
        None
    }

    fn scratch(&self) -> PixelFitter<'a> {
        self.0.scratch()
    }

    fn pixel(&self, p: usize, samples: &[f32], fitter: &mut PixelFitter<'a>) -> Self::Output {
        let normal = vec_at(self.0.normals, p)?;
        fitter.evidence(normal, vec_at(self.0.tangents, p), samples)
    }

    fn masked(&self) -> Self::Output {
        None
    }
}

impl<'a> PixelMethod for FitMethod<'a> {
    type Scratch = PixelFitter<'a>;
    type Output = Option<PixelOutcome>;

    fn lights(&self) -> Option<&[usize]> {
        None
    }

    fn scratch(&self) -> PixelFitter<'a> {
        PixelFitter::checked(self.lights, self.params)
    }

    fn pixel(&self, p: usize, samples: &[f32], fitter: &mut PixelFitter<'a>) -> Self::Output {
        let Some(normal) = vec_at(self.normals, p) else {
            return Some(PixelOutcome::NoFrame);
        };
        let chosen = self.choices.map(|c| c[p]);
        Some(fitter.fit_as(chosen, normal, vec_at(self.tangents, p), samples))
    }

    fn masked(&self) -> Self::Output {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::fit::testutil::fit_one;
    use crate::brdf::ward::Ward;
    use crate::frames::rig::uniform_cone_lights;

    /// One pixel's samples of a Ward BRDF in the frame (n, t, b = n x t), x = t.
    fn render_pixel(w: &Ward, n: DVec3, t: DVec3, lights: &[DVec3]) -> Vec<f32> {
        crate::brdf::testutil::render_pixel(w, n, t, lights, 1.0)
    }

    /// The default parameters with the Ward model forced (what `--model ward` asks for).
    fn ward_params() -> FitParams {
        FitParams {
            model: FitModel::Ward,
            ..FitParams::default()
        }
    }

    fn frame() -> (DVec3, DVec3) {
        let n = DVec3::new(0.3, -0.2, 0.9).normalize();
        let t = tangent_basis(n).0 * 0.6 + tangent_basis(n).1 * 0.8;
        (n, t)
    }

    #[test]
    fn prediction_matches_the_ward_model() {
        let (n, t) = frame();
        let lights = uniform_cone_lights(200, 65.0);
        let w = Ward::new([0.3, 0.2, 0.1], [0.4, 0.5, 0.6], 0.3, 0.08);
        let rgb = render_pixel(&w, n, t, &lights);
        let params = ward_params();
        let mut f = PixelFitter::new(&lights, &params).unwrap();
        f.fit(n, Some(t), &rgb);
        let fit = WardFit {
            kd: w.kd,
            ks: w.ks,
            alpha_t: w.alpha_x,
            alpha_b: w.alpha_y,
            isotropic: false,
            samples: 0,
            sse: 0.0,
            iterations: 0,
        };
        let (err, peak) = sse(&fit, &f.wsamples.train);
        assert!(f.wsamples.train.len() > 100);
        assert!(err < 1e-10 * peak * peak, "{err} {peak}");
    }

    #[test]
    fn recovers_anisotropic_ward_exactly() {
        let (n, t) = frame();
        let lights = uniform_cone_lights(500, 65.0);
        for (kd, ks, at, ab) in [
            ([0.3, 0.2, 0.1], [0.4, 0.5, 0.6], 0.3, 0.08),
            ([0.5; 3], [0.5; 3], 0.5, 0.1),
            ([0.05, 0.1, 0.2], [0.9, 0.8, 0.7], 0.15, 0.12),
            ([0.6, 0.6, 0.6], [0.0, 0.05, 0.1], 0.25, 0.1),
        ] {
            let w = Ward::new(kd, ks, at, ab);
            let rgb = render_pixel(&w, n, t, &lights);
            let params = ward_params();
            let PixelOutcome::Fitted(fit, _) = fit_one(&lights, &params, n, Some(t), &rgb) else {
                panic!("not fitted")
            };
            for c in 0..3 {
                assert!((fit.kd[c] - kd[c]).abs() < 1e-4, "{fit:?} {kd:?}");
                assert!((fit.ks[c] - ks[c]).abs() < 1e-4, "{fit:?} {ks:?}");
            }
            if ks.iter().any(|&v| v > 0.01) {
                assert!((fit.alpha_t / at - 1.0).abs() < 1e-3, "{fit:?}");
                assert!((fit.alpha_b / ab - 1.0).abs() < 1e-3, "{fit:?}");
            }
            assert!(fit.rms() < 1e-5, "{fit:?}");
        }
    }

    #[test]
    fn isotropic_pixels_get_one_roughness() {
        let (n, t) = frame();
        let lights = uniform_cone_lights(400, 65.0);
        let w = Ward::isotropic([0.2, 0.3, 0.4], [0.5, 0.4, 0.3], 0.12);
        let rgb = render_pixel(&w, n, t, &lights);
        let params = ward_params();
        let PixelOutcome::Fitted(fit, _) = fit_one(&lights, &params, n, None, &rgb) else {
            panic!("not fitted")
        };
        assert!(fit.isotropic);
        assert_eq!(fit.alpha_t, fit.alpha_b);
        assert!((fit.alpha_t / 0.12 - 1.0).abs() < 1e-3, "{fit:?}");
        assert!((fit.ks[0] - 0.5).abs() < 1e-4 && (fit.kd[2] - 0.4).abs() < 1e-4);
    }

    #[test]
    fn invalid_and_back_facing_samples_are_excluded_and_holdout_is_judged() {
        let (n, t) = frame();
        let lights = uniform_cone_lights(300, 65.0);
        let w = Ward::new([0.3; 3], [0.4; 3], 0.2, 0.1);
        let mut rgb = render_pixel(&w, n, t, &lights);
        // Corrupt samples that are marked invalid: must not matter.
        for i in (0..300).step_by(7) {
            rgb[i * 3..i * 3 + 3].fill(f32::NAN);
        }
        let params = FitParams {
            holdout: FitParams::holdout_lights(300, 10).unwrap(),
            ..ward_params()
        };
        let PixelOutcome::Fitted(fit, hold) = fit_one(&lights, &params, n, Some(t), &rgb) else {
            panic!("not fitted")
        };
        assert!((fit.alpha_t / 0.2 - 1.0).abs() < 1e-3, "{fit:?}");
        let lit = (0..300).filter(|&i| n.dot(lights[i]) > 0.0).count();
        assert!(fit.samples < lit, "{} {lit}", fit.samples);
        assert!(hold.samples > 0 && hold.samples <= 10);
        assert!((hold.sse / hold.samples as f64).sqrt() < 1e-5, "{hold:?}");
    }

    #[test]
    fn pixels_without_frames_or_samples_are_reported() {
        let lights = uniform_cone_lights(50, 65.0);
        let params = FitParams::default();
        let mut f = PixelFitter::new(&lights, &params).unwrap();
        let rgb = vec![f32::NAN; 150];
        assert_eq!(
            f.fit(DVec3::new(0.0, 0.0, -1.0), None, &rgb),
            PixelOutcome::NoFrame
        );
        assert_eq!(f.fit(DVec3::Z, None, &rgb), PixelOutcome::TooFewSamples);
        let bad = FitParams {
            holdout: vec![50],
            ..FitParams::default()
        };
        assert!(PixelFitter::new(&lights, &bad).is_err());
    }
}
