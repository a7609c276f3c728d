//! The lobe fit's search: Levenberg-Marquardt from each start, and the starts tried on a subset.

use super::kernel::Subset;
use super::linalg::{damping_floor, solve_spd};
use super::linear::Linear;
use super::{
    normal_equations, project, shape_bounds, trim_shadows, Buffers, LobeStart, Model, State,
    FORESHORTENING_FLOOR, MAX_ITERATIONS, MICROFACET, P, RETRY_RESIDUAL,
};

/// Whether a gain in the sum of squares is too small to go on for: below [`RELATIVE_GAIN`] of
/// the cost, or [`ABSOLUTE_GAIN`] of the samples' energy `syy`.
pub(super) fn negligible(gain: f64, cost: f64, syy: f64, relative: f64) -> bool {
    gain <= relative * cost || gain <= ABSOLUTE_GAIN * syy
}

/// The search stops once a step gains less than this share of the cost...
pub(super) const RELATIVE_GAIN: f64 = 1e-4;

/// The search on a coarse subset stops at this share instead: the polish on the whole subset
/// settles the rest, and at a tenth of this the maps stay the same (docs/performance.md, "The
/// default estimator with the lobe fit", "Fewer passes").
pub(super) const COARSE_RELATIVE_GAIN: f64 = 1e-2;

/// ...or of the samples' energy: a floor much above this stops near-mirror lobes early
/// (docs/performance.md, "Fewer passes").
pub(super) const ABSOLUTE_GAIN: f64 = 1e-12;

/// The gain in the sum of squares the Gauss-Newton model predicts for its undamped step
/// (`(J^T J + floor I) s = rhs`, gain `s . rhs`); `None` where the system is singular.
pub(super) fn undamped_gain(jtj: &[[f64; P]; P], rhs: &[f64; P], floor: f64) -> Option<f64> {
    let mut m = *jtj;
    for (a, row) in m.iter_mut().enumerate() {
        row[a] += floor;
    }
    let step = solve_spd(m, *rhs)?;
    Some(step.iter().zip(rhs).map(|(s, r)| s * r).sum())
}

/// Levenberg-Marquardt from `state` (whose linear part over `samples` is `known`, where the
/// caller has it: one pass fewer) over the parameters marked `free`; returns the state, its
/// linear part (the sum of squares and the coefficients) and the passes over the samples.
/// `buffers` are work buffers (fitted to `samples`).
pub(super) fn levenberg_marquardt(
    samples: &Subset,
    mut state: State,
    known: Option<Linear>,
    free: [bool; P],
    relative: f64,
    buffers: &mut Buffers,
) -> (State, Linear, u32) {
    let Buffers {
        lobe,
        kept,
        jtj: last,
        ..
    } = buffers;
    let syy = samples.energy();
    let mut model = Model::of(&state);
    let mut evals = known.is_none() as u32;
    let mut linear = known.unwrap_or_else(|| project(&model, samples, lobe, kept));
    let mut lambda = 1e-3;
    for _ in 0..MAX_ITERATIONS {
        let (mut jtj, mut rhs) = normal_equations(&model, &linear, free, samples, kept);
        evals += 1;
        // A shape coordinate at a bound that the descent pushes further out is held there this
        // iteration (a projected step), so the others' step does not count on it moving.
        for k in 0..4 {
            let (lo, hi) = shape_bounds(k);
            let i = 3 + k;
            if (state.shape[k] <= lo && rhs[i] < 0.0) || (state.shape[k] >= hi && rhs[i] > 0.0) {
                rhs[i] = 0.0;
                jtj[i] = [0.0; P];
                for row in jtj.iter_mut() {
                    row[i] = 0.0;
                }
            }
        }
        *last = jtj;
        // A floor on the damping: a parameter the data does not constrain (the tangent angle of
        // a round lobe, a width at its bound) must not make the system singular.
        let floor = damping_floor(&jtj);
        // Converged where even the undamped Gauss-Newton step would gain too little: no trial
        // pass is spent finding that out (docs/performance.md, "Fewer passes").
        if undamped_gain(&jtj, &rhs, floor)
            .is_some_and(|g| negligible(g, linear.cost, syy, relative))
        {
            break;
        }
        let mut improved = false;
        for _ in 0..10 {
            let mut m = jtj;
            for (a, row) in m.iter_mut().enumerate() {
                row[a] += lambda * jtj[a][a] + floor;
            }
            let Some(step) = solve_spd(m, rhs) else {
                lambda *= 10.0;
                continue;
            };
            let trial = state.moved(&step);
            let trial_model = Model::of(&trial);
            evals += 1;
            if trial_model.normal.z <= 0.0 {
                lambda *= 4.0;
                continue;
            }
            let trial_linear = project(&trial_model, samples, lobe, kept);
            if trial_linear.cost < linear.cost {
                let gain = linear.cost - trial_linear.cost;
                (state, model, linear) = (trial, trial_model, trial_linear);
                lambda = (lambda / 3.0).max(1e-9);
                improved = !negligible(gain, linear.cost, syy, relative);
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    (state, linear, evals)
}

/// The search on one subset: Levenberg-Marquardt from each start in turn until one explains
/// the samples well, cast shadows trimmed and the fit repeated once without them, then the
/// foreshortening freed where the microfacet lobe leaves a residual. Returns the state, the
/// parameters that were free in it, its linear part over `data` as it is left, and the passes
/// over the samples.
pub(super) fn search_subset(
    data: &mut Subset,
    starts: &[LobeStart],
    relative: f64,
    noise: f64,
    buffers: &mut Buffers,
) -> Option<(State, [bool; P], Linear, u32)> {
    buffers.fit(data);
    let syy = data.energy();
    let mut evals = 0;
    let mut best: Option<(State, Linear)> = None;
    for (k, s) in starts.iter().enumerate() {
        if k > 0 && best.is_some_and(|b| b.1.cost <= (RETRY_RESIDUAL * syy).max(noise)) {
            break;
        }
        let (state, linear, e) =
            levenberg_marquardt(data, State::new(s), None, MICROFACET, relative, buffers);
        evals += e;
        if best.is_none_or(|b| linear.cost < b.1.cost) {
            best = Some((state, linear));
        }
    }
    let (mut state, mut linear) = best?;
    let mut syy = syy;
    if trim_shadows(data, &Model::of(&state), buffers)?.0 > 0 {
        syy = data.energy();
        buffers.fit(data);
        let (refit, refit_linear, e) =
            levenberg_marquardt(data, state, None, MICROFACET, relative, buffers);
        evals += e;
        (state, linear) = (refit, refit_linear);
    }
    // A lobe that is not a microfacet one (Ward's, Phong's) leaves a foreshortening the model
    // above lacks: free `m` (from the microfacet answer), and keep it where it explains more.
    let mut free = MICROFACET;
    if linear.cost > (FORESHORTENING_FLOOR * syy).max(noise) {
        let (free_m, linear_m, e) =
            levenberg_marquardt(data, state, Some(linear), [true; P], relative, buffers);
        evals += e;
        if linear_m.cost < linear.cost {
            (state, free, linear) = (free_m, [true; P], linear_m);
        }
    }
    Some((state, free, linear, evals))
}
