//! Small dense solves and the normal's uncertainty from a Gauss-Newton system.

use super::subset::Subset;
use super::{normal_equations, project, Buffers, Model, P};

/// Solves `a x = b` for a symmetric positive definite `a`; `None` if it is not.
pub(super) fn solve_spd<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    (ldl_solve(&mut a, &mut b, N, |_| 0.0) && b.iter().all(|v| v.is_finite())).then_some(b)
}

/// Solves `a x = b` over the leading `n` x `n` block of `a` by `L D L^T`, in place (`b`
/// becomes `x`, `a` below its diagonal `L`); false where the `j`-th pivot `D[j]` is NaN or at
/// most `floor(j)` (the block is not positive definite, or too near singular). The two-lobe
/// fit's active-set solves share it. No square roots, one reciprocal per pivot: the
/// Levenberg-Marquardt loop solves two or three of these per iteration, each pivot waiting on
/// the one before, so their latency is the solve's time.
// Index loops: the triangular recurrences read clearer as the textbook's indices.
#[allow(clippy::needless_range_loop)]
pub(super) fn ldl_solve<const N: usize>(
    a: &mut [[f64; N]; N],
    b: &mut [f64; N],
    n: usize,
    floor: impl Fn(usize) -> f64,
) -> bool {
    // `diagonal` holds `D`, `inv` its reciprocals.
    let mut diagonal = [0.0; N];
    let mut inv = [0.0; N];
    let mut scaled = [0.0; N];
    for j in 0..n {
        // `scaled[k] = L[j][k] D[k]`, shared by the pivot and the column below it.
        let mut d = a[j][j];
        for k in 0..j {
            scaled[k] = a[j][k] * diagonal[k];
            d -= a[j][k] * scaled[k];
        }
        if d.is_nan() || d <= floor(j) {
            return false;
        }
        diagonal[j] = d;
        inv[j] = 1.0 / d;
        for i in j + 1..n {
            let mut v = a[i][j];
            for k in 0..j {
                v -= a[i][k] * scaled[k];
            }
            a[i][j] = v * inv[j];
        }
    }
    for i in 0..n {
        for k in 0..i {
            b[i] -= a[i][k] * b[k];
        }
    }
    for i in (0..n).rev() {
        b[i] *= inv[i];
        for k in i + 1..n {
            b[i] -= a[k][i] * b[k];
        }
    }
    true
}

/// The standard deviation (radians) of the normal a least-squares fit leaves: the covariance
/// `s^2 (J^T J)^-1` of its two tilts (the rotations about `t` and `b`, the first two
/// parameters) summed, with `s^2 = cost / dof` the samples' scatter about the fit per degree
/// of freedom, whatever its cause (noise, quantisation, light errors, misfit). Infinite where
/// the samples do not determine the normal (docs/method.md, "Confidence").
pub(super) fn tilt_sd<const N: usize>(jtj: &[[f64; N]; N], cost: f64, dof: f64) -> f64 {
    if dof < 1.0 || !cost.is_finite() {
        return f64::INFINITY;
    }
    // A parameter the data do not constrain (the tangent angle of a round lobe, a width at
    // its bound) is held by the same floor the search's damping has.
    let a = floored(jtj);
    let variance = |k: usize| {
        let mut e = [0.0; N];
        e[k] = 1.0;
        solve_spd(a, e).map(|x| x[k]).filter(|v| *v >= 0.0)
    };
    match (variance(0), variance(1)) {
        (Some(v0), Some(v1)) => (cost.max(0.0) / dof * (v0 + v1)).sqrt(),
        _ => f64::INFINITY,
    }
}

/// The floor on a Gauss-Newton system's diagonal that keeps it solvable where a parameter is
/// not constrained (the tangent angle of a round lobe, a width at its bound): a billionth of
/// its trace.
pub(super) fn damping_floor<const N: usize>(jtj: &[[f64; N]; N]) -> f64 {
    1e-9 * (0..N).map(|k| jtj[k][k]).sum::<f64>().max(1e-300)
}

/// `jtj` with [`damping_floor`] added to its diagonal.
pub(super) fn floored<const N: usize>(jtj: &[[f64; N]; N]) -> [[f64; N]; N] {
    let floor = damping_floor(jtj);
    let mut a = *jtj;
    for (k, row) in a.iter_mut().enumerate() {
        row[k] += floor;
    }
    a
}

/// The squared tilt of the normal in one Gauss-Newton step from `m` over `data` (two passes):
/// where `data` are the answer's samples changed a little (half of them, their lights turned),
/// how far the fit would move its normal, to first order. Infinite where the step has no
/// solution.
pub(super) fn tilt_step2(m: &Model, data: &Subset, free: [bool; P], buffers: &mut Buffers) -> f64 {
    buffers.fit(data);
    let Buffers { lobe, kept, .. } = buffers;
    let linear = project(m, data, lobe, kept);
    let (jtj, rhs) = normal_equations(m, &linear, free, data, kept);
    solve_spd(floored(&jtj), rhs).map_or(f64::INFINITY, |d| d[0] * d[0] + d[1] * d[1])
}
