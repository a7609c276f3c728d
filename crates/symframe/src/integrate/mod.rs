//! Normal integration: a height map (and a mesh) from a normal map, orthographic camera.
//!
//! Conventions: pixel `(col, row)`, row 0 at the top; the camera frame has x = right, y = up,
//! z = toward the camera. Heights are along +z in units of the pixel spacing, so a normal
//! `n = (nx, ny, nz)` asks for the slopes `dz/dcol = -nx / nz` and `dz/drow = +ny / nz` (rows
//! run down, against y).
//!
//! Both solvers minimise the same least-squares energy over one-sided differences (Cao et al.,
//! *Bilateral Normal Integration*, ECCV 2022, orthographic form), each term multiplied by `nz`
//! so that grazing normals (`nz -> 0`, infinite slopes) do not dominate:
//!
//! ```text
//! E(z) = sum_i c_i sum_{d in {u+, u-, v+, v-}} w_i^d (nz_i D_d z_i + s_d n_i)^2
//! ```
//!
//! with `c_i` the pixel's confidence weight, `D_d` the forward or backward difference toward a
//! neighbour inside the mask and `s_d n_i` the matching normal component.
//!
//! - [`Solver::Poisson`]: fixed weights 1/2 per side (1 where only one side is in the mask). One
//!   sparse linear solve: the normal equations are a weighted 5-point Laplacian, solved by
//!   conjugate gradients preconditioned with a multigrid V-cycle (red-black Gauss-Seidel
//!   smoothing, 2 x 2 aggregation with Galerkin coarse operators), warm-started coarse to fine
//!   (the map halved until it is small, each level's solution the next one's start): few
//!   iterations at full size (docs/capture.md, "Normal integration"); written here rather than
//!   taken from a sparse crate because the grid structure makes the operator five arrays and
//!   the multigrid preconditioner (which a general sparse solver would not give) is what makes
//!   it fast.
//!   Smooth everywhere: a depth jump is smeared into a slope.
//! - [`Solver::Bilateral`]: the weights of the two sides follow the current surface,
//!   `w^+ = sigmoid(k ((nz D_- z)^2 - (nz D_+ z)^2))`, `w^- = 1 - w^+`, re-solved
//!   (iteratively reweighted least squares, each solve warm-started) until the energy settles:
//!   across a depth discontinuity the side that jumps loses its weight, so the surface may
//!   break there (a jump is only found where the normals on both sides disagree with a
//!   continuous surface, e.g. a step whose height varies along it).
//!
//! Heights are defined up to one offset per connected region of the mask; each region's lowest
//! point is set to 0.

mod energy;
mod height_mesh;
mod multigrid;

pub use height_mesh::Mesh;
pub(crate) use height_mesh::{continuous_edge, triangulate_grid};

use crate::error::{Error, Result};
use crate::regions::{label_regions, OUTSIDE};
use energy::{Level, SideWeights};
use multigrid::Hierarchy;

/// Which solver [`DepthMap::integrate`] runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Solver {
    /// Least squares with fixed weights (a screened-free Poisson problem on the mask).
    Poisson,
    /// Bilateral normal integration (Cao et al. 2022): discontinuity-preserving.
    Bilateral {
        /// Sharpness of the side weights' sigmoid (the paper's k; 2 by default).
        k: f64,
        /// Reweighting iterations at most.
        max_iterations: usize,
        /// Stop when the energy's relative change falls below this.
        tolerance: f64,
    },
}

impl Solver {
    /// The bilateral solver with k = 10, up to 100 iterations, stopping when the energy changes
    /// by less than 1e-4. (The paper's k = 2 assumes depths in other units: with heights in
    /// pixels, started from the Poisson surface, k = 2 leaves a step of a few pixels smeared;
    /// k = 10 recovers both sides of it to 0.02 px RMS in the unit test.)
    pub fn bilateral() -> Self {
        Solver::Bilateral {
            k: 10.0,
            max_iterations: 100,
            tolerance: 1e-4,
        }
    }
}

/// Parameters of [`DepthMap::integrate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegrateParams {
    /// The solver.
    pub solver: Solver,
    /// Conjugate gradients stop when the residual's norm is below this fraction of the
    /// right-hand side's.
    pub cg_tolerance: f64,
    /// Conjugate-gradient iterations per linear solve at most.
    pub cg_max_iterations: usize,
    /// Confidence weights below this are raised to it (so a low-confidence pixel still joins
    /// its neighbours); 1 ignores the confidence.
    pub min_weight: f64,
}

impl Default for IntegrateParams {
    fn default() -> Self {
        Self {
            solver: Solver::Poisson,
            cg_tolerance: 1e-7,
            cg_max_iterations: 20_000,
            min_weight: 0.05,
        }
    }
}

/// A height map and how it was reached.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Heights toward the camera in pixel units, row-major, NaN outside the mask.
    pub depth: Vec<f32>,
    /// Conjugate-gradient iterations over all solves and levels.
    pub cg_iterations: usize,
    /// Bilateral reweighting iterations (0 for Poisson).
    pub reweight_iterations: usize,
    /// Final energy `E(z)` per pixel.
    pub energy: f64,
    /// Connected regions of the mask (each with its own offset).
    pub regions: usize,
    /// Pixels integrated.
    pub pixels: usize,
}

/// Solves the fixed-weight problem on `level`, warm-started from the solution of the level at
/// half the resolution while the map is larger than 64 pixels on its shorter side. Returns the
/// heights (pixel units of `level`) and the iterations spent.
fn poisson_pyramid(level: &Level, params: &IntegrateParams) -> (Vec<f64>, usize) {
    let mut z = vec![0.0; level.w * level.h];
    let mut iterations = 0;
    if level.w.min(level.h) > 64 {
        let coarse = level.halve();
        let (zc, it) = poisson_pyramid(&coarse, params);
        iterations += it;
        for (i, v) in z.iter_mut().enumerate() {
            let (r, q) = (i / level.w, i % level.w);
            // Heights are in pixel units: a coarse pixel is two fine ones.
            *v = 2.0 * zc[(r / 2) * coarse.w + q / 2];
        }
    }
    let sys = Hierarchy::new(level.system(&SideWeights::half(level.w * level.h)));
    let it = sys.solve(&mut z, params.cg_tolerance, params.cg_max_iterations);
    iterations += it;
    (z, iterations)
}

impl DepthMap {
    /// Integrates a normal map (`H x W x 3`, camera frame, unit vectors, NaN where there is no
    /// normal) into heights, weighted by `confidence` (`H x W`, values in [0, 1]) when given.
    pub fn integrate(
        width: usize,
        height: usize,
        normals: &[f32],
        confidence: Option<&[f32]>,
        params: &IntegrateParams,
    ) -> Result<DepthMap> {
        let n = width
            .checked_mul(height)
            .filter(|&n| n > 0)
            .ok_or_else(|| Error::BadParameter(format!("empty {width}x{height} normal map")))?;
        if normals.len() != 3 * n {
            return Err(Error::BadParameter(format!(
                "a {width}x{height} normal map needs {} values, got {}",
                3 * n,
                normals.len()
            )));
        }
        if let Some(c) = confidence {
            if c.len() != n {
                return Err(Error::BadParameter(format!(
                    "a {width}x{height} confidence map needs {n} values, got {}",
                    c.len()
                )));
            }
        }
        if !(params.cg_tolerance > 0.0 && params.cg_tolerance < 1.0) {
            return Err(Error::BadParameter(format!(
                "the solver tolerance must be in (0, 1), got {}",
                params.cg_tolerance
            )));
        }
        if !(params.min_weight > 0.0 && params.min_weight <= 1.0) {
            return Err(Error::BadParameter(format!(
                "the smallest confidence weight must be in (0, 1], got {}",
                params.min_weight
            )));
        }
        let level = Level::from_maps(width, height, normals, confidence, params.min_weight);
        let pixels = level.mask.iter().filter(|&&m| m).count();
        if pixels == 0 {
            return Err(Error::BadMask("the normal map has no valid normal".into()));
        }
        let (mut z, mut cg_iterations) = poisson_pyramid(&level, params);
        let mut weights = SideWeights::half(n);
        let mut reweight_iterations = 0;
        if let Solver::Bilateral {
            k,
            max_iterations,
            tolerance,
        } = params.solver
        {
            if !(k.is_finite() && k > 0.0) {
                return Err(Error::BadParameter(format!(
                    "the bilateral sharpness k must be positive, got {k}"
                )));
            }
            // The reweighting steps solve loosely (each is only a step toward the fixed point);
            // the last system is solved to the full tolerance.
            let inner = params.cg_tolerance.max(1e-4);
            let mut energy = level.energy(&weights, &z);
            let mut sys = None;
            for _ in 0..max_iterations {
                weights = level.bilateral_weights(&z, k);
                let h = Hierarchy::new(level.system(&weights));
                cg_iterations += h.solve(&mut z, inner, params.cg_max_iterations);
                sys = Some(h);
                reweight_iterations += 1;
                let e = level.energy(&weights, &z);
                let change = (e - energy).abs() / energy.max(1e-300);
                energy = e;
                if change < tolerance {
                    break;
                }
            }
            if let Some(h) = sys {
                cg_iterations += h.solve(&mut z, params.cg_tolerance, params.cg_max_iterations);
            }
        }
        let energy = level.energy(&weights, &z);
        // One offset per region: its lowest point at 0.
        let (label, sizes) =
            label_regions(level.w, level.h, |i| level.mask[i]).ok_or_else(|| {
                Error::BadParameter(format!(
                    "a {width}x{height} normal map is too large to integrate"
                ))
            })?;
        let mut lowest = vec![f64::INFINITY; sizes.len()];
        for i in 0..n {
            if label[i] != OUTSIDE {
                let l = label[i] as usize;
                lowest[l] = lowest[l].min(z[i]);
            }
        }
        let depth = (0..n)
            .map(|i| {
                if label[i] == OUTSIDE {
                    f32::NAN
                } else {
                    (z[i] - lowest[label[i] as usize]) as f32
                }
            })
            .collect();
        z.clear();
        Ok(DepthMap {
            width,
            height,
            depth,
            cg_iterations,
            reweight_iterations,
            energy,
            regions: sizes.len(),
            pixels,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Normals of a height field given by its gradient function `(dz/dcol, dz/drow)`.
    fn normals_of(w: usize, h: usize, grad: impl Fn(f64, f64) -> (f64, f64)) -> Vec<f32> {
        let mut out = Vec::with_capacity(3 * w * h);
        for r in 0..h {
            for q in 0..w {
                let (gq, gr) = grad(q as f64, r as f64);
                let (nx, ny, nz) = (-gq, gr, 1.0);
                let len = (nx * nx + ny * ny + nz * nz).sqrt();
                out.extend([(nx / len) as f32, (ny / len) as f32, (nz / len) as f32]);
            }
        }
        out
    }

    /// RMS of `a - b - mean(a - b)` over pixels where `keep`.
    fn rms_after_offset(a: &[f32], b: &[f64], keep: impl Fn(usize) -> bool) -> f64 {
        let idx: Vec<usize> = (0..b.len()).filter(|&i| keep(i)).collect();
        let mean = idx.iter().map(|&i| a[i] as f64 - b[i]).sum::<f64>() / idx.len() as f64;
        (idx.iter()
            .map(|&i| (a[i] as f64 - b[i] - mean).powi(2))
            .sum::<f64>()
            / idx.len() as f64)
            .sqrt()
    }

    fn sphere(size: usize) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
        let rad = size as f64 / 2.0;
        let mut n = vec![f32::NAN; 3 * size * size];
        let mut z = vec![f64::NAN; size * size];
        let mut cos = vec![0.0; size * size];
        for r in 0..size {
            for q in 0..size {
                let x = (q as f64 + 0.5 - rad) / rad;
                let y = -(r as f64 + 0.5 - rad) / rad;
                let rr = x * x + y * y;
                if rr < 1.0 {
                    let i = r * size + q;
                    let nz = (1.0 - rr).sqrt();
                    n[3 * i..3 * i + 3].copy_from_slice(&[x as f32, y as f32, nz as f32]);
                    z[i] = rad * nz;
                    cos[i] = nz;
                }
            }
        }
        (n, z, cos)
    }

    #[test]
    fn both_solvers_recover_a_sphere() {
        let size = 128;
        let (n, truth, cos) = sphere(size);
        let within_60 = |i: usize| cos[i] >= 0.5;
        for solver in [Solver::Poisson, Solver::bilateral()] {
            let params = IntegrateParams {
                solver,
                ..IntegrateParams::default()
            };
            let d = DepthMap::integrate(size, size, &n, None, &params).unwrap();
            assert_eq!(d.regions, 1);
            let rms = rms_after_offset(&d.depth, &truth, within_60);
            // Radius 64 px: 1% is 0.64.
            assert!(rms < 0.005 * 64.0, "{solver:?}: rms {rms}");
            assert!(d.depth.iter().all(|v| v.is_nan() || *v >= 0.0));
        }
    }

    #[test]
    fn a_plane_is_exact_and_regions_get_their_own_offset() {
        let (w, h) = (40, 30);
        let mut n = normals_of(w, h, |_, _| (0.3, -0.2));
        // A gap column splits the map into two regions.
        for r in 0..h {
            n[3 * (r * w + 20)..3 * (r * w + 20) + 3].fill(f32::NAN);
        }
        let d = DepthMap::integrate(w, h, &n, None, &IntegrateParams::default()).unwrap();
        assert_eq!(d.regions, 2);
        assert_eq!(d.pixels, w * h - h);
        for r in 0..h {
            for q in 0..w {
                let i = r * w + q;
                if q == 20 {
                    assert!(d.depth[i].is_nan());
                    continue;
                }
                // Each region's lowest point (top right of it, since z rises to the right and
                // falls downward... z = 0.3 q - 0.2 r) is 0.
                let q0 = if q < 20 { 0.0 } else { 21.0 };
                let want = 0.3 * (q as f64 - q0) - 0.2 * (r as f64 - (h - 1) as f64);
                assert!((d.depth[i] as f64 - want).abs() < 1e-3, "{q},{r}");
            }
        }
    }

    /// Bumps on two planes that meet at a step whose height grows down the image: no surface
    /// fits the normals on both sides, so Poisson bends, bilateral integration breaks.
    fn step_scene(size: usize) -> (Vec<f32>, Vec<f64>) {
        let s = size as f64;
        let bump = |q: f64, r: f64, cq: f64, cr: f64, a: f64| {
            let sg = s * 0.08;
            let e = (-((q - cq).powi(2) + (r - cr).powi(2)) / (2.0 * sg * sg)).exp();
            (
                a * e,
                -a * e * (q - cq) / (sg * sg),
                -a * e * (r - cr) / (sg * sg),
            )
        };
        let field = |q: f64, r: f64| -> (f64, f64, f64) {
            let (b1, b1q, b1r) = bump(q, r, 0.3 * s, 0.5 * s, 6.0);
            let (b2, b2q, b2r) = bump(q, r, 0.75 * s, 0.4 * s, -5.0);
            if q < s / 2.0 {
                // Left: a plane rising toward the bottom (0.25 per row).
                (0.25 * r + b1 + b2, b1q + b2q, 0.25 + b1r + b2r)
            } else {
                (b1 + b2, b1q + b2q, b1r + b2r)
            }
        };
        let n = normals_of(size, size, |q, r| {
            let (_, gq, gr) = field(q, r);
            (gq, gr)
        });
        let z = (0..size * size)
            .map(|i| field((i % size) as f64, (i / size) as f64).0)
            .collect();
        (n, z)
    }

    #[test]
    fn bilateral_keeps_a_discontinuity_that_poisson_smears() {
        let size = 96;
        let (n, truth) = step_scene(size);
        let poisson =
            DepthMap::integrate(size, size, &n, None, &IntegrateParams::default()).unwrap();
        let bini = DepthMap::integrate(
            size,
            size,
            &n,
            None,
            &IntegrateParams {
                solver: Solver::bilateral(),
                ..IntegrateParams::default()
            },
        )
        .unwrap();
        // Across a discontinuity the relative offset of the two sides is not observable: each
        // side is compared with its own offset.
        let side = |d: &DepthMap| {
            let left = rms_after_offset(&d.depth, &truth, |i| i % size < size / 2);
            let right = rms_after_offset(&d.depth, &truth, |i| i % size >= size / 2);
            left.max(right)
        };
        let (e_p, e_b) = (side(&poisson), side(&bini));
        // The step reaches 24 px at the bottom.
        assert!(e_p > 1.5, "poisson rms {e_p}");
        assert!(e_b < 0.05, "bilateral rms {e_b} (poisson {e_p})");
        // The mesh of the bilateral surface breaks at the step, and keeps
        // no triangle across a jump of more than 3 pixels (the jump of the solution: its sides'
        // relative offset is its own).
        let m = bini.mesh(&n, 2.0);
        assert!(m.dropped >= size / 2, "{} dropped", m.dropped);
        let mut kept = 0;
        for r in 0..size - 1 {
            for q in 0..size - 1 {
                let i = r * size + q;
                let jump = (bini.depth[i + 1] - bini.depth[i]).abs();
                if q == size / 2 - 1 && jump > 3.0 {
                    kept += 1;
                }
            }
        }
        let bridging = m
            .triangles
            .iter()
            .filter(|t| {
                let cols: Vec<u32> = t.iter().map(|&v| m.pixels[v as usize][0]).collect();
                let zs: Vec<f32> = t.iter().map(|&v| m.positions[v as usize][2]).collect();
                let spread = zs.iter().cloned().fold(f32::MIN, f32::max)
                    - zs.iter().cloned().fold(f32::MAX, f32::min);
                cols.contains(&(size as u32 / 2 - 1))
                    && cols.contains(&(size as u32 / 2))
                    && spread > 4.0
            })
            .count();
        assert!(
            kept > 0 && bridging == 0,
            "{kept} jumps, {bridging} bridging"
        );
        let full = 2 * (size - 1) * (size - 1);
        assert_eq!(m.triangles.len() + m.dropped, full);
        // The smooth Poisson surface keeps every triangle of a full grid.
        let mp = poisson.mesh(&n, 2.0);
        assert_eq!(mp.triangles.len() + mp.dropped, 2 * (size - 1) * (size - 1));
    }

    #[test]
    fn confidence_weights_the_fit() {
        // A plane with a patch of wrong normals: with zero-ish confidence on the patch the
        // plane around it is unharmed.
        let size = 48;
        let mut n = normals_of(size, size, |_, _| (0.2, 0.1));
        let mut conf = vec![1.0f32; size * size];
        for r in 20..28 {
            for q in 20..28 {
                let i = r * size + q;
                n[3 * i..3 * i + 3].copy_from_slice(&[0.6, 0.0, 0.8]);
                conf[i] = 0.0;
            }
        }
        let truth: Vec<f64> = (0..size * size)
            .map(|i| 0.2 * (i % size) as f64 + 0.1 * (i / size) as f64)
            .collect();
        let outside = |i: usize| {
            let (r, q) = (i / size, i % size);
            !(16..32).contains(&r) || !(16..32).contains(&q)
        };
        let p = IntegrateParams {
            min_weight: 1e-4,
            ..IntegrateParams::default()
        };
        let weighted = DepthMap::integrate(size, size, &n, Some(&conf), &p).unwrap();
        let plain = DepthMap::integrate(size, size, &n, None, &p).unwrap();
        let ew = rms_after_offset(&weighted.depth, &truth, outside);
        let ep = rms_after_offset(&plain.depth, &truth, outside);
        assert!(ew < 0.2 * ep && ew < 0.05, "weighted {ew}, plain {ep}");
    }

    #[test]
    fn bad_input_is_an_error() {
        let p = IntegrateParams::default();
        assert!(DepthMap::integrate(2, 2, &[0.0; 11], None, &p).is_err());
        assert!(DepthMap::integrate(2, 2, &[f32::NAN; 12], None, &p).is_err());
        assert!(DepthMap::integrate(0, 2, &[], None, &p).is_err());
        let n = [0.0, 0.0, 1.0].repeat(4);
        assert!(DepthMap::integrate(2, 2, &n, Some(&[1.0; 3]), &p).is_err());
        let bad = IntegrateParams {
            cg_tolerance: 0.0,
            ..p
        };
        assert!(DepthMap::integrate(2, 2, &n, None, &bad).is_err());
    }

    #[test]
    fn mesh_triangles_face_the_camera() {
        let (n, _, _) = sphere(32);
        let d = DepthMap::integrate(32, 32, &n, None, &IntegrateParams::default()).unwrap();
        let m = d.mesh(&n, 2.0);
        assert_eq!(m.positions.len(), d.pixels);
        assert!(!m.triangles.is_empty());
        for t in &m.triangles {
            let [a, b, c] = t.map(|v| m.positions[v as usize]);
            let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            assert!(cross > 0.0);
        }
    }
}
