//! `symframe integrate`: an estimate's normal map to a height map and a mesh (`depth.npy`,
//! `depth.exr`, `depth.png`, `mesh.ply`, `integrate.json`).

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::integrate::{integrate, mesh, shade, DepthMap, IntegrateParams, Mesh, Solver};

use crate::cli::{IntegrateArgs, IntegrateSolverArg};
use symframe_job::Staging;

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

/// Runs the command; returns the height map and the report written.
pub fn run(args: &IntegrateArgs) -> Result<(DepthMap, IntegrateReport)> {
    let t0 = Instant::now();
    if !(args.max_jump.is_finite() && args.max_jump > 0.0) {
        bail!(
            "--max-jump must be a positive number, got {}",
            args.max_jump
        );
    }
    if !(args.k.is_finite() && args.k > 0.0) {
        bail!("--k must be a positive number, got {}", args.k);
    }
    if !(args.tolerance > 0.0 && args.tolerance < 1.0) {
        bail!("--tolerance must be in (0, 1), got {}", args.tolerance);
    }
    let (w, h, normals, confidence) = read_inputs(&args.estimate, !args.no_confidence)?;
    let solver = match args.solver {
        IntegrateSolverArg::Poisson => Solver::Poisson,
        IntegrateSolverArg::Bilateral => Solver::Bilateral {
            k: args.k,
            max_iterations: args.max_iterations,
            tolerance: 1e-4,
        },
    };
    let params = IntegrateParams {
        solver,
        cg_tolerance: args.tolerance,
        ..IntegrateParams::default()
    };
    let t_int = Instant::now();
    let depth = integrate(w, h, &normals, confidence.as_deref(), &params)
        .with_context(|| format!("{}: cannot integrate", args.estimate.display()))?;
    let integrate_s = t_int.elapsed().as_secs_f64();
    let m = mesh(&depth, &normals, args.max_jump);

    let staging = Staging::new(&args.output)?;
    symframe_io::write_npy_f32(&staging.path("depth.npy"), &[h, w], &depth.depth)?;
    symframe_io::write_exr_map(&staging.path("depth.exr"), w, h, 1, &depth.depth)?;
    let shaded: Vec<f32> = shade(&depth).iter().flat_map(|&v| [v; 3]).collect();
    symframe_io::write_png8_rgb(&staging.path("depth.png"), w, h, &shaded, true)?;
    write_ply(&staging.path("mesh.ply"), &m)?;
    let report = IntegrateReport {
        version: env!("CARGO_PKG_VERSION"),
        estimate: args.estimate.display().to_string(),
        solver: match solver {
            Solver::Poisson => "poisson",
            Solver::Bilateral { .. } => "bilateral",
        },
        k: matches!(solver, Solver::Bilateral { .. }).then_some(args.k),
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
        peak_rss_bytes: symframe_job::peak_rss_bytes(),
        conventions: "depth: height along +z (toward the camera) in pixel spacings, each \
                      connected region's lowest point at 0, NaN outside; mesh: vertex at pixel \
                      centre (x = col + 0.5, y = H - row - 0.5, z = depth), y up",
    };
    let json = serde_json::to_string_pretty(&report)?;
    std::fs::write(staging.path("integrate.json"), json + "\n")
        .context("cannot write integrate.json")?;
    staging.commit()?;
    {
        println!(
            "symframe integrate: {} pixels ({} region(s)) by {} in {:.2} s ({} CG iterations{}), \
             mesh {} vertices, {} triangles ({} dropped at discontinuities), peak memory {} MiB; \
             wrote {}",
            report.pixels,
            report.regions,
            report.solver,
            integrate_s,
            report.cg_iterations,
            if report.reweight_iterations > 0 {
                format!(", {} reweightings", report.reweight_iterations)
            } else {
                String::new()
            },
            report.vertices,
            report.triangles,
            report.triangles_dropped,
            report.peak_rss_bytes.unwrap_or(0) >> 20,
            args.output.display()
        );
    }
    Ok((depth, report))
}
