//! Per-pixel fits of the glTF 2.0 metallic-roughness model with `KHR_materials_anisotropy`
//! ([`GltfPbr`], anisotropy direction = the estimated tangent): base colour per channel,
//! metallic, roughness and anisotropy strength, so that an exported glTF material is what was
//! fitted.
//!
//! # Method
//!
//! The predicted radiance under a light of intensity `E` (the job's exposure, see
//! [`FitParams::exposure`]) is `E f(l, v) (n.l)`. Per channel `f = c A + B`
//! ([`GltfPbr::terms`]), so given the three nonlinear parameters (metallic `m`, roughness `r`,
//! strength `s`) the best base colour of each channel is a one-dimensional least-squares
//! problem, bounded to `[0, 1]` and solved in closed form. The fit is variable projection over
//! `(m, ln r, s²)`: Levenberg-Marquardt on the reduced residuals (the colour re-solved at every
//! point), with their Jacobian by forward differences, steps projected on the bounds
//! `m, s² in [0, 1]`, `r in [roughness_min, 1]` (a parameter at a bound whose gradient points
//! out is held for the step). `s²` rather than `s` because `α_t = mix(α, 1, s²)` is flat in `s`
//! at `s = 0`. The start is the best point of a coarse grid: `m` 0 and 1 over eight
//! roughnesses, then strengths 0.3 to 0.95 around the best roughness when there is a tangent.
//! A pixel without a tangent is fitted with strength 0.
//!
//! # Exposure
//!
//! The base colour is bounded, so the light intensity `E` of the photographs must be known.
//! [`PixelFitter::scale`](super::fit::PixelFitter::scale) fits a pixel with its own
//! intensity (products `E c` and `E` as four linear parameters, solved in closed form);
//! [`choose_exposure`] turns such fits of sampled pixels into one intensity for the whole fit.

use glam::DVec3;

use super::fit::{rms, squared_errors, FitParams, HoldoutError};
use super::lm::{self, Bounds, Residuals, P};
use crate::brdf::gltf::GltfPbr;

/// The fitted glTF parameters of one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GltfFit {
    /// Base colour per channel, in `[0, 1]`.
    pub base_color: [f64; 3],
    /// Metalness, in `[0, 1]`.
    pub metallic: f64,
    /// Perceptual roughness, in `[roughness_min, 1]`.
    pub roughness: f64,
    /// Anisotropy strength along the tangent, in `[0, 1]` (0 without a tangent).
    pub anisotropy: f64,
    /// Whether the pixel had no tangent (strength held at 0).
    pub isotropic: bool,
    /// Training samples used.
    pub samples: usize,
    /// Sum of squared errors over the training samples and channels.
    pub sse: f64,
    /// Levenberg-Marquardt iterations.
    pub iterations: u32,
}

impl GltfFit {
    /// RMS error over the training samples and channels.
    pub fn rms(&self) -> f64 {
        rms(self.sse, self.samples)
    }
}

/// One usable sample: the light in the pixel's local frame (x = t, y = n x t, z = n) and the
/// measured radiance.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct GltfSample {
    pub l: DVec3,
    pub rgb: [f64; 3],
}

/// Per-thread buffers.
#[derive(Debug, Clone, Default)]
pub(crate) struct Scratch {
    /// The residuals of the search.
    res: Residuals,
    /// `(A, B) (n.l)` per sample at the point of the last [`project`].
    terms: Vec<[f64; 2]>,
}

/// The optimal linear parameters at `p` and the cost; with `out`, the residuals (3 per
/// sample). With an exposure `Some(e)`: the base colour in `[0, 1]` under lights of intensity
/// `e`. With `None` (free scale, [`fit_exposure`]): the products `e c` (at least 0) and the
/// pixel's own best `e` (at least 0), returned as `([e c_r, e c_g, e c_b], e)`.
fn project(
    samples: &[GltfSample],
    v: DVec3,
    p: P,
    e: Option<f64>,
    terms: &mut Vec<[f64; 2]>,
    out: Option<&mut Vec<f64>>,
) -> ([f64; 3], f64, f64) {
    let (at, ab) = GltfPbr::alphas(p[1].exp(), p[2].sqrt());
    let (mut aa, mut ab_, mut bb, mut ai, mut bi) = (0.0, 0.0, 0.0, [0.0f64; 3], [0.0f64; 3]);
    // Pass 1: the model's terms (kept for pass 2) and the sums of the linear problem.
    terms.clear();
    for s in samples {
        let (a, b) = GltfPbr::terms(s.l, v, p[0], at, ab).unwrap_or((0.0, 0.0));
        let (a, b) = (a * s.l.z, b * s.l.z);
        terms.push([a, b]);
        aa += a * a;
        ab_ += a * b;
        bb += b * b;
        for c in 0..3 {
            ai[c] += a * s.rgb[c];
            bi[c] += b * s.rgb[c];
        }
    }
    // `lin[c]` multiplies A and `scale` B in the prediction.
    let (lin, scale, coef) = match e {
        Some(e) => {
            let color = std::array::from_fn(|c| {
                if aa > 0.0 {
                    ((ai[c] - e * ab_) / (e * aa)).clamp(0.0, 1.0)
                } else {
                    0.0
                }
            });
            (color.map(|x| x * e), e, color)
        }
        None => {
            // Interior solution of the four-parameter problem, then the bounds.
            let den = 3.0 * (bb - ab_ * ab_ / aa.max(1e-300));
            let num: f64 = (0..3).map(|c| bi[c] - ab_ * ai[c] / aa.max(1e-300)).sum();
            let e = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
            let a = std::array::from_fn(|c| {
                if aa > 0.0 {
                    ((ai[c] - e * ab_) / aa).max(0.0)
                } else {
                    0.0
                }
            });
            (a, e, a)
        }
    };
    // Pass 2: the residuals (direct, no cancellation).
    let mut cost = 0.0;
    let mut out = out;
    if let Some(o) = out.as_deref_mut() {
        o.clear();
    }
    for (s, &[a, b]) in samples.iter().zip(terms.iter()) {
        for (&i, &k) in s.rgb.iter().zip(&lin) {
            let r = i - (k * a + scale * b);
            cost += r * r;
            if let Some(o) = out.as_deref_mut() {
                o.push(r);
            }
        }
    }
    (coef, scale, cost)
}

/// Fits one pixel's usable training samples (light directions local to the pixel's frame, `v`
/// the view in that frame); `iso` holds the strength at 0.
pub(crate) fn fit_samples(
    samples: &[GltfSample],
    v: DVec3,
    iso: bool,
    params: &FitParams,
    scratch: &mut Scratch,
) -> GltfFit {
    let (fit, _, _) = search(samples, v, iso, params, Some(params.exposure), scratch);
    GltfFit {
        sse: sse(&fit, samples, v, params.exposure).0,
        ..fit
    }
}

/// A free-scale fit of one pixel: the model with the light intensity a parameter of the pixel
/// (`e`, at least 0) and products `e c` (at least 0) in place of the colour. Returns `e`, the
/// products and the fitted metalness: what [`choose_exposure`] needs.
pub(crate) fn fit_exposure(
    samples: &[GltfSample],
    v: DVec3,
    iso: bool,
    params: &FitParams,
    scratch: &mut Scratch,
) -> PixelScale {
    let (fit, products, e) = search(samples, v, iso, params, None, scratch);
    PixelScale {
        exposure: e,
        products,
        metallic: fit.metallic,
    }
}

/// The result of a free-scale fit of one pixel
/// ([`PixelFitter::scale`](super::fit::PixelFitter::scale)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PixelScale {
    /// The pixel's own best light intensity.
    pub exposure: f64,
    /// Light intensity times base colour, per channel.
    pub products: [f64; 3],
    /// The fitted metalness.
    pub metallic: f64,
}

/// The job-level light intensity from free-scale fits of sampled pixels: the median of the
/// pixels' own intensities where the fit is mostly dielectric (metalness below 0.5: its
/// specular layer has a known strength, 4% at normal incidence, which fixes the scale; a
/// metal's does not), when at least a quarter of the pixels are, raised if needed to the 99th percentile of the brightest channel of
/// `e c`, so that at most 1% of the pixels' base colours would exceed 1. `None` without any
/// usable pixel.
pub(crate) fn choose_exposure(pixels: &[PixelScale]) -> Option<f64> {
    match exposure_bounds(pixels) {
        (Some(d), Some(b)) => Some(d.max(b)),
        (d, b) => d.or(b),
    }
}

/// The two readings [`choose_exposure`] combines: the median intensity of the mostly
/// dielectric pixels (when they are at least a quarter), and the 99th percentile of the
/// brightest channel of `e c` (the lowest intensity that keeps 99% of the base colours within
/// 1).
pub(crate) fn exposure_bounds(pixels: &[PixelScale]) -> (Option<f64>, Option<f64>) {
    let quantile = |mut v: Vec<f64>, q: f64| -> Option<f64> {
        v.retain(|x| x.is_finite() && *x > 0.0);
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(v[((v.len() - 1) as f64 * q).round() as usize])
    };
    let dielectrics: Vec<f64> = pixels
        .iter()
        .filter(|p| p.metallic < 0.5)
        .map(|p| p.exposure)
        .collect();
    let dielectric = if 4 * dielectrics.len() >= pixels.len() {
        quantile(dielectrics, 0.5)
    } else {
        None
    };
    let brightest = quantile(
        pixels
            .iter()
            .map(|p| p.products.iter().copied().fold(0.0, f64::max))
            .collect(),
        0.99,
    );
    (dielectric, brightest)
}

/// The grid start and Levenberg-Marquardt search; returns the fit (its `sse` unset), the
/// linear coefficients of [`project`] and the scale used.
fn search(
    samples: &[GltfSample],
    v: DVec3,
    iso: bool,
    params: &FitParams,
    e: Option<f64>,
    scratch: &mut Scratch,
) -> (GltfFit, [f64; 3], f64) {
    // The nonlinear parameters `[m, ln r, s²]`.
    let bounds = Bounds {
        lo: [0.0, params.roughness_min.ln(), 0.0],
        hi: [1.0, 0.0, if iso { 0.0 } else { 1.0 }],
        // The strength is held at 0 without a tangent.
        free: [true, true, !iso],
    };
    let cost_at = |p: P, t: &mut Vec<[f64; 2]>| project(samples, v, bounds.clamp(p), e, t, None).2;

    // Start: a coarse grid.
    let mut best = (f64::INFINITY, [0.0; 3]);
    let consider = |p: P, best: &mut (f64, P), t: &mut Vec<[f64; 2]>| {
        let p = bounds.clamp(p);
        let c = cost_at(p, t);
        if c < best.0 {
            *best = (c, p);
        }
    };
    for m in [0.0, 1.0] {
        for r in [0.1f64, 0.15, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0] {
            consider([m, r.ln(), 0.0], &mut best, &mut scratch.terms);
        }
    }
    if !iso {
        let (m, lr) = (best.1[0], best.1[1]);
        for dr in [-0.7f64, -0.35, 0.0] {
            for q in [0.09, 0.25, 0.5, 0.9] {
                consider([m, lr + dr, q], &mut best, &mut scratch.terms);
            }
        }
    }

    // Levenberg-Marquardt on the reduced residuals; the damped system solved whole, a held
    // parameter's row the identity.
    let terms = &mut scratch.terms;
    let (p, iterations) = lm::minimise(
        best.1,
        &bounds,
        params.max_iterations,
        &mut scratch.res,
        |p, out| project(samples, v, p, e, terms, out).2,
        |jtj, g, free, lambda, p| {
            let mut a = [[0.0f64; 3]; 3];
            let mut b = [0.0f64; 3];
            for j in 0..3 {
                if !free[j] {
                    a[j][j] = 1.0;
                    continue;
                }
                for k in 0..3 {
                    if free[k] {
                        a[j][k] = jtj[j][k];
                    }
                }
                a[j][j] +=
                    lambda * jtj[j][j].max(1e-12 * (jtj[0][0] + jtj[1][1] + jtj[2][2]) + 1e-300);
                b[j] = -g[j];
            }
            let step = solve3(a, b)?;
            Some(std::array::from_fn(|j| p[j] + step[j]))
        },
    );
    let (coef, scale, _) = project(samples, v, p, e, &mut scratch.terms, None);
    let fit = GltfFit {
        base_color: coef,
        metallic: p[0],
        roughness: p[1].exp(),
        anisotropy: p[2].sqrt(),
        isotropic: iso,
        samples: samples.len(),
        sse: 0.0,
        iterations,
    };
    (fit, coef, scale)
}

/// Solves a symmetric 3x3 system by Cramer's rule; `None` when singular.
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let m = glam::DMat3::from_cols_array_2d(&a).transpose();
    let det = m.determinant();
    if !(det.is_finite() && det.abs() > 1e-300) {
        return None;
    }
    let x = m.inverse() * DVec3::from(b);
    x.is_finite().then(|| x.to_array())
}

/// The radiance a fit predicts under exposure `e` for one sample.
#[inline]
fn predict(fit: &GltfFit, s: &GltfSample, v: DVec3, e: f64) -> [f64; 3] {
    let (at, ab) = GltfPbr::alphas(fit.roughness, fit.anisotropy);
    let (a, b) = GltfPbr::terms(s.l, v, fit.metallic, at, ab).unwrap_or((0.0, 0.0));
    fit.base_color.map(|c| e * s.l.z * (c * a + b))
}

/// Sum of squared errors and the largest measurement.
pub(crate) fn sse(fit: &GltfFit, samples: &[GltfSample], v: DVec3, e: f64) -> (f64, f64) {
    squared_errors(samples, |s| (predict(fit, s, v, e), s.rgb))
}

/// The held-out error of a fit.
pub(crate) fn holdout(fit: &GltfFit, test: &[GltfSample], v: DVec3, e: f64) -> HoldoutError {
    HoldoutError::of(sse(fit, test, v, e), test.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::fit::testutil::fit_one;
    use crate::appearance::fit::{FitModel, PixelFitter, PixelOutcome};
    use crate::frames::rig::uniform_cone_lights;
    use crate::geometry::tangent_basis;

    /// One pixel's samples of a glTF material in the frame (n, t, b = n x t) under lights of
    /// intensity `e`.
    fn render_pixel(m: &GltfPbr, n: DVec3, t: DVec3, lights: &[DVec3], e: f64) -> Vec<f32> {
        crate::brdf::testutil::render_pixel(m, n, t, lights, e)
    }

    fn frame() -> (DVec3, DVec3) {
        let n = DVec3::new(0.3, -0.2, 0.9).normalize();
        let (t0, b0) = tangent_basis(n);
        (n, t0 * 0.6 + b0 * 0.8)
    }

    fn params(e: f64) -> FitParams {
        FitParams {
            model: FitModel::Gltf,
            exposure: e,
            ..FitParams::default()
        }
    }

    #[test]
    fn recovers_known_materials_exactly() {
        let (n, t) = frame();
        let lights = uniform_cone_lights(500, 65.0);
        for (base, m, r, s, e) in [
            ([0.6, 0.3, 0.1], 0.0, 0.3, 0.0, 1.0),
            ([0.6, 0.3, 0.1], 0.0, 0.45, 0.6, 2.5),
            ([0.9, 0.7, 0.5], 1.0, 0.3, 0.5, 1.0),
            ([0.95, 0.93, 0.88], 1.0, 0.5, 0.8, 1.0),
            ([0.2, 0.5, 0.8], 0.4, 0.25, 0.3, 0.7),
        ] {
            let truth = GltfPbr::new(base, m, r, s);
            let rgb = render_pixel(&truth, n, t, &lights, e);
            let params = params(e);
            let PixelOutcome::FittedGltf(fit, _) = fit_one(&lights, &params, n, Some(t), &rgb)
            else {
                panic!("not fitted")
            };
            for (got, want) in fit.base_color.iter().zip(base) {
                assert!((got - want).abs() < 2e-3, "{fit:?} {truth:?}");
            }
            assert!((fit.metallic - m).abs() < 2e-3, "{fit:?} {truth:?}");
            assert!((fit.roughness - r).abs() < 2e-3, "{fit:?} {truth:?}");
            assert!((fit.anisotropy - s).abs() < 5e-3, "{fit:?} {truth:?}");
            assert!(fit.rms() < 1e-4, "{fit:?}");
        }
    }

    #[test]
    fn isotropic_pixels_have_no_strength_and_holdout_is_judged() {
        let (n, t) = frame();
        let lights = uniform_cone_lights(400, 65.0);
        let truth = GltfPbr::new([0.5, 0.4, 0.3], 0.0, 0.35, 0.0);
        let rgb = render_pixel(&truth, n, t, &lights, 1.0);
        let params = FitParams {
            holdout: crate::appearance::fit::FitParams::holdout_lights(400, 10).unwrap(),
            ..params(1.0)
        };
        let PixelOutcome::FittedGltf(fit, hold) = fit_one(&lights, &params, n, None, &rgb) else {
            panic!("not fitted")
        };
        assert!(fit.isotropic && fit.anisotropy == 0.0);
        assert!((fit.roughness - 0.35).abs() < 2e-3, "{fit:?}");
        assert!(hold.samples > 0 && (hold.sse / hold.samples as f64).sqrt() < 1e-4);
    }

    #[test]
    fn base_colour_stays_in_the_unit_interval() {
        // Rendered four times brighter than the fit assumes: the colour saturates at 1.
        let (n, t) = frame();
        let lights = uniform_cone_lights(300, 65.0);
        let rgb = render_pixel(&GltfPbr::new([0.8; 3], 0.0, 0.4, 0.0), n, t, &lights, 4.0);
        let params = params(1.0);
        let PixelOutcome::FittedGltf(fit, _) = fit_one(&lights, &params, n, Some(t), &rgb) else {
            panic!("not fitted")
        };
        assert!(
            fit.base_color.iter().all(|&c| (0.0..=1.0).contains(&c)),
            "{fit:?}"
        );
        let bad = FitParams {
            exposure: 0.0,
            ..params
        };
        assert!(PixelFitter::new(&lights, &bad).is_err());
    }
}

#[cfg(test)]
mod exposure_tests {
    use super::*;
    use crate::appearance::fit::{FitModel, PixelFitter};
    use crate::brdf::Brdf;
    use crate::frames::rig::uniform_cone_lights;

    #[test]
    fn the_exposure_of_a_dielectric_is_recovered() {
        let lights = uniform_cone_lights(400, 65.0);
        let params = FitParams {
            model: FitModel::Gltf,
            ..FitParams::default()
        };
        let mut f = PixelFitter::new(&lights, &params).unwrap();
        let mut scales = Vec::new();
        for (k, base) in [[0.6, 0.3, 0.1], [0.2, 0.5, 0.4], [0.3, 0.3, 0.3]]
            .into_iter()
            .enumerate()
        {
            let m = GltfPbr::new(base, 0.0, 0.3 + 0.1 * k as f64, 0.0);
            let n = DVec3::new(0.1 * k as f64, 0.2, 1.0).normalize();
            let (t, b) = crate::geometry::tangent_basis(n);
            let local = |d: DVec3| DVec3::new(d.dot(t), d.dot(b), d.dot(n));
            let rgb: Vec<f32> = lights
                .iter()
                .flat_map(|&l| {
                    let nl = n.dot(l).max(0.0);
                    m.eval(local(l), local(DVec3::Z))
                        .map(|v| (3.0 * v * nl) as f32)
                })
                .collect();
            let s = f.scale(n, None, &rgb).unwrap();
            assert!((s.exposure / 3.0 - 1.0).abs() < 1e-3, "{s:?}");
            for (got, want) in s.products.iter().zip(base) {
                assert!((got - 3.0 * want).abs() < 3e-3, "{s:?}");
            }
            scales.push(s);
        }
        let e = choose_exposure(&scales).unwrap();
        assert!((e / 3.0 - 1.0).abs() < 1e-3, "{e}");
        // A bright metal alone: the brightest colour sets it.
        let metal = PixelScale {
            exposure: 0.0,
            products: [2.0, 1.5, 1.0],
            metallic: 1.0,
        };
        assert_eq!(choose_exposure(&[metal]), Some(2.0));
        assert_eq!(choose_exposure(&[]), None);
    }
}
