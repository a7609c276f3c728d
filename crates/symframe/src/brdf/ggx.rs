//! Anisotropic GGX (Trowbridge-Reitz) microfacet BRDF with a Lambertian base.
//!
//! Parameters: diffuse albedo `kd` and Fresnel reflectance at normal incidence `f0` per RGB
//! channel; roughnesses `alpha_x`, `alpha_y` along local x and y (larger = wider highlight).
//!
//! Formula, with `h = normalize(l + v)`:
//!
//! ```text
//! f(l, v) = kd/π + D(h) F(l·h) G2(l, v) / (4 (n·l)(n·v))
//! D(h)    = 1 / (π α_x α_y (h_x²/α_x² + h_y²/α_y² + h_z²)²)
//! F(c)    = f0 + (1 - f0)(1 - c)⁵                                            (Schlick)
//! G2      = 1 / (1 + Λ(l) + Λ(v)),  Λ(w) = (-1 + sqrt(1 + (α_x² w_x² + α_y² w_y²)/w_z²)) / 2
//! ```
//!
//! `G2` is the height-correlated Smith masking-shadowing (Heitz 2014, eq. 99), symmetric in
//! `l` and `v`, so the model is reciprocal. The diffuse term is a plain `kd/π` (not weighted
//! by `1 - F`): the directional albedo is at most `kd + 1` and tends to that bound only for
//! smooth surfaces at grazing views; it is at most 1 when `kd = 0` (energy is lost, not
//! gained, by single-scattering microfacet models) and stays below 1 for `kd + f0 <= 1` over
//! the views the method uses (θ ≤ 60°).
//!
//! Sources: T. S. Trowbridge, K. P. Reitz, JOSA 65(5), 1975; B. Walter, S. Marschner, H. Li,
//! K. Torrance, "Microfacet Models for Refraction through Rough Surfaces", EGSR 2007;
//! E. Heitz, "Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs", JCGT
//! 3(2), 2014; C. Schlick, Computer Graphics Forum 13(3), 1994.
//!
//! Tangent: the axis of the larger α (`X` if `alpha_x > alpha_y`, `Y` if smaller, `None` when
//! equal).

use super::microfacet::{
    assert_roughness, cos_theta_d, diffuse_plus_schlick_lobe, ggx_d, half_vector_above,
    smith_g2_ggx_correlated,
};
use super::{Brdf, TangentAxis};
use glam::DVec3;

/// Anisotropic GGX microfacet BRDF plus Lambertian diffuse.
#[derive(Debug, Clone, PartialEq)]
pub struct Ggx {
    /// Diffuse albedo per RGB channel.
    pub kd: [f64; 3],
    /// Fresnel reflectance at normal incidence per RGB channel, in `[0, 1]`.
    pub f0: [f64; 3],
    /// Roughness along local x; must be positive.
    pub alpha_x: f64,
    /// Roughness along local y; must be positive.
    pub alpha_y: f64,
}

impl Ggx {
    /// An anisotropic GGX BRDF. Panics if a roughness is not positive and finite.
    pub fn new(kd: [f64; 3], f0: [f64; 3], alpha_x: f64, alpha_y: f64) -> Self {
        assert_roughness("GGX", alpha_x, alpha_y);
        Ggx {
            kd,
            f0,
            alpha_x,
            alpha_y,
        }
    }

    /// An isotropic GGX BRDF (`alpha_x = alpha_y = alpha`).
    pub fn isotropic(kd: [f64; 3], f0: [f64; 3], alpha: f64) -> Self {
        Ggx::new(kd, f0, alpha, alpha)
    }
}

impl Brdf for Ggx {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        let Some(h) = half_vector_above(l, v) else {
            return [0.0; 3];
        };
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        let s = ggx_d(h, ax, ay) * smith_g2_ggx_correlated(l, v, h, ax, ay) / (4.0 * l.z * v.z);
        diffuse_plus_schlick_lobe(&self.kd, &self.f0, cos_theta_d(l, v), s)
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::of_roughness(self.alpha_x, self.alpha_y)
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "ggx:kd={},f0={},ax={},ay={}",
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
    fn peak_value() {
        // l = v = n: D = 1/(π α_x α_y), F = f0, Λ = 0.
        let b = Ggx::new([0.1; 3], [0.9, 0.5, 0.2], 0.3, 0.1);
        let f = b.eval(DVec3::Z, DVec3::Z);
        for (c, f0) in [0.9, 0.5, 0.2].into_iter().enumerate() {
            let expect = 0.1 / PI + f0 / (4.0 * PI * 0.03);
            assert!((f[c] - expect).abs() < 1e-12, "{f:?}");
        }
    }

    #[test]
    fn properties() {
        let b = Ggx::new([0.1, 0.2, 0.3], [0.9, 0.5, 0.04], 0.3, 0.1);
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-14);
        assert_mirror_symmetric(&b, 1e-14);
        assert_not_rotation_invariant(&b);
        let iso = Ggx::isotropic([0.1; 3], [0.5; 3], 0.2);
        assert_rotation_invariant(&iso, 1e-9);
    }

    #[test]
    fn tangent_axis_is_wider_roughness() {
        let b = Ggx::new([0.1; 3], [0.9; 3], 0.3, 0.1);
        assert_eq!(b.tangent_axis(), TangentAxis::X);
        assert_eq!(measured_wide_axis(&b), TangentAxis::X);
        let b = Ggx::new([0.1; 3], [0.9; 3], 0.05, 0.2);
        assert_eq!(b.tangent_axis(), TangentAxis::Y);
        assert_eq!(measured_wide_axis(&b), TangentAxis::Y);
        assert_eq!(
            Ggx::isotropic([0.1; 3], [0.9; 3], 0.2).tangent_axis(),
            TangentAxis::None
        );
    }

    #[test]
    fn energy() {
        for (ax, ay) in [(0.1, 0.1), (0.3, 0.1), (0.6, 0.4)] {
            // Pure specular, perfect reflector: single scattering loses energy, never gains.
            assert_energy(&Ggx::new([0.0; 3], [1.0; 3], ax, ay), 85.0, 2e-3);
            assert_energy(&Ggx::new([0.5; 3], [0.04; 3], ax, ay), 85.0, 2e-3);
            assert_energy(&Ggx::new([0.1; 3], [0.9; 3], ax, ay), 60.0, 2e-3);
        }
    }
}
