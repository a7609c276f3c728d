//! A woven fabric (satin, twill) as two anisotropic GGX lobes at right angles sharing one
//! normal: the warp threads' highlight stretched along one axis, the weft's along the other,
//! giving the cross-shaped highlight of woven satin; a Lambertian base under both.
//!
//! Parameters: diffuse albedo `kd`; the warp lobe's Fresnel reflectance `warp_f0` and widths
//! `along` (across the threads' axis, the wide one) and `across`; the weft lobe's weight
//! `weft_weight` relative to the warp's (below 1: the warp is the stronger lobe).
//!
//! Formula, with `f_ggx(l, v; f0, α_x, α_y)` the GGX lobe of [`super::Ggx`] without its
//! diffuse term:
//!
//! ```text
//! f(l, v) = kd/π + f_ggx(l, v; f0, along, across) + weft_weight f_ggx(l, v; f0, across, along)
//! ```
//!
//! Sources: I. Sadeghi, O. Bisker, J. De Deken, H. W. Jensen, "A Practical Microcylinder
//! Appearance Model for Cloth Rendering", ACM TOG 32(2), 2013 (two thread directions, each an
//! anisotropic lobe); here each lobe is the GGX of B. Walter et al., EGSR 2007.
//!
//! Tangent: the axis of the stronger lobe's wider width (local x, the warp's, when
//! `weft_weight < 1`; y when it exceeds 1).

use super::{Brdf, Ggx, TangentAxis};
use glam::DVec3;
use std::f64::consts::PI;

/// Two perpendicular anisotropic GGX lobes over a Lambertian base.
#[derive(Debug, Clone, PartialEq)]
pub struct Woven {
    /// Diffuse albedo per RGB channel.
    pub kd: [f64; 3],
    /// The lobes' Fresnel reflectance at normal incidence per RGB channel.
    pub f0: [f64; 3],
    /// The warp lobe's roughness along local x (the wide axis); positive.
    pub along: f64,
    /// Its roughness along local y; positive.
    pub across: f64,
    /// The weft lobe's weight relative to the warp's; non-negative.
    pub weft_weight: f64,
}

impl Woven {
    /// A woven material. Panics if a roughness is not positive or the weight is negative.
    pub fn new(kd: [f64; 3], f0: [f64; 3], along: f64, across: f64, weft_weight: f64) -> Self {
        assert!(along > 0.0 && across > 0.0 && along.is_finite() && across.is_finite());
        assert!(weft_weight >= 0.0 && weft_weight.is_finite());
        Woven {
            kd,
            f0,
            along,
            across,
            weft_weight,
        }
    }
}

impl Brdf for Woven {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        if l.z <= 0.0 || v.z <= 0.0 {
            return [0.0; 3];
        }
        let warp = Ggx::new([0.0; 3], self.f0, self.along, self.across).eval(l, v);
        let weft = Ggx::new([0.0; 3], self.f0, self.across, self.along).eval(l, v);
        std::array::from_fn(|c| self.kd[c] / PI + warp[c] + self.weft_weight * weft[c])
    }

    fn tangent_axis(&self) -> TangentAxis {
        // The stronger lobe's wide axis: the warp's unless the weft outweighs it.
        let warp = TangentAxis::of_roughness(self.along, self.across);
        let swapped = match warp {
            TangentAxis::X => TangentAxis::Y,
            TangentAxis::Y => TangentAxis::X,
            TangentAxis::None => TangentAxis::None,
        };
        match self.weft_weight.partial_cmp(&1.0) {
            Some(std::cmp::Ordering::Less) => warp,
            Some(std::cmp::Ordering::Greater) => swapped,
            _ => TangentAxis::None,
        }
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "woven:kd={},f0={},along={},across={},weft={}",
            fmt_rgb(&self.kd),
            fmt_rgb(&self.f0),
            self.along,
            self.across,
            self.weft_weight
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;

    #[test]
    fn properties() {
        let b = Woven::new([0.3, 0.1, 0.1], [0.05; 3], 0.35, 0.08, 0.6);
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-12);
        assert_mirror_symmetric(&b, 1e-12);
        assert_not_rotation_invariant(&b);
        assert_eq!(b.tangent_axis(), TangentAxis::X);
        assert_eq!(measured_wide_axis(&b), TangentAxis::X);
        assert_energy(&b, 60.0, 2e-3);
        // Equal lobes: the cross has no stronger arm.
        let even = Woven::new([0.3; 3], [0.05; 3], 0.35, 0.08, 1.0);
        assert_eq!(even.tangent_axis(), TangentAxis::None);
        assert_rotation_invariant_by_quarter_turn(&even);
    }

    /// Two equal perpendicular lobes look the same a quarter turn round the normal.
    fn assert_rotation_invariant_by_quarter_turn(b: &dyn Brdf) {
        let q = |d: DVec3| DVec3::new(-d.y, d.x, d.z);
        for (l, v) in direction_pairs(3, 200) {
            let (a, c) = (b.eval(l, v), b.eval(q(l), q(v)));
            assert!(close(a, c, 1e-12, 1e-14), "{a:?} {c:?}");
        }
    }
}
