//! The per-pixel BRDF slice: measured radiance as a function of the halfway vector,
//! reconstructed between the samples by spherical barycentric interpolation on the rig's
//! triangulation.

use glam::{DVec3, Vec4};

use crate::rig::Rig;
use crate::stack::Stack;

/// Gathers one pixel's samples into rig order (`rig.n_used() * 3` values) in the caller's buffer.
///
/// The stack holds every input light; the rig uses those inside the cone.
#[inline]
pub fn gather_slice(rig: &Rig, stack: &Stack, pixel: usize, out: &mut [f32]) {
    gather_pixel(rig, stack.pixel(pixel), out);
}

/// Gathers one pixel's samples, given as every input light's RGB in input order
/// (`rig.n_input * 3` values, e.g. a pixel of a [`Stack`] or of an on-disk tile), into rig order.
#[inline]
pub fn gather_pixel(rig: &Rig, samples: &[f32], out: &mut [f32]) {
    for (dst, &i) in out.chunks_exact_mut(3).zip(&rig.input_index) {
        dst.copy_from_slice(&samples[i * 3..i * 3 + 3]);
    }
}

/// The slice's RGB value at a unit halfway vector; `None` where there is no data (outside the
/// sampled region, or a corner sample is invalid).
#[inline]
pub fn interpolate(rig: &Rig, slice: &[f32], halfway: DVec3) -> Option<[f64; 3]> {
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
pub trait SliceLookup {
    /// RGB radiance at a unit halfway vector, `None` where there is no data.
    fn value(&self, halfway: DVec3) -> Option<[f64; 3]>;
}

/// The reference reconstruction: triangle location and spherical barycentric weights at every
/// query ([`interpolate`]).
#[derive(Debug, Clone, Copy)]
pub struct ExactSlice<'a> {
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

/// A pixel's slice resampled once onto the rig's [`ResampleGrid`]
/// (crate::rig::ResampleGrid) and read by bilinear interpolation: the fast path. Reused across
/// pixels (one per thread) so nothing allocates per pixel.
#[derive(Debug, Clone)]
pub struct ResampledSlice {
    size: usize,
    min: f64,
    inv_step: f64,
    /// RGB per node (the fourth lane 0), all NaN where there is no data: one 16-byte load per
    /// node, and the bilinear blend runs on the three channels at once.
    values: Vec<Vec4>,
    /// The pixel's samples as RGB_ lanes (rig order), for the resampling.
    lanes: Vec<Vec4>,
}

impl ResampledSlice {
    /// An empty buffer sized for `rig`'s grid.
    pub fn new(rig: &Rig) -> Self {
        let g = &rig.resample;
        Self {
            size: g.size,
            min: g.min,
            inv_step: g.inv_step,
            values: vec![Vec4::NAN; g.size * g.size],
            lanes: Vec::with_capacity(rig.n_used()),
        }
    }

    /// Resamples one pixel's slice (rig order) onto the grid.
    pub fn fill(&mut self, rig: &Rig, samples: &[f32]) {
        let g = &rig.resample;
        debug_assert_eq!(g.size, self.size);
        // The samples as 16-byte RGB_ lanes first: one aligned load per corner below.
        self.lanes.clear();
        self.lanes.extend(
            samples
                .chunks_exact(3)
                .map(|s| Vec4::new(s[0], s[1], s[2], 0.0)),
        );
        let lanes = &self.lanes;
        for ((out, v), w) in self.values.iter_mut().zip(&g.vertices).zip(&g.weights) {
            *out = if v[0] == u32::MAX {
                Vec4::NAN
            } else {
                lanes[v[0] as usize] * w[0]
                    + lanes[v[1] as usize] * w[1]
                    + lanes[v[2] as usize] * w[2]
            };
        }
    }

    /// The grid as the fast objective's kernel reads it.
    #[inline]
    pub fn view(&self) -> GridView<'_> {
        GridView {
            size: self.size,
            scale: self.inv_step as f32,
            offset: (self.min * self.inv_step) as f32,
            values: &self.values,
        }
    }
}

/// A resampled slice in single precision: `size x size` RGB nodes at stereographic coordinates
/// `(i, j) / scale - offset / scale`.
#[derive(Debug, Clone, Copy)]
pub struct GridView<'a> {
    pub(crate) size: usize,
    pub(crate) scale: f32,
    pub(crate) offset: f32,
    pub(crate) values: &'a [Vec4],
}

impl GridView<'_> {
    /// The bilinear value at the unit halfway vector `(x, y, z)`; NaN lanes where there is no
    /// data, `None` outside the grid.
    #[inline(always)]
    pub fn value(&self, x: f32, y: f32, z: f32) -> Option<Vec4> {
        let k = self.scale / (1.0 + z);
        let gx = x * k - self.offset;
        let gy = y * k - self.offset;
        if !(gx >= 0.0 && gy >= 0.0) {
            return None;
        }
        let (ix, iy) = (gx as usize, gy as usize);
        if ix + 1 >= self.size || iy + 1 >= self.size {
            return None;
        }
        let (fx, fy) = (gx - ix as f32, gy - iy as f32);
        let i = iy * self.size + ix;
        let row = &self.values[i..i + self.size + 2];
        let top = row[0] + (row[1] - row[0]) * fx;
        let bottom = row[self.size] + (row[self.size + 1] - row[self.size]) * fx;
        Some(top + (bottom - top) * fy)
    }
}

impl SliceLookup for GridView<'_> {
    #[inline]
    fn value(&self, halfway: DVec3) -> Option<[f64; 3]> {
        let v = GridView::value(self, halfway.x as f32, halfway.y as f32, halfway.z as f32)?;
        // A node without data (NaN) poisons the result: no data here.
        v.is_finite().then(|| [v.x as f64, v.y as f64, v.z as f64])
    }
}

impl SliceLookup for ResampledSlice {
    #[inline]
    fn value(&self, halfway: DVec3) -> Option<[f64; 3]> {
        SliceLookup::value(&self.view(), halfway)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::{uniform_cone_lights, RigOptions};

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
            .halfway_in_camera
            .iter()
            .flat_map(|&h| linear_field(h))
            .collect();
        for (i, &h) in rig.halfway_in_camera.iter().enumerate() {
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
                ..RigOptions::default()
            },
        )
        .unwrap();
        let mut slice = vec![1.0f32; rig.n_used() * 3];
        // Far outside the 40-degree cone.
        assert!(interpolate(&rig, &slice, DVec3::new(0.9, 0.0, 0.3).normalize()).is_none());
        // Poison the sample at the top of the cone: queries next to it have no data.
        let top = rig
            .halfway_in_camera
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.z.total_cmp(&b.1.z))
            .unwrap()
            .0;
        slice[top * 3..top * 3 + 3].fill(f32::NAN);
        assert!(interpolate(&rig, &slice, rig.halfway_in_camera[top]).is_none());
    }

    #[test]
    fn resampled_slice_agrees_with_the_exact_one() {
        let rig = Rig::new(&uniform_cone_lights(500, 65.0), RigOptions::default()).unwrap();
        let lobe = |h: DVec3| {
            let e = (-(h.x * h.x / 0.04 + h.y * h.y / 0.2) / (h.z * h.z)).exp();
            [(0.2 + e) as f32, (0.3 + 0.5 * e) as f32, 0.1]
        };
        let slice: Vec<f32> = rig
            .halfway_in_camera
            .iter()
            .flat_map(|&h| lobe(h))
            .collect();
        let exact = ExactSlice {
            rig: &rig,
            samples: &slice,
        };
        let mut fast = ResampledSlice::new(&rig);
        fast.fill(&rig, &slice);
        let (mut both, mut worst) = (0, 0.0f64);
        for i in 0..40 {
            for j in 0..40 {
                let h = crate::rig::from_stereographic(glam::DVec2::new(
                    -0.6 + 0.03 * i as f64,
                    -0.6 + 0.03 * j as f64,
                ));
                if let (Some(a), Some(b)) = (exact.value(h), fast.value(h)) {
                    both += 1;
                    for c in 0..3 {
                        worst = worst.max((a[c] - b[c]).abs());
                    }
                }
            }
        }
        assert!(both > 800, "{both}");
        // Bilinear on 0.5-degree nodes of a piecewise-linear field: close to the exact one.
        assert!(worst < 0.02, "worst difference {worst}");
        // Far outside the cone: no data on either path.
        let out = DVec3::new(0.95, 0.0, 0.2).normalize();
        assert!(exact.value(out).is_none() && fast.value(out).is_none());
    }

    #[test]
    fn gather_follows_the_rig_order() {
        let mut lights = uniform_cone_lights(10, 65.0);
        lights.insert(3, DVec3::new(0.0, 0.0, -1.0)); // dropped by the rig
        let rig = Rig::new(&lights, RigOptions::default()).unwrap();
        let mut stack = Stack::zeros(2, 1, lights.len());
        for i in 0..lights.len() {
            stack.set_image(i, &[i as f32; 6]);
        }
        let mut out = vec![0.0; rig.n_used() * 3];
        gather_slice(&rig, &stack, 1, &mut out);
        let want: Vec<f32> = rig
            .input_index
            .iter()
            .flat_map(|&i| [i as f32; 3])
            .collect();
        assert_eq!(out, want);
        assert!(!out.contains(&3.0));
    }
}
