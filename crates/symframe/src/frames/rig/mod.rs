//! The light rig: light directions, their halfway vectors, the Delaunay triangulation of the
//! halfway vectors on the disc, and a point-location grid. Built once per rig, shared by every
//! pixel (the view is the same for every pixel of an orthographic camera).

use glam::{DMat3, DVec2, DVec3};

use crate::error::{Error, Result};
use crate::geometry::halfway_from_light;

mod grid;
mod locate;
mod walk;

pub(crate) use grid::Coverage;
pub(crate) use locate::Location;
use locate::{triangulate, LocateGrid, Triangle};
pub(crate) use walk::FastLocator;

/// Options for building a rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigOptions {
    /// Lights with `theta_d = angle(l, h) >= theta_d_max` are dropped (degrees; default 65).
    pub theta_d_max_deg: f64,
}

impl Default for RigOptions {
    fn default() -> Self {
        Self {
            theta_d_max_deg: 65.0,
        }
    }
}

/// The light rig as the estimator uses it: the lights inside the cone and everything derived
/// from their halfway vectors, built once by [`Rig::new`] and read through its accessors.
#[derive(Debug, Clone)]
pub struct Rig {
    /// Used lights (inside the cone), camera frame, unit length.
    lights_in_camera: Vec<DVec3>,
    /// Halfway vector of each used light, camera frame.
    halfway_in_camera: Vec<DVec3>,
    /// For each used light, its index in the input light list (and so in the stack).
    input_index: Vec<usize>,
    /// Number of lights given.
    n_input: usize,
    /// The cone half-angle in halfway space, degrees.
    theta_d_max_deg: f64,
    /// `cos(theta_d_max)`: a halfway vector is inside the cone when `h.z > cos_theta_d_max`.
    cos_theta_d_max: f64,
    triangles: Vec<Triangle>,
    grid: LocateGrid,
    /// Point location in single precision for the fast path.
    fast: FastLocator,
    /// Which halfway vectors lie well inside the sampled region: the symmetry domains' edge.
    coverage: Coverage,
    /// The order the fast objective visits the lights in (rig indices): the Morton order
    /// permuted by bit-reversed rank (a van der Corput sequence over the Morton curve), so that
    /// every prefix of it is a subset spread evenly over the cone, and a coarse evaluation over
    /// any number of lights is a prefix of the full one.
    query_order: Vec<u32>,
    /// The halfway vectors' coordinates in [`Rig::query_order`], single precision: the fast
    /// objective's layout of a pixel without invalid samples.
    query_halfways: [Vec<f32>; 3],
    /// Median angle between neighbouring halfway vectors (radians).
    halfway_spacing: f64,
    /// The triangulation's edges (rig light indices, each once).
    halfway_edges: Vec<[u32; 2]>,
}

/// The triangulation's edges, each once (smaller index first).
fn edges_of(triangles: &[Triangle]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = triangles
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.vertices;
            [[a, b], [b, c], [c, a]].map(|[x, y]| [x.min(y), x.max(y)])
        })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// The median angle of the triangulation's edges between halfway vectors (radians).
fn median_edge(triangles: &[Triangle], halfways: &[DVec3]) -> f64 {
    let mut edges: Vec<f64> = triangles
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.vertices.map(|v| halfways[v as usize]);
            [a.angle_between(b), b.angle_between(c), c.angle_between(a)]
        })
        .collect();
    if edges.is_empty() {
        return 0.0;
    }
    let k = edges.len() / 2;
    *edges.select_nth_unstable_by(k, f64::total_cmp).1
}

/// Indices `0..n` ordered by their bit-reversed value: every prefix spreads evenly over
/// `0..n` (for `n` a power of two, a prefix of `2^k` is every `n / 2^k`-th index).
fn bit_reversed_order(n: usize) -> Vec<u32> {
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.sort_by_key(|i| i.reverse_bits());
    order
}

impl Rig {
    /// Builds the rig from light directions in the camera frame (need not be unit length).
    ///
    /// Lights outside the cone are dropped (see [`Rig::n_dropped`]); a zero or non-finite light
    /// is an error, as is a rig with fewer than three lights inside the cone.
    pub fn new(lights: &[DVec3], options: RigOptions) -> Result<Self> {
        if lights.is_empty() {
            return Err(Error::NoLights);
        }
        let theta = options.theta_d_max_deg;
        if !(theta > 0.0 && theta <= 90.0) {
            return Err(Error::BadParameter(format!(
                "theta_d_max must be in (0, 90] degrees, got {theta}"
            )));
        }
        let cos_theta_d_max = theta.to_radians().cos();
        let mut lights_in_camera = Vec::new();
        let mut halfway_in_camera = Vec::new();
        let mut input_index = Vec::new();
        for (index, &l) in lights.iter().enumerate() {
            let l = l.try_normalize().ok_or(Error::BadLight { index })?;
            let Some(h) = halfway_from_light(l) else {
                continue;
            };
            // theta_d = angle(v, h); strictly inside the cone.
            if h.z > cos_theta_d_max {
                lights_in_camera.push(l);
                halfway_in_camera.push(h);
                input_index.push(index);
            }
        }
        // Spatially coherent order (Morton code on the disc): the objective visits the lights in
        // this order and looks up their reflections, which are then close in memory too.
        let mut order: Vec<usize> = (0..lights_in_camera.len()).collect();
        order.sort_by_key(|&i| morton(halfway_in_camera[i]));
        let lights_in_camera: Vec<DVec3> = order.iter().map(|&i| lights_in_camera[i]).collect();
        let halfway_in_camera: Vec<DVec3> = order.iter().map(|&i| halfway_in_camera[i]).collect();
        let input_index: Vec<usize> = order.iter().map(|&i| input_index[i]).collect();
        if lights_in_camera.is_empty() {
            return Err(Error::AllLightsOutsideCone {
                n_lights: lights.len(),
                theta_d_max_deg: theta,
            });
        }
        if lights_in_camera.len() < 3 {
            return Err(Error::TooFewLights {
                used: lights_in_camera.len(),
            });
        }
        let triangles = triangulate(&halfway_in_camera)?;
        let grid = LocateGrid::new(&triangles, &halfway_in_camera);
        let fast = FastLocator::new(&triangles, &grid, theta);
        // A node is inside where a candidate triangle holds it. The grid's nodes are visited
        // row by row, so the triangle that held the node before is tried first.
        let mut last = None;
        let coverage = Coverage::new(
            |h| {
                let candidates = grid.candidates(DVec2::new(h.x, h.y));
                let holds = |t: u32| triangles[t as usize].weights(h).is_some();
                if last.is_some_and(|t| candidates.contains(&t) && holds(t)) {
                    return true;
                }
                let found = candidates
                    .iter()
                    .copied()
                    .find(|&t| Some(t) != last && holds(t));
                last = found.or(last);
                found.is_some()
            },
            theta,
        );
        let query_order = bit_reversed_order(lights_in_camera.len());
        let query_halfways = [0, 1, 2].map(|c| {
            query_order
                .iter()
                .map(|&j| halfway_in_camera[j as usize][c] as f32)
                .collect()
        });
        let halfway_spacing = median_edge(&triangles, &halfway_in_camera);
        let halfway_edges = edges_of(&triangles);
        Ok(Self {
            lights_in_camera,
            halfway_in_camera,
            input_index,
            n_input: lights.len(),
            theta_d_max_deg: theta,
            cos_theta_d_max,
            triangles,
            grid,
            fast,
            coverage,
            query_order,
            query_halfways,
            halfway_spacing,
            halfway_edges,
        })
    }

    /// The edges of the triangulation of the halfway vectors (rig light indices, each edge
    /// once): which lights are neighbours.
    pub fn halfway_edges(&self) -> &[[u32; 2]] {
        &self.halfway_edges
    }

    /// The median angle between neighbouring halfway vectors (radians, along the edges of the
    /// triangulation): how finely the rig samples a slice.
    #[inline]
    pub fn halfway_spacing(&self) -> f64 {
        self.halfway_spacing
    }

    /// Used lights (inside the cone), camera frame, unit length, in rig order.
    #[inline]
    pub fn lights_in_camera(&self) -> &[DVec3] {
        &self.lights_in_camera
    }

    /// Halfway vector of each used light, camera frame, in rig order.
    #[inline]
    pub fn halfway_in_camera(&self) -> &[DVec3] {
        &self.halfway_in_camera
    }

    /// For each used light, its index in the input light list (and so in the stack).
    #[inline]
    pub fn input_index(&self) -> &[usize] {
        &self.input_index
    }

    /// Number of lights given.
    #[inline]
    pub fn n_input(&self) -> usize {
        self.n_input
    }

    /// The cone half-angle in halfway space, degrees.
    #[inline]
    pub fn theta_d_max_deg(&self) -> f64 {
        self.theta_d_max_deg
    }

    /// `cos(theta_d_max)`: a halfway vector is inside the cone when `h.z > cos_theta_d_max`.
    #[inline]
    pub fn cos_theta_d_max(&self) -> f64 {
        self.cos_theta_d_max
    }

    /// Point location in single precision for the fast path.
    #[inline]
    pub(crate) fn fast(&self) -> &FastLocator {
        &self.fast
    }

    /// Which halfway vectors lie well inside the sampled region: the symmetry domains' edge.
    #[inline]
    pub(crate) fn coverage(&self) -> &Coverage {
        &self.coverage
    }

    /// The order the fast objective visits the lights in (rig indices): the Morton order
    /// permuted by bit-reversed rank, so that every prefix of it is a subset spread evenly over
    /// the cone, and a coarse evaluation over any number of lights is a prefix of the full one.
    #[inline]
    pub fn query_order(&self) -> &[u32] {
        &self.query_order
    }

    /// The halfway vectors' x, y and z in [`Rig::query_order`], single precision.
    #[inline]
    pub(crate) fn query_halfways(&self) -> [&[f32]; 3] {
        let [x, y, z] = &self.query_halfways;
        [x, y, z]
    }

    /// Number of lights used (inside the cone).
    pub fn n_used(&self) -> usize {
        self.lights_in_camera.len()
    }

    /// Number of input lights dropped (outside the cone, or pointing straight away from the view).
    pub fn n_dropped(&self) -> usize {
        self.n_input - self.n_used()
    }

    /// Number of triangles of the halfway-vector triangulation.
    pub fn n_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// Whether a halfway vector's `Coverage` cell lies wholly inside the sampled region. Both
    /// paths' symmetry domains require it of every reflected halfway vector.
    #[inline]
    pub fn covered(&self, halfway: DVec3) -> bool {
        let c = &self.coverage;
        c.grid.cell_of(halfway).is_some_and(|cell| c.covered[cell])
    }

    /// Whether a halfway vector lies inside the measured cone.
    #[inline]
    pub fn in_cone(&self, halfway: DVec3) -> bool {
        halfway.z > self.cos_theta_d_max
    }

    /// Locates a unit halfway vector in the triangulation and returns its spherical barycentric
    /// weights; `None` outside the sampled region (the spherical triangles' union).
    #[inline]
    pub(crate) fn locate(&self, halfway: DVec3) -> Option<Location> {
        self.grid
            .candidates(DVec2::new(halfway.x, halfway.y))
            .iter()
            .find_map(|&t| self.triangles[t as usize].weights(halfway))
    }

    /// The triangulation as [`Rig::locate`] reads it: per triangle, its corners (rig light
    /// indices) and the inverse of the matrix whose columns are their halfway vectors (the
    /// unnormalised spherical barycentric weights of `h` are its rows dotted with `h`).
    pub(crate) fn triangles(&self) -> impl Iterator<Item = ([u32; 3], DMat3)> + '_ {
        self.triangles
            .iter()
            .map(|t| (t.vertices, t.spherical_inverse))
    }

    /// The same lookup as [`Rig::locate`] by testing every triangle: the reference that tests
    /// check the grid against.
    #[cfg(test)]
    pub(crate) fn locate_by_scan(&self, halfway: DVec3) -> Option<Location> {
        self.triangles.iter().find_map(|tri| tri.weights(halfway))
    }
}

/// Morton (Z-order) code of a halfway vector's disc position, 16 bits per axis.
fn morton(h: DVec3) -> u64 {
    let q = |v: f64| (((v + 1.0) * 0.5).clamp(0.0, 1.0) * 65535.0) as u64;
    let spread = |mut x: u64| {
        x = (x | (x << 16)) & 0x0000_ffff_0000_ffff;
        x = (x | (x << 8)) & 0x00ff_00ff_00ff_00ff;
        x = (x | (x << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
        x = (x | (x << 2)) & 0x3333_3333_3333_3333;
        (x | (x << 1)) & 0x5555_5555_5555_5555
    };
    spread(q(h.x)) | (spread(q(h.y)) << 1)
}

/// `n` lights spread uniformly (Fibonacci spiral) over the directions within `2 * theta_d_max` of
/// the view, i.e. uniformly over the rig's light cone (docs/method.md, "Halfway vectors and the
/// light cone").
pub fn uniform_cone_lights(n: usize, theta_d_max_deg: f64) -> Vec<DVec3> {
    // A hair inside the cone so that no light sits exactly on its boundary.
    let max_angle = (2.0 * theta_d_max_deg).min(179.0).to_radians() * 0.999;
    let z_min = max_angle.cos();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (1.0 - z_min) * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lights_outside_the_cone_are_dropped_and_counted() {
        let mut lights = uniform_cone_lights(100, 65.0);
        lights.push(DVec3::new(0.0, 0.0, -1.0)); // straight behind: no halfway vector
        lights.push(DVec3::new(1.0, 0.0, -0.9)); // 132 degrees from view: outside
        let rig = Rig::new(&lights, RigOptions::default()).unwrap();
        assert_eq!(rig.n_used(), 100);
        let mut seen = rig.input_index.clone();
        seen.sort();
        assert_eq!(
            seen,
            (0..100).collect::<Vec<_>>(),
            "every used light maps back once"
        );
        for (l, &i) in rig.lights_in_camera.iter().zip(&rig.input_index) {
            assert!((*l - lights[i].normalize()).length() < 1e-12);
        }
        assert_eq!(rig.n_dropped(), 2);
        assert!(rig.halfway_in_camera.iter().all(|h| rig.in_cone(*h)));
    }

    /// The coverage (nodes visited from the cone's cached list, the triangle that held the
    /// node before tried first) is that of every node of the grid tested against all its
    /// candidates, on rigs of several sizes and cones.
    #[test]
    fn coverage_is_every_node_tested_against_its_candidates() {
        for (n, theta) in [(20, 65.0), (150, 65.0), (400, 40.0), (1512, 65.0)] {
            let options = RigOptions {
                theta_d_max_deg: theta,
            };
            let rig = Rig::new(&uniform_cone_lights(n, 70.0), options).unwrap();
            let grid = grid::StereoGrid::new(theta, rig.coverage.grid.size);
            let nodes = grid.size + 1;
            let cos_max = theta.to_radians().cos();
            let node: Vec<bool> = (0..nodes * nodes)
                .map(|k| {
                    let h = grid.point((k % nodes) as f64, (k / nodes) as f64);
                    h.z > cos_max
                        && rig
                            .grid
                            .candidates(DVec2::new(h.x, h.y))
                            .iter()
                            .any(|&t| rig.triangles[t as usize].weights(h).is_some())
                })
                .collect();
            let covered: Vec<bool> = (0..grid.size * grid.size)
                .map(|c| {
                    let k = (c / grid.size) * nodes + c % grid.size;
                    node[k] && node[k + 1] && node[k + nodes] && node[k + nodes + 1]
                })
                .collect();
            assert!(covered.iter().filter(|&&c| c).count() > 1000);
            assert_eq!(rig.coverage.covered, covered, "{n} lights, {theta} degrees");
        }
    }

    #[test]
    fn the_fast_walk_finds_the_triangles_and_weights_of_the_reference_lookup() {
        for n_lights in [20, 400, 1512] {
            let rig =
                Rig::new(&uniform_cone_lights(n_lights, 65.0), RigOptions::default()).unwrap();
            let f = &rig.fast;
            let (mut both, mut worst) = (0, 0.0f64);
            let mut s = 99u64;
            let mut rnd = || {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64
            };
            for _ in 0..20000 {
                let h = DVec3::new(rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0, rnd()).normalize();
                let h32 = h.as_vec3();
                let walked = f.walk(f.start_of(h32.to_array()), h32.to_array());
                match (rig.locate(h), walked) {
                    (Some(a), Some((t, w))) => {
                        both += 1;
                        let sum = w[0] + w[1] + w[2];
                        let b = f.triangles[t as usize].vertices;
                        // The same point interpolated (on a shared edge either triangle is right).
                        let pa: DVec3 = (0..3)
                            .map(|k| rig.halfway_in_camera[a.vertices[k] as usize] * a.weights[k])
                            .sum();
                        let pb: DVec3 = (0..3)
                            .map(|k| rig.halfway_in_camera[b[k] as usize] * (w[k] / sum) as f64)
                            .sum();
                        worst = worst.max((pa - pb).length());
                    }
                    (None, None) => {}
                    // Only within rounding of the hull may the two disagree.
                    (Some(a), None) => {
                        let wmin = a.weights.iter().copied().fold(1.0, f64::min);
                        assert!(wmin < 1e-5, "{n_lights} lights: {h} missed, {a:?}");
                    }
                    (None, Some((_, w))) => {
                        let wmin = w.iter().copied().fold(1.0, f32::min);
                        assert!(wmin > -1e-5, "{n_lights} lights: {h} found outside, {w:?}");
                    }
                }
            }
            assert!(both > 2000, "{both}");
            assert!(
                worst < 1e-5,
                "{n_lights} lights: interpolated points {worst} apart"
            );
        }
    }

    #[test]
    fn bad_rigs_are_errors() {
        assert_eq!(
            Rig::new(&[], RigOptions::default()).unwrap_err(),
            Error::NoLights
        );
        let bad = [DVec3::Z, DVec3::ZERO, DVec3::X];
        assert_eq!(
            Rig::new(&bad, RigOptions::default()).unwrap_err(),
            Error::BadLight { index: 1 }
        );
        let nan = [DVec3::Z, DVec3::new(f64::NAN, 0.0, 1.0)];
        assert!(matches!(
            Rig::new(&nan, RigOptions::default()),
            Err(Error::BadLight { index: 1 })
        ));
        let behind = [DVec3::new(0.1, 0.0, -1.0), DVec3::new(0.0, 0.1, -1.0)];
        assert!(matches!(
            Rig::new(&behind, RigOptions::default()),
            Err(Error::AllLightsOutsideCone { n_lights: 2, .. })
        ));
    }

    #[test]
    fn grid_location_agrees_with_a_scan_and_weights_are_exact_at_samples() {
        let lights = uniform_cone_lights(400, 65.0);
        let rig = Rig::new(&lights, RigOptions::default()).unwrap();
        // Exact at every sample: weight one on that light.
        for (i, &h) in rig.halfway_in_camera.iter().enumerate() {
            let loc = rig.locate(h).expect("a sample is inside the hull");
            let k = loc.vertices.iter().position(|&v| v as usize == i).unwrap();
            assert!((loc.weights[k] - 1.0).abs() < 1e-9, "{:?}", loc.weights);
        }
        // Random queries: same answer as scanning all triangles.
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut inside = 0;
        let mut worst = 0.0f64;
        for _ in 0..5000 {
            let h = DVec3::new(rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0, rnd()).normalize();
            let a = rig.locate(h);
            let b = rig.locate_by_scan(h);
            assert_eq!(a.is_some(), b.is_some(), "{h}");
            if let (Some(a), Some(b)) = (a, b) {
                inside += 1;
                // On a shared edge either triangle is right; the weights must interpolate the
                // same point.
                let pa: DVec3 = (0..3)
                    .map(|k| rig.halfway_in_camera[a.vertices[k] as usize] * a.weights[k])
                    .sum();
                let pb: DVec3 = (0..3)
                    .map(|k| rig.halfway_in_camera[b.vertices[k] as usize] * b.weights[k])
                    .sum();
                assert!((pa.normalize() - pb.normalize()).length() < 1e-9);
                assert!((pa.normalize() - h).length() < 1e-9);
                let wmin = a.weights.iter().copied().fold(1.0, f64::min);
                worst = worst.min(wmin);
            }
        }
        assert!(inside > 1000);
        assert!(worst > -1e-9, "most negative weight {worst}");
        // Far outside the cone: no data.
        assert!(rig
            .locate(DVec3::new(0.99, 0.0, 0.141).normalize())
            .is_none());
    }
}
