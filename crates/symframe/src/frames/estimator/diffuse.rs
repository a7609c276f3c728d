//! How much of a pixel's signal a Lambertian term leaves unexplained, and how much the
//! capture's noise alone would leave: the diffuse tests' evidence (docs/method.md, "Default
//! measure", "The policy's settings").

use glam::DVec3;

use crate::frames::policy::NoiseShare;
use crate::frames::rig::Rig;
use crate::noise::NoiseModel;

/// The share of a pixel's signal energy (over lights with `n.l` at least
/// [`ShadowSettings::min_cosine`](crate::frames::policy::ShadowSettings::min_cosine): near grazing, shadows the fitted normal cannot tell from light
/// decide nothing) that the best Lambertian
/// term `d (n.l)` with normal `n` (RGB `d >= 0`, least squares) leaves unexplained: 0 for a
/// diffuse surface, the specular part's share otherwise.
pub(super) fn unexplained_share(rig: &Rig, slice: &[f32], n: DVec3, min_cosine: f64) -> f64 {
    let (mut il, mut ll, mut ii) = ([0.0f64; 3], 0.0f64, 0.0f64);
    for (s, l) in slice.chunks_exact(3).zip(rig.lights_in_camera()) {
        let nl = n.dot(*l);
        if nl < min_cosine || !s[0].is_finite() {
            continue;
        }
        ll += nl * nl;
        for c in 0..3 {
            let v = s[c] as f64;
            il[c] += v * nl;
            ii += v * v;
        }
    }
    if ii <= 0.0 || ll <= 0.0 {
        return 0.0;
    }
    let explained: f64 = il.iter().map(|&x| x.max(0.0).powi(2) / ll).sum();
    (1.0 - explained / ii).max(0.0)
}

/// What the capture's noise alone would leave of a Lambertian pixel's well-lit energy
/// ([`unexplained_share`] over the same lights at normal `n`), as a share: each sample's
/// channels carry the noise model's variance at their value (about a third of the grey each),
/// the fit's five parameters (three albedos, the normal's two tilts) take their share, and a
/// sum of squared Gaussian residuals has variance `2 sigma^4` per value.
pub(super) fn diffuse_noise_share(
    rig: &Rig,
    slice: &[f32],
    n: DVec3,
    min_cosine: f64,
    noise: &NoiseModel,
) -> NoiseShare {
    let (mut expected, mut spread, mut energy, mut values) = (0.0, 0.0, 0.0, 0usize);
    for (s, l) in slice.chunks_exact(3).zip(rig.lights_in_camera()) {
        if n.dot(*l) < min_cosine || !s[0].is_finite() {
            continue;
        }
        let [r, g, b] = [s[0] as f64, s[1] as f64, s[2] as f64];
        // One channel's variance at the sample's mean channel value, for all three.
        let v = noise.variance((r + g + b) / 3.0);
        expected += 3.0 * v;
        spread += 3.0 * 2.0 * v * v;
        energy += r * r + g * g + b * b;
        values += 3;
    }
    if energy <= 0.0 || values <= 5 {
        return NoiseShare::default();
    }
    let kept = (values - 5) as f64 / values as f64;
    NoiseShare {
        expected: expected * kept / energy,
        sd: spread.sqrt() / energy,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::policy::PolicySettings;
    use crate::geometry::tangent_basis;

    #[test]
    fn a_diffuse_pixel_leaves_what_its_noise_leaves_and_a_lobe_more() {
        // A coloured Lambertian pixel under 1,000 lights with shot and read noise drawn per
        // channel as the noise model states it: what its Lambertian term leaves is above the
        // noise-free share (so only the noise test tells it diffuse), about the share the
        // noise model expects, and under the test's limit in every draw; a weak glossy coat
        // leaves several times the limit.
        use crate::brdf::{Ggx, Lambertian};
        use crate::frames::lobe::tests::{gaussians, slice};
        use crate::frames::rig::{uniform_cone_lights, RigOptions};
        let rig = Rig::new(&uniform_cone_lights(1000, 65.0), RigOptions::default()).unwrap();
        let n = DVec3::new(0.3, -0.2, 1.0).normalize();
        let t = tangent_basis(n).0;
        let settings = PolicySettings::default();
        let min_cosine = settings.shadows.min_cosine;
        let matte = slice(&rig, &Lambertian::new([0.6, 0.4, 0.3]), n, t);
        let peak = matte.iter().copied().fold(0.0f32, f32::max) as f64;
        // Full scale at the brightest channel: 500 electrons there, read noise of 2.
        let noise = NoiseModel {
            shot: 1.0 / 500.0,
            read: (2.0f64 / 500.0).powi(2),
            ..NoiseModel::default()
        };
        let mut gauss = gaussians(0x2545_f491_4f6c_dd1d);
        let mut noisy = |clean: &[f32], scale: f64| -> Vec<f32> {
            clean
                .iter()
                .map(|&v| {
                    let v = v as f64 * scale;
                    (v + noise.variance(v).sqrt() * gauss()) as f32
                })
                .collect()
        };
        let (mut ratio, draws) = (0.0, 20);
        for _ in 0..draws {
            let s = noisy(&matte, 1.0 / peak);
            let share = unexplained_share(&rig, &s, n, min_cosine);
            let share_noise = diffuse_noise_share(&rig, &s, n, min_cosine, &noise);
            let (limit, expected) = (share_noise.at(3.09), share_noise.expected);
            assert!(share > settings.diffuse.pure_share, "{share}");
            assert!(share < limit, "{share} {limit}");
            ratio += share / expected / draws as f64;
        }
        assert!((0.8..1.2).contains(&ratio), "share / expected {ratio}");
        // The same pixel with a weak glossy coat: its lobe is no noise.
        let glossy = slice(
            &rig,
            &Ggx::new([0.6, 0.4, 0.3], [0.08; 3], 0.15, 0.15),
            n,
            t,
        );
        let s = noisy(&glossy, 1.0 / peak);
        let share = unexplained_share(&rig, &s, n, min_cosine);
        let limit = diffuse_noise_share(&rig, &s, n, min_cosine, &noise).at(3.09);
        assert!(share > 3.0 * limit, "{share} {limit}");
    }
}
