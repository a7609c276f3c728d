//! Light positions from two or more chrome (mirror) spheres seen by a pinhole camera.
//!
//! Each sphere's centre comes from its outline and its known radius: the camera sees a sphere
//! as the cone of rays tangent to it, so the rays through its rim in the image make one angle
//! `a` with the ray to its centre ([`Pinhole::sphere_from_rim`]: the cone fitted to the rim's
//! rays), and the centre lies along the cone's axis at `radius / sin(a)`. Under perspective the
//! outline is an ellipse slightly longer away from the principal point; the cone takes it as it
//! is.
//!
//! Each light's highlight on a sphere ([`crate::Highlight::find`]'s image point) is where the
//! ray from the camera meets the sphere at the point whose normal mirrors the view into the
//! direction of the light: the light lies on the reflected ray from that point
//! ([`Pinhole::reflected_ray`]). With two or more spheres the light is the point closest to all
//! its rays in least squares ([`Triangulation::from_rays`]); the distances from it to the rays
//! are its residual.
//!
//! Pixel points here are in [`Circle`]'s convention (x right, y down, the centre of the
//! top-left pixel at `(0.5, 0.5)`); the camera's `K` is OpenCV's (that centre at `(0, 0)`).

use glam::{DMat3, DVec3};

use crate::calibrate::Circle;
use crate::near::Pinhole;

/// The camera ray (unit) through image point `(x, y)` in [`Circle`]'s pixel convention.
pub(crate) fn pixel_ray(camera: &Pinhole, x: f64, y: f64) -> DVec3 {
    camera.ray(x - 0.5, y - 0.5).normalize()
}

impl Circle {
    /// `count` points evenly spaced on the circle's rim, for [`Pinhole::sphere_from_rim`] where
    /// only the circle is known.
    pub fn rim(&self, count: usize) -> Vec<(f64, f64)> {
        (0..count)
            .map(|k| {
                let a = k as f64 / count as f64 * std::f64::consts::TAU;
                (self.cx + self.r * a.cos(), self.cy + self.r * a.sin())
            })
            .collect()
    }
}

impl Pinhole {
    /// The centre (camera frame) of a sphere of `radius` whose outline passes through the image
    /// points `rim` ([`Circle`]'s pixel convention): the cone of rays tangent to the sphere fitted
    /// to the rays through them (its axis `w / |w|` and `cos(a) = 1 / |w|` from `w . r = 1` by
    /// least squares, then Gauss-Newton on the angles between the rays and the axis), the centre
    /// `radius / sin(a)` along its axis. Why not where fewer than 8 points are given, a value is
    /// not finite, the radius is not positive, or the points do not lie on a cone opening away
    /// from the camera (a line of points, a cone wider than a half turn).
    pub fn sphere_from_rim(&self, rim: &[(f64, f64)], radius: f64) -> Result<DVec3, String> {
        if !(radius.is_finite() && radius > 0.0) {
            return Err(format!(
                "the sphere's radius must be a positive number, got {radius}"
            ));
        }
        if rim.len() < 8 {
            return Err(format!(
                "{} points on the sphere's outline, at least 8 needed",
                rim.len()
            ));
        }
        if rim.iter().any(|(x, y)| !(x.is_finite() && y.is_finite())) {
            return Err("a point of the sphere's outline is not a finite number".into());
        }
        let rays: Vec<DVec3> = rim.iter().map(|&(x, y)| pixel_ray(self, x, y)).collect();
        // w . r_i = 1 by least squares.
        let mut ata = DMat3::ZERO;
        let mut atb = DVec3::ZERO;
        for r in &rays {
            ata += DMat3::from_cols(*r * r.x, *r * r.y, *r * r.z);
            atb += *r;
        }
        let scale = (ata.x_axis.x + ata.y_axis.y + ata.z_axis.z) / 3.0;
        if ata.determinant().abs() <= 1e-18 * scale.powi(3) {
            return Err("the points of the sphere's outline do not span a cone".into());
        }
        let w = ata.inverse() * atb;
        let mut axis = w.normalize();
        let mut cos_a = 1.0 / w.length();
        if !(axis.is_finite() && cos_a > 0.0 && cos_a < 1.0 && axis.z < 0.0) {
            return Err(
                "the points of the sphere's outline do not lie on a cone before the camera".into(),
            );
        }
        // Gauss-Newton on the angles: r_i . axis = cos(a), the axis moved in its tangent plane.
        let mut angle = cos_a.acos();
        for _ in 0..10 {
            let (e1, e2) = {
                let t = if axis.x.abs() < 0.9 {
                    DVec3::X
                } else {
                    DVec3::Y
                };
                let e1 = axis.cross(t).normalize();
                (e1, axis.cross(e1))
            };
            let mut jtj = DMat3::ZERO;
            let mut jtr = DVec3::ZERO;
            for r in &rays {
                let c = r.dot(axis).clamp(-1.0, 1.0);
                let s = (1.0 - c * c).sqrt().max(1e-12);
                // The angle between r and the axis moved by (p, q) in (e1, e2): d/dp = -r.e1 / s.
                let j = DVec3::new(-r.dot(e1) / s, -r.dot(e2) / s, -1.0);
                let res = c.acos() - angle;
                jtj += DMat3::from_cols(j * j.x, j * j.y, j * j.z);
                jtr += j * res;
            }
            if jtj.determinant().abs() <= 1e-300 {
                break;
            }
            let step = -(jtj.inverse() * jtr);
            axis = (axis + step.x * e1 + step.y * e2).normalize();
            angle += step.z;
            if step.length() < 1e-14 {
                break;
            }
        }
        cos_a = angle.cos();
        let sin_a = angle.sin();
        if !(axis.is_finite() && sin_a > 0.0 && cos_a > 0.0 && axis.z < 0.0) {
            return Err(
                "the points of the sphere's outline do not lie on a cone before the camera".into(),
            );
        }
        Ok(axis * (radius / sin_a))
    }

    /// The ray that the mirror sphere of `centre` and `radius` reflects toward the camera at image
    /// point `(x, y)` ([`Circle`]'s pixel convention): the surface point where the camera's ray
    /// meets the sphere (where it passes beside it, the point of the sphere nearest to it) and the
    /// unit direction in which a light must lie to be seen there, `2 (n.v) n - v`.
    pub fn reflected_ray(&self, centre: DVec3, radius: f64, x: f64, y: f64) -> (DVec3, DVec3) {
        let d = pixel_ray(self, x, y);
        let b = d.dot(centre);
        let closest = d * b;
        let off = (centre - closest).length_squared();
        let point = if off <= radius * radius {
            d * (b - (radius * radius - off).sqrt())
        } else {
            centre + (closest - centre).normalize_or(DVec3::Z) * radius
        };
        let n = ((point - centre) / radius).normalize_or(DVec3::Z);
        let v = -d;
        (point, (2.0 * n.dot(v) * n - v).normalize_or(DVec3::Z))
    }
}

/// A light's position from the rays toward it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangulation {
    /// The point closest to the rays (least squares of its distances to them).
    pub position: DVec3,
    /// The root mean square of its distances to the rays.
    pub residual_rms: f64,
    /// The largest of its distances to the rays.
    pub residual_max: f64,
    /// The widest angle between two of the rays, degrees (small angles fix the position along
    /// the rays poorly).
    pub spread_deg: f64,
}

/// The narrowest angle (degrees) that two rays toward a light may make for
/// [`Triangulation::from_rays`] to place it: below it, an error of a tenth of a degree in a ray
/// moves the light along the rays by more than a twentieth of its distance.
pub(crate) const MIN_SPREAD_DEG: f64 = 2.0;

impl Triangulation {
    /// The point closest to the rays `(origin, unit direction)` in least squares, which must lie
    /// ahead of every origin. Why not where fewer than two rays are given, no two are at least
    /// `MIN_SPREAD_DEG` apart, or the point lies behind one of them.
    pub fn from_rays(rays: &[(DVec3, DVec3)]) -> Result<Triangulation, String> {
        if rays.len() < 2 {
            return Err(format!(
                "{} ray{} toward the light, at least 2 needed",
                rays.len(),
                if rays.len() == 1 { "" } else { "s" }
            ));
        }
        if rays.iter().any(|(o, d)| !(o.is_finite() && d.is_finite())) {
            return Err("a ray toward the light is not finite".into());
        }
        let mut spread: f64 = 0.0;
        for (i, (_, a)) in rays.iter().enumerate() {
            for (_, b) in &rays[i + 1..] {
                spread = spread.max(a.angle_between(*b).to_degrees());
            }
        }
        if spread < MIN_SPREAD_DEG {
            return Err(format!(
                "the rays toward the light are {spread:.2} degrees apart at most ({MIN_SPREAD_DEG} \
                 needed): spheres further apart fix it"
            ));
        }
        let mut a = DMat3::ZERO;
        let mut rhs = DVec3::ZERO;
        for (o, d) in rays {
            let p = DMat3::IDENTITY - DMat3::from_cols(*d * d.x, *d * d.y, *d * d.z);
            a += p;
            rhs += p * *o;
        }
        let x = a.inverse() * rhs;
        if !x.is_finite() {
            return Err("the rays toward the light do not fix a point".into());
        }
        let distances: Vec<f64> = rays
            .iter()
            .map(|(o, d)| {
                let q = x - *o;
                (q - d * q.dot(*d)).length()
            })
            .collect();
        if rays.iter().any(|(o, d)| (x - *o).dot(*d) <= 0.0) {
            return Err("the rays toward the light meet behind a sphere".into());
        }
        let n = distances.len() as f64;
        Ok(Triangulation {
            position: x,
            residual_rms: (distances.iter().map(|d| d * d).sum::<f64>() / n).sqrt(),
            residual_max: distances.iter().copied().fold(0.0, f64::max),
            spread_deg: spread,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of a sphere's true outline: the tangent cone's rays projected.
    fn outline(camera: &Pinhole, centre: DVec3, radius: f64, count: usize) -> Vec<(f64, f64)> {
        let axis = centre.normalize();
        let sin_a = radius / centre.length();
        let cos_a = (1.0 - sin_a * sin_a).sqrt();
        let e1 = axis.cross(DVec3::Y).normalize();
        let e2 = axis.cross(e1);
        (0..count)
            .map(|k| {
                let t = k as f64 / count as f64 * std::f64::consts::TAU;
                let r = axis * cos_a + (e1 * t.cos() + e2 * t.sin()) * sin_a;
                let (u, v) = camera.project(r).unwrap();
                (u + 0.5, v + 0.5)
            })
            .collect()
    }

    #[test]
    fn a_sphere_is_placed_by_its_outline_and_radius() {
        let camera = Pinhole::centred(320, 160, 22.6);
        for centre in [
            DVec3::new(0.0, 0.0, -12.0),
            DVec3::new(-1.1, 0.4, -12.6),
            DVec3::new(2.0, -1.0, -9.0),
        ] {
            let rim = outline(&camera, centre, 1.0, 64);
            let c = camera.sphere_from_rim(&rim, 1.0).unwrap();
            assert!((c - centre).length() < 1e-9, "{c} {centre}");
            // Twice the radius: twice the distance, the same direction.
            let c2 = camera.sphere_from_rim(&rim, 2.0).unwrap();
            assert!((c2 - 2.0 * centre).length() < 1e-8);
        }
        let rim = outline(&camera, DVec3::new(0.0, 0.0, -12.0), 1.0, 64);
        assert!(camera
            .sphere_from_rim(&rim[..5], 1.0)
            .unwrap_err()
            .contains("at least 8"));
        assert!(camera
            .sphere_from_rim(&rim, -1.0)
            .unwrap_err()
            .contains("positive"));
        let line: Vec<(f64, f64)> = (0..20).map(|i| (i as f64, 5.0)).collect();
        assert!(camera.sphere_from_rim(&line, 1.0).is_err());
        let mut nan = rim.clone();
        nan[3].0 = f64::NAN;
        assert!(camera
            .sphere_from_rim(&nan, 1.0)
            .unwrap_err()
            .contains("finite"));
    }

    #[test]
    fn two_mirror_spheres_triangulate_a_light() {
        let camera = Pinhole::centred(320, 160, 22.6);
        let balls = [DVec3::new(-1.1, 0.0, -12.6), DVec3::new(1.1, 0.0, -12.6)];
        let light = DVec3::new(3.0, 5.0, -6.0);
        let mut rays = Vec::new();
        for c in balls {
            // The mirror point: the normal halfway between the view and the light, found by
            // bisection along the sphere (independent of Pinhole::reflected_ray's formula).
            let mut n = (light - c).normalize();
            for _ in 0..200 {
                let p = c + n;
                let h = ((light - p).normalize() + (-p).normalize()).normalize();
                n = (n + 0.5 * (h - n)).normalize();
            }
            let (u, v) = camera.project(c + n).unwrap();
            let (o, d) = camera.reflected_ray(c, 1.0, u + 0.5, v + 0.5);
            assert!((o - (c + n)).length() < 1e-9);
            assert!(d.angle_between(light - o) < 1e-9);
            rays.push((o, d));
        }
        let t = Triangulation::from_rays(&rays).unwrap();
        assert!((t.position - light).length() < 1e-8, "{}", t.position);
        assert!(t.residual_max < 1e-8 && t.spread_deg > 10.0);
        assert!(Triangulation::from_rays(&rays[..1])
            .unwrap_err()
            .contains("at least 2"));
        let parallel = [rays[0], (rays[0].0 + DVec3::X * 0.01, rays[0].1)];
        assert!(Triangulation::from_rays(&parallel)
            .unwrap_err()
            .contains("apart"));
        let behind = [rays[0], (rays[1].0, -rays[1].1)];
        assert!(Triangulation::from_rays(&behind).is_err());
    }

    /// Two chrome balls under a dome of lamps, rendered by [`crate::render::NearMirrorBalls`]
    /// (the balls 139 pixels in radius): the spheres found in the mean image, placed by their
    /// outlines, each lamp triangulated from its highlights. Prints the errors over the dome's
    /// radius.
    #[test]
    fn chrome_balls_under_a_dome_give_the_lamps_within_a_percent_of_its_radius() {
        use crate::calibrate::{outline_points, CalibrationParams, Detection, Highlight};
        use crate::render::perspective::dome_lights;
        use crate::render::NearMirrorBalls;
        let (w, h) = (640, 320);
        let depth: f64 = 12.6;
        let half = 0.55 * 4.2;
        let camera = Pinhole::centred(w, h, 2.0 * (half / depth).atan().to_degrees());
        let balls = [
            (DVec3::new(-1.1, 0.0, -depth), 1.0),
            (DVec3::new(1.1, 0.0, -depth), 1.0),
        ];
        let scene = NearMirrorBalls::new(w, h, camera, &balls);
        let dome = 8.4;
        let lights = dome_lights(24, DVec3::new(0.0, 0.0, -depth), dome, 5.0, 1.0);
        let images: Vec<Vec<f32>> = lights.iter().map(|l| scene.render(l.position)).collect();
        let mut mean = vec![0.0f32; w * h];
        for img in &images {
            for (m, v) in mean.iter_mut().zip(img) {
                *m += v / images.len() as f32;
            }
        }
        let brightest: Vec<usize> = images
            .iter()
            .map(|img| {
                (0..img.len())
                    .max_by(|&a, &b| img[a].total_cmp(&img[b]))
                    .unwrap()
            })
            .collect();
        let mut found = Detection::find_all(w, h, &mean, &brightest, 0.05).unwrap();
        assert_eq!(found.len(), 2);
        found.sort_by(|a, b| a.circle.cx.total_cmp(&b.circle.cx));
        let mut spheres = Vec::new();
        for (d, (truth, r)) in found.iter().zip(balls) {
            let (_, rim) = outline_points(w, h, &mean, d.circle).unwrap();
            let c = camera.sphere_from_rim(&rim, r).unwrap();
            let from_circle = camera.sphere_from_rim(&d.circle.rim(256), r).unwrap();
            println!(
                "sphere centre error: {:.4} from the rim's points, {:.4} from its circle",
                (c - truth).length(),
                (from_circle - truth).length()
            );
            spheres.push((d.circle, c));
        }
        let mut errors = Vec::new();
        for (img, light) in images.iter().zip(&lights) {
            let rays: Vec<(DVec3, DVec3)> = spheres
                .iter()
                .filter_map(|(circle, c)| {
                    let hl =
                        Highlight::find(w, h, img, circle, &CalibrationParams::default()).ok()?;
                    Some(camera.reflected_ray(*c, 1.0, hl.x, hl.y))
                })
                .collect();
            if let Ok(t) = Triangulation::from_rays(&rays) {
                errors.push((t.position - light.position).length() / dome);
            }
        }
        let mean_err = errors.iter().sum::<f64>() / errors.len() as f64;
        let max_err = errors.iter().copied().fold(0.0, f64::max);
        println!(
            "{} of {} lamps placed; error over the dome's radius: mean {:.4}%, max {:.4}%",
            errors.len(),
            lights.len(),
            100.0 * mean_err,
            100.0 * max_err
        );
        assert!(errors.len() >= 22, "{} placed", errors.len());
        assert!(max_err < 0.01, "max {max_err}");
    }
}
