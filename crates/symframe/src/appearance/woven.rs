//! The woven fit model: two perpendicular anisotropic GGX lobes sharing the pixel's frame over
//! a Lambertian base (woven satin, twill: the warp threads' highlight stretched along one axis,
//! the weft's along the other). What [`FitModel::Woven`](super::fit::FitModel::Woven) fits per
//! pixel.
//!
//! Parameters, per RGB channel: the diffuse albedo `kd`, the warp lobe's reflectance `kw` and
//! the weft lobe's `kf`; shared by the channels and the lobes: the roughnesses `alpha_t` along
//! the tangent and `alpha_b` along the binormal (the weft lobe has them swapped).
//!
//! Formula, with `L(α_x, α_y) = D(h) G2(l, v) / (4 (n·l)(n·v))` the GGX lobe of
//! [`crate::brdf::Ggx`] without its Fresnel factor:
//!
//! ```text
//! f(l, v) = kd/π + kw L(α_t, α_b) + kf L(α_b, α_t)
//! ```
//!
//! Linear in `kd`, `kw`, `kf` given the roughnesses ([`super::lobe_fit`]). Without a Fresnel
//! factor for the same reason as [`super::clearcoat`]'s base. A pixel without a tangent has
//! one lobe (`kf = 0`, `α_t = α_b`): two equal isotropic lobes are one.
//!
//! Sources: I. Sadeghi, O. Bisker, J. De Deken, H. W. Jensen, "A Practical Microcylinder
//! Appearance Model for Cloth Rendering", ACM TOG 32(2), 2013 (two thread directions, each an
//! anisotropic lobe), as in [`crate::brdf::Woven`]; GGX of B. Walter et al., EGSR 2007.
//!
//! Tangent: the warp's wide axis (`alpha_t >= alpha_b` is the fit's convention, so `kw` is
//! the lobe stretched along the tangent).

use glam::DVec3;
use std::f64::consts::PI;

use super::clearcoat::ggx_lobe;
use crate::brdf::microfacet::half_vector_above;

/// The three functions the reflectances multiply, `[kd, kw, kf]`'s, at local directions `l`,
/// `v` (z = normal): `f = kd b[0] + kw b[1] + kf b[2]`. Zero below the horizon.
#[inline]
pub(crate) fn basis(l: DVec3, v: DVec3, alpha_t: f64, alpha_b: f64) -> [f64; 3] {
    match half_vector_above(l, v) {
        Some(h) => basis_at(l, v, h, alpha_t, alpha_b),
        None => [0.0; 3],
    }
}

/// [`basis`] at the half-vector `h` of `l` and `v` (above the horizon).
#[inline]
pub(crate) fn basis_at(l: DVec3, v: DVec3, h: DVec3, alpha_t: f64, alpha_b: f64) -> [f64; 3] {
    [
        1.0 / PI,
        ggx_lobe(l, v, h, alpha_t, alpha_b),
        ggx_lobe(l, v, h, alpha_b, alpha_t),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::direction_pairs;
    use crate::brdf::{Brdf, Woven};

    /// With the lobes' Fresnel factor constant (f0 = 1) the model is the woven render model.
    #[test]
    fn matches_the_woven_render_model() {
        let kd = [0.25, 0.08, 0.08];
        let woven = Woven::new(kd, [1.0; 3], 0.35, 0.08, 0.5);
        for (l, v) in direction_pairs(3, 300) {
            let b = basis(l, v, 0.35, 0.08);
            let want = woven.eval(l, v);
            for c in 0..3 {
                let got = kd[c] * b[0] + b[1] + 0.5 * b[2];
                assert!(
                    (got - want[c]).abs() <= 1e-9 * want[c].abs().max(1.0),
                    "{got} {want:?}"
                );
            }
        }
    }
}
