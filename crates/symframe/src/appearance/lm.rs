//! The Levenberg-Marquardt search of the variable-projection fits with three nonlinear
//! parameters ([`super::gltf_fit`], [`super::lobe_fit`]): the reduced residuals' Jacobian by
//! forward differences, steps projected on box bounds, a parameter at a bound whose descent
//! direction points out held for the step. Each model brings its residuals and its solve of
//! the damped normal equations; the Ward fit ([`super::ward_fit`]) has its own search (two
//! parameters, analytic derivatives).

/// Three nonlinear parameters.
pub(crate) type P = [f64; 3];

/// The box the parameters live in and which of them the search moves.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bounds {
    /// Lower bounds.
    pub lo: P,
    /// Upper bounds.
    pub hi: P,
    /// The parameters searched; the others stay at their start.
    pub free: [bool; 3],
}

impl Bounds {
    /// `p` with each entry clamped to its bounds.
    pub(crate) fn clamp(&self, p: P) -> P {
        std::array::from_fn(|j| p[j].clamp(self.lo[j], self.hi[j]))
    }
}

/// Per-thread buffers: the residuals at the current point and at the difference points.
#[derive(Debug, Clone, Default)]
pub(crate) struct Residuals {
    r: Vec<f64>,
    rj: [Vec<f64>; 3],
}

/// Levenberg-Marquardt from `start` (within `bounds`), at most `max_iterations` iterations;
/// returns the point reached and the iterations run. `eval(p, out)` is the cost at `p`, with
/// `out` the residuals written there; `step(jtj, g, active, lambda, p)` the next point (before
/// clamping) from the damped normal equations of the `active` parameters, `None` where they are
/// singular. One search for both models, so that their stopping rules stay the same.
pub(crate) fn minimise(
    start: P,
    bounds: &Bounds,
    max_iterations: u32,
    res: &mut Residuals,
    mut eval: impl FnMut(P, Option<&mut Vec<f64>>) -> f64,
    mut step: impl FnMut(&[[f64; 3]; 3], &[f64; 3], [bool; 3], f64, P) -> Option<P>,
) -> (P, u32) {
    let Bounds { lo, hi, free } = *bounds;
    let mut p = start;
    let mut cur = eval(p, Some(&mut res.r));
    let mut lambda = 1e-3;
    let mut iterations = 0;
    'outer: while iterations < max_iterations {
        iterations += 1;
        // Jacobian columns by forward differences (toward the inside at an upper bound).
        let mut jtj = [[0.0f64; 3]; 3];
        let mut g = [0.0f64; 3];
        for j in (0..3).filter(|&j| free[j]) {
            let mut q = p;
            let h = 1e-6 * if p[j] + 1e-6 > hi[j] { -1.0 } else { 1.0 };
            q[j] += h;
            let (rj, r0) = (&mut res.rj[j], &res.r);
            eval(q, Some(rj));
            for (a, b) in rj.iter_mut().zip(r0) {
                *a = (*a - b) / h;
            }
        }
        for j in (0..3).filter(|&j| free[j]) {
            for k in (j..3).filter(|&k| free[k]) {
                let s: f64 = res.rj[j].iter().zip(&res.rj[k]).map(|(a, b)| a * b).sum();
                jtj[j][k] = s;
                jtj[k][j] = s;
            }
            g[j] = res.rj[j].iter().zip(&res.r).map(|(a, b)| a * b).sum();
        }
        // Parameters at a bound whose descent direction points out are held.
        let active: [bool; 3] = std::array::from_fn(|j| {
            free[j] && !((p[j] <= lo[j] && g[j] > 0.0) || (p[j] >= hi[j] && g[j] < 0.0))
        });
        if !active.iter().any(|&f| f) {
            break;
        }
        loop {
            let Some(q) = step(&jtj, &g, active, lambda, p) else {
                lambda *= 10.0;
                if lambda > 1e12 {
                    break 'outer;
                }
                continue;
            };
            let q = bounds.clamp(q);
            let moved = (0..3).map(|j| (q[j] - p[j]).abs()).fold(0.0, f64::max);
            if !moved.is_finite() || moved < 1e-10 {
                break 'outer;
            }
            let next = eval(q, None);
            if next < cur {
                let gain = cur - next;
                p = q;
                cur = eval(p, Some(&mut res.r));
                lambda = (lambda / 3.0).max(1e-9);
                if moved < 1e-8 || gain <= 1e-15 * cur.max(1e-300) {
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
    (p, iterations)
}
