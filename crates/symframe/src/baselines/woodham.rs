//! Lambertian photometric stereo (Woodham 1980), plain and with outlier rejection.

use std::cmp::Ordering;

use glam::{DMat3, DVec3};

use super::{grey_values, BaselineParams, BaselinePixel};
use crate::maps::PixelStatus;

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
/// where that is zero); `None` when no valid sample is brighter than zero. `greys` are the
/// pixel's grey values (NaN where invalid), `work` at least as long (it gets the valid ones for
/// the quantile).
#[inline]
fn shadow_threshold(greys: &[f64], params: &BaselineParams, work: &mut [f64]) -> Option<f64> {
    let q = params.shadow_reference_quantile;
    // The brightest as `brightest` finds it, and the valid values in order.
    let mut max = 0.0;
    let mut valid = 0;
    for &v in greys {
        if v.is_finite() {
            if v > max {
                max = v;
            }
            if q < 1.0 {
                work[valid] = v;
                valid += 1;
            }
        }
    }
    if max <= 0.0 {
        return None;
    }
    let reference = if q >= 1.0 {
        max
    } else {
        let valid = &mut work[..valid];
        let k = ((q * (valid.len() - 1) as f64).floor() as usize).min(valid.len() - 1);
        // The values are finite: `<` orders them as `total_cmp` does but for the sign of zero,
        // which the test below does not see, and costs less.
        let (_, &mut v, _) =
            valid.select_nth_unstable_by(k, |a, b| a.partial_cmp(b).unwrap_or(Ordering::Equal));
        if v > 0.0 {
            v
        } else {
            max
        }
    };
    Some(params.shadow_fraction * reference)
}

/// The pixel's grey values (NaN where invalid) in `scratch[..n]` and `scratch[n..]` a work
/// buffer twice as long, for `n` lights.
fn greys_and_work<'s>(samples: &[f32], scratch: &'s mut Vec<f64>) -> (&'s [f64], &'s mut [f64]) {
    let n = samples.len() / 3;
    grey_values(samples, scratch);
    scratch.resize(3 * n, 0.0);
    let (greys, work) = scratch.split_at_mut(n);
    (greys, work)
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
            considered: eq.n,
        },
        _ => BaselinePixel::empty(PixelStatus::Discarded),
    }
}

/// Woodham's Lambertian photometric stereo at one pixel: the least-squares `g` of
/// `I_i = g . l_i` over the unshadowed samples (grey value at or above
/// [`BaselineParams::shadow_fraction`] of the pixel's reference level, by default the 90th
/// percentile of its grey values), normal `g / |g|`.
///
/// `samples` is the pixel's `n_lights * 3` RGB values (as [`Stack::pixel`](crate::stack::Stack::pixel)), `lights` the unit
/// light directions in the same order, `scratch` a buffer reused between pixels. Confidence:
/// the uncentred R^2 of the fit, `1 - sum r_i^2 / sum I_i^2` over the samples used (1 for an
/// exact Lambertian pixel). Allocation-free once `scratch` has grown (three values per light).
pub(crate) fn woodham_pixel(
    samples: &[f32],
    lights: &[DVec3],
    params: &BaselineParams,
    scratch: &mut Vec<f64>,
) -> BaselinePixel {
    let (greys, work) = greys_and_work(samples, scratch);
    let Some(threshold) = shadow_threshold(greys, params, work) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    // The normal equations over the samples at or above the threshold (NaN never is).
    let mut eq = NormalEquations::default();
    for (&i, &l) in greys.iter().zip(lights) {
        if i >= threshold {
            eq.add(l, i);
        }
    }
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
/// samples it used. Allocation-free once `scratch` has grown (one pass over the samples, three over
/// the unshadowed ones; each grey value computed once).
pub(crate) fn woodham_robust_pixel(
    samples: &[f32],
    lights: &[DVec3],
    params: &BaselineParams,
    scratch: &mut Vec<f64>,
) -> BaselinePixel {
    let (greys, work) = greys_and_work(samples, scratch);
    woodham_robust_greys(greys, lights, params, work)
}

/// [`woodham_robust_pixel`] from the pixel's grey values (`(r + g + b) / 3`, NaN where invalid),
/// with `work` at least twice as long as `greys`: for a caller that reads the grey values
/// again.
pub(crate) fn woodham_robust_greys(
    greys: &[f64],
    lights: &[DVec3],
    params: &BaselineParams,
    work: &mut [f64],
) -> BaselinePixel {
    let Some(threshold) = shadow_threshold(greys, params, work) else {
        return BaselinePixel::empty(PixelStatus::NoData);
    };
    // The unshadowed samples' equations, and the samples as (light index, grey value) pairs
    // in `work`: the two passes below read only them, in the same order as a pass over every
    // sample would.
    let mut eq = NormalEquations::default();
    let mut pairs = 0;
    for (k, &i) in greys.iter().enumerate() {
        // NaN (invalid) is never at or above the threshold.
        if i >= threshold {
            eq.add(lights[k], i);
            work[pairs] = k as f64;
            work[pairs + 1] = i;
            pairs += 2;
        }
    }
    let lit = || {
        work[..pairs]
            .chunks_exact(2)
            .map(|p| (lights[p[0] as usize], p[1]))
    };
    let Some(g1) = eq.solve() else {
        return BaselinePixel::empty(PixelStatus::Discarded);
    };
    let (mut sum, mut sum2) = (0.0, 0.0);
    for (l, i) in lit() {
        let r = i - g1.dot(l);
        sum += r;
        sum2 += r * r;
    }
    let n = eq.n as f64;
    let mean = sum / n;
    let sd = (sum2 / n - mean * mean).max(0.0).sqrt();
    let limit = params.outlier_sigmas * sd;
    let mut kept = NormalEquations::default();
    for (l, i) in lit() {
        if (i - g1.dot(l) - mean).abs() <= limit {
            kept.add(l, i);
        }
    }
    match kept.solve() {
        Some(g2) if kept.n < eq.n => BaselinePixel {
            considered: eq.n,
            ..finish(&kept, Some(g2))
        },
        _ => finish(&eq, Some(g1)),
    }
}
