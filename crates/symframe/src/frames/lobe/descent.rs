//! The Levenberg-Marquardt loop one lobe and two share: the damping, the trial steps and when to
//! stop. Each fit supplies its normal equations and how a step is tried ([`Descent`]).

use super::linalg::{damping_floor, solve_spd};
use super::MAX_ITERATIONS;

/// A least-squares fit Levenberg-Marquardt descends, over `N` nonlinear parameters (the linear
/// ones solved at every point: variable projection).
pub(super) trait Descent<const N: usize> {
    /// A point of the search (the frame and the shape).
    type Point: Copy;
    /// A point's linear part: its coefficients and sum of squares.
    type Linear: Copy;

    /// Whether the search stops where even the undamped Gauss-Newton step would gain too
    /// little, before any trial pass is spent (docs/performance.md, "Fewer passes").
    const STOPS_UNDAMPED: bool;

    /// The sum of squares of a linear part.
    fn cost(linear: &Self::Linear) -> f64;

    /// `J^T J` and `J^T r` at `point` (one pass over the samples), the coordinates at a bound
    /// the descent pushes further out held there ([`hold_at_bound`]).
    fn normal_equations(
        &mut self,
        point: &Self::Point,
        linear: &Self::Linear,
    ) -> ([[f64; N]; N], [f64; N]);

    /// The point `step` leads to from `point` and its linear part, `None` where the step turns
    /// the normal away from the view; the passes over the samples it takes added to `passes`.
    fn try_step(
        &mut self,
        point: &Self::Point,
        step: &[f64; N],
        passes: &mut u32,
    ) -> Option<(Self::Point, Self::Linear)>;

    /// The point [`Descent::try_step`] returned last is the search's from now on.
    fn keep(&mut self);
}

/// A step gaining less than this share of the samples' energy ends the search, whatever the
/// relative gain asked: a floor much above this stops near-mirror lobes early
/// (docs/performance.md, "Fewer passes").
const ABSOLUTE_GAIN: f64 = 1e-12;

/// The gain in the sum of squares the Gauss-Newton model predicts for its undamped step
/// (`(J^T J + floor I) s = rhs`, gain `s . rhs`); `None` where the system is singular.
fn undamped_gain<const N: usize>(jtj: &[[f64; N]; N], rhs: &[f64; N], floor: f64) -> Option<f64> {
    let mut m = *jtj;
    for (a, row) in m.iter_mut().enumerate() {
        row[a] += floor;
    }
    let step = solve_spd(m, *rhs)?;
    Some(step.iter().zip(rhs).map(|(s, r)| s * r).sum())
}

/// Whether a gain in the sum of squares is too small to go on for: below `relative` of the
/// cost, or [`ABSOLUTE_GAIN`] of the samples' energy `syy`.
fn negligible(gain: f64, cost: f64, syy: f64, relative: f64) -> bool {
    gain <= relative * cost || gain <= ABSOLUTE_GAIN * syy
}

/// Levenberg-Marquardt from `point` (its linear part `linear`, `evals` passes spent so far)
/// until a step gains less than `relative` of the cost or [`ABSOLUTE_GAIN`] of
/// the samples' energy `syy`: the point, its linear part and the passes.
pub(super) fn descend<const N: usize, D: Descent<N>>(
    fit: &mut D,
    mut point: D::Point,
    mut linear: D::Linear,
    syy: f64,
    relative: f64,
    mut evals: u32,
) -> (D::Point, D::Linear, u32) {
    let mut lambda = 1e-3;
    for _ in 0..MAX_ITERATIONS {
        let (jtj, rhs) = fit.normal_equations(&point, &linear);
        evals += 1;
        // A floor on the damping: a parameter the data does not constrain (the tangent angle of
        // a round lobe, a width at its bound) must not make the system singular.
        let floor = damping_floor(&jtj);
        if D::STOPS_UNDAMPED
            && undamped_gain(&jtj, &rhs, floor)
                .is_some_and(|g| negligible(g, D::cost(&linear), syy, relative))
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
            let Some((trial, trial_linear)) = fit.try_step(&point, &step, &mut evals) else {
                lambda *= 4.0;
                continue;
            };
            if D::cost(&trial_linear) < D::cost(&linear) {
                let gain = D::cost(&linear) - D::cost(&trial_linear);
                fit.keep();
                (point, linear) = (trial, trial_linear);
                lambda = (lambda / 3.0).max(1e-9);
                improved = !negligible(gain, D::cost(&linear), syy, relative);
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    (point, linear, evals)
}

/// Holds coordinate `i` of value `v` this iteration where it is at a bound of `(lo, hi)` and the
/// descent pushes it further out (a projected step): its row and column of `jtj` and its `rhs`
/// zeroed, so that the others' step does not count on it moving.
pub(super) fn hold_at_bound<const N: usize>(
    jtj: &mut [[f64; N]; N],
    rhs: &mut [f64; N],
    i: usize,
    v: f64,
    (lo, hi): (f64, f64),
) {
    if (v <= lo && rhs[i] < 0.0) || (v >= hi && rhs[i] > 0.0) {
        rhs[i] = 0.0;
        jtj[i] = [0.0; N];
        for row in jtj.iter_mut() {
            row[i] = 0.0;
        }
    }
}
