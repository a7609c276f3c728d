//! The per-pixel symmetry objective as the estimator reads it, behind one trait with two
//! implementations:
//!
//! - [`ExactObjective`], the reference path: [`symmetry_term`] in double precision, with
//!   triangle lookups and spherical barycentric weights at every query.
//! - [`FastObjective`], the fast path: the same spherical barycentric interpolation in single
//!   precision, located by a walk from a grid cell ([`FastLocator`]), the lights
//!   structure-of-arrays, invalid samples dropped up front, both tangent terms in one pass, and
//!   coarse levels summing over a prefix of [`Rig::query_order`] only (an evenly spread subset
//!   of the lights: the coarse-to-fine search's first stages).
//!
//! The fast kernel is written by hand rather than through [`symmetry_term`]'s generic lookup:
//! it is the whole cost of an estimate (the profile of the generic path: half in the lookups,
//! half in the per-light geometry in f64), and this layout's geometry loops vectorise
//! (docs/performance.md, "Where the time went"; `cargo bench -p symframe --bench pixel`).

use std::cell::RefCell;

use glam::{DVec3, Vec3, Vec4};

use crate::frames::rig::{Coverage, FastLocator, Rig};
use crate::frames::slice::{ExactSlice, SliceLookup};
use crate::frames::symmetry::{
    symmetry_term, symmetry_term_over, CosineMode, Frame, Symmetry, SymmetryTerm,
};

/// Which lights an evaluation sums over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Level {
    /// The first `m` valid lights of [`Rig::query_order`], an evenly spread subset: for
    /// locating the minimum. The reference path sums over every light here too.
    Coarse(usize),
    /// Every light: for the final solution and the reported figures.
    Full,
}

/// A pixel's symmetry objective.
pub(crate) trait Objective {
    /// How many valid lights an evaluation at `level` visits (domains scale with it).
    fn queries(&self, level: Level) -> usize;
    /// The `SD_n` sums at a candidate normal.
    fn normal_term(&self, n: DVec3, cosine: CosineMode, level: Level) -> SymmetryTerm;
    /// The `SD_nt` and `SD_nb` sums at a candidate frame.
    fn tangent_terms(&self, frame: Frame, cosine: CosineMode, level: Level) -> [SymmetryTerm; 2];
    /// The slice's value at a unit halfway vector (`None` where there is no data).
    fn value(&self, halfway: DVec3) -> Option<[f64; 3]>;
}

/// The reference objective: [`symmetry_term`] in double precision with exact lookups
/// (triangle location and spherical barycentric weights at every query). Its coarse levels sum
/// over the same prefix of [`Rig::query_order`] as the fast path's, so the two run the same
/// search and differ only in how they read the slice.
#[derive(Debug, Clone)]
pub(crate) struct ExactObjective<'a> {
    rig: &'a Rig,
    slice: ExactSlice<'a>,
    /// The valid lights in query order.
    order: Vec<u32>,
}

impl<'a> ExactObjective<'a> {
    /// The objective of one pixel's slice (rig order, `rig.n_used() * 3` values, NaN = invalid).
    pub(crate) fn new(rig: &'a Rig, samples: &'a [f32]) -> Self {
        let order = rig
            .query_order()
            .iter()
            .copied()
            .filter(|&j| samples[j as usize * 3].is_finite())
            .collect();
        Self {
            rig,
            slice: ExactSlice { rig, samples },
            order,
        }
    }

    fn term(&self, s: Symmetry, frame: Frame, cosine: CosineMode, level: Level) -> SymmetryTerm {
        let (rig, samples) = (self.rig, self.slice.samples);
        match level {
            Level::Full => symmetry_term(rig, samples, &self.slice, s, frame, cosine),
            Level::Coarse(m) => {
                let lights = self.order[..m.min(self.order.len())]
                    .iter()
                    .map(|&j| j as usize);
                symmetry_term_over(rig, samples, &self.slice, s, frame, cosine, lights)
            }
        }
    }
}

impl Objective for ExactObjective<'_> {
    fn queries(&self, level: Level) -> usize {
        match level {
            Level::Coarse(m) => m.min(self.order.len()),
            Level::Full => self.order.len(),
        }
    }

    fn normal_term(&self, n: DVec3, cosine: CosineMode, level: Level) -> SymmetryTerm {
        let frame = Frame::new(n, crate::geometry::tangent_basis(n).0);
        self.term(Symmetry::N, frame, cosine, level)
    }

    fn tangent_terms(&self, frame: Frame, cosine: CosineMode, level: Level) -> [SymmetryTerm; 2] {
        [
            self.term(Symmetry::Nt, frame, cosine, level),
            self.term(Symmetry::Nb, frame, cosine, level),
        ]
    }

    fn value(&self, halfway: DVec3) -> Option<[f64; 3]> {
        self.slice.value(halfway)
    }
}

/// Per-thread buffers of the fast path, reused from pixel to pixel.
#[derive(Debug, Clone)]
pub(crate) struct FastScratch {
    /// The pixel's samples in rig order as RGB_ lanes (NaN where invalid): what the lookups read.
    lanes: Vec<Vec4>,
    hx: Vec<f32>,
    hy: Vec<f32>,
    hz: Vec<f32>,
    samples: Vec<Vec4>,
    focus: RefCell<Focus>,
}

impl FastScratch {
    /// Buffers sized for `rig`.
    pub(crate) fn new(rig: &Rig) -> Self {
        let n = rig.n_used();
        Self {
            lanes: Vec::with_capacity(n),
            hx: Vec::with_capacity(n),
            hy: Vec::with_capacity(n),
            hz: Vec::with_capacity(n),
            samples: Vec::with_capacity(n),
            focus: RefCell::new(Focus::default()),
        }
    }

    /// Prepares the fast objective of one pixel's slice (rig order, `rig.n_used() * 3` values,
    /// NaN = invalid): lays out its samples for the lookups, and its valid lights coarse subset
    /// first.
    pub(crate) fn prepare<'a>(&'a mut self, rig: &'a Rig, samples: &[f32]) -> FastObjective<'a> {
        self.lanes.clear();
        let mut all_valid = true;
        self.lanes.extend(samples.chunks_exact(3).map(|s| {
            if s[0].is_finite() {
                Vec4::new(s[0], s[1], s[2], 0.0)
            } else {
                all_valid = false;
                Vec4::NAN
            }
        }));
        self.samples.clear();
        // Every sample valid (most pixels): the halfway vectors in query order are the rig's.
        let [hx, hy, hz] = if all_valid {
            let lanes = &self.lanes;
            self.samples
                .extend(rig.query_order().iter().map(|&j| lanes[j as usize]));
            rig.query_halfways()
        } else {
            self.hx.clear();
            self.hy.clear();
            self.hz.clear();
            for &j in rig.query_order() {
                let j = j as usize;
                let s = &samples[j * 3..j * 3 + 3];
                if !s[0].is_finite() {
                    continue;
                }
                let h = rig.halfway_in_camera()[j];
                self.hx.push(h.x as f32);
                self.hy.push(h.y as f32);
                self.hz.push(h.z as f32);
                self.samples.push(Vec4::new(s[0], s[1], s[2], 0.0));
            }
            [&self.hx[..], &self.hy[..], &self.hz[..]]
        };
        self.focus.get_mut().built = false;
        FastObjective {
            locator: rig.fast(),
            coverage: rig.coverage(),
            lanes: &self.lanes,
            hx,
            hy,
            hz,
            samples: &self.samples,
            cos_max: rig.cos_theta_d_max() as f32,
            focus: &self.focus,
        }
    }
}

/// The lights that can be in the `SD_n` domain for any normal within [`FOCUS_RADIUS_DEG`] of a
/// centre normal: a full-level `SD_n` near the centre sums over these only, the same domain at a
/// fraction of the cost where the domain is small (normals far from the view, whose full-level
/// searches otherwise visit every light for a hundred in the domain).
///
/// The reflection of `h` about `n` is in the cone exactly when `h` is within `theta_d_max` of
/// the view reflected about `n`, `z'(n) = 2 n.z n - z`, which moves at most twice as far as `n`:
/// lights farther than `theta_d_max + 2 * radius` from `z'(centre)` are never in the domain.
#[derive(Debug, Clone, Default)]
struct Focus {
    /// Whether `centre` and the lights are this pixel's.
    built: bool,
    centre: DVec3,
    /// Whether the subset is small enough to be worth using (else the full level runs).
    useful: bool,
    hx: Vec<f32>,
    hy: Vec<f32>,
    hz: Vec<f32>,
    samples: Vec<Vec4>,
}

/// Radius of a [`Focus`] (degrees): a focus is rebuilt when a full-level `SD_n` is asked for
/// farther than this from its centre.
const FOCUS_RADIUS_DEG: f64 = 4.0;

/// A focus is used where it keeps at most this share of the lights.
const FOCUS_MAX_SHARE: f64 = 0.7;

impl Focus {
    fn covers(&self, n: DVec3) -> bool {
        self.built && n.dot(self.centre) >= FOCUS_RADIUS_DEG.to_radians().cos()
    }

    /// Collects the lights of `all` that can be in the domain near `centre`.
    fn build(&mut self, centre: DVec3, all: &FastObjective) {
        self.built = true;
        self.centre = centre;
        // A tenth of a degree more for the single-precision test.
        let reach = (all.cos_max as f64).acos() + (2.0 * FOCUS_RADIUS_DEG + 0.1).to_radians();
        self.useful = false;
        if reach >= std::f64::consts::PI {
            return;
        }
        let z = (2.0 * centre.z * centre - DVec3::Z).as_vec3();
        let cos_reach = reach.cos() as f32;
        self.hx.clear();
        self.hy.clear();
        self.hz.clear();
        self.samples.clear();
        for (k, &s) in all.samples.iter().enumerate() {
            let h = Vec3::new(all.hx[k], all.hy[k], all.hz[k]);
            if h.dot(z) > cos_reach {
                self.hx.push(h.x);
                self.hy.push(h.y);
                self.hz.push(h.z);
                self.samples.push(s);
            }
        }
        self.useful = (self.samples.len() as f64) < FOCUS_MAX_SHARE * all.samples.len() as f64;
    }
}

/// The fast objective of one pixel (see the module documentation); made by
/// [`FastScratch::prepare`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct FastObjective<'a> {
    locator: &'a FastLocator,
    coverage: &'a Coverage,
    lanes: &'a [Vec4],
    hx: &'a [f32],
    hy: &'a [f32],
    hz: &'a [f32],
    samples: &'a [Vec4],
    cos_max: f32,
    focus: &'a RefCell<Focus>,
}

impl Objective for FastObjective<'_> {
    fn queries(&self, level: Level) -> usize {
        match level {
            Level::Coarse(m) => m.min(self.samples.len()),
            Level::Full => self.samples.len(),
        }
    }

    fn normal_term(&self, n: DVec3, cosine: CosineMode, level: Level) -> SymmetryTerm {
        let frame = Frame::new(n, DVec3::ZERO);
        if level == Level::Full {
            // Over the focus around `n` where that is smaller: the same domain.
            let mut focus = self.focus.borrow_mut();
            if !focus.covers(n) {
                focus.build(n, self);
            }
            if focus.useful {
                let subset = FastObjective {
                    hx: &focus.hx,
                    hy: &focus.hy,
                    hz: &focus.hz,
                    samples: &focus.samples,
                    ..*self
                };
                return subset.run::<false>(frame, cosine, level)[0];
            }
        }
        let [term, _] = self.run::<false>(frame, cosine, level);
        term
    }

    fn tangent_terms(&self, frame: Frame, cosine: CosineMode, level: Level) -> [SymmetryTerm; 2] {
        self.run::<true>(frame, cosine, level)
    }

    fn value(&self, halfway: DVec3) -> Option<[f64; 3]> {
        let h = halfway.as_vec3();
        let h = h.to_array();
        let v = self.interpolate(self.locator.start_of(h), h)?;
        Some([v.x as f64, v.y as f64, v.z as f64])
    }
}

/// The cosine weights `(wa, wb)` of a light and its reflection from `n.l` and `n.G(l)`.
trait Weights {
    /// Whether a diffuse term is removed ([`CosineMode::Compensated`]).
    const COMPENSATED: bool;
    fn weights(&self, n_dot_l: f32, n_dot_lr: f32) -> (f32, f32);
}

struct CrossWeights;
impl Weights for CrossWeights {
    const COMPENSATED: bool = false;
    #[inline(always)]
    fn weights(&self, n_dot_l: f32, n_dot_lr: f32) -> (f32, f32) {
        (n_dot_lr, n_dot_l)
    }
}

struct PowerWeights<const COMPENSATED: bool>(f32);
impl<const C: bool> Weights for PowerWeights<C> {
    const COMPENSATED: bool = C;
    #[inline(always)]
    fn weights(&self, n_dot_l: f32, n_dot_lr: f32) -> (f32, f32) {
        // Ward's exact power (and the compensated default) without a powf per light.
        if self.0 == 0.5 {
            (n_dot_lr.sqrt(), n_dot_l.sqrt())
        } else if self.0 == 0.0 {
            (1.0, 1.0)
        } else if self.0 == 1.0 {
            (n_dot_lr, n_dot_l)
        } else {
            (n_dot_lr.powf(self.0), n_dot_l.powf(self.0))
        }
    }
}

/// Lights per single-precision partial sum before it is added to the double-precision total.
const BLOCK: usize = 64;

/// Running sums of one symmetry term: f32 lanes within a block, f64 across blocks.
#[derive(Default)]
struct Accumulator {
    num: Vec4,
    den: Vec4,
    diffuse_dot: Vec4,
    diffuse_sq: f32,
    count: u32,
    total_num: f64,
    total_den: f64,
    total_diffuse_dot: [f64; 3],
    total_diffuse_sq: f64,
}

impl Accumulator {
    #[inline(always)]
    fn add<W: Weights>(&mut self, s: Vec4, reflected: Vec4, wa: f32, wb: f32, diffuse: f32) {
        let a = s * wa;
        let d = a - reflected * wb;
        self.num += d * d;
        self.den += a * a;
        if W::COMPENSATED {
            self.diffuse_dot += d * diffuse;
            self.diffuse_sq += diffuse * diffuse;
        }
        self.count += 1;
    }

    #[inline(always)]
    fn flush(&mut self) {
        self.total_num += lanes_sum(self.num);
        self.total_den += lanes_sum(self.den);
        for (t, v) in self
            .total_diffuse_dot
            .iter_mut()
            .zip(self.diffuse_dot.to_array())
        {
            *t += v as f64;
        }
        self.total_diffuse_sq += self.diffuse_sq as f64;
        self.num = Vec4::ZERO;
        self.den = Vec4::ZERO;
        self.diffuse_dot = Vec4::ZERO;
        self.diffuse_sq = 0.0;
    }

    fn finish(mut self, compensated: bool) -> SymmetryTerm {
        self.flush();
        let mut term = SymmetryTerm {
            numerator: self.total_num,
            denominator: self.total_den,
            count: self.count,
        };
        if compensated && self.total_diffuse_sq > 1e-12 * self.count as f64 {
            // As in `symmetry_term`: the least-squares non-negative diffuse albedo's part of
            // the difference is removed.
            for dd in self.total_diffuse_dot {
                if dd > 0.0 {
                    term.numerator -= dd * dd / self.total_diffuse_sq;
                }
            }
            term.numerator = term.numerator.max(0.0);
        }
        term
    }
}

#[inline(always)]
fn lanes_sum(v: Vec4) -> f64 {
    (v.x as f64 + v.y as f64) + (v.z as f64 + v.w as f64)
}

impl FastObjective<'_> {
    fn run<const TANGENTS: bool>(
        &self,
        frame: Frame,
        cosine: CosineMode,
        level: Level,
    ) -> [SymmetryTerm; 2] {
        match cosine {
            CosineMode::CrossMultiplied | CosineMode::Auto => {
                self.dispatch::<TANGENTS, _>(frame, level, CrossWeights)
            }
            CosineMode::Raw => {
                self.dispatch::<TANGENTS, _>(frame, level, PowerWeights::<false>(0.0))
            }
            CosineMode::Power(p) => {
                self.dispatch::<TANGENTS, _>(frame, level, PowerWeights::<false>(p as f32))
            }
            CosineMode::Compensated(p) => {
                self.dispatch::<TANGENTS, _>(frame, level, PowerWeights::<true>(p as f32))
            }
        }
    }

    /// The kernel compiled for AVX2 where the processor has it (the geometry loops run 8
    /// lights wide instead of 4; docs/performance.md, "Where the time went"), else for the
    /// baseline.
    /// Both compute the same operations in the same order: identical results.
    #[inline(always)]
    fn dispatch<const TANGENTS: bool, W: Weights>(
        &self,
        frame: Frame,
        level: Level,
        weights: W,
    ) -> [SymmetryTerm; 2] {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2")]
            fn avx2<const T: bool, W: Weights>(
                objective: &FastObjective,
                frame: Frame,
                level: Level,
                weights: W,
            ) -> [SymmetryTerm; 2] {
                objective.kernel::<T, W>(frame, level, weights)
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor supports AVX2 (checked just above).
                return unsafe { avx2::<TANGENTS, W>(self, frame, level, weights) };
            }
        }
        self.kernel::<TANGENTS, W>(frame, level, weights)
    }

    /// The sums of `SD_n` (`TANGENTS` false; the second term is empty) or of `SD_nt` and
    /// `SD_nb` (`TANGENTS` true), with the domain rules of [`symmetry_term`]: `n.l > 0`, the
    /// reflection inside the cone with `n.G(l) > 0` and data there.
    ///
    /// Block by block: first the geometry of every light of the block (branch-free arithmetic
    /// on arrays, which the compiler vectorises), then the lookups and sums for the lights in
    /// the domain.
    #[inline(always)]
    fn kernel<const TANGENTS: bool, W: Weights>(
        &self,
        frame: Frame,
        level: Level,
        weights: W,
    ) -> [SymmetryTerm; 2] {
        let len = self.queries(level);
        let n = frame.n.as_vec3();
        let (t, b) = (frame.t.as_vec3(), frame.b.as_vec3());
        let mut first = Accumulator::default();
        let mut second = Accumulator::default();
        let mut hn = [0.0f32; BLOCK];
        let mut nl = [0.0f32; BLOCK];
        let mut reflections = Reflections::default();
        for start in (0..len).step_by(BLOCK) {
            let end = (start + BLOCK).min(len);
            let (hx, hy, hz) = (
                &self.hx[start..end],
                &self.hy[start..end],
                &self.hz[start..end],
            );
            let samples = &self.samples[start..end];
            let m = end - start;
            // n.h, and n.l with l = 2 (h.v) h - v, v = z.
            for ((((a, l), &x), &y), &z) in
                hn[..m].iter_mut().zip(&mut nl[..m]).zip(hx).zip(hy).zip(hz)
            {
                *a = x * n.x + y * n.y + z * n.z;
                *l = 2.0 * z * *a - n.z;
            }
            if TANGENTS {
                // Across the n-t plane: h - 2 (h.b) b; across the n-b plane: h - 2 (h.t) t.
                for (axis, acc) in [(b, &mut first), (t, &mut second)] {
                    self.reflections(&mut reflections, &weights, m, &hn, &nl, n.z, |k| {
                        let d = 2.0 * (hx[k] * axis.x + hy[k] * axis.y + hz[k] * axis.z);
                        (hx[k] - d * axis.x, hy[k] - d * axis.y, hz[k] - d * axis.z)
                    });
                    self.accumulate::<W>(&mut reflections, samples, m, acc);
                }
            } else {
                // Across the normal axis: 2 (h.n) n - h.
                self.reflections(&mut reflections, &weights, m, &hn, &nl, n.z, |k| {
                    let d = 2.0 * hn[k];
                    (d * n.x - hx[k], d * n.y - hy[k], d * n.z - hz[k])
                });
                self.accumulate::<W>(&mut reflections, samples, m, &mut first);
            }
        }
        [first.finish(W::COMPENSATED), second.finish(W::COMPENSATED)]
    }

    /// The geometry of one reflection for the `m` lights of a block: the reflected halfway
    /// vector and its locator cell, cosine weights, and whether the light is in
    /// the domain (`n.l > 0`, inside the cone, `n.G(l) > 0`). Every reflected halfway vector
    /// keeps its angle to n, so `n.G(l) = 2 r.z (h.n) - n.z`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn reflections<W: Weights>(
        &self,
        out: &mut Reflections,
        weights: &W,
        m: usize,
        hn: &[f32; BLOCK],
        nl: &[f32; BLOCK],
        nz: f32,
        reflect: impl Fn(usize) -> (f32, f32, f32),
    ) {
        let (cells, coverage_cells) = (&self.locator.grid, &self.coverage.grid);
        // Slices of exactly `m` elements: no bounds checks in the loop, so it vectorises.
        let (hn, nl) = (&hn[..m], &nl[..m]);
        let coverage = &mut out.coverage[..m];
        let (cell, rx_out, ry_out, rz_out) = (
            &mut out.cell[..m],
            &mut out.rx[..m],
            &mut out.ry[..m],
            &mut out.rz[..m],
        );
        let (wa_out, wb_out) = (&mut out.wa[..m], &mut out.wb[..m]);
        let (diffuse, inside_out) = (&mut out.diffuse[..m], &mut out.inside[..m]);
        for k in 0..m {
            let (rx, ry, rz) = reflect(k);
            let nlr = 2.0 * rz * hn[k] - nz;
            let inside = (nl[k] > 0.0) & (rz > self.cos_max) & (nlr > 0.0);
            // The locator's and the coverage grid's cells, clamped so they are always valid.
            cell[k] = cells.cell_clamped(rx, ry, rz);
            coverage[k] = coverage_cells.cell_clamped(rx, ry, rz);
            rx_out[k] = rx;
            ry_out[k] = ry;
            rz_out[k] = rz;
            let (wa, wb) = weights.weights(nl[k].max(0.0), nlr.max(0.0));
            wa_out[k] = wa;
            wb_out[k] = wb;
            diffuse[k] = wa * nl[k] - wb * nlr;
            inside_out[k] = inside;
        }
    }

    /// Looks up the reflections of a block and adds the domain's lights to `acc`.
    ///
    /// In passes, so that the loads of different lights overlap: the domain's lights compacted,
    /// then the weights in each one's starting triangle (no branches), then the few that need
    /// to walk on, the interpolation and the sums.
    #[inline(always)]
    fn accumulate<W: Weights>(
        &self,
        r: &mut Reflections,
        samples: &[Vec4],
        m: usize,
        acc: &mut Accumulator,
    ) {
        let loc = self.locator;
        let mut n = 0;
        let covered = &self.coverage.covered;
        for k in 0..m {
            r.domain[n] = k as u8;
            n += (r.inside[k] & covered[r.coverage[k] as usize]) as usize;
        }
        let mut walks = 0;
        for j in 0..n {
            let k = r.domain[j] as usize;
            let t = loc.start[r.cell[k] as usize];
            let w = loc.weights(t, [r.rx[k], r.ry[k], r.rz[k]]);
            r.triangle[j] = t;
            r.weights[j] = w;
            r.walks[walks] = j as u8;
            walks += !FastLocator::inside(w) as usize;
        }
        // The few that start outside their triangle walk on (NaN weights: no data).
        for &j in &r.walks[..walks] {
            let (j, k) = (j as usize, r.domain[j as usize] as usize);
            (r.triangle[j], r.weights[j]) = loc
                .walk(r.triangle[j], [r.rx[k], r.ry[k], r.rz[k]])
                .unwrap_or((0, [f32::NAN; 3]));
        }
        for j in 0..n {
            let k = r.domain[j] as usize;
            let Some(v) = self.blend(r.triangle[j], r.weights[j]) else {
                continue;
            };
            acc.add::<W>(samples[k], v, r.wa[k], r.wb[k], r.diffuse[k]);
        }
        acc.flush();
    }

    /// The slice at the unit vector `h`, walking from triangle `start`: `None` outside the
    /// sampled region or where a corner sample is invalid.
    #[inline]
    fn interpolate(&self, start: u32, h: [f32; 3]) -> Option<Vec4> {
        let (t, w) = self.locator.walk(start, h)?;
        self.blend(t, w)
    }

    /// Spherical barycentric interpolation of triangle `t`'s corners with (unnormalised)
    /// weights `w`; `None` where a corner sample is invalid.
    #[inline(always)]
    fn blend(&self, t: u32, w: [f32; 3]) -> Option<Vec4> {
        let [a, b, c] = self.locator.triangles[t as usize]
            .vertices
            .map(|v| self.lanes[v as usize]);
        let v = (a * w[0] + b * w[1] + c * w[2]) * (1.0 / (w[0] + w[1] + w[2]));
        // An invalid corner (NaN) poisons the value: no data there.
        (!v.x.is_nan()).then_some(v)
    }
}

/// The per-block geometry of one reflection ([`FastObjective::reflections`]).
struct Reflections {
    cell: [u32; BLOCK],
    coverage: [u32; BLOCK],
    rx: [f32; BLOCK],
    ry: [f32; BLOCK],
    rz: [f32; BLOCK],
    wa: [f32; BLOCK],
    wb: [f32; BLOCK],
    diffuse: [f32; BLOCK],
    inside: [bool; BLOCK],
    /// The lights of the block in the domain (indices into the block), then per such light its
    /// starting triangle and weights there.
    domain: [u8; BLOCK],
    walks: [u8; BLOCK],
    triangle: [u32; BLOCK],
    weights: [[f32; 3]; BLOCK],
}

impl Default for Reflections {
    fn default() -> Self {
        Self {
            cell: [0; BLOCK],
            coverage: [0; BLOCK],
            rx: [0.0; BLOCK],
            ry: [0.0; BLOCK],
            rz: [0.0; BLOCK],
            wa: [0.0; BLOCK],
            wb: [0.0; BLOCK],
            diffuse: [0.0; BLOCK],
            inside: [false; BLOCK],
            domain: [0; BLOCK],
            walks: [0; BLOCK],
            triangle: [0; BLOCK],
            weights: [[0.0; 3]; BLOCK],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::rig::{uniform_cone_lights, RigOptions};
    use crate::frames::symmetry::tests::render_slice;
    use crate::geometry::tangent_basis;

    #[test]
    fn fast_terms_agree_with_the_reference_terms() {
        let rig = Rig::new(&uniform_cone_lights(1000, 65.0), RigOptions::default()).unwrap();
        let n = DVec3::new(0.4, 0.2, 1.0).normalize();
        let (u, w) = tangent_basis(n);
        let t = (u * 0.6 + w * 0.8).normalize();
        let mut slice = render_slice(&rig, n, t);
        // A few invalid samples: both paths leave them out.
        for j in [3, 40, 41, 500] {
            slice[j * 3..j * 3 + 3].fill(f32::NAN);
        }
        let exact = ExactObjective::new(&rig, &slice);
        let mut scratch = FastScratch::new(&rig);
        let fast = scratch.prepare(&rig, &slice);
        assert_eq!(fast.queries(Level::Full), rig.n_used() - 4);
        assert_eq!(exact.queries(Level::Full), rig.n_used() - 4);
        assert_eq!(fast.queries(Level::Coarse(200)), 200);
        assert_eq!(exact.queries(Level::Coarse(200)), 200);
        for cosine in [
            CosineMode::CrossMultiplied,
            CosineMode::Raw,
            CosineMode::Power(0.5),
            CosineMode::Compensated(0.5),
        ] {
            // Away from the solution (where the distances are large enough to compare).
            let n1 = (n + 0.1 * u).normalize();
            let t1 = (t + 0.3 * n.cross(t)).normalize();
            let t1 = (t1 - n1 * t1.dot(n1)).normalize();
            let frame = Frame::new(n1, t1);
            let close = |a: SymmetryTerm, b: SymmetryTerm| {
                let (da, db) = (a.distance(1), b.distance(1));
                assert!(
                    (da - db).abs() <= 0.03 * db + 1e-4,
                    "{cosine:?}: fast {a:?} vs exact {b:?}"
                );
                // Domain membership differs only where a reflection lands on the edge of the
                // sampled region.
                assert!(
                    a.count.abs_diff(b.count) <= 2 + b.count / 50,
                    "{a:?} vs {b:?}"
                );
            };
            close(
                fast.normal_term(n1, cosine, Level::Full),
                exact.normal_term(n1, cosine, Level::Full),
            );
            let [a, b] = fast.tangent_terms(frame, cosine, Level::Full);
            let [c, d] = exact.tangent_terms(frame, cosine, Level::Full);
            close(a, c);
            close(b, d);
            // The coarse level samples the same objective.
            let coarse = fast.normal_term(n1, cosine, Level::Coarse(250)).distance(1);
            let full = fast.normal_term(n1, cosine, Level::Full).distance(1);
            assert!((coarse - full).abs() < 0.2 * full, "{coarse} vs {full}");
        }
        // At the true frame the fast distances are near zero too.
        let at = fast.normal_term(n, CosineMode::CrossMultiplied, Level::Full);
        assert!(at.distance(1) < 1e-3, "{at:?}");
    }

    #[test]
    fn the_avx2_build_and_the_baseline_build_give_identical_sums() {
        // Where the processor has no AVX2 both calls run the baseline build: trivially equal.
        let rig = Rig::new(&uniform_cone_lights(700, 65.0), RigOptions::default()).unwrap();
        let n = DVec3::new(-0.3, 0.25, 1.0).normalize();
        let (u, w) = tangent_basis(n);
        let t = (u * 0.8 - w * 0.6).normalize();
        let slice = render_slice(&rig, n, t);
        let mut scratch = FastScratch::new(&rig);
        let fast = scratch.prepare(&rig, &slice);
        let frame = Frame::new((n + 0.05 * w).normalize(), t);
        let frame = Frame::new(frame.n, (t - frame.n * t.dot(frame.n)).normalize());
        for level in [Level::Full, Level::Coarse(150)] {
            let same = |a: [SymmetryTerm; 2], b: [SymmetryTerm; 2]| {
                for (x, y) in a.iter().zip(&b) {
                    assert_eq!(x.numerator.to_bits(), y.numerator.to_bits());
                    assert_eq!(x.denominator.to_bits(), y.denominator.to_bits());
                    assert_eq!(x.count, y.count);
                }
            };
            same(
                fast.dispatch::<true, _>(frame, level, CrossWeights),
                fast.kernel::<true, _>(frame, level, CrossWeights),
            );
            same(
                fast.dispatch::<false, _>(frame, level, PowerWeights::<true>(0.5)),
                fast.kernel::<false, _>(frame, level, PowerWeights::<true>(0.5)),
            );
        }
    }
}
