//! The symmetry objective (Equation 2 of Holroyd et al. 2008, ratio form as in docs/method.md,
//! "Symmetry distances and the domain rule"): how far a pixel's measured slice is from being
//! symmetric under a reflection of the halfway vector in a candidate frame (n, t, b).

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::frames::rig::Rig;
use crate::frames::slice::SliceLookup;
use crate::geometry::light_from_halfway;

/// The three reflections of the halfway vector in a frame (n, t, b = n x t).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Symmetry {
    /// Reflect across the n-t plane: `h' = h - 2 (h.b) b`.
    Nt,
    /// Reflect across the n-b plane: `h' = h - 2 (h.t) t`.
    Nb,
    /// Reflect across the normal axis: `h' = 2 (h.n) n - h` (independent of t).
    N,
}

impl Symmetry {
    /// Applies the reflection to a halfway vector given the frame.
    #[inline]
    pub(crate) fn reflect(self, h: DVec3, n: DVec3, t: DVec3, b: DVec3) -> DVec3 {
        match self {
            Symmetry::Nt => h - 2.0 * h.dot(b) * b,
            Symmetry::Nb => h - 2.0 * h.dot(t) * t,
            Symmetry::N => 2.0 * h.dot(n) * n - h,
        }
    }
}

/// How the cosine factor of the measured radiance is handled when comparing a light with its
/// reflection (docs/method.md, "Cosine forms").
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CosineMode {
    /// The paper's form: `(n.G(l)) I(l)` against `(n.l) I(G(l))`; exact for symmetric BRDFs
    /// (diffuse included).
    #[default]
    CrossMultiplied,
    /// Raw radiances `I(l)` against `I(G(l))`: exact for microfacet models whose `f (n.l)` is
    /// symmetric; wrong for diffuse surfaces.
    Raw,
    /// `(n.G(l))^p I(l)` against `(n.l)^p I(G(l))` for a fixed power `p` (1 = cross-multiplied,
    /// 0 = raw; 0.5 is exact for Ward's `1/sqrt(cos_i cos_o)` lobe).
    Power(f64),
    /// The power-`p` form after removing a per-pixel diffuse term `d (n.l)` (RGB `d >= 0`
    /// fitted in closed form inside the sum): exact for `I = d (n.l) + S(h) (n.l)^p` with `S`
    /// symmetric, i.e. for Lambertian surfaces at any `p` and for a diffuse plus Ward (p = 0.5),
    /// Blinn-Phong (p = 1) or Cook-Torrance-like (p = 0) lobe. The estimator searches with
    /// the paper's form first and refines with this one.
    Compensated(f64),
    /// Chosen per pixel by the estimator (docs/method.md, "Default measure"): the paper's form
    /// where a Lambertian term explains nearly all of the signal, the compensated form at
    /// `p = 0` (exact for microfacet lobes) elsewhere. Evaluated directly, it is the paper's
    /// form.
    Auto,
}

/// A candidate local frame in the camera frame: normal, tangent and binormal `b = n x t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Frame {
    /// Unit normal.
    pub n: DVec3,
    /// Unit tangent, perpendicular to `n`.
    pub t: DVec3,
    /// `n x t`.
    pub b: DVec3,
}

impl Frame {
    /// The frame of a normal and a tangent (`b = n x t`).
    #[inline]
    pub(crate) fn new(n: DVec3, t: DVec3) -> Self {
        Self {
            n,
            t,
            b: n.cross(t),
        }
    }
}

/// The sums of one symmetry distance over its domain.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct SymmetryTerm {
    /// Sum of squared differences (numerator of Equation 2).
    pub numerator: f64,
    /// Sum of squared reference values (denominator of Equation 2).
    pub denominator: f64,
    /// Number of lights in the domain.
    pub count: u32,
}

/// The value a symmetry distance takes when its domain is (too) small: larger than any ratio a
/// real slice produces, so the optimiser walks away from it.
pub(crate) const EMPTY_DISTANCE: f64 = 1.0e3;

impl SymmetryTerm {
    /// The ratio `numerator / denominator`, or [`EMPTY_DISTANCE`] when the domain has fewer
    /// than `min_count` lights or no signal.
    #[inline]
    pub(crate) fn distance(&self, min_count: u32) -> f64 {
        if self.count < min_count.max(1) || self.denominator <= 0.0 {
            EMPTY_DISTANCE
        } else {
            self.numerator / self.denominator
        }
    }
}

/// Evaluates one symmetry term of a pixel's slice (rig order, `rig.n_used() * 3` values, NaN =
/// invalid; `lookup` reconstructs it between samples) in the frame (n, t, b). Allocation-free; `t` and `b` are ignored for [`Symmetry::N`].
///
/// The domain is the lights with `n.l > 0` whose reflected halfway vector is inside the cone
/// and [covered](Rig::covered), maps to a light with `n.G(l) > 0`, and has data in the slice.
#[inline]
pub(crate) fn symmetry_term<L: SliceLookup>(
    rig: &Rig,
    slice: &[f32],
    lookup: &L,
    symmetry: Symmetry,
    frame: Frame,
    cosine: CosineMode,
) -> SymmetryTerm {
    symmetry_term_over(rig, slice, lookup, symmetry, frame, cosine, 0..rig.n_used())
}

/// [`symmetry_term`] summed over the given lights only (rig indices), e.g. a coarse subset.
#[inline]
pub(crate) fn symmetry_term_over<L: SliceLookup>(
    rig: &Rig,
    slice: &[f32],
    lookup: &L,
    symmetry: Symmetry,
    frame: Frame,
    cosine: CosineMode,
    lights: impl Iterator<Item = usize>,
) -> SymmetryTerm {
    let Frame { n, t, b } = frame;
    let mut term = SymmetryTerm::default();
    let mut diffuse_dot = [0.0f64; 3];
    let mut diffuse_sq = 0.0f64;
    for j in lights {
        let (l, h) = (rig.lights_in_camera()[j], rig.halfway_in_camera()[j]);
        let s = &slice[j * 3..j * 3 + 3];
        if !s[0].is_finite() {
            continue;
        }
        let n_dot_l = n.dot(l);
        if n_dot_l <= 0.0 {
            continue;
        }
        let h_reflected = symmetry.reflect(h, n, t, b);
        if !rig.in_cone(h_reflected) || !rig.covered(h_reflected) {
            continue;
        }
        let n_dot_lr = n.dot(light_from_halfway(h_reflected));
        if n_dot_lr <= 0.0 {
            continue;
        }
        let Some(ir) = lookup.value(h_reflected) else {
            continue;
        };
        let (wa, wb) = match cosine {
            CosineMode::CrossMultiplied | CosineMode::Auto => (n_dot_lr, n_dot_l),
            CosineMode::Raw => (1.0, 1.0),
            CosineMode::Power(p) | CosineMode::Compensated(p) => {
                (n_dot_lr.powf(p), n_dot_l.powf(p))
            }
        };
        // What a unit diffuse term contributes to the difference (zero for p = 1).
        let diffuse = wa * n_dot_l - wb * n_dot_lr;
        let mut num = 0.0;
        let mut den = 0.0;
        for c in 0..3 {
            let a = wa * s[c] as f64;
            let d = a - wb * ir[c];
            num += d * d;
            den += a * a;
            diffuse_dot[c] += d * diffuse;
        }
        diffuse_sq += diffuse * diffuse;
        term.numerator += num;
        term.denominator += den;
        term.count += 1;
    }
    if matches!(cosine, CosineMode::Compensated(_)) && diffuse_sq > 1e-12 * term.count as f64 {
        // Least-squares diffuse albedo per channel, kept non-negative; its part of the
        // difference is removed from the numerator.
        for dd in diffuse_dot {
            if dd > 0.0 {
                term.numerator -= dd * dd / diffuse_sq;
            }
        }
        term.numerator = term.numerator.max(0.0);
    }
    term
}

/// The smallest domain (in lights) that counts as non-empty for a rig: a share of the rig's
/// lights, so sparse rigs are not all discarded while degenerate one- or two-light domains never
/// produce spurious zero distances (docs/method.md, "Symmetry distances and the domain rule").
pub(crate) fn default_min_domain(n_used: usize) -> u32 {
    ((n_used as f64 * 0.015).ceil() as u32).clamp(6, 30)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::frames::rig::{uniform_cone_lights, RigOptions};
    use crate::frames::slice::ExactSlice;
    use crate::geometry::tangent_basis;

    /// A symmetric "BRDF" slice: diffuse plus an anisotropic lobe around n in halfway space,
    /// radiance `I = f (n.l)` with `f` a function of (h.t, h.b, h.n) even in h.t and h.b.
    pub(crate) fn render_slice(rig: &Rig, n: DVec3, t: DVec3) -> Vec<f32> {
        let b = n.cross(t);
        rig.lights_in_camera()
            .iter()
            .zip(rig.halfway_in_camera())
            .flat_map(|(&l, &h)| {
                let nl = n.dot(l).max(0.0);
                let (ht, hb, hn) = (h.dot(t), h.dot(b), h.dot(n).max(1e-6));
                let spec = (-((ht / hn).powi(2) / 0.04 + (hb / hn).powi(2) / 0.25)).exp();
                let f = 0.3 + 2.0 * spec;
                [
                    (f * nl) as f32,
                    (0.8 * f * nl) as f32,
                    (0.5 * f * nl) as f32,
                ]
            })
            .collect()
    }

    #[test]
    fn reflections_are_involutions_and_keep_the_right_axes() {
        let n = DVec3::new(0.3, -0.2, 0.9).normalize();
        let (u, w) = tangent_basis(n);
        assert!(u.dot(n).abs() < 1e-12 && w.dot(n).abs() < 1e-12 && u.dot(w).abs() < 1e-12);
        assert!((u.length() - 1.0).abs() < 1e-12 && (w.length() - 1.0).abs() < 1e-12);
        let (t, b) = (u, n.cross(u));
        let h = DVec3::new(0.1, 0.2, 0.95).normalize();
        for s in [Symmetry::Nt, Symmetry::Nb, Symmetry::N] {
            let r = s.reflect(h, n, t, b);
            assert!((r.length() - 1.0).abs() < 1e-12);
            assert!((s.reflect(r, n, t, b) - h).length() < 1e-12);
            assert!(
                (r.dot(n) - h.dot(n)).abs() < 1e-12,
                "all keep the angle to n"
            );
        }
        let r = Symmetry::Nt.reflect(h, n, t, b);
        assert!((r.dot(t) - h.dot(t)).abs() < 1e-12 && (r.dot(b) + h.dot(b)).abs() < 1e-12);
        let r = Symmetry::Nb.reflect(h, n, t, b);
        assert!((r.dot(b) - h.dot(b)).abs() < 1e-12 && (r.dot(t) + h.dot(t)).abs() < 1e-12);
    }

    #[test]
    fn distance_is_near_zero_at_the_true_frame_and_larger_away_from_it() {
        let rig = Rig::new(&uniform_cone_lights(1000, 65.0), RigOptions::default()).unwrap();
        let n = DVec3::new(0.4, 0.2, 1.0).normalize();
        let (u, w) = tangent_basis(n);
        let t = (u * 0.6 + w * 0.8).normalize();
        let b = n.cross(t);
        let slice = render_slice(&rig, n, t);
        let min = default_min_domain(rig.n_used());
        let exact = ExactSlice {
            rig: &rig,
            samples: &slice,
        };
        let sd = |n: DVec3, t: DVec3, s: Symmetry| {
            symmetry_term(
                &rig,
                &slice,
                &exact,
                s,
                Frame::new(n, t),
                CosineMode::CrossMultiplied,
            )
            .distance(min)
        };
        let at_truth = [
            sd(n, t, Symmetry::N),
            sd(n, t, Symmetry::Nt),
            sd(n, t, Symmetry::Nb),
        ];
        for v in at_truth {
            // Not exactly zero: linear interpolation between samples ~4 degrees apart.
            assert!(v < 1e-3, "at the true frame: {at_truth:?}");
        }
        // Tilt the normal by 3 degrees: SD_n grows by orders of magnitude.
        let tilted = (n + 0.0524 * b).normalize();
        assert!(sd(tilted, t, Symmetry::N) > 20.0 * at_truth[0].max(1e-6));
        // Rotate the tangent by 10 degrees: the tangent terms grow.
        let (tu, tw) = (t, b);
        let rot = (tu * 10f64.to_radians().cos() + tw * 10f64.to_radians().sin()).normalize();
        assert!(sd(n, rot, Symmetry::Nt) > 20.0 * at_truth[1].max(1e-6));
        assert!(sd(n, rot, Symmetry::Nb) > 20.0 * at_truth[2].max(1e-6));
    }

    #[test]
    fn small_domains_count_as_empty() {
        let term = SymmetryTerm {
            numerator: 0.0,
            denominator: 1.0,
            count: 2,
        };
        assert_eq!(term.distance(10), EMPTY_DISTANCE);
        assert_eq!(term.distance(2), 0.0);
        assert_eq!(SymmetryTerm::default().distance(1), EMPTY_DISTANCE);
        assert_eq!(default_min_domain(96), 6);
        assert_eq!(default_min_domain(1000), 15);
    }

    #[test]
    fn invalid_samples_are_outside_the_domain() {
        let rig = Rig::new(&uniform_cone_lights(300, 65.0), RigOptions::default()).unwrap();
        let slice = vec![f32::NAN; rig.n_used() * 3];
        let n = DVec3::Z;
        let exact = ExactSlice {
            rig: &rig,
            samples: &slice,
        };
        let term = symmetry_term(
            &rig,
            &slice,
            &exact,
            Symmetry::N,
            Frame::new(n, DVec3::X),
            CosineMode::Raw,
        );
        assert_eq!(term.count, 0);
    }
}
