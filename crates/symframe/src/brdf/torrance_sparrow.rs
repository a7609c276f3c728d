//! Torrance-Sparrow BRDF in the form used in computer vision.
//!
//! Parameters: diffuse albedo `kd` and specular albedo `ks` per RGB channel, `sigma` σ = RMS
//! slope of the V-groove microfacets (larger = wider highlight).
//!
//! Formula, with `h = normalize(l + v)`, `θ_h` the angle between `h` and `n`:
//!
//! ```text
//! f(l, v) = kd/π + ks · D(h) G(l, v, h) / (4 cosθ_i cosθ_o)
//! D(h)    = exp(-tan²θ_h / σ²) / (π σ² cos⁴θ_h)                         (Beckmann)
//! G       = min(1, 2 cosθ_h cosθ_o / (v·h), 2 cosθ_h cosθ_i / (l·h))    (V-groove)
//! ```
//!
//! Choices, stated exactly: Torrance & Sparrow (1967) use a Gaussian in the facet angle,
//! `exp(-c² θ_h²)`; we use its normalised Beckmann form (`tanθ_h ≈ θ_h` near the peak, `c = 1/σ`),
//! normalised so `∫ D (n·h) dω_h = 1`. The Fresnel factor is taken as 1, the convention of
//! photometric-stereo work (e.g. Georghiades 2003; Holroyd et al. 2008, Figure 4): `ks` absorbs
//! the nearly constant reflectance inside the `θ_d < 65°` cone; use [`super::CookTorrance`] for
//! a Fresnel term. With `F = 1` and the V-groove masking the specular directional albedo is at
//! most `ks` for every view (the V-groove `G1` satisfies the projected-area constraint, Heitz
//! 2014), so `kd + ks <= 1` conserves energy.
//!
//! Source: K. E. Torrance, E. M. Sparrow, "Theory for Off-Specular Reflection From Roughened
//! Surfaces", JOSA 57(9), 1967; the `1/(4 cosθ_i cosθ_o)` normalisation as corrected by Walter
//! et al. 2007. Isotropic and reciprocal.

use super::microfacet::{beckmann_d, diffuse_plus_lobe, half_vector_above, vcavity_g};
use super::{Brdf, TangentAxis};
use glam::DVec3;

/// Torrance-Sparrow BRDF (Beckmann facets, V-groove masking, no Fresnel factor).
#[derive(Debug, Clone, PartialEq)]
pub struct TorranceSparrow {
    /// Diffuse albedo per RGB channel.
    pub kd: [f64; 3],
    /// Specular albedo per RGB channel.
    pub ks: [f64; 3],
    /// RMS facet slope σ; must be positive.
    pub sigma: f64,
}

impl TorranceSparrow {
    /// A Torrance-Sparrow BRDF. Panics if `sigma` is not positive and finite.
    pub fn new(kd: [f64; 3], ks: [f64; 3], sigma: f64) -> Self {
        assert!(
            sigma > 0.0 && sigma.is_finite(),
            "Torrance-Sparrow sigma must be positive and finite, got {sigma}"
        );
        TorranceSparrow { kd, ks, sigma }
    }
}

impl Brdf for TorranceSparrow {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        let Some(h) = half_vector_above(l, v) else {
            return [0.0; 3];
        };
        let s = beckmann_d(h, self.sigma, self.sigma) * vcavity_g(l, v, h) / (4.0 * l.z * v.z);
        diffuse_plus_lobe(&self.kd, &self.ks, s)
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::None
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "torrance-sparrow:kd={},ks={},sigma={}",
            fmt_rgb(&self.kd),
            fmt_rgb(&self.ks),
            self.sigma
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;
    use std::f64::consts::PI;

    #[test]
    fn peak_value() {
        // l = v = n: D = 1/(π σ²), G = 1: f = kd/π + ks/(4π σ²).
        let b = TorranceSparrow::new([0.25; 3], [0.5; 3], 0.2);
        let f = b.eval(DVec3::Z, DVec3::Z);
        assert!((f[0] - (0.25 / PI + 0.5 / (4.0 * PI * 0.04))).abs() < 1e-12);
    }

    #[test]
    fn properties() {
        let b = TorranceSparrow::new([0.3, 0.2, 0.1], [0.6, 0.7, 0.8], 0.15);
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-14);
        assert_mirror_symmetric(&b, 1e-14);
        assert_rotation_invariant(&b, 1e-9);
        assert_eq!(b.tangent_axis(), TangentAxis::None);
        assert_eq!(measured_wide_axis(&b), TangentAxis::None);
    }

    #[test]
    fn energy() {
        for sigma in [0.05, 0.2, 0.5] {
            assert_energy(&TorranceSparrow::new([0.0; 3], [1.0; 3], sigma), 85.0, 2e-3);
            assert_energy(&TorranceSparrow::new([0.5; 3], [0.5; 3], sigma), 85.0, 2e-3);
        }
    }
}
