//! Normalised Blinn-Phong BRDF.
//!
//! Parameters: diffuse albedo `kd` and specular albedo `ks` per RGB channel, exponent `e > 0`
//! (larger = narrower highlight).
//!
//! Formula, with `h = normalize(l + v)`:
//!
//! ```text
//! f(l, v) = kd/π + ks · K(e) · (n·h)^e,   K(e) = (e + 2)(e + 4) / (8π (2^(-e/2) + e))
//! ```
//!
//! `K(e)` is the exact normalisation that makes the specular lobe's directional albedo
//! `∫ K (n·h)^e (n·l) dω_l` equal to 1 at normal incidence (`v = n`); for large `e` it is
//! `(e + 6)/(8π) + O(1/e)`, close to the familiar `(e + 8)/(8π)` approximation
//! (Akenine-Möller, Haines & Hoffman, *Real-Time Rendering* 3rd ed., section 7.6), which
//! slightly over-normalises. Note: the `(e + 2)/(2π)` factor often quoted
//! normalises the *distribution* `D(h)` (`∫ D (n·h) dω_h = 1`), not this BRDF: used as
//! `ks (e+2)/(2π) (n·h)^e` it reflects up to 4× the incident energy, so it is not used here.
//! For other views the albedo is below 1 (about `cos²θ_o` for large `e`: the lobe is
//! clipped by the horizon and the cosine falls), so `kd + ks <= 1` conserves energy.
//!
//! Sources: J. F. Blinn, "Models of Light Reflection for Computer Synthesized Pictures",
//! SIGGRAPH 1977; normalisation from F. Giesen, "The Blinn-Phong Normalization Zoo" (2009) and
//! Sloan & Hoffman. Isotropic and reciprocal.

use super::microfacet::{diffuse_plus_lobe, half_vector_above};
use super::{Brdf, TangentAxis};
use glam::DVec3;
use std::f64::consts::PI;

/// Normalised Blinn-Phong BRDF.
#[derive(Debug, Clone, PartialEq)]
pub struct BlinnPhong {
    /// Diffuse albedo per RGB channel.
    pub kd: [f64; 3],
    /// Specular albedo per RGB channel (the lobe's albedo at normal incidence).
    pub ks: [f64; 3],
    /// Blinn exponent on `n·h`; must be positive.
    pub e: f64,
}

impl BlinnPhong {
    /// A normalised Blinn-Phong BRDF. Panics if the exponent is not positive and finite.
    pub fn new(kd: [f64; 3], ks: [f64; 3], e: f64) -> Self {
        assert!(
            e > 0.0 && e.is_finite(),
            "Blinn-Phong exponent must be positive and finite, got {e}"
        );
        BlinnPhong { kd, ks, e }
    }

    /// The normalisation `K(e) = (e + 2)(e + 4) / (8π (2^(-e/2) + e))`.
    pub fn normalisation(e: f64) -> f64 {
        (e + 2.0) * (e + 4.0) / (8.0 * PI * ((-0.5 * e).exp2() + e))
    }
}

impl Brdf for BlinnPhong {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let Some(h) = half_vector_above(light_in_local, view_in_local) else {
            return [0.0; 3];
        };
        let s = Self::normalisation(self.e) * h.z.powf(self.e);
        diffuse_plus_lobe(&self.kd, &self.ks, s)
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::None
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "blinn-phong:kd={},ks={},e={}",
            fmt_rgb(&self.kd),
            fmt_rgb(&self.ks),
            self.e
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;

    #[test]
    fn normalisation_is_exact_at_normal_incidence() {
        for e in [1.0, 10.0, 50.0, 200.0] {
            let b = BlinnPhong::new([0.0; 3], [1.0; 3], e);
            let a = directional_albedo(&b, DVec3::Z, 600);
            assert!((a[0] - 1.0).abs() < 2e-3, "e={e}: {a:?}");
        }
        // Large-e behaviour: (e+6)/(8π) + O(1/e), below the familiar (e+8)/(8π).
        for e in [100.0, 1e4] {
            let k = BlinnPhong::normalisation(e);
            assert!((k * 8.0 * PI - (e + 6.0)).abs() < 10.0 / e, "{e}: {k}");
            assert!(k < (e + 8.0) / (8.0 * PI));
        }
    }

    #[test]
    fn peak_value() {
        let b = BlinnPhong::new([0.2; 3], [0.5; 3], 10.0);
        let k = 12.0 * 14.0 / (8.0 * PI * (1.0 / 32.0 + 10.0));
        let f = b.eval(dir(0.3, 0.2), dir(0.3, 0.2 + PI));
        assert!((f[0] - (0.2 / PI + 0.5 * k)).abs() < 1e-12);
    }

    #[test]
    fn properties() {
        let b = BlinnPhong::new([0.3, 0.2, 0.1], [0.6, 0.7, 0.8], 40.0);
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
        for e in [1.0, 5.0, 50.0, 500.0] {
            assert_energy(&BlinnPhong::new([0.0; 3], [1.0; 3], e), 85.0, 2e-3);
            assert_energy(&BlinnPhong::new([0.5; 3], [0.5; 3], e), 85.0, 2e-3);
        }
    }
}
