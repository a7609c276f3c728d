//! Exact point location in the rig's triangulation (the reference path): the spherical
//! triangles, their Delaunay triangulation on the disc and a bucket grid of candidates.

use glam::{DMat3, DVec2, DVec3};
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

use crate::error::{Error, Result};

/// One triangle of the halfway-vector triangulation with what a lookup needs, precomputed.
#[derive(Debug, Clone, Copy)]
pub(super) struct Triangle {
    /// Rig light indices of the three corners.
    pub(super) vertices: [u32; 3],
    /// Inverse of the 3x3 matrix whose columns are the corners' halfway vectors (spherical
    /// barycentric weights, Cabral et al. 1999: exact at the corners, linear on the sphere).
    pub(super) spherical_inverse: DMat3,
}

/// A located query: the triangle's corners (rig light indices) and their weights (sum 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Location {
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
pub(super) struct LocateGrid {
    min: DVec2,
    inv_cell: DVec2,
    cells: usize,
    /// CSR offsets into `triangles`, `cells * cells + 1` entries.
    start: Vec<u32>,
    triangles: Vec<u32>,
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

impl Triangle {
    /// Spherical barycentric weights of `h` when it lies inside this spherical triangle.
    ///
    /// The triangle is found on the sphere, not on the disc: a great-circle edge bulges past the
    /// planar edge, and a point inside a thin planar triangle at the hull can lie well outside
    /// the spherical one (some of its weights clearly negative).
    #[inline]
    pub(super) fn weights(&self, h: DVec3) -> Option<Location> {
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

/// Delaunay triangulation of the halfway vectors projected onto the disc.
pub(super) fn triangulate(halfway: &[DVec3]) -> Result<Vec<Triangle>> {
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
    pub(super) fn new(triangles: &[Triangle], halfway: &[DVec3]) -> Self {
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
    pub(super) fn candidates(&self, p: DVec2) -> &[u32] {
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
