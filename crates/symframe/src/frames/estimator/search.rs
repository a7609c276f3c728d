//! The symmetry search of a pixel's frame: the distances `SD_n` and `SD_nt + SD_nb` on a level
//! of the lights, the normal's Nelder-Mead search on coarse levels and its polish on all of
//! them, the judge between starts, the tangent's scan, and whether a normal is within the rig's
//! reach (docs/method.md, "The search").

use glam::DVec3;

use super::diffuse::unexplained_share;
use super::Estimator;
use crate::frames::objective::{Level, Objective};
use crate::frames::optim::{nelder_mead, NelderMeadOptions};
use crate::frames::rig::Rig;
use crate::frames::symmetry::{CosineMode, Frame, EMPTY_DISTANCE};
use crate::geometry::tangent_basis;

impl Estimator<'_> {
    /// The domain size under which a distance at `level` counts as empty: the rig's minimum
    /// scaled to the share of lights the level visits (never below 6 lights).
    pub(super) fn min_count<O: Objective>(&self, objective: &O, level: Level) -> u32 {
        let full = objective.queries(Level::Full).max(1);
        let part = objective.queries(level);
        if part >= full {
            self.min_domain
        } else {
            ((self.min_domain as usize * part).div_ceil(full) as u32)
                .max(6)
                .min(self.min_domain)
        }
    }

    /// `SD_n` at a candidate normal.
    pub(super) fn normal_distance<O: Objective>(
        &self,
        objective: &O,
        n: DVec3,
        cosine: CosineMode,
        level: Level,
    ) -> f64 {
        if n.z <= 0.0 {
            return EMPTY_DISTANCE;
        }
        objective
            .normal_term(n, cosine, level)
            .distance(self.min_count(objective, level))
    }

    /// `SD_nt + SD_nb` at a candidate tangent of a fixed normal, and the smaller domain.
    pub(super) fn tangent_distance<O: Objective>(
        &self,
        objective: &O,
        n: DVec3,
        t: DVec3,
        cosine: CosineMode,
        level: Level,
    ) -> (f64, u32) {
        let min = self.min_count(objective, level);
        let [nt, nb] = objective.tangent_terms(Frame::new(n, t), cosine, level);
        (nt.distance(min) + nb.distance(min), nt.count.min(nb.count))
    }

    /// Minimises `SD_n` with 2D Nelder-Mead on the gnomonic chart of the tangent plane at
    /// `start`, initial simplex `step` radians; returns the normal and the evaluations used.
    pub(super) fn search_normal<O: Objective>(
        &self,
        objective: &O,
        start: DVec3,
        cosine: CosineMode,
        level: Level,
        step: f64,
        budget: u32,
    ) -> (DVec3, u32) {
        let (u, w) = tangent_basis(start);
        let chart = |x: &[f64; 2]| (start + x[0] * u + x[1] * w).normalize();
        let m = nelder_mead(
            |x: &[f64; 2]| self.normal_distance(objective, chart(x), cosine, level),
            [0.0, 0.0],
            [step, step],
            NelderMeadOptions {
                max_evals: budget,
                x_tolerance: 1e-4,
                f_tolerance: f64::INFINITY,
            },
        );
        (chart(&m.x), m.evals)
    }

    /// Coarse to fine: Nelder-Mead on the coarse level `coarse` from `start` (simplex `step`,
    /// at most `budget` evaluations), a restart there with a small simplex against premature
    /// collapse, and a polish on the full level. Where the coarse domain at the coarse
    /// solution is too small to trust, the coarse stages are repeated on a larger prefix.
    pub(super) fn minimise_normal<O: Objective>(
        &self,
        objective: &O,
        start: DVec3,
        cosine: CosineMode,
        mut coarse: Level,
        step: f64,
        budget: u32,
    ) -> (DVec3, u32) {
        let mut evals = 0;
        let mut n = start;
        let mut step = step;
        for _ in 0..3 {
            let (m, e1) = self.search_normal(objective, n, cosine, coarse, step, budget);
            let (m, e2) = self.search_normal(objective, m, cosine, coarse, 0.01, 20);
            evals += e1 + e2;
            let count = objective.normal_term(m, cosine, coarse).count;
            evals += 1;
            if coarse == Level::Full || count >= COARSE_RELIABLE {
                n = m;
                break;
            }
            // Too few lights: grow the prefix to reach the target domain, restart from the
            // original start if the coarse solution has no domain at all.
            coarse = coarse_level(objective, coarse, count, 2 * COARSE_RELIABLE);
            if count >= 6 {
                n = m;
                step = step.min(0.05);
            }
        }
        let (n, e) = self.quadratic_polish(objective, n, cosine, POLISH_RADIUS_DEG.to_radians());
        (n, evals + e)
    }

    /// One quadratic-fit step on the full level: the objective at a 3x3 stencil of spacing `r`
    /// radians around `centre` on its tangent plane, a least-squares quadratic through the nine
    /// values, and its minimum (the best stencil point where the fit has no minimum nearby).
    pub(super) fn quadratic_polish<O: Objective>(
        &self,
        objective: &O,
        centre: DVec3,
        cosine: CosineMode,
        r: f64,
    ) -> (DVec3, u32) {
        let (u, w) = tangent_basis(centre);
        let chart = |x: f64, y: f64| (centre + x * u + y * w).normalize();
        let mut f = [[0.0f64; 3]; 3];
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for (i, row) in f.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                let (x, y) = ((i as f64 - 1.0) * r, (j as f64 - 1.0) * r);
                *v = self.normal_distance(objective, chart(x, y), cosine, Level::Full);
                if *v < best.0 {
                    best = (*v, x, y);
                }
            }
        }
        if f.iter().flatten().any(|v| *v >= EMPTY_DISTANCE) {
            return (chart(best.1, best.2), 9);
        }
        let q = StencilQuadratic::of(&f, r);
        if let Some([x, y]) = q.minimum() {
            if x.abs() <= 1.5 * r && y.abs() <= 1.5 * r {
                return (chart(x, y), 9);
            }
        }
        (chart(best.1, best.2), 9)
    }

    /// The search's answer `found`, unless one of `starts` has a clearly lower `SD_n` on the full
    /// level (below [`SearchSettings::judge_margin`](crate::frames::policy::SearchSettings::judge_margin) times it):
    /// then the coarse levels misled the search (a lobe narrower than their spacing is aliased
    /// there), and a full-level search from the best start decides. The result never has a
    /// higher full-level distance than the best start.
    pub(super) fn judge_at_full<'s, O: Objective>(
        &self,
        objective: &O,
        found: DVec3,
        starts: impl Iterator<Item = &'s DVec3>,
        cosine: CosineMode,
    ) -> (DVec3, u32) {
        let full = |n: DVec3| self.normal_distance(objective, n, cosine, Level::Full);
        let mut evals = 1;
        let at_found = full(found);
        let mut best = (at_found, found);
        for &s in starts {
            let v = full(s);
            evals += 1;
            if v < best.0 {
                best = (v, s);
            }
        }
        // Only a clear win counts: near-ties would make the outcome hang on rounding (the fast
        // and reference paths must take the same branch), and a misled search ends several
        // times above its start.
        if best.1 == found || best.0 >= self.policy.search.judge_margin * at_found {
            return (found, evals);
        }
        let (m, e) = self.search_normal(objective, best.1, cosine, Level::Full, 0.02, 80);
        let (m, e2) = self.quadratic_polish(objective, m, cosine, POLISH_RADIUS_DEG.to_radians());
        let v = full(m);
        evals += e + e2 + 1;
        (if v < best.0 { m } else { best.1 }, evals)
    }

    /// The symmetry search's normal (docs/method.md, "The search"), from the brightest sample
    /// `j`'s halfway vector or light, whichever the slice is more symmetric about, and judged
    /// against that halfway vector and the highlight's centroid `from_moments` on every light;
    /// under a compensated measure refined with it from the paper form's answer, `cosine`
    /// then set to it. `None` where the paper form's answer is beyond the rig's reach and a
    /// refinement would walk it back.
    pub(super) fn search_for_normal<O: Objective>(
        &self,
        slice: &[f32],
        objective: &O,
        j: usize,
        from_moments: Option<DVec3>,
        cosine: &mut CosineMode,
        evals: &mut u32,
    ) -> Option<DVec3> {
        let rig = self.rig;
        // The two starts are compared on a quarter of the lights (all of them on small rigs);
        // the domain there sizes the coarse level of the search.
        let quarter = quarter_level(objective);
        let at = |n: DVec3| {
            let term = objective.normal_term(n, *cosine, quarter);
            (
                term.distance(self.min_count(objective, quarter)),
                term.count,
            )
        };
        let mut start = rig.halfway_in_camera()[j];
        let mut start_at = at(start);
        let light = rig.lights_in_camera()[j];
        if light.z > 0.0 {
            let light_at = at(light);
            if light_at.0 < start_at.0 {
                (start, start_at) = (light, light_at);
            }
        }
        *evals += 2;
        let coarse = coarse_level(objective, quarter, start_at.1, NORMAL_DOMAIN_TARGET);

        let (n, e) = self.minimise_normal(
            objective,
            start,
            *cosine,
            coarse,
            0.12,
            self.params.max_normal_evals,
        );
        *evals += e;
        let starts = [Some(rig.halfway_in_camera()[j]), from_moments];
        // A search that ended beyond the reach is left there (discarded or a fallback): the
        // judge must not turn it into a clamped guess inside the sampled region.
        let mut n = n;
        if centre_observed(rig, objective, n) {
            let (m, e) = self.judge_at_full(objective, n, starts.iter().flatten(), *cosine);
            *evals += e;
            n = m;
        }
        let diffuse = self.params.cosine == CosineMode::Auto
            && unexplained_share(rig, slice, n, self.policy.shadows.min_cosine)
                < self.policy.diffuse.specular_share;
        let refine = match self.params.cosine {
            CosineMode::Compensated(p) => Some(CosineMode::Compensated(p)),
            CosineMode::Auto => (!diffuse).then_some(CosineMode::Compensated(0.0)),
            _ => None,
        };
        if let Some(refined) = refine {
            // A normal beyond the rig's reach in the paper's form stays discarded: the flatter
            // compensated measure could otherwise walk it back inside the sampled region to a
            // wrong but plausible-looking normal.
            if n.z <= 0.0 || !centre_observed(rig, objective, n) {
                return None;
            }
            // The compensated measure is flatter far from the solution: refine the paper's
            // solution with it (where p = 1 the two coincide).
            *cosine = refined;
            let (m, e) = self.minimise_normal(objective, n, *cosine, coarse, 0.06, 150);
            *evals += e;
            // Judged against the paper-form solution only: the other starts may lie inside the
            // reach where that solution does not.
            let (m, e) = self.judge_at_full(objective, m, [n].iter(), *cosine);
            *evals += e;
            n = m;
        }
        Some(n)
    }

    /// The tangent about `n` that makes the slice most symmetric under `G_nt` and `G_nb`: the
    /// objective scanned over its 90-degree period on a coarse level, the best angle refined
    /// there, then polished on the full level; with the terms there and the anisotropy.
    /// `None` where either term's domain is too small.
    pub(super) fn search_tangent<O: Objective>(
        &self,
        objective: &O,
        n: DVec3,
        cosine: CosineMode,
        evals: &mut u32,
    ) -> Option<TangentSearch> {
        let (u, w) = tangent_basis(n);
        let tangent_at = |psi: f64| u * psi.cos() + w * psi.sin();
        let period = std::f64::consts::FRAC_PI_2;
        let quarter = quarter_level(objective);
        let (_, count) = self.tangent_distance(objective, n, u, cosine, quarter);
        let coarse = coarse_level(objective, quarter, count, TANGENT_DOMAIN_TARGET);
        let mut scan = [0.0f64; TANGENT_SCAN];
        for (k, v) in scan.iter_mut().enumerate() {
            let t = tangent_at(period * k as f64 / TANGENT_SCAN as f64);
            *v = self.tangent_distance(objective, n, t, cosine, coarse).0;
        }
        *evals += 1 + TANGENT_SCAN as u32;
        let (k_best, _) = scan
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .unwrap_or((0, &0.0));
        let psi0 = period * k_best as f64 / TANGENT_SCAN as f64;
        let search_tangent = |psi: f64, step: f64, level: Level, budget: u32| {
            nelder_mead(
                |x: &[f64; 1]| {
                    self.tangent_distance(objective, n, tangent_at(x[0]), cosine, level)
                        .0
                },
                [psi],
                [step],
                NelderMeadOptions {
                    max_evals: budget,
                    x_tolerance: 1e-4,
                    f_tolerance: f64::INFINITY,
                },
            )
        };
        let rough = search_tangent(psi0, period / TANGENT_SCAN as f64 / 2.0, coarse, 60);
        *evals += rough.evals;
        let psi = {
            // A parabola through three full-level values around the coarse solution.
            let d = TANGENT_POLISH_DEG.to_radians();
            let f = [-d, 0.0, d].map(|o| {
                self.tangent_distance(
                    objective,
                    n,
                    tangent_at(rough.x[0] + o),
                    cosine,
                    Level::Full,
                )
                .0
            });
            *evals += 3;
            let curvature = f[0] - 2.0 * f[1] + f[2];
            let shift = if curvature > 0.0 {
                (0.5 * d * (f[0] - f[2]) / curvature).clamp(-d, d)
            } else if f[0] < f[2] {
                -d
            } else {
                d
            };
            rough.x[0] + shift
        };
        let t = tangent_at(psi);
        let [term_nt, term_nb] = objective.tangent_terms(Frame::new(n, t), cosine, Level::Full);
        if term_nt.count < self.min_domain
            || term_nb.count < self.min_domain
            || term_nt.denominator <= 0.0
            || term_nb.denominator <= 0.0
        {
            return None;
        }
        let sd_nt = term_nt.numerator / term_nt.denominator;
        let sd_nb = term_nb.numerator / term_nb.denominator;
        // Anisotropy: how much worse the tangent objective is half a period (45 degrees) away
        // from the solution, on the full level.
        let f_min = sd_nt + sd_nb;
        let f_max = self
            .tangent_distance(
                objective,
                n,
                tangent_at(psi + period / 2.0),
                cosine,
                Level::Full,
            )
            .0;
        *evals += 2;
        let anisotropy = ((f_max - f_min) / (f_max + f_min + ANISOTROPY_FLOOR)).clamp(0.0, 1.0);
        Some(TangentSearch {
            tangent: t,
            sd_nt,
            sd_nb,
            f_min,
            f_max,
            anisotropy,
        })
    }
}

/// Number of angles the tangent objective is scanned at over its period (90 degrees) before
/// the 1D refinement; also the samples of the anisotropy measure.
pub(super) const TANGENT_SCAN: usize = 9;

/// Absolute floor of the anisotropy ratio's denominator: symmetry distances below this are
/// interpolation noise, not anisotropy.
pub(super) const ANISOTROPY_FLOOR: f64 = 1e-3;

/// The widest-highlight heuristic: is the slice, around `n` in halfway space, brighter along
/// `candidate` than along `current` at equal angles? Compares symmetric pairs `n cos d +- a
/// sin d` for several `d` where all four points have data, so uneven sample density cannot
/// bias it.
pub(super) fn highlight_wider_along<O: Objective>(
    objective: &O,
    n: DVec3,
    candidate: DVec3,
    current: DVec3,
) -> bool {
    let mut along_candidate = 0.0;
    let mut along_current = 0.0;
    for k in 1..=12 {
        let d = (2.0 * k as f64).to_radians();
        let (s, c) = d.sin_cos();
        let probe = |a: DVec3| {
            let h = n * c + a * s;
            objective.value(h).map(|v| v[0] + v[1] + v[2])
        };
        if let (Some(a), Some(b), Some(p), Some(q)) = (
            probe(candidate),
            probe(-candidate),
            probe(current),
            probe(-current),
        ) {
            along_candidate += a + b;
            along_current += p + q;
        }
    }
    along_candidate > along_current
}

/// Coarse domains smaller than this (lights) do not locate a minimum reliably: the search
/// repeats on a larger prefix.
pub(super) const COARSE_RELIABLE: u32 = 32;

/// How many lights the coarse level's `SD_n` domain should hold: enough to place the minimum
/// within the full level's basin (a fraction of a degree), few enough to be cheap.
pub(super) const NORMAL_DOMAIN_TARGET: u32 = 64;

/// The same for the tangent terms' domains.
pub(super) const TANGENT_DOMAIN_TARGET: u32 = 64;

/// Spacing of the full-level quadratic fit that ends the normal search (degrees): wide enough
/// to average over the objective's ripples at the scale of the light spacing (the reference and
/// fast paths then agree), narrow enough to stay quadratic.
pub(super) const POLISH_RADIUS_DEG: f64 = 1.0;

/// Spacing of the full-level parabola that ends the tangent search (degrees).
pub(super) const TANGENT_POLISH_DEG: f64 = 1.0;

/// The coarse level whose domain holds about `target` lights, given that `level` has a domain
/// of `count` lights; the full level where that is most of the lights anyway.
pub(super) fn coarse_level<O: Objective>(
    objective: &O,
    level: Level,
    count: u32,
    target: u32,
) -> Level {
    let full = objective.queries(Level::Full);
    let part = objective.queries(level);
    let m = (part as u64 * target as u64).div_ceil(count.max(1) as u64) as usize;
    if m >= full * 3 / 4 {
        Level::Full
    } else {
        Level::Coarse(m.max(target as usize))
    }
}

/// Half-angle of the neighbourhood of `h = n` that must be observed for a normal to count as
/// within the rig's reach (degrees).
pub(super) const CENTRE_RADIUS_DEG: f64 = 2.0;

/// Whether the slice has data at `h = n` and around it in four directions: the centre of the
/// symmetries must be observed. A normal beyond the rig's reach (a rig within 45 degrees of the
/// view has halfway vectors within ~22) otherwise settles at the edge of the sampled region with a
/// small but meaningless distance: a clamped guess, which docs/method.md ("Beyond-reach discard")
/// says never to return. The points must lie in [covered](Rig::covered) cells, as the domains'
/// lights do.
pub(super) fn centre_observed<O: Objective>(rig: &Rig, objective: &O, n: DVec3) -> bool {
    let (u, w) = tangent_basis(n);
    let (s, c) = CENTRE_RADIUS_DEG.to_radians().sin_cos();
    let observed = |h: DVec3| rig.covered(h) && objective.value(h).is_some();
    observed(n) && [u, -u, w, -w].iter().all(|&a| observed(n * c + a * s))
}

/// The least-squares quadratic `c + g.x + x^T H x / 2` through a function's values `f[i][j]`
/// at `((i - 1) r, (j - 1) r)` on a 3 x 3 stencil (an orthogonal basis there: closed form).
#[derive(Debug, Clone, Copy)]
pub(super) struct StencilQuadratic {
    pub(super) c: f64,
    pub(super) g: [f64; 2],
    /// `H_xx`, `H_yy`, `H_xy`.
    pub(super) h: [f64; 3],
}

impl StencilQuadratic {
    pub(super) fn of(f: &[[f64; 3]; 3], r: f64) -> Self {
        let col = |i: usize| f[i][0] + f[i][1] + f[i][2];
        let row = |j: usize| f[0][j] + f[1][j] + f[2][j];
        let hxx = (col(2) - 2.0 * col(1) + col(0)) / (3.0 * r * r);
        let hyy = (row(2) - 2.0 * row(1) + row(0)) / (3.0 * r * r);
        Self {
            c: (col(0) + col(1) + col(2)) / 9.0 - (hxx + hyy) * r * r / 3.0,
            g: [(col(2) - col(0)) / (6.0 * r), (row(2) - row(0)) / (6.0 * r)],
            h: [
                hxx,
                hyy,
                (f[2][2] - f[2][0] - f[0][2] + f[0][0]) / (4.0 * r * r),
            ],
        }
    }

    /// The offset of the minimum from the stencil's centre; `None` where `H` is not positive
    /// definite.
    pub(super) fn minimum(&self) -> Option<[f64; 2]> {
        let ([gx, gy], [hxx, hyy, hxy]) = (self.g, self.h);
        let det = hxx * hyy - hxy * hxy;
        (hxx > 0.0 && det > 0.0)
            .then(|| [-(hyy * gx - hxy * gy) / det, -(hxx * gy - hxy * gx) / det])
    }
}

/// What the tangent search found about a normal ([`Estimator::search_tangent`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct TangentSearch {
    /// The tangent candidate (one of the two symmetry axes).
    pub(super) tangent: DVec3,
    /// `SD_nt` and `SD_nb` at the answer, on every light.
    pub(super) sd_nt: f64,
    pub(super) sd_nb: f64,
    /// `SD_nt + SD_nb` at the answer and half a period (45 degrees) away.
    pub(super) f_min: f64,
    pub(super) f_max: f64,
    /// `(f_max - f_min) / (f_max + f_min)`, floored: how much the slice prefers the axes.
    pub(super) anisotropy: f64,
}

/// The index of the brightest sample of a slice (the search's start: docs/method.md, "The
/// search"; for diffuse surfaces the light itself is the better guess, and is tried too), or
/// `None` where no sample holds data.
pub(super) fn brightest_sample(slice: &[f32]) -> Option<usize> {
    let mut brightest = None;
    let mut best = 0.0f32;
    for (j, s) in slice.chunks_exact(3).enumerate() {
        let y = s[0] + s[1] + s[2];
        if y.is_finite() && y > best {
            best = y;
            brightest = Some(j);
        }
    }
    brightest
}

/// The level the search's starts are compared on and its coarse levels sized from: a quarter
/// of the lights (all of them on rigs of up to 256).
fn quarter_level<O: Objective>(objective: &O) -> Level {
    Level::Coarse(objective.queries(Level::Full).div_ceil(4).max(256))
}
