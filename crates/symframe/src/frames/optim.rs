//! Nelder-Mead simplex minimisation in `N` dimensions, allocation-free.
//!
//! Written by hand (not `argmin`): the per-pixel optimisation runs millions of times, and
//! argmin's Nelder-Mead allocates on every iteration, which costs more than a cheap objective
//! (docs/performance.md, "Where the time went").

/// Stopping rules for [`nelder_mead`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct NelderMeadOptions {
    /// Maximum number of objective evaluations.
    pub max_evals: u32,
    /// Stop when every vertex is within this distance of the best one (parameter units).
    pub x_tolerance: f64,
    /// ... and the spread of values is below this.
    pub f_tolerance: f64,
}

impl Default for NelderMeadOptions {
    fn default() -> Self {
        Self {
            max_evals: 200,
            x_tolerance: 1e-5,
            f_tolerance: 1e-12,
        }
    }
}

/// The result of a minimisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Minimum<const N: usize> {
    /// The best point found.
    pub x: [f64; N],
    /// The objective there.
    pub value: f64,
    /// Objective evaluations used.
    pub evals: u32,
}

/// Minimises `f` from `x0` with an initial simplex of axis steps `step` (standard coefficients:
/// reflection 1, expansion 2, contraction 1/2, shrink 1/2).
pub(crate) fn nelder_mead<const N: usize, F>(
    mut f: F,
    x0: [f64; N],
    step: [f64; N],
    options: NelderMeadOptions,
) -> Minimum<N>
where
    F: FnMut(&[f64; N]) -> f64,
{
    // N + 1 vertices; const generic expressions are unstable, so keep N + 1 in a fixed array
    // of size N with the extra vertex separate.
    let mut evals = 0u32;
    let mut eval = |x: &[f64; N], evals: &mut u32| {
        *evals += 1;
        let v = f(x);
        if v.is_nan() {
            f64::INFINITY
        } else {
            v
        }
    };
    let mut pts = [[0.0f64; N]; 8];
    let mut vals = [0.0f64; 8];
    assert!(N < pts.len(), "nelder_mead supports up to 7 dimensions");
    pts[0] = x0;
    vals[0] = eval(&x0, &mut evals);
    for i in 0..N {
        let mut p = x0;
        p[i] += step[i];
        pts[i + 1] = p;
        vals[i + 1] = eval(&p, &mut evals);
    }
    let m = N + 1;
    loop {
        // Order the vertices by value (insertion sort: N + 1 is tiny).
        for i in 1..m {
            let mut j = i;
            while j > 0 && vals[j] < vals[j - 1] {
                vals.swap(j, j - 1);
                pts.swap(j, j - 1);
                j -= 1;
            }
        }
        let spread_x = (1..m)
            .map(|i| {
                (0..N)
                    .map(|k| (pts[i][k] - pts[0][k]).abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        let spread_f = vals[N] - vals[0];
        if evals >= options.max_evals
            || (spread_x <= options.x_tolerance && spread_f <= options.f_tolerance.max(0.0))
            || spread_x <= options.x_tolerance * 1e-3
        {
            break;
        }
        // Centroid of all but the worst.
        let mut c = [0.0f64; N];
        for p in pts.iter().take(N) {
            for k in 0..N {
                c[k] += p[k] / N as f64;
            }
        }
        let along = |t: f64| -> [f64; N] {
            let mut r = [0.0; N];
            for k in 0..N {
                r[k] = c[k] + t * (pts[N][k] - c[k]);
            }
            r
        };
        let xr = along(-1.0);
        let fr = eval(&xr, &mut evals);
        if fr < vals[0] {
            let xe = along(-2.0);
            let fe = eval(&xe, &mut evals);
            if fe < fr {
                pts[N] = xe;
                vals[N] = fe;
            } else {
                pts[N] = xr;
                vals[N] = fr;
            }
            continue;
        }
        if fr < vals[N - 1] {
            pts[N] = xr;
            vals[N] = fr;
            continue;
        }
        // Contraction, outside or inside.
        let (xc, fc) = if fr < vals[N] {
            let x = along(-0.5);
            let v = eval(&x, &mut evals);
            (x, v)
        } else {
            let x = along(0.5);
            let v = eval(&x, &mut evals);
            (x, v)
        };
        if fc < vals[N].min(fr) {
            pts[N] = xc;
            vals[N] = fc;
            continue;
        }
        // Shrink toward the best vertex.
        let best = pts[0];
        for i in 1..m {
            for (x, b) in pts[i].iter_mut().zip(best) {
                *x = b + 0.5 * (*x - b);
            }
            let p = pts[i];
            vals[i] = eval(&p, &mut evals);
        }
    }
    Minimum {
        x: pts[0],
        value: vals[0],
        evals,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_minimum_of_rosenbrock() {
        let r = nelder_mead(
            |x: &[f64; 2]| (1.0 - x[0]).powi(2) + 100.0 * (x[1] - x[0] * x[0]).powi(2),
            [-1.2, 1.0],
            [0.5, 0.5],
            NelderMeadOptions {
                max_evals: 2000,
                x_tolerance: 1e-8,
                f_tolerance: 1e-16,
            },
        );
        assert!(
            (r.x[0] - 1.0).abs() < 1e-4 && (r.x[1] - 1.0).abs() < 1e-4,
            "{r:?}"
        );
    }

    #[test]
    fn one_dimensional_quadratic_and_budget() {
        let r = nelder_mead(
            |x: &[f64; 1]| (x[0] - 0.3).powi(2),
            [0.0],
            [0.1],
            NelderMeadOptions::default(),
        );
        assert!((r.x[0] - 0.3).abs() < 1e-5, "{r:?}");
        let r = nelder_mead(
            |x: &[f64; 2]| x[0].abs() + x[1].abs(),
            [5.0, 5.0],
            [0.01, 0.01],
            NelderMeadOptions {
                max_evals: 20,
                ..Default::default()
            },
        );
        assert!(r.evals <= 22, "stops near the budget: {}", r.evals);
    }

    #[test]
    fn nan_is_treated_as_infinitely_bad() {
        let r = nelder_mead(
            |x: &[f64; 2]| {
                if x[0] < 0.0 {
                    f64::NAN
                } else {
                    (x[0] - 1.0).powi(2) + x[1] * x[1]
                }
            },
            [0.5, 0.5],
            [0.2, 0.2],
            NelderMeadOptions::default(),
        );
        assert!((r.x[0] - 1.0).abs() < 1e-4 && r.x[1].abs() < 1e-4);
    }
}
