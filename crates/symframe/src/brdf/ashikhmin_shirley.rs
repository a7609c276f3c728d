//! Anisotropic Ashikhmin-Shirley BRDF.
//!
//! Parameters: diffuse reflectance `rd` and specular reflectance at normal incidence `rs`
//! (Schlick's `F0`) per RGB channel; Phong-like exponents `nu` along local x and `nv` along
//! local y. A larger exponent gives a *narrower* highlight along that axis.
//!
//! Formula, with `h = normalize(l + v)`, `k` either `l` or `v` (`h·l = h·v`):
//!
//! ```text
//! f   = ρ_s + ρ_d
//! ρ_s = sqrt((nu+1)(nv+1)) / (8π) · (n·h)^((nu h_x² + nv h_y²)/(1 - (n·h)²))
//!       / ((h·k) max(n·l, n·v)) · F(h·k)
//! F   = rs + (1 - rs)(1 - h·k)⁵                                     (Schlick)
//! ρ_d = 28 rd / (23π) · (1 - rs) · (1 - (1 - n·l/2)⁵) · (1 - (1 - n·v/2)⁵)
//! ```
//!
//! The exponent `(nu cos²φ_h + nv sin²φ_h)` is written with the halfway vector's components;
//! at `h = n` the specular power term is 1. The specular lobe is only approximately energy
//! conserving (the `max(n·l, n·v)` denominator is a heuristic); the diffuse term is built so
//! that `rd + rs <= 1` keeps the total albedo at or below 1 when the lobe's albedo is `F`.
//!
//! Source: M. Ashikhmin, P. Shirley, "An Anisotropic Phong BRDF Model", Journal of Graphics
//! Tools 5(2), 2000, eqs. 4-5. Reciprocal and symmetric under `x → -x` and `y → -y`.
//!
//! Tangent: the axis with the SMALLER exponent (wider highlight): `X` if `nu < nv`, `Y` if
//! `nv < nu`, `None` when equal.

use super::microfacet::{cos_theta_d, fresnel_schlick, half_vector_above};
use super::{Brdf, TangentAxis};
use glam::DVec3;
use std::f64::consts::PI;

/// Anisotropic Ashikhmin-Shirley BRDF (specular and diffuse terms).
#[derive(Debug, Clone, PartialEq)]
pub struct AshikhminShirley {
    /// Diffuse reflectance `R_d` per RGB channel.
    pub rd: [f64; 3],
    /// Specular reflectance at normal incidence `R_s` per RGB channel.
    pub rs: [f64; 3],
    /// Exponent along local x (larger = narrower); must be positive.
    pub nu: f64,
    /// Exponent along local y (larger = narrower); must be positive.
    pub nv: f64,
}

impl AshikhminShirley {
    /// An Ashikhmin-Shirley BRDF. Panics if an exponent is not positive and finite.
    pub fn new(rd: [f64; 3], rs: [f64; 3], nu: f64, nv: f64) -> Self {
        assert!(
            nu > 0.0 && nv > 0.0 && nu.is_finite() && nv.is_finite(),
            "Ashikhmin-Shirley exponents must be positive and finite, got {nu}, {nv}"
        );
        AshikhminShirley { rd, rs, nu, nv }
    }
}

impl Brdf for AshikhminShirley {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        let Some(h) = half_vector_above(l, v) else {
            return [0.0; 3];
        };
        let s2 = h.x * h.x + h.y * h.y; // 1 - (n·h)²
        let power = if s2 > 0.0 {
            // (n·h)^(E/s2) = exp(½ ln(1 - s2) · E / s2), accurate near the normal.
            let e = self.nu * h.x * h.x + self.nv * h.y * h.y;
            (0.5 * (-s2).ln_1p() * e / s2).exp()
        } else {
            1.0
        };
        let hk = cos_theta_d(l, v);
        let spec =
            ((self.nu + 1.0) * (self.nv + 1.0)).sqrt() / (8.0 * PI) * power / (hk * l.z.max(v.z));
        let p5 = |x: f64| {
            let y = 1.0 - 0.5 * x;
            let y2 = y * y;
            1.0 - y2 * y2 * y
        };
        let diff_geom = 28.0 / (23.0 * PI) * p5(l.z) * p5(v.z);
        std::array::from_fn(|c| {
            spec * fresnel_schlick(hk, self.rs[c]) + diff_geom * self.rd[c] * (1.0 - self.rs[c])
        })
    }

    fn tangent_axis(&self) -> TangentAxis {
        // A larger exponent is a narrower highlight: the exponents order like inverse roughness.
        TangentAxis::of_roughness(self.nv, self.nu)
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "ashikhmin-shirley:rd={},rs={},nu={},nv={}",
            fmt_rgb(&self.rd),
            fmt_rgb(&self.rs),
            self.nu,
            self.nv
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;

    #[test]
    fn peak_value() {
        // l = v = n: power 1, h·k = 1, max = 1, F = rs; diffuse factors (1 - 1/32)².
        let b = AshikhminShirley::new([0.4; 3], [0.1; 3], 100.0, 10.0);
        let spec = (101.0f64 * 11.0).sqrt() / (8.0 * PI) * 0.1;
        let diff = 28.0 / (23.0 * PI) * 0.4 * 0.9 * (31.0f64 / 32.0).powi(2);
        let f = b.eval(DVec3::Z, DVec3::Z);
        assert!((f[1] - (spec + diff)).abs() < 1e-12, "{f:?}");
    }

    #[test]
    fn exponent_by_hand() {
        // h tilted by t along x: power = cos(t)^nu.
        let b = AshikhminShirley::new([0.0; 3], [1.0; 3], 50.0, 5.0);
        let t: f64 = 0.1;
        let h = dir(t, 0.0);
        let v = DVec3::Z;
        let l = 2.0 * h.z * h - v;
        let expect = (51.0f64 * 6.0).sqrt() / (8.0 * PI) * t.cos().powf(50.0) / (h.z * 1.0);
        let f = b.eval(l, v);
        assert!((f[0] - expect).abs() < 1e-12 * expect, "{f:?} vs {expect}");
    }

    #[test]
    fn properties() {
        let b = AshikhminShirley::new([0.3, 0.2, 0.1], [0.05, 0.3, 0.6], 200.0, 20.0);
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-14);
        assert_mirror_symmetric(&b, 1e-14);
        assert_not_rotation_invariant(&b);
        let iso = AshikhminShirley::new([0.3; 3], [0.1; 3], 50.0, 50.0);
        assert_rotation_invariant(&iso, 1e-9);
    }

    #[test]
    fn tangent_axis_is_smaller_exponent() {
        let b = AshikhminShirley::new([0.3; 3], [0.1; 3], 200.0, 20.0);
        assert_eq!(b.tangent_axis(), TangentAxis::Y);
        assert_eq!(measured_wide_axis(&b), TangentAxis::Y);
        let b = AshikhminShirley::new([0.3; 3], [0.1; 3], 5.0, 80.0);
        assert_eq!(b.tangent_axis(), TangentAxis::X);
        assert_eq!(measured_wide_axis(&b), TangentAxis::X);
        let iso = AshikhminShirley::new([0.3; 3], [0.1; 3], 30.0, 30.0);
        assert_eq!(iso.tangent_axis(), TangentAxis::None);
    }

    #[test]
    fn energy() {
        for (nu, nv) in [(10.0, 10.0), (100.0, 10.0), (1000.0, 100.0)] {
            assert_energy(
                &AshikhminShirley::new([1.0; 3], [0.0; 3], nu, nv),
                85.0,
                0.0,
            );
            assert_energy(
                &AshikhminShirley::new([0.5; 3], [0.5; 3], nu, nv),
                85.0,
                0.0,
            );
            assert_energy(
                &AshikhminShirley::new([0.0; 3], [1.0; 3], nu, nv),
                85.0,
                0.0,
            );
        }
    }
}
