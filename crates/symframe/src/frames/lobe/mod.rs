//! A symmetric lobe fitted to a pixel's samples: the smooth reconstruction of the slice for
//! rigs whose lights are too far apart for the piecewise-linear one (docs/method.md, "Lobe
//! fit").
//!
//! The model is a diffuse term plus a lobe symmetric about the two planes of the frame
//! `(n, t, b)`, over the pixel's grey values:
//!
//! `I(l) = d (n.l)+ + (s1 + s2 (1 - h.v)^5) G1(n.l) (n.l)^m L(h)`,
//! `L(h) = (1 + q / k)^-k / (h.n)^4` where `n.l > 0`,
//! `q = (h.t / (h.n) / a_t)^2 + (h.b / (h.n) / a_b)^2`
//!
//! (`h` the halfway vector of `l` and the view; `q` in slope space; `G1` Smith's masking,
//! `s1 + s2 (1 - h.v)^5` Schlick's Fresnel in linear form). At `k = 2` the lobe is
//! GGX's distribution of normals; as `k` grows it tends to Beckmann's; `m` is the lobe's
//! foreshortening (0 for microfacet models, whose `1 / (n.l)` cancels the cosine; 1/2 for
//! Ward's; 1 for Phong-like lobes), so the family covers the lobes a measured slice shows
//! without assuming one. Whatever `k`, `a_t`, `a_b`,
//! the lobe is mirror-symmetric about the planes `(n, t)` and `(n, b)` (the foreshortening
//! breaks it only as the paper's cross-multiplied cosines undo): the frame that lets it
//! explain the samples best is the frame about which the samples are most symmetric, read
//! through a smooth reconstruction instead of the triangulation. `d`, `s1`, `s2` enter linearly and
//! are solved in closed form (variable projection); the seven others (the frame's rotations about
//! its three axes, `ln a_t`, `ln a_b`, `ln k`, `m`) by Levenberg-Marquardt with an analytic
//! (Kaufman) Jacobian from the highlight's moments and other starts, over an evenly spread
//! subset of the lights plus the lights of the highlight (the lobe's shape is read there; the
//! rest fix the diffuse term). The loops over the samples are vector code (`lobe/kernel.rs`,
//! `lobe/lanes.rs`).

use crate::frames::rig::Rig;
use crate::noise::NoiseModel;
use glam::{DQuat, DVec3};

use crate::geometry::tangent_basis;

mod descent;
mod kernel;
mod lanes;
mod light_share;
mod linalg;
mod linear;
mod noise_fit;
mod pair;
mod search;
mod subset;

use light_share::{light_draws_seed, light_share};
use linalg::{tilt_sd, tilt_step2};
use linear::{apply, nnls3, ActiveSet, Linear};
use noise_fit::{
    fitted_parameters, noise_cost, noise_variances, noise_weights, SETTLED_Z, WEIGHTED_SD_FLOOR,
};
use search::{levenberg_marquardt, search_subset, COARSE_RELATIVE_GAIN, RELATIVE_GAIN};

pub(crate) use pair::{fit_lobe_pair, LobePair};

use subset::{choose_lights, Subset};

/// Range of the lobe widths `a_t`, `a_b` (slope units): below, a lobe is a single sample's
/// spike; above, no highlight is left to locate.
const ALPHA_RANGE: (f64, f64) = (0.004, 1.5);

/// Range of the shape exponent `k` (2: GGX, large: Beckmann). The upper end puts Beckmann's
/// distribution inside the family: `(1 + q / k)^-k` is within 0.1% of `exp(-q)` out to
/// `q = 4` at `k = 1e4`; below it, a Beckmann lobe is fitted with the foreshortening and the
/// normal bent to make up for its tails (docs/method.md, "Beckmann inside the family").
const SHAPE_RANGE: (f64, f64) = (0.75, 1.0e4);

/// Range of the foreshortening exponent `m`.
const FORESHORTENING_RANGE: (f64, f64) = (-1.0, 2.0);

/// Number of nonlinear parameters.
const P: usize = 7;

/// A lobe fitted to one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LobeFit {
    /// Unit normal: the lobe's centre.
    pub normal: DVec3,
    /// Unit tangent: the lobe's wider axis (perpendicular to `normal`).
    pub tangent: DVec3,
    /// Widths along `tangent` and along `normal x tangent` (slope units, `alpha[0] >= alpha[1]`).
    pub alpha: [f64; 2],
    /// Shape exponent `k`.
    pub shape: f64,
    /// Foreshortening exponent `m`.
    pub foreshortening: f64,
    /// The diffuse coefficient (grey, sum of the three channels, as the lobe's).
    pub diffuse: f64,
    /// The lobe's coefficient at normal incidence (`s f0`).
    pub specular: f64,
    /// The lobe's Fresnel coefficient (`s (1 - f0)`, Schlick's form).
    pub fresnel: f64,
    /// Share of the samples' energy the model leaves unexplained, in [0, 1].
    pub residual: f64,
    /// Samples left out as cast shadows.
    pub trimmed: usize,
    /// Standard deviation of the normal (radians, both tilts together) the samples' scatter
    /// about the fit leaves ([`tilt_sd`]); infinite where they do not determine it.
    pub normal_sd: f64,
    /// Standard deviation of the normal (radians) the lights' own uncertainty gives (0 where
    /// the lights are taken as exact): how far the fit moves, refitted, when every light is
    /// off by the capture's light error at random.
    pub light_sd: f64,
    /// The share of the samples' energy the capture's noise alone would leave unexplained
    /// (its expectation, the fitted parameters' degrees of freedom taken off): each sample's
    /// variance under the noise model, and where the lights are uncertain what turning them by
    /// their error changes in the lobe's prediction. 0 for a noise-free capture.
    pub noise_share: f64,
    /// The standard deviation of that share: `sqrt(2 sum var_i^2) / sum y_i^2`, the spread of
    /// a sum of independent squared Gaussian residuals.
    pub noise_share_sd: f64,
    /// Model evaluations used.
    pub evals: u32,
}

impl LobeFit {
    /// Full width at half maximum of the lobe along its wider axis (slope units): where
    /// `(1 + q / k)^-k` falls to 1/2.
    pub(crate) fn full_width(&self) -> f64 {
        let k = self.shape;
        2.0 * self.alpha[0] * (k * (2f64.powf(1.0 / k) - 1.0)).sqrt()
    }

    /// `(a_t - a_b) / (a_t + a_b)`: 0 for a round lobe, towards 1 for a brushed one.
    pub(crate) fn elongation(&self) -> f64 {
        (self.alpha[0] - self.alpha[1]) / (self.alpha[0] + self.alpha[1])
    }
}

/// A point of the search: the frame and the lobe's shape `[ln a_t, ln a_b, ln k, m]`. The
/// search moves the frame by small rotations about its own axes (a chart centred on the current
/// frame, re-centred at every step), so the derivatives stay simple and no direction is singular.
#[derive(Debug, Clone, Copy)]
struct State {
    normal: DVec3,
    tangent: DVec3,
    shape: [f64; 4],
}

impl State {
    /// The state at a start (the tangent made perpendicular to the normal), microfacet GGX.
    fn new(start: &LobeStart) -> Self {
        let normal = start.normal.normalize();
        let t = start.tangent - normal * normal.dot(start.tangent);
        let tangent = if t.length_squared() > 1e-12 {
            t.normalize()
        } else {
            tangent_basis(normal).0
        };
        let ln_alpha = |a: f64| a.clamp(ALPHA_RANGE.0, ALPHA_RANGE.1).ln();
        Self {
            normal,
            tangent,
            shape: [
                ln_alpha(start.alpha[0]),
                ln_alpha(start.alpha[1]),
                2f64.ln(),
                0.0,
            ],
        }
    }

    /// The state moved by `d`: the frame turned by the rotation vector `(d0, d1, d2)` in the
    /// frame's axes `(t, b, n)`, the shape's coordinates shifted by `d3..d6`.
    fn moved(&self, d: &[f64; P]) -> Self {
        let b = self.normal.cross(self.tangent);
        let turn = DQuat::from_scaled_axis(d[0] * self.tangent + d[1] * b + d[2] * self.normal);
        let normal = (turn * self.normal).normalize();
        let t = turn * self.tangent;
        let tangent = (t - normal * normal.dot(t)).normalize();
        let mut shape = self.shape;
        for (k, (v, s)) in shape.iter_mut().zip(&d[3..]).enumerate() {
            let (lo, hi) = shape_bounds(k);
            *v = (*v + s).clamp(lo, hi);
        }
        Self {
            normal,
            tangent,
            shape,
        }
    }
}

/// The range of the shape coordinate `k` (`ln a_t`, `ln a_b`, `ln k`, `m`): the search stays
/// inside (a step across a bound stops at it).
fn shape_bounds(k: usize) -> (f64, f64) {
    match k {
        0 | 1 => (ALPHA_RANGE.0.ln(), ALPHA_RANGE.1.ln()),
        2 => (SHAPE_RANGE.0.ln(), SHAPE_RANGE.1.ln()),
        _ => FORESHORTENING_RANGE,
    }
}

/// The model at a state: the frame, and the shape's values.
#[derive(Clone, Copy)]
struct Model {
    normal: DVec3,
    t: DVec3,
    b: DVec3,
    inv_a2: [f64; 2],
    shape: f64,
    foreshortening: f64,
    alpha2: f64,
}

impl Model {
    fn of(s: &State) -> Self {
        let a = |v: f64| v.exp().clamp(ALPHA_RANGE.0, ALPHA_RANGE.1);
        Self {
            normal: s.normal,
            t: s.tangent,
            b: s.normal.cross(s.tangent),
            inv_a2: [a(s.shape[0]).powi(-2), a(s.shape[1]).powi(-2)],
            alpha2: a(s.shape[0]) * a(s.shape[1]),
            shape: s.shape[2].exp().clamp(SHAPE_RANGE.0, SHAPE_RANGE.1),
            foreshortening: s.shape[3].clamp(FORESHORTENING_RANGE.0, FORESHORTENING_RANGE.1),
        }
    }
}

/// Lights of the evenly spread subset the fit reads besides the highlight's.
const SPREAD_LIGHTS: usize = 256;

/// Most highlight lights the fit reads besides the spread subset: a broad lobe under a dense rig
/// has many times more above [`HIGHLIGHT_SHARE`] (docs/method.md, "Lobe fit").
const HIGHLIGHT_LIGHTS: usize = 256;

/// Samples at or above this share of the brightest are the highlight's, read by the fit.
const HIGHLIGHT_SHARE: f64 = 0.02;

/// Levenberg-Marquardt iterations at most.
const MAX_ITERATIONS: u32 = 60;

/// The policy's default for a lobe to be the pixel's answer (`LobeSettings::explains`): the
/// share of the energy a fit may leave unexplained.
pub(crate) const LOBE_EXPLAINS: f64 = 0.002;

/// A fit leaving more than this share of the energy unexplained is retried from other starts
/// (the tangent and normal axes swapped, the brightest sample's halfway vector, broad lobes):
/// the estimator's threshold for a lobe to be the pixel's answer.
const RETRY_RESIDUAL: f64 = LOBE_EXPLAINS;

/// Lights of the coarse subset the search runs on: the first of the spread subset's and of the
/// highlight's (so evenly spread too); the fit is then polished on the whole subset, which
/// gives the same maps as searching on all of it (docs/performance.md, "The default estimator
/// with the lobe fit", Coarse-to-fine).
const COARSE_SPREAD: usize = 128;

/// Highlight lights of the coarse subset (see [`COARSE_SPREAD`]).
const COARSE_HIGHLIGHT: usize = 128;

/// Fewest samples in the part of a lobe fit's split ([`fit_lobe`]'s `normal_sd`): its fit
/// must still read the lobe, not only its neighbourhood (lower is faster on dense rigs).
const SPLIT_SAMPLES: usize = 128;

/// Per-thread buffers of [`fit_lobe`], reused from pixel to pixel.
#[derive(Debug, Clone, Default)]
pub(crate) struct LobeScratch {
    fine: Subset,
    coarse: Subset,
    buffers: Buffers,
    chosen: Vec<u8>,
    greys: Vec<f64>,
    /// The lights of `fine` and `coarse`.
    fine_lights: Vec<u32>,
    coarse_lights: Vec<u32>,
    /// The two-lobe fit's per-sample terms, at the current state and at a trial step.
    pair: [Vec<pair::Terms>; 2],
    /// The two-lobe fit's residual at every light.
    residuals: Vec<f64>,
    /// Every other sample of `fine` (the split-half fit's), or all of them with the lights
    /// turned (the light error's).
    every: Subset,
    /// [`predicted_greys`]'s samples and buffers.
    probe: Probe,
}

/// The buffers [`predicted_greys`] evaluates a fitted lobe in (its own, so the fit's kept
/// terms stay those of its samples).
#[derive(Debug, Clone, Default)]
struct Probe {
    samples: Subset,
    /// A zero per light: the probed samples' values (their residuals are then minus the
    /// prediction).
    zeros: Vec<f64>,
    lobe: Vec<f64>,
    r: Vec<f64>,
    kept: kernel::Kept,
}

/// Per-sample work buffers: the lobe's values, the residuals, and which samples stay.
#[derive(Debug, Clone, Default)]
struct Buffers {
    lobe: Vec<f64>,
    r: Vec<f64>,
    keep: Vec<bool>,
    kept: kernel::Kept,
    /// The fit's prediction at each sample, and the variance the lights' error gives it.
    predicted: Vec<f64>,
    light_var: Vec<f64>,
    /// The noise-weighted polish's weight per sample, and its predictions with the normal
    /// tilted.
    weight: Vec<f64>,
    tilted: Vec<f64>,
    /// The last Gauss-Newton system's `J^T J` (at the search's answer or the step before).
    jtj: [[f64; P]; P],
}

impl Buffers {
    /// Makes the buffers at least as long as the subset's samples with the padding (only
    /// grown: the fine and the coarse subset share them, and a shrink then a regrowth would
    /// fill the difference with zeros every time).
    fn fit(&mut self, data: &Subset) {
        for buffer in [&mut self.lobe, &mut self.r] {
            if buffer.len() < data.padded_len() {
                buffer.resize(data.padded_len(), 0.0);
            }
        }
    }
}

/// Leaves out the samples of `data` in cast shadow under `model`: light is taken away where
/// the lobe and the diffuse term predict it, so samples far below a clear prediction, from
/// lights well above the horizon, go (interreflections add light, and stay). Returns how many
/// went and the model's linear part over the samples as they were; `None` where fewer than
/// eight samples would be left.
fn trim_shadows(
    data: &mut Subset,
    model: &Model,
    buffers: &mut Buffers,
) -> Option<(usize, Linear)> {
    buffers.fit(data);
    let Buffers {
        lobe,
        r,
        keep,
        kept,
        ..
    } = buffers;
    let linear = residuals(model, data, lobe, r, kept);
    let max_prediction = (0..data.len())
        .map(|j| data.value(j) - r[j])
        .fold(0.0, f64::max);
    keep.clear();
    keep.extend((0..data.len()).map(|j| {
        let prediction = data.value(j) - r[j];
        let shadow = model.normal.dot(data.light(j)) >= SHADOW_MIN_COSINE
            && prediction >= SHADOW_LEVEL * max_prediction
            && data.value(j) < SHADOW_FRACTION * prediction;
        !shadow
    }));
    let removed = keep.iter().filter(|&&k| !k).count();
    if removed > 0 && data.len() - removed < 8 {
        return None;
    }
    if removed > 0 {
        data.retain(|j| keep[j]);
    }
    Some((removed, linear))
}

/// Widths of the broad starts tried where the highlight's own fail (slope units, along and
/// across the highlight's axis).
const BROAD_START: (f64, f64) = (0.3, 0.1);

/// Where the fit starts: a normal, a tangent and the widths along it and across (slope units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LobeStart {
    /// Unit normal.
    pub normal: DVec3,
    /// Unit tangent.
    pub tangent: DVec3,
    /// Widths along `tangent` and across.
    pub alpha: [f64; 2],
}

/// The linear part at `m`: the basis functions' sums over the samples and their non-negative
/// least squares (the residual sum of squares from the sums, without a second pass); the
/// lobe's value per sample into `lobe`.
fn project(m: &Model, samples: &Subset, lobe: &mut [f64], kept: &mut kernel::Kept) -> Linear {
    let sums = kernel::sums(m, samples, lobe, kept);
    let mut linear = nnls3(sums.gram, sums.products, sums.energy);
    linear.cost = linear.cost.max(0.0);
    linear
}

/// The model's residuals `y - d a - s1 L - s2 L F` at `m`, with its coefficients solved there,
/// over the samples into `r` (one per sample with the padding; `lobe`, as long, gets the lobe's
/// values); returns the linear part.
fn residuals(
    m: &Model,
    samples: &Subset,
    lobe: &mut [f64],
    r: &mut [f64],
    kept: &mut kernel::Kept,
) -> Linear {
    let linear = project(m, samples, lobe, kept);
    kernel::residuals(m, samples, linear.coefficients, lobe, r);
    linear
}

/// The Gauss-Newton system of the reduced (variable-projection) problem at `m`, whose linear
/// part is `linear`, over the parameters marked `free`, in one pass over the samples:
/// Kaufman's (1975) Jacobian `J = -P v`, with `v_i` the derivative of the prediction at fixed
/// coefficients and `P` the projection off the active basis functions. Returns `J^T J` and
/// `-J^T r = v^T r` (the residuals are orthogonal to the active functions).
///
/// Analytic derivatives (one pass) instead of forward differences (seven passes): fewer model
/// passes per fit (docs/performance.md, "The default estimator with the lobe fit").
fn normal_equations(
    m: &Model,
    linear: &Linear,
    free: [bool; P],
    samples: &Subset,
    kept: &kernel::Kept,
) -> ([[f64; P]; P], [f64; P]) {
    let kernel::GaussNewton { vtv, vtr, ftv } =
        kernel::gauss_newton(m, samples, linear.coefficients, free, kept);
    // J^T J = v^T v - (F_A^T v)^T (F_A^T F_A)^-1 (F_A^T v).
    let mut solved = [[0.0f64; 3]; P];
    if let Some(inverse) = ActiveSet::of(linear.set).inverse(&linear.gram) {
        for (i, w) in solved.iter_mut().enumerate() {
            let x = apply(&inverse, &[ftv[0][i], ftv[1][i], ftv[2][i]]);
            if x.iter().all(|v| v.is_finite()) {
                *w = x;
            }
        }
    }
    let mut jtj = [[0.0f64; P]; P];
    for a in 0..P {
        for b in a..P {
            let correction: f64 = (0..3).map(|k| ftv[k][a] * solved[b][k]).sum();
            jtj[a][b] = vtv[a][b] - correction;
            jtj[b][a] = jtj[a][b];
        }
    }
    (jtj, vtr)
}

/// A sample is in cast shadow when it is below this fraction of the model's prediction...
const SHADOW_FRACTION: f64 = 0.25;

/// ...its light is this far above the tangent plane (`n.l`; nearer grazing, a small error in
/// the normal could put a lit sample in shadow)...
const SHADOW_MIN_COSINE: f64 = 0.2;

/// ...and the prediction is at least this share of the brightest prediction (not noise).
const SHADOW_LEVEL: f64 = 1e-3;

/// The parameters a microfacet lobe is fitted with (`m = 0`).
const MICROFACET: [bool; P] = [true, true, true, true, true, true, false];

/// The foreshortening exponent is looked for only where the microfacet lobe leaves more than
/// this share of the energy unexplained.
const FORESHORTENING_FLOOR: f64 = 1e-6;

/// Fits the symmetric lobe model to one pixel: `samples` RGB in `rig` order (NaN = invalid),
/// from `start` (retried from other starts where it explains the samples poorly); `noise` is
/// the capture's noise model, for [`LobeFit::noise_share`], and its lights' uncertainty, for
/// [`LobeFit::light_sd`]. `None` where fewer than eight samples are valid or nothing is lit.
/// Allocation-free once `scratch` has grown to the rig.
pub(crate) fn fit_lobe(
    samples: &[f32],
    rig: &Rig,
    start: LobeStart,
    noise: &NoiseModel,
    scratch: &mut LobeScratch,
) -> Option<LobeFit> {
    let light_error = noise.light_error_deg.to_radians();
    let brightest = choose_lights(samples, rig, scratch)?;
    let LobeScratch {
        fine,
        coarse,
        every,
        buffers,
        greys,
        fine_lights,
        ..
    } = scratch;
    let (starts, count) = starts_from(start, rig.halfway_in_camera()[brightest]);
    let starts = &starts[..count];
    // The coarse subset pays where it is much smaller than the whole one (dense rigs); under a
    // sparse rig the search reads every light: a lobe sampled by few lights can alias in a
    // subset (docs/performance.md, "Coarse-to-fine").
    let polish = fine.len() >= 2 * coarse.len();
    let searched = if polish { &mut *coarse } else { &mut *fine };
    // Where the polish follows, the search need not settle to the last digits: the polish
    // does (docs/performance.md, "Fewer passes").
    let relative = if polish {
        COARSE_RELATIVE_GAIN
    } else {
        RELATIVE_GAIN
    };
    let settled = noise_cost(searched, noise, SETTLED_Z);
    let (mut state, free, mut linear, mut evals) =
        search_subset(searched, starts, relative, settled, buffers)?;
    // The polish on the whole subset, from the coarse answer (a few iterations).
    if polish {
        // Where no sample went, the linear part the trimming found is the polish's start.
        let (removed, trimmed) = trim_shadows(fine, &Model::of(&state), buffers)?;
        buffers.fit(fine);
        let known = (removed == 0).then_some(trimmed);
        let (polished, polished_linear, e) =
            levenberg_marquardt(fine, state, known, free, RELATIVE_GAIN, buffers);
        evals += e;
        (state, linear) = (polished, polished_linear);
    }
    let moved2 = weighted_polish(
        (fine, every),
        (&mut state, &mut linear),
        free,
        noise,
        buffers,
        &mut evals,
    );
    let syy = fine.energy();
    let m = Model::of(&state);
    let normal_sd = tilt_uncertainty(&m, (fine, every), (&linear, free), moved2, buffers);
    evals += 2;
    // The lights' uncertainty, and what they add to each sample's variance (for the noise
    // share below).
    buffers.light_var.clear();
    let light_sd = if light_error > 0.0 {
        let seed = light_draws_seed(fine_lights, greys, fine.len());
        let (sd, e) = light_share(&state, fine, every, free, light_error, seed, buffers);
        evals += e;
        sd
    } else {
        0.0
    };
    // What the noise alone would leave (docs/method.md, "Noise model"): a grey is the sum of
    // three channels, each about a third of it.
    let (noise_share, noise_share_sd) = {
        let (sum, sum2) = noise_variances(fine, noise, &buffers.light_var);
        let parameters = fitted_parameters(&free, &linear);
        let n = fine.len() as f64;
        let kept = ((n - parameters as f64) / n).max(0.0);
        if syy > 0.0 {
            (sum * kept / syy, (2.0 * sum2).sqrt() / syy)
        } else {
            (0.0, 0.0)
        }
    };
    // The coefficients and the sum of squares from the sums over the whole subset, as the
    // search judged its steps (the last search ran on it).
    let Linear {
        coefficients: [diffuse, specular, fresnel],
        cost,
        ..
    } = linear;
    let a = [m.inv_a2[0].powf(-0.5), m.inv_a2[1].powf(-0.5)];
    let (tangent, alpha) = if a[0] >= a[1] {
        (m.t, a)
    } else {
        (m.b, [a[1], a[0]])
    };
    Some(LobeFit {
        normal: m.normal,
        tangent,
        alpha,
        shape: m.shape,
        foreshortening: m.foreshortening,
        diffuse,
        specular,
        fresnel,
        residual: (cost / syy).clamp(0.0, 1.0),
        trimmed: fine_lights.len() - fine.len(),
        normal_sd,
        light_sd,
        noise_share,
        noise_share_sd,
        evals,
    })
}

/// The fit's starts from `start` and the brightest sample's halfway vector, and how many of
/// them to try: the start, its axes swapped, the brightest sample's centre (where it is not
/// the start's), and broad lobes from the same centre both ways. A highlight cut by the rig's
/// edge (its peak outside the lights) has moments far narrower than the lobe, and a start that
/// narrow converges to a spurious fit (docs/method.md, "Lobe fit").
fn starts_from(start: LobeStart, brightest: DVec3) -> ([LobeStart; 5], usize) {
    let swapped = LobeStart {
        tangent: start.normal.cross(start.tangent),
        ..start
    };
    let brightest_start = LobeStart {
        normal: brightest,
        ..start
    };
    let broad = LobeStart {
        alpha: [BROAD_START.0, BROAD_START.1],
        ..start
    };
    let broad_swapped = LobeStart {
        alpha: [BROAD_START.0, BROAD_START.1],
        ..swapped
    };
    let mut starts = [start, swapped, brightest_start, broad, broad_swapped];
    // The brightest sample is often the moments' centre already.
    let distinct = brightest_start.normal.angle_between(start.normal) > 1e-3;
    if !distinct {
        starts[2] = broad_swapped;
    }
    (starts, if distinct { 5 } else { 4 })
}

/// The normal's standard deviation (radians, both tilts) the scatter of the samples of `fine`
/// about the fit `linear` leaves, through the last Gauss-Newton system in `buffers`.
fn scatter_sd(fine: &Subset, linear: &Linear, free: [bool; P], buffers: &Buffers) -> f64 {
    let parameters = fitted_parameters(&free, linear);
    tilt_sd(
        &buffers.jtj,
        linear.cost,
        fine.len() as f64 - parameters as f64,
    )
}

/// The noise-weighted polish (docs/method.md, "Lobe fit", "The noise-weighted fit"): where the
/// capture is noisy and the fit explains the samples to the noise, the fit on `fine` is
/// repeated from its answer with each sample weighted by the inverse of its variance under the
/// noise model, the lights' error included (into `every`); `state` and `linear` become its
/// answer, the unweighted linear part and Gauss-Newton system at it. Returns how far the
/// weighting moved the normal, squared: a misfit the noise hides moves it, a lobe the family
/// describes moves it within the noise (the normal's uncertainty reads it). 0 where it did not
/// run.
fn weighted_polish(
    (fine, every): (&Subset, &mut Subset),
    (state, linear): (&mut State, &mut Linear),
    free: [bool; P],
    noise: &NoiseModel,
    buffers: &mut Buffers,
    evals: &mut u32,
) -> f64 {
    let scatter_sd = scatter_sd(fine, linear, free, buffers);
    if !(scatter_sd >= WEIGHTED_SD_FLOOR
        && noise_weights(fine, state, linear.coefficients, noise, buffers))
    {
        return 0.0;
    }
    let unweighted = state.normal;
    every.weighted(fine, &buffers.weight);
    buffers.fit(every);
    let (weighted, _, e) = levenberg_marquardt(every, *state, None, free, RELATIVE_GAIN, buffers);
    let moved2 = weighted.normal.angle_between(unweighted).powi(2);
    *state = weighted;
    // The unweighted linear part and Gauss-Newton system at the new answer, as every
    // figure after it reads them.
    buffers.fit(fine);
    let m = Model::of(state);
    let Buffers {
        lobe, kept, jtj, ..
    } = &mut *buffers;
    *linear = project(&m, fine, lobe, kept);
    *jtj = normal_equations(&m, linear, free, fine, kept).0;
    *evals += e + 2;
    moved2
}

/// The normal's standard deviation (radians, both tilts) at the answer `m`, from the last
/// Gauss-Newton system over the whole subset `fine` (at the answer, or a step too small to
/// take before it), the split and the noise-weighted polish's move `moved2`; two passes over
/// the part's samples (in `every`).
///
/// Split: the fit repeated from the answer on every k-th sample. Its normal's distance from
/// the whole fit's estimates the whole fit's error, what the lights' sampling of the lobe
/// leaves (a lobe the model does not describe, read between few lights) as well as the noise:
/// for nested fits `var(n_k - n) = var(n_k) - var(n)`, and a k-th of the samples has k times
/// the variance, so `var(n) = var(n_k - n) / (k - 1)`. One distance is one draw of two degrees
/// of freedom whatever k: a dense rig's fit is split every fourth sample (at least
/// SPLIT_SAMPLES in the part), at a quarter of a pass's cost, a sparse rig's in halves. One
/// Gauss-Newton step from the answer on the part gives its normal to first order (two passes
/// over its samples instead of a fit). And where the noise-weighted polish ran, how far it
/// moved the normal: both fits estimate the same normal where the lobe describes the
/// material, so a move beyond the noise is the model's error.
fn tilt_uncertainty(
    m: &Model,
    (fine, every): (&Subset, &mut Subset),
    (linear, free): (&Linear, [bool; P]),
    moved2: f64,
    buffers: &mut Buffers,
) -> f64 {
    let sd = scatter_sd(fine, linear, free, buffers);
    let k = (fine.len() / SPLIT_SAMPLES).clamp(2, 4);
    every.gather_every(fine, k);
    let split2 = tilt_step2(m, every, free, buffers) / (k - 1) as f64;
    (sd * sd + split2 + moved2).sqrt()
}

/// The grey value (the sum of the channels) the fitted lobe `fit` predicts under each light
/// of `js` (rig indices), diffuse term included, into `out` (in `js`'s order): what a clipped
/// sample's lower bound is held against (docs/method.md, "Clipped samples in the lobe fit").
pub(crate) fn predicted_greys(
    fit: &LobeFit,
    js: &[u32],
    rig: &Rig,
    scratch: &mut LobeScratch,
    out: &mut Vec<f64>,
) {
    // The fit's state (its widths and shape in the search's coordinates), so the model is the
    // one the fit evaluated.
    let m = Model::of(&State {
        normal: fit.normal,
        tangent: fit.tangent,
        shape: [
            fit.alpha[0].ln(),
            fit.alpha[1].ln(),
            fit.shape.ln(),
            fit.foreshortening,
        ],
    });
    let Probe {
        samples,
        zeros,
        lobe,
        r,
        kept,
    } = &mut scratch.probe;
    zeros.resize(rig.lights_in_camera().len(), 0.0);
    samples.gather(js, rig.lights_in_camera(), rig.halfway_in_camera(), zeros);
    for buffer in [&mut *lobe, &mut *r] {
        buffer.resize(samples.padded_len(), 0.0);
    }
    kernel::sums(&m, samples, lobe, kept);
    let coefficients = [fit.diffuse, fit.specular, fit.fresnel];
    kernel::residuals(&m, samples, coefficients, lobe, r);
    out.clear();
    out.extend(r[..js.len()].iter().map(|v| -v));
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::brdf::{Brdf, Ggx, Layered, Ward};
    use crate::frames::rig::{uniform_cone_lights, Rig, RigOptions};

    /// The slice of `brdf` at a pixel of frame `(n, t)` under `rig` (view `+z`), RGB (the red
    /// channel's value in all three).
    pub(crate) fn slice(rig: &Rig, brdf: &dyn Brdf, n: DVec3, t: DVec3) -> Vec<f32> {
        crate::brdf::testutil::render_pixel(brdf, n, t, rig.lights_in_camera(), 1.0)
            .chunks_exact(3)
            .flat_map(|s| [s[0]; 3])
            .collect()
    }

    fn fit(rig: &Rig, samples: &[f32], start: LobeStart) -> LobeFit {
        fit_lobe(
            samples,
            rig,
            start,
            &NoiseModel::default(),
            &mut LobeScratch::default(),
        )
        .unwrap()
    }

    /// Standard normal draws (xorshift, Box-Muller) from `seed`.
    pub(crate) fn gaussians(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            let mut u = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let (u1, u2) = (u().max(1e-12), u());
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        }
    }

    fn frame() -> (DVec3, DVec3) {
        let n = DVec3::new(0.35, -0.2, 1.0).normalize();
        let (u, w) = tangent_basis(n);
        (n, (u + 0.7 * w).normalize())
    }

    #[test]
    fn a_brushed_lobe_under_a_sparse_rig_gives_its_frame() {
        // Halfway vectors ~4 degrees apart, the lobe ~3 degrees wide across the grooves.
        let rig = Rig::new(&uniform_cone_lights(200, 65.0), RigOptions::default()).unwrap();
        let (n, t) = frame();
        let brdf = Ggx::new([0.02; 3], [0.9; 3], 0.3, 0.06);
        let samples = slice(&rig, &brdf, n, t);
        // Start a few degrees off, with the axes swapped.
        let (u, _) = tangent_basis(n);
        let start = LobeStart {
            normal: (n + 0.06 * u).normalize(),
            tangent: n.cross(t),
            alpha: [0.1, 0.1],
        };
        let f = fit(&rig, &samples, start);
        assert!(f.normal.angle_between(n).to_degrees() < 0.2, "{f:?}");
        assert!(f.tangent.dot(t).abs() > 0.999, "{f:?}");
        assert!(f.elongation() > 0.5 && f.residual < 1e-3, "{f:?}");
    }

    #[test]
    fn the_normal_s_standard_deviation_matches_its_scatter_under_noise() {
        // Gaussian noise of 1% of the peak on a glossy lobe under 500 lights: over 40 draws the
        // RMS angle of the fitted normals from the truth is what `normal_sd` says, within the
        // draws' own spread (the split half adds up to its variance again: at most 1.5x).
        let rig = Rig::new(&uniform_cone_lights(500, 65.0), RigOptions::default()).unwrap();
        let (n, t) = frame();
        let brdf = Ggx::new([0.1; 3], [0.9; 3], 0.2, 0.1);
        let clean = slice(&rig, &brdf, n, t);
        let peak = clean.iter().copied().fold(0.0f32, f32::max) as f64;
        let mut gauss = gaussians(0x2545_f491_4f6c_dd1d);
        let (mut errors2, mut sds2) = (0.0, 0.0);
        let draws = 40;
        for _ in 0..draws {
            let noisy: Vec<f32> = clean
                .chunks_exact(3)
                .flat_map(|s| [(s[0] as f64 + 0.01 * peak * gauss()) as f32; 3])
                .collect();
            let start = LobeStart {
                normal: n,
                tangent: t,
                alpha: [0.2, 0.1],
            };
            let f = fit(&rig, &noisy, start);
            errors2 += f.normal.angle_between(n).powi(2);
            sds2 += f.normal_sd.powi(2);
        }
        let (rms, sd) = (
            (errors2 / draws as f64).sqrt(),
            (sds2 / draws as f64).sqrt(),
        );
        assert!(rms > 0.0 && sd.is_finite(), "{rms} {sd}");
        let ratio = sd / rms;
        assert!((0.75..=2.0).contains(&ratio), "sd {sd} against rms {rms}");
    }

    #[test]
    fn the_noise_share_is_what_shot_and_read_noise_leave() {
        // Shot and read noise drawn per channel as the noise model states it, on a brushed
        // lobe under 1,000 lights: the fit's residual share is the expected noise share
        // (within a fifth, over 10 draws), well above the fixed 0.2%, and within the test's
        // limit in every draw; without the noise model the share is 0.
        let rig = Rig::new(&uniform_cone_lights(1000, 65.0), RigOptions::default()).unwrap();
        let (n, t) = frame();
        let brdf = Ggx::new([0.05; 3], [0.9; 3], 0.25, 0.08);
        let clean = slice(&rig, &brdf, n, t);
        let peak = clean.iter().copied().fold(0.0f32, f32::max) as f64;
        // Full scale at the peak: 200 electrons there (a dim exposure), read noise of 2.
        let noise = NoiseModel {
            shot: 1.0 / 200.0 / 3.0,
            read: (2.0f64 / 200.0).powi(2) / 9.0,
            ..NoiseModel::default()
        };
        let mut gauss = gaussians(0x9e37_79b9_7f4a_7c15);
        let start = LobeStart {
            normal: n,
            tangent: t,
            alpha: [0.25, 0.08],
        };
        let mut ratio = 0.0;
        let draws = 10;
        for _ in 0..draws {
            // Channels in units of full scale (the peak's channel value at 1/3).
            let noisy: Vec<f32> = clean
                .iter()
                .map(|&v| {
                    let v = v as f64 / peak / 3.0;
                    (v + noise.variance(v).sqrt() * gauss()) as f32
                })
                .collect();
            let mut scratch = LobeScratch::default();
            let f = fit_lobe(&noisy, &rig, start, &noise, &mut scratch).unwrap();
            let limit = f.noise_share + 1e-4 + 3.09 * f.noise_share_sd;
            assert!(f.residual > 0.002 && f.residual < limit, "{f:?}");
            ratio += f.residual / f.noise_share / draws as f64;
            let quiet = fit_lobe(&noisy, &rig, start, &NoiseModel::default(), &mut scratch);
            assert_eq!(quiet.unwrap().noise_share, 0.0);
        }
        assert!(
            (0.8..1.2).contains(&ratio),
            "residual / noise share {ratio}"
        );
    }

    /// A pixel of frame `(n, t)` rendered under `lights` each turned by `error` degrees at
    /// random (stream `seed`), as a calibration off by that much would give it: the rig of the
    /// given lights and the samples in its order.
    fn under_turned_lights(
        lights: &[DVec3],
        error: f64,
        seed: u64,
        brdf: &dyn Brdf,
        (n, t): (DVec3, DVec3),
    ) -> (Rig, Vec<f32>) {
        let rig = Rig::new(lights, RigOptions::default()).unwrap();
        let mut turned = Subset::default();
        let halfways: Vec<DVec3> = lights.iter().map(|l| (*l + DVec3::Z).normalize()).collect();
        let ones = vec![1.0; lights.len()];
        let all: Vec<u32> = (0..lights.len() as u32).collect();
        turned.gather(&all, lights, &halfways, &ones);
        turned.jitter_lights(error.to_radians(), seed);
        let true_lights: Vec<DVec3> = (0..lights.len()).map(|i| turned.light(i)).collect();
        let true_rig = Rig::new(&true_lights, RigOptions::default()).unwrap();
        // Rendered under the true lights, in the given rig's order.
        let rendered = slice(&true_rig, brdf, n, t);
        let mut samples = vec![f32::NAN; 3 * rig.lights_in_camera().len()];
        for (k, &j) in true_rig.input_index().iter().enumerate() {
            if let Some(i) = rig.input_index().iter().position(|&x| x == j) {
                samples[3 * i..3 * i + 3].copy_from_slice(&rendered[3 * k..3 * k + 3]);
            }
        }
        (rig, samples)
    }

    #[test]
    fn lights_off_by_their_error_leave_what_the_light_term_expects() {
        // Lights each off by 1 degree at random on a sharp glossy lobe, noise-free otherwise:
        // the fixed 0.2% refuses the fit, the light term of the noise share accepts it.
        let lights = uniform_cone_lights(1000, 65.0);
        let brdf = Ggx::new([0.05; 3], [0.9; 3], 0.08, 0.08);
        let (rig, samples) = under_turned_lights(&lights, 1.0, 7, &brdf, frame());
        let (n, t) = frame();
        let start = LobeStart {
            normal: n,
            tangent: t,
            alpha: [0.08, 0.08],
        };
        let told = NoiseModel {
            light_error_deg: 1.0,
            ..NoiseModel::default()
        };
        let f = fit_lobe(&samples, &rig, start, &told, &mut LobeScratch::default()).unwrap();
        assert!(f.residual > 0.002, "{f:?}");
        assert!(
            f.residual < f.noise_share + 1e-4 + 3.09 * f.noise_share_sd,
            "{f:?}"
        );
    }

    #[test]
    fn the_light_share_is_what_the_lights_error_moves_the_normal_by() {
        // A clear coat over a glossy base under 200 lights, fitted as one lobe (the family
        // cannot hold both, so the fit slides along its shape when the lights turn), lights
        // each off by 1 degree at random (24 draws): the normal moves from where the exact
        // lights put it by what the light share says, as a root mean square over the draws.
        let lights = uniform_cone_lights(200, 65.0);
        let brdf = Layered::new(
            0.03,
            1.5,
            Box::new(Ggx::isotropic([0.3, 0.12, 0.05], [0.3; 3], 0.2)),
        );
        let (n, t) = frame();
        let start = LobeStart {
            normal: n,
            tangent: t,
            alpha: [0.1, 0.1],
        };
        let told = NoiseModel {
            light_error_deg: 1.0,
            ..NoiseModel::default()
        };
        let mut scratch = LobeScratch::default();
        let exact_rig = Rig::new(&lights, RigOptions::default()).unwrap();
        let exact = slice(&exact_rig, &brdf, n, t);
        let at_exact = fit_lobe(&exact, &exact_rig, start, &told, &mut scratch)
            .unwrap()
            .normal;
        let (mut moved2, mut predicted2) = (0.0, 0.0);
        let draws = 24;
        for seed in 0..draws {
            let (rig, samples) = under_turned_lights(&lights, 1.0, seed, &brdf, (n, t));
            let f = fit_lobe(&samples, &rig, start, &told, &mut scratch).unwrap();
            moved2 += f.normal.angle_between(at_exact).powi(2) / draws as f64;
            predicted2 += f.light_sd.powi(2) / draws as f64;
        }
        let ratio = (moved2 / predicted2).sqrt();
        assert!(
            (0.7..1.4).contains(&ratio),
            "moved {:.3} deg rms, light share {:.3} deg rms",
            moved2.sqrt().to_degrees(),
            predicted2.sqrt().to_degrees()
        );
    }

    #[test]
    fn weighting_by_the_lights_error_brings_the_normal_closer() {
        // Lights each off by 1 degree at random, and the shot noise of 4,000 electrons at the
        // peak, on a glossy and a brushed lobe (12 draws each): told the noise and the lights'
        // error, the fit weights each sample by the inverse of its variance (the steep flanks,
        // which the lights' error moves most, least) and its normal is closer to the truth, on
        // average, than the fit that weighs every sample the same.
        let lights = uniform_cone_lights(1000, 65.0);
        let (n, t) = frame();
        let told = NoiseModel {
            shot: 1.0 / 4000.0 / 3.0,
            read: (10.0f64 / 4000.0).powi(2) / 9.0,
            light_error_deg: 1.0,
            ..NoiseModel::default()
        };
        let mut gauss = gaussians(0x2545_f491_4f6c_dd1d);
        let mut sums = [0.0f64; 2];
        for (brdf, alpha) in [
            (Ggx::new([0.05; 3], [0.9; 3], 0.12, 0.12), [0.12, 0.12]),
            (Ggx::new([0.05; 3], [0.9; 3], 0.25, 0.08), [0.25, 0.08]),
        ] {
            let start = LobeStart {
                normal: n,
                tangent: t,
                alpha,
            };
            let (mut weighted, mut even) = (0.0, 0.0);
            let mut scratch = LobeScratch::default();
            for seed in 0..12 {
                let (rig, clean) = under_turned_lights(&lights, 1.0, seed, &brdf, (n, t));
                let peak = clean.iter().copied().fold(0.0f32, f32::max) as f64;
                // Channels in units of full scale (the peak's channel value at 1/3).
                let samples: Vec<f32> = clean
                    .iter()
                    .map(|&v| {
                        let v = v as f64 / peak / 3.0;
                        (v + told.variance(v).sqrt() * gauss()) as f32
                    })
                    .collect();
                let mut error = |noise: &NoiseModel| {
                    let f = fit_lobe(&samples, &rig, start, noise, &mut scratch).unwrap();
                    f.normal.angle_between(n).to_degrees()
                };
                weighted += error(&told);
                even += error(&NoiseModel::default());
            }
            assert!(weighted < even, "{weighted} vs {even} (sums of degrees)");
            sums = [sums[0] + weighted, sums[1] + even];
        }
        assert!(sums[0] < 0.92 * sums[1], "{sums:?}");
    }

    #[test]
    fn tilt_sd_is_the_covariance_of_the_first_two_parameters() {
        // J^T J diagonal: the variances are s^2 / J^T J_kk.
        let mut jtj = [[0.0; 3]; 3];
        jtj[0][0] = 4.0;
        jtj[1][1] = 1.0;
        jtj[2][2] = 9.0;
        let sd = tilt_sd(&jtj, 10.0, 10.0);
        assert!((sd - (0.25f64 + 1.0).sqrt()).abs() < 1e-6, "{sd}");
        assert_eq!(tilt_sd(&jtj, 10.0, 0.0), f64::INFINITY);
    }

    #[test]
    fn a_ward_lobe_and_a_cast_shadow_are_explained() {
        let rig = Rig::new(&uniform_cone_lights(400, 65.0), RigOptions::default()).unwrap();
        let (n, t) = frame();
        // Ward's lobe is not a microfacet one (it carries (n.l)^(1/2)).
        let ward = Ward::new([0.3; 3], [0.5; 3], 0.1, 0.3);
        let mut samples = slice(&rig, &ward, n, t);
        let start = LobeStart {
            normal: n,
            tangent: t,
            alpha: [0.2, 0.1],
        };
        let f = fit(&rig, &samples, start);
        assert!(f.normal.angle_between(n).to_degrees() < 0.3, "{f:?}");
        assert!(f.residual < 1e-3, "{f:?}");
        // Something blocks the lights on one side (a cast shadow): those samples go dark.
        for (s, l) in samples.chunks_exact_mut(3).zip(rig.lights_in_camera()) {
            if l.x < -0.3 && l.dot(n) > 0.2 {
                s.fill(0.0);
            }
        }
        let shadowed = fit(&rig, &samples, start);
        assert!(
            shadowed.normal.angle_between(n).to_degrees() < 0.3,
            "{shadowed:?}"
        );
        assert!(shadowed.residual < 1e-3, "{shadowed:?}");
    }

    #[test]
    fn nnls_keeps_coefficients_non_negative() {
        // y = 2 a exactly, with b anti-correlated: the unconstrained answer would go negative.
        let g = [[1.0, -0.5, 0.0], [-0.5, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let fit = nnls3(g, [2.0, -1.0, 0.0], 4.0);
        let (x, r) = (fit.coefficients, fit.cost);
        assert!(x.iter().all(|&v| v >= 0.0), "{x:?}");
        assert!((x[0] - 2.0).abs() < 1e-12 && r.abs() < 1e-12, "{x:?} {r}");
        assert_eq!(fit.set, 1);
    }
}
