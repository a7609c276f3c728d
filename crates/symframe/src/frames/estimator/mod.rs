//! The estimator pipeline: per pixel, the normal that makes the slice most symmetric under
//! `G_n`, then the tangent that makes it most symmetric under `G_nt` and `G_nb`, the
//! widest-highlight choice of t over b, a confidence and an anisotropy measure; and the whole
//! stack, in parallel over row bands. The maps it fills are in [`crate::maps`].

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::noise::NoiseModel;

use crate::baselines::{
    grey_values, highlight_peak, woodham_robust_greys, BaselineParams, BaselinePixel,
};
use crate::error::Result;
use crate::frames::lobe::{fit_lobe_pair, LobeFit, LobeScratch};
use crate::frames::objective::{ExactObjective, FastScratch, Level, Objective};
use crate::frames::policy::{
    self, has_tangent, tangent_confidence, NoiseShare, NormalChoice, NormalEvidence,
    PolicySettings, TangentEvidence, TangentSettings, DEFAULT_MIN_ANISOTROPY,
};
use crate::frames::rig::Rig;
use crate::frames::symmetry::{default_min_domain, CosineMode};
use crate::highlight::{highlight_moments_of_greys, HighlightMoments, HIGHLIGHT_LEVEL};
use crate::method::{run_stack, PixelMethod};
use crate::stack::Stack;

use crate::maps::{EstimateMaps, PixelRecord, PixelSource, PixelStatus};

mod censored;
mod confidence;
mod diffuse;
mod lobe_answer;
mod search;
mod shadows;

use censored::{clipped_in_colour, Censoring};
use confidence::{within_confident, ModelBuffers, ModelSlice};
use diffuse::{diffuse_noise_share, unexplained_share};
use search::{brightest_sample, centre_observed, highlight_wider_along, TangentSearch};

/// Parameters of the symmetry estimator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EstimatorParams {
    /// Cosine handling in the symmetry distance.
    pub cosine: CosineMode,
    /// Smallest domain (lights) that counts as non-empty; `None` = `default_min_domain`.
    pub min_domain: Option<u32>,
    /// Pixels whose confidence is below this are culled (no estimate).
    pub min_confidence: f32,
    /// Pixels whose anisotropy is below this get no tangent (the slice is isotropic).
    pub min_anisotropy: f32,
    /// Whether to estimate tangents at all.
    pub tangents: bool,
    /// Evaluation budget of the 2D normal search.
    pub max_normal_evals: u32,
    /// The capture's noise model: its clip level censors samples (docs/method.md, "Noise
    /// model"). The default knows nothing (float samples, nothing clipped).
    #[serde(default)]
    pub noise: NoiseModel,
    /// How the slice is reconstructed between samples.
    pub interpolation: Interpolation,
    /// What to do where the normal is beyond the rig's reach.
    pub fallback: Fallback,
}

/// How the objective reads a pixel's slice between the measured samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    /// The fast path: the same spherical barycentric weights in single precision, located by a
    /// walk from a grid cell, over the lights that can be in the domain.
    #[default]
    #[serde(alias = "resampled")]
    Fast,
    /// Triangle location and spherical barycentric weights at every query in double
    /// precision, every light visited (reference path).
    Exact,
}

impl Default for EstimatorParams {
    fn default() -> Self {
        Self {
            cosine: CosineMode::Auto,
            min_domain: None,
            min_confidence: 0.0,
            min_anisotropy: DEFAULT_MIN_ANISOTROPY,
            tangents: true,
            max_normal_evals: 300,
            noise: NoiseModel::default(),
            interpolation: Interpolation::default(),
            fallback: Fallback::default(),
        }
    }
}

/// What the estimator does at a pixel whose symmetry centre is beyond the rig's reach.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Fallback {
    /// A robust Lambertian fit where the pixel has a diffuse part, the highlight centroid
    /// otherwise; recorded in the source map with a lowered confidence.
    #[default]
    Auto,
    /// No estimate (the pixel is discarded).
    None,
}

/// The estimate at one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelEstimate {
    /// What happened.
    pub status: PixelStatus,
    /// Which method produced the normal.
    pub source: PixelSource,
    /// Unit normal in the camera frame, when estimated.
    pub normal: Option<DVec3>,
    /// Unit tangent (an axis: sign arbitrary) in the camera frame, when the slice is anisotropic.
    pub tangent: Option<DVec3>,
    /// Confidence in [0, 1]: the probability that the normal is within 1 degree of the truth
    /// (0 where nothing was estimated; docs/method.md, "Confidence").
    pub confidence: f32,
    /// Anisotropy in [0, 1]: how much the tangent objective varies with the tangent's angle
    /// (for the lobe fit: its elongation).
    pub anisotropy: f32,
    /// How clearly the data single out the tangent's axes, in [0, 1] (0 where there is no
    /// tangent; `crate::frames::policy::tangent_confidence`).
    pub tangent_confidence: f32,
    /// Symmetry distances at the solution: `[SD_n, SD_nt, SD_nb]` (for the lobe fit: `[SD_n,
    /// unexplained share, 0]`).
    pub residual: [f64; 3],
    /// Objective evaluations spent.
    pub evals: u32,
}

impl PixelEstimate {
    fn empty(status: PixelStatus) -> Self {
        Self {
            status,
            source: PixelSource::None,
            normal: None,
            tangent: None,
            confidence: 0.0,
            anisotropy: f32::NAN,
            tangent_confidence: 0.0,
            residual: [f64::NAN; 3],
            evals: 0,
        }
    }
}

/// The per-pixel estimator for one rig.
#[derive(Debug, Clone)]
pub struct Estimator<'a> {
    rig: &'a Rig,
    params: EstimatorParams,
    min_domain: u32,
    /// The choice of answer's settings (the tangent's `min_anisotropy` from the parameters).
    policy: PolicySettings,
}

impl<'a> Estimator<'a> {
    /// An estimator for `rig`.
    pub fn new(rig: &'a Rig, params: EstimatorParams) -> Self {
        let min_domain = params
            .min_domain
            .unwrap_or_else(|| default_min_domain(rig.n_used()));
        Self {
            rig,
            params,
            min_domain,
            policy: PolicySettings {
                tangent: TangentSettings {
                    min_anisotropy: params.min_anisotropy as f64,
                    ..TangentSettings::default()
                },
                ..PolicySettings::default()
            },
        }
    }

    /// The rig this estimator uses.
    pub fn rig(&self) -> &Rig {
        self.rig
    }

    /// The domain size under which a symmetry distance counts as empty.
    pub fn min_domain(&self) -> u32 {
        self.min_domain
    }

    /// The robust Lambertian fit (Woodham with outlier rejection, default parameters) of a
    /// pixel over the rig's lights: the shadow pass, the diffuse test, the sharp-lobe rule and
    /// the fallback all read the pixel's diffuse part through it.
    /// `greys` are the slice's grey values (as [`grey_values`] makes them), `work` a buffer.
    fn lambertian_fit(&self, greys: &[f64], work: &mut Vec<f64>) -> BaselinePixel {
        if work.len() < 2 * greys.len() {
            work.resize(2 * greys.len(), 0.0);
        }
        woodham_robust_greys(
            greys,
            self.rig.lights_in_camera(),
            &BaselineParams::default(),
            work,
        )
    }

    /// Estimates the frame at one pixel from its slice (rig order, `rig.n_used() * 3` values).
    pub fn estimate_pixel(&self, slice: &[f32]) -> PixelEstimate {
        let mut scratch = PixelScratch::new(self.rig);
        self.estimate_pixel_with(slice, &mut scratch)
    }

    /// [`Estimator::estimate_pixel`] with the caller's buffers (the fast path without a
    /// per-pixel allocation; unused by the reference path).
    pub fn estimate_pixel_with(&self, slice: &[f32], scratch: &mut PixelScratch) -> PixelEstimate {
        let PixelScratch {
            fast,
            shadow_levels,
            unshadowed,
            lobe,
            greys,
            lambert,
            censored,
            censoring,
            lobe_input,
            base_input,
            coloured,
            model,
        } = scratch;
        let raw = slice;
        // Clipped samples read through the censoring map: the clipped top of a highlight stays
        // in the slice, at the clip level, symmetric wherever the unclipped slice is.
        let clipped = self.params.noise.censor(slice, censored);
        let slice = if clipped { &censored[..] } else { slice };
        // The robust Lambertian fit of the slice the estimator reads (refitted once the cast
        // shadows are out): the diffuse test, the sharp-lobe rule and the fallback share it.
        // The grey values once: the Lambertian fits and the highlight's moments read them.
        grey_values(slice, greys);
        let first = self.lambertian_fit(greys, lambert);
        let (slice, fit) = if self.mark_cast_shadows(slice, &first, unshadowed, shadow_levels) {
            grey_values(unshadowed, greys);
            (&unshadowed[..], self.lambertian_fit(greys, lambert))
        } else {
            (slice, first)
        };
        // Everything a diffuse term does not explain is read through a smooth, symmetric
        // reconstruction of the slice: the lobe that explains the samples best is centred on
        // the normal (docs/method.md, "Lobe fit"). Where no lobe of the family explains the
        // pixel (interreflections, a BRDF outside the family), the search decides.
        let auto = self.params.cosine == CosineMode::Auto;
        let moments = highlight_moments_of_greys(greys, self.rig.halfway_in_camera());
        // Under the default measure, the share of the energy the fit's Lambertian term leaves
        // unexplained, once: the diffuse tests and the lobe-over-diffuse rules read it.
        let share = fit
            .normal
            .filter(|_| auto)
            .map(|n| unexplained_share(self.rig, slice, n, self.policy.shadows.min_cosine));
        // A pixel its Lambertian fit explains to the noise floor has no lobe to find.
        // Where the fit explains the pixel but for more than a noise-free share, what the
        // capture's noise would leave tells whether the rest is a lobe or noise.
        let diffuse_noise = share
            .filter(|&v| {
                fit.confidence as f64 >= self.policy.diffuse.centre_fit
                    && v >= self.policy.diffuse.pure_share
            })
            .zip(fit.normal)
            .map(|(_, n)| {
                diffuse_noise_share(
                    self.rig,
                    slice,
                    n,
                    self.policy.shadows.min_cosine,
                    &self.params.noise,
                )
            });
        let pure_diffuse = policy::pure_diffuse(&self.policy.diffuse, &fit, share, diffuse_noise);
        // A clipped sample is a lower bound the lobe's model cannot take as a value: the fit
        // leaves the clipped samples out, and where it breaks their bounds the normal is only
        // as certain as the bounds let it be (docs/method.md, "Clipped samples in the lobe
        // fit").
        let clip = self
            .params
            .noise
            .clip_level
            .filter(|_| clipped && auto && !pure_diffuse);
        if let Some(c) = clip {
            censoring.leave_out(raw, slice, c, lobe_input);
        }
        let fitted = match moments.filter(|_| auto && !pure_diffuse) {
            Some(m) if clip.is_some() => self
                .lobe_fit(lobe_input, m.normal, m.tangent, m.radius, lobe)
                .map(|first| self.bounds_checked(first, lobe_input, raw, censoring)),
            Some(m) => self.lobe_fit(slice, m.normal, m.tangent, m.radius, lobe),
            None => None,
        };
        let lobe_slice = if clip.is_some() {
            &lobe_input[..]
        } else {
            slice
        };
        // Where one lobe leaves the samples unexplained, two sharing its frame may explain them
        // (a coat over a base, a woven cross): the pair then stands for the lobe, with the axis
        // of the lobe that has one (docs/method.md, "Two lobes").
        let (fitted, paired) = match fitted {
            // A pixel the Lambertian fit explains but for a spike the rig undersamples is left
            // to it, as with one lobe.
            Some(f)
                if !policy::lobe_explains(&self.policy.lobe, &f)
                    && policy::spiked_diffuse(&self.policy.diffuse, &fit, None).is_none() =>
            {
                match fit_lobe_pair(&f, self.rig, self.params.noise.light_error_deg, lobe) {
                    Some(p) if policy::pair_explains(&self.policy.lobe, &p, &f) => {
                        let l = p.as_lobe(|l| self.lobe_has_tangent(l));
                        let pair = LobeFit {
                            evals: f.evals + p.evals,
                            noise_share: f.noise_share,
                            noise_share_sd: f.noise_share_sd,
                            ..l
                        };
                        (Some(pair), true)
                    }
                    _ => (Some(f), false),
                }
            }
            other => (other, false),
        };
        // Under a sharp coat one lobe cannot explain coat and base together: the base, fitted
        // without the coat's samples (those at or above the highlight level of the brightest),
        // is the evidence of the base's elongation and axes.
        let base = match (fitted, moments) {
            (Some(f), Some(m)) if policy::reads_base(&self.policy.lobe, m.count, &f) => {
                base_input.clear();
                base_input.extend_from_slice(lobe_slice);
                let max = greys
                    .iter()
                    .copied()
                    .filter(|v| v.is_finite())
                    .fold(0.0, f64::max);
                for (s, g) in base_input.chunks_exact_mut(3).zip(greys.iter()) {
                    if *g >= HIGHLIGHT_LEVEL * max {
                        s.fill(f32::NAN);
                    }
                }
                self.lobe_fit(base_input, f.normal, f.tangent, f.alpha[0].atan(), lobe)
            }
            _ => None,
        };
        let lobes = Lobes {
            fitted,
            base,
            paired,
        };
        let evidence = (share, diffuse_noise);
        let answer = |e: PixelEstimate| self.or_fallback(e, &fit, share, moments, fitted.as_ref());
        // The symmetry of a pixel with clipped samples reads them in the highlight's colour
        // (docs/method.md, "Clipped samples in the symmetry").
        let symmetric = match self.params.noise.clip_level.filter(|_| clipped) {
            Some(c) => {
                clipped_in_colour(slice, c, coloured);
                &coloured[..]
            }
            None => slice,
        };
        match self.params.interpolation {
            Interpolation::Exact => {
                let objective = ExactObjective::new(self.rig, symmetric);
                let pixel = (slice, (&mut *lobe, &mut *model));
                answer(self.solve(pixel, &objective, &fit, evidence, moments, lobes))
            }
            Interpolation::Fast => {
                let objective = fast.prepare(self.rig, symmetric);
                let pixel = (slice, (&mut *lobe, &mut *model));
                answer(self.solve(pixel, &objective, &fit, evidence, moments, lobes))
            }
        }
    }

    /// `e`, or where it was discarded (beyond the rig's reach) and fallbacks are on, the
    /// fallback's estimate: the fitted lobe `lobe` where it explains the pixel, or explains it
    /// much better than a diffuse term; else a robust Lambertian fit where a diffuse term
    /// explains the pixel; the highlight centroid otherwise; with a lowered confidence.
    fn or_fallback(
        &self,
        e: PixelEstimate,
        lambert: &BaselinePixel,
        share: Option<f64>,
        moments: Option<HighlightMoments>,
        lobe: Option<&LobeFit>,
    ) -> PixelEstimate {
        if e.status != PixelStatus::Discarded || self.params.fallback == Fallback::None {
            return e;
        }
        let Some((source, normal, confidence)) =
            policy::choose_fallback(&self.policy, lambert, share, moments, lobe)
        else {
            return e;
        };
        let confidence = self.policy.fallback.confidence * confidence;
        let status = self.status_of(confidence);
        let estimated = status == PixelStatus::Estimated;
        // Beyond the reach the lobe is fitted to the part of the highlight the rig sees: its
        // axes are the tangent's only where the rig samples halfway vectors at its centre, so
        // that the samples show its shape about its peak (a highlight cut off before its peak
        // fits an elongated lobe whatever the material), and then as sure as the fallback's
        // normal (docs/method.md, "Fallbacks and the source map").
        let lobe = lobe.filter(|f| {
            estimated
                && source == PixelSource::Lobe
                && self.params.tangents
                && self.lobe_has_tangent(f)
                && self.rig.covered(f.normal)
        });
        PixelEstimate {
            status,
            source,
            normal: estimated.then_some(normal),
            tangent: lobe.map(|f| f.tangent),
            anisotropy: lobe.map_or(e.anisotropy, |f| f.elongation() as f32),
            tangent_confidence: lobe.map_or(e.tangent_confidence, |_| confidence),
            confidence,
            ..e
        }
    }

    /// The estimate of one pixel with a given objective of its slice; `share` (the Lambertian
    /// term's unexplained share, default measure only) and `moments` as computed once per pixel.
    fn solve<O: Objective>(
        &self,
        (slice, model): (&[f32], ModelBuffers<'_>),
        objective: &O,
        fit: &BaselinePixel,
        (share, diffuse_noise): (Option<f64>, Option<NoiseShare>),
        moments: Option<HighlightMoments>,
        lobes: Lobes,
    ) -> PixelEstimate {
        let fitted = lobes.fitted;
        let rig = self.rig;
        let Some(j) = brightest_sample(slice) else {
            return PixelEstimate::empty(PixelStatus::NoData);
        };
        let discarded = |evals| PixelEstimate {
            evals,
            ..PixelEstimate::empty(PixelStatus::Discarded)
        };
        let mut evals = 0u32;
        // With a compensated measure, the search starts in the paper's form (p = 1).
        let mut cosine = match self.params.cosine {
            CosineMode::Compensated(_) | CosineMode::Auto => CosineMode::CrossMultiplied,
            c => c,
        };
        // The reading that answers the normal (`frames::policy::choose_normal`), from the
        // evidence gathered so far. A lobe much narrower than the spacing of the lights is read
        // through one or two samples: the piecewise-linear slice cannot be symmetric about its
        // centre, while a log-quadratic reconstruction of the lobe is, about its peak
        // (docs/method.md, "Sharp lobes"); the peak is read only where that rule asks for it.
        let auto = self.params.cosine == CosineMode::Auto;
        let sharp = moments.is_some_and(|m| m.count <= self.policy.lobe.sharp_samples);
        let evidence = NormalEvidence {
            auto,
            lobe: fitted.as_ref(),
            lambertian: fit,
            share,
            diffuse_noise,
            sharp,
        };
        let choice = policy::choose_normal(&self.policy, &evidence, || {
            highlight_peak(slice, rig.lights_in_camera())
        });
        let (n, source, lobe) = match choice {
            NormalChoice::Lobe(f) => {
                evals += f.evals;
                (f.normal, PixelSource::Lobe, Some(*f))
            }
            NormalChoice::Sharp(m, from) => (m, from, None),
            // A diffuse slice is symmetric about the normal of its Lambertian term, and a robust
            // Lambertian fit finds that centre in closed form from every lit sample, where the
            // search reads it through the interpolated slice (docs/method.md, "Default
            // measure"). The reach is checked below as for any normal.
            NormalChoice::Diffuse(m) => (m, PixelSource::Lambertian, None),
            NormalChoice::Search => {
                let from_moments = moments.map(|m| m.normal);
                match self.search_for_normal(
                    slice,
                    objective,
                    j,
                    from_moments,
                    &mut cosine,
                    &mut evals,
                ) {
                    Some(n) => (n, PixelSource::Symmetry, None),
                    None => return discarded(evals),
                }
            }
        };
        let term_n = objective.normal_term(n, cosine, Level::Full);
        if term_n.count < self.min_domain
            || term_n.denominator <= 0.0
            || n.z <= 0.0
            || !centre_observed(rig, objective, n)
        {
            return discarded(evals);
        }
        let sd_n = term_n.numerator / term_n.denominator;
        if let Some(f) = lobe {
            let e = self.lobe_estimate(slice, objective, cosine, &f, &term_n, sd_n);
            return PixelEstimate {
                evals: e.evals + evals,
                ..e
            };
        }
        let Some(found) = self.search_tangent(objective, n, cosine, &mut evals) else {
            return discarded(evals);
        };
        let (tangent, evidence) =
            self.tangent_by_evidence(objective, n, &found, moments, sharp, lobes);
        let coverage = self.coverage(slice, n, &term_n);
        // A search that doubts its own answer gives way to a lobe fit that nearly explains the
        // samples, within the reach (`frames::policy::search_gives_way`).
        let symmetry = sd_n + found.sd_nt + found.sd_nb;
        let quality = coverage / (1.0 + symmetry / self.policy.search.symmetry_scale);
        if source == PixelSource::Symmetry {
            let plausible = fitted.filter(|f| {
                policy::search_gives_way(&self.policy, quality, f, || {
                    centre_observed(rig, objective, f.normal)
                })
            });
            if let Some(f) = plausible {
                let term =
                    objective.normal_term(f.normal, CosineMode::CrossMultiplied, Level::Full);
                if term.count >= self.min_domain && term.denominator > 0.0 {
                    let sd = term.numerator / term.denominator;
                    let cross = CosineMode::CrossMultiplied;
                    let e = self.lobe_estimate(slice, objective, cross, &f, &term, sd);
                    return PixelEstimate {
                        evals: e.evals + evals + f.evals,
                        ..e
                    };
                }
            }
        }
        // Confidence: how sure the slice's symmetry is of the answer, whichever rule gave it
        // (docs/method.md, "Confidence"); read once the answer stands.
        let sd = self.answer_sd(
            objective,
            (n, &term_n),
            cosine,
            (fitted.as_ref(), lobes.paired),
            (slice, model),
            &mut evals,
        );
        let confidence = (coverage * within_confident(sd)) as f32;
        let status = self.status_of(confidence);
        let keep = status == PixelStatus::Estimated;
        PixelEstimate {
            status,
            source,
            normal: keep.then_some(n),
            tangent: if keep { tangent } else { None },
            confidence,
            anisotropy: found.anisotropy as f32,
            tangent_confidence: match tangent {
                Some(_) if keep => {
                    tangent_confidence(&self.policy.tangent, &evidence, found.f_min, found.f_max)
                }
                _ => 0.0,
            },
            residual: [sd_n, found.sd_nt, found.sd_nb],
            evals,
        }
    }

    /// The tangent where the data determine one (`frames::policy`, docs/method.md, "Tangents
    /// by evidence"), of the frame the search `found` about `n`, and the evidence read: the
    /// slice's symmetry anisotropy and an independent reading of the highlight's wide axis.
    /// Under a sharp coat (a lobe read through one or two lights) the highlight's moments are
    /// the coat's, round; the lobe fitted to the samples is the broad base's (the coat is too
    /// narrow to pull it), and its elongation, where the rig resolves it, is the base's.
    fn tangent_by_evidence<O: Objective>(
        &self,
        objective: &O,
        n: DVec3,
        found: &TangentSearch,
        moments: Option<HighlightMoments>,
        sharp: bool,
        Lobes { fitted, base, .. }: Lobes,
    ) -> (Option<DVec3>, TangentEvidence) {
        let moments_elongated = moments
            .is_some_and(|m| m.has_tangent(self.policy.tangent.min_moment_elongation))
            || (sharp && base.or(fitted).is_some_and(|f| self.lobe_has_tangent(&f)));
        let t = found.tangent;
        let b = n.cross(t);
        let evidence = TangentEvidence {
            anisotropy: found.anisotropy,
            moments_elongated,
            axes: [t, b],
            lobes: [fitted, base].map(|f| f.map(|f| self.lobe_axis(&f))),
        };
        if !(self.params.tangents && has_tangent(&self.policy.tangent, &evidence)) {
            return (None, evidence);
        }
        // Which of the two symmetry axes is the tangent (the wider highlight's): the fitted
        // lobe's or the highlight's wide axis where they are elongated (they read every sample
        // of the highlight, its clipped plateau included), else the slice probed along both
        // axes.
        let wide = base
            .or(fitted)
            .filter(|f| self.lobe_has_tangent(f))
            .map(|f| f.tangent)
            .or_else(|| {
                moments
                    .filter(|m| m.has_tangent(self.policy.tangent.min_moment_elongation))
                    .map(|m| m.tangent)
            });
        let swap = match wide {
            Some(w) => w.dot(b).abs() > w.dot(t).abs(),
            None => highlight_wider_along(objective, n, b, t),
        };
        (Some(if swap { b } else { t }), evidence)
    }

    /// A pixel's status for its `confidence`: culled under the user's threshold.
    fn status_of(&self, confidence: f32) -> PixelStatus {
        if confidence < self.params.min_confidence {
            PixelStatus::Culled
        } else {
            PixelStatus::Estimated
        }
    }
}

/// The lobes fitted to a pixel: the one of all its samples, and under a sharp coat the base's,
/// fitted without the coat's samples.
#[derive(Debug, Clone, Copy)]
struct Lobes {
    fitted: Option<LobeFit>,
    base: Option<LobeFit>,
    /// Whether `fitted` stands for two lobes sharing the frame (its parameters are one of
    /// them).
    paired: bool,
}

/// Per-thread buffers of the per-pixel estimator (the fast path's samples and light
/// layout), reused from pixel to pixel.
#[derive(Debug, Clone)]
pub struct PixelScratch {
    fast: FastScratch,
    /// The cast-shadow pass's diffuse levels `I / (n.l)`.
    shadow_levels: Vec<f64>,
    unshadowed: Vec<f32>,
    lobe: LobeScratch,
    greys: Vec<f64>,
    /// The robust Lambertian fit's work buffer (twice the lights).
    lambert: Vec<f64>,
    /// The slice through the censoring map (pixels with clipped samples).
    censored: Vec<f32>,
    /// The clipped samples' bounds, and the fit under them.
    censoring: Censoring,
    /// The lobe fit's samples, the clipped ones left out.
    lobe_input: Vec<f32>,
    /// The base lobe's samples under a sharp coat, the coat's left out.
    base_input: Vec<f32>,
    /// What the symmetry reads of a pixel with clipped samples ([`clipped_in_colour`]).
    coloured: Vec<f32>,
    /// The fitted lobe's own slice, read for the reconstruction's bias.
    model: ModelSlice,
}

impl PixelScratch {
    /// Buffers sized for `rig`.
    pub fn new(rig: &Rig) -> Self {
        Self {
            fast: FastScratch::new(rig),
            shadow_levels: Vec::with_capacity(rig.n_used()),
            unshadowed: Vec::with_capacity(rig.n_used() * 3),
            lobe: LobeScratch::default(),
            greys: Vec::with_capacity(rig.n_used()),
            lambert: vec![0.0; 2 * rig.n_used()],
            censored: Vec::with_capacity(rig.n_used() * 3),
            censoring: Censoring::default(),
            lobe_input: Vec::with_capacity(rig.n_used() * 3),
            base_input: Vec::with_capacity(rig.n_used() * 3),
            coloured: Vec::with_capacity(rig.n_used() * 3),
            model: ModelSlice::new(rig),
        }
    }
}

impl PixelRecord {
    /// The map values of an estimate.
    pub fn from_estimate(e: &PixelEstimate) -> Self {
        let scored = matches!(e.status, PixelStatus::Estimated | PixelStatus::Culled);
        Self {
            status: e.status,
            source: if scored { e.source } else { PixelSource::None },
            normal: e.normal.map_or([f32::NAN; 3], |n| n.as_vec3().to_array()),
            tangent: e.tangent.map_or([f32::NAN; 3], |t| t.as_vec3().to_array()),
            confidence: if scored { e.confidence } else { f32::NAN },
            anisotropy: if scored { e.anisotropy } else { f32::NAN },
            tangent_confidence: if scored {
                e.tangent_confidence
            } else {
                f32::NAN
            },
            residual: if scored {
                e.residual[0] as f32
            } else {
                f32::NAN
            },
            evals: e.evals,
        }
    }
}

impl PixelMethod for Estimator<'_> {
    type Scratch = PixelScratch;
    type Output = PixelRecord;

    fn lights(&self) -> Option<&[usize]> {
        Some(self.rig.input_index())
    }

    fn scratch(&self) -> PixelScratch {
        PixelScratch::new(self.rig)
    }

    fn pixel(&self, _p: usize, samples: &[f32], scratch: &mut PixelScratch) -> PixelRecord {
        PixelRecord::from_estimate(&self.estimate_pixel_with(samples, scratch))
    }

    fn masked(&self) -> PixelRecord {
        PixelRecord::MASKED
    }
}

/// Estimates every pixel of a stack (inside `mask` when given), in parallel over row bands.
/// `progress` is called with the number of pixels finished by each band.
pub fn estimate_stack(
    stack: &Stack,
    rig: &Rig,
    mask: Option<&[bool]>,
    params: EstimatorParams,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<EstimateMaps> {
    Stack::check_inputs(
        stack.width,
        stack.height,
        stack.n_lights,
        rig.n_input(),
        mask,
    )?;
    let records = run_stack(&Estimator::new(rig, params), stack, mask, progress);
    Ok(EstimateMaps::from_records(
        stack.width,
        stack.height,
        &records,
    ))
}
