//! The lights' uncertainty in a lobe fit ([`super::LobeFit::light_sd`]): how far the normal
//! moves when the fit is repeated with every light turned at random by the calibration's
//! error, and what the turns add to each sample's variance (docs/method.md, "Confidence").

use glam::DVec3;

use super::search::{levenberg_marquardt, RELATIVE_GAIN};
use super::subset::Subset;
use super::{residuals, Buffers, Model, State, P};

/// Draws of the lights' error the lobe fit's [`super::LobeFit::light_sd`] averages: two
/// degrees of freedom each, so that the estimate rarely falls far below the variance it stands
/// for (a quarter of it at about one pixel in a thousand with eight; one in eleven with two).
/// Higher is slower (a refit each, two passes per iteration), only where a light error is
/// given.
pub(super) const LIGHT_DRAWS: u64 = 8;

/// The seed of a pixel's light-error draws ([`LIGHT_DRAWS`]): a hash of its `len` fitted
/// samples' grey values (`greys` at `lights`), so that a pixel draws the same turns every run.
pub(super) fn light_draws_seed(lights: &[u32], greys: &[f64], len: usize) -> u64 {
    lights.iter().fold(len as u64, |h, &j| {
        (h ^ greys[j as usize].to_bits()).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The root mean squared angle (radians) the normal `normal` of a fit of `fine` moves by
/// when `refit` repeats the fit from its answer on the samples with every light turned
/// ([`Subset::turned_from`], into `turned`) by `light_error` (radians, RMS) at random,
/// [`LIGHT_DRAWS`] times from the stream `seed`; `refit` returns the refitted normal and the
/// passes it took, summed here. One lobe and two share it.
pub(super) fn moved_by_turned_lights(
    fine: &Subset,
    turned: &mut Subset,
    normal: DVec3,
    light_error: f64,
    seed: u64,
    mut refit: impl FnMut(&Subset) -> (DVec3, u32),
) -> (f64, u32) {
    let (mut sum, mut evals) = (0.0, 0);
    for draw in 0..LIGHT_DRAWS {
        turned.turned_from(fine, light_error, seed.wrapping_add(draw));
        let (moved, e) = refit(turned);
        sum += moved.angle_between(normal).powi(2);
        evals += e;
    }
    ((sum / LIGHT_DRAWS as f64).sqrt(), evals)
}

/// The standard deviation (radians) of the normal of the one-lobe fit `state` of `fine` (its
/// free parameters `free`) under lights off by `light_error` (radians, RMS) at random, and the
/// passes over the samples it took ([`moved_by_turned_lights`], each draw refitted by
/// Levenberg-Marquardt to convergence). A refit, not one Gauss-Newton step: a lobe read between
/// few lights can answer a turn of its lights nonlinearly, sliding along a valley of its shape
/// and tilt several times further than the step from the answer predicts (or less far), and a
/// calibration's error moves the answer as the refit does. The same draws leave in
/// `buffers.light_var` what the turned lights change in each sample's prediction, its variance
/// from the lights.
pub(super) fn light_share(
    state: &State,
    fine: &Subset,
    turned: &mut Subset,
    free: [bool; P],
    light_error: f64,
    seed: u64,
    buffers: &mut Buffers,
) -> (f64, u32) {
    let m = Model::of(state);
    buffers.fit(fine);
    predict(&m, fine, buffers);
    let Buffers {
        r,
        predicted,
        light_var,
        ..
    } = &mut *buffers;
    predicted.clear();
    predicted.extend_from_slice(&r[..fine.len()]);
    light_var.clear();
    light_var.resize(fine.len(), 0.0);
    let (sd, e) = moved_by_turned_lights(fine, turned, state.normal, light_error, seed, |turned| {
        buffers.fit(turned);
        let (refit, _, e) = levenberg_marquardt(turned, *state, None, free, RELATIVE_GAIN, buffers);
        predict(&m, turned, buffers);
        let Buffers {
            r,
            predicted,
            light_var,
            ..
        } = &mut *buffers;
        for (v, (now, before)) in light_var.iter_mut().zip(r.iter().zip(predicted.iter())) {
            *v += (now - before).powi(2) / LIGHT_DRAWS as f64;
        }
        (refit.normal, e + 1)
    });
    // One pass more: the prediction at the answer.
    (sd, e + 1)
}

/// What `m` predicts for each sample of `data`, into `buffers.r` (each value less its
/// residual).
fn predict(m: &Model, data: &Subset, buffers: &mut Buffers) {
    let Buffers { lobe, r, kept, .. } = buffers;
    residuals(m, data, lobe, r, kept);
    for (i, v) in r.iter_mut().enumerate().take(data.len()) {
        *v = data.value(i) - *v;
    }
}
