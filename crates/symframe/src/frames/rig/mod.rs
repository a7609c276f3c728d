//! The light rig: light directions, their halfway vectors, the Delaunay triangulation of the
//! halfway vectors on the disc, and a point-location grid. Built once per rig, shared by every
//! pixel (the view is the same for every pixel of an orthographic camera).

use glam::{DMat3, DVec2, DVec3};
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

use crate::error::{Error, Result};
use crate::geometry::{from_stereographic, halfway_from_light};

/// One triangle of the halfway-vector triangulation with what a lookup needs, precomputed.
#[derive(Debug, Clone, Copy)]
struct Triangle {
    /// Rig light indices of the three corners.
    vertices: [u32; 3],
    /// Inverse of the 3x3 matrix whose columns are the corners' halfway vectors (spherical
    /// barycentric weights, Cabral et al. 1999: exact at the corners, linear on the sphere).
    spherical_inverse: DMat3,
}

/// A located query: the triangle's corners (rig light indices) and their weights (sum 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location {
    /// Rig light indices of the triangle's corners.
    pub vertices: [u32; 3],
    /// Interpolation weights of the corners.
    pub weights: [f64; 3],
}

/// Uniform bucket grid over the disc for point location: cell -> candidate triangles.
///
/// Hand-written rather than spade's own locate: spade's walk shares one atomic hint between
/// threads, and a flat grid with a few candidates per cell is faster in the per-pixel hot loop.
#[derive(Debug, Clone)]
struct LocateGrid {
    min: DVec2,
    inv_cell: DVec2,
    cells: usize,
    /// CSR offsets into `triangles`, `cells * cells + 1` entries.
    start: Vec<u32>,
    triangles: Vec<u32>,
}

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
/// from their halfway vectors.
#[derive(Debug, Clone)]
pub struct Rig {
    /// Used lights (inside the cone), camera frame, unit length.
    pub lights_in_camera: Vec<DVec3>,
    /// Halfway vector of each used light, camera frame.
    pub halfway_in_camera: Vec<DVec3>,
    /// For each used light, its index in the input light list (and so in the stack).
    pub input_index: Vec<usize>,
    /// Number of lights given.
    pub n_input: usize,
    /// The cone half-angle in halfway space, degrees.
    pub theta_d_max_deg: f64,
    /// `cos(theta_d_max)`: a halfway vector is inside the cone when `h.z > cos_theta_d_max`.
    pub cos_theta_d_max: f64,
    triangles: Vec<Triangle>,
    grid: LocateGrid,
    /// Point location in single precision for the fast path.
    pub fast: FastLocator,
    /// Which halfway vectors lie well inside the sampled region: the symmetry domains' edge.
    pub coverage: Coverage,
    /// The order the fast objective visits the lights in (rig indices): the Morton order
    /// permuted by bit-reversed rank (a van der Corput sequence over the Morton curve), so that
    /// every prefix of it is a subset spread evenly over the cone, and a coarse evaluation over
    /// any number of lights is a prefix of the full one.
    pub query_order: Vec<u32>,
}

/// Indices `0..n` ordered by their bit-reversed value: every prefix spreads evenly over
/// `0..n` (for `n` a power of two, a prefix of `2^k` is every `n / 2^k`-th index).
fn bit_reversed_order(n: usize) -> Vec<u32> {
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.sort_by_key(|i| i.reverse_bits());
    order
}

/// A regular `size x size` grid of cells over the stereographic projection of the cone,
/// `s = (h.x, h.y) / (1 + h.z)`, slightly wider than the cone: the cells of [`Coverage`] and
/// [`FastLocator`].
#[derive(Debug, Clone, Copy)]
pub struct StereoGrid {
    /// Cells per side.
    pub(crate) size: usize,
    /// Cells per stereographic unit.
    pub(crate) scale: f32,
    /// Stereographic coordinate of the grid's corner times `scale`, negated.
    pub(crate) offset: f32,
    /// Half the grid's side and a cell's side, stereographic units (double precision).
    extent: f64,
    step: f64,
}

impl StereoGrid {
    fn new(theta_d_max_deg: f64, size: usize) -> Self {
        let extent = (theta_d_max_deg.to_radians() / 2.0).tan() * 1.001;
        let step = 2.0 * extent / size as f64;
        Self {
            size,
            scale: (1.0 / step) as f32,
            offset: (extent / step) as f32,
            extent,
            step,
        }
    }

    /// The unit vector at grid coordinates `(x, y)` (in cells from the corner).
    fn point(&self, x: f64, y: f64) -> DVec3 {
        from_stereographic(DVec2::new(
            -self.extent + x * self.step,
            -self.extent + y * self.step,
        ))
    }

    /// The cell of a unit vector, clamped to the grid: what the fast kernel computes for every
    /// light, so it stays branch-free and vectorises.
    #[inline(always)]
    pub(crate) fn cell_clamped(&self, x: f32, y: f32, z: f32) -> u32 {
        let last = (self.size - 1) as f32;
        let k = self.scale / (1.0 + z.max(0.0));
        // `max` then `min` (not `clamp`): the result is never NaN.
        let gx = (x * k + self.offset).max(0.0).min(last);
        let gy = (y * k + self.offset).max(0.0).min(last);
        // SAFETY: gx and gy are finite and in [0, size - 1], so they fit an i32. The unchecked
        // conversion is what lets the kernel's geometry loop vectorise (the saturating `as`
        // does not).
        let (ix, iy) = unsafe { (gx.to_int_unchecked::<i32>(), gy.to_int_unchecked::<i32>()) };
        (iy * self.size as i32 + ix) as u32
    }

    /// The cell of a unit vector in double precision, `None` outside the grid.
    #[inline]
    fn cell_of(&self, h: DVec3) -> Option<usize> {
        let k = self.scale as f64 / (1.0 + h.z);
        let (gx, gy) = (h.x * k + self.offset as f64, h.y * k + self.offset as f64);
        if !(gx >= 0.0 && gy >= 0.0) {
            return None;
        }
        let (ix, iy) = (gx as usize, gy as usize);
        (ix < self.size && iy < self.size).then_some(iy * self.size + ix)
    }
}

/// The edge of the symmetry domains: a regular grid of cells over the stereographic projection
/// of the cone, each marked covered when its four corners lie inside the sampled region.
/// A reflected halfway vector counts only in a covered cell (both paths, [`Rig::covered`]):
/// the domains stop about one cell (0.5 to 0.9 degrees) short of the region's edge, where
/// the hull's long thin triangles interpolate worst, and a normal just beyond the rig's reach
/// is not propped up by the last sliver of data.
#[derive(Debug, Clone)]
pub struct Coverage {
    /// The cells.
    pub(crate) grid: StereoGrid,
    /// Per cell (row-major): whether it is covered.
    pub(crate) covered: Vec<bool>,
}

/// Cells per side of the [`Coverage`] grid.
const COVERAGE_SIZE: usize = 159;

impl Coverage {
    fn new(inside: impl Fn(DVec3) -> bool, theta_d_max_deg: f64) -> Self {
        let grid = StereoGrid::new(theta_d_max_deg, COVERAGE_SIZE);
        let nodes = COVERAGE_SIZE + 1;
        let cos_max = theta_d_max_deg.to_radians().cos();
        let node: Vec<bool> = (0..nodes * nodes)
            .map(|k| {
                let h = grid.point((k % nodes) as f64, (k / nodes) as f64);
                h.z > cos_max && inside(h)
            })
            .collect();
        let covered = (0..COVERAGE_SIZE * COVERAGE_SIZE)
            .map(|c| {
                let (i, j) = (c % COVERAGE_SIZE, c / COVERAGE_SIZE);
                let k = j * nodes + i;
                node[k] && node[k + 1] && node[k + nodes] && node[k + nodes + 1]
            })
            .collect();
        Self { grid, covered }
    }
}

/// The triangulation in single precision with a walk for point location: the fast path's
/// lookups ([`crate::frames::objective::FastObjective`]). The same spherical triangles and barycentric
/// weights as [`Rig::locate`], so the fast and reference paths read the same slice; only the
/// precision and the search differ.
///
/// A query starts at the triangle stored for its cell of a regular grid over the stereographic
/// projection of the cone, `s = (h.x, h.y) / (1 + h.z)`, and walks across the edge of its most
/// negative weight until no weight is negative (a visibility walk; the cells are a few times
/// smaller than the triangles, so most queries take one step). Hand-written: it is the method's
/// hot loop, and one 64-byte triangle per step keeps it in cache.
#[derive(Debug, Clone)]
pub struct FastLocator {
    /// The cells.
    pub(crate) grid: StereoGrid,
    /// Per cell: the triangle holding its centre, or the nearest one, or the sentinel (the last
    /// triangle, outside everything) where none is near.
    pub(crate) start: Vec<u32>,
    /// The triangles, then the sentinel: a triangle outside everything (all weights `-h.z`,
    /// negative over the cone) whose neighbours are itself.
    pub(crate) triangles: Vec<WalkTriangle>,
    /// The sentinel's index (the last).
    pub(crate) sentinel: u32,
}

/// One triangle as the walk reads it: a cache line.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
pub(crate) struct WalkTriangle {
    /// Rows of the inverse corner matrix: weight `k` is `rows[k] . h` (unnormalised).
    pub(crate) rows: [[f32; 3]; 3],
    /// Rig light indices of the corners.
    pub(crate) vertices: [u32; 3],
    /// The triangle across the edge opposite each corner (the sentinel on the hull).
    pub(crate) neighbours: [u32; 3],
}

/// A weight this far below zero still counts as inside (unnormalised weights are ~1): points
/// on an edge belong to both triangles, and single-precision rounding must not bounce the walk.
const WALK_EPS: f32 = 1e-6;

/// Steps after which a walk gives up (no data): never reached on the rigs tested, where a walk
/// takes at most a few steps.
const MAX_WALK: usize = 64;

/// Triangles per grid cell, about: the grid side is `sqrt(triangles) * CELLS_PER_TRIANGLE_SIDE`.
const CELLS_PER_TRIANGLE_SIDE: f64 = 4.0;

impl FastLocator {
    fn new(rig_triangles: &[Triangle], grid: &LocateGrid, theta_d_max_deg: f64) -> Self {
        let n = rig_triangles.len();
        // Neighbours through shared edges.
        let mut edges: std::collections::HashMap<(u32, u32), Vec<(u32, usize)>> =
            std::collections::HashMap::with_capacity(3 * n);
        for (t, tri) in rig_triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri.vertices[(k + 1) % 3], tri.vertices[(k + 2) % 3]);
                edges
                    .entry((a.min(b), a.max(b)))
                    .or_default()
                    .push((t as u32, k));
            }
        }
        let sentinel = n as u32;
        let mut triangles: Vec<WalkTriangle> = rig_triangles
            .iter()
            .map(|tri| {
                let m = tri.spherical_inverse.transpose();
                WalkTriangle {
                    rows: [m.x_axis, m.y_axis, m.z_axis].map(|r| r.as_vec3().to_array()),
                    vertices: tri.vertices,
                    neighbours: [sentinel; 3],
                }
            })
            .collect();
        for sharing in edges.values() {
            if let [(t0, k0), (t1, k1)] = sharing[..] {
                triangles[t0 as usize].neighbours[k0] = t1;
                triangles[t1 as usize].neighbours[k1] = t0;
            }
        }
        let size = (((n as f64).sqrt() * CELLS_PER_TRIANGLE_SIDE).ceil() as usize).clamp(8, 1024);
        let cells = StereoGrid::new(theta_d_max_deg, size);
        triangles.push(WalkTriangle {
            rows: [[0.0, 0.0, -1.0]; 3],
            vertices: [0; 3],
            neighbours: [sentinel; 3],
        });
        let mut start = vec![sentinel; size * size];
        for j in 0..size {
            for i in 0..size {
                let h = cells.point(i as f64 + 0.5, j as f64 + 0.5);
                // The triangle holding the centre, else the candidate it is least outside of.
                start[j * size + i] = grid
                    .candidates(DVec2::new(h.x, h.y))
                    .iter()
                    .map(|&t| {
                        let w = rig_triangles[t as usize].spherical_inverse * h;
                        (t, w.min_element())
                    })
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .map_or(sentinel, |(t, _)| t);
            }
        }
        Self {
            grid: cells,
            start,
            triangles,
            sentinel,
        }
    }

    /// The walk's start for a unit vector: the triangle of its cell.
    #[inline(always)]
    pub(crate) fn start_of(&self, h: [f32; 3]) -> u32 {
        self.start[self.grid.cell_clamped(h[0], h[1], h[2]) as usize]
    }

    /// The unnormalised spherical barycentric weights of `h` in triangle `t`.
    #[inline(always)]
    pub(crate) fn weights(&self, t: u32, h: [f32; 3]) -> [f32; 3] {
        self.triangles[t as usize]
            .rows
            .map(|r| r[0] * h[0] + r[1] * h[1] + r[2] * h[2])
    }

    /// Whether weights place a point inside their triangle.
    #[inline(always)]
    pub(crate) fn inside(w: [f32; 3]) -> bool {
        w[0].min(w[1]).min(w[2]) >= -WALK_EPS
    }

    /// Walks from triangle `t` to the one holding the unit vector `h`: that triangle and its
    /// weights, `None` outside the sampled region.
    #[inline]
    pub(crate) fn walk(&self, mut t: u32, h: [f32; 3]) -> Option<(u32, [f32; 3])> {
        for _ in 0..MAX_WALK {
            if t == self.sentinel {
                return None;
            }
            let w = self.weights(t, h);
            // Across the edge of the most negative weight, unless none is negative.
            let k = if w[0] <= w[1] && w[0] <= w[2] {
                0
            } else if w[1] <= w[2] {
                1
            } else {
                2
            };
            if w[k] >= -WALK_EPS {
                return Some((t, w));
            }
            t = self.triangles[t as usize].neighbours[k];
        }
        None
    }
}

#[derive(Debug, Clone, Copy)]
struct DiscVertex {
    position: Point2<f64>,
    index: u32,
}

impl HasPosition for DiscVertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.position
    }
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
        let coverage = Coverage::new(
            |h| {
                grid.candidates(DVec2::new(h.x, h.y))
                    .iter()
                    .any(|&t| triangles[t as usize].weights(h).is_some())
            },
            theta,
        );
        let query_order = bit_reversed_order(lights_in_camera.len());
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
        })
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

    /// Whether a halfway vector's [`Coverage`] cell lies wholly inside the sampled region. Both
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
    pub fn locate(&self, halfway: DVec3) -> Option<Location> {
        self.grid
            .candidates(DVec2::new(halfway.x, halfway.y))
            .iter()
            .find_map(|&t| self.triangles[t as usize].weights(halfway))
    }

    /// The same lookup as [`Rig::locate`] by testing every triangle: the reference that tests
    /// check the grid against.
    pub fn locate_by_scan(&self, halfway: DVec3) -> Option<Location> {
        self.triangles.iter().find_map(|tri| tri.weights(halfway))
    }
}

impl Triangle {
    /// Spherical barycentric weights of `h` when it lies inside this spherical triangle.
    ///
    /// The triangle is found on the sphere, not on the disc: a great-circle edge bulges past the
    /// planar edge, and a point inside a thin planar triangle at the hull can lie well outside
    /// the spherical one (weights down to -0.12 were seen on a 400-light rig).
    #[inline]
    fn weights(&self, h: DVec3) -> Option<Location> {
        const EPS: f64 = -1e-10;
        let w = self.spherical_inverse * h;
        if w.x >= EPS && w.y >= EPS && w.z >= EPS {
            let s = w.x + w.y + w.z;
            Some(Location {
                vertices: self.vertices,
                weights: [w.x / s, w.y / s, w.z / s],
            })
        } else {
            None
        }
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

/// Delaunay triangulation of the halfway vectors projected onto the disc.
fn triangulate(halfway: &[DVec3]) -> Result<Vec<Triangle>> {
    let vertices: Vec<DiscVertex> = halfway
        .iter()
        .enumerate()
        .map(|(i, h)| DiscVertex {
            position: Point2::new(h.x, h.y),
            index: i as u32,
        })
        .collect();
    let dt = DelaunayTriangulation::<DiscVertex>::bulk_load(vertices).map_err(|e| {
        Error::BadParameter(format!("cannot triangulate the light directions: {e}"))
    })?;
    let mut triangles = Vec::with_capacity(dt.num_inner_faces());
    for face in dt.inner_faces() {
        let [a, b, c] = face.vertices().map(|v| v.data().index);
        let (pa, pb, pc) = (
            halfway[a as usize],
            halfway[b as usize],
            halfway[c as usize],
        );
        let m = DMat3::from_cols(pa, pb, pc);
        if m.determinant().abs() < 1e-14 {
            continue; // corners on one great circle: no area, never contains a query
        }
        triangles.push(Triangle {
            vertices: [a, b, c],
            spherical_inverse: m.inverse(),
        });
    }
    if triangles.is_empty() {
        return Err(Error::BadParameter(
            "the light directions inside the cone are collinear on the disc: no triangle".into(),
        ));
    }
    Ok(triangles)
}

impl LocateGrid {
    fn new(triangles: &[Triangle], halfway: &[DVec3]) -> Self {
        // Each triangle's disc bounding box, padded: a great-circle edge of chord length L
        // bulges at most L^2 / 8 past its chord.
        let boxes: Vec<(DVec2, DVec2)> = triangles
            .iter()
            .map(|tri| {
                let p3 = tri.vertices.map(|v| halfway[v as usize]);
                let pts = p3.map(|p| DVec2::new(p.x, p.y));
                let longest = (p3[0] - p3[1])
                    .length_squared()
                    .max((p3[1] - p3[2]).length_squared())
                    .max((p3[2] - p3[0]).length_squared());
                let pad = DVec2::splat(longest / 8.0 + 1e-9);
                (
                    pts[0].min(pts[1]).min(pts[2]) - pad,
                    pts[0].max(pts[1]).max(pts[2]) + pad,
                )
            })
            .collect();
        let mut min = DVec2::splat(f64::INFINITY);
        let mut max = DVec2::splat(f64::NEG_INFINITY);
        for (lo, hi) in &boxes {
            min = min.min(*lo);
            max = max.max(*hi);
        }
        // About one triangle per cell keeps the candidate lists short.
        let cells = ((triangles.len() as f64).sqrt().ceil() as usize).clamp(1, 1024);
        let extent = (max - min).max(DVec2::splat(1e-12));
        let inv_cell = DVec2::splat(cells as f64) / extent;
        let cell_range = |lo: f64, hi: f64, m: f64, inv: f64| {
            let a = (((lo - m) * inv).floor().max(0.0) as usize).min(cells - 1);
            let b = (((hi - m) * inv).floor().max(0.0) as usize).min(cells - 1);
            a..=b
        };
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); cells * cells];
        for (t, (lo, hi)) in boxes.iter().enumerate() {
            for cy in cell_range(lo.y, hi.y, min.y, inv_cell.y) {
                for cx in cell_range(lo.x, hi.x, min.x, inv_cell.x) {
                    lists[cy * cells + cx].push(t as u32);
                }
            }
        }
        let mut start = Vec::with_capacity(cells * cells + 1);
        let mut flat = Vec::new();
        start.push(0);
        for l in &lists {
            flat.extend_from_slice(l);
            start.push(flat.len() as u32);
        }
        Self {
            min,
            inv_cell,
            cells,
            start,
            triangles: flat,
        }
    }

    /// The triangles whose padded boxes overlap the cell of a disc point (none outside).
    #[inline]
    fn candidates(&self, p: DVec2) -> &[u32] {
        match self.cell_of(p) {
            Some(cell) => &self.triangles[self.start[cell] as usize..self.start[cell + 1] as usize],
            None => &[],
        }
    }

    #[inline]
    fn cell_of(&self, p: DVec2) -> Option<usize> {
        let c = (p - self.min) * self.inv_cell;
        let n = self.cells as f64;
        if !(c.x >= -1e-6 && c.y >= -1e-6 && c.x <= n + 1e-6 && c.y <= n + 1e-6) {
            return None;
        }
        let cx = (c.x.max(0.0) as usize).min(self.cells - 1);
        let cy = (c.y.max(0.0) as usize).min(self.cells - 1);
        Some(cy * self.cells + cx)
    }
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
