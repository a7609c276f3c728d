//! Point location in single precision for the fast path: a walk across the triangulation
//! from a grid cell ([`FastLocator`]).

use glam::DVec2;

use super::grid::StereoGrid;
use super::locate::{LocateGrid, Triangle};

/// The triangulation in single precision with a walk for point location: the fast path's
/// lookups ([`crate::frames::objective::FastObjective`]). The same spherical triangles and
/// barycentric weights as [`Rig::locate`](super::Rig::locate), so the fast and reference paths
/// read the same slice; only the precision and the search differ.
///
/// A query starts at the triangle stored for its cell of a regular grid over the stereographic
/// projection of the cone, `s = (h.x, h.y) / (1 + h.z)`, and walks across the edge of its most
/// negative weight until no weight is negative (a visibility walk; the cells are a few times
/// smaller than the triangles, so most queries take one step). Hand-written: it is the method's
/// hot loop, and one 64-byte triangle per step keeps it in cache.
#[derive(Debug, Clone)]
pub(crate) struct FastLocator {
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
    pub(super) fn new(rig_triangles: &[Triangle], grid: &LocateGrid, theta_d_max_deg: f64) -> Self {
        let n = rig_triangles.len();
        // Neighbours through shared edges: each edge's sides, sorted by the edge (an edge with
        // two sides joins their triangles).
        let mut edges: Vec<((u32, u32), u32, usize)> = Vec::with_capacity(3 * n);
        for (t, tri) in rig_triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri.vertices[(k + 1) % 3], tri.vertices[(k + 2) % 3]);
                edges.push(((a.min(b), a.max(b)), t as u32, k));
            }
        }
        edges.sort_unstable();
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
        for sharing in edges.chunk_by(|a, b| a.0 == b.0) {
            if let [(_, t0, k0), (_, t1, k1)] = *sharing {
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
