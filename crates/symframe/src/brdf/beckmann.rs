//! Anisotropic Beckmann microfacet conductor: a coloured metal (brushed gold) whose lobe is
//! not GGX's, for checking that a material slightly off the estimator's lobe family is not
//! answered with that family's bias.
//!
//! Parameters: Fresnel reflectance at normal incidence `f0` per RGB channel (a conductor's
//! colour), roughnesses `alpha_x`, `alpha_y` (RMS slopes along local x and y), a Lambertian
//! `kd` (0 for a bare metal).
//!
//! Formula, with `h = normalize(l + v)`:
//!
//! ```text
//! f(l, v) = kd/π + D(h) F(l·h) G2(l, v) / (4 (n·l)(n·v))
//! D(h)    = exp(-(h_x²/α_x² + h_y²/α_y²)/h_z²) / (π α_x α_y h_z⁴)
//! F(c)    = f0 + (1 - f0)(1 - c)⁵                                            (Schlick)
//! G2      = 1 / (1 + Λ(l) + Λ(v)), Λ the Beckmann Smith term (Walter et al. 2007, eq. 27)
//! ```
//!
//! Sources: P. Beckmann, A. Spizzichino, "The Scattering of Electromagnetic Waves from Rough
//! Surfaces", 1963; B. Walter, S. Marschner, H. Li, K. Torrance, "Microfacet Models for
//! Refraction through Rough Surfaces", EGSR 2007; E. Heitz, JCGT 3(2), 2014 (height-correlated
//! G2).
//!
//! Tangent: the axis of the larger α.

use super::microfacet::{
    assert_roughness, beckmann_d, cos_theta_d, diffuse_plus_schlick_lobe, half_vector_above,
    smith_g2_beckmann_correlated,
};
use super::{Brdf, TangentAxis};
use glam::DVec3;

/// Anisotropic Beckmann microfacet BRDF with a coloured Schlick Fresnel.
#[derive(Debug, Clone, PartialEq)]
pub struct Beckmann {
    /// Diffuse albedo per RGB channel.
    pub kd: [f64; 3],
    /// Fresnel reflectance at normal incidence per RGB channel, in `[0, 1]`.
    pub f0: [f64; 3],
    /// RMS slope along local x; positive.
    pub alpha_x: f64,
    /// RMS slope along local y; positive.
    pub alpha_y: f64,
}

impl Beckmann {
    /// An anisotropic Beckmann BRDF. Panics if a roughness is not positive and finite.
    pub fn new(kd: [f64; 3], f0: [f64; 3], alpha_x: f64, alpha_y: f64) -> Self {
        assert_roughness("Beckmann", alpha_x, alpha_y);
        Beckmann {
            kd,
            f0,
            alpha_x,
            alpha_y,
        }
    }
}

impl Brdf for Beckmann {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        let Some(h) = half_vector_above(l, v) else {
            return [0.0; 3];
        };
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        let s = beckmann_d(h, ax, ay) * smith_g2_beckmann_correlated(l, v, h, ax, ay)
            / (4.0 * l.z * v.z);
        diffuse_plus_schlick_lobe(&self.kd, &self.f0, cos_theta_d(l, v), s)
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::of_roughness(self.alpha_x, self.alpha_y)
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "beckmann:kd={},f0={},ax={},ay={}",
            fmt_rgb(&self.kd),
            fmt_rgb(&self.f0),
            self.alpha_x,
            self.alpha_y
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;
    use std::f64::consts::PI;

    #[test]
    fn peak_value_and_properties() {
        // l = v = n: D = 1/(π α_x α_y), F = f0, Λ = 0.
        let b = Beckmann::new([0.0; 3], [1.0, 0.71, 0.29], 0.2, 0.05);
        let f = b.eval(DVec3::Z, DVec3::Z);
        assert!((f[1] - 0.71 / (4.0 * PI * 0.01)).abs() < 1e-9, "{f:?}");
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-12);
        assert_mirror_symmetric(&b, 1e-12);
        assert_not_rotation_invariant(&b);
        assert_eq!(b.tangent_axis(), TangentAxis::X);
        assert_eq!(measured_wide_axis(&b), TangentAxis::X);
        assert_energy(&Beckmann::new([0.0; 3], [1.0; 3], 0.3, 0.1), 85.0, 2e-3);
    }
}
