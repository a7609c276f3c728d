//! The synthetic renderer: scenes with known normals and tangents, rendered with any
//! [`Brdf`] under distant point lights and an orthographic camera. Ground truth for every test.

use glam::DVec3;
use rayon::prelude::*;

use crate::brdf::{Brdf, TangentAxis};
use crate::stack::Stack;

/// How the tangent direction varies over a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TangentField {
    /// Circles around the view axis: `t = normalize(z x n)` (a hue wheel in the tangent map).
    Circular,
    /// A fixed camera-frame direction projected onto each tangent plane.
    Axial(DVec3),
}

impl TangentField {
    /// The unit tangent at normal `n`.
    pub fn tangent_at(&self, n: DVec3) -> DVec3 {
        let fallback = |d: DVec3| {
            let p = d - d.dot(n) * n;
            p.try_normalize()
                .unwrap_or_else(|| (DVec3::X - n.x * n).normalize())
        };
        match *self {
            TangentField::Circular => DVec3::Z
                .cross(n)
                .try_normalize()
                .unwrap_or_else(|| fallback(DVec3::X)),
            TangentField::Axial(d) => fallback(d),
        }
    }
}

/// A surface seen by the camera: per pixel, a normal and a tangent (camera frame), inside a mask.
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
}

impl Scene {
    /// A sphere filling a `size x size` image (pixel centres inside the disc), seen head-on.
    pub fn sphere(size: usize, field: TangentField) -> Self {
        let r = size as f64 / 2.0;
        let n = size * size;
        let mut scene = Self {
            width: size,
            height: size,
            mask: vec![false; n],
            normals_in_camera: vec![DVec3::Z; n],
            tangents_in_camera: vec![DVec3::X; n],
        };
        for y in 0..size {
            for x in 0..size {
                let nx = (x as f64 + 0.5 - r) / r;
                let ny = -(y as f64 + 0.5 - r) / r; // image up is +y
                let rr = nx * nx + ny * ny;
                if rr < 1.0 {
                    let p = y * size + x;
                    let normal = DVec3::new(nx, ny, (1.0 - rr).sqrt());
                    scene.mask[p] = true;
                    scene.normals_in_camera[p] = normal;
                    scene.tangents_in_camera[p] = field.tangent_at(normal);
                }
            }
        }
        scene
    }

    /// A flat `width x height` patch with one normal and tangent everywhere.
    pub fn plane(width: usize, height: usize, normal: DVec3, tangent: DVec3) -> Self {
        let n = normal.normalize();
        let t = TangentField::Axial(tangent).tangent_at(n);
        Self {
            width,
            height,
            mask: vec![true; width * height],
            normals_in_camera: vec![n; width * height],
            tangents_in_camera: vec![t; width * height],
        }
    }

    /// Number of pixels.
    pub fn n_pixels(&self) -> usize {
        self.width * self.height
    }

    /// Ground-truth normals, `H x W x 3`, NaN outside the mask.
    pub fn gt_normals(&self) -> Vec<f32> {
        self.masked_vectors(&self.normals_in_camera)
    }

    /// Ground-truth tangents (the wide-highlight axis, method.md), `H x W x 3`, NaN outside.
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
    /// `radiance = f(l, v) (n.l)`, zero outside the mask and in attached shadow.
    pub fn render(&self, brdf: &dyn Brdf, light_in_camera: DVec3) -> Vec<f32> {
        let l = light_in_camera.normalize();
        let axis = brdf.tangent_axis();
        let mut out = vec![0.0f32; self.n_pixels() * 3];
        for (p, px) in out.chunks_exact_mut(3).enumerate() {
            if !self.mask[p] {
                continue;
            }
            let (x, y, n) = self.local_axes(p, axis);
            let n_dot_l = n.dot(l);
            if n_dot_l <= 0.0 {
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

    /// Renders the whole stack (one image per light), in parallel over lights.
    pub fn render_stack(&self, brdf: &dyn Brdf, lights_in_camera: &[DVec3]) -> Stack {
        let images: Vec<Vec<f32>> = lights_in_camera
            .par_iter()
            .map(|&l| self.render(brdf, l))
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
}
