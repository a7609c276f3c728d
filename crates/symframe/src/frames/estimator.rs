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
use crate::frames::lobe::{fit_lobe, fit_lobe_pair, LobeFit, LobeScratch, LobeStart};
use crate::frames::objective::{ExactObjective, FastScratch, Level, Objective};
use crate::frames::optim::{nelder_mead, NelderMeadOptions};
use crate::frames::policy::{
    self, has_tangent, tangent_confidence, LobeAxis, NormalChoice, NormalEvidence, PolicySettings,
    TangentEvidence, TangentSettings, DEFAULT_MIN_ANISOTROPY,
};
use crate::frames::rig::Rig;
use crate::frames::symmetry::{
    default_min_domain, CosineMode, Frame, SymmetryTerm, EMPTY_DISTANCE,
};
use crate::geometry::tangent_basis;
use crate::highlight::{highlight_moments_of_greys, HighlightMoments, HIGHLIGHT_LEVEL};
use crate::method::{run_stack, PixelMethod};
use crate::stack::Stack;

use crate::maps::{EstimateMaps, PixelRecord, PixelSource, PixelStatus};

/// Parameters of the symmetry estimator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EstimatorParams {
    /// Cosine handling in the symmetry distance.
    pub cosine: CosineMode,
    /// Smallest domain (lights) that counts as non-empty; `None` = [`default_min_domain`].
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
    /// Confidence in [0, 1]: the probability that the normal is within
    /// [`CONFIDENT_WITHIN_DEG`] of the truth (0 where nothing was estimated).
    pub confidence: f32,
    /// Anisotropy in [0, 1]: how much the tangent objective varies with the tangent's angle
    /// (for the lobe fit: its elongation).
    pub anisotropy: f32,
    /// How clearly the data single out the tangent's axes, in [0, 1] (0 where there is no
    /// tangent; [`crate::frames::policy::tangent_confidence`]).
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

/// Number of angles the tangent objective is scanned at over its period (90 degrees) before
/// the 1D refinement; also the samples of the anisotropy measure.
const TANGENT_SCAN: usize = 9;

/// Absolute floor of the anisotropy ratio's denominator: symmetry distances below this are
/// interpolation noise, not anisotropy.
const ANISOTROPY_FLOOR: f64 = 1e-3;

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

    /// The domain size under which a distance at `level` counts as empty: the rig's minimum
    /// scaled to the share of lights the level visits (never below 6 lights).
    fn min_count<O: Objective>(&self, objective: &O, level: Level) -> u32 {
        let full = objective.queries(Level::Full).max(1);
        let part = objective.queries(level);
        if part >= full {
            self.min_domain
        } else {
            ((self.min_domain as usize * part).div_ceil(full) as u32)
                .max(6)
                .min(self.min_domain)
        }
    }

    /// `SD_n` at a candidate normal.
    fn normal_distance<O: Objective>(
        &self,
        objective: &O,
        n: DVec3,
        cosine: CosineMode,
        level: Level,
    ) -> f64 {
        if n.z <= 0.0 {
            return EMPTY_DISTANCE;
        }
        objective
            .normal_term(n, cosine, level)
            .distance(self.min_count(objective, level))
    }

    /// `SD_nt + SD_nb` at a candidate tangent of a fixed normal, and the smaller domain.
    fn tangent_distance<O: Objective>(
        &self,
        objective: &O,
        n: DVec3,
        t: DVec3,
        cosine: CosineMode,
        level: Level,
    ) -> (f64, u32) {
        let min = self.min_count(objective, level);
        let [nt, nb] = objective.tangent_terms(Frame::new(n, t), cosine, level);
        (nt.distance(min) + nb.distance(min), nt.count.min(nb.count))
    }

    /// Minimises `SD_n` with 2D Nelder-Mead on the gnomonic chart of the tangent plane at
    /// `start`, initial simplex `step` radians; returns the normal and the evaluations used.
    fn search_normal<O: Objective>(
        &self,
        objective: &O,
        start: DVec3,
        cosine: CosineMode,
        level: Level,
        step: f64,
        budget: u32,
    ) -> (DVec3, u32) {
        let (u, w) = tangent_basis(start);
        let chart = |x: &[f64; 2]| (start + x[0] * u + x[1] * w).normalize();
        let m = nelder_mead(
            |x: &[f64; 2]| self.normal_distance(objective, chart(x), cosine, level),
            [0.0, 0.0],
            [step, step],
            NelderMeadOptions {
                max_evals: budget,
                x_tolerance: 1e-4,
                f_tolerance: f64::INFINITY,
            },
        );
        (chart(&m.x), m.evals)
    }

    /// Coarse to fine: Nelder-Mead on the coarse level `coarse` from `start` (simplex `step`,
    /// at most `budget` evaluations), a restart there with a small simplex against premature
    /// collapse, and a polish on the full level. Where the coarse domain at the coarse
    /// solution is too small to trust, the coarse stages are repeated on a larger prefix.
    fn minimise_normal<O: Objective>(
        &self,
        objective: &O,
        start: DVec3,
        cosine: CosineMode,
        mut coarse: Level,
        step: f64,
        budget: u32,
    ) -> (DVec3, u32) {
        let mut evals = 0;
        let mut n = start;
        let mut step = step;
        for _ in 0..3 {
            let (m, e1) = self.search_normal(objective, n, cosine, coarse, step, budget);
            let (m, e2) = self.search_normal(objective, m, cosine, coarse, 0.01, 20);
            evals += e1 + e2;
            let count = objective.normal_term(m, cosine, coarse).count;
            evals += 1;
            if coarse == Level::Full || count >= COARSE_RELIABLE {
                n = m;
                break;
            }
            // Too few lights: grow the prefix to reach the target domain, restart from the
            // original start if the coarse solution has no domain at all.
            coarse = coarse_level(objective, coarse, count, 2 * COARSE_RELIABLE);
            if count >= 6 {
                n = m;
                step = step.min(0.05);
            }
        }
        let (n, e) = self.quadratic_polish(objective, n, cosine, POLISH_RADIUS_DEG.to_radians());
        (n, evals + e)
    }

    /// One quadratic-fit step on the full level: the objective at a 3x3 stencil of spacing `r`
    /// radians around `centre` on its tangent plane, a least-squares quadratic through the nine
    /// values, and its minimum (the best stencil point where the fit has no minimum nearby).
    fn quadratic_polish<O: Objective>(
        &self,
        objective: &O,
        centre: DVec3,
        cosine: CosineMode,
        r: f64,
    ) -> (DVec3, u32) {
        let (u, w) = tangent_basis(centre);
        let chart = |x: f64, y: f64| (centre + x * u + y * w).normalize();
        let mut f = [[0.0f64; 3]; 3];
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for (i, row) in f.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                let (x, y) = ((i as f64 - 1.0) * r, (j as f64 - 1.0) * r);
                *v = self.normal_distance(objective, chart(x, y), cosine, Level::Full);
                if *v < best.0 {
                    best = (*v, x, y);
                }
            }
        }
        if f.iter().flatten().any(|v| *v >= EMPTY_DISTANCE) {
            return (chart(best.1, best.2), 9);
        }
        let q = StencilQuadratic::of(&f, r);
        if let Some([x, y]) = q.minimum() {
            if x.abs() <= 1.5 * r && y.abs() <= 1.5 * r {
                return (chart(x, y), 9);
            }
        }
        (chart(best.1, best.2), 9)
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

    /// The search's answer `found`, unless one of `starts` has a clearly lower `SD_n` on the full
    /// level (below [`SearchSettings::judge_margin`] times it):
    /// then the coarse levels misled the search (a lobe narrower than their spacing is aliased
    /// there), and a full-level search from the best start decides. The result never has a
    /// higher full-level distance than the best start.
    fn judge_at_full<'s, O: Objective>(
        &self,
        objective: &O,
        found: DVec3,
        starts: impl Iterator<Item = &'s DVec3>,
        cosine: CosineMode,
    ) -> (DVec3, u32) {
        let full = |n: DVec3| self.normal_distance(objective, n, cosine, Level::Full);
        let mut evals = 1;
        let at_found = full(found);
        let mut best = (at_found, found);
        for &s in starts {
            let v = full(s);
            evals += 1;
            if v < best.0 {
                best = (v, s);
            }
        }
        // Only a clear win counts: near-ties would make the outcome hang on rounding (the fast
        // and reference paths must take the same branch), and a misled search ends several
        // times above its start.
        if best.1 == found || best.0 >= self.policy.search.judge_margin * at_found {
            return (found, evals);
        }
        let (m, e) = self.search_normal(objective, best.1, cosine, Level::Full, 0.02, 80);
        let (m, e2) = self.quadratic_polish(objective, m, cosine, POLISH_RADIUS_DEG.to_radians());
        let v = full(m);
        evals += e + e2 + 1;
        (if v < best.0 { m } else { best.1 }, evals)
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
            lobe_input,
            base_input,
        } = scratch;
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
                diffuse_noise_limit(
                    self.rig,
                    slice,
                    n,
                    self.policy.shadows.min_cosine,
                    &self.params.noise,
                    self.policy.diffuse.noise_z,
                )
            });
        let pure_diffuse = policy::pure_diffuse(&self.policy.diffuse, &fit, share, diffuse_noise);
        // The lobe's model has no clip: a censored sample tells it nothing it can fit (copied
        // only where a lobe is fitted).
        let lobe_slice = match self
            .params
            .noise
            .clip_level
            .filter(|_| clipped && auto && !pure_diffuse)
        {
            Some(c) => {
                lobe_input.clear();
                lobe_input.extend_from_slice(slice);
                for s in lobe_input.chunks_exact_mut(3).filter(|s| s[0] >= c) {
                    s.fill(f32::NAN);
                }
                &lobe_input[..]
            }
            None => slice,
        };
        let fitted = if auto && !pure_diffuse {
            moments.and_then(|m| self.lobe_fit(lobe_slice, m.normal, m.tangent, m.radius, lobe))
        } else {
            None
        };
        // Where one lobe leaves the samples unexplained, two sharing its frame may explain them
        // (a coat over a base, a woven cross): the pair then stands for the lobe, with the axis
        // of the lobe that has one (docs/method.md, "Two lobes").
        let fitted = match fitted {
            // A pixel the Lambertian fit explains but for a spike the rig undersamples is left
            // to it, as with one lobe.
            Some(f)
                if !policy::lobe_explains(&self.policy.lobe, &f)
                    && policy::spiked_diffuse(&self.policy.diffuse, &fit, None).is_none() =>
            {
                match fit_lobe_pair(&f, self.rig, lobe) {
                    Some(p) if policy::pair_explains(&self.policy.lobe, &p, &f) => {
                        let l = p.as_lobe(|l| self.lobe_has_tangent(l));
                        Some(LobeFit {
                            evals: f.evals + p.evals,
                            light_sd: f.light_sd,
                            noise_share: f.noise_share,
                            noise_share_sd: f.noise_share_sd,
                            ..l
                        })
                    }
                    _ => Some(f),
                }
            }
            other => other,
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
        let lobes = Lobes { fitted, base };
        match self.params.interpolation {
            Interpolation::Exact => {
                let objective = ExactObjective::new(self.rig, slice);
                let e = self.solve(
                    slice,
                    &objective,
                    &fit,
                    (share, diffuse_noise),
                    moments,
                    lobes,
                );
                self.or_fallback(e, &fit, share, moments, fitted.as_ref())
            }
            Interpolation::Fast => {
                let objective = fast.prepare(self.rig, slice);
                let e = self.solve(
                    slice,
                    &objective,
                    &fit,
                    (share, diffuse_noise),
                    moments,
                    lobes,
                );
                self.or_fallback(e, &fit, share, moments, fitted.as_ref())
            }
        }
    }

    /// Copies `slice` into `out` with the samples in cast shadow marked invalid (NaN), when the
    /// pixel has a diffuse part to tell them by; returns whether any was marked. A cast shadow
    /// (a light the surface faces but something else blocks) is not symmetric: left in, its
    /// zeros pull the normal away from the light (measured: 7 degrees mean on a Lambertian bumpy
    /// scene). A robust Lambertian fit `g` over the unshadowed samples predicts the diffuse
    /// part; a sample far below the prediction where it is clearly lit is in shadow. Pixels the
    /// fit does not explain (metals) are left as they are: their dark samples are the lobe's
    /// tails.
    fn mark_cast_shadows(
        &self,
        slice: &[f32],
        fit: &BaselinePixel,
        out: &mut Vec<f32>,
        scratch: &mut Vec<f64>,
    ) -> bool {
        let lights = self.rig.lights_in_camera();
        let Some(n) = fit
            .normal
            .filter(|_| fit.confidence as f64 >= self.policy.shadows.diffuse_fit)
        else {
            return false;
        };
        // The albedo along n: the mean of I / (n.l) over the well-lit samples the fit used is
        // not at hand, so take the brightest diffuse-looking level, the 90th percentile of
        // I / (n.l) over lights with n.l >= 0.3.
        scratch.clear();
        for (s, l) in slice.chunks_exact(3).zip(lights) {
            let nl = n.dot(*l);
            let v = (s[0] + s[1] + s[2]) as f64;
            if nl >= 0.3 && v.is_finite() {
                scratch.push(v / nl);
            }
        }
        if scratch.len() < 8 {
            return false;
        }
        let k = scratch.len() * 9 / 10;
        let (_, &mut albedo, _) = scratch.select_nth_unstable_by(k, f64::total_cmp);
        out.clear();
        out.extend_from_slice(slice);
        let mut marked = false;
        for (s, l) in out.chunks_exact_mut(3).zip(lights) {
            let nl = n.dot(*l);
            let v = (s[0] + s[1] + s[2]) as f64;
            if nl >= self.policy.shadows.min_cosine
                && v < self.policy.shadows.fraction * albedo * nl
            {
                s.fill(f32::NAN);
                marked = true;
            }
        }
        marked
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
        PixelEstimate {
            status,
            source,
            normal: (status == PixelStatus::Estimated).then_some(normal),
            confidence,
            ..e
        }
    }

    /// The estimate of one pixel with a given objective of its slice; `share` (the Lambertian
    /// term's unexplained share, default measure only) and `moments` as computed once per pixel.
    fn solve<O: Objective>(
        &self,
        slice: &[f32],
        objective: &O,
        fit: &BaselinePixel,
        (share, diffuse_noise): (Option<f64>, Option<f64>),
        moments: Option<HighlightMoments>,
        lobes: Lobes,
    ) -> PixelEstimate {
        let Lobes { fitted, base } = lobes;
        let rig = self.rig;
        // Start: the halfway vector of the brightest sample (docs/method.md, "The search"). The
        // brightest light itself is also tried: for diffuse surfaces it is the better guess.
        let mut brightest = None;
        let mut best = 0.0f32;
        for (j, s) in slice.chunks_exact(3).enumerate() {
            let y = s[0] + s[1] + s[2];
            if y.is_finite() && y > best {
                best = y;
                brightest = Some(j);
            }
        }
        let Some(j) = brightest else {
            return PixelEstimate::empty(PixelStatus::NoData);
        };
        let mut evals = 0u32;
        // With a compensated measure, the search starts in the paper's form (p = 1).
        let mut cosine = match self.params.cosine {
            CosineMode::Compensated(_) | CosineMode::Auto => CosineMode::CrossMultiplied,
            c => c,
        };
        // The two starts are compared on a quarter of the lights (all of them on small rigs);
        // the domain there sizes the coarse level of the search.
        let quarter = Level::Coarse(objective.queries(Level::Full).div_ceil(4).max(256));
        let at = |n: DVec3| {
            let term = objective.normal_term(n, cosine, quarter);
            (
                term.distance(self.min_count(objective, quarter)),
                term.count,
            )
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
        let mut source = PixelSource::Symmetry;
        let lobe = match choice {
            NormalChoice::Lobe(f) => Some(*f),
            _ => None,
        };
        let n = if let Some(f) = lobe {
            source = PixelSource::Lobe;
            evals += f.evals;
            f.normal
        } else if let NormalChoice::Sharp(m, from) = choice {
            source = from;
            m
        } else if let NormalChoice::Diffuse(m) = choice {
            // A diffuse slice is symmetric about the normal of its Lambertian term, and a robust
            // Lambertian fit finds that centre in closed form from every lit sample, where the
            // search reads it through the interpolated slice (docs/method.md, "Default
            // measure"). The reach is checked below as for any normal.
            source = PixelSource::Lambertian;
            m
        } else {
            let mut start = rig.halfway_in_camera()[j];
            let mut start_at = at(start);
            let light = rig.lights_in_camera()[j];
            if light.z > 0.0 {
                let light_at = at(light);
                if light_at.0 < start_at.0 {
                    (start, start_at) = (light, light_at);
                }
            }
            evals += 2;
            let coarse = coarse_level(objective, quarter, start_at.1, NORMAL_DOMAIN_TARGET);

            let (n, e) = self.minimise_normal(
                objective,
                start,
                cosine,
                coarse,
                0.12,
                self.params.max_normal_evals,
            );
            evals += e;
            let starts = [Some(rig.halfway_in_camera()[j]), moments.map(|m| m.normal)];
            // A search that ended beyond the reach is left there (discarded or a fallback): the
            // judge must not turn it into a clamped guess inside the sampled region.
            let mut n = n;
            if centre_observed(rig, objective, n) {
                let (m, e) = self.judge_at_full(objective, n, starts.iter().flatten(), cosine);
                evals += e;
                n = m;
            }
            let diffuse = self.params.cosine == CosineMode::Auto
                && unexplained_share(rig, slice, n, self.policy.shadows.min_cosine)
                    < self.policy.diffuse.specular_share;
            let refine = match self.params.cosine {
                CosineMode::Compensated(p) => Some(CosineMode::Compensated(p)),
                CosineMode::Auto => (!diffuse).then_some(CosineMode::Compensated(0.0)),
                _ => None,
            };
            if let Some(refined) = refine {
                // A normal beyond the rig's reach in the paper's form stays discarded: the flatter
                // compensated measure could otherwise walk it back inside the sampled region to a
                // wrong but plausible-looking normal.
                if n.z <= 0.0 || !centre_observed(rig, objective, n) {
                    return PixelEstimate {
                        evals,
                        ..PixelEstimate::empty(PixelStatus::Discarded)
                    };
                }
                // The compensated measure is flatter far from the solution: refine the paper's
                // solution with it (where p = 1 the two coincide).
                cosine = refined;
                let (m, e) = self.minimise_normal(objective, n, cosine, coarse, 0.06, 150);
                evals += e;
                // Judged against the paper-form solution only: the other starts may lie inside the
                // reach where that solution does not.
                let (m, e) = self.judge_at_full(objective, m, [n].iter(), cosine);
                evals += e;
                n = m;
            }
            n
        };
        let term_n = objective.normal_term(n, cosine, Level::Full);
        if term_n.count < self.min_domain
            || term_n.denominator <= 0.0
            || n.z <= 0.0
            || !centre_observed(rig, objective, n)
        {
            return PixelEstimate {
                evals,
                ..PixelEstimate::empty(PixelStatus::Discarded)
            };
        }
        let sd_n = term_n.numerator / term_n.denominator;
        if let Some(f) = lobe {
            let e = self.lobe_estimate(slice, objective, cosine, &f, &term_n, sd_n);
            return PixelEstimate {
                evals: e.evals + evals,
                ..e
            };
        }

        // Tangent: scan the objective over its 90-degree period on a coarse level, refine the
        // best angle there, then polish on the full level.
        let (u, w) = tangent_basis(n);
        let tangent_at = |psi: f64| u * psi.cos() + w * psi.sin();
        let period = std::f64::consts::FRAC_PI_2;
        let (_, count) = self.tangent_distance(objective, n, u, cosine, quarter);
        let coarse = coarse_level(objective, quarter, count, TANGENT_DOMAIN_TARGET);
        let mut scan = [0.0f64; TANGENT_SCAN];
        for (k, v) in scan.iter_mut().enumerate() {
            let t = tangent_at(period * k as f64 / TANGENT_SCAN as f64);
            *v = self.tangent_distance(objective, n, t, cosine, coarse).0;
        }
        evals += 1 + TANGENT_SCAN as u32;
        let (k_best, _) = scan
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .unwrap_or((0, &0.0));
        let psi0 = period * k_best as f64 / TANGENT_SCAN as f64;
        let search_tangent = |psi: f64, step: f64, level: Level, budget: u32| {
            nelder_mead(
                |x: &[f64; 1]| {
                    self.tangent_distance(objective, n, tangent_at(x[0]), cosine, level)
                        .0
                },
                [psi],
                [step],
                NelderMeadOptions {
                    max_evals: budget,
                    x_tolerance: 1e-4,
                    f_tolerance: f64::INFINITY,
                },
            )
        };
        let rough = search_tangent(psi0, period / TANGENT_SCAN as f64 / 2.0, coarse, 60);
        evals += rough.evals;
        let psi = {
            // A parabola through three full-level values around the coarse solution.
            let d = TANGENT_POLISH_DEG.to_radians();
            let f = [-d, 0.0, d].map(|o| {
                self.tangent_distance(
                    objective,
                    n,
                    tangent_at(rough.x[0] + o),
                    cosine,
                    Level::Full,
                )
                .0
            });
            evals += 3;
            let curvature = f[0] - 2.0 * f[1] + f[2];
            let shift = if curvature > 0.0 {
                (0.5 * d * (f[0] - f[2]) / curvature).clamp(-d, d)
            } else if f[0] < f[2] {
                -d
            } else {
                d
            };
            rough.x[0] + shift
        };
        let mut t = tangent_at(psi);
        let [term_nt, term_nb] = objective.tangent_terms(Frame::new(n, t), cosine, Level::Full);
        if term_nt.count < self.min_domain
            || term_nb.count < self.min_domain
            || term_nt.denominator <= 0.0
            || term_nb.denominator <= 0.0
        {
            return PixelEstimate {
                evals,
                ..PixelEstimate::empty(PixelStatus::Discarded)
            };
        }
        let sd_nt = term_nt.numerator / term_nt.denominator;
        let sd_nb = term_nb.numerator / term_nb.denominator;
        // Anisotropy: how much worse the tangent objective is half a period (45 degrees) away
        // from the solution, on the full level.
        let f_min = sd_nt + sd_nb;
        let f_max = self
            .tangent_distance(
                objective,
                n,
                tangent_at(psi + period / 2.0),
                cosine,
                Level::Full,
            )
            .0;
        evals += 2;
        let anisotropy = ((f_max - f_min) / (f_max + f_min + ANISOTROPY_FLOOR)).clamp(0.0, 1.0);

        // The tangent where the data determine one (`frames::policy`, docs/method.md,
        // "Tangents by evidence"): the slice's symmetry anisotropy and an independent reading
        // of the highlight's wide axis. Under a sharp coat (a lobe read through one or two
        // lights) the highlight's moments are the coat's, round; the lobe fitted to the
        // samples is the broad base's (the coat is too narrow to pull it), and its elongation,
        // where the rig resolves it, is the base's.
        let moments_elongated = moments
            .is_some_and(|m| m.has_tangent(self.policy.tangent.min_moment_elongation))
            || (sharp && base.or(fitted).is_some_and(|f| self.lobe_has_tangent(&f)));
        let b = n.cross(t);
        let evidence = TangentEvidence {
            anisotropy,
            moments_elongated,
            axes: [t, b],
            lobes: [fitted, base].map(|f| f.map(|f| self.lobe_axis(&f))),
        };
        let tangent = if self.params.tangents && has_tangent(&self.policy.tangent, &evidence) {
            // Which of the two symmetry axes is the tangent (the wider highlight's): the
            // fitted lobe's or the highlight's wide axis where they are elongated (they
            // read every sample of the highlight, its clipped plateau included), else the
            // slice probed along both axes.
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
            if swap {
                t = b;
            }
            Some(t)
        } else {
            None
        };

        // Confidence: how sure the slice's symmetry is of the answer, whichever rule gave it
        // (docs/method.md, "Confidence").
        let (judged, e) = self.symmetry_sd(objective, n, cosine, Level::Full, true, &term_n);
        evals += e;
        // The lights' uncertainty moves any reading of the highlight's centre about as much as
        // it moves the lobe fitted to it (the symmetry cannot turn its rig's lights).
        let mut variance = judged.variance() + fitted.map_or(0.0, |f| f.light_sd.powi(2));
        // A fitted lobe is a second reading of the centre: where the two disagree by more
        // than both their uncertainties allow, one of them is biased (a reconstruction or a
        // model that does not describe the slice), and the answer may be the biased one.
        if let Some(f) = fitted.filter(|f| f.normal_sd.is_finite()) {
            let d = n.angle_between(f.normal);
            variance += disagreement(d * d, variance, f.normal_sd.powi(2));
        }
        let sd = variance.sqrt();
        let coverage = self.coverage(slice, n, &term_n);
        let confidence = (coverage * within_confident(sd)) as f32;
        // A search that doubts its own answer gives way to a lobe fit that nearly explains the
        // samples, within the reach (`frames::policy::search_gives_way`).
        let quality = coverage / (1.0 + (sd_n + sd_nt + sd_nb) / self.policy.search.symmetry_scale);
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
        let status = self.status_of(confidence);
        let keep = status == PixelStatus::Estimated;
        PixelEstimate {
            status,
            source,
            normal: keep.then_some(n),
            tangent: if keep { tangent } else { None },
            confidence,
            anisotropy: anisotropy as f32,
            tangent_confidence: match tangent {
                Some(_) if keep => {
                    tangent_confidence(&self.policy.tangent, &evidence, f_min, f_max)
                }
                _ => 0.0,
            },
            residual: [sd_n, sd_nt, sd_nb],
            evals,
        }
    }

    /// The symmetric lobe fitted to a pixel, from the highlight's centre `normal`, widest axis
    /// `tangent` and RMS angular `radius`.
    fn lobe_fit(
        &self,
        slice: &[f32],
        normal: DVec3,
        tangent: DVec3,
        radius: f64,
        scratch: &mut LobeScratch,
    ) -> Option<LobeFit> {
        let rig = self.rig;
        let r = radius.tan().max(LOBE_START_WIDTH);
        let start = LobeStart {
            normal,
            tangent,
            alpha: [1.2 * r, 0.8 * r],
        };
        fit_lobe(slice, rig, start, &self.params.noise, scratch)
    }

    /// The estimate of a pixel the lobe `f` explains (its normal within the rig's reach): the
    /// lobe's frame, its elongation as the anisotropy, a tangent where the lobe is elongated.
    fn lobe_estimate<O: Objective>(
        &self,
        slice: &[f32],
        objective: &O,
        cosine: CosineMode,
        f: &LobeFit,
        term_n: &SymmetryTerm,
        sd_n: f64,
    ) -> PixelEstimate {
        let anisotropy = f.elongation();
        let tangent = (self.params.tangents && self.lobe_has_tangent(f)).then_some(f.tangent);
        // The data's symmetry judges the lobe's centre, which is only as certain as the
        // symmetry can confirm it: its own variance (up to the stencil's resolution) is added,
        // and where the slice is more symmetric about a normal nearby than the two readings'
        // uncertainties allow, the lobe does not describe the material and its centre may be
        // biased by as much (docs/method.md, "Confidence").
        // On the first JUDGE_LIGHTS of the query order (evenly spread; all of them on small
        // rigs), as the tangent's confidence below, and without the split halves.
        let judged_on = Level::Coarse(JUDGE_LIGHTS);
        let centre = objective.normal_term(f.normal, cosine, judged_on);
        let (judged, evals) =
            self.symmetry_sd(objective, f.normal, cosine, judged_on, false, &centre);
        let own = f.normal_sd.powi(2);
        let sd = (own + f.light_sd.powi(2) + unconfirmed(&judged, own)).sqrt();
        let confidence = (self.coverage(slice, f.normal, term_n) * within_confident(sd)) as f32;
        let status = self.status_of(confidence);
        let keep = status == PixelStatus::Estimated;
        // The tangent's confidence is the data's, as for the search: how much more symmetric
        // the slice is about the lobe's axes than about the pair 45 degrees away.
        let (tangent_confidence, evals) = match tangent {
            Some(t) if keep => {
                let b = f.normal.cross(t);
                let at = |a: DVec3| {
                    self.tangent_distance(objective, f.normal, a, cosine, judged_on)
                        .0
                };
                let evidence = TangentEvidence {
                    anisotropy,
                    moments_elongated: false,
                    axes: [t, b],
                    lobes: [Some(self.lobe_axis(f)), None],
                };
                let c = tangent_confidence(
                    &self.policy.tangent,
                    &evidence,
                    at(t),
                    at((t + b).normalize()),
                );
                (c, evals + 3)
            }
            _ => (0.0, evals + 1),
        };
        PixelEstimate {
            status,
            source: PixelSource::Lobe,
            normal: keep.then_some(f.normal),
            tangent: if keep { tangent } else { None },
            confidence,
            anisotropy: anisotropy as f32,
            tangent_confidence,
            residual: [sd_n, f.residual, 0.0],
            evals,
        }
    }

    /// Whether a fitted lobe is elongated enough for a tangent, and wide enough for the rig to
    /// tell: `--min-anisotropy` scales the elongation threshold (its default asks for widths in
    /// a ratio of 2); the rig tells a lobe's shape only where its long axis spans several
    /// lights (narrower, it reads as elongated or round by where the lights happen to be).
    fn lobe_has_tangent(&self, f: &LobeFit) -> bool {
        let threshold = self.policy.lobe.min_elongation * self.params.min_anisotropy as f64
            / DEFAULT_MIN_ANISOTROPY as f64;
        let resolved = f.full_width().atan()
            >= self.policy.lobe.resolved_spacings * self.rig.halfway_spacing();
        f.elongation() >= threshold && resolved
    }

    /// A fitted lobe's reading of the highlight's axes, for the tangent decision.
    fn lobe_axis(&self, f: &LobeFit) -> LobeAxis {
        LobeAxis {
            tangent: f.tangent,
            residual: f.residual,
            elongated: self.lobe_has_tangent(f),
        }
    }

    /// A pixel's status for its `confidence`: culled under the user's threshold.
    fn status_of(&self, confidence: f32) -> PixelStatus {
        if confidence < self.params.min_confidence {
            PixelStatus::Culled
        } else {
            PixelStatus::Estimated
        }
    }

    /// The share of the pixel's cosine-weighted signal inside the normal's symmetry domain,
    /// relative to a quarter and capped at 1 (docs/method.md, "Confidence"): low where the
    /// domain covers little of the measured slice (normals near the rig's reach).
    fn coverage(&self, slice: &[f32], n: DVec3, term_n: &SymmetryTerm) -> f64 {
        let mut total = 0.0;
        for (s, l) in slice.chunks_exact(3).zip(self.rig.lights_in_camera()) {
            let nl = n.dot(*l);
            if nl > 0.0 && s[0].is_finite() {
                total += nl * nl * (s[0] as f64).powi(2)
                    + nl * nl * (s[1] as f64).powi(2)
                    + nl * nl * (s[2] as f64).powi(2);
            }
        }
        if total > 0.0 {
            (term_n.denominator / total / 0.25).min(1.0)
        } else {
            0.0
        }
    }

    /// What the slice's symmetry says of a normal `n`, read on the lights of `level` (`term_n`
    /// its term at `n` there), and the evaluations spent (docs/method.md, "Confidence"): the
    /// symmetry distance `SD_n` on a 3 x 3 stencil around `n` ([`SD_STENCIL_DEG`] apart)
    /// fitted by a quadratic with gradient `g` and Hessian `H`; the squared offset `|H^-1 g|^2`
    /// of its minimum from `n` (where the slice is more symmetric about another normal than
    /// about the one given), and the minimum's variance: the scatter of the slice about its
    /// symmetry (what the quadratic's minimum leaves, per independent pair of lights) through
    /// `H`, `2 f_min / (count / 2 - 2) tr(H^-1)`, or where `split` and larger, the split
    /// halves'. Infinite where the stencil has no minimum.
    fn symmetry_sd<O: Objective>(
        &self,
        objective: &O,
        n: DVec3,
        cosine: CosineMode,
        level: Level,
        split: bool,
        term_n: &SymmetryTerm,
    ) -> (SymmetryJudgement, u32) {
        let r = SD_STENCIL_DEG.to_radians();
        let (u, w) = tangent_basis(n);
        let chart = |x: f64, y: f64| (n + x * u + y * w).normalize();
        // The distance over every light, and over each half of them (the first half of the
        // query order, evenly spread, and the rest: its terms are sums over the lights).
        let half = Level::Coarse(objective.queries(level) / 2);
        let min = self.min_count(objective, level);
        let mut f = [[0.0f64; 3]; 3];
        let mut halves = [[[0.0f64; 3]; 3]; 2];
        for i in 0..3 {
            for j in 0..3 {
                let m = chart((i as f64 - 1.0) * r, (j as f64 - 1.0) * r);
                let full = if (i, j) == (1, 1) {
                    *term_n
                } else {
                    objective.normal_term(m, cosine, level)
                };
                if !split {
                    f[i][j] = full.distance(min);
                    continue;
                }
                let first = objective.normal_term(m, cosine, half);
                let rest = SymmetryTerm {
                    numerator: full.numerator - first.numerator,
                    denominator: full.denominator - first.denominator,
                    count: full.count - first.count.min(full.count),
                };
                f[i][j] = full.distance(min);
                halves[0][i][j] = first.distance(min / 2);
                halves[1][i][j] = rest.distance(min / 2);
            }
        }
        let evals = if split { 17 } else { 8 };
        if f.iter()
            .flatten()
            .any(|v| *v >= EMPTY_DISTANCE || !v.is_finite())
        {
            return (SymmetryJudgement::NONE, evals);
        }
        let q = StencilQuadratic::of(&f, r);
        let pairs = term_n.count as f64 / 2.0 - 2.0;
        let Some([dx, dy]) = q.minimum().filter(|_| pairs >= 1.0) else {
            return (SymmetryJudgement::NONE, evals);
        };
        let StencilQuadratic {
            c,
            g: [gx, gy],
            h: [hxx, hyy, hxy],
        } = q;
        let det = hxx * hyy - hxy * hxy;
        // The quadratic's minimum value, and the scatter it stands for through the curvature.
        let f_min = (f[1][1] + 0.5 * (gx * dx + gy * dy)).max(0.0);
        let variance = 2.0 * f_min / pairs * (hxx + hyy) / det;
        // The distance's own roughness: what the quadratic leaves at the nine points (three
        // degrees of freedom; the piecewise-linear reconstruction's kinks, noise) is noise on
        // the gradient, `var(g) = s^2 / (6 r^2)` per axis, moving the minimum by `H^-1 g`.
        let mut rss = 0.0;
        for (i, row) in f.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let (x, y) = ((i as f64 - 1.0) * r, (j as f64 - 1.0) * r);
                let fitted = c + gx * x + gy * y + 0.5 * (hxx * x * x + hyy * y * y) + hxy * x * y;
                rss += (v - fitted).powi(2);
            }
        }
        let var_g = rss / 3.0 / (6.0 * r * r);
        // tr(H^-1 var_g I H^-1) = var_g |H^-1|_F^2.
        let inv_frob2 = (hxx * hxx + hyy * hyy + 2.0 * hxy * hxy) / (det * det);
        let roughness = var_g * inv_frob2;
        // Split half: the minima of the two halves' quadratics differ by twice the full one's
        // error where the halves are independent (`var(m1 - m2) = 4 var(m)`): an estimate of
        // its variance that holds whatever each light's noise (light errors, shot noise
        // rising with the signal), where the curvature's assumes it alike.
        let split = match halves.map(|h| StencilQuadratic::of(&h, r).minimum()) {
            _ if !split => 0.0,
            [Some([x1, y1]), Some([x2, y2])] => ((x1 - x2).powi(2) + (y1 - y2).powi(2)) / 4.0,
            _ => f64::INFINITY,
        };
        let scatter = (variance + roughness).max(split);
        let judged = SymmetryJudgement {
            offset2: dx * dx + dy * dy,
            scatter,
        };
        (judged, evals)
    }
}

/// What the slice's symmetry says of a normal ([`Estimator::symmetry_sd`]), in squared
/// radians: how far its minimum is from the normal, and the variance of that minimum.
#[derive(Debug, Clone, Copy)]
struct SymmetryJudgement {
    /// `|H^-1 g|^2`: the squared offset of the stencil quadratic's minimum.
    offset2: f64,
    /// The minimum's variance (the scatter through the curvature and the distance's roughness,
    /// or the split halves' where larger).
    scatter: f64,
}

impl SymmetryJudgement {
    /// The stencil has no minimum: the symmetry cannot judge the normal.
    const NONE: Self = Self {
        offset2: f64::INFINITY,
        scatter: f64::INFINITY,
    };

    /// The normal's variance as the symmetry judges it: its offset from the minimum and the
    /// minimum's own variance.
    fn variance(&self) -> f64 {
        self.offset2 + self.scatter
    }
}

/// The squared disagreement `d2` of two readings of one normal beyond what their variances
/// `va` and `vb` explain (`E d^2 = va + vb` for unbiased independent readings): an estimate of
/// the squared bias one of them carries, 0 where they agree within their noise.
fn disagreement(d2: f64, va: f64, vb: f64) -> f64 {
    (d2 - va - vb).max(0.0)
}

/// The variance a model's reading of the normal (of variance `own`) adds where the data's
/// symmetry judges it (`judged`): what the symmetry cannot confirm. Its own variance, up to the
/// stencil's squared spacing (beyond it the stencil does not resolve the minimum), plus the
/// readings' disagreement beyond both variances; the squared spacing where the distance has no
/// minimum on the stencil (the symmetry does not place the normal within it).
fn unconfirmed(judged: &SymmetryJudgement, own: f64) -> f64 {
    let resolution = SD_STENCIL_DEG.to_radians().powi(2);
    if judged.offset2.is_finite() {
        disagreement(judged.offset2, own, judged.scatter) + judged.scatter.min(resolution)
    } else {
        resolution
    }
}

/// The least-squares quadratic `c + g.x + x^T H x / 2` through a function's values `f[i][j]`
/// at `((i - 1) r, (j - 1) r)` on a 3 x 3 stencil (an orthogonal basis there: closed form).
#[derive(Debug, Clone, Copy)]
struct StencilQuadratic {
    c: f64,
    g: [f64; 2],
    /// `H_xx`, `H_yy`, `H_xy`.
    h: [f64; 3],
}

impl StencilQuadratic {
    fn of(f: &[[f64; 3]; 3], r: f64) -> Self {
        let col = |i: usize| f[i][0] + f[i][1] + f[i][2];
        let row = |j: usize| f[0][j] + f[1][j] + f[2][j];
        let hxx = (col(2) - 2.0 * col(1) + col(0)) / (3.0 * r * r);
        let hyy = (row(2) - 2.0 * row(1) + row(0)) / (3.0 * r * r);
        Self {
            c: (col(0) + col(1) + col(2)) / 9.0 - (hxx + hyy) * r * r / 3.0,
            g: [(col(2) - col(0)) / (6.0 * r), (row(2) - row(0)) / (6.0 * r)],
            h: [
                hxx,
                hyy,
                (f[2][2] - f[2][0] - f[0][2] + f[0][0]) / (4.0 * r * r),
            ],
        }
    }

    /// The offset of the minimum from the stencil's centre; `None` where `H` is not positive
    /// definite.
    fn minimum(&self) -> Option<[f64; 2]> {
        let ([gx, gy], [hxx, hyy, hxy]) = (self.g, self.h);
        let det = hxx * hyy - hxy * hxy;
        (hxx > 0.0 && det > 0.0)
            .then(|| [-(hyy * gx - hxy * gy) / det, -(hxx * gy - hxy * gx) / det])
    }
}

/// The angle (degrees) confidence is about: a pixel's confidence is the probability that its
/// normal is within this of the truth.
pub const CONFIDENT_WITHIN_DEG: f64 = 1.0;

/// The probability that a normal whose error is a two-dimensional normal variable of total
/// standard deviation `sd` (radians) is within [`CONFIDENT_WITHIN_DEG`] of the truth:
/// `1 - exp(-a^2 / sd^2)` (the error's squared length over half its variance is chi-square
/// with two degrees of freedom).
fn within_confident(sd: f64) -> f64 {
    if !sd.is_finite() {
        return 0.0;
    }
    let a = CONFIDENT_WITHIN_DEG.to_radians();
    if sd <= 0.0 {
        1.0
    } else {
        1.0 - (-(a / sd).powi(2)).exp()
    }
}

/// Lights (the first of the query order, so evenly spread) on which the slice's symmetry
/// judges a lobe's answer: its centre on the stencil and its tangent. More lights judge more
/// finely and cost in proportion, eleven evaluations at every lobe pixel (higher is slower; a
/// smaller rig's lights are all read).
const JUDGE_LIGHTS: usize = 256;

/// The spacing (degrees) of the stencil the symmetry's judgement of a normal reads
/// ([`Estimator::symmetry_sd`]): the polish's.
const SD_STENCIL_DEG: f64 = POLISH_RADIUS_DEG;

/// The lobes fitted to a pixel: the one of all its samples, and under a sharp coat the base's,
/// fitted without the coat's samples.
#[derive(Debug, Clone, Copy)]
struct Lobes {
    fitted: Option<LobeFit>,
    base: Option<LobeFit>,
}

/// Smallest width the lobe fit starts from (slope units): a highlight of one sample has no
/// moment to measure it by.
const LOBE_START_WIDTH: f64 = 0.02;

/// The share of a pixel's signal energy (over lights with `n.l` at least
/// [`ShadowSettings::min_cosine`]: near grazing, shadows the fitted normal cannot tell from light
/// decide nothing) that the best Lambertian
/// term `d (n.l)` with normal `n` (RGB `d >= 0`, least squares) leaves unexplained: 0 for a
/// diffuse surface, the specular part's share otherwise.
fn unexplained_share(rig: &Rig, slice: &[f32], n: DVec3, min_cosine: f64) -> f64 {
    let (mut il, mut ll, mut ii) = ([0.0f64; 3], 0.0f64, 0.0f64);
    for (s, l) in slice.chunks_exact(3).zip(rig.lights_in_camera()) {
        let nl = n.dot(*l);
        if nl < min_cosine || !s[0].is_finite() {
            continue;
        }
        ll += nl * nl;
        for c in 0..3 {
            let v = s[c] as f64;
            il[c] += v * nl;
            ii += v * v;
        }
    }
    if ii <= 0.0 || ll <= 0.0 {
        return 0.0;
    }
    let explained: f64 = il.iter().map(|&x| x.max(0.0).powi(2) / ll).sum();
    (1.0 - explained / ii).max(0.0)
}

/// What the capture's noise alone would leave of a Lambertian pixel's well-lit energy
/// ([`unexplained_share`] over the same lights at normal `n`), as a share, `z` standard
/// deviations above its expectation: each sample's channels carry the noise model's variance
/// at their value (about a third of the grey each), the fit's five parameters (three albedos,
/// the normal's two tilts) take their share, and a sum of squared Gaussian residuals has
/// variance `2 sigma^4` per value.
fn diffuse_noise_limit(
    rig: &Rig,
    slice: &[f32],
    n: DVec3,
    min_cosine: f64,
    noise: &NoiseModel,
    z: f64,
) -> f64 {
    let (mut expected, mut spread, mut energy, mut values) = (0.0, 0.0, 0.0, 0usize);
    for (s, l) in slice.chunks_exact(3).zip(rig.lights_in_camera()) {
        if n.dot(*l) < min_cosine || !s[0].is_finite() {
            continue;
        }
        let [r, g, b] = [s[0] as f64, s[1] as f64, s[2] as f64];
        // One channel's variance at the sample's mean channel value, for all three.
        let v = noise.variance((r + g + b) / 3.0);
        expected += 3.0 * v;
        spread += 3.0 * 2.0 * v * v;
        energy += r * r + g * g + b * b;
        values += 3;
    }
    if energy <= 0.0 || values <= 5 {
        return 0.0;
    }
    let kept = (values - 5) as f64 / values as f64;
    (expected * kept + z * spread.sqrt()) / energy
}

/// The widest-highlight heuristic: is the slice, around `n` in halfway space, brighter along
/// `candidate` than along `current` at equal angles? Compares symmetric pairs `n cos d +- a
/// sin d` for several `d` where all four points have data, so uneven sample density cannot
/// bias it.
fn highlight_wider_along<O: Objective>(
    objective: &O,
    n: DVec3,
    candidate: DVec3,
    current: DVec3,
) -> bool {
    let mut along_candidate = 0.0;
    let mut along_current = 0.0;
    for k in 1..=12 {
        let d = (2.0 * k as f64).to_radians();
        let (s, c) = d.sin_cos();
        let probe = |a: DVec3| {
            let h = n * c + a * s;
            objective.value(h).map(|v| v[0] + v[1] + v[2])
        };
        if let (Some(a), Some(b), Some(p), Some(q)) = (
            probe(candidate),
            probe(-candidate),
            probe(current),
            probe(-current),
        ) {
            along_candidate += a + b;
            along_current += p + q;
        }
    }
    along_candidate > along_current
}

/// Coarse domains smaller than this (lights) do not locate a minimum reliably: the search
/// repeats on a larger prefix.
const COARSE_RELIABLE: u32 = 32;

/// How many lights the coarse level's `SD_n` domain should hold: enough to place the minimum
/// within the full level's basin (a fraction of a degree), few enough to be cheap.
const NORMAL_DOMAIN_TARGET: u32 = 64;

/// The same for the tangent terms' domains.
const TANGENT_DOMAIN_TARGET: u32 = 64;

/// Spacing of the full-level quadratic fit that ends the normal search (degrees): wide enough
/// to average over the objective's ripples at the scale of the light spacing (the reference and
/// fast paths then agree), narrow enough to stay quadratic.
const POLISH_RADIUS_DEG: f64 = 1.0;

/// Spacing of the full-level parabola that ends the tangent search (degrees).
const TANGENT_POLISH_DEG: f64 = 1.0;

/// The coarse level whose domain holds about `target` lights, given that `level` has a domain
/// of `count` lights; the full level where that is most of the lights anyway.
fn coarse_level<O: Objective>(objective: &O, level: Level, count: u32, target: u32) -> Level {
    let full = objective.queries(Level::Full);
    let part = objective.queries(level);
    let m = (part as u64 * target as u64).div_ceil(count.max(1) as u64) as usize;
    if m >= full * 3 / 4 {
        Level::Full
    } else {
        Level::Coarse(m.max(target as usize))
    }
}

/// Half-angle of the neighbourhood of `h = n` that must be observed for a normal to count as
/// within the rig's reach (degrees).
const CENTRE_RADIUS_DEG: f64 = 2.0;

/// Whether the slice has data at `h = n` and around it in four directions: the centre of the
/// symmetries must be observed. A normal beyond the rig's reach (a rig within 45 degrees of the
/// view has halfway vectors within ~22) otherwise settles at the edge of the sampled region with a
/// small but meaningless distance: a clamped guess, which docs/method.md ("Beyond-reach discard")
/// says never to return. The points must lie in [covered](Rig::covered) cells, as the domains'
/// lights do.
fn centre_observed<O: Objective>(rig: &Rig, objective: &O, n: DVec3) -> bool {
    let (u, w) = tangent_basis(n);
    let (s, c) = CENTRE_RADIUS_DEG.to_radians().sin_cos();
    let observed = |h: DVec3| rig.covered(h) && objective.value(h).is_some();
    observed(n) && [u, -u, w, -w].iter().all(|&a| observed(n * c + a * s))
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
    /// The lobe fit's samples, the censored ones left out.
    lobe_input: Vec<f32>,
    /// The base lobe's samples under a sharp coat, the coat's left out.
    base_input: Vec<f32>,
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
            lobe_input: Vec::with_capacity(rig.n_used() * 3),
            base_input: Vec::with_capacity(rig.n_used() * 3),
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
    crate::stack::check_inputs(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readings_that_disagree_beyond_their_noise_carry_a_bias() {
        let deg2 = 1f64.to_radians().powi(2);
        // Within what the two variances explain: no bias.
        assert_eq!(disagreement(0.5 * deg2, 0.3 * deg2, 0.3 * deg2), 0.0);
        // Beyond it: the excess, which lowers the confidence of either reading.
        let bias = disagreement(4.0 * deg2, 0.5 * deg2, 0.5 * deg2);
        assert!((bias - 3.0 * deg2).abs() < 1e-15);
        let own = (0.5 * deg2).sqrt();
        assert!(within_confident((own * own + bias).sqrt()) < within_confident(own));
        // A symmetry that cannot judge (no minimum on the stencil) has infinite variance.
        assert!(SymmetryJudgement::NONE.variance().is_infinite());
        assert_eq!(disagreement(1.0, f64::INFINITY, 0.0), 0.0);
    }

    #[test]
    fn a_lobe_is_as_certain_as_the_symmetry_confirms_it() {
        let deg2 = 1f64.to_radians().powi(2);
        let own = (0.1f64.to_radians()).powi(2);
        let confidence =
            |j: SymmetryJudgement| within_confident((own + unconfirmed(&j, own)).sqrt());
        // A sharp minimum at the lobe's centre confirms it: it stays confident.
        let sharp = SymmetryJudgement {
            offset2: 0.0,
            scatter: 0.05 * deg2,
        };
        assert!(confidence(sharp) > 0.99);
        // A symmetry with no minimum on the stencil, or too shallow to place one within it,
        // confirms nothing finer than the stencil: however small the fit's own variance, the
        // lobe is not confident (the family's bias on a material outside it is hidden there).
        assert!(confidence(SymmetryJudgement::NONE) < 0.9);
        let shallow = SymmetryJudgement {
            offset2: 0.5 * deg2,
            scatter: 3.0 * deg2,
        };
        assert!(confidence(shallow) < 0.9);
        // A minimum elsewhere, beyond both readings' variances, counts as the lobe's bias.
        let elsewhere = SymmetryJudgement {
            offset2: 2.0 * deg2,
            scatter: 0.05 * deg2,
        };
        assert!(confidence(elsewhere) < 0.9 && confidence(elsewhere) < confidence(sharp));
    }

    #[test]
    fn a_diffuse_pixel_leaves_what_its_noise_leaves_and_a_lobe_more() {
        // A coloured Lambertian pixel under 1,000 lights with shot and read noise drawn per
        // channel as the noise model states it: what its Lambertian term leaves is above the
        // noise-free share (so only the noise test tells it diffuse), about the share the
        // noise model expects, and under the test's limit in every draw; a weak glossy coat
        // leaves several times the limit.
        use crate::brdf::{Ggx, Lambertian};
        use crate::frames::lobe::tests::{gaussians, slice};
        use crate::frames::rig::{uniform_cone_lights, RigOptions};
        let rig = Rig::new(&uniform_cone_lights(1000, 65.0), RigOptions::default()).unwrap();
        let n = DVec3::new(0.3, -0.2, 1.0).normalize();
        let t = tangent_basis(n).0;
        let settings = PolicySettings::default();
        let min_cosine = settings.shadows.min_cosine;
        let matte = slice(&rig, &Lambertian::new([0.6, 0.4, 0.3]), n, t);
        let peak = matte.iter().copied().fold(0.0f32, f32::max) as f64;
        // Full scale at the brightest channel: 500 electrons there, read noise of 2.
        let noise = NoiseModel {
            shot: 1.0 / 500.0,
            read: (2.0f64 / 500.0).powi(2),
            ..NoiseModel::default()
        };
        let mut gauss = gaussians(0x2545_f491_4f6c_dd1d);
        let mut noisy = |clean: &[f32], scale: f64| -> Vec<f32> {
            clean
                .iter()
                .map(|&v| {
                    let v = v as f64 * scale;
                    (v + noise.variance(v).sqrt() * gauss()) as f32
                })
                .collect()
        };
        let (mut ratio, draws) = (0.0, 20);
        for _ in 0..draws {
            let s = noisy(&matte, 1.0 / peak);
            let share = unexplained_share(&rig, &s, n, min_cosine);
            let limit = diffuse_noise_limit(&rig, &s, n, min_cosine, &noise, 3.09);
            let expected = diffuse_noise_limit(&rig, &s, n, min_cosine, &noise, 0.0);
            assert!(share > settings.diffuse.pure_share, "{share}");
            assert!(share < limit, "{share} {limit}");
            ratio += share / expected / draws as f64;
        }
        assert!((0.8..1.2).contains(&ratio), "share / expected {ratio}");
        // The same pixel with a weak glossy coat: its lobe is no noise.
        let glossy = slice(
            &rig,
            &Ggx::new([0.6, 0.4, 0.3], [0.08; 3], 0.15, 0.15),
            n,
            t,
        );
        let s = noisy(&glossy, 1.0 / peak);
        let share = unexplained_share(&rig, &s, n, min_cosine);
        let limit = diffuse_noise_limit(&rig, &s, n, min_cosine, &noise, 3.09);
        assert!(share > 3.0 * limit, "{share} {limit}");
    }

    #[test]
    fn confidence_is_the_chance_of_being_within_a_degree() {
        let deg = 1f64.to_radians();
        assert_eq!(within_confident(0.0), 1.0);
        assert_eq!(within_confident(f64::INFINITY), 0.0);
        // sd = 1 degree: 1 - 1/e; 0.9 at sd = 1 / sqrt(ln 10) degrees.
        assert!((within_confident(deg) - (1.0 - (-1f64).exp())).abs() < 1e-12);
        let sd90 = deg / 10f64.ln().sqrt();
        assert!((within_confident(sd90) - 0.9).abs() < 1e-12);
        assert!(within_confident(2.0 * deg) < within_confident(deg));
    }
}
