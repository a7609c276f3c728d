//! The integrate job (`symframe integrate`): an estimate's normal map to a height map and a
//! mesh (`depth.npy`, `depth.exr`, `depth.png`, `mesh.ply`, `integrate.json`).
//!
//! With a pinhole camera (`K.txt`, or the one a near-light estimate recorded in its report)
//! the normals are integrated as a perspective depth map ([`Pinhole::integrate`]): metric
//! depths along the optical axis, scaled as the estimate's `depth.npy` (its median over each
//! connected region kept) or, without one, so that the object's centre is at the given distance;
//! the mesh is the surface points the pixels see, in the camera frame.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use symframe::{DepthMap, IntegrateParams, Mesh, Pinhole, Solver};

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
    /// The camera's `K.txt` (OpenCV's intrinsics): a perspective depth map and mesh. `None`:
    /// the camera the estimate's `report.json` records (a near-light estimate), else an
    /// orthographic height map.
    pub camera: Option<PathBuf>,
    /// With a camera: the depth of the object's centre along the optical axis, in the unit the
    /// depths are wanted in; needed where the estimate wrote no `depth.npy` to scale by.
    pub distance: Option<f64>,
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
            camera: None,
            distance: None,
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
    /// The pinhole camera of a perspective integration (absent for a height map).
    pub camera: Option<CameraReport>,
    /// Units and frame of the outputs.
    pub conventions: &'static str,
}

/// The camera of a perspective integration, as `integrate.json` records it.
#[derive(Debug, Clone, Serialize)]
pub struct CameraReport {
    /// The intrinsics, row-major, OpenCV's convention.
    #[serde(rename = "K")]
    pub k: [[f64; 3]; 3],
    /// Where K came from: the K.txt read, or the estimate's report.json.
    pub from: String,
    /// How the depths were scaled: by the estimate's depth.npy, or the given distance.
    pub scale: String,
}

/// The pinhole camera a folder's records name: `integrate.json`'s `camera` (a perspective
/// integration) or `report.json`'s `near` section (a near-light estimate); `None` where neither
/// records one. The file read comes with it.
pub fn recorded_camera(dir: &Path) -> Result<Option<(Pinhole, PathBuf)>> {
    for (file, section) in [("integrate.json", "camera"), ("report.json", "near")] {
        let path = dir.join(file);
        if !path.is_file() {
            continue;
        }
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        let json: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{}: not valid JSON", path.display()))?;
        let Some(k) = json.get(section).and_then(|s| s.get("K")) else {
            continue;
        };
        let k: [[f64; 3]; 3] = serde_json::from_value(k.clone())
            .with_context(|| format!("{}: {section}.K is not a 3 x 3 matrix", path.display()))?;
        let camera = Pinhole::from_k(k)
            .map_err(|why| anyhow::anyhow!("{}: {section}.K: {why}", path.display()))?;
        return Ok(Some((camera, path)));
    }
    Ok(None)
}

/// The camera a job is to use: the K.txt given, else the one `dir`'s records name.
pub(crate) fn camera_for(given: Option<&Path>, dir: &Path) -> Result<Option<(Pinhole, PathBuf)>> {
    match given {
        Some(k) => Ok(Some((symframe_io::near::read_camera(k)?, k.to_path_buf()))),
        None => recorded_camera(dir),
    }
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

/// What `integrate.json` says of a perspective integration's outputs.
const PERSPECTIVE_CONVENTIONS: &str = "depth: distance along the optical axis in the unit of \
    the estimate's depth.npy or the given distance, NaN outside; mesh: the surface point each \
    pixel sees, camera frame (x right, y up, z toward the viewer, origin at the centre of \
    projection), same unit";

/// Writes a binary little-endian PLY: float x y z nx ny nz per vertex, triangles as
/// `uchar 3, int a b c`; `camera_frame`: the vertices are metric camera-frame points (a
/// perspective mesh), else pixel units.
pub fn write_ply(path: &Path, m: &Mesh, camera_frame: bool) -> Result<()> {
    let file = std::fs::File::create(path)
        .with_context(|| format!("{}: cannot create", path.display()))?;
    let mut out = std::io::BufWriter::new(file);
    let units = if camera_frame {
        "camera frame in the depths' unit, origin at the centre of projection"
    } else {
        "pixel units"
    };
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment symframe integrate: {units}, x right, \
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
    let camera = camera_for(config.camera.as_deref(), &config.estimate)?;
    let scale_by = match camera {
        Some(_) => estimate_depth(&config.estimate)?,
        None => None,
    };
    let mut inputs = vec![
        config.estimate.join("normals.npy"),
        config.estimate.join("confidence.npy"),
    ];
    inputs.extend(scale_by.clone());
    let result = out
        .guard_inputs(
            &inputs,
            "integrate.json",
            &|n| integrate_owned(n) || n == "integrate.json",
            &|_| false,
        )
        .and_then(|()| integrate_into(config, camera, scale_by.as_deref(), &out, t0));
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
/// docs/performance.md, "Memory model", Integration).
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
    camera: Option<(Pinhole, PathBuf)>,
    scale_by: Option<&Path>,
    out: &OutputDir,
    t0: Instant,
) -> Result<(DepthMap, IntegrateReport)> {
    let solver = config.params.solver;
    let (w, h, normals, confidence) = read_inputs(&config.estimate, config.use_confidence)?;
    let t_int = Instant::now();
    let (depth, m, camera_report) = match &camera {
        None => {
            let depth = DepthMap::integrate(w, h, &normals, confidence.as_deref(), &config.params)
                .with_context(|| format!("{}: cannot integrate", config.estimate.display()))?;
            let m = depth.mesh(&normals, config.max_jump);
            (depth, m, None)
        }
        Some((cam, from)) => {
            let (depth, scale) =
                integrate_perspective(config, cam, scale_by, w, h, &normals, &confidence)?;
            let m = cam.mesh(w, h, &depth.depth, &normals, config.max_jump);
            let report = CameraReport {
                k: cam.k(),
                from: from.display().to_string(),
                scale,
            };
            (depth, m, Some(report))
        }
    };
    let integrate_s = t_int.elapsed().as_secs_f64();

    let staging = OutputSet::new(out, integrate_owned)?;
    symframe_io::write_npy_f32(&staging.path("depth.npy"), &[h, w], &depth.depth)?;
    symframe_io::write_exr_map(&staging.path("depth.exr"), w, h, 1, &depth.depth)?;
    let picture = match &camera {
        None => shade(w, h, &depth.depth),
        Some((cam, _)) => shade(w, h, &cam.picture_heights(&depth.depth)),
    };
    let shaded: Vec<f32> = picture.iter().flat_map(|&v| [v; 3]).collect();
    symframe_io::write_png8_rgb(&staging.path("depth.png"), w, h, &shaded, true)?;
    write_ply(&staging.path("mesh.ply"), &m, camera.is_some())?;
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
        conventions: if camera_report.is_some() {
            PERSPECTIVE_CONVENTIONS
        } else {
            "depth: height along +z (toward the camera) in pixel spacings, each connected \
             region's lowest point at 0, NaN outside; mesh: vertex at pixel centre (x = col + \
             0.5, y = H - row - 0.5, z = depth), y up"
        },
        camera: camera_report,
    };
    staging.commit("integrate.json", serde_json::to_value(&report)?, &|_| {})?;
    Ok((depth, report))
}

/// Shades a `w` x `h` height map for a picture (`depth.png`): Lambertian under a light from the
/// upper left (`(-1, 1, 2)` normalised), 0.15 ambient, values in [0, 1], NaN outside.
fn shade(w: usize, h: usize, z: &[f32]) -> Vec<f32> {
    let l = {
        let v = [-1.0f64, 1.0, 2.0];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    };
    (0..w * h)
        .map(|i| {
            if !z[i].is_finite() {
                return f32::NAN;
            }
            let (r, q) = (i / w, i % w);
            let at = |rr: usize, qq: usize| z[rr * w + qq];
            // Central differences where both sides exist, one-sided otherwise.
            let diff = |a: Option<f32>, b: Option<f32>, c: f32| -> f64 {
                match (a.filter(|v| v.is_finite()), b.filter(|v| v.is_finite())) {
                    (Some(a), Some(b)) => (b as f64 - a as f64) / 2.0,
                    (Some(a), None) => c as f64 - a as f64,
                    (None, Some(b)) => b as f64 - c as f64,
                    (None, None) => 0.0,
                }
            };
            let dzdq = diff(
                (q > 0).then(|| at(r, q - 1)),
                (q + 1 < w).then(|| at(r, q + 1)),
                z[i],
            );
            let dzdr = diff(
                (r > 0).then(|| at(r - 1, q)),
                (r + 1 < h).then(|| at(r + 1, q)),
                z[i],
            );
            // n = (-dz/dx, -dz/dy, 1) with y = -row.
            let (nx, ny, nz) = (-dzdq, dzdr, 1.0);
            let len = (nx * nx + ny * ny + nz * nz).sqrt();
            let d = ((nx * l[0] + ny * l[1] + nz * l[2]) / len).max(0.0);
            (0.15 + 0.85 * d) as f32
        })
        .collect()
}

/// The depth map a near-light estimate wrote (`depth.npy`, its report.json having a `near`
/// section); `None` for any other folder, whose `depth.npy`, if any, is not the estimate's.
fn estimate_depth(dir: &Path) -> Result<Option<PathBuf>> {
    let (report, depth) = (dir.join("report.json"), dir.join("depth.npy"));
    if !(report.is_file() && depth.is_file()) {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&report)
        .with_context(|| format!("{}: cannot read", report.display()))?;
    let json: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", report.display()))?;
    Ok(json
        .get("near")
        .is_some_and(|n| !n.is_null())
        .then_some(depth))
}

/// The perspective depth map of `normals` through `camera`, scaled by the estimate's depth map
/// `scale_by` (each region's median kept) where there is one, else with the object's centre at
/// the configured distance; with how it was scaled.
fn integrate_perspective(
    config: &IntegrateConfig,
    camera: &Pinhole,
    scale_by: Option<&Path>,
    w: usize,
    h: usize,
    normals: &[f32],
    confidence: &Option<Vec<f32>>,
) -> Result<(DepthMap, String)> {
    let has_normal = |p: usize| normals[3 * p..3 * p + 3].iter().all(|v| v.is_finite());
    let (previous, centre, scale) = if let Some(dp) = scale_by {
        let (shape, d) = symframe_io::read_npy_f32(dp)?;
        if shape != [h, w] {
            bail!(
                "{}: shape {shape:?} does not match normals.npy ({h} x {w} expected)",
                dp.display()
            );
        }
        let previous: Vec<f32> = (0..w * h)
            .map(|p| {
                if has_normal(p) && d[p] > 0.0 {
                    d[p]
                } else {
                    f32::NAN
                }
            })
            .collect();
        let scale = format!("each region's median depth that of {}", dp.display());
        (previous, None, scale)
    } else {
        let Some(distance) = config.distance else {
            bail!(
                "{}: no depth map of a near-light estimate to scale the depths by; give the depth of the object's centre along the optical axis (--distance)",
                config.estimate.display()
            );
        };
        if !(distance.is_finite() && distance > 0.0) {
            bail!("the object's distance must be a positive depth, got {distance}");
        }
        let previous: Vec<f32> = (0..w * h)
            .map(|p| {
                if has_normal(p) {
                    distance as f32
                } else {
                    f32::NAN
                }
            })
            .collect();
        let scale = format!("the object's centre at depth {distance}");
        (previous, Some(distance), scale)
    };
    let depth = camera
        .integrate(
            w,
            h,
            normals,
            confidence.as_deref(),
            &previous,
            centre,
            &config.params,
        )
        .with_context(|| format!("{}: cannot integrate", config.estimate.display()))?;
    Ok((depth, scale))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        estimate, export_gltf, synth_near, Control, EstimateConfig, ExportConfig, NearSynthConfig,
    };
    use glam::DVec3;

    /// The shaded picture is NaN exactly where the heights are and within [0, 1] elsewhere.
    #[test]
    fn shading_is_bounded_and_keeps_the_holes() {
        let (w, h) = (8, 6);
        let z: Vec<f32> = (0..w * h)
            .map(|i| match i % 7 {
                0 => f32::NAN,
                k => (k * k) as f32 * 0.3 - (i / w) as f32,
            })
            .collect();
        let s = shade(w, h, &z);
        assert_eq!(s.len(), z.len());
        assert!(s
            .iter()
            .zip(&z)
            .all(|(s, z)| s.is_nan() == z.is_nan() && (s.is_nan() || (0.0..=1.0).contains(s))));
        // A flat patch faces the view: 0.15 + 0.85 * l.z.
        let flat = shade(3, 3, &[1.0; 9]);
        assert!((flat[4] - (0.15 + 0.85 * 2.0 / 6f64.sqrt()) as f32).abs() < 1e-6);
    }

    /// Each mesh vertex's distance from the true surface point of its pixel, over the object's
    /// width, with whether the pixel's true normal is within 60 degrees of its view.
    fn vertex_errors(m: &Mesh, camera: &Pinhole, data: &Path) -> Vec<(f64, bool)> {
        let (shape, truth) = symframe_io::read_npy_f32(&data.join("gt_depth.npy")).unwrap();
        let (_, normals) = symframe_io::read_npy_f32(&data.join("gt_normals.npy")).unwrap();
        let w = shape[1];
        m.positions
            .iter()
            .zip(&m.pixels)
            .map(|(p, px)| {
                let (col, row) = (px[0] as usize, px[1] as usize);
                let i = row * w + col;
                let at = camera.point(col as f64, row as f64, truth[i] as f64);
                let n = DVec3::from_array([0, 1, 2].map(|c| normals[3 * i + c] as f64));
                let facing = n.dot(camera.view(col as f64, row as f64)) > 0.5;
                let e = (DVec3::from_array(p.map(f64::from)) - at).length();
                (e / crate::synth_near::PAIR_WIDTH, facing)
            })
            .collect()
    }

    /// A near render's normals integrated through its camera: the mesh lies on the true
    /// surface, in the camera frame and the lights' unit, whether the depths are scaled by the
    /// estimate's depth.npy or by the object's distance; export gltf --mesh builds the same mesh.
    #[test]
    fn a_near_estimate_integrates_to_its_surface_in_the_camera_frame() {
        let d = tempfile::tempdir().unwrap();
        let data = d.path().join("data");
        let capture = NearSynthConfig {
            size: 96,
            lights: 80,
            ..NearSynthConfig::new(&data)
        };
        synth_near(&capture, &Control::default()).unwrap();
        let est = d.path().join("est");
        let mut config = EstimateConfig::new(&data, &est);
        config.near.max_iterations = 3;
        estimate(&config, &Control::default()).unwrap();
        let camera = capture.scene().camera;
        let check = |m: &Mesh| {
            let errors = vertex_errors(m, &camera, &data);
            assert!(errors.len() > 2000, "{} vertices", errors.len());
            let mean = errors.iter().map(|e| e.0).sum::<f64>() / errors.len() as f64;
            let facing = errors
                .iter()
                .filter(|e| e.1)
                .map(|e| e.0)
                .fold(0.0, f64::max);
            let within = errors.iter().filter(|e| e.0 < 0.01).count() as f64 / errors.len() as f64;
            assert!(mean < 0.005, "mean vertex error {mean} of the width");
            assert!(
                facing < 0.01,
                "largest within 60 degrees of the view {facing}"
            );
            assert!(within > 0.95, "{within} of the vertices within 1%");
        };

        // The camera the estimate's report records, scaled by its depth.npy.
        let (_, report) = integrate_job(&IntegrateConfig::new(&est, d.path().join("int"))).unwrap();
        let cam = report.camera.expect("a perspective integration");
        assert_eq!(cam.k, camera.k());
        assert!(cam.scale.contains("depth.npy"), "{}", cam.scale);
        let (_, ours) = symframe_io::read_npy_f32(&d.path().join("int/depth.npy")).unwrap();
        let (_, theirs) = symframe_io::read_npy_f32(&est.join("depth.npy")).unwrap();
        for (a, b) in ours.iter().zip(&theirs).filter(|(a, _)| a.is_finite()) {
            assert!((a / b - 1.0).abs() < 0.01, "integrate {a}, estimate {b}");
        }
        let m = camera.mesh(96, 48, &ours, &normals_of(&est), 2.0);
        check(&m);
        let ply = std::fs::read(d.path().join("int/mesh.ply")).unwrap();
        assert!(String::from_utf8_lossy(&ply[..200]).contains("camera frame"));

        // Without depth.npy: K.txt given, the depths scaled by the object's distance.
        let bare = d.path().join("bare");
        std::fs::create_dir(&bare).unwrap();
        for f in std::fs::read_dir(&est).unwrap() {
            let f = f.unwrap().path();
            let name = f.file_name().unwrap().to_owned();
            if f.extension().is_some_and(|e| e == "npy") && name != "depth.npy" {
                std::fs::copy(&f, bare.join(name)).unwrap();
            }
        }
        let mut config = IntegrateConfig::new(&bare, d.path().join("int2"));
        config.camera = Some(data.join("K.txt"));
        let e = integrate_job(&config).unwrap_err().to_string();
        assert!(e.contains("--distance"), "{e}");
        config.distance = Some(capture.camera_ratio * crate::synth_near::PAIR_WIDTH);
        let (_, report) = integrate_job(&config).unwrap();
        assert!(report.camera.unwrap().scale.contains("centre"));
        let (_, depth) = symframe_io::read_npy_f32(&d.path().join("int2/depth.npy")).unwrap();
        check(&camera.mesh(96, 48, &depth, &normals_of(&est), 2.0));

        // export gltf --mesh: the perspective mesh in the camera frame, its bounds those of the
        // integrated mesh.
        let mut ex = ExportConfig::new(&est, d.path().join("asset.gltf"));
        ex.mesh = true;
        ex.depth = Some(d.path().join("int/depth.npy"));
        let done = export_gltf(&ex).unwrap();
        assert_eq!(done.vertices, m.positions.len());
        let doc: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.path().join("asset.gltf")).unwrap()).unwrap();
        let position = doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
            .as_u64()
            .unwrap() as usize;
        let accessor = &doc["accessors"][position];
        for (k, pick) in [("min", f32::min as fn(f32, f32) -> f32), ("max", f32::max)] {
            for axis in 0..3 {
                let want = m.positions.iter().map(|p| p[axis]).reduce(pick).unwrap();
                let got = accessor[k][axis].as_f64().unwrap() as f32;
                assert!((got - want).abs() < 1e-4, "{k}[{axis}]: {got} vs {want}");
            }
        }
        // An orthographic height map is not read through a camera.
        let mut ortho = IntegrateConfig::new(&bare, d.path().join("ortho"));
        ortho.distance = None;
        integrate_job(&ortho).unwrap();
        let mut ex = ExportConfig::new(&bare, d.path().join("ortho.glb"));
        ex.mesh = true;
        ex.depth = Some(d.path().join("ortho/depth.npy"));
        ex.camera = Some(data.join("K.txt"));
        let e = export_gltf(&ex).unwrap_err().to_string();
        assert!(e.contains("orthographic"), "{e}");
    }

    fn normals_of(dir: &Path) -> Vec<f32> {
        symframe_io::read_npy_f32(&dir.join("normals.npy"))
            .unwrap()
            .1
    }
}
