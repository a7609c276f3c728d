//! Per-pixel fits of the two-lobe models sharing the estimated frame: a clear coat over an
//! anisotropic base ([`super::clearcoat`]) and two perpendicular anisotropic lobes
//! ([`super::woven`]). Both are `f = kd b0 + ka b1 + kb b2` per RGB channel, three
//! reflectances times three functions `b` of the directions that depend only on the
//! roughnesses shared by the channels.
//!
//! # Method
//!
//! Variable projection, as the Ward fit ([`super::ward_fit`]): given the roughnesses, the nine
//! reflectances are three bounded 3-parameter least-squares problems (one per channel, one
//! Gram matrix), solved exactly by trying every active set; Levenberg-Marquardt runs on the
//! log-roughnesses only (`ln α_t`, `ln α_b`, and the coat's `ln α_c`; one shared `ln α` for the
//! base of a pixel without a tangent), with the reduced residuals' Jacobian by forward
//! differences. Roughnesses are kept in `[alpha_min, 1]`. The reflectances are at least 0, and
//! each lobe's peak radiance (`k / (4 π α_x α_y)`, at the mirror direction) at most
//! [`FitParams::max_peak_ratio`] times the pixel's brightest measurement: as for the Ward fit,
//! a pixel whose mirror direction lies outside the lights sees only a lobe's tail, which an
//! unbounded fit explains with an arbitrarily bright spike. The start is the best point of a
//! coarse grid of roughnesses (for the coat, three coat roughnesses times the base grid).

// Small dense matrices, filled and solved by index pairs.
#![allow(clippy::needless_range_loop)]

use glam::DVec3;
use std::f64::consts::PI;

use super::fit::{rms, squared_errors, FitParams, HoldoutError};
use super::gltf_fit::GltfSample;
use super::lm::{self, Bounds, Residuals, P};
use super::{clearcoat, woven};
use crate::brdf::{Brdf, TangentAxis};

/// Which two-lobe model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LobeKind {
    /// A sharp isotropic coat over an anisotropic base (`appearance/clearcoat.rs`).
    Clearcoat,
    /// Two perpendicular anisotropic lobes (`appearance/woven.rs`).
    Woven,
}

/// One pixel's two-lobe model: the parameters relighting needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LobeModel {
    /// Which model.
    pub kind: LobeKind,
    /// Diffuse albedo per channel.
    pub kd: [f64; 3],
    /// The first lobe's reflectance per channel: the base's (clear coat), the warp's (woven).
    pub ka: [f64; 3],
    /// The second lobe's: the coat's at normal incidence (clear coat), the weft's (woven).
    pub kb: [f64; 3],
    /// Roughness along the tangent (the base's, or the warp's).
    pub alpha_t: f64,
    /// Roughness along the binormal.
    pub alpha_b: f64,
    /// The coat's roughness (clear coat; NaN for woven).
    pub alpha_c: f64,
}

impl LobeModel {
    /// The three functions the reflectances multiply at local directions `l`, `v`.
    #[inline]
    fn basis(&self, l: DVec3, v: DVec3) -> [f64; 3] {
        match self.kind {
            LobeKind::Clearcoat => clearcoat::basis(l, v, self.alpha_t, self.alpha_b, self.alpha_c),
            LobeKind::Woven => woven::basis(l, v, self.alpha_t, self.alpha_b),
        }
    }

    /// Whether the parameters make a model: finite, reflectances at least 0, roughnesses
    /// positive.
    pub fn is_valid(&self) -> bool {
        let k = self.kd.iter().chain(&self.ka).chain(&self.kb);
        let alphas = match self.kind {
            LobeKind::Clearcoat => [self.alpha_t, self.alpha_b, self.alpha_c],
            LobeKind::Woven => [self.alpha_t, self.alpha_b, self.alpha_b],
        };
        k.copied().all(|x| x.is_finite() && x >= 0.0)
            && alphas.iter().all(|&a| a.is_finite() && a > 0.0)
    }
}

impl Brdf for LobeModel {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        if light_in_local.z <= 0.0 || view_in_local.z <= 0.0 {
            return [0.0; 3];
        }
        let b = self.basis(light_in_local, view_in_local);
        std::array::from_fn(|c| self.kd[c] * b[0] + self.ka[c] * b[1] + self.kb[c] * b[2])
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::of_roughness(self.alpha_t, self.alpha_b)
    }

    fn name(&self) -> String {
        format!("{self:?}")
    }
}

/// The fitted two-lobe parameters of one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LobeFit {
    /// The parameters.
    pub model: LobeModel,
    /// Whether the pixel had no tangent (one base roughness; woven: one lobe).
    pub isotropic: bool,
    /// Training samples used.
    pub samples: usize,
    /// Sum of squared errors over the training samples and channels.
    pub sse: f64,
    /// Levenberg-Marquardt iterations.
    pub iterations: u32,
}

impl LobeFit {
    /// RMS error over the training samples and channels.
    pub fn rms(&self) -> f64 {
        rms(self.sse, self.samples)
    }
}

/// Per-thread buffers.
#[derive(Debug, Clone, Default)]
pub(crate) struct Scratch {
    /// Per sample, what of the basis does not depend on the roughnesses.
    fixed: Vec<Option<clearcoat::Fixed>>,
    /// `b (n.l)` per sample at the point of the last [`project`].
    cols: Vec<[f64; 3]>,
    /// The residuals of the search.
    res: Residuals,
}

/// The roughnesses of the nonlinear parameters `p`, the log-roughnesses
/// `[ln α_t, ln α_b, ln α_c]` (unused entries ignored): `(α_t, α_b, α_c)`.
fn alphas(kind: LobeKind, iso: bool, p: P) -> (f64, f64, f64) {
    let at = p[0].exp();
    let ab = if iso { at } else { p[1].exp() };
    (
        at,
        ab,
        if kind == LobeKind::Clearcoat {
            p[2].exp()
        } else {
            f64::NAN
        },
    )
}

/// Which entries of `P` are free: `α_t` always, `α_b` with a tangent, `α_c` for the coat.
fn free_params(kind: LobeKind, iso: bool) -> [bool; 3] {
    [true, !iso, kind == LobeKind::Clearcoat]
}

/// Minimises `x^T G x - 2 x^T r` over `0 <= x_j <= upper_j` (`G` symmetric positive
/// semi-definite): the best feasible stationary point over every active set (each variable
/// free, at 0, or at its upper bound when finite), exact for a convex box problem.
fn box_ls3(g: &[[f64; 3]; 3], r: [f64; 3], upper: [f64; 3]) -> [f64; 3] {
    let obj = |x: &[f64; 3]| {
        let mut o = 0.0;
        for j in 0..3 {
            o -= 2.0 * x[j] * r[j];
            for k in 0..3 {
                o += x[j] * g[j][k] * x[k];
            }
        }
        o
    };
    let mut best = [0.0; 3];
    let mut best_obj = 0.0;
    // State per variable: 0 at zero, 1 free, 2 at the upper bound.
    for code in 0..27 {
        let state = [code % 3, (code / 3) % 3, code / 9];
        if (0..3).any(|j| state[j] == 2 && !upper[j].is_finite()) {
            continue;
        }
        let mut x = [0.0; 3];
        let free: Vec<usize> = (0..3).filter(|&j| state[j] == 1).collect();
        for j in 0..3 {
            if state[j] == 2 {
                x[j] = upper[j];
            }
        }
        if !free.is_empty() {
            // G_ff x_f = r_f - G_fc x_c.
            let n = free.len();
            let mut a = [[0.0; 4]; 3];
            for (i, &j) in free.iter().enumerate() {
                for (k, &m) in free.iter().enumerate() {
                    a[i][k] = g[j][m];
                }
                a[i][3] = r[j]
                    - (0..3)
                        .filter(|m| state[*m] == 2)
                        .map(|m| g[j][m] * x[m])
                        .sum::<f64>();
            }
            let Some(sol) = solve(&mut a, n) else {
                continue;
            };
            let mut ok = true;
            for (i, &j) in free.iter().enumerate() {
                if !(sol[i] >= 0.0 && sol[i] <= upper[j]) {
                    ok = false;
                }
                x[j] = sol[i];
            }
            if !ok {
                continue;
            }
        }
        let o = obj(&x);
        if o < best_obj {
            best_obj = o;
            best = x;
        }
    }
    best
}

/// Solves the `n x n` system of the augmented rows `a` (column 3 the right-hand side) by
/// Gaussian elimination with partial pivoting; `None` when (nearly) singular.
fn solve(a: &mut [[f64; 4]; 3], n: usize) -> Option<[f64; 3]> {
    let scale = (0..n).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs().is_nan() || a[piv][col].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(col, piv);
        for row in 0..n {
            if row != col {
                let f = a[row][col] / a[col][col];
                for k in col..4 {
                    a[row][k] -= f * a[col][k];
                }
            }
        }
    }
    let mut x = [0.0; 3];
    for i in 0..n {
        x[i] = a[i][3] / a[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The optimal reflectances at `p` (`[kd, ka, kb]` per channel) and the cost; with `out`, the
/// residuals (3 per sample). `brightest` bounds the lobes' peaks.
#[allow(clippy::too_many_arguments)]
fn project(
    kind: LobeKind,
    samples: &[GltfSample],
    fixed: &[Option<clearcoat::Fixed>],
    v: DVec3,
    iso: bool,
    p: P,
    bound: f64,
    cols: &mut Vec<[f64; 3]>,
    out: Option<&mut Vec<f64>>,
) -> ([[f64; 3]; 3], f64) {
    let (at, ab, ac) = alphas(kind, iso, p);
    let mut g = [[0.0f64; 3]; 3];
    let mut r = [[0.0f64; 3]; 3];
    cols.clear();
    for (s, f) in samples.iter().zip(fixed) {
        let mut b = match (kind, f) {
            (_, None) => [0.0; 3],
            (LobeKind::Clearcoat, Some(f)) => clearcoat::basis_at(s.l, v, f, at, ab, ac),
            (LobeKind::Woven, Some(f)) => woven::basis_at(s.l, v, f.h, at, ab),
        };
        if kind == LobeKind::Woven && iso {
            b[2] = 0.0;
        }
        let b = b.map(|x| x * s.l.z);
        cols.push(b);
        for j in 0..3 {
            for k in j..3 {
                g[j][k] += b[j] * b[k];
            }
            for c in 0..3 {
                r[c][j] += b[j] * s.rgb[c];
            }
        }
    }
    for j in 0..3 {
        for k in 0..j {
            g[j][k] = g[k][j];
        }
    }
    // A lobe's peak radiance is about k / (4 pi a_x a_y).
    let peak = |ax: f64, ay: f64| bound * 4.0 * PI * ax * ay;
    let second = match kind {
        LobeKind::Clearcoat => peak(ac, ac),
        LobeKind::Woven if iso => 0.0,
        LobeKind::Woven => peak(ab, at),
    };
    let upper = [f64::INFINITY, peak(at, ab), second];
    let coef: [[f64; 3]; 3] = std::array::from_fn(|c| box_ls3(&g, r[c], upper));
    let mut cost = 0.0;
    let mut out = out;
    if let Some(o) = out.as_deref_mut() {
        o.clear();
    }
    for (s, b) in samples.iter().zip(cols.iter()) {
        for c in 0..3 {
            let x = &coef[c];
            let e = s.rgb[c] - (x[0] * b[0] + x[1] * b[1] + x[2] * b[2]);
            cost += e * e;
            if let Some(o) = out.as_deref_mut() {
                o.push(e);
            }
        }
    }
    (coef, cost)
}

/// Fits one pixel's usable training samples (light directions local to the pixel's frame, `v`
/// the view in that frame); `iso`: the pixel has no tangent.
pub(crate) fn fit_samples(
    kind: LobeKind,
    samples: &[GltfSample],
    v: DVec3,
    iso: bool,
    params: &FitParams,
    scratch: &mut Scratch,
) -> LobeFit {
    let brightest = samples.iter().flat_map(|s| s.rgb).fold(0.0f64, f64::max);
    let bound = params.max_peak_ratio * brightest;
    let (lo, hi) = (params.alpha_min.ln(), params.alpha_max.min(1.0).ln());
    let bounds = Bounds {
        lo: [lo; 3],
        hi: [hi; 3],
        free: free_params(kind, iso),
    };
    // What of the basis does not depend on the roughnesses, once per sample (the coat's
    // Fresnel factors are unused by the woven model).
    let mut fixed_buf = std::mem::take(&mut scratch.fixed);
    fixed_buf.clear();
    fixed_buf.extend(samples.iter().map(|s| clearcoat::fixed(s.l, v)));
    let fixed = &fixed_buf[..];
    let cost_at = |p: P, cols: &mut Vec<[f64; 3]>| {
        project(
            kind,
            samples,
            fixed,
            v,
            iso,
            bounds.clamp(p),
            bound,
            cols,
            None,
        )
        .1
    };

    // Start: a coarse grid, the tangent's roughness the wider.
    const GRID: [f64; 6] = [0.02, 0.05, 0.1, 0.2, 0.4, 0.8];
    let coats: &[f64] = match kind {
        LobeKind::Clearcoat => &[0.01, 0.03, 0.08],
        LobeKind::Woven => &[1.0],
    };
    let mut best = (f64::INFINITY, [0.0; 3]);
    for &c in coats {
        for (i, &a) in GRID.iter().enumerate() {
            for &b in if iso { &GRID[i..=i] } else { &GRID[..=i] } {
                let p = bounds.clamp([a.ln(), b.ln(), c.ln()]);
                let cost = cost_at(p, &mut scratch.cols);
                if cost < best.0 {
                    best = (cost, p);
                }
            }
        }
    }

    // Levenberg-Marquardt on the reduced residuals; the damped system solved over the
    // parameters not held.
    let cols = &mut scratch.cols;
    let (p, iterations) = lm::minimise(
        best.1,
        &bounds,
        params.max_iterations,
        &mut scratch.res,
        |p, out| project(kind, samples, fixed, v, iso, p, bound, cols, out).1,
        |jtj, g, active, lambda, p| {
            let trace: f64 = (0..3).map(|j| jtj[j][j]).sum();
            let idx: Vec<usize> = (0..3).filter(|&j| active[j]).collect();
            let mut a = [[0.0f64; 4]; 3];
            for (i, &j) in idx.iter().enumerate() {
                for (k, &m) in idx.iter().enumerate() {
                    a[i][k] = jtj[j][m];
                }
                a[i][i] += lambda * jtj[j][j].max(1e-12 * trace + 1e-300);
                a[i][3] = -g[j];
            }
            let sol = solve(&mut a, idx.len())?;
            let mut q = p;
            for (i, &j) in idx.iter().enumerate() {
                q[j] += sol[i];
            }
            Some(q)
        },
    );
    let (coef, _) = project(
        kind,
        samples,
        fixed,
        v,
        iso,
        p,
        bound,
        &mut scratch.cols,
        None,
    );
    scratch.fixed = fixed_buf;
    let (at, ab, ac) = alphas(kind, iso, p);
    let fit = LobeFit {
        model: LobeModel {
            kind,
            kd: coef.map(|x| x[0]),
            ka: coef.map(|x| x[1]),
            kb: coef.map(|x| x[2]),
            alpha_t: at,
            alpha_b: ab,
            alpha_c: ac,
        },
        isotropic: iso,
        samples: samples.len(),
        sse: 0.0,
        iterations,
    };
    LobeFit {
        sse: sse(&fit, samples, v).0,
        ..fit
    }
}

/// Sum of squared errors and the largest measurement.
pub(crate) fn sse(fit: &LobeFit, samples: &[GltfSample], v: DVec3) -> (f64, f64) {
    squared_errors(samples, |s| {
        let f = fit.model.eval(s.l, v);
        (f.map(|x| x * s.l.z), s.rgb)
    })
}

/// The held-out error of a fit.
pub(crate) fn holdout(fit: &LobeFit, test: &[GltfSample], v: DVec3) -> HoldoutError {
    HoldoutError::of(sse(fit, test, v), test.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::fit::testutil::fit_one;
    use crate::appearance::fit::{FitModel, PixelOutcome};
    use crate::brdf::{Ggx, Layered, Woven};
    use crate::frames::rig::uniform_cone_lights;
    use crate::geometry::tangent_basis;

    fn frame() -> (DVec3, DVec3) {
        let n = DVec3::new(0.3, -0.2, 0.9).normalize();
        let (t0, b0) = tangent_basis(n);
        (n, t0 * 0.6 + b0 * 0.8)
    }

    fn fit_pixel(model: FitModel, brdf: &dyn Brdf, lights: &[DVec3]) -> LobeFit {
        let (n, t) = frame();
        let rgb = crate::brdf::testutil::render_pixel(brdf, n, t, lights, 1.0);
        let params = FitParams {
            model,
            ..FitParams::default()
        };
        match fit_one(lights, &params, n, Some(t), &rgb) {
            PixelOutcome::FittedLobes(fit, _) => fit,
            other => panic!("not a two-lobe fit: {other:?}"),
        }
    }

    /// A rendered clear coat over a brushed GGX base (the layered render model, base Fresnel
    /// constant) is recovered: every reflectance and roughness.
    #[test]
    fn recovers_a_clear_coat_over_a_brushed_base() {
        let lights = uniform_cone_lights(600, 65.0);
        let kd = [0.05, 0.08, 0.25];
        let ks = [0.5, 0.5, 0.6];
        let truth = Layered::new(
            0.03,
            clearcoat::COAT_IOR,
            Box::new(Ggx::new(kd, ks, 0.35, 0.12)),
        );
        // The layered model's base Fresnel is Schlick's with f0 = ks: nearly constant here.
        let fit = fit_pixel(FitModel::Clearcoat, &truth, &lights);
        let m = fit.model;
        let f0 = crate::brdf::microfacet::fresnel_dielectric(1.0, clearcoat::COAT_IOR);
        for c in 0..3 {
            assert!((m.kd[c] - kd[c]).abs() < 2e-3, "{fit:?}");
            assert!((m.ka[c] / ks[c] - 1.0).abs() < 1e-2, "{fit:?}");
            assert!((m.kb[c] / f0 - 1.0).abs() < 2e-2, "{fit:?}");
        }
        assert!((m.alpha_t / 0.35 - 1.0).abs() < 1e-2, "{fit:?}");
        assert!((m.alpha_b / 0.12 - 1.0).abs() < 1e-2, "{fit:?}");
        assert!((m.alpha_c / 0.03 - 1.0).abs() < 2e-2, "{fit:?}");
    }

    /// Rendered woven satin (two perpendicular GGX lobes, Fresnel constant) is recovered
    /// exactly.
    #[test]
    fn recovers_woven_satin() {
        let lights = uniform_cone_lights(600, 65.0);
        let kd = [0.25, 0.08, 0.08];
        let truth = Woven::new(kd, [1.0; 3], 0.35, 0.08, 0.5);
        let fit = fit_pixel(FitModel::Woven, &truth, &lights);
        let m = fit.model;
        for c in 0..3 {
            assert!((m.kd[c] - kd[c]).abs() < 1e-4, "{fit:?}");
            assert!((m.ka[c] - 1.0).abs() < 1e-3, "{fit:?}");
            assert!((m.kb[c] - 0.5).abs() < 1e-3, "{fit:?}");
        }
        assert!((m.alpha_t / 0.35 - 1.0).abs() < 1e-3, "{fit:?}");
        assert!((m.alpha_b / 0.08 - 1.0).abs() < 1e-3, "{fit:?}");
        assert!(fit.rms() < 1e-5, "{fit:?}");
    }

    /// Car paint and woven satin on a sphere under 400 lights, 12 held out: relit under the
    /// held-out lights, no pixel of the two-lobe fit of its material (nor of the automatic
    /// fit of car paint, the sharper highlight) rises above twice the brightest training
    /// sample of its pixel, or above the true render's own ratio where a highlight falling
    /// between the training lights takes the truth higher; and the relit images match the
    /// truth (PSNR over the sphere).
    #[test]
    fn two_lobe_fits_relight_within_the_training_samples() {
        use crate::appearance::fit::testutil::{choose_exposure, fit_scene, judge_relit};
        use crate::appearance::relight::{Edits, Relighter};
        use crate::render::{Scene, TangentField};
        let lights = uniform_cone_lights(400, 65.0);
        let holdout = FitParams::holdout_lights(400, 12).unwrap();
        let scene = Scene::sphere(16, TangentField::Circular);
        let car_paint = Layered::new(
            0.03,
            clearcoat::COAT_IOR,
            Box::new(Ggx::new([0.05, 0.08, 0.25], [0.5, 0.5, 0.6], 0.35, 0.12)),
        );
        let satin = Woven::new([0.25, 0.08, 0.08], [0.05; 3], 0.35, 0.08, 0.5);
        let cases: [(&dyn Brdf, FitModel, f64); 3] = [
            (&car_paint, FitModel::Clearcoat, 40.0),
            (&car_paint, FitModel::Auto, 40.0),
            (&satin, FitModel::Woven, 45.0),
        ];
        for (brdf, model, min_psnr) in cases {
            let stack = scene.render_stack(brdf, &lights);
            let mut params = FitParams {
                model,
                holdout: holdout.clone(),
                ..FitParams::default()
            };
            if model.uses_gltf() {
                params.exposure = choose_exposure(&lights, &params, &scene, &stack).exposure;
            }
            let fit = fit_scene(&params, &scene, &stack, &lights);
            let relighter = Relighter::of_fit(&fit.ward, fit.gltf.as_ref(), &Edits::default())
                .unwrap()
                .with_lobes(fit.lobes.as_ref().unwrap(), &Edits::default())
                .unwrap();
            let (relit_ratio, truth_ratio, psnr) =
                judge_relit(&relighter, &scene, &stack, &lights, &holdout);
            assert!(
                relit_ratio <= truth_ratio.max(2.0),
                "{model:?}: relit {relit_ratio}, truth {truth_ratio}"
            );
            assert!(psnr >= min_psnr, "{model:?}: {psnr} dB");
        }
    }

    #[test]
    fn box_least_squares_is_exact() {
        // A random convex problem against a brute-force grid.
        let g = [[2.0, 0.5, 0.3], [0.5, 1.0, 0.2], [0.3, 0.2, 0.8]];
        let r = [1.0, -0.5, 0.9];
        let upper = [f64::INFINITY, 0.3, 0.6];
        let x = box_ls3(&g, r, upper);
        let obj = |x: [f64; 3]| {
            let mut o = 0.0;
            for j in 0..3 {
                o -= 2.0 * x[j] * r[j];
                for k in 0..3 {
                    o += x[j] * g[j][k] * x[k];
                }
            }
            o
        };
        let mut best = f64::INFINITY;
        for i in 0..=100 {
            for j in 0..=30 {
                for k in 0..=60 {
                    best = best.min(obj([i as f64 * 0.01, j as f64 * 0.01, k as f64 * 0.01]));
                }
            }
        }
        assert!(obj(x) <= best + 1e-12, "{x:?}");
        assert!(x[1] >= 0.0 && x[1] <= 0.3 && x[2] <= 0.6);
    }
}
