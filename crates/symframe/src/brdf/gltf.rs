//! glTF 2.0 metallic-roughness BRDF with `KHR_materials_anisotropy`.
//!
//! Parameters: base colour `c` per RGB channel in `[0, 1]`, `metallic` in `[0, 1]`,
//! `roughness` in `(0, 1]` and anisotropy strength `s` in `[0, 1]`; the direction of increased
//! roughness is local x (the tangent; `anisotropyRotation` 0).
//!
//! Formula, with `h = normalize(l + v)`, `α = roughness²`, `α_t = mix(α, 1, s²)`, `α_b = α`:
//!
//! ```text
//! D(h)   = 1 / (π α_t α_b (h_x²/α_t² + h_y²/α_b² + h_z²)²)
//! V(l,v) = min(1, 0.5 / (l_z |(α_t v_x, α_b v_y, v_z)| + v_z |(α_t l_x, α_b l_y, l_z)|))
//! S      = (1 - |v·h|)⁵
//! dielectric = (1 - F_d) c/π + F_d V D,      F_d = 0.04 + 0.96 S     (fresnel_mix, ior 1.5)
//! metal      = (c + (1 - c) S) V D                                    (conductor_fresnel)
//! f(l, v)    = (1 - metallic) dielectric + metallic metal
//! ```
//!
//! Per channel `f = c A + B` with `A`, `B` independent of the colour ([`GltfPbr::terms`]):
//! the fit uses this to solve for the colour in closed form. `V` is the height-correlated Smith
//! visibility `G2 / (4 (n·l)(n·v))`, symmetric in `l` and `v`, so the model is reciprocal.
//!
//! Sources: the glTF 2.0 specification, Appendix B "BRDF Implementation" (Khronos, 2021);
//! the `KHR_materials_anisotropy` extension (Khronos, 2023), "Anisotropy" and
//! "Implementation" (`D_GGX_anisotropic`, `V_GGX_anisotropic`).
//!
//! Tangent: local x when the strength is positive and `α < 1` (`α_t > α_b`), else none.

use super::microfacet::half_vector_above;
use super::{Brdf, TangentAxis};
use glam::DVec3;
use std::f64::consts::PI;

/// glTF 2.0 metallic-roughness BRDF with `KHR_materials_anisotropy` (direction = local x).
#[derive(Debug, Clone, PartialEq)]
pub struct GltfPbr {
    /// Base colour per RGB channel, in `[0, 1]`.
    pub base_color: [f64; 3],
    /// Metalness, in `[0, 1]`.
    pub metallic: f64,
    /// Perceptual roughness, in `(0, 1]` (`α = roughness²`).
    pub roughness: f64,
    /// Anisotropy strength, in `[0, 1]`.
    pub anisotropy: f64,
}

/// The Fresnel reflectance at normal incidence of the dielectric (`ior = 1.5`).
pub(crate) const DIELECTRIC_F0: f64 = 0.04;

impl GltfPbr {
    /// A glTF material. Panics if a parameter is outside its range (see the fields).
    pub fn new(base_color: [f64; 3], metallic: f64, roughness: f64, anisotropy: f64) -> Self {
        assert!(
            base_color.iter().all(|c| (0.0..=1.0).contains(c))
                && (0.0..=1.0).contains(&metallic)
                && roughness > 0.0
                && roughness <= 1.0
                && (0.0..=1.0).contains(&anisotropy),
            "glTF parameters out of range: base colour {base_color:?}, metallic {metallic}, \
             roughness {roughness}, anisotropy {anisotropy}"
        );
        Self {
            base_color,
            metallic,
            roughness,
            anisotropy,
        }
    }

    /// `(α_t, α_b)`: the GGX roughnesses along the tangent and the bitangent.
    pub fn alphas(roughness: f64, anisotropy: f64) -> (f64, f64) {
        let a = roughness * roughness;
        (a + (1.0 - a) * anisotropy * anisotropy, a)
    }

    /// `(A, B)` with `f = c A + B` per channel at `metallic` and GGX roughnesses `at`, `ab`;
    /// `None` when either direction is at or below the horizon.
    #[inline]
    pub fn terms(l: DVec3, v: DVec3, metallic: f64, at: f64, ab: f64) -> Option<(f64, f64)> {
        let h = half_vector_above(l, v)?;
        let f = DVec3::new(ab * h.x, at * h.y, at * ab * h.z);
        let w2 = at * ab / f.length_squared();
        let d = at * ab * w2 * w2 / PI;
        let gv = l.z * DVec3::new(at * v.x, ab * v.y, v.z).length();
        let gl = v.z * DVec3::new(at * l.x, ab * l.y, l.z).length();
        let vis = (0.5 / (gv + gl)).min(1.0);
        let spec = vis * d;
        let s = (1.0 - v.dot(h).abs()).powi(5);
        let fd = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * s;
        let a = (1.0 - metallic) * (1.0 - fd) / PI + metallic * (1.0 - s) * spec;
        let b = ((1.0 - metallic) * fd + metallic * s) * spec;
        Some((a, b))
    }
}

impl Brdf for GltfPbr {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (at, ab) = Self::alphas(self.roughness, self.anisotropy);
        match Self::terms(light_in_local, view_in_local, self.metallic, at, ab) {
            Some((a, b)) => self.base_color.map(|c| c * a + b),
            None => [0.0; 3],
        }
    }

    fn tangent_axis(&self) -> TangentAxis {
        let (at, ab) = Self::alphas(self.roughness, self.anisotropy);
        TangentAxis::of_roughness(at, ab)
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "gltf:base={},metallic={},roughness={},anisotropy={}",
            fmt_rgb(&self.base_color),
            self.metallic,
            self.roughness,
            self.anisotropy
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;

    #[test]
    fn peak_value_by_hand() {
        // l = v = n: h = n, v.h = 1 so S = 0, F_d = 0.04; D = 1/(π α_t α_b);
        // V = 0.5 / (1 + 1) = 1/4.
        let (r, s) = (0.5, 0.6);
        let a = 0.25;
        let at = a + (1.0 - a) * 0.36;
        let d = 1.0 / (PI * at * a);
        let b = GltfPbr::new([0.8, 0.4, 0.2], 0.0, r, s);
        let f = b.eval(DVec3::Z, DVec3::Z);
        for (c, base) in [0.8, 0.4, 0.2].into_iter().enumerate() {
            let expect = 0.96 * base / PI + 0.04 * 0.25 * d;
            assert!((f[c] - expect).abs() < 1e-12, "{f:?} {expect}");
        }
        // A metal reflects its base colour at normal incidence and has no diffuse part.
        let m = GltfPbr::new([0.8, 0.4, 0.2], 1.0, r, s).eval(DVec3::Z, DVec3::Z);
        for (c, base) in [0.8, 0.4, 0.2].into_iter().enumerate() {
            assert!((m[c] - base * 0.25 * d).abs() < 1e-12, "{m:?}");
        }
    }

    #[test]
    fn off_peak_value_by_hand() {
        // An isotropic metal, l and v 60 degrees apart in the xz plane: h = z tilted 0 (v·h =
        // cos 30°), D = α²/(π ((n·h)² (α² - 1) + 1)²), V = 0.5 / (2 l_z sqrt(α² sin² + cos²)).
        let (theta, r) = (30f64.to_radians(), 0.4);
        let a: f64 = r * r;
        let l = DVec3::new(theta.sin(), 0.0, theta.cos());
        let v = DVec3::new(-theta.sin(), 0.0, theta.cos());
        let d = a * a / (PI * (a * a - 1.0 + 1.0).powi(2));
        let g = theta.cos() * (a * a * theta.sin().powi(2) + theta.cos().powi(2)).sqrt();
        let vis = 0.5 / (2.0 * g);
        let s = (1.0 - theta.cos()).powi(5);
        let f = GltfPbr::new([0.9, 0.5, 0.1], 1.0, r, 0.0).eval(l, v);
        for (c, base) in [0.9, 0.5, 0.1].into_iter().enumerate() {
            let expect = (base + (1.0 - base) * s) * vis * d;
            assert!((f[c] - expect).abs() < 1e-12 * expect, "{f:?} {expect}");
        }
        // Tilting h away from the normal by 0.2 rad along x (the tangent) and along y: the
        // anisotropic D is wider along x.
        let b = GltfPbr::new([0.5; 3], 1.0, 0.3, 0.7);
        let (at, ab) = GltfPbr::alphas(0.3, 0.7);
        let d_of = |h: DVec3| {
            1.0 / (PI
                * at
                * ab
                * (h.x * h.x / (at * at) + h.y * h.y / (ab * ab) + h.z * h.z).powi(2))
        };
        for h in [dir(0.2, 0.0), dir(0.2, 0.5 * PI)] {
            let v = DVec3::Z;
            let l = 2.0 * h.z * h - v;
            let (_, bb) = GltfPbr::terms(l, v, 1.0, at, ab).unwrap();
            let (aa, _) = GltfPbr::terms(l, v, 1.0, at, ab).unwrap();
            let gv = l.z * 1.0;
            let gl = (at * at * l.x * l.x + ab * ab * l.y * l.y + l.z * l.z).sqrt();
            let vis = 0.5 / (gv + gl);
            let s = (1.0 - h.z).powi(5);
            let expect = (0.5 + 0.5 * s) * vis * d_of(h);
            assert!((0.5 * aa + bb - expect).abs() < 1e-12 * expect);
            assert!((b.eval(l, v)[0] - expect).abs() < 1e-12 * expect);
        }
        assert!(b.eval(dir(0.4, 0.0), DVec3::Z)[0] > b.eval(dir(0.4, 0.5 * PI), DVec3::Z)[0]);
    }

    #[test]
    fn properties() {
        let b = GltfPbr::new([0.7, 0.5, 0.2], 0.3, 0.4, 0.8);
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-12);
        assert_mirror_symmetric(&b, 1e-13);
        assert_not_rotation_invariant(&b);
        assert_eq!(b.tangent_axis(), TangentAxis::X);
        assert_eq!(measured_wide_axis(&b), TangentAxis::X);
        let iso = GltfPbr::new([0.7, 0.5, 0.2], 0.3, 0.4, 0.0);
        assert_rotation_invariant(&iso, 1e-9);
        assert_eq!(iso.tangent_axis(), TangentAxis::None);
    }

    #[test]
    fn energy() {
        // A white metal: single scattering loses energy, never gains.
        for (r, s) in [(0.3, 0.0), (0.5, 0.5), (0.8, 0.9)] {
            assert_energy(&GltfPbr::new([1.0; 3], 1.0, r, s), 85.0, 2e-3);
            // The dielectric weights its diffuse part by 1 - F(v.h) per half vector, not by
            // the layer's directional albedo (the specification's fresnel_mix): a white one
            // reflects up to a few percent more than it receives; the fit does not rely on it.
            assert_energy(&GltfPbr::new([1.0; 3], 0.0, r, s), 85.0, 0.03);
            assert_energy(&GltfPbr::new([0.8; 3], 0.5, r, s), 85.0, 2e-3);
        }
    }

    #[test]
    fn spec_round_trip() {
        let b = GltfPbr::new([0.7, 0.5, 0.2], 0.3, 0.4, 0.8);
        let p = crate::brdf::parse_model(&b.name()).unwrap();
        assert_eq!(p.name(), b.name());
        assert!(crate::brdf::parse_model("gltf:metallic=1.5").is_err());
        assert!(crate::brdf::parse_model("gltf:roughness=0").is_err());
        assert!(crate::brdf::parse_model("gltf:base=1.2").is_err());
    }

    #[test]
    #[should_panic(expected = "glTF parameters out of range")]
    fn rejects_zero_roughness() {
        let _ = GltfPbr::new([0.5; 3], 0.0, 0.0, 0.0);
    }
}
