//! Mirror (chrome) spheres seen by a pinhole camera under one near lamp: the images a light
//! position calibration reads ([`crate::near::chrome`]), with the truth it is measured against.
//!
//! Each point of the image is a ray from the camera's centre; the nearest sphere it meets
//! reflects it (a perfect mirror, `r = d - 2 (d.n) n`). The reflected ray sees the lamp, a
//! small sphere of `lamp_radius` about the light's position, unless another sphere stands in
//! the way; a ray that meets another sphere is reflected again (up to four times), and the
//! last ray sees a room lit from above (`room * (0.5 + 0.5 r.y)`), times the reflectance once
//! per reflection. The lamp seen through two mirrors is left out (a far smaller spot, shrunk
//! by the second convex mirror). Off the spheres: `background`. Pixels are the mean over `samples x samples` points where a rim crosses them
//! (else their centre), then blurred by the lens (a Gaussian of `blur` pixels); the lamp's
//! reflection, a fraction of a pixel across, is found on a grid eight times finer in the pixels
//! whose reflected rays pass near the lamp and spread by the same blur from where it lies.
//!
//! It shares no geometry with the calibration (its own rays, intersections and reflection), so
//! the calibration is measured against it. Pixel points are in [`crate::calibrate::Circle`]'s
//! convention (the top-left pixel's centre at `(0.5, 0.5)`); the camera's `K` in OpenCV's.

use glam::DVec3;

use super::mirror_ball::{develop, lamp_hits, pixel_points};
use crate::near::Pinhole;

/// Mirror spheres before a pinhole camera, and what they reflect.
#[derive(Debug, Clone, PartialEq)]
pub struct NearMirrorBalls {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The camera.
    pub camera: Pinhole,
    /// The spheres: centre (camera frame, z < 0) and radius.
    pub balls: Vec<(DVec3, f64)>,
    /// The lamp's radius, in the scene's length unit (a small LED diffuser).
    pub lamp_radius: f64,
    /// The lamp's radiance.
    pub lamp: f64,
    /// The room's radiance, lit from above.
    pub room: f64,
    /// The mirror's reflectance.
    pub reflectance: f64,
    /// The value off the spheres.
    pub background: f64,
    /// Points per pixel along each axis where a rim crosses the pixel.
    pub samples: usize,
    /// The lens's point spread, a Gaussian's standard deviation in pixels (0: none).
    pub blur: f64,
}

/// The most reflections a ray from the camera is followed through (between the spheres).
const MAX_BOUNCES: usize = 4;

/// What a point of the image sees.
struct Seen {
    /// The room's (or another sphere's) radiance, without the lamp.
    room: f64,
    /// Whether it sees the lamp.
    lamp: bool,
}

impl NearMirrorBalls {
    /// Spheres of a `width x height` image under a lamp of radius 0.05 units and radiance 5000,
    /// a room of radiance 1, reflectance 0.8, a black background, 8 x 8 points a pixel on the
    /// rims and a lens blur of 0.7 pixels.
    pub fn new(width: usize, height: usize, camera: Pinhole, balls: &[(DVec3, f64)]) -> Self {
        Self {
            width,
            height,
            camera,
            balls: balls.to_vec(),
            lamp_radius: 0.05,
            lamp: 5000.0,
            room: 1.0,
            reflectance: 0.8,
            background: 0.0,
            samples: 8,
            blur: 0.7,
        }
    }

    /// The distance along the unit ray `(o, d)` to sphere `(c, r)`, beyond `near`.
    fn hit(o: DVec3, d: DVec3, c: DVec3, r: f64, near: f64) -> Option<f64> {
        let oc = o - c;
        let b = oc.dot(d);
        let disc = b * b - (oc.length_squared() - r * r);
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        [-b - s, -b + s].into_iter().find(|&t| t > near)
    }

    /// The nearest sphere the camera's ray through image point `(x, y)` meets: its index, the
    /// surface point and the reflected unit direction.
    fn mirror(&self, x: f64, y: f64) -> Option<(usize, DVec3, DVec3)> {
        let d = self.camera.ray(x - 0.5, y - 0.5).normalize();
        let (t, i) = self
            .balls
            .iter()
            .enumerate()
            .filter_map(|(i, &(c, r))| Self::hit(DVec3::ZERO, d, c, r, 0.0).map(|t| (t, i)))
            .min_by(|a, b| a.0.total_cmp(&b.0))?;
        let (c, r) = self.balls[i];
        let p = d * t;
        let n = (p - c) / r;
        Some((i, p, d - 2.0 * d.dot(n) * n))
    }

    /// What image point `(x, y)` sees under the lamp at `light`; `None` off the spheres.
    fn at(&self, x: f64, y: f64, light: DVec3) -> Option<Seen> {
        let (mut i, mut p, mut r) = self.mirror(x, y)?;
        let mut gain = self.reflectance;
        let mut lamp = None;
        for bounce in 0..MAX_BOUNCES {
            let other = self
                .balls
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .filter_map(|(j, &(c, rad))| Self::hit(p, r, c, rad, 1e-9).map(|t| (t, j)))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            if bounce == 0 {
                let to_lamp = Self::hit(p, r, light, self.lamp_radius, 0.0);
                lamp = Some(to_lamp.is_some_and(|s| other.is_none_or(|(t, _)| s < t)));
            }
            let Some((t, j)) = other else {
                break;
            };
            let (c, rad) = self.balls[j];
            p += r * t;
            let n = (p - c) / rad;
            r -= 2.0 * r.dot(n) * n;
            i = j;
            gain *= self.reflectance;
        }
        Some(Seen {
            room: gain * self.room * (0.5 + 0.5 * r.y),
            lamp: lamp.unwrap_or(false),
        })
    }

    /// The image (`width x height` grey values, row-major) under the lamp at `light` (camera
    /// frame). See the module documentation.
    pub fn render(&self, light: DVec3) -> Vec<f32> {
        let (width, height) = (self.width, self.height);
        let k = self.samples.max(1);
        let mut room = vec![self.background; width * height];
        let mut hits: Vec<(f64, f64, f64)> = Vec::new();
        for row in 0..height {
            for col in 0..width {
                let (x, y) = (col as f64 + 0.5, row as f64 + 0.5);
                let centre = self.mirror(x, y);
                let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
                    .map(|(a, b)| self.mirror(col as f64 + a, row as f64 + b).map(|m| m.0));
                let rim = corners.iter().any(|c| *c != centre.map(|m| m.0));
                if centre.is_none() && !rim {
                    continue;
                }
                // Whether the reflected rays of this pixel pass near the lamp: the angle from
                // the centre's ray to the lamp within the lamp's own angle and twice what the
                // reflected direction turns across a pixel.
                let near_lamp = rim
                    || centre.is_some_and(|(i, p, r)| {
                        let span = [(1.0, 0.0), (0.0, 1.0)]
                            .iter()
                            .map(|(a, b)| match self.mirror(x + a, y + b) {
                                Some((j, _, q)) if j == i => r.angle_between(q),
                                _ => std::f64::consts::PI,
                            })
                            .fold(0.0, f64::max);
                        let to = light - p;
                        let own = (self.lamp_radius / to.length()).min(1.0).asin();
                        r.angle_between(to) < own + 2.0 * span
                    });
                let points = pixel_points(col, row, k, rim);
                let share = 1.0 / points.len() as f64;
                room[row * width + col] = points
                    .iter()
                    .map(|&(px, py)| self.at(px, py, light).map_or(self.background, |s| s.room))
                    .sum::<f64>()
                    * share;
                if near_lamp {
                    lamp_hits(
                        col,
                        row,
                        k,
                        self.reflectance,
                        self.lamp,
                        &mut hits,
                        |px, py| self.at(px, py, light).is_some_and(|s| s.lamp),
                    );
                }
            }
        }
        develop(&room, &hits, width, height, self.blur)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lamp_is_seen_where_the_mirror_sends_the_view_to_it() {
        let camera = Pinhole::centred(96, 48, 22.6);
        let balls = [
            (DVec3::new(-1.1, 0.0, -12.0), 1.0),
            (DVec3::new(1.1, 0.0, -12.0), 1.0),
        ];
        let scene = NearMirrorBalls {
            blur: 0.0,
            ..NearMirrorBalls::new(96, 48, camera, &balls)
        };
        // A lamp behind the camera, on the left ball's line along z: its reflection is within
        // two pixels of the ball's centre as the camera sees it (the normal there is halfway
        // between z and the view, 5 degrees apart: about a pixel). The right ball shows it too.
        let light = DVec3::new(-1.1, 0.0, 2.0);
        let img = scene.render(light);
        let brightest = (0..img.len())
            .filter(|i| i % 96 < 48)
            .max_by(|&a, &b| img[a].total_cmp(&img[b]))
            .unwrap();
        let (u, v) = camera.project(balls[0].0).unwrap();
        let (col, row) = ((brightest % 96) as f64, (brightest / 96) as f64);
        assert!(
            (col - u).abs() <= 2.0 && (row - v).abs() <= 1.0,
            "{col} {row}"
        );
        assert!(img[brightest] > 3.0, "{}", img[brightest]);
        // Off the balls: the background.
        assert_eq!(img[0], 0.0);
        // A lamp behind the right ball, seen from the left ball's right side, is hidden by it.
        let hidden = scene.render(DVec3::new(3.5, 0.0, -12.0));
        let lit = hidden.iter().filter(|&&v| v > 5.0).count();
        let lamp_free = scene.render(DVec3::new(3.5, 0.0, -12.0) + DVec3::new(0.0, 4.0, 0.0));
        assert!(lamp_free.iter().filter(|&&v| v > 5.0).count() > 0);
        // Its reflection on the right ball is there: only the left ball's is hidden.
        assert!(lit > 0);
        let left_half = (0..48)
            .flat_map(|r| (0..48).map(move |c| r * 96 + c))
            .filter(|&i| hidden[i] > 5.0)
            .count();
        assert_eq!(left_half, 0);
    }
}
