//! Point lights near the object: each light's direction and irradiance at a surface point, and
//! the centre of the sphere through the lights (a dome's centre, where the object is taken to be
//! when its distance is not known).

use glam::{DMat3, DVec3};

/// A point light (an LED) in the camera frame.
///
/// The irradiance it gives a surface point `p` facing it is `intensity * cos(a)^mu / r^2`, with
/// `r` the distance from the light to `p` and `a` the angle between the light's principal
/// direction and the ray from the light to `p` (Quéau et al.'s LED model, as in LUCES); without
/// a principal direction the light is isotropic (`mu` unused).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLight {
    /// Position, camera frame (any length unit, the same as the depths').
    pub position: DVec3,
    /// Radiant intensity per RGB channel.
    pub intensity: [f64; 3],
    /// Unit direction the LED points in (from the LED into the scene), if it is not isotropic.
    pub principal: Option<DVec3>,
    /// Falloff exponent about the principal direction (0: isotropic).
    pub mu: f64,
}

impl PointLight {
    /// An isotropic light of unit intensity at `position`.
    pub fn isotropic(position: DVec3) -> Self {
        Self {
            position,
            intensity: [1.0; 3],
            principal: None,
            mu: 0.0,
        }
    }

    /// The unit direction from `p` toward the light, and the light's irradiance factor at `p`
    /// without its intensity: `cos(a)^mu / r^2` (0 behind an LED, where `cos(a) <= 0`).
    /// `None` when `p` is at the light.
    #[inline]
    pub fn at(&self, p: DVec3) -> Option<(DVec3, f64)> {
        let d = self.position - p;
        let r2 = d.length_squared();
        if r2.is_nan() || r2 <= 0.0 {
            return None;
        }
        let l = d / r2.sqrt();
        let falloff = match self.principal {
            None => 1.0,
            Some(s) => {
                let c = -s.dot(l);
                if c <= 0.0 {
                    0.0
                } else if self.mu == 0.0 {
                    1.0
                } else {
                    c.powf(self.mu)
                }
            }
        };
        Some((l, falloff / r2))
    }

    /// The sphere that best fits `points` (algebraic least squares: `|p|^2 = 2 c.p + k`), as
    /// (centre, radius); `None` for fewer than four points, points on one plane or circle (the
    /// fit is ill-conditioned), or a non-finite answer.
    pub fn fit_sphere(points: &[DVec3]) -> Option<(DVec3, f64)> {
        if points.len() < 4 {
            return None;
        }
        // Centred on the mean for conditioning; unknowns (c', k') of |q|^2 = 2 c'.q + k'.
        let mean = points.iter().copied().sum::<DVec3>() / points.len() as f64;
        let scale = points
            .iter()
            .map(|p| (*p - mean).length())
            .fold(0.0, f64::max);
        if !(scale > 0.0 && scale.is_finite()) {
            return None;
        }
        // Normal equations of the 4 unknowns.
        let mut a = [[0.0f64; 4]; 4];
        let mut b = [0.0f64; 4];
        for p in points {
            let q = (*p - mean) / scale;
            let row = [2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0];
            let rhs = q.length_squared();
            for i in 0..4 {
                for j in 0..4 {
                    a[i][j] += row[i] * row[j];
                }
                b[i] += row[i] * rhs;
            }
        }
        let x = solve4(a, b)?;
        let c = DVec3::new(x[0], x[1], x[2]);
        let r2 = x[3] + c.length_squared();
        if r2.is_nan() || r2 <= 0.0 {
            return None;
        }
        // Ill-conditioned (points on a plane): the centre runs off far beyond the points.
        if c.length() > 1e3 {
            return None;
        }
        let centre = mean + c * scale;
        let radius = r2.sqrt() * scale;
        (centre.is_finite() && radius.is_finite()).then_some((centre, radius))
    }
}

/// Solves a symmetric 4 x 4 system by Gaussian elimination with partial pivoting; `None` when
/// it is (nearly) singular.
fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    let norm = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    for col in 0..4 {
        let pivot = (col..4).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        let p = a[pivot][col].abs();
        if p.is_nan() || p <= 1e-12 * norm {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..4 {
            let f = a[row][col] / pivot_row[col];
            for (x, y) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * y;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 4];
    for row in (0..4).rev() {
        let s: f64 = (row + 1..4).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

/// The rotation that takes the unit vector `v` to +z along the great circle between them (the
/// identity for `v = z`); for `v = -z`, the half turn about x.
pub(crate) fn rotation_to_z(v: DVec3) -> DMat3 {
    let c = v.z;
    if c < -1.0 + 1e-12 {
        return DMat3::from_rotation_x(std::f64::consts::PI);
    }
    // Rodrigues' formula with axis v x z (unnormalised), angle acos(c).
    let axis = v.cross(DVec3::Z);
    let k = 1.0 / (1.0 + c);
    let [x, y, z] = axis.to_array();
    DMat3::from_cols(
        DVec3::new(c + x * x * k, x * y * k + z, x * z * k - y),
        DVec3::new(x * y * k - z, c + y * y * k, y * z * k + x),
        DVec3::new(x * z * k + y, y * z * k - x, c + z * z * k),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn irradiance_falls_with_the_square_of_the_distance_and_the_led_cosine() {
        let light = PointLight::isotropic(DVec3::new(0.0, 0.0, 4.0));
        let (l, e) = light.at(DVec3::ZERO).unwrap();
        assert_eq!(l, DVec3::Z);
        assert!((e - 1.0 / 16.0).abs() < 1e-15);
        let (_, e2) = light.at(DVec3::new(0.0, 0.0, -4.0)).unwrap();
        assert!((e / e2 - 4.0).abs() < 1e-12);
        assert_eq!(light.at(light.position), None);
        // An LED pointing down -z with mu 2: 60 degrees off its axis gives a quarter.
        let led = PointLight {
            principal: Some(-DVec3::Z),
            mu: 2.0,
            ..light
        };
        let p = DVec3::new(4.0 * 3f64.sqrt(), 0.0, 0.0);
        let (l, e) = led.at(p).unwrap();
        assert!((l.angle_between(DVec3::new(-3f64.sqrt(), 0.0, 1.0)) < 1e-12));
        assert!((e - 0.25 / 64.0).abs() < 1e-15, "{e}");
        // Behind the LED: dark.
        let (_, e) = led.at(DVec3::new(0.0, 0.0, 8.0)).unwrap();
        assert_eq!(e, 0.0);
    }

    #[test]
    fn a_dome_gives_its_centre_and_a_plane_nothing() {
        let centre = DVec3::new(0.3, -0.2, -12.0);
        let dome: Vec<DVec3> = (0..40)
            .map(|i| {
                let a = i as f64 * 2.399_963;
                let z = 0.1 + 0.85 * (i as f64 / 40.0);
                let r = (1.0 - z * z).sqrt();
                centre + 8.0 * DVec3::new(r * a.cos(), r * a.sin(), z)
            })
            .collect();
        let (c, r) = PointLight::fit_sphere(&dome).unwrap();
        assert!(
            (c - centre).length() < 1e-9 && (r - 8.0).abs() < 1e-9,
            "{c} {r}"
        );
        let plane: Vec<DVec3> = (0..20)
            .map(|i| DVec3::new((i % 5) as f64, (i / 5) as f64, -3.0))
            .collect();
        assert_eq!(PointLight::fit_sphere(&plane), None);
        assert_eq!(PointLight::fit_sphere(&dome[..3]), None);
    }

    #[test]
    fn rotations_to_z_are_rotations() {
        for v in [
            DVec3::Z,
            DVec3::new(0.3, -0.2, 0.9).normalize(),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 0.1, -1.0).normalize(),
            -DVec3::Z,
        ] {
            let r = rotation_to_z(v);
            assert!((r * v - DVec3::Z).length() < 1e-12, "{v}");
            assert!((r.determinant() - 1.0).abs() < 1e-12);
            assert!((r.transpose() * r - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-12));
        }
    }
}
