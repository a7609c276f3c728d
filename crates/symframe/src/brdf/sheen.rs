//! A sheen fabric (velvet, brushed cotton): a Lambertian base, the "Charlie" sheen lobe of
//! fibres standing up from the surface (bright at grazing angles, symmetric about the normal)
//! and a weak anisotropic GGX lobe of the threads.
//!
//! Parameters: diffuse albedo `kd`; sheen colour `sheen` and roughness `sheen_alpha` in
//! (0, 1]; the thread lobe's Fresnel reflectance `f0` and widths `alpha_x`, `alpha_y`.
//!
//! Formula, with `θ_h` the angle of `h = normalize(l + v)` from the normal:
//!
//! ```text
//! f(l, v) = kd/π + sheen D_s(h) V(l, v) + f_ggx(l, v; f0, α_x, α_y)
//! D_s(h)  = (2 + 1/α_s) sin(θ_h)^(1/α_s) / (2π)                 (Estevez & Kulla 2017)
//! V(l, v) = 1 / (4 (n·l + n·v - (n·l)(n·v)))                     (Neubelt & Pettineo 2013)
//! ```
//!
//! `V` is symmetric in `l` and `v`: the model is reciprocal.
//!
//! Sources: A. C. Estevez, C. Kulla, "Production Friendly Microfacet Sheen BRDF", Sony Pictures
//! Imageworks, 2017; D. Neubelt, M. Pettineo, "Crafting a Next-Gen Material Pipeline for The
//! Order: 1886", SIGGRAPH 2013 course; glTF `KHR_materials_sheen` uses the same `D_s`.
//!
//! Tangent: the thread lobe's wider axis.

use super::{Brdf, Ggx, TangentAxis};
use glam::DVec3;
use std::f64::consts::PI;

/// Lambertian base, Charlie sheen and a weak anisotropic GGX thread lobe.
#[derive(Debug, Clone, PartialEq)]
pub struct Sheen {
    /// Diffuse albedo per RGB channel.
    pub kd: [f64; 3],
    /// Sheen colour per RGB channel.
    pub sheen: [f64; 3],
    /// Sheen roughness in (0, 1].
    pub sheen_alpha: f64,
    /// The thread lobe.
    pub threads: Ggx,
}

impl Sheen {
    /// A sheen fabric. Panics if the sheen roughness is outside (0, 1].
    pub fn new(kd: [f64; 3], sheen: [f64; 3], sheen_alpha: f64, threads: Ggx) -> Self {
        assert!(
            sheen_alpha > 0.0 && sheen_alpha <= 1.0,
            "sheen roughness in (0, 1]"
        );
        Sheen {
            kd,
            sheen,
            sheen_alpha,
            threads: Ggx {
                kd: [0.0; 3],
                ..threads
            },
        }
    }
}

impl Brdf for Sheen {
    fn eval(&self, light_in_local: DVec3, view_in_local: DVec3) -> [f64; 3] {
        let (l, v) = (light_in_local, view_in_local);
        if l.z <= 0.0 || v.z <= 0.0 {
            return [0.0; 3];
        }
        let h = (l + v).normalize();
        let sin_h = (1.0 - h.z * h.z).max(0.0).sqrt();
        let inv = 1.0 / self.sheen_alpha;
        let d = (2.0 + inv) * sin_h.powf(inv) / (2.0 * PI);
        let vis = 1.0 / (4.0 * (l.z + v.z - l.z * v.z));
        let t = self.threads.eval(l, v);
        std::array::from_fn(|c| self.kd[c] / PI + self.sheen[c] * d * vis + t[c])
    }

    fn tangent_axis(&self) -> TangentAxis {
        self.threads.tangent_axis()
    }

    fn name(&self) -> String {
        use super::spec::fmt_rgb;
        format!(
            "sheen:kd={},sheen={},sheen_alpha={},threads=({})",
            fmt_rgb(&self.kd),
            fmt_rgb(&self.sheen),
            self.sheen_alpha,
            self.threads.name()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::testutil::*;

    #[test]
    fn properties() {
        let b = Sheen::new(
            [0.4, 0.1, 0.1],
            [0.5; 3],
            0.4,
            Ggx::new([0.0; 3], [0.04; 3], 0.3, 0.15),
        );
        assert_zero_below_horizon(&b);
        assert_nonneg_finite(&b);
        assert_reciprocal(&b, 1e-12);
        assert_mirror_symmetric(&b, 1e-12);
        assert_not_rotation_invariant(&b);
        assert_eq!(b.tangent_axis(), TangentAxis::X);
        assert_energy(&b, 60.0, 2e-3);
        // The sheen brightens grazing configurations: at 80 degrees, back-scattering.
        let g = dir(80f64.to_radians(), 0.0);
        let s = b.eval(g, g)[0]
            - Sheen {
                sheen: [0.0; 3],
                ..b.clone()
            }
            .eval(g, g)[0];
        assert!(s > 0.1, "{s}");
    }
}
