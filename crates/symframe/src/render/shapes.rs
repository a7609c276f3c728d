//! Scene constructors: sphere, cylinder, planes, and height fields (bumps).

use glam::DVec3;

use super::noise::Rng;
use super::tangent::{image_position, project_to_tangent_plane};
use super::{Scene, TangentField};

/// One Gaussian bump of a height field, in pixel units: `amplitude * exp(-d^2 / (2 sigma^2))`
/// where `d` is the distance from `(col, row)` (pixel centres at integer coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bump {
    /// Centre column (pixel units, 0 = centre of the leftmost pixel).
    pub col: f64,
    /// Centre row (pixel units, 0 = centre of the top pixel).
    pub row: f64,
    /// Width (standard deviation), pixels.
    pub sigma: f64,
    /// Height at the centre, pixels (negative for a dent).
    pub amplitude: f64,
}

impl Bump {
    /// The bump's height at continuous pixel coordinates.
    pub fn height_at(&self, col: f64, row: f64) -> f64 {
        let d2 = (col - self.col).powi(2) + (row - self.row).powi(2);
        self.amplitude * (-d2 / (2.0 * self.sigma * self.sigma)).exp()
    }
}

/// A seeded random field of bumps for [`Scene::bumps`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BumpParams {
    /// Number of bumps.
    pub count: usize,
    /// Height scale: each bump's amplitude is `relief * sigma * U(0.6, 1.4)`, so at relief 1 a
    /// lone bump's steepest slope is 20 to 40 degrees (bumps overlap, so sums can be steeper).
    pub relief: f64,
    /// Seed of the layout.
    pub seed: u64,
}

impl Default for BumpParams {
    /// 12 bumps, relief 1, seed 0.
    fn default() -> Self {
        Self {
            count: 12,
            relief: 1.0,
            seed: 0,
        }
    }
}

impl BumpParams {
    /// The bumps for a `size x size` image: centres uniform in the middle 70% of the frame,
    /// widths `sigma = size * U(0.05, 0.12)`, amplitudes as documented on `relief`.
    pub fn bumps(&self, size: usize) -> Vec<Bump> {
        let mut rng = Rng::new(self.seed);
        let s = size as f64;
        (0..self.count)
            .map(|_| {
                let col = rng.range(0.15, 0.85) * s - 0.5;
                let row = rng.range(0.15, 0.85) * s - 0.5;
                let sigma = s * rng.range(0.05, 0.12);
                let amplitude = self.relief * sigma * rng.range(0.6, 1.4);
                Bump {
                    col,
                    row,
                    sigma,
                    amplitude,
                }
            })
            .collect()
    }
}

impl Scene {
    /// The frame of a tilted planar patch: the normal at `theta_n_deg` from the view, tilted
    /// toward the image-plane azimuth `phi_n_deg` (counter-clockwise from x, so 0 tilts toward +x
    /// and the normal lies in the x-z plane), and the tangent rotated by `tangent_angle_deg` about
    /// the normal from the projection of camera x onto the tangent plane (positive angles turn from
    /// x toward `n x x_proj`, i.e. counter-clockwise as seen from the camera). This is the paper's
    /// Figure 3 set-up: `phi_n = 0`, tangent 25 degrees off the x-z plane. Returns `(n, t)`.
    ///
    /// The projection of x degenerates only for a normal along x (`theta_n = 90`, `phi_n = 0`);
    /// the projection of y is used there.
    pub fn plane_frame(theta_n_deg: f64, phi_n_deg: f64, tangent_angle_deg: f64) -> (DVec3, DVec3) {
        let (st, ct) = theta_n_deg.to_radians().sin_cos();
        let (sp, cp) = phi_n_deg.to_radians().sin_cos();
        let n = DVec3::new(st * cp, st * sp, ct);
        let r = project_to_tangent_plane(DVec3::X, n);
        let (sa, ca) = tangent_angle_deg.to_radians().sin_cos();
        let t = (ca * r + sa * n.cross(r)).normalize();
        (n, t)
    }

    /// A scene from per-pixel normals inside a mask; tangents from `field`.
    fn from_normals(
        width: usize,
        height: usize,
        mask: Vec<bool>,
        normals_in_camera: Vec<DVec3>,
        field: TangentField,
    ) -> Self {
        let mut scene = Self {
            width,
            height,
            mask,
            normals_in_camera,
            tangents_in_camera: vec![DVec3::X; width * height],
            heights: None,
        };
        scene.set_tangent_field(field);
        scene
    }

    /// Recomputes every tangent (inside the mask) from `field`, evaluated at each pixel's
    /// normalised image position (see `image_position`).
    pub fn set_tangent_field(&mut self, field: TangentField) {
        for p in 0..self.n_pixels() {
            if self.mask[p] {
                let (x, y) =
                    image_position(self.width, self.height, p % self.width, p / self.width);
                self.tangents_in_camera[p] =
                    field.tangent_at_point(self.normals_in_camera[p], x, y);
            }
        }
    }

    /// A sphere filling a `size x size` image (pixel centres inside the disc), seen head-on.
    pub fn sphere(size: usize, field: TangentField) -> Self {
        let r = size as f64 / 2.0;
        let n = size * size;
        let mut mask = vec![false; n];
        let mut normals = vec![DVec3::Z; n];
        for y in 0..size {
            for x in 0..size {
                let nx = (x as f64 + 0.5 - r) / r;
                let ny = -(y as f64 + 0.5 - r) / r; // image up is +y
                let rr = nx * nx + ny * ny;
                if rr < 1.0 {
                    let p = y * size + x;
                    mask[p] = true;
                    normals[p] = DVec3::new(nx, ny, (1.0 - rr).sqrt());
                }
            }
        }
        Self::from_normals(size, size, mask, normals, field)
    }

    /// A cylinder whose axis runs along image y, filling a `size x size` image: every pixel is
    /// covered, and the normal of column `x` is `(u, 0, sqrt(1 - u^2))` with
    /// `u = (x + 0.5 - size/2) / (size/2)`.
    pub fn cylinder(size: usize, field: TangentField) -> Self {
        let r = size as f64 / 2.0;
        let normals = (0..size * size)
            .map(|p| {
                let u = ((p % size) as f64 + 0.5 - r) / r;
                DVec3::new(u, 0.0, (1.0 - u * u).sqrt())
            })
            .collect();
        Self::from_normals(size, size, vec![true; size * size], normals, field)
    }

    /// A flat `width x height` patch with one normal and tangent everywhere (the tangent is
    /// projected onto the plane).
    pub fn plane(width: usize, height: usize, normal: DVec3, tangent: DVec3) -> Self {
        let n = normal.normalize();
        let t = project_to_tangent_plane(tangent, n);
        Self {
            width,
            height,
            mask: vec![true; width * height],
            normals_in_camera: vec![n; width * height],
            tangents_in_camera: vec![t; width * height],
            heights: None,
        }
    }

    /// A flat patch in the orientation of [`Scene::plane_frame`] (angles in degrees).
    pub fn tilted_plane(
        width: usize,
        height: usize,
        theta_n_deg: f64,
        phi_n_deg: f64,
        tangent_angle_deg: f64,
    ) -> Self {
        let (n, t) = Scene::plane_frame(theta_n_deg, phi_n_deg, tangent_angle_deg);
        Self::plane(width, height, n, t)
    }

    /// A height field covering the whole `width x height` frame. `heights` (row-major, pixel
    /// units, samples at pixel centres; see `render/shadow.rs`) give the normals by finite
    /// differences (central inside, one-sided on the border):
    /// `n = normalize(-dh/dx, -dh/dy, 1)` with x = column and y = up = -row. The heights stay
    /// in the scene, so rendering casts shadows.
    ///
    /// # Panics
    /// If `heights` does not have `width * height` values or a side is shorter than 2.
    pub fn height_field(
        width: usize,
        height: usize,
        heights: Vec<f64>,
        field: TangentField,
    ) -> Self {
        assert_eq!(heights.len(), width * height, "height_field: wrong length");
        assert!(width >= 2 && height >= 2, "height_field: too small");
        let h = |c: usize, r: usize| heights[r * width + c];
        let diff = |i: usize, n: usize, f: &dyn Fn(usize) -> f64| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            (f(b) - f(a)) / (b - a) as f64
        };
        let normals = (0..width * height)
            .map(|p| {
                let (c, r) = (p % width, p / width);
                let dh_dcol = diff(c, width, &|k| h(k, r));
                let dh_drow = diff(r, height, &|k| h(c, k));
                DVec3::new(-dh_dcol, dh_drow, 1.0).normalize()
            })
            .collect();
        let mut scene =
            Self::from_normals(width, height, vec![true; width * height], normals, field);
        scene.heights = Some(heights);
        scene
    }

    /// A `size x size` height field that is the sum of `bumps` over flat ground at height 0.
    pub fn from_bumps(size: usize, bumps: &[Bump], field: TangentField) -> Self {
        let heights = (0..size * size)
            .map(|p| {
                let (c, r) = ((p % size) as f64, (p / size) as f64);
                bumps.iter().map(|b| b.height_at(c, r)).sum()
            })
            .collect();
        Self::height_field(size, size, heights, field)
    }

    /// A `size x size` field of seeded random bumps ([`BumpParams::bumps`]), with cast shadows.
    pub fn bumps(size: usize, params: &BumpParams, field: TangentField) -> Self {
        Self::from_bumps(size, &params.bumps(size), field)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_frames(s: &Scene) {
        assert_eq!(s.mask.len(), s.n_pixels());
        for p in 0..s.n_pixels() {
            if s.mask[p] {
                let n = s.normals_in_camera[p];
                let t = s.tangents_in_camera[p];
                assert!((n.length() - 1.0).abs() < 1e-12 && n.z >= 0.0, "{p}: n {n}");
                assert!(
                    (t.length() - 1.0).abs() < 1e-9 && t.dot(n).abs() < 1e-9,
                    "{p}: t {t}"
                );
            }
        }
    }

    fn area(s: &Scene) -> usize {
        s.mask.iter().filter(|&&m| m).count()
    }

    #[test]
    fn sphere_frames_and_area() {
        for f in [
            TangentField::Circular,
            TangentField::Radial,
            TangentField::Swirl(30.0),
        ] {
            let s = Scene::sphere(32, f);
            check_frames(&s);
            let a = std::f64::consts::PI * 16.0 * 16.0;
            assert!((area(&s) as f64 - a).abs() < 0.05 * a);
            assert!(s.heights.is_none());
        }
    }

    #[test]
    fn cylinder_fills_the_frame_with_horizontal_normals() {
        let s = Scene::cylinder(20, TangentField::Axial(DVec3::Y));
        check_frames(&s);
        assert_eq!(area(&s), 400);
        for p in 0..400 {
            let n = s.normals_in_camera[p];
            assert_eq!(n.y, 0.0);
            // Rows are identical; columns left of centre face left.
            assert_eq!(n, s.normals_in_camera[p % 20]);
            assert_eq!(n.x < 0.0, p % 20 < 10);
            // The axial field along y is the cylinder's axis.
            assert!((s.tangents_in_camera[p] - DVec3::Y).length() < 1e-12);
        }
        // The edge columns are nearly grazing.
        assert!(s.normals_in_camera[0].z < 0.35);
    }

    #[test]
    fn tilted_plane_has_the_requested_angles() {
        let s = Scene::tilted_plane(5, 4, 40.0, 0.0, 25.0);
        check_frames(&s);
        assert_eq!(area(&s), 20);
        let (n, t) = (s.normals_in_camera[7], s.tangents_in_camera[7]);
        assert!((n.z.acos().to_degrees() - 40.0).abs() < 1e-9);
        assert!(
            n.y.abs() < 1e-15 && n.x > 0.0,
            "normal in the x-z plane: {n}"
        );
        // The tangent is 25 degrees from the x-z plane (whose normal is y).
        assert!((t.y.asin().to_degrees() - 25.0).abs() < 1e-9, "{t}");
        // Angle 0: the projection of x; azimuth 90 tilts toward +y.
        let (n0, t0) = Scene::plane_frame(30.0, 0.0, 0.0);
        assert!((t0 - (DVec3::X - n0.x * n0).normalize()).length() < 1e-12);
        let (n9, t9) = Scene::plane_frame(30.0, 90.0, 0.0);
        assert!(n9.y > 0.49 && n9.x.abs() < 1e-12 && (t9 - DVec3::X).length() < 1e-12);
        // Degenerate reference: a normal along x uses y.
        let (nx, tx) = Scene::plane_frame(90.0, 0.0, 0.0);
        assert!(nx.dot(tx).abs() < 1e-12 && (tx.length() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bump_field_normals_follow_the_gradient() {
        let p = BumpParams {
            count: 6,
            relief: 1.0,
            seed: 3,
        };
        let s = Scene::bumps(40, &p, TangentField::Radial);
        check_frames(&s);
        assert_eq!(area(&s), 1600);
        let h = s.heights.as_ref().unwrap();
        assert!(h.iter().all(|&v| v >= 0.0) && h.iter().cloned().fold(0.0, f64::max) > 1.0);
        // Deterministic in the seed, different across seeds.
        assert_eq!(Scene::bumps(40, &p, TangentField::Radial), s);
        assert_ne!(
            Scene::bumps(40, &BumpParams { seed: 4, ..p }, TangentField::Radial).heights,
            s.heights
        );
        // A single bump: normals tilt away from its centre (right of it: +x; above it: +y).
        let b = Bump {
            col: 10.0,
            row: 10.0,
            sigma: 4.0,
            amplitude: 3.0,
        };
        let s = Scene::from_bumps(21, &[b], TangentField::Circular);
        let at = |c: usize, r: usize| s.normals_in_camera[r * 21 + c];
        assert!((at(10, 10) - DVec3::Z).length() < 1e-12);
        assert!(at(14, 10).x > 0.3 && at(14, 10).y.abs() < 1e-12);
        assert!(at(10, 6).y > 0.3 && at(10, 6).x.abs() < 1e-12);
        // Central differences match the analytic slope (their error here is h'''/6, 2%).
        let slope = 3.0 * 4.0 / 16.0 * (-0.5f64).exp(); // dh/dcol at 4 px = sigma
        let n = at(14, 10);
        assert!(
            (n.x / n.z - slope).abs() < 0.03 * slope,
            "{} vs {slope}",
            n.x / n.z
        );
    }
}
