//! The least-squares energy of one level of the normal map: its normals, confidence weights
//! and mask, the one-sided terms' weights (fixed halves or the bilateral ones), the energy of a
//! height map and the normal equations the multigrid solver takes.

use rayon::prelude::*;

use super::multigrid::System;

/// The normal map one level works on: normals (unit, NaN outside), weights, mask.
pub(super) struct Level {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) mask: Vec<bool>,
    /// `(nx, ny, nz)` per pixel, `nz` at least a small positive number inside the mask.
    n: Vec<[f64; 3]>,
    /// Confidence weight per pixel.
    c: Vec<f64>,
}

impl Level {
    pub(super) fn from_maps(
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
    pub(super) fn halve(&self) -> Self {
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

/// The weights of the forward (+) sides, per pixel, for u (columns) and v (rows).
pub(super) struct SideWeights {
    u: Vec<f64>,
    v: Vec<f64>,
}

impl SideWeights {
    pub(super) fn half(n: usize) -> Self {
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
    pub(super) fn system(&self, sw: &SideWeights) -> System {
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
    pub(super) fn energy(&self, sw: &SideWeights, z: &[f64]) -> f64 {
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
    pub(super) fn bilateral_weights(&self, z: &[f64], k: f64) -> SideWeights {
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
