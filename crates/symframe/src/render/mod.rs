//! The synthetic renderer: scenes with known normals and tangents, rendered with any
//! [`Brdf`] under distant point lights and an orthographic camera. Ground truth for every test
//! and for `symframe synth`.
//!
//! - Scenes ([`Scene`]): [`Scene::sphere`], [`Scene::cylinder`], [`Scene::plane`] /
//!   [`Scene::tilted_plane`] (see [`Scene::plane_frame`]), and height fields
//!   ([`Scene::height_field`], [`Scene::bumps`], [`Scene::from_bumps`]) which cast shadows
//!   (`shadow`, [`Scene::cast_shadows`]).
//! - Tangent fields ([`TangentField`]): circular, axial, radial, swirl, or any function.
//! - Light rigs (`rigs`): the uniform cone, a DiLiGenT-like 96-light grid.
//! - A mirror ball for light calibration ([`MirrorBall`]): lamps of finite size, anti-aliased;
//!   mirror balls before a pinhole camera under a near lamp ([`NearMirrorBalls`]).
//! - Degradations (`noise`): exposure, Gaussian and shot noise, clipping, quantisation.

use glam::DVec3;
use rayon::prelude::*;

use crate::brdf::{Brdf, TangentAxis};
use crate::eval::{evaluate, Evaluation};
use crate::stack::Stack;

mod mirror_ball;
mod near_mirror;
pub(crate) mod noise;
pub(crate) mod perspective;
pub(crate) mod rigs;
pub(crate) mod shadow;
mod shapes;
mod tangent;

pub use mirror_ball::MirrorBall;
pub use near_mirror::NearMirrorBalls;
pub use noise::{Degradation, Noise, Rng};
pub use perspective::{dome_lights, Ball, NearScene};
pub use rigs::diligent_lights;
pub use shapes::{Bump, BumpParams};
pub use tangent::TangentField;

/// A surface seen by the camera: per pixel, a normal and a tangent (camera frame), inside a
/// mask, and for height fields the surface height (which casts shadows).
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixels covered by the surface.
    pub mask: Vec<bool>,
    /// Unit normals (meaningful inside the mask).
    pub normals_in_camera: Vec<DVec3>,
    /// Unit tangents, perpendicular to the normals (meaningful inside the mask).
    pub tangents_in_camera: Vec<DVec3>,
    /// Surface heights at pixel centres in pixel units, row-major, for height fields. When
    /// present, [`Scene::render`] tests cast shadows (`shadow`); set to `None` to render
    /// without them.
    pub heights: Option<Vec<f64>>,
}

impl Scene {
    /// Estimated `normals` and `tangents` (`H x W x 3`, NaN where none) against this scene's
    /// truth, over the masked pixels whose true normal is within 60 degrees of the view: the
    /// figures the demo, the tests and the experiments report.
    pub fn evaluate(&self, normals: &[f32], tangents: &[f32]) -> Evaluation {
        evaluate(
            normals,
            tangents,
            &self.gt_normals(),
            Some(&self.gt_tangents()),
            Some(&self.mask),
            60.0,
            None,
        )
    }

    /// Number of pixels.
    pub fn n_pixels(&self) -> usize {
        self.width * self.height
    }

    /// Ground-truth normals, `H x W x 3`, NaN outside the mask.
    pub fn gt_normals(&self) -> Vec<f32> {
        self.masked_vectors(&self.normals_in_camera)
    }

    /// Ground-truth tangents (the wide-highlight axis: docs/method.md, "The widest-highlight
    /// tangent rule"), `H x W x 3`, NaN outside.
    pub fn gt_tangents(&self) -> Vec<f32> {
        self.masked_vectors(&self.tangents_in_camera)
    }

    fn masked_vectors(&self, v: &[DVec3]) -> Vec<f32> {
        v.iter()
            .zip(&self.mask)
            .flat_map(|(d, &m)| {
                if m {
                    d.as_vec3().to_array()
                } else {
                    [f32::NAN; 3]
                }
            })
            .collect()
    }

    /// The BRDF's local frame at pixel `p` as (x axis, y axis, normal), oriented so that the
    /// model's wide-highlight axis lies along the scene's tangent.
    fn local_axes(&self, p: usize, axis: TangentAxis) -> (DVec3, DVec3, DVec3) {
        let n = self.normals_in_camera[p];
        let t = self.tangents_in_camera[p];
        match axis {
            TangentAxis::Y => (t.cross(n), t, n),
            TangentAxis::X | TangentAxis::None => (t, n.cross(t), n),
        }
    }

    /// Renders the image under one distant light of unit intensity: interleaved linear RGB,
    /// `radiance = f(l, v) (n.l)`, zero outside the mask, in attached shadow (`n.l <= 0`) and,
    /// for scenes with [`Scene::heights`], in cast shadow (`shadow`).
    pub fn render(&self, brdf: &dyn Brdf, light_in_camera: DVec3) -> Vec<f32> {
        let l = light_in_camera.normalize();
        let axis = brdf.tangent_axis();
        let tracer = self
            .heights
            .as_deref()
            .map(|h| shadow::ShadowTracer::new(h, self.width, self.height));
        let mut out = vec![0.0f32; self.n_pixels() * 3];
        for (p, px) in out.chunks_exact_mut(3).enumerate() {
            if !self.mask[p] {
                continue;
            }
            let (x, y, n) = self.local_axes(p, axis);
            let n_dot_l = n.dot(l);
            if n_dot_l <= 0.0 || tracer.as_ref().is_some_and(|t| t.shadowed(p, l)) {
                continue;
            }
            let to_local = |d: DVec3| DVec3::new(d.dot(x), d.dot(y), d.dot(n));
            let f = brdf.eval(to_local(l), to_local(DVec3::Z));
            for c in 0..3 {
                px[c] = (f[c] * n_dot_l) as f32;
            }
        }
        out
    }

    /// Renders image number `index` of a capture: [`Scene::render`] under `light`, then
    /// `degradation` applied with that index (so a stack is deterministic in the seed whatever
    /// order its images are rendered in).
    pub fn render_degraded(
        &self,
        brdf: &dyn Brdf,
        light_in_camera: DVec3,
        index: usize,
        degradation: &Degradation,
    ) -> Vec<f32> {
        let mut img = self.render(brdf, light_in_camera);
        degradation.apply(&mut img, index);
        img
    }

    /// Renders the whole stack (one image per light), in parallel over lights.
    pub fn render_stack(&self, brdf: &dyn Brdf, lights_in_camera: &[DVec3]) -> Stack {
        self.render_stack_degraded(brdf, lights_in_camera, &Degradation::default())
    }

    /// Renders the whole stack with a degradation (image `i` uses index `i`; see
    /// [`Scene::render_degraded`]), in parallel over lights. To drop clipped samples as a
    /// dataset reader would, apply `noise::mark_saturated` to the images instead.
    pub fn render_stack_degraded(
        &self,
        brdf: &dyn Brdf,
        lights_in_camera: &[DVec3],
        degradation: &Degradation,
    ) -> Stack {
        let images: Vec<Vec<f32>> = lights_in_camera
            .par_iter()
            .enumerate()
            .map(|(i, &l)| self.render_degraded(brdf, l, i, degradation))
            .collect();
        let mut stack = Stack::zeros(self.width, self.height, lights_in_camera.len());
        for (i, img) in images.iter().enumerate() {
            stack.set_image(i, img);
        }
        stack
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Constant;
    impl Brdf for Constant {
        fn eval(&self, l: DVec3, v: DVec3) -> [f64; 3] {
            if l.z <= 0.0 || v.z <= 0.0 {
                [0.0; 3]
            } else {
                [1.0, 0.5, 0.25]
            }
        }
        fn tangent_axis(&self) -> TangentAxis {
            TangentAxis::None
        }
        fn name(&self) -> String {
            "constant".into()
        }
    }

    #[test]
    fn sphere_normals_are_unit_and_face_the_camera() {
        let s = Scene::sphere(32, TangentField::Circular);
        let inside = s.mask.iter().filter(|&&m| m).count();
        let area = std::f64::consts::PI * 16.0 * 16.0;
        assert!((inside as f64 - area).abs() < 0.05 * area);
        for p in 0..s.n_pixels() {
            if s.mask[p] {
                let n = s.normals_in_camera[p];
                let t = s.tangents_in_camera[p];
                assert!((n.length() - 1.0).abs() < 1e-12 && n.z > 0.0);
                assert!((t.length() - 1.0).abs() < 1e-9 && t.dot(n).abs() < 1e-9);
            }
        }
        // Row 0 is the top: normals there point up (+y).
        let top = (0..32).find(|&x| s.mask[x + 32]).unwrap() + 32;
        assert!(s.normals_in_camera[top].y > 0.5);
    }

    #[test]
    fn lambertian_rendering_is_albedo_times_cosine() {
        let s = Scene::plane(2, 2, DVec3::new(0.0, 0.6, 0.8), DVec3::X);
        let l = DVec3::new(0.0, 0.0, 1.0);
        let img = s.render(&Constant, l);
        assert!((img[0] - 0.8).abs() < 1e-6 && (img[1] - 0.4).abs() < 1e-6);
        // Behind the surface: black.
        let img = s.render(&Constant, DVec3::new(0.0, -0.8, 0.6));
        assert!(img.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn degraded_stacks_are_deterministic_per_image() {
        let s = Scene::sphere(12, TangentField::Circular);
        let lights = rigs::diligent_lights();
        let d = Degradation {
            noise: Noise::Gaussian { sigma: 0.01 },
            seed: 9,
            ..Degradation::default()
        };
        let a = s.render_stack_degraded(&Constant, &lights, &d);
        let b = s.render_stack_degraded(&Constant, &lights, &d);
        assert_eq!(a, b);
        assert_eq!(a.image(5), s.render_degraded(&Constant, lights[5], 5, &d));
        assert_ne!(a, s.render_stack(&Constant, &lights));
        assert_eq!(
            s.render_stack_degraded(&Constant, &lights, &Degradation::default()),
            s.render_stack(&Constant, &lights)
        );
    }
}
