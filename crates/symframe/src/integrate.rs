//! Normal integration: a height map (and a mesh) from a normal map, orthographic camera.
//!
//! Conventions: pixel `(col, row)`, row 0 at the top; the camera frame has x = right, y = up,
//! z = toward the camera. Heights are along +z in units of the pixel spacing, so a normal
//! `n = (nx, ny, nz)` asks for the slopes `dz/dcol = -nx / nz` and `dz/drow = +ny / nz` (rows
//! run down, against y).
//!
//! Both solvers minimise the same least-squares energy over one-sided differences (Cao et al.,
//! *Bilateral Normal Integration*, ECCV 2022, orthographic form), each term multiplied by `nz`
//! so that grazing normals (`nz -> 0`, infinite slopes) do not dominate:
//!
//! ```text
//! E(z) = sum_i c_i sum_{d in {u+, u-, v+, v-}} w_i^d (nz_i D_d z_i + s_d n_i)^2
//! ```
//!
//! with `c_i` the pixel's confidence weight, `D_d` the forward or backward difference toward a
//! neighbour inside the mask and `s_d n_i` the matching normal component.
//!
//! - [`Solver::Poisson`]: fixed weights 1/2 per side (1 where only one side is in the mask). One
//!   sparse linear solve: the normal equations are a weighted 5-point Laplacian, solved by
//!   conjugate gradients preconditioned with a multigrid V-cycle (red-black Gauss-Seidel
//!   smoothing, 2 x 2 aggregation with Galerkin coarse operators), warm-started coarse to fine
//!   (the map halved until it is small, each level's solution the next one's start). About 40
//!   iterations at 1024 x 1024, seconds in all; written here rather than taken from a sparse
//!   crate because the grid structure makes the operator five arrays and the multigrid
//!   preconditioner (which a general sparse solver would not give) is what makes it fast.
//!   Smooth everywhere: a depth jump is smeared into a slope.
//! - [`Solver::Bilateral`]: the weights of the two sides follow the current surface,
//!   `w^+ = sigmoid(k ((nz D_- z)^2 - (nz D_+ z)^2))`, `w^- = 1 - w^+`, re-solved
//!   (iteratively reweighted least squares, each solve warm-started) until the energy settles:
//!   across a depth discontinuity the side that jumps loses its weight, so the surface may
//!   break there (a jump is only found where the normals on both sides disagree with a
//!   continuous surface, e.g. a step whose height varies along it).
//!
//! Heights are defined up to one offset per connected region of the mask; each region's lowest
//! point is set to 0.

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::regions::{label_regions, OUTSIDE};

/// Which solver [`integrate`] runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Solver {
    /// Least squares with fixed weights (a screened-free Poisson problem on the mask).
    Poisson,
    /// Bilateral normal integration (Cao et al. 2022): discontinuity-preserving.
    Bilateral {
        /// Sharpness of the side weights' sigmoid (the paper's k; 2 by default).
        k: f64,
        /// Reweighting iterations at most.
        max_iterations: usize,
        /// Stop when the energy's relative change falls below this.
        tolerance: f64,
    },
}

impl Solver {
    /// The bilateral solver with k = 10, up to 100 iterations, stopping when the energy changes
    /// by less than 1e-4. (The paper's k = 2 assumes depths in other units: with heights in
    /// pixels, started from the Poisson surface, k = 2 leaves a step of a few pixels smeared;
    /// k = 10 recovers both sides of it to 0.02 px RMS in the unit test.)
    pub fn bilateral() -> Self {
        Solver::Bilateral {
            k: 10.0,
            max_iterations: 100,
            tolerance: 1e-4,
        }
    }
}

/// Parameters of [`integrate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegrateParams {
    /// The solver.
    pub solver: Solver,
    /// Conjugate gradients stop when the residual's norm is below this fraction of the
    /// right-hand side's.
    pub cg_tolerance: f64,
    /// Conjugate-gradient iterations per linear solve at most.
    pub cg_max_iterations: usize,
    /// Confidence weights below this are raised to it (so a low-confidence pixel still joins
    /// its neighbours); 1 ignores the confidence.
    pub min_weight: f64,
}

impl Default for IntegrateParams {
    fn default() -> Self {
        Self {
            solver: Solver::Poisson,
            cg_tolerance: 1e-7,
            cg_max_iterations: 20_000,
            min_weight: 0.05,
        }
    }
}

/// A height map and how it was reached.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Heights toward the camera in pixel units, row-major, NaN outside the mask.
    pub depth: Vec<f32>,
    /// Conjugate-gradient iterations over all solves and levels.
    pub cg_iterations: usize,
    /// Bilateral reweighting iterations (0 for Poisson).
    pub reweight_iterations: usize,
    /// Final energy `E(z)` per pixel.
    pub energy: f64,
    /// Connected regions of the mask (each with its own offset).
    pub regions: usize,
    /// Pixels integrated.
    pub pixels: usize,
}

/// The normal map one level works on: normals (unit, NaN outside), weights, mask.
struct Level {
    w: usize,
    h: usize,
    mask: Vec<bool>,
    /// `(nx, ny, nz)` per pixel, `nz` at least a small positive number inside the mask.
    n: Vec<[f64; 3]>,
    /// Confidence weight per pixel.
    c: Vec<f64>,
}

impl Level {
    fn from_maps(
        w: usize,
        h: usize,
        normals: &[f32],
        confidence: Option<&[f32]>,
        min_weight: f64,
    ) -> Self {
        let mut mask = vec![false; w * h];
        let mut n = vec![[0.0; 3]; w * h];
        let mut c = vec![0.0; w * h];
        for i in 0..w * h {
            let v = &normals[3 * i..3 * i + 3];
            if v.iter().all(|x| x.is_finite()) {
                let (x, y, z) = (v[0] as f64, v[1] as f64, v[2] as f64);
                let len = (x * x + y * y + z * z).sqrt();
                if len > 0.0 && z > -0.5 * len {
                    mask[i] = true;
                    // Normals facing away (estimation noise at the rim) are laid on the rim.
                    let z = (z / len).max(1e-3);
                    let s = ((1.0 - z * z).max(0.0) / ((x * x + y * y) / (len * len)).max(1e-300))
                        .sqrt()
                        / len;
                    n[i] = [x * s, y * s, z];
                    let conf = confidence
                        .map(|cf| cf[i] as f64)
                        .filter(|v| v.is_finite())
                        .unwrap_or(1.0);
                    c[i] = conf.clamp(min_weight.min(1.0), 1.0);
                }
            }
        }
        Self { w, h, mask, n, c }
    }

    /// The level at half the resolution: a coarse pixel covers 2 x 2 fine ones, is in the mask
    /// when any of them is, and takes their mean normal and weight.
    fn halve(&self) -> Self {
        let (w, h) = (self.w.div_ceil(2), self.h.div_ceil(2));
        let mut mask = vec![false; w * h];
        let mut n = vec![[0.0; 3]; w * h];
        let mut c = vec![0.0; w * h];
        for r in 0..h {
            for q in 0..w {
                let (mut s, mut cs, mut k) = ([0.0; 3], 0.0, 0);
                for (dr, dq) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    let (fr, fq) = (2 * r + dr, 2 * q + dq);
                    if fr < self.h && fq < self.w && self.mask[fr * self.w + fq] {
                        let f = fr * self.w + fq;
                        for (acc, v) in s.iter_mut().zip(self.n[f]) {
                            *acc += v;
                        }
                        cs += self.c[f];
                        k += 1;
                    }
                }
                if k > 0 {
                    let len = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
                    let i = r * w + q;
                    if len > 0.0 {
                        mask[i] = true;
                        n[i] = [s[0] / len, s[1] / len, (s[2] / len).max(1e-3)];
                        c[i] = cs / k as f64;
                    }
                }
            }
        }
        Self { w, h, mask, n, c }
    }
}

/// The normal equations of the energy for given side weights: couplings to the right and
/// lower neighbour, their `c g` sums, the diagonal and the right-hand side.
struct System {
    w: usize,
    h: usize,
    /// Coupling between pixel i and i + 1.
    cr: Vec<f64>,
    /// Coupling between pixel i and i + w.
    cd: Vec<f64>,
    diag: Vec<f64>,
    b: Vec<f64>,
}

/// The weights of the forward (+) sides, per pixel, for u (columns) and v (rows).
struct SideWeights {
    u: Vec<f64>,
    v: Vec<f64>,
}

impl SideWeights {
    fn half(n: usize) -> Self {
        Self {
            u: vec![0.5; n],
            v: vec![0.5; n],
        }
    }
}

/// The one-sided terms of pixel `i`: for each of u+, u-, v+, v-, the neighbour (if in the
/// mask), the term's weight, and the target of `z_nb - z_i` (forward) or `z_i - z_nb`
/// (backward) scaled by nz: `nz * diff = t`.
fn side_weight(wplus: f64, has_plus: bool, has_minus: bool) -> (f64, f64) {
    match (has_plus, has_minus) {
        (true, true) => (wplus, 1.0 - wplus),
        (true, false) => (1.0, 0.0),
        (false, true) => (0.0, 1.0),
        (false, false) => (0.0, 0.0),
    }
}

impl Level {
    fn has(&self, r: isize, q: isize) -> bool {
        r >= 0
            && q >= 0
            && (r as usize) < self.h
            && (q as usize) < self.w
            && self.mask[r as usize * self.w + q as usize]
    }

    /// Per pixel: (weight of u+, u-, v+, v-) times the confidence.
    fn term_weights(&self, sw: &SideWeights, i: usize) -> [f64; 4] {
        let (r, q) = ((i / self.w) as isize, (i % self.w) as isize);
        let (up, um) = side_weight(sw.u[i], self.has(r, q + 1), self.has(r, q - 1));
        let (vp, vm) = side_weight(sw.v[i], self.has(r + 1, q), self.has(r - 1, q));
        let c = self.c[i];
        [c * up, c * um, c * vp, c * vm]
    }

    /// Assembles the normal equations. A term `a (nz (z_j - z_i) - t)^2` couples i and j with
    /// `a nz^2` and adds `a nz t` to `b_j`, subtracts it from `b_i`. Targets: u direction
    /// `t = -nx`, v direction (rows down) `t = +ny`.
    fn system(&self, sw: &SideWeights) -> System {
        let (w, h) = (self.w, self.h);
        let n = w * h;
        let weights: Vec<[f64; 4]> = (0..n)
            .into_par_iter()
            .map(|i| {
                if self.mask[i] {
                    self.term_weights(sw, i)
                } else {
                    [0.0; 4]
                }
            })
            .collect();
        // Pair (i, i+1): forward term of i, backward term of i+1.
        let pair = |i: usize, j: usize, fw: f64, bw: f64, target: fn(&[f64; 3]) -> f64| {
            let (ni, nj) = (&self.n[i], &self.n[j]);
            let c = fw * ni[2] * ni[2] + bw * nj[2] * nj[2];
            let cg = fw * ni[2] * target(ni) + bw * nj[2] * target(nj);
            (c, cg)
        };
        let tu = |v: &[f64; 3]| -v[0];
        let tv = |v: &[f64; 3]| v[1];
        let (cr, gr): (Vec<f64>, Vec<f64>) = (0..n)
            .into_par_iter()
            .map(|i| {
                if (i % w) + 1 < w && self.mask[i] && self.mask[i + 1] {
                    pair(i, i + 1, weights[i][0], weights[i + 1][1], tu)
                } else {
                    (0.0, 0.0)
                }
            })
            .unzip();
        let (cd, gd): (Vec<f64>, Vec<f64>) = (0..n)
            .into_par_iter()
            .map(|i| {
                if i / w + 1 < h && self.mask[i] && self.mask[i + w] {
                    pair(i, i + w, weights[i][2], weights[i + w][3], tv)
                } else {
                    (0.0, 0.0)
                }
            })
            .unzip();
        let (diag, b): (Vec<f64>, Vec<f64>) = (0..n)
            .into_par_iter()
            .map(|i| {
                let (q, r) = (i % w, i / w);
                let mut d = cr[i] + cd[i];
                let mut b = -gr[i] - gd[i];
                if q > 0 {
                    d += cr[i - 1];
                    b += gr[i - 1];
                }
                if r > 0 {
                    d += cd[i - w];
                    b += gd[i - w];
                }
                (d, b)
            })
            .unzip();
        System {
            w,
            h,
            cr,
            cd,
            diag,
            b,
        }
    }

    /// The energy per pixel of `z` under side weights `sw`.
    fn energy(&self, sw: &SideWeights, z: &[f64]) -> f64 {
        let w = self.w;
        let total: f64 = (0..w * self.h)
            .into_par_iter()
            .filter(|&i| self.mask[i])
            .map(|i| {
                let [up, um, vp, vm] = self.term_weights(sw, i);
                let [nx, ny, nz] = self.n[i];
                let mut e = 0.0;
                if up > 0.0 {
                    e += up * (nz * (z[i + 1] - z[i]) + nx).powi(2);
                }
                if um > 0.0 {
                    e += um * (nz * (z[i] - z[i - 1]) + nx).powi(2);
                }
                if vp > 0.0 {
                    e += vp * (nz * (z[i + w] - z[i]) - ny).powi(2);
                }
                if vm > 0.0 {
                    e += vm * (nz * (z[i] - z[i - w]) - ny).powi(2);
                }
                e
            })
            .sum();
        total / self.mask.iter().filter(|&&m| m).count().max(1) as f64
    }

    /// The bilateral side weights of surface `z`.
    fn bilateral_weights(&self, z: &[f64], k: f64) -> SideWeights {
        let w = self.w;
        let sig = |x: f64| 1.0 / (1.0 + (-k * x).exp());
        let (u, v): (Vec<f64>, Vec<f64>) = (0..w * self.h)
            .into_par_iter()
            .map(|i| {
                if !self.mask[i] {
                    return (0.5, 0.5);
                }
                let (r, q) = ((i / w) as isize, (i % w) as isize);
                let nz = self.n[i][2];
                let d = |ok: bool, a: usize, b: usize| if ok { nz * (z[a] - z[b]) } else { 0.0 };
                let up = d(self.has(r, q + 1), i + 1, i);
                let um = d(self.has(r, q - 1), i, i.wrapping_sub(1));
                let vp = d(self.has(r + 1, q), i + w, i);
                let vm = d(self.has(r - 1, q), i, i.wrapping_sub(w));
                (sig(um * um - up * up), sig(vm * vm - vp * vp))
            })
            .unzip();
        SideWeights { u, v }
    }
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
struct Hierarchy {
    levels: Vec<System>,
}

impl Hierarchy {
    fn new(fine: System) -> Self {
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
    fn solve(&self, x: &mut [f64], tolerance: f64, max_iterations: usize) -> usize {
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

/// Solves the fixed-weight problem on `level`, warm-started from the solution of the level at
/// half the resolution while the map is larger than 64 pixels on its shorter side. Returns the
/// heights (pixel units of `level`) and the iterations spent.
fn poisson_pyramid(level: &Level, params: &IntegrateParams) -> (Vec<f64>, usize) {
    let mut z = vec![0.0; level.w * level.h];
    let mut iterations = 0;
    if level.w.min(level.h) > 64 {
        let coarse = level.halve();
        let (zc, it) = poisson_pyramid(&coarse, params);
        iterations += it;
        for (i, v) in z.iter_mut().enumerate() {
            let (r, q) = (i / level.w, i % level.w);
            // Heights are in pixel units: a coarse pixel is two fine ones.
            *v = 2.0 * zc[(r / 2) * coarse.w + q / 2];
        }
    }
    let sys = Hierarchy::new(level.system(&SideWeights::half(level.w * level.h)));
    let it = sys.solve(&mut z, params.cg_tolerance, params.cg_max_iterations);
    iterations += it;
    (z, iterations)
}

/// Integrates a normal map (`H x W x 3`, camera frame, unit vectors, NaN where there is no
/// normal) into heights, weighted by `confidence` (`H x W`, values in [0, 1]) when given.
pub fn integrate(
    width: usize,
    height: usize,
    normals: &[f32],
    confidence: Option<&[f32]>,
    params: &IntegrateParams,
) -> Result<DepthMap> {
    let n = width
        .checked_mul(height)
        .filter(|&n| n > 0)
        .ok_or_else(|| Error::BadParameter(format!("empty {width}x{height} normal map")))?;
    if normals.len() != 3 * n {
        return Err(Error::BadParameter(format!(
            "a {width}x{height} normal map needs {} values, got {}",
            3 * n,
            normals.len()
        )));
    }
    if let Some(c) = confidence {
        if c.len() != n {
            return Err(Error::BadParameter(format!(
                "a {width}x{height} confidence map needs {n} values, got {}",
                c.len()
            )));
        }
    }
    if !(params.cg_tolerance > 0.0 && params.cg_tolerance < 1.0) {
        return Err(Error::BadParameter(format!(
            "the solver tolerance must be in (0, 1), got {}",
            params.cg_tolerance
        )));
    }
    if !(params.min_weight > 0.0 && params.min_weight <= 1.0) {
        return Err(Error::BadParameter(format!(
            "the smallest confidence weight must be in (0, 1], got {}",
            params.min_weight
        )));
    }
    let level = Level::from_maps(width, height, normals, confidence, params.min_weight);
    let pixels = level.mask.iter().filter(|&&m| m).count();
    if pixels == 0 {
        return Err(Error::BadMask("the normal map has no valid normal".into()));
    }
    let (mut z, mut cg_iterations) = poisson_pyramid(&level, params);
    let mut weights = SideWeights::half(n);
    let mut reweight_iterations = 0;
    if let Solver::Bilateral {
        k,
        max_iterations,
        tolerance,
    } = params.solver
    {
        if !(k.is_finite() && k > 0.0) {
            return Err(Error::BadParameter(format!(
                "the bilateral sharpness k must be positive, got {k}"
            )));
        }
        // The reweighting steps solve loosely (each is only a step toward the fixed point);
        // the last system is solved to the full tolerance.
        let inner = params.cg_tolerance.max(1e-4);
        let mut energy = level.energy(&weights, &z);
        let mut sys = None;
        for _ in 0..max_iterations {
            weights = level.bilateral_weights(&z, k);
            let h = Hierarchy::new(level.system(&weights));
            cg_iterations += h.solve(&mut z, inner, params.cg_max_iterations);
            sys = Some(h);
            reweight_iterations += 1;
            let e = level.energy(&weights, &z);
            let change = (e - energy).abs() / energy.max(1e-300);
            energy = e;
            if change < tolerance {
                break;
            }
        }
        if let Some(h) = sys {
            cg_iterations += h.solve(&mut z, params.cg_tolerance, params.cg_max_iterations);
        }
    }
    let energy = level.energy(&weights, &z);
    // One offset per region: its lowest point at 0.
    let (label, sizes) = label_regions(level.w, level.h, |i| level.mask[i]).ok_or_else(|| {
        Error::BadParameter(format!(
            "a {width}x{height} normal map is too large to integrate"
        ))
    })?;
    let mut lowest = vec![f64::INFINITY; sizes.len()];
    for i in 0..n {
        if label[i] != OUTSIDE {
            let l = label[i] as usize;
            lowest[l] = lowest[l].min(z[i]);
        }
    }
    let depth = (0..n)
        .map(|i| {
            if label[i] == OUTSIDE {
                f32::NAN
            } else {
                (z[i] - lowest[label[i] as usize]) as f32
            }
        })
        .collect();
    z.clear();
    Ok(DepthMap {
        width,
        height,
        depth,
        cg_iterations,
        reweight_iterations,
        energy,
        regions: sizes.len(),
        pixels,
    })
}

/// A triangle mesh on the pixel grid.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions `(x, y, z)`: x = column + 0.5, y = height - row - 0.5 (up), z = the
    /// height; pixel units (a perspective mesh, [`crate::near::perspective_mesh`]: the
    /// camera-frame points the pixels see, in the depths' unit).
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals (the normal map's).
    pub normals: Vec<[f32; 3]>,
    /// Pixel `(col, row)` of each vertex.
    pub pixels: Vec<[u32; 2]>,
    /// Triangles, counter-clockwise seen from the camera (+z).
    pub triangles: Vec<[u32; 3]>,
    /// Triangles left out because an edge crossed a depth discontinuity.
    pub dropped: usize,
}

/// Builds a mesh with a vertex at the centre of every pixel with a height and a normal, two
/// triangles per 2 x 2 block (one where only three of its pixels are valid), leaving out any
/// triangle with an edge whose height difference departs from what the normals predict by more
/// than `max_jump * (1 + |predicted|)` pixels (a depth discontinuity).
pub fn mesh(depth: &DepthMap, normals: &[f32], max_jump: f64) -> Mesh {
    let (w, h) = (depth.width, depth.height);
    let mut index = vec![u32::MAX; w * h];
    let mut m = Mesh::default();
    let slope = |i: usize| -> Option<(f64, f64)> {
        let v = &normals[3 * i..3 * i + 3];
        if !v.iter().all(|x| x.is_finite()) {
            return None;
        }
        let nz = (v[2] as f64).max(0.05);
        Some((-(v[0] as f64) / nz, v[1] as f64 / nz))
    };
    for i in 0..w * h {
        let v = &normals[3 * i..3 * i + 3];
        if depth.depth[i].is_finite() && v.iter().all(|x| x.is_finite()) {
            index[i] = m.positions.len() as u32;
            let (r, q) = (i / w, i % w);
            m.positions
                .push([q as f32 + 0.5, (h - r) as f32 - 0.5, depth.depth[i]]);
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-30);
            m.normals.push([v[0] / len, v[1] / len, v[2] / len]);
            m.pixels.push([q as u32, r as u32]);
        }
    }
    // An edge a -> b is continuous when its height step agrees with the mean slope.
    let continuous = |a: usize, b: usize| -> bool {
        let (Some((pa, qa)), Some((pb, qb))) = (slope(a), slope(b)) else {
            return false;
        };
        let dq = (b % w) as f64 - (a % w) as f64;
        let dr = (b / w) as f64 - (a / w) as f64;
        let predicted = 0.5 * (pa + pb) * dq + 0.5 * (qa + qb) * dr;
        let step = depth.depth[b] as f64 - depth.depth[a] as f64;
        (step - predicted).abs() <= max_jump * (1.0 + predicted.abs())
    };
    triangulate_grid(w, h, &index, continuous, &mut m);
    m
}

/// The triangles of a mesh on a `w` x `h` pixel grid whose vertices `index` numbers (`u32::MAX`
/// where a pixel has none): two per 2 x 2 block, one where only three of its pixels have a
/// vertex, counter-clockwise seen from the camera; a triangle with an edge that is not
/// `continuous` (a depth discontinuity) is left out and counted in `m.dropped`.
pub(crate) fn triangulate_grid(
    w: usize,
    h: usize,
    index: &[u32],
    continuous: impl Fn(usize, usize) -> bool,
    m: &mut Mesh,
) {
    let ok = |i: usize| index[i] != u32::MAX;
    for r in 0..h.saturating_sub(1) {
        for q in 0..w.saturating_sub(1) {
            let a = r * w + q; // top left
            let b = a + 1; // top right
            let c = a + w; // bottom left
            let d = c + 1; // bottom right
            let tris: &[[usize; 3]] = match (ok(a), ok(b), ok(c), ok(d)) {
                (true, true, true, true) => &[[a, c, b], [b, c, d]],
                (true, true, true, false) => &[[a, c, b]],
                (false, true, true, true) => &[[b, c, d]],
                (true, false, true, true) => &[[a, c, d]],
                (true, true, false, true) => &[[a, d, b]],
                _ => &[],
            };
            for t in tris {
                if continuous(t[0], t[1]) && continuous(t[1], t[2]) && continuous(t[2], t[0]) {
                    m.triangles.push(t.map(|i| index[i]));
                } else {
                    m.dropped += 1;
                }
            }
        }
    }
}

/// Shades a height map for a picture: Lambertian under a light from the upper left
/// (`(-1, 1, 2)` normalised), 0.15 ambient, values in [0, 1], NaN outside.
pub fn shade(depth: &DepthMap) -> Vec<f32> {
    let (w, h) = (depth.width, depth.height);
    let z = &depth.depth;
    let l = {
        let v = [-1.0f64, 1.0, 2.0];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    };
    (0..w * h)
        .map(|i| {
            if !z[i].is_finite() {
                return f32::NAN;
            }
            let (r, q) = (i / w, i % w);
            let at = |rr: usize, qq: usize| z[rr * w + qq];
            // Central differences where both sides exist, one-sided otherwise.
            let diff = |a: Option<f32>, b: Option<f32>, c: f32| -> f64 {
                match (a.filter(|v| v.is_finite()), b.filter(|v| v.is_finite())) {
                    (Some(a), Some(b)) => (b as f64 - a as f64) / 2.0,
                    (Some(a), None) => c as f64 - a as f64,
                    (None, Some(b)) => b as f64 - c as f64,
                    (None, None) => 0.0,
                }
            };
            let dzdq = diff(
                (q > 0).then(|| at(r, q - 1)),
                (q + 1 < w).then(|| at(r, q + 1)),
                z[i],
            );
            let dzdr = diff(
                (r > 0).then(|| at(r - 1, q)),
                (r + 1 < h).then(|| at(r + 1, q)),
                z[i],
            );
            // n = (-dz/dx, -dz/dy, 1) with y = -row.
            let (nx, ny, nz) = (-dzdq, dzdr, 1.0);
            let len = (nx * nx + ny * ny + nz * nz).sqrt();
            let d = ((nx * l[0] + ny * l[1] + nz * l[2]) / len).max(0.0);
            (0.15 + 0.85 * d) as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Normals of a height field given by its gradient function `(dz/dcol, dz/drow)`.
    fn normals_of(w: usize, h: usize, grad: impl Fn(f64, f64) -> (f64, f64)) -> Vec<f32> {
        let mut out = Vec::with_capacity(3 * w * h);
        for r in 0..h {
            for q in 0..w {
                let (gq, gr) = grad(q as f64, r as f64);
                let (nx, ny, nz) = (-gq, gr, 1.0);
                let len = (nx * nx + ny * ny + nz * nz).sqrt();
                out.extend([(nx / len) as f32, (ny / len) as f32, (nz / len) as f32]);
            }
        }
        out
    }

    /// RMS of `a - b - mean(a - b)` over pixels where `keep`.
    fn rms_after_offset(a: &[f32], b: &[f64], keep: impl Fn(usize) -> bool) -> f64 {
        let idx: Vec<usize> = (0..b.len()).filter(|&i| keep(i)).collect();
        let mean = idx.iter().map(|&i| a[i] as f64 - b[i]).sum::<f64>() / idx.len() as f64;
        (idx.iter()
            .map(|&i| (a[i] as f64 - b[i] - mean).powi(2))
            .sum::<f64>()
            / idx.len() as f64)
            .sqrt()
    }

    fn sphere(size: usize) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
        let rad = size as f64 / 2.0;
        let mut n = vec![f32::NAN; 3 * size * size];
        let mut z = vec![f64::NAN; size * size];
        let mut cos = vec![0.0; size * size];
        for r in 0..size {
            for q in 0..size {
                let x = (q as f64 + 0.5 - rad) / rad;
                let y = -(r as f64 + 0.5 - rad) / rad;
                let rr = x * x + y * y;
                if rr < 1.0 {
                    let i = r * size + q;
                    let nz = (1.0 - rr).sqrt();
                    n[3 * i..3 * i + 3].copy_from_slice(&[x as f32, y as f32, nz as f32]);
                    z[i] = rad * nz;
                    cos[i] = nz;
                }
            }
        }
        (n, z, cos)
    }

    #[test]
    fn both_solvers_recover_a_sphere() {
        let size = 128;
        let (n, truth, cos) = sphere(size);
        let within_60 = |i: usize| cos[i] >= 0.5;
        for solver in [Solver::Poisson, Solver::bilateral()] {
            let params = IntegrateParams {
                solver,
                ..IntegrateParams::default()
            };
            let d = integrate(size, size, &n, None, &params).unwrap();
            assert_eq!(d.regions, 1);
            let rms = rms_after_offset(&d.depth, &truth, within_60);
            // Radius 64 px: 1% is 0.64.
            assert!(rms < 0.005 * 64.0, "{solver:?}: rms {rms}");
            assert!(d.depth.iter().all(|v| v.is_nan() || *v >= 0.0));
        }
    }

    #[test]
    fn a_plane_is_exact_and_regions_get_their_own_offset() {
        let (w, h) = (40, 30);
        let mut n = normals_of(w, h, |_, _| (0.3, -0.2));
        // A gap column splits the map into two regions.
        for r in 0..h {
            n[3 * (r * w + 20)..3 * (r * w + 20) + 3].fill(f32::NAN);
        }
        let d = integrate(w, h, &n, None, &IntegrateParams::default()).unwrap();
        assert_eq!(d.regions, 2);
        assert_eq!(d.pixels, w * h - h);
        for r in 0..h {
            for q in 0..w {
                let i = r * w + q;
                if q == 20 {
                    assert!(d.depth[i].is_nan());
                    continue;
                }
                // Each region's lowest point (top right of it, since z rises to the right and
                // falls downward... z = 0.3 q - 0.2 r) is 0.
                let q0 = if q < 20 { 0.0 } else { 21.0 };
                let want = 0.3 * (q as f64 - q0) - 0.2 * (r as f64 - (h - 1) as f64);
                assert!((d.depth[i] as f64 - want).abs() < 1e-3, "{q},{r}");
            }
        }
    }

    /// Bumps on two planes that meet at a step whose height grows down the image: no surface
    /// fits the normals on both sides, so Poisson bends, bilateral integration breaks.
    fn step_scene(size: usize) -> (Vec<f32>, Vec<f64>) {
        let s = size as f64;
        let bump = |q: f64, r: f64, cq: f64, cr: f64, a: f64| {
            let sg = s * 0.08;
            let e = (-((q - cq).powi(2) + (r - cr).powi(2)) / (2.0 * sg * sg)).exp();
            (
                a * e,
                -a * e * (q - cq) / (sg * sg),
                -a * e * (r - cr) / (sg * sg),
            )
        };
        let field = |q: f64, r: f64| -> (f64, f64, f64) {
            let (b1, b1q, b1r) = bump(q, r, 0.3 * s, 0.5 * s, 6.0);
            let (b2, b2q, b2r) = bump(q, r, 0.75 * s, 0.4 * s, -5.0);
            if q < s / 2.0 {
                // Left: a plane rising toward the bottom (0.25 per row).
                (0.25 * r + b1 + b2, b1q + b2q, 0.25 + b1r + b2r)
            } else {
                (b1 + b2, b1q + b2q, b1r + b2r)
            }
        };
        let n = normals_of(size, size, |q, r| {
            let (_, gq, gr) = field(q, r);
            (gq, gr)
        });
        let z = (0..size * size)
            .map(|i| field((i % size) as f64, (i / size) as f64).0)
            .collect();
        (n, z)
    }

    #[test]
    fn bilateral_keeps_a_discontinuity_that_poisson_smears() {
        let size = 96;
        let (n, truth) = step_scene(size);
        let poisson = integrate(size, size, &n, None, &IntegrateParams::default()).unwrap();
        let bini = integrate(
            size,
            size,
            &n,
            None,
            &IntegrateParams {
                solver: Solver::bilateral(),
                ..IntegrateParams::default()
            },
        )
        .unwrap();
        // Across a discontinuity the relative offset of the two sides is not observable: each
        // side is compared with its own offset.
        let side = |d: &DepthMap| {
            let left = rms_after_offset(&d.depth, &truth, |i| i % size < size / 2);
            let right = rms_after_offset(&d.depth, &truth, |i| i % size >= size / 2);
            left.max(right)
        };
        let (e_p, e_b) = (side(&poisson), side(&bini));
        // The step reaches 24 px at the bottom.
        assert!(e_p > 1.5, "poisson rms {e_p}");
        assert!(e_b < 0.05, "bilateral rms {e_b} (poisson {e_p})");
        // The mesh of the bilateral surface breaks at the step, and keeps
        // no triangle across a jump of more than 3 pixels (the jump of the solution: its sides'
        // relative offset is its own).
        let m = mesh(&bini, &n, 2.0);
        assert!(m.dropped >= size / 2, "{} dropped", m.dropped);
        let mut kept = 0;
        for r in 0..size - 1 {
            for q in 0..size - 1 {
                let i = r * size + q;
                let jump = (bini.depth[i + 1] - bini.depth[i]).abs();
                if q == size / 2 - 1 && jump > 3.0 {
                    kept += 1;
                }
            }
        }
        let bridging = m
            .triangles
            .iter()
            .filter(|t| {
                let cols: Vec<u32> = t.iter().map(|&v| m.pixels[v as usize][0]).collect();
                let zs: Vec<f32> = t.iter().map(|&v| m.positions[v as usize][2]).collect();
                let spread = zs.iter().cloned().fold(f32::MIN, f32::max)
                    - zs.iter().cloned().fold(f32::MAX, f32::min);
                cols.contains(&(size as u32 / 2 - 1))
                    && cols.contains(&(size as u32 / 2))
                    && spread > 4.0
            })
            .count();
        assert!(
            kept > 0 && bridging == 0,
            "{kept} jumps, {bridging} bridging"
        );
        let full = 2 * (size - 1) * (size - 1);
        assert_eq!(m.triangles.len() + m.dropped, full);
        // The smooth Poisson surface keeps every triangle of a full grid.
        let mp = mesh(&poisson, &n, 2.0);
        assert_eq!(mp.triangles.len() + mp.dropped, 2 * (size - 1) * (size - 1));
    }

    #[test]
    fn confidence_weights_the_fit() {
        // A plane with a patch of wrong normals: with zero-ish confidence on the patch the
        // plane around it is unharmed.
        let size = 48;
        let mut n = normals_of(size, size, |_, _| (0.2, 0.1));
        let mut conf = vec![1.0f32; size * size];
        for r in 20..28 {
            for q in 20..28 {
                let i = r * size + q;
                n[3 * i..3 * i + 3].copy_from_slice(&[0.6, 0.0, 0.8]);
                conf[i] = 0.0;
            }
        }
        let truth: Vec<f64> = (0..size * size)
            .map(|i| 0.2 * (i % size) as f64 + 0.1 * (i / size) as f64)
            .collect();
        let outside = |i: usize| {
            let (r, q) = (i / size, i % size);
            !(16..32).contains(&r) || !(16..32).contains(&q)
        };
        let p = IntegrateParams {
            min_weight: 1e-4,
            ..IntegrateParams::default()
        };
        let weighted = integrate(size, size, &n, Some(&conf), &p).unwrap();
        let plain = integrate(size, size, &n, None, &p).unwrap();
        let ew = rms_after_offset(&weighted.depth, &truth, outside);
        let ep = rms_after_offset(&plain.depth, &truth, outside);
        assert!(ew < 0.2 * ep && ew < 0.05, "weighted {ew}, plain {ep}");
    }

    #[test]
    fn bad_input_is_an_error() {
        let p = IntegrateParams::default();
        assert!(integrate(2, 2, &[0.0; 11], None, &p).is_err());
        assert!(integrate(2, 2, &[f32::NAN; 12], None, &p).is_err());
        assert!(integrate(0, 2, &[], None, &p).is_err());
        let n = [0.0, 0.0, 1.0].repeat(4);
        assert!(integrate(2, 2, &n, Some(&[1.0; 3]), &p).is_err());
        let bad = IntegrateParams {
            cg_tolerance: 0.0,
            ..p
        };
        assert!(integrate(2, 2, &n, None, &bad).is_err());
    }

    #[test]
    fn mesh_triangles_face_the_camera_and_shading_is_bounded() {
        let (n, _, _) = sphere(32);
        let d = integrate(32, 32, &n, None, &IntegrateParams::default()).unwrap();
        let m = mesh(&d, &n, 2.0);
        assert_eq!(m.positions.len(), d.pixels);
        assert!(!m.triangles.is_empty());
        for t in &m.triangles {
            let [a, b, c] = t.map(|v| m.positions[v as usize]);
            let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            assert!(cross > 0.0);
        }
        let s = shade(&d);
        assert!(s
            .iter()
            .zip(&d.depth)
            .all(|(s, z)| s.is_nan() == z.is_nan() && (s.is_nan() || (0.0..=1.0).contains(s))));
    }
}
