//! Regular grids over the stereographic projection of the cone: [`StereoGrid`] and the
//! symmetry domains' edge, [`Coverage`].

use std::sync::{Arc, Mutex};

use glam::{DVec2, DVec3};

use crate::geometry::from_stereographic;

/// A regular `size x size` grid of cells over the stereographic projection of the cone,
/// `s = (h.x, h.y) / (1 + h.z)`, slightly wider than the cone: the cells of [`Coverage`] and
/// [`FastLocator`](super::FastLocator).
#[derive(Debug, Clone, Copy)]
pub(crate) struct StereoGrid {
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
    pub(super) fn new(theta_d_max_deg: f64, size: usize) -> Self {
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
    pub(super) fn point(&self, x: f64, y: f64) -> DVec3 {
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
    pub(super) fn cell_of(&self, h: DVec3) -> Option<usize> {
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
/// A reflected halfway vector counts only in a covered cell (both paths,
/// [`Rig::covered`](super::Rig::covered)): the domains stop about one cell (0.5 to 0.9 degrees)
/// short of the region's edge, where the hull's long thin triangles interpolate worst, and a
/// normal just beyond the rig's reach is not propped up by the last sliver of data.
#[derive(Debug, Clone)]
pub(crate) struct Coverage {
    /// The cells.
    pub(crate) grid: StereoGrid,
    /// Per cell (row-major): whether it is covered.
    pub(crate) covered: Vec<bool>,
}

/// Cells per side of the [`Coverage`] grid.
const COVERAGE_SIZE: usize = 159;

/// Grid nodes: index (row-major) and unit vector.
type ConeNodes = Vec<(u32, DVec3)>;

/// The [`Coverage`] grid's nodes strictly inside the cone of `theta_d_max_deg` (index, unit
/// vector), row by row: the same for every rig of that cone, so computed once per cone (a
/// near-light estimate builds hundreds of rigs of one cone).
fn cone_nodes(theta_d_max_deg: f64) -> Arc<ConeNodes> {
    /// The cones seen (their angle's bits), at most [`CONES_KEPT`], the oldest dropped.
    static CONES: Mutex<Vec<(u64, Arc<ConeNodes>)>> = Mutex::new(Vec::new());
    const CONES_KEPT: usize = 4;
    let key = theta_d_max_deg.to_bits();
    let mut cones = CONES.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, v)) = cones.iter().find(|(k, _)| *k == key) {
        return v.clone();
    }
    let grid = StereoGrid::new(theta_d_max_deg, COVERAGE_SIZE);
    let nodes = COVERAGE_SIZE + 1;
    let cos_max = theta_d_max_deg.to_radians().cos();
    let inside: Arc<ConeNodes> = Arc::new(
        (0..nodes * nodes)
            .map(|k| (k as u32, grid.point((k % nodes) as f64, (k / nodes) as f64)))
            .filter(|(_, h)| h.z > cos_max)
            .collect(),
    );
    if cones.len() >= CONES_KEPT {
        cones.remove(0);
    }
    cones.push((key, inside.clone()));
    inside
}

impl Coverage {
    /// The coverage of the region where `inside` holds (within the cone), its nodes visited
    /// row by row.
    pub(super) fn new(mut inside: impl FnMut(DVec3) -> bool, theta_d_max_deg: f64) -> Self {
        let grid = StereoGrid::new(theta_d_max_deg, COVERAGE_SIZE);
        let nodes = COVERAGE_SIZE + 1;
        let mut node = vec![false; nodes * nodes];
        for &(k, h) in cone_nodes(theta_d_max_deg).iter() {
            node[k as usize] = inside(h);
        }
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
