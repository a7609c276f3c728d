//! A sharp dielectric coat over any base BRDF, sharing its frame: car paint (a clear coat over
//! a brushed or metallic base), lacquered brushed metal. Two lobes about one normal: the coat's
//! narrow isotropic highlight and the base's broad, possibly anisotropic one.
//!
//! Parameters: the coat's GGX roughness `coat_alpha` and index of refraction `coat_ior`; the
//! base BRDF.
//!
//! Formula (a single-scattering thin coat, no refraction of the directions into the coat):
//!
//! ```text
//! f(l, v) = D_c(h) F(l·h) G2_c(l, v) / (4 (n·l)(n·v))  +  (1 - F(n·l)) (1 - F(n·v)) f_base(l, v)
//! ```
//!
//! with `D_c`, `G2_c` isotropic GGX of roughness `coat_alpha` and `F` the exact dielectric
//! Fresnel reflectance of `coat_ior`. Both terms are symmetric in `l` and `v`, so the sum is
//! reciprocal; the base is seen through the coat's transmission both ways (energy the coat
//! reflects does not reach the base).
//!
//! Sources: A. Weidlich, A. Wilkie, "Arbitrarily Layered Micro-Facet Surfaces", GRAPHITE 2007
//! (the attenuated-base form, here without the refracted directions); B. Walter et al., EGSR
//! 2007 (GGX); the glTF `KHR_materials_clearcoat` extension uses the same two-term form.
//!
//! Tangent: the base's.

use super::microfacet::{
    cos_theta_d, fresnel_dielectric, ggx_d, half_vector_above, smith_g2_ggx_correlated,
};
use super::{Brdf, TangentAxis};
use glam::DVec3;

/// A clear GGX coat over a base BRDF.
pub struct Layered {
    /// The coat's GGX roughness (isotropic); positive.
    pub coat_alpha: f64,
    /// The coat's index of refraction (1.5 for a lacquer).
    pub coat_ior: f64,
    /// What lies under the coat.
    pub base: Box<dyn Brdf>,
}

impl Layered {
    /// A coat of roughness `coat_alpha` and index `coat_ior` over `base`. Panics if the
    /// roughness is not positive and finite or the index is not above 1.
    pub fn new(coat_alpha: f64, coat_ior: f64, base: Box<dyn Brdf>) -> Self {
        assert!(
            coat_alpha > 0.0 && coat_alpha.is_finite(),
            "coat roughness must be positive and finite, got {coat_alpha}"
        );
        assert!(coat_ior > 1.0, "coat index must exceed 1, got {coat_ior}");
        Layered {
            coat_alpha,
            coat_ior,
            base,
        }
    }
}

impl Brdf for Layered {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        let Some(h) = half_vector_above(l, v) else {
            return [0.0; 3];
        };
        let a = self.coat_alpha;
        let coat = ggx_d(h, a, a)
            * smith_g2_ggx_correlated(l, v, h, a, a)
            * fresnel_dielectric(cos_theta_d(l, v), self.coat_ior)
            / (4.0 * l.z * v.z);
        let through = (1.0 - fresnel_dielectric(l.z, self.coat_ior))
            * (1.0 - fresnel_dielectric(v.z, self.coat_ior));
        let base = self.base.eval(l, v);
        std::array::from_fn(|c| coat + through * base[c])
    }

    fn tangent_axis(&self) -> TangentAxis {
        self.base.tangent_axis()
    }

    fn name(&self) -> String {
        format!(
            "layered:coat_alpha={},ior={},base=({})",
            self.coat_alpha,
            self.coat_ior,
            self.base.name()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;
    use crate::brdf::Ggx;

    fn car_paint() -> Layered {
        Layered::new(
            0.02,
            1.5,
            Box::new(Ggx::new([0.05, 0.1, 0.3], [0.6, 0.6, 0.65], 0.3, 0.1)),
        )
    }

    #[test]
    fn properties() {
        let b = car_paint();
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-12);
        assert_mirror_symmetric(&b, 1e-12);
        assert_not_rotation_invariant(&b);
        assert_eq!(b.tangent_axis(), TangentAxis::X);
        assert_energy(&b, 60.0, 2e-3);
    }

    #[test]
    fn the_coat_is_a_sharp_peak_over_the_base() {
        let b = car_paint();
        let base = Ggx::new([0.05, 0.1, 0.3], [0.6, 0.6, 0.65], 0.3, 0.1);
        // At the mirror direction the coat's peak dominates; 10 degrees off it has gone and
        // the base, dimmed by the coat's transmission, remains.
        let v = dir(20f64.to_radians(), 0.0);
        let mirror = dir(20f64.to_radians(), std::f64::consts::PI);
        assert!(b.eval(mirror, v)[0] > 5.0 * base.eval(mirror, v)[0]);
        let off = dir(40f64.to_radians(), std::f64::consts::PI);
        let (f, g) = (b.eval(off, v)[0], base.eval(off, v)[0]);
        assert!(f < g && f > 0.8 * g, "{f} {g}");
    }
}
