//! Near-light renders: spheres seen by a pinhole camera, lit by point lights (a dome of LEDs),
//! with their true normals, tangents and depths. The ground truth of the near-light model
//! ([`crate::near`]) and of `symframe synth --near`.
//!
//! Each pixel is one ray through its centre (no anti-aliasing): the nearest sphere it meets
//! gives the pixel's surface point, normal and tangent. Under a light at `L` the pixel's
//! radiance is `f(l, v) (n.l) E(p)`, with `l` the unit direction from the point `p` to `L`, `v`
//! from `p` to the camera, and `E(p)` the light's irradiance there
//! ([`PointLight::at`] times its intensity); zero where `n.l <= 0` and where another sphere
//! stands between `p` and the light (cast shadows).

use glam::DVec3;

use crate::brdf::{Brdf, TangentAxis};
use crate::geometry::tangent_basis;
use crate::near::{Pinhole, PointLight};

/// A sphere of a near-light scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ball {
    /// Centre, camera frame (z < 0: in front of the camera).
    pub centre: DVec3,
    /// Radius, in the centre's units.
    pub radius: f64,
    /// Which of the render's materials it is made of.
    pub material: usize,
}

impl Ball {
    /// The nearest distance along the unit ray `d` from `o` at which it meets the sphere, if
    /// beyond `near`.
    fn hit(&self, o: DVec3, d: DVec3, near: f64) -> Option<f64> {
        let oc = o - self.centre;
        let b = oc.dot(d);
        let c = oc.length_squared() - self.radius * self.radius;
        let disc = b * b - c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        [-b - s, -b + s].into_iter().find(|&t| t > near)
    }

    /// The brushing tangent at its unit normal `n`: circles about the axis from its centre
    /// toward the camera (a part turned on a lathe that faces the camera).
    fn tangent(&self, n: DVec3) -> DVec3 {
        let axis = (-self.centre).normalize();
        axis.cross(n)
            .try_normalize()
            .unwrap_or_else(|| tangent_basis(n).0)
    }
}

/// Spheres seen by a pinhole camera: per pixel, the sphere it sees (if any), the surface point,
/// normal and tangent.
#[derive(Debug, Clone, PartialEq)]
pub struct NearScene {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The camera.
    pub camera: Pinhole,
    /// The spheres.
    pub balls: Vec<Ball>,
    /// Per pixel, the index of the ball it sees, `None` for the background.
    pub seen: Vec<Option<u16>>,
    /// Per pixel, the surface point (camera frame; zero on the background).
    pub points: Vec<DVec3>,
    /// Per pixel, the unit normal (camera frame).
    pub normals: Vec<DVec3>,
    /// Per pixel, the unit tangent (camera frame): the brushing direction.
    pub tangents: Vec<DVec3>,
}

impl NearScene {
    /// Casts one ray per pixel centre at `balls` (at most 65,535).
    pub fn spheres(width: usize, height: usize, camera: Pinhole, balls: &[Ball]) -> Self {
        let n = width * height;
        let mut scene = Self {
            width,
            height,
            camera,
            balls: balls.to_vec(),
            seen: vec![None; n],
            points: vec![DVec3::ZERO; n],
            normals: vec![DVec3::Z; n],
            tangents: vec![DVec3::X; n],
        };
        for p in 0..n {
            let d = camera
                .ray((p % width) as f64, (p / width) as f64)
                .normalize();
            let nearest = balls
                .iter()
                .enumerate()
                .take(u16::MAX as usize)
                .filter_map(|(i, b)| b.hit(DVec3::ZERO, d, 0.0).map(|t| (t, i)))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((t, i)) = nearest {
                let ball = &balls[i];
                let point = d * t;
                let normal = ((point - ball.centre) / ball.radius).normalize();
                scene.seen[p] = Some(i as u16);
                scene.points[p] = point;
                scene.normals[p] = normal;
                scene.tangents[p] = ball.tangent(normal);
            }
        }
        scene
    }

    /// Pixels that see a sphere.
    pub fn mask(&self) -> Vec<bool> {
        self.seen.iter().map(Option::is_some).collect()
    }

    /// Depth along the optical axis (`-z` of the surface point), NaN on the background.
    pub fn depth(&self) -> Vec<f32> {
        self.points
            .iter()
            .zip(&self.seen)
            .map(|(p, s)| if s.is_some() { -p.z as f32 } else { f32::NAN })
            .collect()
    }

    /// Ground-truth normals, `H x W x 3`, NaN on the background.
    pub fn gt_normals(&self) -> Vec<f32> {
        self.masked(&self.normals)
    }

    /// Ground-truth tangents (the brushing direction), `H x W x 3`, NaN on the background.
    pub fn gt_tangents(&self) -> Vec<f32> {
        self.masked(&self.tangents)
    }

    fn masked(&self, v: &[DVec3]) -> Vec<f32> {
        v.iter()
            .zip(&self.seen)
            .flat_map(|(d, s)| match s {
                Some(_) => d.as_vec3().to_array(),
                None => [f32::NAN; 3],
            })
            .collect()
    }

    /// The image under one light: interleaved linear RGB, `materials[ball.material]` on each
    /// ball (the module's formula). A ball whose material index is out of range renders black.
    pub fn render(&self, materials: &[&dyn Brdf], light: &PointLight) -> Vec<f32> {
        let mut out = vec![0.0f32; self.width * self.height * 3];
        for (p, px) in out.chunks_exact_mut(3).enumerate() {
            let Some(i) = self.seen[p] else {
                continue;
            };
            let Some(brdf) = materials.get(self.balls[i as usize].material) else {
                continue;
            };
            let point = self.points[p];
            let Some((l, falloff)) = light.at(point) else {
                continue;
            };
            let (n, t) = (self.normals[p], self.tangents[p]);
            let n_dot_l = n.dot(l);
            if n_dot_l <= 0.0 || falloff <= 0.0 {
                continue;
            }
            let dist = (light.position - point).length();
            let blocked =
                self.balls.iter().enumerate().any(|(j, b)| {
                    j != i as usize && b.hit(point, l, 1e-9).is_some_and(|s| s < dist)
                });
            if blocked {
                continue;
            }
            let (x, y) = match brdf.tangent_axis() {
                TangentAxis::Y => (t.cross(n), t),
                TangentAxis::X | TangentAxis::None => (t, n.cross(t)),
            };
            let to_local = |d: DVec3| DVec3::new(d.dot(x), d.dot(y), d.dot(n));
            let v = -point.normalize();
            let f = brdf.eval(to_local(l), to_local(v));
            for c in 0..3 {
                px[c] = (f[c] * n_dot_l * falloff * light.intensity[c]) as f32;
            }
        }
        out
    }
}

/// `n` isotropic lights of intensity `intensity` spread evenly (a Fibonacci spiral) over the cap
/// of the sphere of `radius` about `centre` that faces the camera (`+z`), from `min_elevation_deg`
/// above the sphere's equator (the plane `z = centre.z`) to its top.
pub fn dome_lights(
    n: usize,
    centre: DVec3,
    radius: f64,
    min_elevation_deg: f64,
    intensity: f64,
) -> Vec<PointLight> {
    let z0 = min_elevation_deg.to_radians().sin();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            // Even in area: z uniform over [z0, 1].
            let z = 1.0 - (1.0 - z0) * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let a = golden * i as f64;
            PointLight {
                intensity: [intensity; 3],
                ..PointLight::isotropic(centre + radius * DVec3::new(r * a.cos(), r * a.sin(), z))
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::Lambertian;

    fn two_balls() -> NearScene {
        let cam = Pinhole::centred(96, 48, 22.6);
        let balls = [
            Ball {
                centre: DVec3::new(-1.1, 0.0, -12.0),
                radius: 1.0,
                material: 0,
            },
            Ball {
                centre: DVec3::new(1.1, 0.0, -12.0),
                radius: 1.0,
                material: 1,
            },
        ];
        NearScene::spheres(96, 48, cam, &balls)
    }

    #[test]
    fn pixels_see_the_spheres_where_they_project() {
        let s = two_balls();
        for p in 0..s.width * s.height {
            if let Some(i) = s.seen[p] {
                let b = s.balls[i as usize];
                let q = s.points[p];
                assert!(((q - b.centre).length() - b.radius).abs() < 1e-9);
                // The point projects back onto its pixel, and faces the camera.
                let (c, r) = s.camera.project(q).unwrap();
                assert!((c - (p % s.width) as f64).abs() < 1e-9);
                assert!((r - (p / s.width) as f64).abs() < 1e-9);
                assert!(s.normals[p].dot(-q) > 0.0);
                assert!(s.tangents[p].dot(s.normals[p]).abs() < 1e-12);
            }
        }
        // The left ball is on the image's left (x < 0), the right one on the right.
        let row = s.height / 2;
        assert_eq!(s.seen[row * s.width + s.width / 4], Some(0));
        assert_eq!(s.seen[row * s.width + 3 * s.width / 4], Some(1));
        let depth = s.depth();
        let d = depth[row * s.width + s.width / 4];
        assert!(d > 10.9 && d < 11.2, "{d}");
    }

    #[test]
    fn a_matte_ball_follows_the_inverse_square_law_and_casts_shadows() {
        let s = two_balls();
        let white = Lambertian::new([1.0; 3]);
        let mats: [&dyn Brdf; 2] = [&white, &white];
        let row = s.height / 2;
        let p = row * s.width + s.width / 4;
        let light = PointLight {
            intensity: [2.0, 1.0, 0.5],
            ..PointLight::isotropic(s.points[p] + 3.0 * s.normals[p])
        };
        let img = s.render(&mats, &light);
        // Facing the light 3 units away: albedo / pi * intensity / 9.
        let want = 2.0 / std::f64::consts::PI / 9.0;
        assert!((img[3 * p] as f64 - want).abs() < 1e-6, "{}", img[3 * p]);
        assert!((img[3 * p + 2] as f64 - want / 4.0).abs() < 1e-6);
        // A light far to the right, level with the balls: the right ball shades the left
        // ball's right side.
        let side = PointLight::isotropic(DVec3::new(20.0, 0.0, -12.0));
        let img = s.render(&mats, &side);
        let inner = (0..s.width / 2)
            .rev()
            .map(|c| row * s.width + c)
            .find(|&q| s.seen[q] == Some(0))
            .unwrap();
        assert!(s.normals[inner].x > 0.3);
        assert_eq!(img[3 * inner], 0.0);
        let outer = (s.width / 2..s.width)
            .rev()
            .map(|c| row * s.width + c)
            .find(|&q| s.seen[q] == Some(1))
            .unwrap();
        assert!(img[3 * outer] > 0.0);
    }

    #[test]
    fn dome_lights_lie_on_the_cap() {
        let c = DVec3::new(0.0, 0.0, -12.0);
        let lights = dome_lights(150, c, 8.0, 5.0, 64.0);
        assert_eq!(lights.len(), 150);
        for l in &lights {
            let d = l.position - c;
            assert!((d.length() - 8.0).abs() < 1e-9);
            assert!(d.z / 8.0 >= 5f64.to_radians().sin() - 1e-12);
            assert_eq!(l.intensity, [64.0; 3]);
        }
    }
}
