//! The sparse solve of the normal equations: the five-array operator on the pixel grid and its
//! multigrid hierarchy (2 x 2 aggregation, Galerkin coarse operators, red-black Gauss-Seidel
//! smoothing), used as the preconditioner of conjugate gradients.

use rayon::prelude::*;

/// The normal equations of the energy for given side weights: couplings to the right and
/// lower neighbour, their `c g` sums, the diagonal and the right-hand side.
pub(super) struct System {
    pub(super) w: usize,
    pub(super) h: usize,
    /// Coupling between pixel i and i + 1.
    pub(super) cr: Vec<f64>,
    /// Coupling between pixel i and i + w.
    pub(super) cd: Vec<f64>,
    pub(super) diag: Vec<f64>,
    pub(super) b: Vec<f64>,
}

impl System {
    /// `y = A x`.
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let (w, h) = (self.w, self.h);
        y.par_chunks_mut(w).enumerate().for_each(|(r, row)| {
            for (q, out) in row.iter_mut().enumerate() {
                let i = r * w + q;
                let mut v = self.diag[i] * x[i];
                if q + 1 < w {
                    v -= self.cr[i] * x[i + 1];
                }
                if q > 0 {
                    v -= self.cr[i - 1] * x[i - 1];
                }
                if r + 1 < h {
                    v -= self.cd[i] * x[i + w];
                }
                if r > 0 {
                    v -= self.cd[i - w] * x[i - w];
                }
                *out = v;
            }
        });
    }

    /// The operator on 2 x 2 aggregates of pixels (Galerkin product with piecewise-constant
    /// interpolation: couplings between aggregates are the sums of the fine couplings between
    /// them).
    fn coarsen(&self) -> System {
        let (w, h) = (self.w, self.h);
        let (wc, hc) = (w.div_ceil(2), h.div_ceil(2));
        let mut cr = vec![0.0; wc * hc];
        let mut cd = vec![0.0; wc * hc];
        for r in 0..h {
            for q in 0..w {
                let i = r * w + q;
                let ic = (r / 2) * wc + q / 2;
                if q % 2 == 1 && q + 1 < w {
                    cr[ic] += self.cr[i];
                }
                if r % 2 == 1 && r + 1 < h {
                    cd[ic] += self.cd[i];
                }
            }
        }
        let diag = (0..wc * hc)
            .map(|i| {
                let (r, q) = (i / wc, i % wc);
                let mut d = cr[i] + cd[i];
                if q > 0 {
                    d += cr[i - 1];
                }
                if r > 0 {
                    d += cd[i - wc];
                }
                d
            })
            .collect();
        System {
            w: wc,
            h: hc,
            cr,
            cd,
            diag,
            b: Vec::new(),
        }
    }

    /// One red-black Gauss-Seidel half sweep over the pixels of `colour` ((row + col) % 2).
    fn gauss_seidel(&self, colour: usize, b: &[f64], x: &mut [f64], tmp: &mut Vec<f64>) {
        let (w, h) = (self.w, self.h);
        tmp.resize(x.len(), 0.0);
        let xs: &[f64] = x;
        tmp.par_chunks_mut(w).enumerate().for_each(|(r, row)| {
            for (q, out) in row.iter_mut().enumerate() {
                let i = r * w + q;
                if (r + q) % 2 != colour || self.diag[i] <= 0.0 {
                    *out = xs[i];
                    continue;
                }
                let mut v = b[i];
                if q + 1 < w {
                    v += self.cr[i] * xs[i + 1];
                }
                if q > 0 {
                    v += self.cr[i - 1] * xs[i - 1];
                }
                if r + 1 < h {
                    v += self.cd[i] * xs[i + w];
                }
                if r > 0 {
                    v += self.cd[i - w] * xs[i - w];
                }
                *out = v / self.diag[i];
            }
        });
        x.copy_from_slice(tmp);
    }
}

/// A multigrid hierarchy: the operator on pixels, then on 2 x 2 aggregates of the level
/// above, down to a few hundred unknowns.
pub(super) struct Hierarchy {
    levels: Vec<System>,
}

impl Hierarchy {
    pub(super) fn new(fine: System) -> Self {
        let mut levels = vec![fine];
        while levels.last().is_some_and(|l| l.w.min(l.h) > 8) {
            let c = levels.last().map(System::coarsen);
            levels.extend(c);
        }
        Self { levels }
    }

    /// One symmetric V-cycle from zero for `A x = b` at level `k` (two red-black Gauss-Seidel
    /// sweeps before, the same in reverse order after, the coarsest level by many sweeps):
    /// a symmetric positive (semi-)definite preconditioner.
    fn vcycle(&self, k: usize, b: &[f64]) -> Vec<f64> {
        let a = &self.levels[k];
        let n = a.w * a.h;
        let mut x = vec![0.0; n];
        let mut tmp = Vec::new();
        if k + 1 == self.levels.len() {
            for _ in 0..50 {
                a.gauss_seidel(0, b, &mut x, &mut tmp);
                a.gauss_seidel(1, b, &mut x, &mut tmp);
            }
            for _ in 0..50 {
                a.gauss_seidel(1, b, &mut x, &mut tmp);
                a.gauss_seidel(0, b, &mut x, &mut tmp);
            }
            return x;
        }
        for _ in 0..2 {
            a.gauss_seidel(0, b, &mut x, &mut tmp);
            a.gauss_seidel(1, b, &mut x, &mut tmp);
        }
        let mut ax = vec![0.0; n];
        a.apply(&x, &mut ax);
        let c = &self.levels[k + 1];
        let mut rc = vec![0.0; c.w * c.h];
        for i in 0..n {
            let (r, q) = (i / a.w, i % a.w);
            rc[(r / 2) * c.w + q / 2] += b[i] - ax[i];
        }
        let ec = self.vcycle(k + 1, &rc);
        x.par_chunks_mut(a.w).enumerate().for_each(|(r, row)| {
            for (q, v) in row.iter_mut().enumerate() {
                *v += ec[(r / 2) * c.w + q / 2];
            }
        });
        for _ in 0..2 {
            a.gauss_seidel(1, b, &mut x, &mut tmp);
            a.gauss_seidel(0, b, &mut x, &mut tmp);
        }
        x
    }

    /// Solves `A x = b` (the finest level's right-hand side) by conjugate gradients
    /// preconditioned with [`Hierarchy::vcycle`], from `x`; returns the iterations. The system
    /// is singular (a constant per region) but consistent, so the iterates converge; pixels
    /// without couplings keep their value.
    pub(super) fn solve(&self, x: &mut [f64], tolerance: f64, max_iterations: usize) -> usize {
        let a = &self.levels[0];
        let n = x.len();
        let dot = |u: &[f64], v: &[f64]| -> f64 {
            u.par_chunks(4096)
                .zip(v.par_chunks(4096))
                .map(|(u, v)| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>())
                .sum()
        };
        let bnorm = dot(&a.b, &a.b).sqrt();
        if bnorm == 0.0 {
            return 0;
        }
        let mut r = vec![0.0; n];
        a.apply(x, &mut r);
        r.par_iter_mut()
            .zip(&a.b)
            .zip(&a.diag)
            .for_each(|((r, b), d)| *r = if *d > 0.0 { b - *r } else { 0.0 });
        let mut zv = self.vcycle(0, &r);
        let mut p = zv.clone();
        let mut rz = dot(&r, &zv);
        let mut ap = vec![0.0; n];
        let mut it = 0;
        while it < max_iterations && dot(&r, &r).sqrt() > tolerance * bnorm {
            a.apply(&p, &mut ap);
            let pap = dot(&p, &ap);
            if pap <= 0.0 || rz <= 0.0 {
                break;
            }
            let alpha = rz / pap;
            x.par_iter_mut().zip(&p).for_each(|(x, p)| *x += alpha * p);
            r.par_iter_mut()
                .zip(&ap)
                .for_each(|(r, ap)| *r -= alpha * ap);
            zv = self.vcycle(0, &r);
            let rz_new = dot(&r, &zv);
            let beta = rz_new / rz;
            rz = rz_new;
            p.par_iter_mut()
                .zip(&zv)
                .for_each(|(p, z)| *p = z + beta * *p);
            it += 1;
        }
        it
    }
}
