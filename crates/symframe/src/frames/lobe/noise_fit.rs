//! What the capture's noise leaves of a lobe fit, and the noise-weighted polish's weights.

use crate::noise::NoiseModel;

use super::kernel;
use super::linear::Linear;
use super::subset::Subset;
use super::{Buffers, Model, State, P};

/// A fit leaving no more than what the capture's noise leaves, at this many standard
/// deviations above its expectation (the one-sided 0.1% point of the normal distribution, as
/// the estimator's acceptance), is as good as the samples allow: it is not retried from other
/// starts, nor given the foreshortening exponent (neither could be told from noise). Higher:
/// fewer retries on noisy captures, faster.
pub(super) const SETTLED_Z: f64 = 3.09;

/// The sum of squared residuals the capture's noise alone leaves on `data`, `z` standard
/// deviations above its expectation ([`noise_variances`]); 0 for a noise-free capture.
pub(super) fn noise_cost(data: &Subset, noise: &NoiseModel, z: f64) -> f64 {
    let (sum, sum2) = noise_variances(data, noise, &[]);
    sum + z * (2.0 * sum2).sqrt()
}

/// The parameters a fit adjusted: its free nonlinear ones and its active linear coefficients.
pub(super) fn fitted_parameters(free: &[bool; P], linear: &Linear) -> usize {
    free.iter().filter(|f| **f).count() + linear.set.count_ones() as usize
}

/// The noise model's variance of a grey value `v`: the sum of three channels of about a third
/// of it, each with the model's variance.
pub(super) fn grey_variance(noise: &NoiseModel, v: f64) -> f64 {
    3.0 * noise.variance(v / 3.0)
}

/// The sum of the samples' noise variances over `data` and the sum of their squares: each grey
/// value's ([`grey_variance`]) plus what the lights' error adds to sample `i` (`light_var[i]`,
/// 0 beyond it).
pub(super) fn noise_variances(data: &Subset, noise: &NoiseModel, light_var: &[f64]) -> (f64, f64) {
    let (mut sum, mut sum2) = (0.0, 0.0);
    for i in 0..data.len() {
        let y = data.value(i).max(0.0);
        let v = grey_variance(noise, y) + light_var.get(i).copied().unwrap_or(0.0);
        sum += v;
        sum2 += v * v;
    }
    (sum, sum2)
}

/// The noise-weighted polish runs only where the unweighted fit's normal scatters by at least
/// this much (radians: a hundredth of a degree, the resolution the error figures are given
/// at): the weights change the answer by less than its scatter, so below it they cannot change
/// it by a figure anyone reads (a noise-free render whose noise estimate reads its curvature).
/// Lower is slower on clean captures.
pub(super) const WEIGHTED_SD_FLOOR: f64 = 0.01 * std::f64::consts::PI / 180.0;

/// The step (radians) of the forward differences that give each sample's slope with respect to
/// the normal's two tilts, for the variance the lights' error gives it.
pub(super) const TILT_STEP: f64 = 1e-5;

/// The weights of the noise-weighted polish into `buffers.weight`, one per sample of `data`:
/// the inverse of each sample's variance at the fit `state` (coefficients `c`) under `noise`
/// (docs/method.md, "Lobe fit", "The noise-weighted fit"): the noise model's variance of its
/// prediction, plus what turning its light by the lights' RMS error moves the prediction by
/// (the prediction's slope with respect to the normal's tilts: a light turned by `e` turns the
/// halfway vector by about `e / (2 h.l)`). The weights' mean is 1. False where every sample
/// weighs the same: a noise-free capture, or a fit the noise does not explain.
pub(super) fn noise_weights(
    data: &Subset,
    state: &State,
    c: [f64; 3],
    noise: &NoiseModel,
    buffers: &mut Buffers,
) -> bool {
    let light_error = noise.light_error_deg.to_radians();
    if noise.variance(1.0) <= 0.0 && light_error <= 0.0 {
        return false;
    }
    buffers.fit(data);
    let Buffers {
        lobe,
        r,
        kept,
        predicted,
        weight,
        tilted,
        ..
    } = buffers;
    let n = data.len();
    let mut prediction = |m: &Model, out: &mut Vec<f64>| {
        kernel::sums(m, data, lobe, kept);
        kernel::residuals(m, data, c, lobe, r);
        out.clear();
        out.extend((0..n).map(|i| data.value(i) - r[i]));
    };
    let m = Model::of(state);
    prediction(&m, predicted);
    // The prediction's slopes with respect to the frame's tilts about `t` (in `weight` for
    // now) and about `b`. A light turned by `e` about an axis moves the diffuse term as the
    // frame's tilt by `e` does, the lobe as a tilt by about `e / (2 h.l)` (the halfway
    // vector turns by that much): the diffuse slope is analytic (`d (n.l) = -l.b` and `l.t`),
    // the lobe's is the rest.
    weight.clear();
    weight.resize(n, 0.0);
    let moved = |axis: usize| {
        let mut d = [0.0; P];
        d[axis] = TILT_STEP;
        Model::of(&state.moved(&d))
    };
    prediction(&moved(0), tilted);
    for ((w, t), p) in weight.iter_mut().zip(tilted.iter()).zip(predicted.iter()) {
        *w = (t - p) / TILT_STEP;
    }
    prediction(&moved(1), tilted);
    // Each sample's variance under the noise model and the lights' error (in `weight`).
    for i in 0..n {
        let p = predicted[i].max(0.0);
        let l = data.light(i);
        // A light the error could carry across the horizon moves the diffuse term too.
        let lit = if m.normal.dot(l) > -2.0 * light_error {
            c[0]
        } else {
            0.0
        };
        let diffuse = [-lit * l.dot(m.b), lit * l.dot(m.t)];
        let total = [weight[i], (tilted[i] - predicted[i]) / TILT_STEP];
        let half = 0.5 / l.dot(data.halfway(i)).max(0.1);
        let mut from_lights = 0.0;
        for a in 0..2 {
            let turned = diffuse[a] + (total[a] - diffuse[a]) * half;
            from_lights += turned * turned * light_error * light_error / 2.0;
        }
        weight[i] = grey_variance(noise, p) + from_lights;
    }
    let dof = n as f64 - (P + 3) as f64;
    if dof < 1.0 {
        return false;
    }
    // A variance floor a millionth of the mean: a sample the model puts at 0 in a capture
    // without read noise must not weigh without bound.
    let floor = 1e-6 * weight.iter().sum::<f64>() / n as f64;
    if floor.is_nan() || floor <= 0.0 {
        return false;
    }
    for w in weight.iter_mut() {
        *w = w.max(floor);
    }
    // The residuals' chi-square under the variances plus `extra`, common to every sample.
    let chi2 = |extra: f64| -> f64 {
        (0..n)
            .map(|i| {
                let r = data.value(i) - predicted[i];
                r * r / (weight[i] + extra)
            })
            .sum()
    };
    // A fit the noise does not explain (its chi-square beyond the one-sided 0.1% point, as
    // the settled fit's test) is a lobe the family does not describe (two lobes, a sheen):
    // weighting its samples by the noise would weight the model's error, so it keeps the
    // unweighted answer.
    let chi2_noise = chi2(0.0);
    if chi2_noise > dof + SETTLED_Z * (2.0 * dof).sqrt() {
        return false;
    }
    let mut extra = 0.0;
    if chi2_noise > dof {
        // Within the noise's spread but above its expectation: the variance `extra` that makes
        // the chi-square equal its degrees of freedom is added to every sample's (what the
        // model leaves beyond the noise, spread evenly). The chi-square falls as `extra`
        // grows: bisection on a log scale up to a value that makes every residual noise, to a
        // millionth of `extra` (the weights then to a millionth; the noise model itself is
        // known to a few percent).
        let top = (0..n)
            .map(|i| (data.value(i) - predicted[i]).powi(2))
            .fold(0.0f64, f64::max)
            .max(f64::MIN_POSITIVE);
        let (mut lo, mut hi) = (top * 1e-12, top);
        for _ in 0..40 {
            if hi <= lo * (1.0 + 1e-6) {
                break;
            }
            let mid = (lo * hi).sqrt();
            if chi2(mid) > dof {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        extra = hi;
    }
    let mut sum = 0.0;
    for w in weight.iter_mut() {
        *w = 1.0 / (*w + extra);
        sum += *w;
    }
    if !(sum > 0.0 && sum.is_finite()) {
        return false;
    }
    // The mean weight 1: the costs keep their scale.
    let scale = n as f64 / sum;
    for w in weight.iter_mut() {
        *w *= scale;
    }
    true
}
