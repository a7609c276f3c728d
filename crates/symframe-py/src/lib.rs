//! The native part of the `symframe` Python package: numpy arrays in and out, the library job
//! API ([`symframe_job`]) and the core's in-memory estimators underneath. The Python package
//! (`python/symframe/__init__.py`) checks array types and shapes and documents the API; this
//! module does the work with the GIL released.

mod appearance;
mod arrays;
mod dataset;
mod estimate;
mod options;
mod runner;

use std::path::PathBuf;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

use crate::appearance::{fit, relight};
use crate::arrays::{kept, put_maps};
use crate::dataset::{load, Dataset};
use crate::estimate::{estimate_arrays, estimate_path};
use crate::options::Options;
use crate::runner::{run_job, to_py};

pyo3::create_exception!(
    _native,
    SymframeError,
    PyRuntimeError,
    "A symframe job failed; the message is the command line's one-line error."
);

/// A JSON text as Python objects (`json.loads`).
fn json_to_py<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// A serializable value as Python objects.
fn to_python<'py>(py: Python<'py>, v: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(v)
        .map_err(|e| SymframeError::new_err(format!("cannot serialize: {e}")))?;
    json_to_py(py, &text)
}

/// The `symframe integrate` job: an estimate's normals to a height map and a mesh written to
/// `out`; returns `{"depth": H x W float32, "report": integrate.json}`.
#[pyfunction]
#[pyo3(signature = (estimate, out, options=None))]
fn integrate<'py>(
    py: Python<'py>,
    estimate: PathBuf,
    out: PathBuf,
    options: Option<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    use symframe::Solver;
    let mut o = Options::new("integrate", options);
    let mut config = symframe_job::IntegrateConfig::new(estimate, out);
    let solver: String = o.or("solver", "bilateral".to_string())?;
    let k: f64 = o.or("k", 10.0)?;
    config.params.solver = match solver.as_str() {
        "poisson" => Solver::Poisson,
        "bilateral" => match Solver::bilateral() {
            Solver::Bilateral {
                max_iterations,
                tolerance,
                ..
            } => Solver::Bilateral {
                k,
                max_iterations,
                tolerance,
            },
            Solver::Poisson => Solver::Poisson,
        },
        other => {
            return Err(PyValueError::new_err(format!(
                "solver must be poisson or bilateral, got '{other}'"
            )))
        }
    };
    config.params.cg_tolerance = o.or("tolerance", config.params.cg_tolerance)?;
    config.use_confidence = o.or("use_confidence", config.use_confidence)?;
    config.max_jump = o.or("max_jump", config.max_jump)?;
    o.finish()?;
    let (depth, report) = run_job(py, None, None, |_| symframe_job::integrate_job(&config))?;
    let dict = PyDict::new(py);
    dict.set_item(
        "depth",
        PyArray1::from_vec(py, depth.depth).reshape([depth.height, depth.width])?,
    )?;
    dict.set_item("report", to_python(py, &report)?)?;
    Ok(dict)
}

/// The `symframe eval` figures of estimated maps against ground truth.
#[pyfunction]
#[pyo3(signature = (normals, gt_normals, tangents=None, gt_tangents=None, mask=None, max_angle=60.0))]
fn evaluate<'py>(
    py: Python<'py>,
    normals: numpy::PyReadonlyArray3<'py, f32>,
    gt_normals: numpy::PyReadonlyArray3<'py, f32>,
    tangents: Option<numpy::PyReadonlyArray3<'py, f32>>,
    gt_tangents: Option<numpy::PyReadonlyArray3<'py, f32>>,
    mask: Option<PyReadonlyArray2<'py, bool>>,
    max_angle: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let slice = |a: &numpy::PyReadonlyArray3<'py, f32>| {
        a.as_slice()
            .map(|s| s.to_vec())
            .map_err(|e| PyValueError::new_err(e.to_string()))
    };
    let n = slice(&normals)?;
    let g = slice(&gt_normals)?;
    let t = match &tangents {
        Some(t) => slice(t)?,
        None => vec![f32::NAN; n.len()],
    };
    let gt = gt_tangents.as_ref().map(slice).transpose()?;
    let m = mask
        .as_ref()
        .map(|m| {
            m.as_slice()
                .map(|s| s.to_vec())
                .map_err(|e| PyValueError::new_err(e.to_string()))
        })
        .transpose()?;
    let e =
        py.detach(|| symframe::evaluate(&n, &t, &g, gt.as_deref(), m.as_deref(), max_angle, None));
    to_python(py, &e)
}

/// Renders a synthetic capture (a sphere or cylinder, a reflectance model spec as for `symframe
/// synth --model`, lights uniform over a cone) into an `.lp` dataset folder with ground truth;
/// returns the `.lp` path.
#[pyfunction]
#[pyo3(signature = (out, shape, size, n_lights, theta_d_max, model, tangent_field, format))]
#[allow(clippy::too_many_arguments)]
fn synth(
    py: Python<'_>,
    out: PathBuf,
    shape: String,
    size: usize,
    n_lights: usize,
    theta_d_max: f64,
    model: String,
    tangent_field: String,
    format: String,
) -> PyResult<PathBuf> {
    use symframe::render::{Scene, TangentField};
    let field = match tangent_field.as_str() {
        "circular" => TangentField::Circular,
        "radial" => TangentField::Radial,
        other => {
            return Err(PyValueError::new_err(format!(
                "tangent_field must be circular or radial, got '{other}'"
            )))
        }
    };
    let format = match format.as_str() {
        "exr" => symframe_io::ImageFormat::Exr,
        "png16" => symframe_io::ImageFormat::Png16,
        "png8" => symframe_io::ImageFormat::Png8,
        other => {
            return Err(PyValueError::new_err(format!(
                "format must be exr, png16 or png8, got '{other}'"
            )))
        }
    };
    if !(8..=2048).contains(&size) {
        return Err(PyValueError::new_err(format!(
            "size must be between 8 and 2048, got {size}"
        )));
    }
    if !(1..=100_000).contains(&n_lights) {
        return Err(PyValueError::new_err(format!(
            "lights must be in 1..=100000, got {n_lights}"
        )));
    }
    if !(theta_d_max > 0.0 && theta_d_max < 90.0) {
        return Err(PyValueError::new_err(format!(
            "theta_d_max must be in (0, 90) degrees, got {theta_d_max}"
        )));
    }
    let brdf = symframe::brdf::parse_model(&model)
        .map_err(|e| PyValueError::new_err(format!("model: {e}")))?;
    let scene = match shape.as_str() {
        "sphere" => Scene::sphere(size, field),
        "cylinder" => Scene::cylinder(size, field),
        other => {
            return Err(PyValueError::new_err(format!(
                "shape must be sphere or cylinder, got '{other}'"
            )))
        }
    };
    py.detach(|| -> anyhow::Result<PathBuf> {
        symframe_io::check_synth_target(&out, false)?;
        // The output folder's lock, as the CLI's synth takes it; checked again under it.
        let lock = symframe_job::OutputDir::lock(&out)?;
        let written = (|| -> anyhow::Result<PathBuf> {
            symframe_io::check_synth_target(&out, false)?;
            let lights = symframe::uniform_cone_lights(n_lights, theta_d_max);
            let images: Vec<Vec<f32>> = {
                use rayon::prelude::*;
                lights
                    .par_iter()
                    .map(|&l| scene.render(brdf.as_ref(), l))
                    .collect()
            };
            Ok(symframe_io::write_lp_dataset(
                &out,
                &lights,
                &images,
                scene.width,
                scene.height,
                format,
                Some(&scene.gt_normals()),
                Some(&scene.gt_tangents()),
                Some(&scene.mask),
            )?)
        })();
        if written.is_err() {
            lock.discard_unfinished();
        }
        written
    })
    .map_err(to_py)
}

/// The `symframe merge` job: the output folders of `estimate --tiles K/N` shards joined into
/// the full maps in `out` (maps, pictures and `report.json`, as the command line writes them).
#[pyfunction]
#[pyo3(signature = (shards, out, progress=None, threads=None))]
fn merge<'py>(
    py: Python<'py>,
    shards: Vec<PathBuf>,
    out: PathBuf,
    progress: Option<Py<PyAny>>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let done = run_job(py, progress, threads, |ctl| {
        symframe_job::merge(&shards, &out, true, ctl)
    })?;
    let path = out.join("report.json");
    let text = std::fs::read_to_string(&path)
        .map_err(|e| SymframeError::new_err(format!("{}: cannot read: {e}", path.display())))?;
    let dict = PyDict::new(py);
    dict.set_item("report", json_to_py(py, &text)?)?;
    put_maps(py, &dict, kept(done.maps)?)?;
    Ok(dict)
}

/// The `symframe view` job: the viewer page of a fit folder; returns its path. What the command
/// line prints as warnings (estimate maps not found) become `UserWarning`s.
#[pyfunction]
#[pyo3(signature = (fit_dir, out=None, frames=None, from_samples=None))]
fn view(
    py: Python<'_>,
    fit_dir: PathBuf,
    out: Option<PathBuf>,
    frames: Option<PathBuf>,
    from_samples: Option<PathBuf>,
) -> PyResult<PathBuf> {
    let mut config = symframe_job::ViewConfig::new(fit_dir);
    if let Some(out) = out {
        config.output = out;
    }
    config.frames = frames;
    config.samples = from_samples.map(|c| (c, symframe_io::DecodeOptions::default()));
    let done = py
        .detach(|| symframe_job::write_viewer(&config))
        .map_err(to_py)?;
    for note in &done.notes {
        let message = std::ffi::CString::new(note.replace('\0', " ")).unwrap_or_default();
        PyErr::warn(
            py,
            &py.get_type::<pyo3::exceptions::PyUserWarning>(),
            &message,
            1,
        )?;
    }
    Ok(done.path)
}

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SymframeError", m.py().get_type::<SymframeError>())?;
    m.add(
        "__version__",
        PyString::new(m.py(), env!("CARGO_PKG_VERSION")),
    )?;
    m.add_class::<Dataset>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_path, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(relight, m)?)?;
    m.add_function(wrap_pyfunction!(integrate, m)?)?;
    m.add_function(wrap_pyfunction!(synth, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(view, m)?)?;
    Ok(())
}
