//! The lobe fit's search: Levenberg-Marquardt from each start, and the starts tried on a subset.

use super::descent::{descend, hold_at_bound, Descent};
use super::linear::Linear;
use super::subset::Subset;
use super::{
    normal_equations, project, shape_bounds, trim_shadows, Buffers, LobeStart, Model, State,
    FORESHORTENING_FLOOR, MICROFACET, P, RETRY_RESIDUAL,
};

/// The search stops once a step gains less than this share of the cost (or a tiny share of the
/// samples' energy, `ABSOLUTE_GAIN` in `lobe/descent.rs`).
pub(super) const RELATIVE_GAIN: f64 = 1e-4;

/// The search on a coarse subset stops at this share instead: the polish on the whole subset
/// settles the rest, and at a tenth of this the maps stay the same (docs/performance.md, "The
/// default estimator with the lobe fit", "Fewer passes").
pub(super) const COARSE_RELATIVE_GAIN: f64 = 1e-2;

/// The largest turn of the frame one step of the search may take, in lobe widths (the geometric
/// mean of `a_t` and `a_b`, radians), within [`MAX_TURN_RANGE`]: the step's model is the terms'
/// first-order change with the frame's rotation (`lobe/kernel.rs`), and a turn of several widths
/// leaves the lobe the step was computed on; the damping then needs several trial passes to
/// shrink it, or the step lands in another basin (docs/performance.md, "The frame's turn per
/// step").
const MAX_TURN_WIDTHS: f64 = 2.0;

/// The range of the largest turn, radians.
const MAX_TURN_RANGE: (f64, f64) = (0.05, 1.5);

/// Levenberg-Marquardt from `state` (whose linear part over `samples` is `known`, where the
/// caller has it: one pass fewer) over the parameters marked `free`; returns the state, its
/// linear part (the sum of squares and the coefficients) and the passes over the samples.
/// `buffers` are work buffers (fitted to `samples`).
pub(super) fn levenberg_marquardt(
    samples: &Subset,
    state: State,
    known: Option<Linear>,
    free: [bool; P],
    relative: f64,
    buffers: &mut Buffers,
) -> (State, Linear, u32) {
    let model = Model::of(&state);
    let evals = known.is_none() as u32;
    let linear =
        known.unwrap_or_else(|| project(&model, samples, &mut buffers.lobe, &mut buffers.kept));
    let mut fit = OneLobe {
        samples,
        free,
        model,
        trial: model,
        buffers,
    };
    descend(&mut fit, state, linear, samples.energy(), relative, evals)
}

/// The one-lobe fit as [`descend`] reads it: the samples and the parameters free in it, the
/// model at the search's point and at its last trial, and the work buffers (the last `J^T J`
/// left in `buffers.jtj`).
struct OneLobe<'a> {
    samples: &'a Subset,
    free: [bool; P],
    model: Model,
    trial: Model,
    buffers: &'a mut Buffers,
}

impl Descent<P> for OneLobe<'_> {
    type Point = State;
    type Linear = Linear;
    const STOPS_UNDAMPED: bool = true;

    fn cost(linear: &Linear) -> f64 {
        linear.cost
    }

    fn normal_equations(&mut self, state: &State, linear: &Linear) -> ([[f64; P]; P], [f64; P]) {
        let (mut jtj, mut rhs) = normal_equations(
            &self.model,
            linear,
            self.free,
            self.samples,
            &self.buffers.kept,
        );
        for k in 0..4 {
            hold_at_bound(&mut jtj, &mut rhs, 3 + k, state.shape[k], shape_bounds(k));
        }
        self.buffers.jtj = jtj;
        (jtj, rhs)
    }

    fn try_step(
        &mut self,
        state: &State,
        step: &[f64; P],
        passes: &mut u32,
    ) -> Option<(State, Linear)> {
        // The Gauss-Newton model is linear in the frame's rotation: a step that turns the frame
        // by more than a few lobe widths is shortened along its direction to that turn.
        let turn = (step[0] * step[0] + step[1] * step[1] + step[2] * step[2]).sqrt();
        let max_turn =
            (MAX_TURN_WIDTHS * self.model.alpha2.sqrt()).clamp(MAX_TURN_RANGE.0, MAX_TURN_RANGE.1);
        let step = &if turn > max_turn {
            step.map(|v| v * (max_turn / turn))
        } else {
            *step
        };
        let trial = state.moved(step);
        self.trial = Model::of(&trial);
        *passes += 1;
        if self.trial.normal.z <= 0.0 {
            return None;
        }
        let Buffers { lobe, kept, .. } = &mut *self.buffers;
        Some((trial, project(&self.trial, self.samples, lobe, kept)))
    }

    fn keep(&mut self) {
        self.model = self.trial;
    }
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
