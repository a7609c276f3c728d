//! The baselines the paper compares against (its Figure 4): Lambertian photometric stereo
//! (Woodham 1980), the same with outlier rejection, and the max-reflectance ("specularity")
//! method. Each is good at one end of the range of materials; they are here to measure the
//! symmetry method against, on the same stacks and with the same outputs ([`EstimateMaps`]).
//!
//! Every baseline works on one value per sample, the **grey value**: the mean of the three
//! channels. For a Lambertian surface every channel gives the same normal (the albedo only
//! scales `g = albedo * n`), so averaging first loses nothing and costs a third of three fits.
//! A sample whose grey value is not finite (the stack's marker of an invalid sample) is skipped.
//!
//! Unlike the symmetry method, the baselines use every light given: there is no light cone.

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::frames::estimator::{EstimateMaps, PixelRecord, PixelSource, PixelStatus};
use crate::frames::highlight::highlight_moments_by;
use crate::geometry::halfway_from_light;
use crate::geometry::tangent_basis;
use crate::method::{run_stack, PixelMethod};
use crate::stack::Stack;

/// Which baseline to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Baseline {
    /// Least-squares Lambertian photometric stereo over the unshadowed samples.
    Woodham,
    /// As [`Baseline::Woodham`], then samples whose residual is more than
    /// [`BaselineParams::outlier_sigmas`] standard deviations from the mean residual are dropped
    /// and the fit is repeated (the paper's Figure 4 baseline).
    WoodhamRobust,
    /// The halfway vector of the brightest sample, refined by a quadratic fit of the log grey
    /// value over its nearest neighbours in halfway space.
    MaxReflectance,
    /// The intensity-weighted mean (normal) and second moment (tangent axis) of the halfway
    /// vectors of the brightest samples ([`crate::frames::highlight`]).
    HighlightCentroid,
}

impl Baseline {
    /// Every baseline, in a fixed order.
    pub const ALL: [Baseline; 4] = [
        Baseline::Woodham,
        Baseline::WoodhamRobust,
        Baseline::MaxReflectance,
        Baseline::HighlightCentroid,
    ];

    /// The baseline's name as on the command line and in reports (`woodham`, `woodham-robust`,
    /// `max-reflectance`).
    pub fn name(self) -> &'static str {
        match self {
            Baseline::Woodham => "woodham",
            Baseline::WoodhamRobust => "woodham-robust",
            Baseline::MaxReflectance => "max-reflectance",
            Baseline::HighlightCentroid => "highlight-centroid",
        }
    }

    /// The measure its normals come from: a Lambertian fit or the brightest highlight.
    pub fn source(self) -> PixelSource {
        match self {
            Baseline::Woodham | Baseline::WoodhamRobust => PixelSource::Lambertian,
            Baseline::MaxReflectance | Baseline::HighlightCentroid => PixelSource::Highlight,
        }
    }
}

impl std::fmt::Display for Baseline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Parameters of the baselines.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BaselineParams {
    /// A sample is in shadow, and left out of the Woodham fits, when its grey value is below
    /// this fraction of the pixel's reference level (see `shadow_reference_quantile`; default
    /// 0.05). Zero keeps every valid sample, shadowed zeros included: plain least squares,
    /// which is biased by several degrees when lights reach far from the view (a shadowed zero
    /// is not `albedo * n.l < 0`).
    pub shadow_fraction: f64,
    /// The pixel's reference level for the shadow threshold is this quantile of its valid grey
    /// values (default 0.9; the maximum where that quantile is zero). 1 makes it the maximum:
    /// then on a glossy material a highlight 20 times brighter than the diffuse part puts every
    /// diffuse sample "in shadow" and the fit runs on the highlight alone (measured: 37 degrees
    /// mean error on a Ward sphere with `alpha = 0.1`). A high quantile is the brightness of the
    /// lit diffuse part as long as the highlight covers under 10% of the lights.
    pub shadow_reference_quantile: f64,
    /// `woodham-robust` drops samples whose residual after the first fit is more than this many
    /// standard deviations from the mean residual (default 2, the paper's Figure 4).
    pub outlier_sigmas: f64,
}

impl Default for BaselineParams {
    fn default() -> Self {
        Self {
            shadow_fraction: 0.05,
            shadow_reference_quantile: 0.9,
            outlier_sigmas: 2.0,
        }
    }
}

impl BaselineParams {
    /// Checks the ranges: `shadow_fraction` in `[0, 1)`, `shadow_reference_quantile` in
    /// `[0.5, 1]`, `outlier_sigmas` positive.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..1.0).contains(&self.shadow_fraction) {
            return Err(Error::BadParameter(format!(
                "shadow fraction must be in [0, 1), got {}",
                self.shadow_fraction
            )));
        }
        if !(0.5..=1.0).contains(&self.shadow_reference_quantile) {
            return Err(Error::BadParameter(format!(
                "shadow reference quantile must be in [0.5, 1], got {}",
                self.shadow_reference_quantile
            )));
        }
        if !(self.outlier_sigmas > 0.0 && self.outlier_sigmas.is_finite()) {
            return Err(Error::BadParameter(format!(
                "outlier threshold must be a positive number of standard deviations, got {}",
                self.outlier_sigmas
            )));
        }
        Ok(())
    }
}

/// The result of a baseline at one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaselinePixel {
    /// What happened: [`PixelStatus::Estimated`], [`PixelStatus::NoData`] (no valid sample
    /// brighter than zero) or [`PixelStatus::Discarded`] (too few unshadowed samples, a
    /// degenerate fit, or a normal facing away from the camera); `Masked` from the stack driver.
    pub status: PixelStatus,
    /// Unit normal in the camera frame, when estimated.
    pub normal: Option<DVec3>,
    /// Unit tangent axis, for the baselines that estimate one (highlight centroid).
    pub tangent: Option<DVec3>,
    /// Goodness of fit in [0, 1] (0 where nothing was estimated); see each baseline's function.
    pub confidence: f32,
    /// Samples the final fit used.
    pub used: u32,
}

impl BaselinePixel {
    fn empty(status: PixelStatus) -> Self {
        Self {
            status,
            normal: None,
            tangent: None,
            confidence: 0.0,
            used: 0,
        }
    }

    /// What the maps hold at this pixel, whose normal comes from `source`: the normal and,
    /// where there is one, the confidence; no tangent or anisotropy (`NaN`), no objective
    /// evaluations.
    pub fn record(&self, source: PixelSource) -> PixelRecord {
        PixelRecord {
            status: self.status,
            source: if self.normal.is_some() {
                source
            } else {
                PixelSource::None
            },
            normal: self
                .normal
                .map_or([f32::NAN; 3], |n| n.as_vec3().to_array()),
            tangent: self
                .tangent
                .map_or([f32::NAN; 3], |t| t.as_vec3().to_array()),
            confidence: if self.normal.is_some() {
                self.confidence
            } else {
                f32::NAN
            },
            anisotropy: f32::NAN,
            evals: 0,
        }
    }
}

/// The grey value of one RGB sample (mean of the channels); `None` if not finite.
#[inline]
fn grey(rgb: &[f32]) -> Option<f64> {
    let v = (rgb[0] as f64 + rgb[1] as f64 + rgb[2] as f64) / 3.0;
    v.is_finite().then_some(v)
}

/// Index and grey value of the brightest valid sample, if any is brighter than zero.
#[inline]
fn brightest(samples: &[f32]) -> Option<(usize, f64)> {
    let mut best: Option<(usize, f64)> = None;
    for (i, s) in samples.chunks_exact(3).enumerate() {
        if let Some(v) = grey(s) {
            if v > best.map_or(0.0, |b| b.1) {
                best = Some((i, v));
            }
        }
    }
    best
}

/// Accumulated normal equations `A g = b` of the Lambertian model `I = g . l`.
#[derive(Debug, Clone, Copy, Default)]
struct NormalEquations {
    /// Upper triangle of `A = sum l l^T`: xx, xy, xz, yy, yz, zz.
    a: [f64; 6],
    /// `b = sum I l`.
    b: DVec3,
    /// `sum I^2`, for the goodness of fit.
    ii: f64,
    /// Samples added.
    n: u32,
}

impl NormalEquations {
    #[inline]
    fn add(&mut self, l: DVec3, i: f64) {
        let a = &mut self.a;
        a[0] += l.x * l.x;
        a[1] += l.x * l.y;
        a[2] += l.x * l.z;
        a[3] += l.y * l.y;
        a[4] += l.y * l.z;
        a[5] += l.z * l.z;
        self.b += i * l;
        self.ii += i * i;
        self.n += 1;
    }

    fn matrix(&self) -> DMat3 {
        let a = &self.a;
        DMat3::from_cols(
            DVec3::new(a[0], a[1], a[2]),
            DVec3::new(a[1], a[3], a[4]),
            DVec3::new(a[2], a[4], a[5]),
        )
    }

    /// The least-squares `g`, or `None` with fewer than 3 samples or lights too close to
    /// coplanar (determinant below `1e-9` of `(trace / 3)^3`, its value for evenly spread
    /// lights).
    fn solve(&self) -> Option<DVec3> {
        if self.n < 3 {
            return None;
        }
        let m = self.matrix();
        let scale = (self.a[0] + self.a[3] + self.a[5]) / 3.0;
        let det = m.determinant();
        if det.is_nan() || det <= 1e-9 * scale * scale * scale {
            return None;
        }
        let g = m.inverse() * self.b;
        g.is_finite().then_some(g)
    }

    /// Share of the fitted samples' energy the fit explains, `1 - sum r^2 / sum I^2` (the
    /// uncentred R^2), in [0, 1].
    fn explained(&self, g: DVec3) -> f64 {
        if self.ii <= 0.0 {
            return 0.0;
        }
        // sum (I - g.l)^2 = sum I^2 - 2 g.b + g^T A g.
        let ss = self.ii - 2.0 * g.dot(self.b) + g.dot(self.matrix() * g);
        (1.0 - ss.max(0.0) / self.ii).clamp(0.0, 1.0)
    }
}

/// The pixel's shadow threshold: [`BaselineParams::shadow_fraction`] of its reference level
/// (the [`BaselineParams::shadow_reference_quantile`] of its valid grey values, or the maximum
/// where that is zero); `None` when no valid sample is brighter than zero. `scratch` holds the
/// grey values for the quantile (reused: no allocation once it has grown to the light count).
#[inline]
fn shadow_threshold(
    samples: &[f32],
    params: &BaselineParams,
    scratch: &mut Vec<f64>,
) -> Option<f64> {
    let (_, max) = brightest(samples)?;
    let q = params.shadow_reference_quantile;
    let reference = if q >= 1.0 {
        max
    } else {
        scratch.clear();
        scratch.extend(samples.chunks_exact(3).filter_map(grey));
        let k = ((q * (scratch.len() - 1) as f64).floor() as usize).min(scratch.len() - 1);
        let (_, &mut v, _) = scratch.select_nth_unstable_by(k, f64::total_cmp);
        if v > 0.0 {
            v
        } else {
            max
        }
    };
    Some(params.shadow_fraction * reference)
}

/// The normal equations over the samples at or above `threshold`.
#[inline]
fn lit_equations(samples: &[f32], lights: &[DVec3], threshold: f64) -> NormalEquations {
    let mut eq = NormalEquations::default();
    for (s, &l) in samples.chunks_exact(3).zip(lights) {
        if let Some(i) = grey(s) {
            if i >= threshold {
                eq.add(l, i);
            }
        }
    }
    eq
}

/// The estimate from solved normal equations: the normal is `g / |g|`; a degenerate system or
/// a normal facing away from the camera is discarded.
fn finish(eq: &NormalEquations, g: Option<DVec3>) -> BaselinePixel {
    let Some(g) = g else {
        return BaselinePixel::empty(PixelStatus::Discarded);
    };
    match g.try_normalize() {
        Some(n) if n.z > 0.0 => BaselinePixel {
            status: PixelStatus::Estimated,
            normal: Some(n),
            tangent: None,
            confidence: eq.explained(g) as f32,
            used: eq.n,
        },
        _ => BaselinePixel::empty(PixelStatus::Discarded),
    }
}

/// Woodham's Lambertian photometric stereo at one pixel: the least-squares `g` of
/// `I_i = g . l_i` over the unshadowed samples (grey value at or above
/// [`BaselineParams::shadow_fraction`] of the pixel's reference level, by default the 90th
/// percentile of its grey values), normal `g / |g|`.
///
/// `samples` is the pixel's `n_lights * 3` RGB values (as [`Stack::pixel`]), `lights` the unit
/// light directions in the same order, `scratch` a buffer reused between pixels. Confidence:
/// the uncentred R^2 of the fit, `1 - sum r_i^2 / sum I_i^2` over the samples used (1 for an
/// exact Lambertian pixel). Allocation-free once `scratch` has grown to the light count.
pub fn woodham_pixel(
    samples: &[f32],
    lights: &[DVec3],
    params: &BaselineParams,
    scratch: &mut Vec<f64>,
) -> BaselinePixel {
    let Some(threshold) = shadow_threshold(samples, params, scratch) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    let eq = lit_equations(samples, lights, threshold);
    finish(&eq, eq.solve())
}

/// Woodham with outlier rejection at one pixel (the paper's Figure 4 baseline). The rule:
///
/// 1. fit `g_1` over the unshadowed samples as [`woodham_pixel`];
/// 2. over the same samples, the residuals `r_i = I_i - g_1 . l_i` have mean `m` and (population)
///    standard deviation `s`;
/// 3. drop the samples with `|r_i - m| > k s` (`k` = [`BaselineParams::outlier_sigmas`], 2),
///    and fit again over the rest, once. If fewer than 3 samples are left or the refit is
///    degenerate, the first fit stands.
///
/// Highlights and cast shadows leave large residuals and are dropped; an exact Lambertian pixel
/// has `s = 0` and keeps every sample. Confidence: the uncentred R^2 of the final fit over the
/// samples it used. Allocation-free once `scratch` has grown (three passes over the samples).
pub fn woodham_robust_pixel(
    samples: &[f32],
    lights: &[DVec3],
    params: &BaselineParams,
    scratch: &mut Vec<f64>,
) -> BaselinePixel {
    let Some(threshold) = shadow_threshold(samples, params, scratch) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    let eq = lit_equations(samples, lights, threshold);
    let Some(g1) = eq.solve() else {
        return BaselinePixel::empty(PixelStatus::Discarded);
    };
    let (mut sum, mut sum2) = (0.0, 0.0);
    for (s, &l) in samples.chunks_exact(3).zip(lights) {
        if let Some(i) = grey(s).filter(|&i| i >= threshold) {
            let r = i - g1.dot(l);
            sum += r;
            sum2 += r * r;
        }
    }
    let n = eq.n as f64;
    let mean = sum / n;
    let sd = (sum2 / n - mean * mean).max(0.0).sqrt();
    let limit = params.outlier_sigmas * sd;
    let mut kept = NormalEquations::default();
    for (s, &l) in samples.chunks_exact(3).zip(lights) {
        if let Some(i) = grey(s).filter(|&i| i >= threshold) {
            if (i - g1.dot(l) - mean).abs() <= limit {
                kept.add(l, i);
            }
        }
    }
    match kept.solve() {
        Some(g2) if kept.n < eq.n => finish(&kept, Some(g2)),
        _ => finish(&eq, Some(g1)),
    }
}

/// Neighbours of the brightest sample (in halfway space) that the max-reflectance refinement
/// fits over, besides the brightest sample itself.
pub const MAX_REFLECTANCE_NEIGHBOURS: usize = 12;

/// The max-reflectance ("specularity") method at one pixel: the normal is the halfway vector
/// `h = normalize(l + v)` where the slice is brightest. Refinement between samples:
///
/// 1. take the brightest valid sample `j` and the [`MAX_REFLECTANCE_NEIGHBOURS`] valid,
///    positive samples whose halfway vectors are nearest to `h_j`;
/// 2. map their halfway vectors to the gnomonic chart of the tangent plane at `h_j` and fit
///    `ln I = c0 + c1 u + c2 w + c3 u^2 + c4 u w + c5 w^2` by least squares (exact for a
///    Gaussian lobe: Beckmann-like highlights are quadratic in log space);
/// 3. the normal is the chart point of the fitted maximum; if the fit is degenerate, not a
///    maximum, or its peak lies outside the neighbourhood, it is `h_j` itself.
///
/// So the answer is exact for a highlight centred on the normal sampled densely enough, and
/// within the lights' spacing otherwise. It assumes the peak of the slice is a mirror-like
/// highlight: on a diffuse surface the brightest light is along the normal, so the halfway
/// vector lies halfway between the normal and the view (an error of half the normal's angle
/// from the view; the paper's Figure 4).
///
/// Confidence: the highlight's contrast, `1 - mean / max` of the valid grey values (near 1 for
/// a sharp highlight, about 0.5 for a diffuse surface under lights spread over a wide cone).
/// Allocation-free.
pub fn max_reflectance_pixel(samples: &[f32], lights: &[DVec3]) -> BaselinePixel {
    let Some((j, max)) = brightest(samples) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    let Some(hj) = halfway_from_light(lights[j]) else {
        return BaselinePixel::empty(PixelStatus::Discarded);
    };
    const K: usize = MAX_REFLECTANCE_NEIGHBOURS;
    // The K nearest by cosine to h_j, sorted descending; (cos, index).
    let mut near = [(f64::NEG_INFINITY, usize::MAX); K];
    let (mut sum, mut count) = (0.0, 0usize);
    for (i, (s, &l)) in samples.chunks_exact(3).zip(lights).enumerate() {
        let Some(v) = grey(s) else { continue };
        sum += v;
        count += 1;
        if i == j || v <= 0.0 {
            continue;
        }
        let Some(h) = halfway_from_light(l) else {
            continue;
        };
        let c = h.dot(hj);
        if c > near[K - 1].0 {
            let mut k = K - 1;
            while k > 0 && near[k - 1].0 < c {
                near[k] = near[k - 1];
                k -= 1;
            }
            near[k] = (c, i);
        }
    }
    let confidence = (1.0 - sum / count as f64 / max).clamp(0.0, 1.0) as f32;
    let normal = refine_peak(samples, lights, hj, max, &near).unwrap_or(hj);
    if normal.z <= 0.0 {
        return BaselinePixel::empty(PixelStatus::Discarded);
    }
    let used = 1 + near.iter().filter(|n| n.1 != usize::MAX).count() as u32;
    BaselinePixel {
        status: PixelStatus::Estimated,
        normal: Some(normal),
        tangent: None,
        confidence,
        used,
    }
}

/// Smallest elongation of the highlight for the highlight-centroid baseline to report a
/// tangent (the estimator's own rule, [`crate::frames::estimator::MIN_ELONGATION`]).
const CENTROID_MIN_ELONGATION: f64 = crate::frames::estimator::MIN_ELONGATION;

/// The highlight-centroid baseline at one pixel: the normal is the intensity-weighted mean of
/// the halfway vectors of the samples at or above half the brightest grey value, the tangent
/// the widest axis of their weighted second moment where the highlight is elongated
/// ([`highlight_moments`]). Strong on glossy materials under dense rigs; on diffuse surfaces it
/// shares max-reflectance's bias (half the normal's angle from the view). Confidence: the
/// highlight's contrast. Allocation-free.
pub fn highlight_centroid_pixel(samples: &[f32], lights: &[DVec3]) -> BaselinePixel {
    let Some(m) = highlight_moments_by(samples, |i| halfway_from_light(lights[i])) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    if m.normal.z <= 0.0 {
        return BaselinePixel::empty(PixelStatus::Discarded);
    }
    BaselinePixel {
        status: PixelStatus::Estimated,
        normal: Some(m.normal),
        tangent: m.has_tangent(CENTROID_MIN_ELONGATION).then_some(m.tangent),
        confidence: m.contrast as f32,
        used: m.count,
    }
}

/// Step 2-3 of [`max_reflectance_pixel`]: the log-quadratic peak near `hj`, if well defined.
fn refine_peak(
    samples: &[f32],
    lights: &[DVec3],
    hj: DVec3,
    max: f64,
    near: &[(f64, usize); MAX_REFLECTANCE_NEIGHBOURS],
) -> Option<DVec3> {
    let (e1, e2) = tangent_basis(hj);
    let chart = |h: DVec3| {
        let d = h.dot(hj);
        (h.dot(e1) / d, h.dot(e2) / d)
    };
    // Chart radius of the neighbourhood: coordinates are scaled by it for conditioning.
    let mut radius = 0.0f64;
    let mut n_pts = 1;
    for &(c, i) in near.iter().filter(|n| n.1 != usize::MAX) {
        if c <= 0.0 {
            continue;
        }
        let (u, w) = chart(halfway_from_light(lights[i])?);
        radius = radius.max(u.hypot(w));
        n_pts += 1;
    }
    if n_pts < 7 || radius <= 0.0 {
        return None;
    }
    // Normal equations of the 6-parameter fit, augmented: [A | b].
    let mut m = [[0.0f64; 7]; 6];
    let mut add = |u: f64, w: f64, y: f64| {
        let phi = [1.0, u, w, u * u, u * w, w * w];
        for r in 0..6 {
            for c in 0..6 {
                m[r][c] += phi[r] * phi[c];
            }
            m[r][6] += phi[r] * y;
        }
    };
    add(0.0, 0.0, max.ln());
    for &(c, i) in near.iter().filter(|n| n.1 != usize::MAX) {
        if c <= 0.0 {
            continue;
        }
        let (u, w) = chart(halfway_from_light(lights[i])?);
        let y = grey(&samples[i * 3..i * 3 + 3])?;
        add(u / radius, w / radius, y.ln());
    }
    let c = solve6(m)?;
    // Stationary point: H p = -grad, H = [[2 c3, c4], [c4, 2 c5]] must be negative definite.
    let (h11, h12, h22) = (2.0 * c[3], c[4], 2.0 * c[5]);
    let det = h11 * h22 - h12 * h12;
    if !(h11 < 0.0 && det > 0.0) {
        return None;
    }
    let pu = (-c[1] * h22 + c[2] * h12) / det;
    let pw = (-c[2] * h11 + c[1] * h12) / det;
    let step = pu.hypot(pw);
    if step.is_nan() || step > 1.0 {
        return None;
    }
    (hj + radius * (pu * e1 + pw * e2)).try_normalize()
}

/// Solves a 6x6 system given as an augmented matrix by Gaussian elimination with partial
/// pivoting; `None` if (numerically) singular.
fn solve6(mut m: [[f64; 7]; 6]) -> Option<[f64; 6]> {
    let scale = (0..6).map(|k| m[k][k].abs()).fold(0.0, f64::max);
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    for col in 0..6 {
        let piv = (col..6).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[piv][col].is_nan() || m[piv][col].abs() <= 1e-12 * scale {
            return None;
        }
        m.swap(col, piv);
        let pivot_row = m[col];
        for row in m.iter_mut().skip(col + 1) {
            let f = row[col] / pivot_row[col];
            for (v, p) in row.iter_mut().zip(pivot_row).skip(col) {
                *v -= f * p;
            }
        }
    }
    let mut x = [0.0f64; 6];
    for r in (0..6).rev() {
        let mut v = m[r][6];
        for c in r + 1..6 {
            v -= m[r][c] * x[c];
        }
        x[r] = v / m[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Runs one baseline at one pixel (`samples` as [`Stack::pixel`], `lights` unit, same order;
/// `scratch` a buffer reused between pixels).
pub fn baseline_pixel(
    method: Baseline,
    samples: &[f32],
    lights: &[DVec3],
    params: &BaselineParams,
    scratch: &mut Vec<f64>,
) -> BaselinePixel {
    match method {
        Baseline::Woodham => woodham_pixel(samples, lights, params, scratch),
        Baseline::WoodhamRobust => woodham_robust_pixel(samples, lights, params, scratch),
        Baseline::MaxReflectance => max_reflectance_pixel(samples, lights),
        Baseline::HighlightCentroid => highlight_centroid_pixel(samples, lights),
    }
}

/// A baseline ready to run per pixel: the method, its unit lights (one per input light) and
/// its parameters, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct BaselineMethod {
    method: Baseline,
    lights: Vec<DVec3>,
    params: BaselineParams,
}

impl BaselineMethod {
    /// Checks `params` and normalises `lights` (camera frame, one per stack image).
    pub fn new(method: Baseline, lights: &[DVec3], params: BaselineParams) -> Result<Self> {
        params.validate()?;
        Ok(Self {
            method,
            lights: baseline_lights(lights)?,
            params,
        })
    }

    /// Which baseline.
    pub fn method(&self) -> Baseline {
        self.method
    }

    /// The unit light directions, one per input light.
    pub fn unit_lights(&self) -> &[DVec3] {
        &self.lights
    }

    /// The parameters.
    pub fn params(&self) -> &BaselineParams {
        &self.params
    }
}

impl PixelMethod for BaselineMethod {
    type Scratch = Vec<f64>;
    type Output = PixelRecord;
    /// The baselines are cheap per pixel: wider bands than the symmetry estimator's.
    const BAND_ROWS: usize = 8;

    fn lights(&self) -> Option<&[usize]> {
        None
    }

    fn scratch(&self) -> Vec<f64> {
        Vec::with_capacity(self.lights.len())
    }

    fn pixel(&self, _p: usize, samples: &[f32], scratch: &mut Vec<f64>) -> PixelRecord {
        baseline_pixel(self.method, samples, &self.lights, &self.params, scratch)
            .record(self.method.source())
    }

    fn masked(&self) -> PixelRecord {
        PixelRecord::MASKED
    }
}

/// Runs a baseline on every pixel of a stack (inside `mask` when given) with the default
/// [`BaselineParams`], in parallel over row bands; see [`estimate_stack_baseline_with`].
pub fn estimate_stack_baseline(
    stack: &Stack,
    lights: &[DVec3],
    mask: Option<&[bool]>,
    method: Baseline,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<EstimateMaps> {
    estimate_stack_baseline_with(
        stack,
        lights,
        mask,
        method,
        BaselineParams::default(),
        progress,
    )
}

/// Runs a baseline on every pixel of a stack, in parallel over row bands, and returns the same
/// maps as the symmetry estimator: tangents and anisotropy are NaN (the baselines recover
/// normals only), confidence is the baseline's goodness of fit, `evals` is 0. Every light is
/// used (no cone). `lights` are camera-frame directions, one per stack image (normalised here).
/// `progress` is called with the number of pixels finished by each band.
pub fn estimate_stack_baseline_with(
    stack: &Stack,
    lights: &[DVec3],
    mask: Option<&[bool]>,
    method: Baseline,
    params: BaselineParams,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<EstimateMaps> {
    let method = BaselineMethod::new(method, lights, params)?;
    crate::frames::estimator::check_inputs(
        stack.width,
        stack.height,
        stack.n_lights,
        method.lights.len(),
        mask,
    )?;
    let records = run_stack(&method, stack, mask, progress);
    Ok(EstimateMaps::from_records(
        stack.width,
        stack.height,
        &records,
    ))
}

/// The unit light directions a baseline runs with: `lights` normalised; an error if there are
/// none or one is zero or not finite.
pub fn baseline_lights(lights: &[DVec3]) -> Result<Vec<DVec3>> {
    if lights.is_empty() {
        return Err(Error::NoLights);
    }
    lights
        .iter()
        .enumerate()
        .map(|(index, l)| {
            l.try_normalize()
                .filter(|_| l.is_finite())
                .ok_or(Error::BadLight { index })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::rig::uniform_cone_lights;

    /// One Lambertian pixel: `albedo * max(n.l, 0)` per channel.
    fn lambert(n: DVec3, lights: &[DVec3], albedo: [f32; 3]) -> Vec<f32> {
        lights
            .iter()
            .flat_map(|l| {
                let c = n.dot(*l).max(0.0) as f32;
                albedo.map(|a| a * c)
            })
            .collect()
    }

    fn angle_deg(a: DVec3, b: DVec3) -> f64 {
        a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    #[test]
    fn names_round_trip_through_serde() {
        for b in Baseline::ALL {
            let s = serde_json::to_string(&b).unwrap();
            assert_eq!(s, format!("\"{}\"", b.name()));
            assert_eq!(serde_json::from_str::<Baseline>(&s).unwrap(), b);
        }
    }

    #[test]
    fn woodham_is_exact_on_a_lambertian_pixel_and_ignores_invalid_samples() {
        let lights = uniform_cone_lights(200, 65.0);
        let n = DVec3::new(0.4, -0.3, 0.8).normalize();
        let mut s = lambert(n, &lights, [0.7, 0.5, 0.3]);
        // Invalid samples (NaN) are skipped.
        for k in [5, 17, 99] {
            s[k * 3..k * 3 + 3].fill(f32::NAN);
        }
        let p = BaselineParams::default();
        for r in [
            woodham_pixel(&s, &lights, &p, &mut Vec::new()),
            woodham_robust_pixel(&s, &lights, &p, &mut Vec::new()),
        ] {
            assert_eq!(r.status, PixelStatus::Estimated);
            assert!(angle_deg(r.normal.unwrap(), n) < 1e-4, "{r:?}");
            assert!(r.confidence > 0.999, "{r:?}");
        }
    }

    #[test]
    fn robust_woodham_drops_a_highlight() {
        let lights = uniform_cone_lights(300, 65.0);
        let n = DVec3::new(-0.2, 0.3, 0.9).normalize();
        let mut s = lambert(n, &lights, [0.5; 3]);
        // A few very bright samples (a highlight) near the mirror direction.
        let mirror = 2.0 * n.z * n - DVec3::Z;
        let mut by_angle: Vec<usize> = (0..lights.len()).collect();
        by_angle.sort_by(|&a, &b| lights[b].dot(mirror).total_cmp(&lights[a].dot(mirror)));
        for &k in &by_angle[..6] {
            s[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v += 3.0);
        }
        let p = BaselineParams::default();
        let plain = woodham_pixel(&s, &lights, &p, &mut Vec::new());
        let robust = woodham_robust_pixel(&s, &lights, &p, &mut Vec::new());
        let (ep, er) = (
            angle_deg(plain.normal.unwrap(), n),
            angle_deg(robust.normal.unwrap(), n),
        );
        assert!(ep > 1.0, "plain {ep}");
        assert!(er < 1e-3, "robust {er}, {robust:?}");
        assert!(robust.used < plain.used);
    }

    #[test]
    fn dark_and_sparse_pixels_have_no_estimate() {
        let lights = uniform_cone_lights(50, 65.0);
        let p = BaselineParams::default();
        let dark = vec![0.0f32; 150];
        let nan = vec![f32::NAN; 150];
        for m in Baseline::ALL {
            assert_eq!(
                baseline_pixel(m, &dark, &lights, &p, &mut Vec::new()).status,
                PixelStatus::NoData
            );
            assert_eq!(
                baseline_pixel(m, &nan, &lights, &p, &mut Vec::new()).status,
                PixelStatus::NoData
            );
        }
        // Two lit samples: too few for a 3-parameter fit.
        let mut two = dark.clone();
        two[0..3].fill(0.5);
        two[3..6].fill(0.4);
        assert_eq!(
            woodham_pixel(&two, &lights, &p, &mut Vec::new()).status,
            PixelStatus::Discarded
        );
        // Lights all in one plane: degenerate.
        let flat: Vec<DVec3> = (0..10)
            .map(|i| DVec3::new((i as f64 * 0.2).cos(), 0.0, (i as f64 * 0.2).sin()).normalize())
            .collect();
        let s = lambert(DVec3::new(0.3, 0.0, 0.9).normalize(), &flat, [0.5; 3]);
        assert_eq!(
            woodham_pixel(&s, &flat, &p, &mut Vec::new()).status,
            PixelStatus::Discarded
        );
    }

    #[test]
    fn max_reflectance_finds_a_gaussian_highlight_between_samples() {
        let lights = uniform_cone_lights(400, 65.0);
        let n = DVec3::new(0.25, 0.1, 0.9).normalize();
        // A Gaussian lobe in the halfway angle: exactly log-quadratic.
        let s: Vec<f32> = lights
            .iter()
            .flat_map(|&l| {
                let h = halfway_from_light(l).unwrap();
                let t2 = (1.0 / h.dot(n).powi(2) - 1.0).max(0.0);
                [(-t2 / 0.01).exp() as f32; 3]
            })
            .collect();
        let r = max_reflectance_pixel(&s, &lights);
        let (j, _) = brightest(&s).unwrap();
        let coarse = angle_deg(halfway_from_light(lights[j]).unwrap(), n);
        let fine = angle_deg(r.normal.unwrap(), n);
        assert!(
            fine < 0.05 && fine < coarse,
            "refined {fine}, brightest {coarse}"
        );
        assert!(r.confidence > 0.9, "{r:?}");
    }

    #[test]
    fn stack_driver_checks_its_inputs_and_fills_statuses() {
        let lights = uniform_cone_lights(30, 65.0);
        let mut stack = Stack::zeros(3, 2, 30);
        let n = DVec3::new(0.1, 0.2, 0.95).normalize();
        let px = lambert(n, &lights, [0.6; 3]);
        stack.pixel_mut(1).copy_from_slice(&px);
        stack.pixel_mut(4).copy_from_slice(&px);
        let mask = [true, true, true, false, true, true];
        let m = estimate_stack_baseline(&stack, &lights, Some(&mask), Baseline::Woodham, &|_| {})
            .unwrap();
        assert_eq!(m.counts.estimated, 2);
        assert_eq!(m.counts.masked, 1);
        assert_eq!(m.counts.no_data, 3);
        assert_eq!(m.status[1], PixelStatus::Estimated);
        assert!(m.tangents.iter().all(|v| v.is_nan()));
        assert!(m.anisotropy.iter().all(|v| v.is_nan()));
        assert!(m.confidence[0].is_nan() && m.confidence[1] > 0.99);
        let got = DVec3::new(
            m.normals[3] as f64,
            m.normals[4] as f64,
            m.normals[5] as f64,
        );
        // Normalised first: a unit vector rounded to f32 is off unit length by ~1e-7.
        assert!(angle_deg(got.normalize(), n) < 1e-3);

        let e = |r: Result<EstimateMaps>| r.unwrap_err();
        let run = |l: &[DVec3], mask: Option<&[bool]>| {
            estimate_stack_baseline(&stack, l, mask, Baseline::Woodham, &|_| {})
        };
        assert_eq!(
            e(run(&lights[..29], None)),
            Error::LightCountMismatch { stack: 30, rig: 29 }
        );
        let mut bad = lights.clone();
        bad[7] = DVec3::ZERO;
        assert_eq!(e(run(&bad, None)), Error::BadLight { index: 7 });
        assert!(matches!(
            e(run(&lights, Some(&[false; 6]))),
            Error::BadMask(_)
        ));
        assert!(matches!(
            e(run(&lights, Some(&[true; 5]))),
            Error::BadMask(_)
        ));
        let bad_params = BaselineParams {
            shadow_fraction: 1.5,
            ..BaselineParams::default()
        };
        assert!(matches!(
            estimate_stack_baseline_with(
                &stack,
                &lights,
                None,
                Baseline::Woodham,
                bad_params,
                &|_| {}
            ),
            Err(Error::BadParameter(_))
        ));
    }
}
