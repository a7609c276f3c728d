//! Two lobes sharing one frame, fitted to a pixel's samples where one lobe leaves them
//! unexplained: a sharp coat over a broad anisotropic base (car paint, lacquered brushed metal),
//! the two perpendicular lobes of a woven fabric's warp and weft (docs/method.md, "Two lobes").
//!
//! `I(l) = d (n.l)+ + sum over X in {A, B} of (s1X + s2X (1 - h.v)^5) L_X(l)`, each `L_X` the
//! one-lobe model's lobe (`lobe/mod.rs`) with its own widths `a_tX`, `a_bX` along the shared
//! axes `(t, b)`, a shared shape `k` and no foreshortening. Both lobes are
//! mirror-symmetric about the planes `(n, t)` and `(n, b)`, so the frame that lets the pair
//! explain the samples is the frame about which the samples are most symmetric, as for one lobe.
//! The five linear coefficients are solved by non-negative least squares at every step
//! (variable projection), the eight others (the frame's rotations about its axes, the four
//! `ln a`, `ln k`) by Levenberg-Marquardt with Kaufman's Jacobian, over the samples the one-lobe fit
//! read. Scalar code: it runs only at pixels one lobe does not explain.

// Index loops: the small dense solves and sums read clearer as the textbook's indices.
#![allow(clippy::needless_range_loop)]

use glam::{DQuat, DVec3};

use crate::frames::rig::Rig;

use super::descent::{descend, hold_at_bound, Descent};
use super::light_share::{light_draws_seed, moved_by_turned_lights};
use super::linalg::{ldl_solve, tilt_sd};
use super::search::{COARSE_RELATIVE_GAIN, RELATIVE_GAIN};
use super::subset::Subset;
use super::{LobeFit, LobeScratch, ALPHA_RANGE, RETRY_RESIDUAL, SHAPE_RANGE};

/// Number of linear coefficients: the diffuse term and each lobe's two Fresnel terms.
const C: usize = 5;

/// Number of nonlinear parameters: the frame's three rotations, the four `ln a`, `ln k`.
const P: usize = 8;

/// Two lobes sharing one frame, fitted to one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LobePair {
    /// Unit normal: the shared centre.
    pub normal: DVec3,
    /// Unit tangent of the shared frame (the first axis of both lobes' widths).
    pub tangent: DVec3,
    /// The lobes' widths along `tangent` and along `normal x tangent` (slope units).
    pub alpha: [[f64; 2]; 2],
    /// The share of the samples' modelled energy each lobe carries.
    pub share: [f64; 2],
    /// The shape exponent `k` both lobes share.
    pub shape: f64,
    /// Share of the samples' energy the pair leaves unexplained, in [0, 1].
    pub residual: f64,
    /// Share of the same samples' energy the one lobe the pair started from leaves
    /// unexplained.
    pub single_residual: f64,
    /// Samples the pair was fitted to.
    pub samples: usize,
    /// How much what the pair leaves over every valid light looks like structure rather than
    /// independent noise: the z score `sum r_i r_j / sqrt(sum r_i^2 r_j^2)` of the residuals
    /// of neighbouring lights (the triangulation's edges). About standard normal where the
    /// residuals are independent noise (shot and read noise, quantisation, each light's own
    /// calibration error); large where a smooth misfit is left (a material the pair does not
    /// describe, a cast shadow).
    pub structure: f64,
    /// Share of the energy of every valid light in front of the surface the pair leaves
    /// unexplained: unlike [`LobePair::residual`] (over the fitted samples, cast shadows
    /// trimmed) it counts the samples the fit left out.
    pub residual_everywhere: f64,
    /// Standard deviation of the shared normal (radians) the samples' scatter about the pair
    /// leaves, as [`LobeFit::normal_sd`].
    pub normal_sd: f64,
    /// Standard deviation of the shared normal (radians) from the lights' uncertainty, as
    /// [`LobeFit::light_sd`].
    pub light_sd: f64,
    /// Model evaluations used.
    pub evals: u32,
}

/// Parameters the pair has beyond one lobe's: a second lobe's two widths and two Fresnel
/// coefficients, the shape shared (the one-lobe fit's foreshortening counted as its own).
const EXTRA_PARAMETERS: f64 = 3.0;

/// The upper 0.1% point of the chi-square distribution with [`EXTRA_PARAMETERS`] degrees of
/// freedom: the F test's level (one pixel in a thousand takes a second lobe it does not need).
const CHI2_3_999: f64 = 16.27;

impl LobePair {
    /// Whether the second lobe explains significantly more than the one lobe the pair started
    /// from: the F test of the nested fits, with the pair's own residual as the noise
    /// (no noise model needed: where the pair describes the material its residual is the
    /// noise; where it does not, the test is the stricter for it). The level's quantile for
    /// the residual's degrees of freedom `q` is `chi2 / 3 + 50 / q` (within 2% of F(3, q)'s
    /// 0.1% point for q >= 30).
    pub(crate) fn significant(&self) -> bool {
        let dof = self.samples as f64 - 13.0;
        if dof < 8.0 {
            return false;
        }
        let gain = (self.single_residual - self.residual).max(0.0) / EXTRA_PARAMETERS;
        let noise = self.residual / dof;
        gain > (CHI2_3_999 / EXTRA_PARAMETERS + 50.0 / dof) * noise
    }

    /// The pair read as one lobe for the estimator's rules: its frame, with the widths and the
    /// wide axis of the lobe that gives the tangent (the stronger of those `elongated` accepts,
    /// the stronger lobe where neither is), and the pair's residual.
    pub(crate) fn as_lobe(&self, elongated: impl Fn(&LobeFit) -> bool) -> LobeFit {
        let b = self.normal.cross(self.tangent);
        let lobe = |x: usize| {
            let [at, ab] = self.alpha[x];
            let (tangent, alpha) = if at >= ab {
                (self.tangent, [at, ab])
            } else {
                (b, [ab, at])
            };
            LobeFit {
                normal: self.normal,
                tangent,
                alpha,
                shape: self.shape,
                foreshortening: 0.0,
                diffuse: 0.0,
                specular: 0.0,
                fresnel: 0.0,
                residual: self.residual,
                trimmed: 0,
                normal_sd: self.normal_sd,
                light_sd: self.light_sd,
                noise_share: 0.0,
                noise_share_sd: 0.0,
                evals: self.evals,
            }
        };
        let order = if self.share[0] >= self.share[1] {
            [0, 1]
        } else {
            [1, 0]
        };
        let [stronger, weaker] = order.map(lobe);
        if !elongated(&stronger) && elongated(&weaker) {
            weaker
        } else {
            stronger
        }
    }
}

/// A point of the search: the frame, the four `ln a` (`[a_tA, a_bA, a_tB, a_bB]`) and `ln k`.
#[derive(Debug, Clone, Copy)]
struct State {
    normal: DVec3,
    tangent: DVec3,
    ln_alpha: [f64; 4],
    ln_shape: f64,
}

impl State {
    /// The state moved by `d`: the frame turned by `(d0, d1, d2)` about `(t, b, n)`, the
    /// widths' and the shape's logarithms shifted by `d3..d7` (and kept in range).
    fn moved(&self, d: &[f64; P]) -> Self {
        let b = self.normal.cross(self.tangent);
        let turn = DQuat::from_scaled_axis(d[0] * self.tangent + d[1] * b + d[2] * self.normal);
        let normal = (turn * self.normal).normalize();
        let t = turn * self.tangent;
        let tangent = (t - normal * normal.dot(t)).normalize();
        let mut ln_alpha = self.ln_alpha;
        for (v, s) in ln_alpha.iter_mut().zip(&d[3..7]) {
            *v = (*v + s).clamp(ALPHA_RANGE.0.ln(), ALPHA_RANGE.1.ln());
        }
        Self {
            normal,
            tangent,
            ln_alpha,
            ln_shape: (self.ln_shape + d[7]).clamp(SHAPE_RANGE.0.ln(), SHAPE_RANGE.1.ln()),
        }
    }
}

/// One lobe's constants at a state.
#[derive(Clone, Copy)]
struct Widths {
    inv_a2: [f64; 2],
    alpha2: f64,
}

impl Widths {
    fn of(ln_at: f64, ln_ab: f64) -> Self {
        let (at, ab) = (ln_at.exp(), ln_ab.exp());
        Self {
            inv_a2: [at.powi(-2), ab.powi(-2)],
            alpha2: at * ab,
        }
    }
}

/// A sample's projections on the frame.
struct Geometry {
    nl: f64,
    hn: f64,
    ht: f64,
    hb: f64,
    lt: f64,
    lb: f64,
}

impl Geometry {
    /// The projections of light `l` and halfway vector `h` on `model`'s frame, `nl` given.
    fn of(model: &Model, nl: f64, l: DVec3, h: DVec3) -> Self {
        Self {
            nl,
            hn: model.normal.dot(h),
            ht: model.t.dot(h),
            hb: model.b.dot(h),
            lt: model.t.dot(l),
            lb: model.b.dot(l),
        }
    }
}

/// A lobe's value at a lit sample and the derivatives of its logarithm with respect to the
/// frame's rotations about `(t, b, n)`, its `ln a_t`, `ln a_b` and `ln k`; zero where the
/// halfway vector is (nearly) behind the normal. The one-lobe model's formulas
/// (`lobe/kernel.rs`).
fn lobe(g: &Geometry, w: &Widths, k: f64) -> (f64, [f64; 6]) {
    if g.hn <= 1e-3 {
        return (0.0, [0.0; 6]);
    }
    let inv_hn = 1.0 / g.hn;
    let (x, y) = (g.ht * inv_hn, g.hb * inv_hn);
    let (qt, qb) = (x * x * w.inv_a2[0], y * y * w.inv_a2[1]);
    let q = qt + qb;
    let base = 1.0 + q / k;
    let ln_base = base.ln();
    let by_q = -1.0 / base;
    let nl = g.nl;
    let root = (nl * nl * (1.0 - w.alpha2) + w.alpha2).sqrt();
    let inv_sum = 1.0 / (nl + root);
    let masking = 2.0 * nl * inv_sum;
    let value = (-k * ln_base).exp() * masking * inv_hn.powi(4);
    let by_nl = 1.0 / nl - (nl * (1.0 - w.alpha2) / root + 1.0) * inv_sum;
    let d_nl = [-g.lb, g.lt, 0.0];
    let d_hn = [-g.hb, g.ht, 0.0];
    let d_ht = [0.0, -g.hn, g.hb];
    let d_hb = [g.hn, 0.0, -g.ht];
    let mut d = [0.0; 6];
    for r in 0..3 {
        let dx = (d_ht[r] - x * d_hn[r]) * inv_hn;
        let dy = (d_hb[r] - y * d_hn[r]) * inv_hn;
        let dq = 2.0 * (x * dx * w.inv_a2[0] + y * dy * w.inv_a2[1]);
        d[r] = by_q * dq + by_nl * d_nl[r] - 4.0 * d_hn[r] * inv_hn;
    }
    let by_width = -(1.0 - nl * nl) / root * inv_sum * 0.5 * w.alpha2;
    d[3] = by_q * (-2.0 * qt) + by_width;
    d[4] = by_q * (-2.0 * qb) + by_width;
    d[5] = q / base - k * ln_base;
    (value, d)
}

/// The model at a state, as the passes read it.
struct Model {
    normal: DVec3,
    t: DVec3,
    b: DVec3,
    lobes: [Widths; 2],
    shape: f64,
}

impl Model {
    fn of(s: &State) -> Self {
        Self {
            normal: s.normal,
            t: s.tangent,
            b: s.normal.cross(s.tangent),
            lobes: [
                Widths::of(s.ln_alpha[0], s.ln_alpha[1]),
                Widths::of(s.ln_alpha[2], s.ln_alpha[3]),
            ],
            shape: s.ln_shape.exp(),
        }
    }

    /// Sample `i`'s basis functions `(n.l, L_A, L_A F, L_B, L_B F)` and, for the Jacobian, the
    /// derivatives of `n.l` and of `ln L_A`, `ln L_B`; `None` where the light is behind.
    #[allow(clippy::type_complexity)]
    fn terms(&self, s: &Subset, i: usize) -> Option<([f64; C], [f64; 2], [[f64; 6]; 2])> {
        let l = s.light(i);
        let h = s.halfway(i);
        let nl = self.normal.dot(l);
        if nl <= 0.0 {
            return None;
        }
        let g = Geometry::of(self, nl, l, h);
        let f = s.fresnel(i);
        let (la, da) = lobe(&g, &self.lobes[0], self.shape);
        let (lb, db) = lobe(&g, &self.lobes[1], self.shape);
        Some(([nl, la, la * f, lb, lb * f], [-g.lb, g.lt], [da, db]))
    }
}

/// The linear part at a state: coefficients, residual sum of squares, active set (bit `k`:
/// coefficient `k` free) and the Gram matrix of the basis functions.
#[derive(Debug, Clone, Copy)]
struct Linear {
    coefficients: [f64; C],
    cost: f64,
    set: u8,
    gram: [[f64; C]; C],
}

/// Solves the Gram block of the `members` of `g` against `p` (`L D L^T`); `None` where the
/// block is (nearly) singular or a value is not finite.
fn solve_members(g: &[[f64; C]; C], p: &[f64; C], members: &[usize]) -> Option<[f64; C]> {
    let n = members.len();
    let mut a = [[0.0; C]; C];
    let mut x = [0.0; C];
    for (r, &i) in members.iter().enumerate() {
        for (c, &j) in members.iter().enumerate() {
            a[r][c] = g[i][j];
        }
        x[r] = p[i];
    }
    if !ldl_solve(&mut a, &mut x, n, |j| 1e-12 * g[members[j]][members[j]]) {
        return None;
    }
    let mut out = [0.0; C];
    for (r, &i) in members.iter().enumerate() {
        out[i] = x[r];
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The members of active set `mask`.
fn members(mask: u8) -> ([usize; C], usize) {
    let mut m = [0; C];
    let mut n = 0;
    for k in 0..C {
        if mask & (1 << k) != 0 {
            m[n] = k;
            n += 1;
        }
    }
    (m, n)
}

/// Non-negative least squares over the five basis functions from their Gram matrix, products
/// with the values and the values' energy: every active set is tried (31 small solves), exact.
fn nnls(gram: [[f64; C]; C], p: [f64; C], syy: f64) -> Linear {
    let cost = |x: &[f64; C]| {
        let mut r = syy;
        for a in 0..C {
            r -= 2.0 * x[a] * p[a];
            for b in 0..C {
                r += x[a] * gram[a][b] * x[b];
            }
        }
        r.max(0.0)
    };
    let mut best = Linear {
        coefficients: [0.0; C],
        cost: syy,
        set: 0,
        gram,
    };
    for set in 1u8..(1 << C) {
        let (m, n) = members(set);
        let Some(x) = solve_members(&gram, &p, &m[..n]) else {
            continue;
        };
        if x.iter().all(|&v| v >= 0.0) {
            let c = cost(&x);
            if c < best.cost {
                best = Linear {
                    coefficients: x,
                    cost: c,
                    set,
                    gram,
                };
            }
        }
    }
    best
}

/// A sample's terms at a model: the basis functions, the derivatives of `n.l` and of the
/// lobes' logarithms (zero for a light behind the surface).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Terms {
    f: [f64; C],
    d_a: [f64; 2],
    d: [[f64; 6]; 2],
}

/// The linear part at `m` over the samples (one pass), the samples' terms into `terms`: the
/// Gauss-Newton system at the same model reads them (an accepted step's pass is the next
/// system's).
fn project(m: &Model, s: &Subset, syy: f64, terms: &mut Vec<Terms>) -> Linear {
    let mut gram = [[0.0; C]; C];
    let mut p = [0.0; C];
    terms.clear();
    for i in 0..s.len() {
        let t = match m.terms(s, i) {
            Some((f, d_a, d)) => Terms { f, d_a, d },
            None => Terms::default(),
        };
        terms.push(t);
        let f = t.f;
        let y = s.value(i);
        for a in 0..C {
            p[a] += f[a] * y;
            for b in a..C {
                gram[a][b] += f[a] * f[b];
            }
        }
    }
    for a in 0..C {
        for b in 0..a {
            gram[a][b] = gram[b][a];
        }
    }
    nnls(gram, p, syy)
}

/// The reduced problem's Gauss-Newton system at `m` with linear part `lin` (Kaufman's
/// Jacobian, as the one-lobe fit's `normal_equations`): `J^T J` and `v^T r`, from the samples'
/// `terms` at `m` (as [`project`] left them).
fn normal_equations(lin: &Linear, s: &Subset, terms: &[Terms]) -> ([[f64; P]; P], [f64; P]) {
    let c = lin.coefficients;
    let mut vtv = [[0.0; P]; P];
    let mut vtr = [0.0; P];
    let mut ftv = [[0.0; P]; C];
    for i in 0..s.len() {
        let Terms {
            f,
            d_a,
            d: [da, db],
        } = terms[i];
        if f[0] <= 0.0 {
            continue;
        }
        let fr = s.fresnel(i);
        let pa = (c[1] + c[2] * fr) * f[1];
        let pb = (c[3] + c[4] * fr) * f[3];
        let mut v = [0.0; P];
        for r in 0..3 {
            let diffuse = if r < 2 { c[0] * d_a[r] } else { 0.0 };
            v[r] = diffuse + pa * da[r] + pb * db[r];
        }
        v[3] = pa * da[3];
        v[4] = pa * da[4];
        v[5] = pb * db[3];
        v[6] = pb * db[4];
        v[7] = pa * da[5] + pb * db[5];
        let prediction: f64 = f.iter().zip(&c).map(|(f, c)| f * c).sum();
        let r = s.value(i) - prediction;
        for a in 0..P {
            vtr[a] += v[a] * r;
            for b in a..P {
                vtv[a][b] += v[a] * v[b];
            }
            for k in 0..C {
                ftv[k][a] += f[k] * v[a];
            }
        }
    }
    // J^T J = v^T v - (F_A^T v)^T (F_A^T F_A)^-1 (F_A^T v).
    let (mm, n) = members(lin.set);
    let mut solved = [[0.0; C]; P];
    for (a, w) in solved.iter_mut().enumerate() {
        if n > 0 {
            let u: [f64; C] = std::array::from_fn(|k| ftv[k][a]);
            *w = solve_members(&lin.gram, &u, &mm[..n]).unwrap_or([0.0; C]);
        }
    }
    let mut jtj = [[0.0; P]; P];
    for a in 0..P {
        for b in a..P {
            let correction: f64 = (0..C).map(|k| ftv[k][a] * solved[b][k]).sum();
            jtj[a][b] = vtv[a][b] - correction;
            jtj[b][a] = jtj[a][b];
        }
    }
    (jtj, vtr)
}

/// Levenberg-Marquardt from `state` until a step gains less than `relative` of the cost: the
/// state, its linear part and the passes used.
fn levenberg_marquardt(
    s: &Subset,
    state: State,
    syy: f64,
    relative: f64,
    buffers: &mut [Vec<Terms>; 2],
) -> (State, Linear, u32) {
    let linear = project(&Model::of(&state), s, syy, &mut buffers[0]);
    let mut fit = Pair {
        samples: s,
        syy,
        terms: buffers,
    };
    descend(&mut fit, state, linear, syy, relative, 1)
}

/// The pair's fit as [`descend`] reads it: the samples, their energy, and the samples' terms at
/// the search's point and at its last trial.
struct Pair<'a> {
    samples: &'a Subset,
    syy: f64,
    terms: &'a mut [Vec<Terms>; 2],
}

impl Descent<P> for Pair<'_> {
    type Point = State;
    type Linear = Linear;
    const STOPS_UNDAMPED: bool = false;

    fn cost(linear: &Linear) -> f64 {
        linear.cost
    }

    fn normal_equations(&mut self, state: &State, linear: &Linear) -> ([[f64; P]; P], [f64; P]) {
        let (mut jtj, mut rhs) = normal_equations(linear, self.samples, &self.terms[0]);
        // A width or the shape at its bound that the descent pushes further out is held this
        // iteration.
        let alpha = (ALPHA_RANGE.0.ln(), ALPHA_RANGE.1.ln());
        for k in 0..4 {
            hold_at_bound(&mut jtj, &mut rhs, 3 + k, state.ln_alpha[k], alpha);
        }
        let shape = (SHAPE_RANGE.0.ln(), SHAPE_RANGE.1.ln());
        hold_at_bound(&mut jtj, &mut rhs, 7, state.ln_shape, shape);
        (jtj, rhs)
    }

    fn try_step(
        &mut self,
        state: &State,
        step: &[f64; P],
        passes: &mut u32,
    ) -> Option<(State, Linear)> {
        let trial = state.moved(step);
        if trial.normal.z <= 0.0 {
            return None;
        }
        *passes += 1;
        let linear = project(
            &Model::of(&trial),
            self.samples,
            self.syy,
            &mut self.terms[1],
        );
        Some((trial, linear))
    }

    fn keep(&mut self) {
        self.terms.swap(0, 1);
    }
}

/// Widths of the second lobe's starts besides the crossed one: a sharp coat at this share of
/// the one lobe's narrower width, and a broad round lobe of this width (slope units).
const COAT_START_SHARE: f64 = 0.3;
const BROAD_START: f64 = 0.3;

/// Fits two lobes sharing one frame to the samples the last [`super::fit_lobe`] on `scratch`
/// chose (those it left out as cast shadows included) (call it right after, for the same pixel and `rig`), from the one lobe `single` it fitted: the
/// second lobe starts crossed (the first's widths swapped: a woven cross), as a sharp round
/// coat, and as a broad round lobe; the best fit is kept. `None` where the samples are too few.
pub(crate) fn fit_lobe_pair(
    single: &LobeFit,
    rig: &Rig,
    light_error_deg: f64,
    scratch: &mut LobeScratch,
) -> Option<LobePair> {
    let (lights, halfways) = (rig.lights_in_camera(), rig.halfway_in_camera());
    let LobeScratch {
        fine,
        coarse,
        every,
        pair,
        greys,
        residuals,
        fine_lights,
        coarse_lights,
        ..
    } = scratch;
    // The samples the one lobe left out as cast shadows are read again: under a coat they are
    // the coat's or the base's, which the pair may explain; a real cast shadow it cannot, and
    // it is then not accepted.
    if single.trimmed > 0 {
        fine.gather(fine_lights, lights, halfways, greys);
        coarse.gather(coarse_lights, lights, halfways, greys);
    }
    // As for one lobe: where the whole subset is at least twice the coarse one (dense rigs),
    // the starts are searched on the coarse subset to a looser tolerance and the best is
    // polished on the whole.
    let polish = fine.len() >= 2 * coarse.len();
    let (searched, relative): (&Subset, f64) = if polish {
        (coarse, COARSE_RELATIVE_GAIN)
    } else {
        (fine, RELATIVE_GAIN)
    };
    if fine.len() < 12 || searched.len() < 12 {
        return None;
    }
    let syy = fine.energy();
    let searched_syy = searched.energy();
    if syy <= 0.0 || searched_syy <= 0.0 {
        return None;
    }
    let ln_shape = single.shape.clamp(SHAPE_RANGE.0, SHAPE_RANGE.1).ln();
    let ln = |a: f64| a.clamp(ALPHA_RANGE.0, ALPHA_RANGE.1).ln();
    let [a0, a1] = single.alpha;
    let coat = (COAT_START_SHARE * a1).max(ALPHA_RANGE.0 * 2.0);
    let starts = [
        [ln(a0), ln(a1), ln(a1), ln(a0)],
        [ln(a0), ln(a1), ln(coat), ln(coat)],
        [ln(a0), ln(a1), ln(BROAD_START), ln(BROAD_START)],
    ];
    let mut evals = 0;
    let mut best: Option<(State, Linear)> = None;
    for ln_alpha in starts {
        let start = State {
            normal: single.normal,
            tangent: single.tangent,
            ln_alpha,
            ln_shape,
        };
        let (state, linear, e) = levenberg_marquardt(searched, start, searched_syy, relative, pair);
        evals += e;
        if best.is_none_or(|b| linear.cost < b.1.cost) {
            best = Some((state, linear));
        }
        // As for one lobe, the starts are tried until one explains the samples.
        if best.is_some_and(|b| b.1.cost <= RETRY_RESIDUAL * searched_syy) {
            break;
        }
    }
    let (mut state, mut linear) = best?;
    if polish {
        let (polished, polished_linear, e) =
            levenberg_marquardt(fine, state, syy, RELATIVE_GAIN, pair);
        evals += e;
        (state, linear) = (polished, polished_linear);
    }
    let s: &Subset = fine;
    // Each lobe's share of the modelled energy.
    let model = Model::of(&state);
    // The normal's uncertainty from the Gauss-Newton system at the answer (the terms
    // recomputed there: the buffer may hold another start's).
    let normal_sd = {
        let at = project(&model, s, syy, &mut pair[0]);
        let (jtj, _) = normal_equations(&at, s, &pair[0]);
        evals += 2;
        let parameters = P + members(at.set).1;
        tilt_sd(&jtj, at.cost, s.len() as f64 - parameters as f64)
    };
    // The lights' uncertainty, as for one lobe ([`LobeFit::light_sd`]): the pair refitted from
    // the answer with every light turned at random by the light error, the root mean squared
    // angle its normal moved over the draws. The pair's own: its normal is read where its
    // sharper lobe is, between fewer lights than the one lobe's (a coat's highlight under a
    // sparse rig).
    let light_error = light_error_deg.to_radians();
    let light_sd = if light_error > 0.0 {
        let seed = light_draws_seed(fine_lights, greys, s.len());
        let (sd, e) = moved_by_turned_lights(s, every, state.normal, light_error, seed, |turned| {
            let (refit, _, e) = levenberg_marquardt(turned, state, syy, RELATIVE_GAIN, pair);
            (refit.normal, e)
        });
        evals += e;
        sd
    } else {
        0.0
    };
    let c = linear.coefficients;
    let mut energy = [0.0f64; 2];
    for i in 0..s.len() {
        if let Some((f, _, _)) = model.terms(s, i) {
            energy[0] += (c[1] * f[1] + c[2] * f[2]).powi(2);
            energy[1] += (c[3] * f[3] + c[4] * f[4]).powi(2);
        }
    }
    let total = (energy[0] + energy[1]).max(f64::MIN_POSITIVE);
    let (structure, residual_everywhere) = residual_structure(
        &model,
        c,
        lights,
        halfways,
        greys,
        rig.halfway_edges(),
        residuals,
    );
    let alpha = |k: usize| [state.ln_alpha[k].exp(), state.ln_alpha[k + 1].exp()];
    Some(LobePair {
        normal: state.normal,
        tangent: state.tangent,
        alpha: [alpha(0), alpha(2)],
        share: [energy[0] / total, energy[1] / total],
        shape: model.shape,
        residual: (linear.cost / syy).clamp(0.0, 1.0),
        single_residual: single.residual,
        samples: s.len(),
        structure,
        residual_everywhere,
        normal_sd,
        light_sd,
        evals,
    })
}

/// The z score of the correlation of neighbouring lights' residuals under `model` with
/// coefficients `c` (see [`LobePair::structure`]) and the share of their energy the residuals
/// hold ([`LobePair::residual_everywhere`]): every light with a valid grey value (NaN:
/// invalid or censored) in front of the surface, every edge between two such lights. Edges'
/// products of independent zero-mean residuals are uncorrelated (two edges share at most one
/// light), so their sum over the root of their summed squares is about standard normal, whatever
/// each light's noise level.
fn residual_structure(
    model: &Model,
    c: [f64; C],
    lights: &[DVec3],
    halfways: &[DVec3],
    greys: &[f64],
    edges: &[[u32; 2]],
    residuals: &mut Vec<f64>,
) -> (f64, f64) {
    residuals.clear();
    residuals.extend(
        lights
            .iter()
            .zip(halfways)
            .zip(greys)
            .map(|((&l, &h), &y)| {
                let nl = model.normal.dot(l);
                if !y.is_finite() || nl <= 0.0 {
                    return f64::NAN;
                }
                let g = Geometry::of(model, nl, l, h);
                let fr = super::subset::schlick(h);
                let la = lobe(&g, &model.lobes[0], model.shape).0;
                let lb = lobe(&g, &model.lobes[1], model.shape).0;
                y - (c[0] * nl + (c[1] + c[2] * fr) * la + (c[3] + c[4] * fr) * lb)
            }),
    );
    let (mut sum, mut squares) = (0.0, 0.0);
    for &[i, j] in edges {
        let (a, b) = (residuals[i as usize], residuals[j as usize]);
        if a.is_finite() && b.is_finite() {
            sum += a * b;
            squares += (a * b) * (a * b);
        }
    }
    let (mut left, mut energy) = (0.0, 0.0);
    for (r, y) in residuals.iter().zip(greys) {
        if r.is_finite() {
            left += r * r;
            energy += y * y;
        }
    }
    let z = if squares > 0.0 {
        sum / squares.sqrt()
    } else {
        0.0
    };
    (z, if energy > 0.0 { left / energy } else { 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::{Brdf, Ggx, Layered, Woven};
    use crate::frames::lobe::tests::slice;
    use crate::frames::lobe::{fit_lobe, LobeStart};
    use crate::frames::rig::{uniform_cone_lights, Rig, RigOptions};
    use crate::geometry::tangent_basis;

    fn fits(rig: &Rig, brdf: &dyn Brdf, n: DVec3, t: DVec3) -> (LobeFit, LobePair) {
        let samples = slice(rig, brdf, n, t);
        let mut scratch = LobeScratch::default();
        let (u, _) = tangent_basis(n);
        let start = LobeStart {
            normal: (n + 0.03 * u).normalize(),
            tangent: t,
            alpha: [0.2, 0.1],
        };
        let single = fit_lobe(
            &samples,
            rig,
            start,
            &crate::noise::NoiseModel::default(),
            &mut scratch,
        )
        .unwrap();
        let pair = fit_lobe_pair(&single, rig, 0.0, &mut scratch).unwrap();
        (single, pair)
    }

    fn frame() -> (DVec3, DVec3) {
        let n = DVec3::new(0.3, -0.25, 1.0).normalize();
        let (u, w) = tangent_basis(n);
        (n, (u + 0.6 * w).normalize())
    }

    #[test]
    fn a_woven_cross_is_explained_by_two_crossed_lobes() {
        let rig = Rig::new(&uniform_cone_lights(200, 65.0), RigOptions::default()).unwrap();
        let (n, t) = frame();
        let woven = Woven::new([0.25, 0.08, 0.08], [0.05; 3], 0.35, 0.08, 0.5);
        let (single, pair) = fits(&rig, &woven, n, t);
        assert!(single.residual > 1e-3, "{single:?}");
        assert!(pair.residual < 1e-4, "{pair:?}");
        assert!(pair.normal.angle_between(n).to_degrees() < 0.1, "{pair:?}");
        // The tangent is the stronger (warp) lobe's wide axis.
        let lobe = pair.as_lobe(|f| f.elongation() > 0.3);
        assert!(lobe.tangent.dot(t).abs() > 0.999, "{lobe:?}");
    }

    #[test]
    fn a_clear_coat_over_brushed_metal_gives_the_base_s_axis() {
        let rig = Rig::new(&uniform_cone_lights(1000, 65.0), RigOptions::default()).unwrap();
        let (n, t) = frame();
        let base = Ggx::new([0.05, 0.1, 0.2], [0.5, 0.45, 0.6], 0.3, 0.1);
        let car = Layered::new(0.03, 1.5, Box::new(base));
        let (_, pair) = fits(&rig, &car, n, t);
        assert!(pair.residual < 2e-3, "{pair:?}");
        assert!(pair.normal.angle_between(n).to_degrees() < 0.2, "{pair:?}");
        let lobe = pair.as_lobe(|f| f.elongation() > 0.3);
        assert!(lobe.tangent.dot(t).abs() > 0.99, "{lobe:?}");
    }
}
