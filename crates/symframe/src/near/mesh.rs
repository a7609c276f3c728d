//! The mesh of a perspective depth map: a vertex at the surface point each pixel sees, in the
//! camera frame and the depths' unit, so that the mesh seen through the pinhole lies on the
//! photographs.

use glam::DVec3;

use crate::integrate::{continuous_edge, triangulate_grid, Mesh};
use crate::near::Pinhole;

/// Smallest cosine between a normal and the ray to its pixel used to predict the depth's slope:
/// normals turning away from the camera ask for unbounded slopes, as `nz -> 0` does in the
/// orthographic mesh.
const MIN_FACING: f64 = 0.05;

impl Pinhole {
    /// Builds the mesh of `depth` (`H x W`, metric depths along the optical axis through this
    /// camera, NaN where none) with the camera-frame `normals` (`H x W x 3`): a vertex at
    /// `self.point(col, row, depth)` for every pixel with a depth and a normal, two triangles per
    /// 2 x 2 block (one where only three pixels are valid), counter-clockwise seen from the camera.
    /// A triangle is left out where an edge's log-depth step departs from the normals' prediction
    /// (`d ln z / du = -(n . r_u) / (n . r)`) by more than `max_jump * (1 + |predicted|)` once both
    /// are scaled to pixels by the focal length (a depth discontinuity, judged as
    /// [`crate::DepthMap::mesh`] judges it for a height map).
    pub fn mesh(
        &self,
        width: usize,
        height: usize,
        depth: &[f32],
        normals: &[f32],
        max_jump: f64,
    ) -> Mesh {
        let (w, h) = (width, height);
        let mut index = vec![u32::MAX; w * h];
        let mut m = Mesh::default();
        let r_u = self.ray(1.0, 0.0) - self.ray(0.0, 0.0);
        let r_v = self.ray(0.0, 1.0) - self.ray(0.0, 0.0);
        let focal = 0.5 * (self.fx + self.fy);
        let normal = |i: usize| -> Option<DVec3> {
            let v = DVec3::from_array([0, 1, 2].map(|c| normals[3 * i + c] as f64));
            (v.is_finite() && v.length() > 0.0).then(|| v.normalize())
        };
        // The normal's log-depth slopes (along u, along v) at pixel i.
        let slope = |i: usize| -> Option<(f64, f64)> {
            let n = normal(i)?;
            let r = self.ray((i % w) as f64, (i / w) as f64);
            let nr = n.dot(r).min(-MIN_FACING * r.length());
            Some((-n.dot(r_u) / nr, -n.dot(r_v) / nr))
        };
        for i in 0..w * h {
            let d = depth[i];
            if let (true, Some(n)) = (d.is_finite() && d > 0.0, normal(i)) {
                index[i] = m.positions.len() as u32;
                let (r, q) = (i / w, i % w);
                let p = self.point(q as f64, r as f64, d as f64);
                m.positions.push(p.as_vec3().to_array());
                m.normals.push(n.as_vec3().to_array());
                m.pixels.push([q as u32, r as u32]);
            }
        }
        let log_depth = |i: usize| (depth[i] as f64).ln();
        let continuous = |a, b| continuous_edge(w, a, b, &slope, &log_depth, focal, max_jump);
        triangulate_grid(w, h, &index, continuous, &mut m);
        m
    }

    /// Heights in pixel spacings for a picture of a perspective depth map: `-f ln z` (f the mean
    /// focal length), whose slopes are the surface's in pixel units where the rays are near the
    /// axis, so the integrate job's picture shades it as it shades a height map.
    pub fn picture_heights(&self, depth: &[f32]) -> Vec<f32> {
        let focal = 0.5 * (self.fx + self.fy);
        depth
            .iter()
            .map(|&d| {
                if d.is_finite() && d > 0.0 {
                    (-focal * (d as f64).ln()) as f32
                } else {
                    f32::NAN
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::IntegrateParams;

    /// A sphere of radius 1 at depth 6 seen by a 64 x 48 camera: its depth map, normals and the
    /// true surface point of each pixel (NaN where the ray misses it).
    fn sphere() -> (Pinhole, usize, usize, Vec<f32>, Vec<f32>) {
        let (w, h) = (64, 48);
        let cam = Pinhole::centred(w, h, 25.0);
        let c = DVec3::new(0.2, -0.1, -6.0);
        let mut depth = vec![f32::NAN; w * h];
        let mut normals = vec![f32::NAN; 3 * w * h];
        for i in 0..w * h {
            let d = cam.ray((i % w) as f64, (i / w) as f64).normalize();
            // |t d - c| = 1: t^2 - 2 t (d.c) + |c|^2 - 1 = 0, the nearer root.
            let b = d.dot(c);
            let disc = b * b - c.length_squared() + 1.0;
            if disc <= 0.0 {
                continue;
            }
            let p = d * (b - disc.sqrt());
            let n = (p - c).normalize();
            if n.dot(-d) < 0.1 {
                continue;
            }
            depth[i] = -p.z as f32;
            normals[3 * i..3 * i + 3].copy_from_slice(&n.as_vec3().to_array());
        }
        (cam, w, h, depth, normals)
    }

    #[test]
    fn the_mesh_of_a_sphere_lies_on_it() {
        let (cam, w, h, depth, normals) = sphere();
        let m = cam.mesh(w, h, &depth, &normals, 2.0);
        assert_eq!(
            m.positions.len(),
            depth.iter().filter(|d| d.is_finite()).count()
        );
        assert!(m.triangles.len() > m.positions.len());
        assert_eq!(m.dropped, 0);
        let c = DVec3::new(0.2, -0.1, -6.0);
        for (p, px) in m.positions.iter().zip(&m.pixels) {
            let p = DVec3::from_array(p.map(f64::from));
            assert!(((p - c).length() - 1.0).abs() < 1e-5);
            let (col, row) = cam.project(p).unwrap();
            assert!((col - px[0] as f64).abs() < 1e-3 && (row - px[1] as f64).abs() < 1e-3);
        }
        // Counter-clockwise seen from the camera: each face's normal points back at it.
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| DVec3::from_array(m.positions[i as usize].map(f64::from)));
            assert!((b - a).cross(c - a).dot(-a) > 0.0);
        }
    }

    #[test]
    fn integrated_normals_give_the_sphere_back_and_a_step_is_cut() {
        let (cam, w, h, depth, normals) = sphere();
        // Integrated from its normals alone and placed by the sphere's centre, 6 away.
        let start: Vec<f32> = depth
            .iter()
            .map(|d| if d.is_finite() { 6.0 } else { f32::NAN })
            .collect();
        let params = IntegrateParams::default();
        let got = cam
            .integrate(w, h, &normals, None, &start, Some(6.0), &params)
            .unwrap()
            .depth;
        let errs: Vec<(f32, f32)> = got
            .iter()
            .zip(&depth)
            .enumerate()
            .filter(|(_, (_, d))| d.is_finite())
            .map(|(i, (g, d))| ((g - d).abs(), normals[3 * i + 2]))
            .collect();
        let mean = errs.iter().map(|e| e.0).sum::<f32>() / errs.len() as f32;
        let facing = errs
            .iter()
            .filter(|e| e.1 > 0.5)
            .map(|e| e.0)
            .fold(0.0f32, f32::max);
        // Within 1% of the sphere's size on average and 2% where it faces the camera; the
        // grazing rim, whose slopes the grid resolves least, is left out of the second.
        assert!(mean < 0.01, "mean depth error {mean}");
        assert!(
            facing < 0.02,
            "largest depth error facing the camera {facing}"
        );
        // The right half pushed back by a tenth: the triangles across the step are dropped.
        let stepped: Vec<f32> = depth
            .iter()
            .enumerate()
            .map(|(i, &d)| if i % w >= w / 2 { d + 0.1 } else { d })
            .collect();
        let m = cam.mesh(w, h, &stepped, &normals, 2.0);
        assert!(m.dropped > 0);
        let rows = depth
            .chunks_exact(w)
            .filter(|r| r[w / 2 - 1].is_finite() && r[w / 2].is_finite())
            .count();
        assert!(
            m.dropped >= rows,
            "{} dropped, {rows} rows cross the step",
            m.dropped
        );
    }
}
