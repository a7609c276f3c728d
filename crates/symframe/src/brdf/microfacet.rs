//! Shared microfacet building blocks, defined once and used by every analytic model.
//!
//! All functions work in the local frame (x, y = anisotropy axes, z = normal) on unit vectors.
//!
//! - Normal distributions `D(h)`, normalised so that `∫ D(h) (h·n) dω_h = 1` over the
//!   hemisphere:
//!   - anisotropic Beckmann (Beckmann & Spizzichino 1963; Walter et al. 2007, eq. 33, with the
//!     anisotropic form of Heitz 2014):
//!     `D = exp(-(h_x²/α_x² + h_y²/α_y²) / h_z²) / (π α_x α_y h_z⁴)`;
//!   - anisotropic GGX / Trowbridge-Reitz (Trowbridge & Reitz 1975; Walter et al. 2007, eq. 33;
//!     Heitz 2014, eq. 85): `D = 1 / (π α_x α_y (h_x²/α_x² + h_y²/α_y² + h_z²)²)`.
//! - Smith masking (Heitz 2014, "Understanding the Masking-Shadowing Function in
//!   Microfacet-Based BRDFs", JCGT 3(2)): with `a = w_z / sqrt(α_x² w_x² + α_y² w_y²)`
//!   (`= 1/(α tanθ)` with the projected roughness α),
//!   - Beckmann: `Λ(a) = (erf(a) - 1)/2 + exp(-a²)/(2 a √π)`, evaluated as
//!     `(exp(-a²)/(a√π) - erfc(a)) / 2` to avoid cancellation (`erfc` to ~1e-7 relative);
//!   - GGX: `Λ(a) = (-1 + sqrt(1 + 1/a²)) / 2`;
//!   - `G1(w, h) = χ⁺((w·h)/(w·n)) / (1 + Λ(w))`; height-correlated
//!     `G2 = 1 / (1 + Λ(l) + Λ(v))` and separable `G2 = G1(l) G1(v)`.
//! - The V-cavity masking of Torrance & Sparrow (1967) and Cook & Torrance (1982):
//!   `G = min(1, 2 (n·h)(n·v)/(v·h), 2 (n·h)(n·l)/(l·h))`.
//! - Fresnel: Schlick (1994) `F = F0 + (1 - F0)(1 - cosθ)⁵`, and the exact unpolarised
//!   dielectric reflectance in the form given by Cook & Torrance (1982):
//!   `F = ½ (g-c)²/(g+c)² (1 + ((c(g+c)-1)/(c(g-c)+1))²)`, `c = cosθ`, `g² = η² + c² - 1`
//!   (total internal reflection, `g² < 0`, gives 1).

use glam::DVec3;
use std::f64::consts::PI;

/// The normalised halfway vector `normalize(l + v)`, or `None` when `l + v` is (nearly) zero.
#[inline]
pub(crate) fn half_vector(l: DVec3, v: DVec3) -> Option<DVec3> {
    let h = l + v;
    let len2 = h.length_squared();
    if len2 > 1e-300 {
        Some(h / len2.sqrt())
    } else {
        None
    }
}

/// `cosθ_d = l·h = v·h`, computed symmetrically as `|l + v| / 2` (for unit `l`, `v`), so
/// that a model using it is reciprocal to the last bit.
#[inline]
pub(crate) fn cos_theta_d(l: DVec3, v: DVec3) -> f64 {
    (0.5 * (l + v).length()).min(1.0)
}

/// A Lambertian term plus a grey lobe scaled per channel, `kd / π + ks s`: the shape of every
/// diffuse-plus-specular model here (Ward, Blinn-Phong, Torrance-Sparrow, Cook-Torrance).
#[inline]
pub(crate) fn diffuse_plus_lobe(kd: &[f64; 3], ks: &[f64; 3], lobe: f64) -> [f64; 3] {
    std::array::from_fn(|c| kd[c] / std::f64::consts::PI + ks[c] * lobe)
}

/// `kd / π + lobe F_schlick(cosθ_d, f0)` per channel: the Beckmann and GGX models' one shape.
#[inline]
pub(crate) fn diffuse_plus_schlick_lobe(
    kd: &[f64; 3],
    f0: &[f64; 3],
    cos_theta_d: f64,
    lobe: f64,
) -> [f64; 3] {
    std::array::from_fn(|c| kd[c] / PI + lobe * fresnel_schlick(cos_theta_d, f0[c]))
}

/// Panics unless both roughnesses are positive and finite: Beckmann's, GGX's and Ward's check.
#[track_caller]
pub(crate) fn assert_roughness(model: &str, alpha_x: f64, alpha_y: f64) {
    assert!(
        alpha_x > 0.0 && alpha_y > 0.0 && alpha_x.is_finite() && alpha_y.is_finite(),
        "{model} roughness must be positive and finite, got {alpha_x}, {alpha_y}"
    );
}

/// The halfway vector of two directions that are both above the horizon (`z > 0`), or `None`
/// when either is at or below it. Every model uses this to return zero below the horizon.
#[inline]
pub(crate) fn half_vector_above(l: DVec3, v: DVec3) -> Option<DVec3> {
    if l.z > 0.0 && v.z > 0.0 {
        half_vector(l, v)
    } else {
        None
    }
}

/// `tan²θ_h (cos²φ_h/α_x² + sin²φ_h/α_y²) = (h_x²/α_x² + h_y²/α_y²) / h_z²`: the anisotropic
/// "slope" exponent shared by Ward and Beckmann. `h_z` must be positive.
#[inline]
pub(crate) fn aniso_slope2(h: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    let sx = h.x / alpha_x;
    let sy = h.y / alpha_y;
    (sx * sx + sy * sy) / (h.z * h.z)
}

/// Anisotropic Beckmann distribution `D(h)` (1/sr), zero for `h_z <= 0`.
#[inline]
pub(crate) fn beckmann_d(h: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    if h.z <= 0.0 {
        return 0.0;
    }
    let c2 = h.z * h.z;
    (-aniso_slope2(h, alpha_x, alpha_y)).exp() / (PI * alpha_x * alpha_y * c2 * c2)
}

/// Anisotropic GGX (Trowbridge-Reitz) distribution `D(h)` (1/sr), zero for `h_z <= 0`.
#[inline]
pub(crate) fn ggx_d(h: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    if h.z <= 0.0 {
        return 0.0;
    }
    let sx = h.x / alpha_x;
    let sy = h.y / alpha_y;
    let t = sx * sx + sy * sy + h.z * h.z;
    1.0 / (PI * alpha_x * alpha_y * t * t)
}

/// `a = w_z / sqrt(α_x² w_x² + α_y² w_y²)`, i.e. `1 / (α_proj tanθ)`; infinite at the normal.
#[inline]
fn smith_a(w: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    let px = alpha_x * w.x;
    let py = alpha_y * w.y;
    let s2 = px * px + py * py;
    if s2 == 0.0 {
        f64::INFINITY
    } else {
        w.z / s2.sqrt()
    }
}

/// Complementary error function, Numerical Recipes `erfcc` (Chebyshev fit, relative error
/// below 1.2e-7 everywhere).
pub(crate) fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let ans = t * poly.exp();
    if x >= 0.0 {
        ans
    } else {
        2.0 - ans
    }
}

/// Smith `Λ(w)` for the anisotropic Beckmann distribution; `w_z` must be positive.
#[inline]
pub(crate) fn beckmann_lambda(w: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    let a = smith_a(w, alpha_x, alpha_y);
    if !a.is_finite() || a > 26.0 {
        // exp(-a²) underflows: Λ is exactly representable as 0.
        return 0.0;
    }
    let sqrt_pi = PI.sqrt();
    (((-a * a).exp() / (a * sqrt_pi) - erfc(a)) * 0.5).max(0.0)
}

/// Smith `Λ(w)` for the anisotropic GGX distribution; `w_z` must be positive.
#[inline]
pub(crate) fn ggx_lambda(w: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    let px = alpha_x * w.x;
    let py = alpha_y * w.y;
    let t2 = (px * px + py * py) / (w.z * w.z); // α² tan²θ
    0.5 * ((1.0 + t2).sqrt() - 1.0)
}

/// `χ⁺((w·h)/(w·n))`: the microfacet `h` is visible from `w` only on its front side.
#[inline]
fn facet_visible(w: DVec3, h: DVec3) -> bool {
    w.z > 0.0 && w.dot(h) > 0.0
}

/// Smith `G1(w, h) = χ⁺ / (1 + Λ(w))` for a given `Λ`: Beckmann's and GGX's.
#[inline]
#[cfg(test)]
fn smith_g1(w: DVec3, h: DVec3, lambda: impl Fn(DVec3) -> f64) -> f64 {
    if !facet_visible(w, h) {
        return 0.0;
    }
    1.0 / (1.0 + lambda(w))
}

/// Height-correlated Smith `G2 = χ⁺ / (1 + Λ(l) + Λ(v))` for a given `Λ`: Beckmann's and GGX's.
#[inline]
fn smith_g2_correlated(l: DVec3, v: DVec3, h: DVec3, lambda: impl Fn(DVec3) -> f64) -> f64 {
    if !facet_visible(l, h) || !facet_visible(v, h) {
        return 0.0;
    }
    1.0 / (1.0 + lambda(l) + lambda(v))
}

/// Smith `G1(w, h)` for Beckmann.
#[inline]
#[cfg(test)]
pub(crate) fn smith_g1_beckmann(w: DVec3, h: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    smith_g1(w, h, |w| beckmann_lambda(w, alpha_x, alpha_y))
}

/// Smith `G1(w, h)` for GGX.
#[inline]
#[cfg(test)]
pub(crate) fn smith_g1_ggx(w: DVec3, h: DVec3, alpha_x: f64, alpha_y: f64) -> f64 {
    smith_g1(w, h, |w| ggx_lambda(w, alpha_x, alpha_y))
}

/// Height-correlated Smith `G2(l, v, h) = 1 / (1 + Λ(l) + Λ(v))` for GGX (Heitz 2014, eq. 99).
#[inline]
pub(crate) fn smith_g2_ggx_correlated(
    l: DVec3,
    v: DVec3,
    h: DVec3,
    alpha_x: f64,
    alpha_y: f64,
) -> f64 {
    smith_g2_correlated(l, v, h, |w| ggx_lambda(w, alpha_x, alpha_y))
}

/// Height-correlated Smith `G2(l, v, h) = 1 / (1 + Λ(l) + Λ(v))` for Beckmann.
#[inline]
pub(crate) fn smith_g2_beckmann_correlated(
    l: DVec3,
    v: DVec3,
    h: DVec3,
    alpha_x: f64,
    alpha_y: f64,
) -> f64 {
    smith_g2_correlated(l, v, h, |w| beckmann_lambda(w, alpha_x, alpha_y))
}

/// V-cavity `G1(w, h) = min(1, 2 (n·h)(n·w) / (w·h))` (Heitz 2014, section 4).
#[inline]
pub(crate) fn vcavity_g1(w: DVec3, h: DVec3) -> f64 {
    if !facet_visible(w, h) || h.z <= 0.0 {
        return 0.0;
    }
    (2.0 * h.z * w.z / w.dot(h)).min(1.0)
}

/// Torrance-Sparrow / Cook-Torrance V-cavity shadowing-masking
/// `G = min(1, 2 (n·h)(n·v)/(v·h), 2 (n·h)(n·l)/(l·h))`, symmetric in `l` and `v`.
#[inline]
pub(crate) fn vcavity_g(l: DVec3, v: DVec3, h: DVec3) -> f64 {
    vcavity_g1(l, h).min(vcavity_g1(v, h))
}

/// Schlick's Fresnel approximation `F0 + (1 - F0)(1 - cosθ)⁵` for `cosθ` in `[0, 1]`.
#[inline]
pub(crate) fn fresnel_schlick(cos_theta: f64, f0: f64) -> f64 {
    let m = (1.0 - cos_theta).clamp(0.0, 1.0);
    let m2 = m * m;
    f0 + (1.0 - f0) * m2 * m2 * m
}

/// Exact unpolarised Fresnel reflectance of a dielectric interface with relative index of
/// refraction `eta` (Cook & Torrance 1982 form), for `cosθ` in `[0, 1]`.
#[inline]
pub(crate) fn fresnel_dielectric(cos_theta: f64, eta: f64) -> f64 {
    let c = cos_theta.clamp(0.0, 1.0);
    let g2 = eta * eta + c * c - 1.0;
    if g2 <= 0.0 {
        return 1.0; // total internal reflection
    }
    let g = g2.sqrt();
    let a = (g - c) / (g + c);
    let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    0.5 * a * a * (1.0 + b * b)
}

/// The relative index of refraction whose normal-incidence Fresnel reflectance is `f0`
/// (`f0 = ((η-1)/(η+1))²`), for `f0` in `[0, 1)`.
#[cfg(test)]
pub(crate) fn ior_from_f0(f0: f64) -> f64 {
    let s = f0.clamp(0.0, 1.0 - 1e-12).sqrt();
    (1.0 + s) / (1.0 - s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::dir;

    /// Midpoint quadrature of `∫ g(h) dω_h` over the upper hemisphere, with θ = (π/2) s²
    /// (fine near the normal, where the distributions peak).
    fn integrate_hemisphere(n: usize, g: impl Fn(DVec3) -> f64) -> f64 {
        let mut sum = 0.0;
        for i in 0..n {
            let s = (i as f64 + 0.5) / n as f64;
            let theta = 0.5 * PI * s * s;
            let dtheta = PI * s / n as f64;
            for j in 0..n {
                let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                sum += g(dir(theta, phi)) * theta.sin() * dtheta * (2.0 * PI / n as f64);
            }
        }
        sum
    }

    #[test]
    fn distributions_are_normalised() {
        for &(ax, ay) in &[(0.1, 0.1), (0.1, 0.5), (0.3, 0.2), (0.6, 0.6)] {
            let b = integrate_hemisphere(800, |h| beckmann_d(h, ax, ay) * h.z);
            assert!((b - 1.0).abs() < 2e-3, "Beckmann {ax} {ay}: {b}");
        }
        // GGX has long tails: the projected-area integral converges more slowly.
        for &(ax, ay) in &[(0.1, 0.1), (0.1, 0.5), (0.3, 0.2)] {
            let g = integrate_hemisphere(800, |h| ggx_d(h, ax, ay) * h.z);
            assert!((g - 1.0).abs() < 2e-3, "GGX {ax} {ay}: {g}");
        }
    }

    #[test]
    fn distributions_peak_value() {
        assert!((beckmann_d(DVec3::Z, 0.2, 0.4) - 1.0 / (PI * 0.08)).abs() < 1e-12);
        assert!((ggx_d(DVec3::Z, 0.2, 0.4) - 1.0 / (PI * 0.08)).abs() < 1e-12);
        assert_eq!(beckmann_d(-DVec3::Z, 0.2, 0.4), 0.0);
        assert_eq!(ggx_d(DVec3::X, 0.2, 0.4), 0.0);
    }

    /// Heitz 2014, eq. 20: a correct masking function satisfies
    /// `∫ G1(w, h) max(0, w·h) D(h) dω_h = w·n` for every direction `w`.
    #[test]
    fn masking_functions_satisfy_projected_area() {
        let (ax, ay) = (0.15, 0.4);
        for &(t, p) in &[(0.0, 0.0), (0.5, 0.3), (1.0, 1.2), (1.3, 2.0)] {
            let w = dir(t, p);
            let beck = integrate_hemisphere(800, |h| {
                smith_g1_beckmann(w, h, ax, ay) * w.dot(h).max(0.0) * beckmann_d(h, ax, ay)
            });
            let ggx = integrate_hemisphere(800, |h| {
                smith_g1_ggx(w, h, ax, ay) * w.dot(h).max(0.0) * ggx_d(h, ax, ay)
            });
            let vc = integrate_hemisphere(800, |h| {
                vcavity_g1(w, h) * w.dot(h).max(0.0) * beckmann_d(h, ax, ay)
            });
            for (name, val) in [("beckmann", beck), ("ggx", ggx), ("vcavity", vc)] {
                assert!(
                    (val - w.z).abs() < 5e-3 * w.z.max(0.2),
                    "{name} at theta={t}: {val} vs {}",
                    w.z
                );
            }
        }
    }

    #[test]
    fn erfc_matches_known_values() {
        // Reference values of erfc.
        for &(x, e) in &[
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (1.0, 0.157_299_207_050_285_1),
            (2.0, 0.004_677_734_981_047_266),
            (-1.0, 1.842_700_792_949_715),
            (3.0, 2.209_049_699_858_544e-5),
        ] {
            assert!(
                (erfc(x) - e).abs() <= 1.2e-7 * e,
                "erfc({x}) = {} vs {e}",
                erfc(x)
            );
        }
    }

    #[test]
    fn masking_limits() {
        let h = DVec3::Z;
        assert!((smith_g1_beckmann(DVec3::Z, h, 0.3, 0.3) - 1.0).abs() < 1e-15);
        assert!((smith_g1_ggx(DVec3::Z, h, 0.3, 0.3) - 1.0).abs() < 1e-15);
        let grazing = dir(0.5 * PI - 1e-4, 0.0);
        assert!(smith_g1_ggx(grazing, h, 0.3, 0.3) < 0.01);
        assert!(smith_g1_beckmann(grazing, h, 0.3, 0.3) < 0.01);
        // Back-facing microfacet is invisible.
        assert_eq!(smith_g1_ggx(dir(0.3, 0.0), dir(1.5, PI), 0.3, 0.3), 0.0);
        // Monotone in the angle.
        let mut last = 1.0;
        for k in 0..=89 {
            let w = dir((k as f64).to_radians(), 0.7);
            let g = smith_g1_beckmann(w, DVec3::Z, 0.3, 0.3);
            assert!(g <= last + 1e-15 && g > 0.0);
            last = g;
        }
    }

    #[test]
    fn fresnel_limits() {
        assert!((fresnel_schlick(1.0, 0.04) - 0.04).abs() < 1e-15);
        assert!((fresnel_schlick(0.0, 0.04) - 1.0).abs() < 1e-15);
        let eta = 1.5;
        let f0 = ((eta - 1.0) / (eta + 1.0)) * ((eta - 1.0) / (eta + 1.0));
        assert!((fresnel_dielectric(1.0, eta) - f0).abs() < 1e-15);
        assert!((fresnel_dielectric(0.0, eta) - 1.0).abs() < 1e-15);
        assert!((ior_from_f0(f0) - eta).abs() < 1e-12);
        // Brewster-ish dip then rise; always in [0, 1] and increasing toward grazing past 60°.
        for k in 0..=90 {
            let f = fresnel_dielectric((k as f64).to_radians().cos(), eta);
            assert!((0.0..=1.0).contains(&f));
        }
        // Exact value at 45 degrees for eta = 1.5 (from the s/p reflectances).
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let st = c / eta;
        let ct = (1.0 - st * st).sqrt();
        let rs = ((c - eta * ct) / (c + eta * ct)).powi(2);
        let rp = ((ct - eta * c) / (ct + eta * c)).powi(2);
        assert!((fresnel_dielectric(c, eta) - 0.5 * (rs + rp)).abs() < 1e-14);
    }

    #[test]
    fn vcavity_is_symmetric_and_bounded() {
        let l = dir(0.7, 0.2);
        let v = dir(1.2, 2.5);
        let h = half_vector(l, v).unwrap();
        let g = vcavity_g(l, v, h);
        assert_eq!(g, vcavity_g(v, l, h));
        assert!((0.0..=1.0).contains(&g));
        assert_eq!(vcavity_g(DVec3::Z, DVec3::Z, DVec3::Z), 1.0);
    }

    #[test]
    fn half_vector_degenerate() {
        assert!(half_vector(DVec3::X, -DVec3::X).is_none());
        assert!(half_vector_above(DVec3::Z, dir(1.6, 0.0)).is_none());
        let h = half_vector(DVec3::X, DVec3::Z).unwrap();
        assert!((h - DVec3::new(1.0, 0.0, 1.0).normalize()).length() < 1e-15);
    }
}
