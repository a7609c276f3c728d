//! The clear-coat fit model: a sharp isotropic dielectric coat over an anisotropic GGX base,
//! sharing the pixel's frame (car paint, lacquered brushed metal). What
//! [`FitModel::Clearcoat`](super::fit::FitModel::Clearcoat) fits per pixel.
//!
//! Parameters, per RGB channel: the base's diffuse albedo `kd` and lobe reflectance `ks`, the
//! coat's reflectance at normal incidence `kc` (about 0.04 for a lacquer); shared by the
//! channels: the base's GGX roughnesses `alpha_t` along the tangent and `alpha_b` along the
//! binormal, and the coat's roughness `alpha_c`.
//!
//! Formula, with `L(α_x, α_y) = D(h) G2(l, v) / (4 (n·l)(n·v))` the GGX lobe of
//! [`crate::brdf::Ggx`] without its Fresnel factor, `F` the exact dielectric Fresnel
//! reflectance of index [`COAT_IOR`] and `T(c) = 1 - F(c)` the coat's transmission:
//!
//! ```text
//! f(l, v) = T(n·l) T(n·v) (kd/π + ks L(α_t, α_b))  +  kc (F(l·h) / F(1)) L(α_c, α_c)
//! ```
//!
//! Linear in `kd`, `ks`, `kc` given the roughnesses, which is what the fit exploits
//! ([`super::lobe_fit`]). The base lobe carries no Fresnel factor of its own: over a rig's
//! cone (view and light within 65 degrees of each other) Schlick's factor varies by less than
//! 0.1% of its value, and `ks` absorbs its level.
//!
//! Sources: the attenuated-base form of A. Weidlich, A. Wilkie, "Arbitrarily Layered
//! Micro-Facet Surfaces", GRAPHITE 2007, as in [`crate::brdf::Layered`]; GGX of B. Walter et
//! al., EGSR 2007; the glTF `KHR_materials_clearcoat` extension, the export's form, has the
//! same two layers (coat factor = `kc / F(1)`, coat roughness = `sqrt(α_c)`).
//!
//! Tangent: the base's wide axis (`alpha_t >= alpha_b` is the fit's convention).

use glam::DVec3;
use std::f64::consts::PI;

use crate::brdf::microfacet::{
    cos_theta_d, fresnel_dielectric, ggx_d, half_vector_above, smith_g2_ggx_correlated,
};

/// The coat's index of refraction (a lacquer's; glTF's clear coat has the same).
pub(crate) const COAT_IOR: f64 = 1.5;

/// The GGX lobe `D G2 / (4 (n·l)(n·v))` at half-vector `h`, without a Fresnel factor.
#[inline]
pub(crate) fn ggx_lobe(l: DVec3, v: DVec3, h: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    ggx_d(h, alpha_x, alpha_y) * smith_g2_ggx_correlated(l, v, h, alpha_x, alpha_y)
        / (4.0 * l.z * v.z)
}

/// What of [`basis`] does not depend on the roughnesses (the half-vector and the coat's
/// Fresnel factors), computed once per sample by a fit that evaluates many roughnesses.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Fixed {
    /// The half-vector.
    pub h: DVec3,
    /// `T(n.l) T(n.v)`: the base seen through the coat both ways.
    pub through: f64,
    /// `F(l.h) / F(1)`: the coat's Fresnel factor over its normal-incidence value.
    pub coat: f64,
}

/// [`Fixed`] at local directions `l`, `v`; `None` below the horizon.
#[inline]
pub(crate) fn fixed(l: DVec3, v: DVec3) -> Option<Fixed> {
    let h = half_vector_above(l, v)?;
    Some(Fixed {
        h,
        through: (1.0 - fresnel_dielectric(l.z, COAT_IOR))
            * (1.0 - fresnel_dielectric(v.z, COAT_IOR)),
        coat: fresnel_dielectric(cos_theta_d(l, v), COAT_IOR) / fresnel_dielectric(1.0, COAT_IOR),
    })
}

/// [`basis`] from its roughness-free part `f` (of the same `l`, `v`).
#[inline]
pub(crate) fn basis_at(
    l: DVec3,
    v: DVec3,
    f: &Fixed,
    alpha_t: f64,
    alpha_b: f64,
    alpha_c: f64,
) -> [f64; 3] {
    [
        f.through / PI,
        f.through * ggx_lobe(l, v, f.h, alpha_t, alpha_b),
        f.coat * ggx_lobe(l, v, f.h, alpha_c, alpha_c),
    ]
}

/// The three functions the reflectances multiply, `[kd, ks, kc]`'s, at local directions
/// `l`, `v` (z = normal): `f = kd b[0] + ks b[1] + kc b[2]`. Zero below the horizon.
#[inline]
pub(crate) fn basis(l: DVec3, v: DVec3, alpha_t: f64, alpha_b: f64, alpha_c: f64) -> [f64; 3] {
    match fixed(l, v) {
        Some(f) => basis_at(l, v, &f, alpha_t, alpha_b, alpha_c),
        None => [0.0; 3],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::direction_pairs;
    use crate::brdf::{Brdf, Ggx, Layered};

    /// With the base's Fresnel factor constant (f0 = 1) the model is the layered render model
    /// over a GGX base exactly.
    #[test]
    fn matches_the_layered_model() {
        let (at, ab, ac) = (0.35, 0.12, 0.03);
        let kd = [0.05, 0.08, 0.25];
        let layered = Layered::new(ac, COAT_IOR, Box::new(Ggx::new(kd, [1.0; 3], at, ab)));
        let kc = fresnel_dielectric(1.0, COAT_IOR);
        for (l, v) in direction_pairs(7, 300) {
            let b = basis(l, v, at, ab, ac);
            let want = layered.eval(l, v);
            for c in 0..3 {
                let got = kd[c] * b[0] + b[1] + kc * b[2];
                assert!(
                    (got - want[c]).abs() <= 1e-9 * want[c].abs().max(1.0),
                    "{got} {want:?}"
                );
            }
        }
    }
}
