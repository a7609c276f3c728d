//! Cook-Torrance BRDF.
//!
//! Parameters: diffuse albedo `kd` and specular weight `ks` per RGB channel, `m` = RMS facet
//! slope (Beckmann roughness; larger = wider highlight), `ior` = relative index of refraction η
//! of the (dielectric) surface.
//!
//! Formula, with `h = normalize(l + v)`:
//!
//! ```text
//! f(l, v) = kd/π + ks · F(l·h; η) D(h) G(l, v, h) / (4 (n·l)(n·v))
//! D(h)    = exp(-tan²θ_h / m²) / (π m² cos⁴θ_h)                        (Beckmann)
//! G       = min(1, 2 (n·h)(n·v)/(v·h), 2 (n·h)(n·l)/(l·h))              (V-cavity)
//! F(c; η) = ½ (g-c)²/(g+c)² (1 + ((c(g+c)-1)/(c(g-c)+1))²),  g² = η² + c² - 1
//! ```
//!
//! Normalisation, stated exactly: Cook & Torrance (1982) write
//! `R_s = F D' G / (π (n·l)(n·v))` with the un-normalised `D' = exp(-tan²α/m²)/(m² cos⁴α)`,
//! i.e. `R_s = F D G / ((n·l)(n·v))` with the normalised `D = D'/π` above. That is four times
//! the microfacet-theory value `F D G / (4 (n·l)(n·v))` (Walter et al. 2007, eq. 20), which we
//! use, so `ks` is the specular albedo of a perfect mirror (`F = 1`). With `F <= 1` and the
//! V-cavity masking the specular albedo is at most `ks`, so `kd + ks <= 1` conserves energy.
//!
//! Source: R. L. Cook, K. E. Torrance, "A Reflectance Model for Computer Graphics", ACM TOG
//! 1(1), 1982. Isotropic and reciprocal.

use super::microfacet::{
    beckmann_d, cos_theta_d, diffuse_plus_lobe, fresnel_dielectric, half_vector_above, vcavity_g,
};
use super::{Brdf, TangentAxis};
use glam::DVec3;

/// Cook-Torrance BRDF (Beckmann D, exact dielectric Fresnel, V-cavity G).
#[derive(Debug, Clone, PartialEq)]
pub struct CookTorrance {
    /// Diffuse albedo per RGB channel.
    pub kd: [f64; 3],
    /// Specular weight per RGB channel (multiplies `F D G / (4 (n·l)(n·v))`).
    pub ks: [f64; 3],
    /// RMS facet slope `m`; must be positive.
    pub m: f64,
    /// Relative index of refraction η; must be positive.
    pub ior: f64,
}

impl CookTorrance {
    /// A Cook-Torrance BRDF. Panics if `m` or `ior` is not positive and finite.
    pub fn new(kd: [f64; 3], ks: [f64; 3], m: f64, ior: f64) -> Self {
        assert!(
            m > 0.0 && m.is_finite() && ior > 0.0 && ior.is_finite(),
            "Cook-Torrance m and ior must be positive and finite, got {m}, {ior}"
        );
        CookTorrance { kd, ks, m, ior }
    }
}

impl Brdf for CookTorrance {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        let Some(h) = half_vector_above(l, v) else {
            return [0.0; 3];
        };
        let f = fresnel_dielectric(cos_theta_d(l, v), self.ior);
        let s = f * beckmann_d(h, self.m, self.m) * vcavity_g(l, v, h) / (4.0 * l.z * v.z);
        diffuse_plus_lobe(&self.kd, &self.ks, s)
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::None
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "cook-torrance:kd={},ks={},m={},ior={}",
            fmt_rgb(&self.kd),
            fmt_rgb(&self.ks),
            self.m,
            self.ior
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
        // l = v = n: F = ((η-1)/(η+1))², D = 1/(π m²), G = 1.
        let b = CookTorrance::new([0.1; 3], [1.0; 3], 0.3, 1.5);
        let f0 = 0.04;
        let expect = 0.1 / PI + f0 / (4.0 * PI * 0.09);
        assert!((b.eval(DVec3::Z, DVec3::Z)[2] - expect).abs() < 1e-12);
    }

    #[test]
    fn fresnel_rises_toward_grazing() {
        let b = CookTorrance::new([0.0; 3], [1.0; 3], 0.2, 1.5);
        // Mirror configurations with h = n: D and G fixed apart from the 1/cos² factor.
        let at = |t: f64| {
            let l = dir(t, 0.0);
            let v = dir(t, PI);
            b.eval(l, v)[0] * l.z * v.z
        };
        assert!(at(1.4) > 5.0 * at(0.1));
    }

    #[test]
    fn properties() {
        let b = CookTorrance::new([0.3, 0.2, 0.1], [0.6, 0.7, 0.8], 0.2, 1.8);
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
        for m in [0.05, 0.2, 0.5] {
            // A near-perfect conductor-like Fresnel (η large) is the worst case.
            assert_energy(&CookTorrance::new([0.0; 3], [1.0; 3], m, 50.0), 85.0, 2e-3);
            assert_energy(&CookTorrance::new([0.5; 3], [0.5; 3], m, 1.5), 85.0, 2e-3);
        }
    }
}
