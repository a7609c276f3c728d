//! The integrate job (`symframe integrate`): an estimate's normal map to a height map and a
//! mesh (`depth.npy`, `depth.exr`, `depth.png`, `mesh.ply`, `integrate.json`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::integrate::{integrate, mesh, shade, DepthMap, IntegrateParams, Mesh, Solver};

use crate::outdir::{OutputDir, OutputSet};

/// Everything an integrate job needs.
#[derive(Debug, Clone, PartialEq)]
pub struct IntegrateConfig {
    /// Output folder of [`crate::estimate`] (`normals.npy`; `confidence.npy` weights the fit).
    pub estimate: PathBuf,
    /// Output folder (created; `depth.npy`, `depth.exr`, `depth.png`, `mesh.ply`,
    /// `integrate.json` in it are replaced).
    pub output: PathBuf,
    /// The solver and its tolerances.
    pub params: IntegrateParams,
    /// Weight the fit by `confidence.npy` when present.
    pub use_confidence: bool,
    /// Mesh: leave out triangles with an edge whose height step departs from the normals'
    /// prediction by more than this many pixels times (1 + the predicted step).
    pub max_jump: f64,
}

impl IntegrateConfig {
    /// Bilateral integration (k = 10), confidence-weighted, jumps above 2 px cut.
    pub fn new(estimate: impl Into<PathBuf>, output: impl Into<PathBuf>) -> Self {
        Self {
            estimate: estimate.into(),
            output: output.into(),
            params: IntegrateParams {
                solver: Solver::bilateral(),
                ..IntegrateParams::default()
            },
            use_confidence: true,
            max_jump: 2.0,
        }
    }
}

/// What `integrate.json` records.
#[derive(Debug, Serialize)]
pub struct IntegrateReport {
    /// symframe version.
    pub version: &'static str,
    /// The estimate folder read.
    pub estimate: String,
    /// `poisson` or `bilateral`.
    pub solver: &'static str,
    /// Bilateral sharpness k (bilateral only).
    pub k: Option<f64>,
    /// Whether `confidence.npy` weighted the fit.
    pub confidence_weighted: bool,
    /// Width and height of the map.
    pub width: usize,
    /// Height of the map.
    pub height: usize,
    /// Pixels integrated.
    pub pixels: usize,
    /// Connected regions (each has its lowest point at height 0).
    pub regions: usize,
    /// Conjugate-gradient iterations, all solves.
    pub cg_iterations: usize,
    /// Bilateral reweighting iterations.
    pub reweight_iterations: usize,
    /// Final energy per pixel.
    pub energy: f64,
    /// Mesh vertices.
    pub vertices: usize,
    /// Mesh triangles.
    pub triangles: usize,
    /// Triangles left out at depth discontinuities.
    pub triangles_dropped: usize,
    /// Seconds spent integrating.
    pub integrate_s: f64,
    /// Seconds in all.
    pub total_s: f64,
    /// Peak resident memory of the process, bytes (Linux).
    pub peak_rss_bytes: Option<u64>,
    /// Units and frame of the outputs.
    pub conventions: &'static str,
}

/// An estimate's maps: width, height, normals, confidence.
type Inputs = (usize, usize, Vec<f32>, Option<Vec<f32>>);

/// Reads `normals.npy` (H x W x 3) and, when present and wanted, `confidence.npy` (H x W).
fn read_inputs(dir: &Path, use_confidence: bool) -> Result<Inputs> {
    let np = dir.join("normals.npy");
    if !np.is_file() {
        bail!(
            "{}: missing (the input must be an output folder of symframe estimate)",
            np.display()
        );
    }
    let (shape, normals) = symframe_io::read_npy_f32(&np)?;
    if shape.len() != 3 || shape[2] != 3 || shape[0] == 0 || shape[1] == 0 {
        bail!(
            "{}: expected an H x W x 3 array, got shape {shape:?}",
            np.display()
        );
    }
    let (h, w) = (shape[0], shape[1]);
    let cp = dir.join("confidence.npy");
    let confidence = if use_confidence && cp.is_file() {
        let (cs, c) = symframe_io::read_npy_f32(&cp)?;
        if cs != [h, w] {
            bail!(
                "{}: shape {cs:?} does not match normals.npy ({h} x {w} expected)",
                cp.display()
            );
        }
        Some(c)
    } else {
        None
    };
    Ok((w, h, normals, confidence))
}

/// Writes a binary little-endian PLY: float x y z nx ny nz per vertex, triangles as
/// `uchar 3, int a b c`.
pub fn write_ply(path: &Path, m: &Mesh) -> Result<()> {
    let file = std::fs::File::create(path)
        .with_context(|| format!("{}: cannot create", path.display()))?;
    let mut out = std::io::BufWriter::new(file);
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment symframe integrate: pixel units, x right, \
         y up, z toward the camera\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.positions.len(),
        m.triangles.len()
    );
    let write = |out: &mut std::io::BufWriter<std::fs::File>| -> std::io::Result<()> {
        out.write_all(header.as_bytes())?;
        for (p, n) in m.positions.iter().zip(&m.normals) {
            for v in p.iter().chain(n) {
                out.write_all(&v.to_le_bytes())?;
            }
        }
        for t in &m.triangles {
            out.write_all(&[3u8])?;
            for &v in t {
                out.write_all(&(v as i32).to_le_bytes())?;
            }
        }
        out.flush()
    };
    write(&mut out).with_context(|| format!("{}: cannot write", path.display()))
}

/// Runs an integrate job: reads the estimate's normals, integrates them, and writes the height
/// map, its pictures, the mesh and `integrate.json` as one set; returns the map and the report.
pub fn integrate_job(config: &IntegrateConfig) -> Result<(DepthMap, IntegrateReport)> {
    let t0 = Instant::now();
    if !(config.max_jump.is_finite() && config.max_jump > 0.0) {
        bail!(
            "the mesh's jump limit must be a positive number, got {}",
            config.max_jump
        );
    }
    if let Solver::Bilateral { k, .. } = config.params.solver {
        if !(k.is_finite() && k > 0.0) {
            bail!("the bilateral sharpness k must be a positive number, got {k}");
        }
    }
    if !(config.params.cg_tolerance > 0.0 && config.params.cg_tolerance < 1.0) {
        bail!(
            "the solver tolerance must be in (0, 1), got {}",
            config.params.cg_tolerance
        );
    }
    check_memory(&config.estimate.join("normals.npy"))?;
    // The output folder's lock and rules, as for every job: nothing there replaced that an
    // earlier integrate did not write, no input of the run replaced, no folder replaced.
    let out = OutputDir::lock(&config.output)?;
    let inputs = [
        config.estimate.join("normals.npy"),
        config.estimate.join("confidence.npy"),
    ];
    let result = out
        .guard_inputs(
            &inputs,
            "integrate.json",
            &|n| integrate_owned(n) || n == "integrate.json",
            &|_| false,
        )
        .and_then(|()| integrate_into(config, &out, t0));
    if result.is_err() {
        out.discard_unfinished();
    }
    result
}

/// The files of an integrate's output set besides `integrate.json`.
fn integrate_owned(name: &str) -> bool {
    matches!(name, "depth.npy" | "depth.exr" | "depth.png" | "mesh.ply")
}

/// Memory integration takes per pixel of the map, bytes: the solver's multigrid levels, the
/// weights, the mesh and the pictures (peak resident memory over pixels at 2048 x 2048:
/// docs/performance.md, "Integration").
const INTEGRATE_BYTES_PER_PIXEL: u64 = 200;

/// Refuses, before reading it, a normal map whose integration cannot fit in the memory this
/// process may use (the smaller of the free memory and its address-space limit), with the
/// figures, rather than failing an allocation half-way.
fn check_memory(normals: &Path) -> Result<()> {
    let Ok(meta) = std::fs::metadata(normals) else {
        return Ok(()); // read_inputs names the missing file
    };
    let pixels = meta.len() / 12;
    let need = pixels * INTEGRATE_BYTES_PER_PIXEL + 3 * meta.len();
    if let Some(have) = crate::tiles::memory_available_bytes() {
        if need > have {
            bail!(
                "{}: integrating a map of about {:.1} megapixels needs about {:.1} GiB of memory, \
                 {:.1} GiB available; integrate a crop, or on a machine with more memory",
                normals.display(),
                pixels as f64 / 1e6,
                need as f64 / (1u64 << 30) as f64,
                have as f64 / (1u64 << 30) as f64
            );
        }
    }
    Ok(())
}

/// Reads, integrates and writes the set into the locked folder `out`.
fn integrate_into(
    config: &IntegrateConfig,
    out: &OutputDir,
    t0: Instant,
) -> Result<(DepthMap, IntegrateReport)> {
    let solver = config.params.solver;
    let (w, h, normals, confidence) = read_inputs(&config.estimate, config.use_confidence)?;
    let t_int = Instant::now();
    let depth = integrate(w, h, &normals, confidence.as_deref(), &config.params)
        .with_context(|| format!("{}: cannot integrate", config.estimate.display()))?;
    let integrate_s = t_int.elapsed().as_secs_f64();
    let m = mesh(&depth, &normals, config.max_jump);

    let staging = OutputSet::new(out, integrate_owned)?;
    symframe_io::write_npy_f32(&staging.path("depth.npy"), &[h, w], &depth.depth)?;
    symframe_io::write_exr_map(&staging.path("depth.exr"), w, h, 1, &depth.depth)?;
    let shaded: Vec<f32> = shade(&depth).iter().flat_map(|&v| [v; 3]).collect();
    symframe_io::write_png8_rgb(&staging.path("depth.png"), w, h, &shaded, true)?;
    write_ply(&staging.path("mesh.ply"), &m)?;
    let report = IntegrateReport {
        version: env!("CARGO_PKG_VERSION"),
        estimate: config.estimate.display().to_string(),
        solver: match solver {
            Solver::Poisson => "poisson",
            Solver::Bilateral { .. } => "bilateral",
        },
        k: match solver {
            Solver::Bilateral { k, .. } => Some(k),
            Solver::Poisson => None,
        },
        confidence_weighted: confidence.is_some(),
        width: w,
        height: h,
        pixels: depth.pixels,
        regions: depth.regions,
        cg_iterations: depth.cg_iterations,
        reweight_iterations: depth.reweight_iterations,
        energy: depth.energy,
        vertices: m.positions.len(),
        triangles: m.triangles.len(),
        triangles_dropped: m.dropped,
        integrate_s,
        total_s: t0.elapsed().as_secs_f64(),
        peak_rss_bytes: crate::peak_rss_bytes(),
        conventions: "depth: height along +z (toward the camera) in pixel spacings, each \
                      connected region's lowest point at 0, NaN outside; mesh: vertex at pixel \
                      centre (x = col + 0.5, y = H - row - 0.5, z = depth), y up",
    };
    staging.commit("integrate.json", serde_json::to_value(&report)?, &|_| {})?;
    Ok((depth, report))
}
