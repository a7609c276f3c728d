//! The lobe fit's loops over the samples: the sums the linear solve, the residuals and the
//! Gauss-Newton system need, block by block of [`LANES`] samples.
//!
//! Written by hand for speed: the fit is most of the estimator's time on dense rigs
//! (docs/performance.md, "The default estimator with the lobe fit").
//! The samples are stored as columns ([`Subset`]) (one array per coordinate, padded to whole blocks with
//! empty samples of weight 0), and every block's terms are branch-free arithmetic on
//! [`LANES`] lanes ([`F64x16`]), so they run as vector instructions (the Gauss-Newton loop's
//! running sums by fused multiply-adds); the block loops are compiled three times, for AVX-512F
//! or AVX2 with FMA where the processor has them and for the baseline, with the same operations
//! in the same order (identical results).

#[cfg(target_arch = "x86_64")]
use super::lanes::{Avx2, Avx512};
use super::lanes::{F64x16, Lanes, LANES};

/// The builds of the sample loops: the same operations in the same order (identical results),
/// compiled for the baseline, for AVX2 with FMA and for AVX-512F.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Backend {
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Backend {
    /// The fastest build this processor runs.
    pub(super) fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                return Backend::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Backend::Avx2;
            }
        }
        Backend::Baseline
    }

    /// Every build this processor runs (the tests compare them).
    #[cfg(test)]
    fn available() -> Vec<Self> {
        let mut all = vec![Backend::Baseline];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                all.push(Backend::Avx2);
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                all.push(Backend::Avx512);
            }
        }
        all
    }
}
use super::subset::Subset;
use super::{Model, P};

/// The model's constants as the loops read them.
#[derive(Clone, Copy)]
struct Frame {
    n: [f64; 3],
    t: [f64; 3],
    b: [f64; 3],
    inv_a2: [f64; 2],
    alpha2: f64,
    shape: f64,
    foreshortening: f64,
}

impl Frame {
    /// The constants' bits: equal bits, equal terms.
    fn bits(&self) -> [u64; 14] {
        let mut v = [0.0; 14];
        v[..3].copy_from_slice(&self.n);
        v[3..6].copy_from_slice(&self.t);
        v[6..9].copy_from_slice(&self.b);
        v[9..11].copy_from_slice(&self.inv_a2);
        v[11] = self.alpha2;
        v[12] = self.shape;
        v[13] = self.foreshortening;
        v.map(f64::to_bits)
    }

    fn of(m: &Model) -> Self {
        Self {
            n: m.normal.to_array(),
            t: m.t.to_array(),
            b: m.b.to_array(),
            inv_a2: m.inv_a2,
            alpha2: m.alpha2,
            shape: m.shape,
            foreshortening: m.foreshortening,
        }
    }
}

/// A block's terms: the diffuse basis `a = (n.l)+`, the lobe `L`, and (used by the
/// Gauss-Newton loop only; the other loops let the compiler drop them) the derivatives of
/// `a` with respect to the frame's rotations about `t` and `b`, and of `ln L` with respect to
/// the seven parameters (the frame's rotations about `t`, `b`, `n`, then `ln a_t`, `ln a_b`,
/// `ln k`, `m`).
struct Terms<V> {
    a: V,
    lobe: V,
    d_a: [V; 2],
    d_ln_lobe: [V; P],
}

/// The costly part of the terms of the last [`sums`] pass, per sample (with the padding), and
/// what they are of: the Gauss-Newton pass at the same model over the same samples (the
/// Levenberg-Marquardt loop's next pass after an accepted step, most of its passes) reads it
/// instead of computing the divisions, logarithms, root and exponential again, and derives the
/// rest as it would have. The values are the same bits either way.
#[derive(Debug, Clone, Default)]
pub(super) struct Kept {
    /// The samples' identity, the model's constants' bits and whether the foreshortening was
    /// in the terms; `None` until a pass has kept its terms.
    key: Option<(u64, [u64; 14], bool)>,
    /// The fields of [`CachedTerms`], in its order.
    columns: [Vec<f64>; 8],
}

impl Kept {
    /// Whether the terms kept are those at `f` (with the foreshortening's terms where
    /// `foreshortened`) over the samples `s`.
    fn holds(&self, f: &Frame, s: &Subset, foreshortened: bool) -> bool {
        self.key == Some((s.id, f.bits(), foreshortened))
    }

    /// Makes the columns at least as long as the subset's samples with the padding (only
    /// grown, as the lobe fit's other buffers).
    fn fit(&mut self, s: &Subset) {
        for c in &mut self.columns {
            if c.len() < s.padded_len() {
                c.resize(s.padded_len(), 0.0);
            }
        }
    }

    /// Keeps a block's costly part.
    #[inline(always)]
    fn store<V: Lanes>(&mut self, i: usize, c: &CachedTerms<V>) {
        let values = [
            c.inv_hn, c.ln_base, c.ln_nl, c.inv_sum, c.value, c.by_q, c.inv_nl, c.inv_root,
        ];
        for (column, v) in self.columns.iter_mut().zip(values) {
            v.store(&mut column[i..]);
        }
    }

    /// A block's kept costly part.
    #[inline(always)]
    fn load<V: Lanes>(&self, i: usize) -> CachedTerms<V> {
        let [inv_hn, ln_base, ln_nl, inv_sum, value, by_q, inv_nl, inv_root] = &self.columns;
        CachedTerms {
            inv_hn: V::load(inv_hn, i),
            ln_base: V::load(ln_base, i),
            ln_nl: V::load(ln_nl, i),
            inv_sum: V::load(inv_sum, i),
            value: V::load(value, i),
            by_q: V::load(by_q, i),
            inv_nl: V::load(inv_nl, i),
            inv_root: V::load(inv_root, i),
        }
    }
}

#[inline(always)]
fn dot<V: Lanes>(a: [f64; 3], b: [V; 3]) -> V {
    b[0] * a[0] + b[1] * a[1] + b[2] * a[2]
}

/// A block of samples, as the loops read them.
struct Block<V> {
    l: [V; 3],
    h: [V; 3],
    fresnel: V,
    y: V,
    w: V,
}

impl Subset {
    #[inline(always)]
    fn block<V: Lanes>(&self, i: usize) -> Block<V> {
        let load = |c: &Vec<f64>| V::load(c, i);
        Block {
            l: [load(&self.l[0]), load(&self.l[1]), load(&self.l[2])],
            h: [load(&self.h[0]), load(&self.h[1]), load(&self.h[2])],
            fresnel: load(&self.fresnel),
            y: load(&self.y),
            w: load(&self.w),
        }
    }
}

/// The cheap part of a block's terms: the sample's projections on the frame and which samples
/// count (with safe stand-ins where they do not).
struct Geometry<V: Lanes> {
    nl: V,
    hn_s: V,
    ht: V,
    hb: V,
    lt: V,
    lb: V,
    nl_s: V,
    lit: V::Mask,
    lobed: V::Mask,
}

#[inline(always)]
fn geometry<V: Lanes>(f: &Frame, s: &Block<V>) -> Geometry<V> {
    let zero = V::splat(0.0);
    let one = V::splat(1.0);
    let nl = dot(f.n, s.l);
    let (hn, ht, hb) = (dot(f.n, s.h), dot(f.t, s.h), dot(f.b, s.h));
    let (lt, lb) = (dot(f.t, s.l), dot(f.b, s.l));
    let lit = nl.gt(zero) & s.w.gt(zero);
    let lobed = lit & hn.gt(V::splat(1e-3));
    // Safe stand-ins where the sample is unlit (the results are masked out below).
    Geometry {
        nl,
        hn_s: V::select(lobed, hn, one),
        ht,
        hb,
        lt,
        lb,
        nl_s: V::select(lit, nl, one),
        lit,
        lobed,
    }
}

/// The costly part of a block's terms (its divisions, logarithms, root and exponential):
/// what a [`sums`] pass keeps for the Gauss-Newton pass at the same model ([`Kept`]).
#[derive(Clone, Copy)]
struct CachedTerms<V> {
    inv_hn: V,
    ln_base: V,
    ln_nl: V,
    inv_sum: V,
    value: V,
    by_q: V,
    inv_nl: V,
    inv_root: V,
}

/// The slopes `x, y` of the halfway vector in the frame and their quadratic form `qt, qb`.
#[inline(always)]
fn slopes<V: Lanes>(f: &Frame, g: &Geometry<V>, inv_hn: V) -> (V, V, V, V) {
    let (x, y) = (g.ht * inv_hn, g.hb * inv_hn);
    let (qt, qb) = (x * x * f.inv_a2[0], y * y * f.inv_a2[1]);
    (x, y, qt, qb)
}

/// `FORESHORTENED`: whether `m` may be non-zero (with `m = 0` the power of `n.l` is left out).
#[inline(always)]
fn costly<V: Lanes, const FORESHORTENED: bool>(f: &Frame, g: &Geometry<V>) -> CachedTerms<V> {
    let zero = V::splat(0.0);
    let one = V::splat(1.0);
    let nl_s = g.nl_s;
    // Reciprocals shared by the terms: a division costs several multiplications.
    let inv_hn = one / g.hn_s;
    let (_, _, qt, qb) = slopes(f, g, inv_hn);
    let q = qt + qb;
    let base = q * (1.0 / f.shape) + 1.0;
    let ln_base = base.ln();
    let ln_nl = if FORESHORTENED { nl_s.ln() } else { zero };
    let root = (nl_s * nl_s * (1.0 - f.alpha2) + f.alpha2).sqrt();
    let inv_sum = one / (nl_s + root);
    // Smith's masking of the light for a GGX surface of the lobe's mean width: microfacet
    // lobes dim towards grazing lights by this much (the view's factor is the same for all).
    let masking = nl_s * 2.0 * inv_sum;
    let inv_hn2 = inv_hn * inv_hn;
    let ln_power = if FORESHORTENED {
        ln_base * -f.shape + ln_nl * f.foreshortening
    } else {
        ln_base * -f.shape
    };
    CachedTerms {
        inv_hn,
        ln_base,
        ln_nl,
        inv_sum,
        value: ln_power.exp() * masking * (inv_hn2 * inv_hn2),
        by_q: -(one / base),
        inv_nl: one / nl_s,
        inv_root: one / root,
    }
}

/// The terms of a block from its geometry and costly part.
#[inline(always)]
fn finish<V: Lanes, const FORESHORTENED: bool>(
    f: &Frame,
    s_w: V,
    g: &Geometry<V>,
    c: &CachedTerms<V>,
) -> Terms<V> {
    let zero = V::splat(0.0);
    let one = V::splat(1.0);
    let (nl_s, hn_s, ht, hb, lt, lb) = (g.nl_s, g.hn_s, g.ht, g.hb, g.lt, g.lb);
    let (inv_hn, by_q, inv_sum, inv_root) = (c.inv_hn, c.by_q, c.inv_sum, c.inv_root);
    let (x, y, qt, qb) = slopes(f, g, inv_hn);
    let q = qt + qb;
    // d ln L / dq, and d ln L / d(n.l) through the masking and the foreshortening.
    let mut by_nl = c.inv_nl - (nl_s * (1.0 - f.alpha2) * inv_root + 1.0) * inv_sum;
    if FORESHORTENED {
        by_nl = by_nl + c.inv_nl * f.foreshortening;
    }
    // A rotation w = (w_t, w_b, w_n) of the frame moves n by w x n = w_b t - w_t b,
    // t by w_n b - w_b n, and b by w_t n - w_n t.
    let d_nl = [-lb, lt, zero];
    let d_hn = [-hb, ht, zero];
    let d_ht = [zero, -hn_s, hb];
    let d_hb = [hn_s, zero, -ht];
    let mut d = [zero; P];
    for k in 0..3 {
        let dx = (d_ht[k] - x * d_hn[k]) * inv_hn;
        let dy = (d_hb[k] - y * d_hn[k]) * inv_hn;
        let dq = (x * dx * f.inv_a2[0] + y * dy * f.inv_a2[1]) * 2.0;
        d[k] = by_q * dq + by_nl * d_nl[k] - d_hn[k] * inv_hn * 4.0;
    }
    // The masking reads the widths' product: d ln M / d ln a = a_t a_b d ln M / d(a_t a_b).
    let by_width = -((one - nl_s * nl_s) * inv_root * inv_sum) * (0.5 * f.alpha2);
    d[3] = by_q * (qt * -2.0) + by_width;
    d[4] = by_q * (qb * -2.0) + by_width;
    d[5] = (-(q * by_q) * (1.0 / f.shape) - c.ln_base) * f.shape;
    d[6] = c.ln_nl;
    Terms {
        a: V::select(g.lit, g.nl * s_w, zero),
        lobe: V::select(g.lobed, c.value * s_w, zero),
        d_a: [
            V::select(g.lit, -lb * s_w, zero),
            V::select(g.lit, lt * s_w, zero),
        ],
        d_ln_lobe: d,
    }
}

/// The terms of a block; `FORESHORTENED`: whether `m` may be non-zero (with `m = 0` the power
/// of `n.l` is left out).
#[inline(always)]
fn terms<V: Lanes, const FORESHORTENED: bool>(f: &Frame, s: &Block<V>) -> Terms<V> {
    let g = geometry(f, s);
    let c = costly::<V, FORESHORTENED>(f, &g);
    finish::<V, FORESHORTENED>(f, s.w, &g, &c)
}

/// The basis functions' sums over the samples: the Gram matrix of `(a, L, L F)`, their
/// products with the values, and the values' energy.
pub(super) struct Sums {
    pub(super) gram: [[f64; 3]; 3],
    pub(super) products: [f64; 3],
    pub(super) energy: f64,
}

#[inline(always)]
fn sums_kernel<V: Lanes, const M: bool>(
    f: &Frame,
    s: &Subset,
    lobe: &mut [f64],
    kept: &mut Kept,
) -> [f64; 10] {
    let mut acc = [V::splat(0.0); 10];
    for (i, out) in (0..s.padded_len())
        .step_by(LANES)
        .zip(lobe.chunks_exact_mut(LANES))
    {
        let b = s.block::<V>(i);
        let g = geometry(f, &b);
        let costly = costly::<V, M>(f, &g);
        kept.store(i, &costly);
        let t = finish::<V, M>(f, b.w, &g, &costly);
        let (fa, fb, fc, y) = (t.a, t.lobe, t.lobe * b.fresnel, b.y);
        fb.store(out);
        for (slot, v) in acc.iter_mut().zip([
            fa * fa,
            fa * fb,
            fa * fc,
            fb * fb,
            fb * fc,
            fc * fc,
            fa * y,
            fb * y,
            fc * y,
            y * y,
        ]) {
            *slot = *slot + v;
        }
    }
    // Loops, not `map`: a closure would be compiled outside this function's target features.
    let mut out = [0.0; 10];
    for (o, a) in out.iter_mut().zip(acc) {
        *o = a.sum();
    }
    out
}

/// The basis functions' sums at `m` over the samples; the lobe's value per sample into `lobe`
/// (one per sample with the padding); the terms into `kept` for the Gauss-Newton pass.
pub(super) fn sums(m: &Model, s: &Subset, lobe: &mut [f64], kept: &mut Kept) -> Sums {
    sums_with(Backend::detect(), m, s, lobe, kept)
}

/// [`sums`] in the build `backend` (one the processor runs).
fn sums_with(backend: Backend, m: &Model, s: &Subset, lobe: &mut [f64], kept: &mut Kept) -> Sums {
    let f = Frame::of(m);
    let foreshortened = m.foreshortening != 0.0;
    kept.key = None;
    kept.fit(s);
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn avx2<const M: bool>(f: &Frame, s: &Subset, lobe: &mut [f64], k: &mut Kept) -> [f64; 10] {
        sums_kernel::<Avx2, M>(f, s, lobe, k)
    }
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn avx512<const M: bool>(f: &Frame, s: &Subset, lobe: &mut [f64], k: &mut Kept) -> [f64; 10] {
        sums_kernel::<Avx512, M>(f, s, lobe, k)
    }
    let v = match backend {
        Backend::Baseline if foreshortened => sums_kernel::<F64x16, true>(&f, s, lobe, kept),
        Backend::Baseline => sums_kernel::<F64x16, false>(&f, s, lobe, kept),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `backend` is a build the processor runs (`Backend::detect`,
        // `Backend::available`).
        Backend::Avx2 => unsafe {
            if foreshortened {
                avx2::<true>(&f, s, lobe, kept)
            } else {
                avx2::<false>(&f, s, lobe, kept)
            }
        },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above.
        Backend::Avx512 => unsafe {
            if foreshortened {
                avx512::<true>(&f, s, lobe, kept)
            } else {
                avx512::<false>(&f, s, lobe, kept)
            }
        },
    };
    kept.key = Some((s.id, f.bits(), foreshortened));
    Sums {
        gram: [[v[0], v[1], v[2]], [v[1], v[3], v[4]], [v[2], v[4], v[5]]],
        products: [v[6], v[7], v[8]],
        energy: v[9],
    }
}

/// The residuals `y - d a - (s1 + s2 F) L` into `r` from the lobe's values `lobe` (as
/// [`sums`] left them) and the coefficients `c`.
pub(super) fn residuals(m: &Model, s: &Subset, c: [f64; 3], lobe: &[f64], r: &mut [f64]) {
    let n = m.normal.to_array();
    for i in 0..s.padded_len() {
        let nl = n[0] * s.l[0][i] + n[1] * s.l[1][i] + n[2] * s.l[2][i];
        let a = nl.max(0.0) * s.w[i];
        r[i] = s.y[i] - c[0] * a - lobe[i] * (c[1] + c[2] * s.fresnel[i]);
    }
}

/// The Gauss-Newton loop's sums at `m` with coefficients `c`: with `v_i` the derivative of the
/// prediction with respect to parameter `i` (0 unless `free[i]`) and `r` the residual, `v^T v`,
/// `v^T r` and the products `F^T v` of the basis functions `F = (a, L, L F)` with `v`.
pub(super) struct GaussNewton {
    pub(super) vtv: [[f64; P]; P],
    pub(super) vtr: [f64; P],
    pub(super) ftv: [[f64; P]; 3],
}

/// Entries of the upper triangle of `v^T v`.
const TRIANGLE: usize = P * (P + 1) / 2;

/// What [`gauss_newton_kernel`] sums: the triangle of `v^T v`, `v^T r`, `F^T v`.
type GaussNewtonSums = ([f64; TRIANGLE], [f64; P], [[f64; P]; 3]);

#[inline(always)]
fn gauss_newton_kernel<V: Lanes, const M: bool, const KEPT: bool>(
    f: &Frame,
    s: &Subset,
    c: [f64; 3],
    free: [f64; P],
    kept: &Kept,
) -> GaussNewtonSums {
    let zero = V::splat(0.0);
    // Without the foreshortening, its derivative is 0: six parameters.
    let used = if M { P } else { P - 1 };
    let mut vtv = [zero; TRIANGLE];
    let mut vtr = [zero; P];
    let mut ftv = [[zero; P]; 3];
    for i in (0..s.padded_len()).step_by(LANES) {
        let b = s.block::<V>(i);
        let t = if KEPT {
            finish::<V, M>(f, b.w, &geometry(f, &b), &kept.load::<V>(i))
        } else {
            terms::<V, M>(f, &b)
        };
        let (fresnel, y) = (b.fresnel, b.y);
        let lobe = (fresnel * c[2] + c[1]) * t.lobe;
        let mut v = [zero; P];
        for j in 0..used {
            v[j] = lobe * t.d_ln_lobe[j] * free[j];
        }
        v[0] = v[0] + t.d_a[0] * (c[0] * free[0]);
        v[1] = v[1] + t.d_a[1] * (c[0] * free[1]);
        let r = y - t.a * c[0] - lobe;
        let basis = [t.a, t.lobe, t.lobe * fresnel];
        for p in 0..used {
            vtr[p] = v[p].mul_add(r, vtr[p]);
            for q in p..used {
                let e = triangle_index(p, q);
                vtv[e] = v[p].mul_add(v[q], vtv[e]);
            }
        }
        for (row, fb) in ftv.iter_mut().zip(basis) {
            for p in 0..used {
                row[p] = fb.mul_add(v[p], row[p]);
            }
        }
    }
    // Loops, not `map`: a closure would be compiled outside this function's target features.
    let mut sums: GaussNewtonSums = ([0.0; TRIANGLE], [0.0; P], [[0.0; P]; 3]);
    for (o, a) in sums.0.iter_mut().zip(vtv) {
        *o = a.sum();
    }
    for (o, a) in sums.1.iter_mut().zip(vtr) {
        *o = a.sum();
    }
    for (row, acc) in sums.2.iter_mut().zip(ftv) {
        for (o, a) in row.iter_mut().zip(acc) {
            *o = a.sum();
        }
    }
    sums
}

/// The Gauss-Newton loop's sums at `m` with coefficients `c` over the parameters marked
/// `free`, in one pass over the samples.
/// The terms are read from `kept` where they are the last [`sums`] pass's at `m` over `s`.
pub(super) fn gauss_newton(
    m: &Model,
    s: &Subset,
    c: [f64; 3],
    free: [bool; P],
    kept: &Kept,
) -> GaussNewton {
    gauss_newton_with(Backend::detect(), m, s, c, free, kept)
}

/// [`gauss_newton`] in the build `backend` (one the processor runs).
fn gauss_newton_with(
    backend: Backend,
    m: &Model,
    s: &Subset,
    c: [f64; 3],
    free: [bool; P],
    kept: &Kept,
) -> GaussNewton {
    let f = Frame::of(m);
    let foreshortened = m.foreshortening != 0.0 || free[6];
    let reuse = kept.holds(&f, s, foreshortened);
    let on = free.map(|b| if b { 1.0 } else { 0.0 });
    // The kernel compiled for one build: its lanes and (on x86-64) its target features.
    macro_rules! build {
        ($name:ident, $lanes:ty $(, $features:literal)?) => {
            $(#[cfg(target_arch = "x86_64")] #[target_feature(enable = $features)])?
            fn $name<const M: bool, const K: bool>(
                f: &Frame,
                s: &Subset,
                c: [f64; 3],
                on: [f64; P],
                kept: &Kept,
            ) -> GaussNewtonSums {
                gauss_newton_kernel::<$lanes, M, K>(f, s, c, on, kept)
            }
        };
    }
    build!(baseline, F64x16);
    build!(avx2, Avx2, "avx2,fma");
    build!(avx512, Avx512, "avx512f");
    // The build for the foreshortening's presence and for kept terms.
    macro_rules! by_flags {
        ($build:ident) => {
            match (foreshortened, reuse) {
                (true, true) => $build::<true, true>(&f, s, c, on, kept),
                (true, false) => $build::<true, false>(&f, s, c, on, kept),
                (false, true) => $build::<false, true>(&f, s, c, on, kept),
                (false, false) => $build::<false, false>(&f, s, c, on, kept),
            }
        };
    }
    let (triangle, vtr, ftv) = match backend {
        Backend::Baseline => by_flags!(baseline),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `backend` is a build the processor runs (`Backend::detect`,
        // `Backend::available`).
        Backend::Avx2 => unsafe { by_flags!(avx2) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above.
        Backend::Avx512 => unsafe { by_flags!(avx512) },
    };
    GaussNewton {
        vtv: mirrored(triangle),
        vtr,
        ftv,
    }
}

/// Index of entry `(p, q)`, `p <= q`, of the upper triangle stored row by row.
#[inline(always)]
const fn triangle_index(p: usize, q: usize) -> usize {
    p * P - p * (p + 1) / 2 + q
}

/// The symmetric matrix whose upper triangle, row by row, is `triangle`.
// Index loops: the triangle's layout reads clearer with the textbook's indices.
#[allow(clippy::needless_range_loop)]
fn mirrored(triangle: [f64; TRIANGLE]) -> [[f64; P]; P] {
    let mut m = [[0.0; P]; P];
    for p in 0..P {
        for q in p..P {
            let e = triangle_index(p, q);
            (m[p][q], m[q][p]) = (triangle[e], triangle[e]);
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::super::State;
    use super::*;
    use crate::frames::rig::{uniform_cone_lights, Rig, RigOptions};
    use glam::DVec3;

    fn state() -> State {
        let n = DVec3::new(0.35, -0.2, 1.0).normalize();
        let (u, w) = crate::geometry::tangent_basis(n);
        State {
            normal: n,
            tangent: (u + 0.7 * w).normalize(),
            shape: [0.3f64.ln(), 0.08f64.ln(), 3f64.ln(), 0.4],
        }
    }

    #[test]
    fn the_derivatives_match_central_differences() {
        let state = state();
        let frame = Frame::of(&Model::of(&state));
        let rig = Rig::new(&uniform_cone_lights(60, 65.0), RigOptions::default()).unwrap();
        // One sample in every lane.
        let block = |l: DVec3, h: DVec3| Block {
            l: [F64x16::splat(l.x), F64x16::splat(l.y), F64x16::splat(l.z)],
            h: [F64x16::splat(h.x), F64x16::splat(h.y), F64x16::splat(h.z)],
            fresnel: F64x16::splat(0.0),
            y: F64x16::splat(0.0),
            w: F64x16::splat(1.0),
        };
        let at = |d: [f64; P], l: DVec3, h: DVec3| {
            let f = Frame::of(&Model::of(&state.moved(&d)));
            let t = terms::<F64x16, true>(&f, &block(l, h));
            (t.a.0[0], t.lobe.0[0])
        };
        let mut checked = 0;
        for (&l, &h) in rig.lights_in_camera().iter().zip(rig.halfway_in_camera()) {
            let t = terms::<F64x16, true>(&frame, &block(l, h));
            if state.normal.dot(l) < 0.1 || t.lobe.0[0] < 1e-6 {
                continue;
            }
            for i in 0..P {
                let (mut plus, mut minus) = ([0.0; P], [0.0; P]);
                plus[i] = 1e-6;
                minus[i] = -1e-6;
                let fd = (at(plus, l, h).1.ln() - at(minus, l, h).1.ln()) / 2e-6;
                let g = t.d_ln_lobe[i].0[0];
                assert!(
                    (fd - g).abs() <= 1e-5 * (1.0 + fd.abs()),
                    "{i}: {fd} vs {g}"
                );
                if i < 2 {
                    let fd = (at(plus, l, h).0 - at(minus, l, h).0) / 2e-6;
                    let d = t.d_a[i].0[0];
                    assert!((fd - d).abs() <= 1e-6, "{i}: {fd} vs {d}");
                }
            }
            checked += 1;
        }
        assert!(checked > 20, "{checked}");
    }

    #[test]
    fn every_build_gives_the_baseline_sums_bit_for_bit() {
        // With and without the foreshortening (the loops compiled with and without its terms).
        let mut microfacet = state();
        microfacet.shape[3] = 0.0;
        for model in [Model::of(&state()), Model::of(&microfacet)] {
            builds_agree(&model);
        }
    }

    fn builds_agree(model: &Model) {
        let rig = Rig::new(&uniform_cone_lights(101, 65.0), RigOptions::default()).unwrap();
        let mut s = Subset::default();
        let js: Vec<u32> = (0..rig.n_used() as u32).collect();
        let y: Vec<f64> = (0..rig.n_used()).map(|k| 0.1 + (k % 7) as f64).collect();
        s.gather(&js, rig.lights_in_camera(), rig.halfway_in_camera(), &y);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let gn_values = |gn: &GaussNewton| {
            let mut all: Vec<f64> = gn.vtv.iter().flatten().copied().collect();
            all.extend(gn.vtr);
            all.extend(gn.ftv.iter().flatten());
            all
        };
        let run = |backend: Backend, free: [bool; P]| {
            let mut lobe = vec![0.0; s.padded_len()];
            let mut kept = Kept::default();
            let sums = sums_with(backend, model, &s, &mut lobe, &mut kept);
            let c = [0.3, 1.0, 0.5];
            let fresh = gauss_newton_with(backend, model, &s, c, free, &Kept::default());
            // The terms the sums pass kept give the Gauss-Newton sums bit for bit.
            assert!(kept.holds(&Frame::of(model), &s, model.foreshortening != 0.0));
            let reused = gauss_newton_with(backend, model, &s, c, free, &kept);
            assert_eq!(
                bits(&gn_values(&reused)),
                bits(&gn_values(&fresh)),
                "{backend:?}"
            );
            let mut all = lobe;
            all.extend(sums.gram.iter().flatten());
            all.extend(sums.products);
            all.push(sums.energy);
            all.extend(gn_values(&fresh));
            all
        };
        let backends = Backend::available();
        for free in [[true; P], [true, true, true, true, true, true, false]] {
            let baseline = run(Backend::Baseline, free);
            assert!(baseline.iter().all(|v| v.is_finite()));
            assert!(baseline.iter().filter(|v| **v != 0.0).count() > 100);
            for &b in &backends[1..] {
                assert_eq!(bits(&run(b, free)), bits(&baseline), "{b:?}");
            }
        }
        assert_eq!(backends.last(), Some(&Backend::detect()));
    }
}
