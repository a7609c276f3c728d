//! The samples a lobe fit reads ([`Subset`]): one subset of a pixel's lights as columns (light
//! and halfway vectors, Fresnel weight, grey value, weight), padded to whole blocks of
//! [`LANES`] for the sample loops (`kernel`), and the same samples under turned lights; which
//! of a pixel's lights a fit reads ([`choose_lights`]).

use std::sync::atomic::{AtomicU64, Ordering};

use glam::DVec3;

use super::lanes::LANES;
use super::{
    LobeScratch, COARSE_HIGHLIGHT, COARSE_SPREAD, HIGHLIGHT_LIGHTS, HIGHLIGHT_SHARE, SPREAD_LIGHTS,
};
use crate::frames::rig::Rig;

/// The samples of one subset of the lights, as columns: light and halfway vectors (camera
/// frame), Schlick's Fresnel weight of the halfway vector, the grey value and a weight (1 for a
/// sample, 0 for the padding that completes the last block).
#[derive(Debug, Clone, Default)]
pub(super) struct Subset {
    pub(super) l: [Vec<f64>; 3],
    pub(super) h: [Vec<f64>; 3],
    pub(super) fresnel: Vec<f64>,
    pub(super) y: Vec<f64>,
    pub(super) w: Vec<f64>,
    pub(super) len: usize,
    /// Which samples these are: new whenever they change (the kept terms name them).
    pub(super) id: u64,
}

/// A fresh identity for a subset's samples.
fn next_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// The lights the fit reads, gathered into `scratch`'s fine and coarse subsets (with their
/// grey values, NaN where invalid): an evenly spread prefix of the rig's query order, and the
/// highlight's lights (at most `HIGHLIGHT_LIGHTS`, evenly over it); the brightest sample's
/// light, or `None` where nothing is lit or the coarse subset has fewer than eight samples.
pub(super) fn choose_lights(
    samples: &[f32],
    rig: &Rig,
    scratch: &mut LobeScratch,
) -> Option<usize> {
    let (lights, halfways, spread) = (
        rig.lights_in_camera(),
        rig.halfway_in_camera(),
        rig.query_order(),
    );
    let LobeScratch {
        fine,
        coarse,
        chosen,
        greys,
        fine_lights,
        coarse_lights,
        ..
    } = scratch;
    // The grey values once (NaN where invalid): the passes below read them several times.
    greys.clear();
    greys.extend(
        samples[..lights.len() * 3]
            .chunks_exact(3)
            .map(|s| s[0] as f64 + s[1] as f64 + s[2] as f64),
    );
    let greys = &*greys;
    let grey = |j: usize| {
        let v = greys[j];
        v.is_finite().then_some(v)
    };
    let (mut max, mut brightest) = (0.0, 0);
    for j in 0..lights.len() {
        if let Some(v) = grey(j).filter(|&v| v > max) {
            (max, brightest) = (v, j);
        }
    }
    if max <= 0.0 {
        return None;
    }
    // 0: not read; 1: the fine subset; 2: the coarse one too.
    chosen.clear();
    chosen.resize(lights.len(), 0);
    for (k, &j) in spread.iter().take(SPREAD_LIGHTS).enumerate() {
        chosen[j as usize] = if k < COARSE_SPREAD { 2 } else { 1 };
    }
    // A broad highlight under a dense rig holds hundreds of lights: at most HIGHLIGHT_LIGHTS of
    // them are read, the first in the spread order (so evenly over the highlight).
    let mut highlight = 0;
    for &j in spread {
        let j = j as usize;
        if chosen[j] != 0 || !grey(j).is_some_and(|v| v >= HIGHLIGHT_SHARE * max) {
            continue;
        }
        if highlight == HIGHLIGHT_LIGHTS {
            break;
        }
        chosen[j] = if highlight < COARSE_HIGHLIGHT { 2 } else { 1 };
        highlight += 1;
    }
    // The chosen valid lights, in rig order.
    fine_lights.clear();
    coarse_lights.clear();
    for (j, &c) in chosen.iter().enumerate() {
        if c == 0 || grey(j).is_none() {
            continue;
        }
        fine_lights.push(j as u32);
        if c == 2 {
            coarse_lights.push(j as u32);
        }
    }
    fine.gather(fine_lights, lights, halfways, greys);
    coarse.gather(coarse_lights, lights, halfways, greys);
    (coarse.len() >= 8).then_some(brightest)
}

impl Subset {
    fn columns(&mut self) -> [&mut Vec<f64>; 9] {
        let [lx, ly, lz] = &mut self.l;
        let [hx, hy, hz] = &mut self.h;
        [
            lx,
            ly,
            lz,
            hx,
            hy,
            hz,
            &mut self.fresnel,
            &mut self.y,
            &mut self.w,
        ]
    }

    /// Makes the samples those of lights `js`, in that order: light and halfway vectors from
    /// `lights` and `halfways`, values from `y` (all indexed by light), padded. Column by column,
    /// faster than appending sample by sample to nine columns (docs/performance.md,
    /// "Rig-built layouts").
    pub(super) fn gather(&mut self, js: &[u32], lights: &[DVec3], halfways: &[DVec3], y: &[f64]) {
        fn fill(column: &mut Vec<f64>, js: &[u32], value: impl Fn(usize) -> f64) {
            column.clear();
            column.extend(js.iter().map(|&j| value(j as usize)));
        }
        let [lx, ly, lz] = &mut self.l;
        fill(lx, js, |j| lights[j].x);
        fill(ly, js, |j| lights[j].y);
        fill(lz, js, |j| lights[j].z);
        let [hx, hy, hz] = &mut self.h;
        fill(hx, js, |j| halfways[j].x);
        fill(hy, js, |j| halfways[j].y);
        fill(hz, js, |j| halfways[j].z);
        fill(&mut self.fresnel, js, |j| schlick(halfways[j]));
        fill(&mut self.y, js, |j| y[j]);
        fill(&mut self.w, js, |_| 1.0);
        self.len = js.len();
        self.id = next_id();
        self.pad();
    }

    /// Completes the last block with empty samples.
    fn pad(&mut self) {
        let padded = self.len.div_ceil(LANES) * LANES;
        // An empty sample: weight 0, no light, behind every normal the fit can reach.
        let values = [0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
        for (v, x) in self.columns().into_iter().zip(values) {
            v.resize(padded, x);
        }
    }

    fn truncate(&mut self, len: usize) {
        for v in self.columns() {
            v.truncate(len);
        }
    }

    /// Number of samples (without the padding).
    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// Number of samples with the padding: the length of the per-sample buffers.
    pub(super) fn padded_len(&self) -> usize {
        self.y.len()
    }

    /// Light of sample `i`.
    pub(super) fn light(&self, i: usize) -> DVec3 {
        DVec3::new(self.l[0][i], self.l[1][i], self.l[2][i])
    }

    /// Halfway vector of sample `i`.
    pub(super) fn halfway(&self, i: usize) -> DVec3 {
        DVec3::new(self.h[0][i], self.h[1][i], self.h[2][i])
    }

    /// Schlick's Fresnel weight of sample `i` ([`schlick`] of its halfway vector).
    pub(super) fn fresnel(&self, i: usize) -> f64 {
        self.fresnel[i]
    }

    /// Grey value of sample `i`.
    pub(super) fn value(&self, i: usize) -> f64 {
        self.y[i]
    }

    /// Sum of the squared values.
    pub(super) fn energy(&self) -> f64 {
        self.y.iter().map(|v| v * v).sum()
    }

    /// Makes the samples every `step`-th of `from`'s (its first, then every `step` on), padded:
    /// a nested part of `from` for its split.
    pub(super) fn gather_every(&mut self, from: &Subset, step: usize) {
        let step = step.max(1);
        self.len = from.len.div_ceil(step);
        let len = self.len;
        for (column, source) in self.columns().into_iter().zip(from.columns_ref()) {
            column.clear();
            column.extend(source[..from.len].iter().step_by(step).copied());
            debug_assert_eq!(column.len(), len);
        }
        self.id = next_id();
        self.pad();
    }

    fn columns_ref(&self) -> [&Vec<f64>; 9] {
        let [lx, ly, lz] = &self.l;
        let [hx, hy, hz] = &self.h;
        [lx, ly, lz, hx, hy, hz, &self.fresnel, &self.y, &self.w]
    }

    /// Keeps the samples for which `keep(i)` holds, in order, and pads again.
    pub(super) fn retain(&mut self, keep: impl Fn(usize) -> bool) {
        let mut kept = 0;
        for i in 0..self.len {
            if keep(i) {
                for v in self.columns() {
                    v[kept] = v[i];
                }
                kept += 1;
            }
        }
        self.len = kept;
        self.id = next_id();
        self.truncate(kept);
        self.pad();
    }
}

impl Subset {
    /// Makes the samples `from`'s weighted by `weights` (one per sample, without the padding):
    /// each value and each basis function scaled by the weight's root, so that the fit's sum of
    /// squares becomes `sum w_i r_i^2` (a weighted least squares, the variable projection
    /// unchanged).
    pub(super) fn weighted(&mut self, from: &Subset, weights: &[f64]) {
        self.clone_from(from);
        for (i, &w) in weights.iter().enumerate().take(self.len) {
            let root = w.max(0.0).sqrt();
            self.y[i] *= root;
            self.w[i] *= root;
        }
        self.id = next_id();
    }
}

impl Subset {
    /// Makes the samples `from`'s with their lights turned ([`Subset::jitter_lights`]).
    pub(super) fn turned_from(&mut self, from: &Subset, sd: f64, seed: u64) {
        self.clone_from(from);
        self.jitter_lights(sd, seed);
    }

    /// Turns every sample's light by a random angle (each of its two components normal with
    /// standard deviation `sd / sqrt(2)` radians: `sd` the RMS angle) from the stream `seed`,
    /// and recomputes its halfway vector and Fresnel weight: the samples as a calibration off
    /// by `sd` would have placed them.
    pub(super) fn jitter_lights(&mut self, sd: f64, seed: u64) {
        let mut state = seed;
        let mut normal = move || {
            // splitmix64, then Box-Muller (one of the pair).
            let mut next = || {
                state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
                let mut z = state;
                z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
                ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
            };
            let (u1, u2) = (next().max(1e-300), next());
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        let s = sd / std::f64::consts::SQRT_2;
        for i in 0..self.len {
            let l = self.light(i);
            let (u, w) = crate::geometry::tangent_basis(l);
            let moved = (l + u * (s * normal()) + w * (s * normal())).normalize();
            let h = (moved + DVec3::Z).normalize();
            for (k, v) in moved.to_array().into_iter().enumerate() {
                self.l[k][i] = v;
            }
            for (k, v) in h.to_array().into_iter().enumerate() {
                self.h[k][i] = v;
            }
            self.fresnel[i] = schlick(h);
        }
        self.id = next_id();
    }
}

/// Schlick's Fresnel weight `(1 - h.v)^5` of a halfway vector (view `+z`): the lobe's
/// second basis function is the lobe times it, so that `s1 + s2 (1 - h.v)^5 = s (f0 + (1 - f0)
/// (1 - h.v)^5)` brightens grazing reflections as a dielectric's Fresnel term does (and
/// barely at all for a metal's, `s2 ~ 0`), with both coefficients linear.
pub(super) fn schlick(h: DVec3) -> f64 {
    let c = (1.0 - h.z).clamp(0.0, 1.0);
    let c2 = c * c;
    c2 * c2 * c
}
