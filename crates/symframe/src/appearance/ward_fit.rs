//! The anisotropic Ward fit of one pixel (paper Section 5.1): diffuse albedo `kd` and specular
//! albedo `ks` per RGB channel, roughness `alpha_t` along the tangent and `alpha_b` along the
//! binormal, chosen to minimise the squared error of the predicted radiance `f(l, v) (n.l)` (the
//! [`Ward`](crate::brdf::ward::Ward) formula, local frame x = t, y = b, z = n) against the
//! measured samples. The driver (samples, held-out lights, summary) is [`super::fit`].
//!
//! # Method
//!
//! Given the roughnesses, the radiance is linear in six parameters, with the same two basis
//! functions for every channel: `phi_d(l) = (n.l)/pi` for `kd` and
//! `phi_s(l) = sqrt((n.l)/(n.v)) exp(-((h.t/h.n)^2/alpha_t^2 + (h.b/h.n)^2/alpha_b^2))` for the
//! lobe's peak radiance `P = ks / (4 pi alpha_t alpha_b)` (the specular radiance at the mirror
//! direction). The fit is therefore a *variable projection* problem (Golub & Pereyra 1973):
//! for each roughness pair the linear parameters are the exact bounded least-squares solution of
//! three 2x2 problems (one per channel, sharing one Gram matrix), and Levenberg-Marquardt runs
//! on the two log-roughnesses only, with Kaufman's (1975) approximation of the reduced problem's
//! Gauss-Newton matrix. Everything one iteration needs (Gram matrix, right-hand sides, gradient
//! and Kaufman matrix) is a fixed set of sums over the samples, so an iteration is one pass over
//! the pixel's samples with no allocation and no per-sample storage besides the samples
//! themselves. Working in log-roughness keeps the roughnesses positive and makes the steps
//! relative; they are clamped to `[alpha_min, alpha_max]`. `ks = 4 pi alpha_t alpha_b P` at the
//! end.
//!
//! Why the peak and not `ks` as the linear parameter: the two are the same model, but the peak
//! is far less correlated with the roughness, and it can be bounded by the data. Where the
//! pixel's mirror direction is outside the lights (normals beyond about 65 degrees from the
//! view for a 130-degree rig), only the lobe's tail is measured and an unbounded fit can explain
//! it with an arbitrarily sharp, arbitrarily bright spike (seen: `ks` of 1e13). The constraints
//! are `kd >= 0`, `0 <= P <= max_peak_ratio * (brightest measurement of the pixel)`; they do not
//! depend on the roughness, so the reduced gradient stays exact. The default ratio (8) allows a
//! peak falling between lights of a dense rig (a lobe of roughness 0.02 sampled 0.025 rad away
//! in halfway space is seen at a fifth of its peak).
//!
//! The start is the best point of a coarse roughness grid (isotropic values 0.01 to 1.28 in
//! factors of 2, then a 3x3 anisotropic neighbourhood of the best one with the wider roughness
//! along t), each point with its closed-form linear parameters: about 16 passes, enough to land
//! in the basin of the global minimum on the materials tested.
//!
//! Samples that are invalid (NaN), under lights held out, or with `n.l <= 0` are not used. A
//! pixel without a tangent (isotropic slice: NaN tangent) gets one roughness
//! (`alpha_t = alpha_b`). Pixels without a normal, with the normal facing away from the view,
//! or with fewer than [`FitParams::min_samples`] usable samples are not fitted (NaN).
//!

use std::f64::consts::PI;

use super::fit::{squared_errors, FitParams, HoldoutError, WardFit};

/// One usable sample, with everything a pass needs precomputed.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Sample {
    /// `(n.l) / pi`: the diffuse basis function.
    pub diffuse: f64,
    /// `sqrt((n.l) / (n.v))`: the specular basis without the lobe's exponential.
    pub spec: f64,
    /// `(h.t / h.n)^2`.
    pub xt: f64,
    /// `(h.b / h.n)^2`.
    pub xb: f64,
    /// Measured RGB radiance.
    pub rgb: [f64; 3],
}

/// Roughness grid of the start (isotropic values).
const ALPHA_GRID: [f64; 8] = [0.01, 0.02, 0.04, 0.08, 0.16, 0.32, 0.64, 1.28];

/// What one pass at a roughness pair yields.
#[derive(Debug, Clone, Copy, Default)]
struct Pass {
    /// Sum of squared errors with the optimal linear parameters.
    cost: f64,
    /// Optimal `[kd, peak]` per channel.
    coef: [[f64; 2]; 3],
    /// Gradient of `cost / 2` with respect to the log-roughnesses.
    grad: [f64; 2],
    /// Kaufman's Gauss-Newton matrix of `cost / 2`: `[h00, h01, h11]`.
    hess: [f64; 3],
}

/// Bounded least squares of a 2x2 problem: minimises `x^T G x - 2 x^T r` over `x0 >= 0`,
/// `0 <= x1 <= upper`, `G = [[a, b], [b, c]]` positive semi-definite. The interior solution if
/// feasible, else the best of the edges' (clamped) solutions: exact for a convex box problem.
#[inline]
fn box_ls2(a: f64, b: f64, c: f64, r: [f64; 2], upper: f64) -> [f64; 2] {
    let obj = |x: [f64; 2]| {
        a * x[0] * x[0] + 2.0 * b * x[0] * x[1] + c * x[1] * x[1]
            - 2.0 * (x[0] * r[0] + x[1] * r[1])
    };
    let det = a * c - b * b;
    if det > 1e-12 * a * c && det > 0.0 {
        let x = [(c * r[0] - b * r[1]) / det, (a * r[1] - b * r[0]) / det];
        if x[0] >= 0.0 && x[1] >= 0.0 && x[1] <= upper {
            return x;
        }
    }
    // x0 as a function of a fixed x1, and x1 of x0 = 0.
    let x0_at = |x1: f64| {
        if a > 0.0 {
            ((r[0] - b * x1) / a).max(0.0)
        } else {
            0.0
        }
    };
    let x1_alone = if c > 0.0 {
        (r[1] / c).clamp(0.0, upper)
    } else {
        0.0
    };
    let mut best = [0.0, x1_alone];
    for x in [[x0_at(0.0), 0.0], [x0_at(upper), upper]] {
        if obj(x) < obj(best) {
            best = x;
        }
    }
    best
}

/// One pass over the samples at log-roughnesses `p` (`p[1]` unused when `iso`): the optimal
/// linear parameters (peak at most `upper`), the cost, its gradient and Kaufman's matrix.
/// `derivatives = false` skips the last two.
fn pass(samples: &[Sample], p: [f64; 2], iso: bool, upper: f64, derivatives: bool) -> Pass {
    let at = p[0].exp();
    let ab = if iso { at } else { p[1].exp() };
    let (it2, ib2) = (1.0 / (at * at), 1.0 / (ab * ab));
    // Gram matrix, right-hand sides, sum of squares.
    let (mut gdd, mut gds, mut gss) = (0.0, 0.0, 0.0);
    let mut fi = [[0.0f64; 2]; 3];
    let mut ii = [0.0f64; 3];
    // Derivative sums: psi.psi, [phi_d.psi, phi_s.psi] per parameter, psi.I per parameter and
    // channel.
    let mut pp = [0.0f64; 3];
    let mut fp = [[0.0f64; 2]; 2];
    let mut pi = [[0.0f64; 3]; 2];
    for s in samples {
        let et = s.xt * it2;
        let eb = s.xb * ib2;
        let phi_s = s.spec * (-(et + eb)).exp();
        let phi_d = s.diffuse;
        gdd += phi_d * phi_d;
        gds += phi_d * phi_s;
        gss += phi_s * phi_s;
        for c in 0..3 {
            fi[c][0] += phi_d * s.rgb[c];
            fi[c][1] += phi_s * s.rgb[c];
            ii[c] += s.rgb[c] * s.rgb[c];
        }
        if derivatives {
            // d phi_s / d log alpha = phi_s * 2 x / alpha^2 per axis (both when isotropic).
            let psi = if iso {
                [phi_s * 2.0 * (et + eb), 0.0]
            } else {
                [phi_s * 2.0 * et, phi_s * 2.0 * eb]
            };
            pp[0] += psi[0] * psi[0];
            pp[1] += psi[0] * psi[1];
            pp[2] += psi[1] * psi[1];
            for ((f, q), &y) in fp.iter_mut().zip(pi.iter_mut()).zip(&psi) {
                f[0] += phi_d * y;
                f[1] += phi_s * y;
                for (q, &i) in q.iter_mut().zip(&s.rgb) {
                    *q += y * i;
                }
            }
        }
    }
    let mut out = Pass::default();
    let det = gdd * gss - gds * gds;
    for c in 0..3 {
        let x = box_ls2(gdd, gds, gss, fi[c], upper);
        out.coef[c] = x;
        let cost = ii[c] - 2.0 * (x[0] * fi[c][0] + x[1] * fi[c][1])
            + gdd * x[0] * x[0]
            + 2.0 * gds * x[0] * x[1]
            + gss * x[1] * x[1];
        out.cost += cost.max(0.0);
        if !derivatives || x[1] <= 0.0 {
            // No lobe: the channel does not depend on the roughness.
            continue;
        }
        let (kd, peak) = (x[0], x[1]);
        // The bounds do not depend on the roughness, so the gradient of the reduced cost is
        // that of the full cost at the optimal linear parameters (envelope theorem).
        for k in 0..2 {
            out.grad[k] += peak * (kd * fp[k][0] + peak * fp[k][1] - pi[k][c]);
        }
        // Kaufman: y_k = peak psi_k projected off the span of the free basis functions.
        let peak_free = peak < upper;
        let proj = |k: usize, j: usize| {
            let (ak, aj) = (fp[k], fp[j]);
            match (kd > 0.0, peak_free) {
                (true, true) if det > 0.0 => {
                    (gss * ak[0] * aj[0] - gds * (ak[0] * aj[1] + ak[1] * aj[0])
                        + gdd * ak[1] * aj[1])
                        / det
                }
                (true, false) if gdd > 0.0 => ak[0] * aj[0] / gdd,
                (false, true) if gss > 0.0 => ak[1] * aj[1] / gss,
                _ => 0.0,
            }
        };
        let p2 = peak * peak;
        out.hess[0] += p2 * (pp[0] - proj(0, 0)).max(0.0);
        out.hess[1] += p2 * (pp[1] - proj(0, 1));
        out.hess[2] += p2 * (pp[2] - proj(1, 1)).max(0.0);
    }
    out
}

/// Fits one pixel's usable training samples; `iso` fits one roughness.
pub(crate) fn fit_samples(samples: &[Sample], iso: bool, params: &FitParams) -> WardFit {
    let (lo, hi) = (params.alpha_min.ln(), params.alpha_max.ln());
    let clamp = |p: [f64; 2]| [p[0].clamp(lo, hi), p[1].clamp(lo, hi)];
    let brightest = samples.iter().flat_map(|s| s.rgb).fold(0.0f64, f64::max);
    let upper = params.max_peak_ratio * brightest;
    // Start: the best point of a coarse grid, linear parameters in closed form.
    let mut best_p = [0.0; 2];
    let mut best_cost = f64::INFINITY;
    let try_point = |p: [f64; 2], best_p: &mut [f64; 2], best_cost: &mut f64| {
        let p = clamp(p);
        let c = pass(samples, p, iso, upper, false).cost;
        if c < *best_cost {
            *best_cost = c;
            *best_p = p;
        }
    };
    for a in ALPHA_GRID {
        try_point([a.ln(); 2], &mut best_p, &mut best_cost);
    }
    if !iso {
        let a0 = best_p[0];
        let l2 = std::f64::consts::LN_2;
        for ft in [0.0, 1.0, 2.0] {
            for fb in [-2.0, -1.0, 0.0] {
                if ft != 0.0 || fb != 0.0 {
                    try_point([a0 + ft * l2, a0 + fb * l2], &mut best_p, &mut best_cost);
                }
            }
        }
    }

    // Levenberg-Marquardt on the log-roughnesses (Marquardt's diagonal scaling).
    let mut p = best_p;
    let mut cur = pass(samples, p, iso, upper, true);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    'outer: while iterations < params.max_iterations {
        iterations += 1;
        let (g, h) = (cur.grad, cur.hess);
        let floor = 1e-12 * (h[0] + h[2]) + 1e-300;
        let scale = [h[0].max(floor), h[2].max(floor)];
        loop {
            let a = h[0] + lambda * scale[0];
            let step = if iso {
                [-g[0] / a, 0.0]
            } else {
                let c = h[2] + lambda * scale[1];
                let b = h[1];
                let det = a * c - b * b;
                if det.is_nan() || det <= 0.0 {
                    lambda *= 10.0;
                    if lambda > 1e12 {
                        break 'outer;
                    }
                    continue;
                }
                [(-c * g[0] + b * g[1]) / det, (b * g[0] - a * g[1]) / det]
            };
            let q = clamp([p[0] + step[0], p[1] + step[1]]);
            let moved = (q[0] - p[0]).abs().max((q[1] - p[1]).abs());
            if !moved.is_finite() || moved < 1e-9 {
                break 'outer;
            }
            let next = pass(samples, q, iso, upper, true);
            if next.cost < cur.cost {
                let gain = cur.cost - next.cost;
                p = q;
                cur = next;
                lambda = (lambda / 3.0).max(1e-9);
                if moved < 1e-7 || gain <= 1e-15 * cur.cost.max(1e-300) {
                    break 'outer;
                }
                break;
            }
            lambda *= 4.0;
            if lambda > 1e12 {
                break 'outer;
            }
        }
    }
    let at = p[0].exp();
    let ab = if iso { at } else { p[1].exp() };
    // Ward's albedo from the lobe's peak: peak = ks / (4 pi alpha_t alpha_b).
    let to_ks = 4.0 * PI * at * ab;
    let fit = WardFit {
        kd: [cur.coef[0][0], cur.coef[1][0], cur.coef[2][0]],
        ks: [cur.coef[0][1], cur.coef[1][1], cur.coef[2][1]].map(|v| v * to_ks),
        alpha_t: at,
        alpha_b: ab,
        isotropic: iso,
        samples: samples.len(),
        sse: 0.0,
        iterations,
    };
    WardFit {
        sse: sse(&fit, samples).0,
        ..fit
    }
}

/// The predicted radiance of a fit at one sample.
#[inline]
fn predict(fit: &WardFit, s: &Sample) -> [f64; 3] {
    let e = s.xt / (fit.alpha_t * fit.alpha_t) + s.xb / (fit.alpha_b * fit.alpha_b);
    let phi_s = s.spec * (-e).exp() / (4.0 * PI * fit.alpha_t * fit.alpha_b);
    std::array::from_fn(|c| fit.kd[c] * s.diffuse + fit.ks[c] * phi_s)
}

/// Sum of squared errors (direct, no cancellation) and the largest measurement.
pub(crate) fn sse(fit: &WardFit, samples: &[Sample]) -> (f64, f64) {
    squared_errors(samples, |s| (predict(fit, s), s.rgb))
}

/// The held-out error of a fit.
pub(crate) fn holdout(fit: &WardFit, test: &[Sample]) -> HoldoutError {
    HoldoutError::of(sse(fit, test), test.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_least_squares_respects_the_bounds() {
        // Unconstrained solution (1, -1): the best with x >= 0 has x1 = 0.
        let (a, b, c) = (2.0, 1.0, 2.0);
        let r = [2.0 - 1.0, 1.0 - 2.0];
        let x = box_ls2(a, b, c, r, 10.0);
        assert_eq!(x[1], 0.0);
        assert!((x[0] - 0.5).abs() < 1e-12);
        assert_eq!(box_ls2(1.0, 0.0, 0.0, [-1.0, 0.0], 1.0), [0.0, 0.0]);
        // Unconstrained (1, 3) with x1 <= 2: x1 = 2, x0 = (r0 - 2 b) / a.
        let r = [2.0 + 3.0, 1.0 + 6.0];
        let x = box_ls2(a, b, c, r, 2.0);
        assert_eq!(x, [1.5, 2.0]);
        // Brute force on a grid agrees.
        let obj = |x: [f64; 2]| {
            a * x[0] * x[0] + 2.0 * b * x[0] * x[1] + c * x[1] * x[1]
                - 2.0 * (x[0] * r[0] + x[1] * r[1])
        };
        let mut best = f64::INFINITY;
        for i in 0..=400 {
            for j in 0..=200 {
                best = best.min(obj([i as f64 * 0.01, j as f64 * 0.01]));
            }
        }
        assert!(obj(x) <= best + 1e-12);
    }
}
