//! The lobe fit's linear part: the coefficients of its three basis functions by non-negative
//! least squares, for a given frame and shape.

/// Non-negative least squares of `y ~ c . x` over three basis functions from their Gram
/// matrix `g`, the products `p` with `y` and `syy = y . y`: the coefficients, the residual
/// sum of squares and the active set: the unconstrained solution where every coefficient is
/// positive, else the best of every active set (seven small solves). Exact, with no iterations.
pub(super) fn nnls3(g: [[f64; 3]; 3], p: [f64; 3], syy: f64) -> Linear {
    let residual = |x: [f64; 3]| {
        let mut r = syy;
        for a in 0..3 {
            r -= 2.0 * x[a] * p[a];
            for b in 0..3 {
                r += x[a] * g[a][b] * x[b];
            }
        }
        r
    };
    // Where every coefficient of the unconstrained solution is positive it is the minimum
    // over every active set (the Gram matrix is positive definite there), and every
    // coefficient is free: the other six solves are skipped. A coefficient at exactly 0 is
    // held there by the search below (its active set says so).
    let full = ActiveSet::of(7).solve(&g, &p).map(|x| (x, residual(x)));
    if let Some((x, r)) = full {
        if x.iter().all(|&v| v > 0.0) && r < syy {
            return Linear {
                coefficients: x,
                cost: r,
                set: 7,
                gram: g,
            };
        }
    }
    let mut best = Linear {
        coefficients: [0.0; 3],
        cost: syy,
        set: 0,
        gram: g,
    };
    // The full set last, as solved above: ties go to the smaller sets.
    let subsets = (1u8..7).filter_map(|set| {
        let x = ActiveSet::of(set).solve(&g, &p)?;
        Some((set, x, residual(x)))
    });
    for (set, x, r) in subsets.chain(full.map(|(x, r)| (7, x, r))) {
        if x.iter().all(|&v| v >= 0.0) && r < best.cost {
            best = Linear {
                coefficients: x,
                cost: r,
                set,
                gram: g,
            };
        }
    }
    best
}

/// The linear part of a fit: the coefficients `[d, s1, s2]`, the residual sum of squares, the
/// active set (bit `k`: coefficient `k` free, the others held at 0) and the Gram matrix.
#[derive(Debug, Clone, Copy)]
pub(super) struct Linear {
    pub(super) coefficients: [f64; 3],
    pub(super) cost: f64,
    pub(super) set: u8,
    pub(super) gram: [[f64; 3]; 3],
}

/// A subset of the three basis functions (bit `k` of the mask: function `k`).
pub(super) struct ActiveSet {
    pub(super) members: [usize; 3],
    pub(super) len: usize,
}

impl ActiveSet {
    pub(super) fn of(mask: u8) -> Self {
        let mut members = [0; 3];
        let mut len = 0;
        for k in 0..3 {
            if mask & (1 << k) != 0 {
                members[len] = k;
                len += 1;
            }
        }
        Self { members, len }
    }

    /// The least-squares coefficients with only the members free (others zero):
    /// [`ActiveSet::inverse`] times the products `p`; `None` where the block is singular.
    pub(super) fn solve(&self, g: &[[f64; 3]; 3], p: &[f64; 3]) -> Option<[f64; 3]> {
        Some(apply(&self.inverse(g)?, p)).filter(|x| x.iter().all(|v| v.is_finite()))
    }

    /// The inverse of the members' block of the (symmetric) Gram matrix `g`, zero outside it,
    /// from its adjugate and one division: the Gauss-Newton system applies it to seven vectors
    /// at every iteration. `None` where the block is singular (its determinant at most 1e-12
    /// of its diagonal's product).
    pub(super) fn inverse(&self, g: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
        let mut inv = [[0.0; 3]; 3];
        match self.members[..self.len] {
            [a] => {
                if g[a][a] <= 0.0 {
                    return None;
                }
                inv[a][a] = 1.0 / g[a][a];
            }
            [a, b] => {
                let det = g[a][a] * g[b][b] - g[a][b] * g[a][b];
                if det <= 1e-12 * g[a][a] * g[b][b] {
                    return None;
                }
                let r = 1.0 / det;
                inv[a][a] = g[b][b] * r;
                inv[b][b] = g[a][a] * r;
                inv[a][b] = -g[a][b] * r;
                inv[b][a] = inv[a][b];
            }
            [_, _, _] => {
                // The cofactors of the symmetric matrix (its adjugate's upper triangle).
                let c00 = g[1][1] * g[2][2] - g[1][2] * g[1][2];
                let c01 = g[0][2] * g[1][2] - g[0][1] * g[2][2];
                let c02 = g[0][1] * g[1][2] - g[0][2] * g[1][1];
                let c11 = g[0][0] * g[2][2] - g[0][2] * g[0][2];
                let c12 = g[0][1] * g[0][2] - g[0][0] * g[1][2];
                let c22 = g[0][0] * g[1][1] - g[0][1] * g[0][1];
                let det = g[0][0] * c00 + g[0][1] * c01 + g[0][2] * c02;
                if det <= 1e-12 * g[0][0] * g[1][1] * g[2][2] {
                    return None;
                }
                let r = 1.0 / det;
                inv = [
                    [c00 * r, c01 * r, c02 * r],
                    [c01 * r, c11 * r, c12 * r],
                    [c02 * r, c12 * r, c22 * r],
                ];
            }
            _ => return None,
        }
        Some(inv)
    }
}

/// `m u` for a 3 x 3 matrix.
pub(super) fn apply(m: &[[f64; 3]; 3], u: &[f64; 3]) -> [f64; 3] {
    m.map(|row| row[0] * u[0] + row[1] * u[1] + row[2] * u[2])
}
