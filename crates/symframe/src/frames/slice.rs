//! The per-pixel BRDF slice: measured radiance as a function of the halfway vector,
//! reconstructed between the samples by spherical barycentric interpolation on the rig's
//! triangulation.

use glam::DVec3;

use crate::frames::rig::Rig;

/// The slice's RGB value at a unit halfway vector; `None` where there is no data (outside the
/// sampled region, or a corner sample is invalid).
#[inline]
pub(crate) fn interpolate(rig: &Rig, slice: &[f32], halfway: DVec3) -> Option<[f64; 3]> {
    let loc = rig.locate(halfway)?;
    let mut out = [0.0f64; 3];
    for k in 0..3 {
        let o = loc.vertices[k] as usize * 3;
        let w = loc.weights[k];
        out[0] += w * slice[o] as f64;
        out[1] += w * slice[o + 1] as f64;
        out[2] += w * slice[o + 2] as f64;
    }
    // An invalid corner (NaN) poisons the sum: no data here.
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// A pixel's slice as the symmetry objective reads it: the value at any halfway vector.
pub(crate) trait SliceLookup {
    /// RGB radiance at a unit halfway vector, `None` where there is no data.
    fn value(&self, halfway: DVec3) -> Option<[f64; 3]>;
}

/// The reference reconstruction: triangle location and spherical barycentric weights at every
/// query ([`interpolate`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ExactSlice<'a> {
    /// The rig.
    pub rig: &'a Rig,
    /// The pixel's samples in rig order.
    pub samples: &'a [f32],
}

impl SliceLookup for ExactSlice<'_> {
    #[inline]
    fn value(&self, halfway: DVec3) -> Option<[f64; 3]> {
        interpolate(self.rig, self.samples, halfway)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::rig::{uniform_cone_lights, RigOptions};

    fn linear_field(h: DVec3) -> [f32; 3] {
        [
            (1.0 + h.x) as f32,
            (2.0 - h.y) as f32,
            (0.5 + h.x + 2.0 * h.y + 3.0 * h.z) as f32,
        ]
    }

    #[test]
    fn exact_at_samples_and_linear_fields_are_reproduced() {
        let rig = Rig::new(&uniform_cone_lights(300, 65.0), RigOptions::default()).unwrap();
        let slice: Vec<f32> = rig
            .halfway_in_camera()
            .iter()
            .flat_map(|&h| linear_field(h))
            .collect();
        for (i, &h) in rig.halfway_in_camera().iter().enumerate() {
            let v = interpolate(&rig, &slice, h).unwrap();
            for c in 0..3 {
                assert!((v[c] - slice[i * 3 + c] as f64).abs() < 1e-5);
            }
        }
        // A field linear in the 3D halfway vector and homogeneous is reproduced exactly by
        // spherical barycentric weights up to the normalisation; check an affine field's error
        // stays small between samples.
        let q = DVec3::new(0.1, -0.2, 0.97).normalize();
        let v = interpolate(&rig, &slice, q).unwrap();
        let want = linear_field(q);
        for c in 0..3 {
            assert!((v[c] - want[c] as f64).abs() < 0.02, "{v:?} vs {want:?}");
        }
    }

    #[test]
    fn invalid_corners_and_outside_queries_have_no_data() {
        let rig = Rig::new(
            &uniform_cone_lights(200, 40.0),
            RigOptions {
                theta_d_max_deg: 40.0,
            },
        )
        .unwrap();
        let mut slice = vec![1.0f32; rig.n_used() * 3];
        // Far outside the 40-degree cone.
        assert!(interpolate(&rig, &slice, DVec3::new(0.9, 0.0, 0.3).normalize()).is_none());
        // Poison the sample at the top of the cone: queries next to it have no data.
        let top = rig
            .halfway_in_camera()
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.z.total_cmp(&b.1.z))
            .unwrap()
            .0;
        slice[top * 3..top * 3 + 3].fill(f32::NAN);
        assert!(interpolate(&rig, &slice, rig.halfway_in_camera()[top]).is_none());
    }
}
