//! Lambertian (ideal diffuse) reflection.
//!
//! Parameters: `albedo` ρ per RGB channel (the directional-hemispherical reflectance, in
//! `[0, 1]` for a physical surface).
//!
//! Formula: `f(l, v) = ρ / π` for `l_z > 0` and `v_z > 0`, zero otherwise.
//!
//! Source: J. H. Lambert, *Photometria*, 1760. Isotropic, reciprocal, and symmetric under
//! every reflection and rotation of the local frame; its directional albedo is exactly ρ.

use super::{Brdf, TangentAxis};
use glam::DVec3;
use std::f64::consts::PI;

/// Lambertian BRDF `f = albedo / π`.
#[derive(Debug, Clone, PartialEq)]
pub struct Lambertian {
    /// Diffuse albedo per RGB channel.
    pub albedo: [f64; 3],
}

impl Lambertian {
    /// A Lambertian surface with the given albedo per channel.
    pub fn new(albedo: [f64; 3]) -> Self {
        Lambertian { albedo }
    }
}

impl Brdf for Lambertian {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        if light_in_local.z <= 0.0 || view_in_local.z <= 0.0 {
            return [0.0; 3];
        }
        self.albedo.map(|a| a / PI)
    }

    fn tangent_axis(&self) -> TangentAxis {
        TangentAxis::None
    }

    fn name(&self) -> String {
        format!("lambertian:albedo={}", super::spec::fmt_rgb(&self.albedo))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;

    #[test]
    fn value_is_exact() {
        let b = Lambertian::new([0.8, 0.5, 0.2]);
        let f = b.eval(dir(0.4, 1.0), dir(1.1, -2.0));
        assert_eq!(f, [0.8 / PI, 0.5 / PI, 0.2 / PI]);
        assert_eq!(b.eval(DVec3::Z, DVec3::Z), f);
    }

    #[test]
    fn properties() {
        let b = Lambertian::new([0.9, 0.5, 0.0]);
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 0.0);
        assert_mirror_symmetric(&b, 0.0);
        assert_rotation_invariant(&b, 0.0);
        assert_eq!(b.tangent_axis(), TangentAxis::None);
    }

    #[test]
    fn albedo_is_recovered() {
        let b = Lambertian::new([1.0, 0.5, 0.25]);
        for t in [0.0f64, 30.0, 60.0, 85.0] {
            let a = directional_albedo(&b, dir(t.to_radians(), 0.3), 400);
            assert!(close(a, [1.0, 0.5, 0.25], 2e-3, 0.0), "{t}: {a:?}");
        }
    }
}
