//! Relighting from the measured samples themselves, with no reflectance model: each pixel's
//! BRDF slice (its radiance over `n.l`, a function of the halfway vector for the fixed view)
//! is read at the new light's halfway vector through the estimator's own reconstruction, the
//! spherical barycentric interpolation on the rig's triangulation (`frames/slice.rs`; over the
//! corners with data, near the pixel's horizon), and multiplied by the new `n.l`. Where that halfway vector is outside the rig's coverage (or a
//! corner sample is invalid), the slice is read at the vector's mirror images in the pixel's
//! frame, across the planes of the normal and the tangent, of the normal and the binormal, and
//! both: the symmetry the estimator found the frame by (docs/method.md, "Relighting from the
//! samples").
//!
//! Exact at the measured lights (the slice's own samples) whatever the material: what a
//! parametric model cannot represent (two lobes, sheen, an off-family lobe) is relit as
//! measured. The price: between lights the slice is linear, so a highlight sharper than the
//! rig's spacing is smeared over the triangle that holds it, and the whole stack stays in
//! memory (as many values as the stack).

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::appearance::fit::check_frame_maps;
use crate::error::{Error, Result};
use crate::eval::vec_at;
use crate::frames::rig::Rig;
use crate::geometry::{halfway_from_light, tangent_basis};
use crate::stack::Stack;

/// Renders a capture under new lights from its own samples ([`SampleRelighter::render`]).
#[derive(Debug, Clone)]
pub struct SampleRelighter {
    rig: Rig,
    width: usize,
    height: usize,
    /// Per pixel: the unit normal and tangent (camera frame), `None` without a frame.
    frames: Vec<Option<(DVec3, DVec3)>>,
    /// Per pixel, per light of the rig (rig order): the RGB slice, radiance over `n.l`; NaN
    /// where the sample is invalid or the light is behind the surface.
    slices: Vec<f32>,
}

impl SampleRelighter {
    /// The relighter of `stack` (its lights those of `rig`, in input order) in the frames of
    /// the `normals` and `tangents` maps (`H x W x 3`, camera frame; NaN tangent: isotropic,
    /// a tangent of its own is made up), inside `mask` when given.
    ///
    /// # Errors
    /// When the maps, the mask or the rig do not match the stack.
    pub fn new(
        stack: &Stack,
        rig: Rig,
        normals: &[f32],
        tangents: &[f32],
        mask: Option<&[bool]>,
    ) -> Result<Self> {
        let (w, h) = (stack.width, stack.height);
        Stack::check_inputs(w, h, stack.n_lights, rig.n_input(), mask)?;
        check_frame_maps(normals, tangents, w * h)?;
        let lights = rig.lights_in_camera();
        let used = rig.n_used();
        let frames: Vec<Option<(DVec3, DVec3)>> = (0..w * h)
            .map(|p| {
                if mask.is_some_and(|m| !m[p]) {
                    return None;
                }
                let n = vec_at(normals, p)?.try_normalize().filter(|n| n.z > 0.0)?;
                let t = vec_at(tangents, p)
                    .map(|t| t - t.dot(n) * n)
                    .and_then(|t| t.try_normalize())
                    .unwrap_or_else(|| tangent_basis(n).0);
                Some((n, t))
            })
            .collect();
        let mut slices = vec![f32::NAN; w * h * used * 3];
        slices
            .par_chunks_mut(used.max(1) * 3)
            .enumerate()
            .for_each(|(p, slice)| {
                let Some((n, _)) = frames[p] else {
                    return;
                };
                let px = stack.pixel(p);
                for (k, (&i, l)) in rig.input_index().iter().zip(lights).enumerate() {
                    let nl = n.dot(*l);
                    if nl > 0.0 {
                        for c in 0..3 {
                            slice[3 * k + c] = (px[3 * i + c] as f64 / nl) as f32;
                        }
                    }
                }
            });
        if frames.iter().all(Option::is_none) {
            return Err(Error::BadParameter(
                "no pixel has a frame to relight from its samples".into(),
            ));
        }
        Ok(Self {
            rig,
            width: w,
            height: h,
            frames,
            slices,
        })
    }

    /// The image under a distant light of unit intensity (the photographs' lights) from
    /// `light` (camera frame, surface toward light; normalised here): interleaved linear RGB
    /// radiance, `H x W x 3`; 0 where a pixel has no frame, faces away from the light, or its
    /// slice has no data at the light's halfway vector or its mirror images. Parallel over rows.
    pub fn render(&self, light: DVec3) -> Vec<f32> {
        let (w, used) = (self.width, self.rig.n_used());
        let mut out = vec![0.0f32; w * self.height * 3];
        let Some((l, h)) = light
            .try_normalize()
            .and_then(|l| Some((l, halfway_from_light(l)?)))
        else {
            return out;
        };
        out.par_chunks_mut(w.max(1) * 3)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, px) in row.chunks_exact_mut(3).enumerate() {
                    let p = y * w + x;
                    let Some((n, t)) = self.frames[p] else {
                        continue;
                    };
                    let nl = n.dot(l);
                    if nl <= 0.0 {
                        continue;
                    }
                    let slice = &self.slices[p * used * 3..(p + 1) * used * 3];
                    let b = n.cross(t);
                    let (ht, hb) = (h.dot(t) * t, h.dot(b) * b);
                    // The halfway vector, then its mirror images in the pixel's frame.
                    let value = [h, h - 2.0 * hb, h - 2.0 * ht, h - 2.0 * (ht + hb)]
                        .into_iter()
                        .find_map(|c| slice_at(&self.rig, slice, c));
                    if let Some(v) = value {
                        for (o, v) in px.iter_mut().zip(v) {
                            *o = (v.max(0.0) * nl) as f32;
                        }
                    }
                }
            });
        out
    }

    // What a renderer elsewhere (the viewer's shader) reads to relight as
    // [`SampleRelighter::render`] does: the slices, the frames and the triangulation.

    /// The lights of the slices (the rig's, in its order).
    pub fn lights(&self) -> usize {
        self.rig.n_used()
    }

    /// Per pixel (rows top to bottom): the unit normal and tangent (camera frame), `None`
    /// without a frame.
    pub fn frames(&self) -> &[Option<(DVec3, DVec3)>] {
        &self.frames
    }

    /// Per pixel, per light ([`SampleRelighter::lights`] of them): the RGB slice, radiance
    /// over `n.l`; NaN where the sample is invalid or the light is behind the surface.
    pub fn slices(&self) -> &[f32] {
        &self.slices
    }

    /// The rig's triangulation of the halfway vectors: per triangle, its corners (indices of
    /// the slices' lights) and the inverse of the matrix whose columns are their halfway
    /// vectors (its rows dotted with a halfway vector give the unnormalised spherical
    /// barycentric weights; the triangle holds the vector where none is negative).
    pub fn triangles(&self) -> impl Iterator<Item = ([u32; 3], DMat3)> + '_ {
        self.rig.triangles()
    }
}

/// The slice's RGB value at a unit halfway vector: the estimator's barycentric interpolation
/// (`frames/slice.rs`) over the triangle's corners that have data, their weights renormalised
/// (near the pixel's horizon some corners' lights are behind the surface); `None` outside the
/// rig or where no corner has data.
fn slice_at(rig: &Rig, slice: &[f32], halfway: DVec3) -> Option<[f64; 3]> {
    let loc = rig.locate(halfway)?;
    let (mut sum, mut weight) = ([0.0f64; 3], 0.0);
    for (&v, &w) in loc.vertices.iter().zip(&loc.weights) {
        let o = v as usize * 3;
        let rgb = &slice[o..o + 3];
        if w > 0.0 && rgb.iter().all(|x| x.is_finite()) {
            for (s, &x) in sum.iter_mut().zip(rgb) {
                *s += w * x as f64;
            }
            weight += w;
        }
    }
    (weight > 0.0).then(|| sum.map(|s| s / weight))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::Ggx;
    use crate::frames::rig::{uniform_cone_lights, RigOptions};
    use crate::render::{Scene, TangentField};

    /// A brushed GGX sphere under 800 lights: relit at a measured light, the samples come
    /// back as they were; at lights between them, the relit images match the true renders;
    /// a light beyond the rig's cone is relit through the slice's mirror images.
    #[test]
    fn relit_from_the_samples_matches_the_renders() {
        let scene = Scene::sphere(24, TangentField::Circular);
        let brdf = Ggx::new([0.3, 0.2, 0.1], [0.5; 3], 0.35, 0.12);
        let lights = uniform_cone_lights(800, 65.0);
        let stack = scene.render_stack(&brdf, &lights);
        let rig = Rig::new(&lights, RigOptions::default()).unwrap();
        let (normals, tangents) = (scene.gt_normals(), scene.gt_tangents());
        let relighter =
            SampleRelighter::new(&stack, rig, &normals, &tangents, Some(&scene.mask)).unwrap();
        let judged: Vec<bool> = (0..scene.n_pixels())
            .map(|p| scene.mask[p] && scene.normals_in_camera[p].z > 0.5)
            .collect();
        // At a measured light: the samples themselves (to float rounding).
        let i = 123;
        let relit = relighter.render(lights[i]);
        let truth = stack.image(i);
        for p in (0..scene.n_pixels()).filter(|&p| judged[p]) {
            for c in 0..3 {
                let (a, b) = (relit[3 * p + c], truth[3 * p + c]);
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs().max(1e-3),
                    "pixel {p}: {a} vs {b}"
                );
            }
        }
        // Between the lights: 40 directions of a second, rotated cone.
        let between: Vec<DVec3> = uniform_cone_lights(41, 60.0)
            .into_iter()
            .skip(1)
            .map(|l| DVec3::new(l.y, -l.x, l.z))
            .collect();
        let psnrs: Vec<f64> = between
            .iter()
            .map(|&l| {
                let truth = scene.render(&brdf, l);
                crate::Relighter::image_psnr(&relighter.render(l), &truth, Some(&judged))
            })
            .collect();
        let mean = psnrs.iter().sum::<f64>() / psnrs.len() as f64;
        assert!(mean > 35.0, "mean {mean} dB: {psnrs:?}");
        // A rig of half the dome (lights to the right of the view): a light to the left has
        // its halfway vector outside it, and the pixels near the centre are relit from its
        // mirror images in their frames.
        let right: Vec<DVec3> = lights.iter().copied().filter(|l| l.x > 0.05).collect();
        let mut half = Stack::zeros(24, 24, right.len());
        for (j, i) in (0..lights.len())
            .filter(|&i| lights[i].x > 0.05)
            .enumerate()
        {
            half.set_image(j, &stack.image(i));
        }
        let rig = Rig::new(&right, RigOptions::default()).unwrap();
        let relighter =
            SampleRelighter::new(&half, rig, &normals, &tangents, Some(&scene.mask)).unwrap();
        let left = DVec3::new(-0.5, 0.1, 0.86).normalize();
        assert!(!relighter.rig.covered(halfway_from_light(left).unwrap()));
        let centre: Vec<bool> = (0..scene.n_pixels())
            .map(|p| scene.mask[p] && scene.normals_in_camera[p].z > 0.94)
            .collect();
        let truth = scene.render(&brdf, left);
        let relit = relighter.render(left);
        // Where one of the mirror images falls inside the half rig (not where the halfway
        // vector's four images are all outside it, near the tangent field's diagonals).
        let mirrored: Vec<bool> = (0..scene.n_pixels())
            .map(|p| centre[p] && relit[3 * p] > 0.0)
            .collect();
        let (n, m) = (
            centre.iter().filter(|&&c| c).count(),
            mirrored.iter().filter(|&&c| c).count(),
        );
        assert!(
            2 * m > n,
            "{m} of {n} central pixels relit from mirror images"
        );
        let psnr = crate::Relighter::image_psnr(&relit, &truth, Some(&mirrored));
        assert!(psnr > 30.0, "from the mirror images: {psnr} dB");
    }

    #[test]
    fn maps_that_do_not_match_are_refused() {
        let scene = Scene::sphere(8, TangentField::Circular);
        let lights = uniform_cone_lights(40, 65.0);
        let stack = Stack::zeros(8, 8, 40);
        let rig = Rig::new(&lights, RigOptions::default()).unwrap();
        let normals = scene.gt_normals();
        assert!(SampleRelighter::new(&stack, rig.clone(), &normals[3..], &normals, None).is_err());
        let nan = vec![f32::NAN; normals.len()];
        assert!(SampleRelighter::new(&stack, rig, &nan, &nan, None).is_err());
    }
}
