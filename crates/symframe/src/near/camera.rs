//! The pinhole camera: pixels to rays and points, points to pixels.
//!
//! Intrinsics come as OpenCV writes them: `K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]` maps a
//! point `(X, Y, Z)` of OpenCV's camera frame (x right, y down, z forward, into the scene) to
//! the pixel `u = (fx X + s Y) / Z + cx`, `v = fy Y / Z + cy`, with u to the right, v down and
//! the centre of the top-left pixel at `(0, 0)`. symframe's camera frame is x right, y up, z
//! toward the viewer (the object has z < 0), so OpenCV's `(X, Y, Z)` is symframe's
//! `(x, -y, -z)`; pixel `(col, row)` of an image (row 0 at the top) is `(u, v) = (col, row)`.

use glam::DVec3;

/// A pinhole camera at symframe's camera-frame origin, looking down -z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Focal length along u, pixels.
    pub fx: f64,
    /// Focal length along v, pixels.
    pub fy: f64,
    /// Principal point, u (pixels, OpenCV's convention).
    pub cx: f64,
    /// Principal point, v (pixels, OpenCV's convention).
    pub cy: f64,
    /// Skew (`K[0][1]`), 0 for square pixel grids.
    pub skew: f64,
}

impl Pinhole {
    /// The camera of an OpenCV intrinsics matrix (row-major); why not where it is not one: a
    /// value not finite, a focal length not positive, or a last row other than `0 0 1` or a
    /// `K[1][0]` other than 0.
    pub fn from_k(k: [[f64; 3]; 3]) -> Result<Self, String> {
        if k.iter().flatten().any(|v| !v.is_finite()) {
            return Err("K holds a value that is not a finite number".into());
        }
        if k[1][0] != 0.0 || k[2] != [0.0, 0.0, 1.0] {
            return Err(format!(
                "K is not a pinhole intrinsics matrix: its second row must start with 0 and its \
                 last row be 0 0 1 (got {} and {} {} {})",
                k[1][0], k[2][0], k[2][1], k[2][2]
            ));
        }
        let (fx, fy) = (k[0][0], k[1][1]);
        if !(fx > 0.0 && fy > 0.0) {
            return Err(format!(
                "K's focal lengths must be positive pixels (got fx {fx}, fy {fy})"
            ));
        }
        Ok(Self {
            fx,
            fy,
            cx: k[0][2],
            cy: k[1][2],
            skew: k[0][1],
        })
    }

    /// A camera of `width x height` pixels with square pixels, no skew, the principal point at
    /// the image centre and a horizontal field of view of `fov_deg` degrees (edge to edge).
    pub fn centred(width: usize, height: usize, fov_deg: f64) -> Self {
        let f = width as f64 / 2.0 / (fov_deg.to_radians() / 2.0).tan();
        Self {
            fx: f,
            fy: f,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
            skew: 0.0,
        }
    }

    /// The intrinsics matrix, row-major, as `K.txt` holds it.
    pub fn k(&self) -> [[f64; 3]; 3] {
        [
            [self.fx, self.skew, self.cx],
            [0.0, self.fy, self.cy],
            [0.0, 0.0, 1.0],
        ]
    }

    /// The point of pixel `(col, row)` at depth 1 along the optical axis (z = -1): every point
    /// the pixel sees is this times its depth.
    #[inline]
    pub fn ray(&self, col: f64, row: f64) -> DVec3 {
        let y = (row - self.cy) / self.fy;
        let x = (col - self.cx - self.skew * y) / self.fx;
        DVec3::new(x, -y, -1.0)
    }

    /// The surface point that pixel `(col, row)` sees at `depth` (its distance from the camera
    /// along the optical axis, so its z is `-depth`).
    #[inline]
    pub fn point(&self, col: f64, row: f64, depth: f64) -> DVec3 {
        self.ray(col, row) * depth
    }

    /// The unit view vector of pixel `(col, row)`: from the surface toward the camera.
    #[inline]
    pub fn view(&self, col: f64, row: f64) -> DVec3 {
        -self.ray(col, row).normalize()
    }

    /// The pixel `(col, row)` a camera-frame point projects to; `None` for a point not in front
    /// of the camera (z >= 0).
    pub fn project(&self, p: DVec3) -> Option<(f64, f64)> {
        if p.z >= 0.0 {
            return None;
        }
        let (x, y) = (p.x / -p.z, -p.y / -p.z);
        Some((self.fx * x + self.skew * y + self.cx, self.fy * y + self.cy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k() -> [[f64; 3]; 3] {
        [[500.0, 0.0, 320.0], [0.0, 480.0, 240.0], [0.0, 0.0, 1.0]]
    }

    #[test]
    fn opencv_pixels_map_to_symframe_directions() {
        let cam = Pinhole::from_k(k()).unwrap();
        // The principal point looks straight down the optical axis, -z.
        assert_eq!(cam.ray(320.0, 240.0), DVec3::new(0.0, 0.0, -1.0));
        assert_eq!(cam.view(320.0, 240.0), DVec3::Z);
        // A pixel to the right of it sees +x; one below it (v grows down) sees -y.
        let right = cam.ray(820.0, 240.0);
        assert_eq!(right, DVec3::new(1.0, 0.0, -1.0));
        let below = cam.ray(320.0, 720.0);
        assert_eq!(below, DVec3::new(0.0, -1.0, -1.0));
        // The top-left pixel's centre is (0, 0): up and to the left.
        let top_left = cam.ray(0.0, 0.0);
        assert!(top_left.x < 0.0 && top_left.y > 0.0);
        // The view vector points back at the camera.
        let v = cam.view(0.0, 0.0);
        assert!((v + top_left.normalize()).length() < 1e-15);
    }

    #[test]
    fn points_project_back_to_their_pixels() {
        let mut m = k();
        m[0][1] = 3.0; // skew
        let cam = Pinhole::from_k(m).unwrap();
        for (col, row, depth) in [(0.0, 0.0, 2.0), (101.5, 377.25, 12.0), (640.0, 0.0, 0.3)] {
            let p = cam.point(col, row, depth);
            assert!((p.z + depth).abs() < 1e-12);
            let (c, r) = cam.project(p).unwrap();
            assert!((c - col).abs() < 1e-9 && (r - row).abs() < 1e-9, "{c} {r}");
        }
        assert_eq!(cam.project(DVec3::new(0.0, 0.0, 1.0)), None);
        assert_eq!(cam.k(), m);
    }

    #[test]
    fn bad_matrices_say_why() {
        let mut m = k();
        m[2][2] = 2.0;
        assert!(Pinhole::from_k(m).unwrap_err().contains("0 0 1"));
        let mut m = k();
        m[1][1] = -480.0;
        assert!(Pinhole::from_k(m).unwrap_err().contains("positive"));
        let mut m = k();
        m[0][2] = f64::NAN;
        assert!(Pinhole::from_k(m).unwrap_err().contains("finite"));
    }

    #[test]
    fn a_centred_camera_spans_its_field_of_view() {
        let cam = Pinhole::centred(200, 100, 30.0);
        // The outer edges of the outermost pixels are 15 degrees off the axis.
        let edge = cam.view(-0.5, cam.cy);
        assert!((edge.angle_between(DVec3::Z).to_degrees() - 15.0).abs() < 1e-9);
        assert_eq!(cam.view(cam.cx, cam.cy), DVec3::Z);
    }
}
