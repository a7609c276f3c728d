//! The native part of the `symframe` Python package: numpy arrays in and out, the library job
//! API ([`symframe_job`]) and the core's in-memory estimators underneath. The Python package
//! (`python/symframe/__init__.py`) checks array types and shapes and documents the API; this
//! module does the work with the GIL released.

mod options;
mod runner;

use std::path::PathBuf;

use anyhow::Context;
use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyReadonlyArray4, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use symframe::{
    check_inputs, BaselineMethod, EstimateMaps, Estimator, PixelMethod, PixelRecord, Rig, Stack,
};
use symframe_io::DecodeOptions;
use symframe_job::{EstimateConfig, EstimateOutcome, MethodConfig, Progress, Sources, Stage};

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

/// The maps a job kept in memory (it was asked to), else an error.
fn kept(maps: Option<EstimateMaps>) -> PyResult<EstimateMaps> {
    maps.ok_or_else(|| SymframeError::new_err("the job kept no maps in memory"))
}

/// The maps as numpy arrays in `dict`.
fn put_maps<'py>(py: Python<'py>, dict: &Bound<'py, PyDict>, maps: EstimateMaps) -> PyResult<()> {
    let (h, w) = (maps.height, maps.width);
    dict.set_item(
        "normals",
        PyArray1::from_vec(py, maps.normals).reshape([h, w, 3])?,
    )?;
    dict.set_item(
        "tangents",
        PyArray1::from_vec(py, maps.tangents).reshape([h, w, 3])?,
    )?;
    dict.set_item(
        "confidence",
        PyArray1::from_vec(py, maps.confidence).reshape([h, w])?,
    )?;
    dict.set_item(
        "anisotropy",
        PyArray1::from_vec(py, maps.anisotropy).reshape([h, w])?,
    )?;
    dict.set_item(
        "tangent_confidence",
        PyArray1::from_vec(py, maps.tangent_confidence).reshape([h, w])?,
    )?;
    dict.set_item(
        "source",
        PyArray1::from_vec(py, maps.source).reshape([h, w])?,
    )?;
    Ok(())
}

/// The lights of an `N x 3` array.
fn lights_of(lights: &PyReadonlyArray2<f64>) -> PyResult<Vec<DVec3>> {
    let s = lights.shape();
    if s[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "lights must be N x 3, got {} x {}",
            s[0], s[1]
        )));
    }
    let v = lights
        .as_slice()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(v.chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect())
}

/// Runs `method` over `images` (`N x H x W x 3`, light-major as numpy holds them) in bands of
/// rows, each band gathered pixel-major, stopping between bands when asked.
fn run_bands<M: PixelMethod<Output = PixelRecord> + Sync>(
    method: &M,
    images: &[f32],
    (n, h, w): (usize, usize, usize),
    mask: Option<&[bool]>,
    ctl: &symframe_job::Control,
) -> anyhow::Result<EstimateMaps> {
    let rows = (16_384 / w.max(1)).clamp(1, h.max(1));
    let bands = h.div_ceil(rows);
    let mut records: Vec<PixelRecord> = Vec::with_capacity(w * h);
    for band in 0..bands {
        if ctl.stop.load(std::sync::atomic::Ordering::SeqCst) {
            return Err(symframe_job::Interrupted.into());
        }
        let (y0, y1) = (band * rows, ((band + 1) * rows).min(h));
        let mut stack = Stack::zeros(w, y1 - y0, n);
        for i in 0..n {
            let image = &images[(i * h + y0) * w * 3..(i * h + y1) * w * 3];
            for (p, px) in image.chunks_exact(3).enumerate() {
                let o = (p * n + i) * 3;
                stack.data[o..o + 3].copy_from_slice(px);
            }
        }
        let band_mask = mask.map(|m| &m[y0 * w..y1 * w]);
        records.extend(symframe::run_stack(method, &stack, band_mask, &|_| {}));
        (ctl.progress)(Progress {
            stage: Stage::Tiles,
            done: band as u64 + 1,
            total: bands as u64,
        });
    }
    Ok(EstimateMaps::from_records(w, h, &records))
}

/// In-memory estimation: `images` float32 `N x H x W x 3`, `lights` float64 `N x 3`, `mask`
/// bool `H x W` or `None`; keyword options as for `estimate_path` (the method's only).
#[pyfunction]
#[pyo3(signature = (images, lights, mask=None, progress=None, threads=None, options=None))]
fn estimate_arrays<'py>(
    py: Python<'py>,
    images: PyReadonlyArray4<'py, f32>,
    lights: PyReadonlyArray2<'py, f64>,
    mask: Option<PyReadonlyArray2<'py, bool>>,
    progress: Option<Py<PyAny>>,
    threads: Option<usize>,
    options: Option<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let mut o = Options::new("estimate", options);
    let method = options::method(&mut o)?;
    o.finish()?;
    let s = images.shape();
    let (n, h, w) = (s[0], s[1], s[2]);
    if s[3] != 3 {
        return Err(PyValueError::new_err(format!(
            "images must be N x H x W x 3, got last axis {}",
            s[3]
        )));
    }
    let lights = lights_of(&lights)?;
    if lights.len() != n {
        return Err(PyValueError::new_err(format!(
            "{} images but {} lights",
            n,
            lights.len()
        )));
    }
    let mask: Option<Vec<bool>> = match &mask {
        None => None,
        Some(m) => {
            if m.shape() != [h, w] {
                return Err(PyValueError::new_err(format!(
                    "mask must be H x W = {h} x {w} like the images, got {} x {}",
                    m.shape()[0],
                    m.shape()[1]
                )));
            }
            Some(
                m.as_slice()
                    .map_err(|e| PyValueError::new_err(e.to_string()))?
                    .to_vec(),
            )
        }
    };
    let images = images
        .as_slice()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let (maps, report) = run_job(py, progress, threads, |ctl| {
        let mask = mask.as_deref();
        match method {
            MethodConfig::Symmetry { rig, params } => {
                let rig = Rig::new(&lights, rig)?;
                check_inputs(w, h, n, rig.n_input(), mask)?;
                let est = Estimator::new(&rig, params);
                let maps = run_bands(&est, images, (n, h, w), mask, ctl)?;
                let report = serde_json::json!({
                    "method": "symmetry",
                    "parameters": {
                        "theta_d_max_deg": rig.theta_d_max_deg(),
                        "estimator": params,
                        "min_domain_used": est.min_domain(),
                    },
                    "lights": {"input": rig.n_input(), "used": rig.n_used(), "dropped": rig.n_dropped()},
                    "width": w, "height": h,
                    "pixels": maps.counts,
                    "sources": Sources::of(&maps.source),
                    "evals_per_pixel": maps.evals as f64 / maps.counts.estimated.max(1) as f64,
                });
                Ok((maps, report))
            }
            MethodConfig::Baseline { method, params } => {
                let b = BaselineMethod::new(method, &lights, params)?;
                check_inputs(w, h, n, b.unit_lights().len(), mask)?;
                let maps = run_bands(&b, images, (n, h, w), mask, ctl)?;
                let report = serde_json::json!({
                    "method": method.name(),
                    "parameters": params,
                    "lights": {"input": n, "used": n, "dropped": 0},
                    "width": w, "height": h,
                    "pixels": maps.counts,
                    "sources": Sources::of(&maps.source),
                    "evals_per_pixel": 0.0,
                });
                Ok((maps, report))
            }
        }
    })?;
    let dict = PyDict::new(py);
    put_maps(py, &dict, maps)?;
    dict.set_item("report", to_python(py, &report)?)?;
    Ok(dict)
}

/// The tiled, resumable estimation job of `symframe estimate`, from `path` into `out`.
#[pyfunction]
#[pyo3(signature = (path, out, progress=None, threads=None, options=None))]
fn estimate_path<'py>(
    py: Python<'py>,
    path: PathBuf,
    out: PathBuf,
    progress: Option<Py<PyAny>>,
    threads: Option<usize>,
    options: Option<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let mut o = Options::new("estimate_path", options);
    let config = EstimateConfig {
        input: path,
        output: out,
        method: options::method(&mut o)?,
        mask: o.get("mask")?,
        decode: options::decode(&mut o)?,
        cache: options::cache(&mut o)?,
        shard: options::shard(&mut o)?,
        normal_png: symframe_io::NormalPng::OpenGl,
        keep_maps: true,
        near: options::near(&mut o)?,
    };
    o.finish()?;
    let outcome = run_job(py, progress, threads, |ctl| {
        symframe_job::estimate(&config, ctl)
    })?;
    let dict = PyDict::new(py);
    match outcome {
        EstimateOutcome::Maps(done) => {
            let done = *done;
            // The report as written (with the output set the job adds while writing).
            let path = config.output.join("report.json");
            let text = std::fs::read_to_string(&path).map_err(|e| {
                SymframeError::new_err(format!("{}: cannot read: {e}", path.display()))
            })?;
            dict.set_item("report", json_to_py(py, &text)?)?;
            put_maps(py, &dict, kept(done.maps)?)?;
            // Near lights: the depth map along the optical axis the rounds ended with.
            let depth = config.output.join("depth.npy");
            if done.report.near.is_some() && depth.is_file() {
                let (shape, d) = symframe_io::read_npy_f32(&depth)
                    .map_err(|e| SymframeError::new_err(e.to_string()))?;
                dict.set_item("depth", map_array(py, d, shape[0], shape[1], 1)?)?;
            }
        }
        EstimateOutcome::Shard(report) => {
            dict.set_item("report", to_python(py, &*report)?)?;
        }
    }
    Ok(dict)
}

/// An `H x W x C` (or `H x W` for `C = 1`) float32 array of a flat map.
fn map_array<'py>(
    py: Python<'py>,
    v: Vec<f32>,
    h: usize,
    w: usize,
    c: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let a = PyArray1::from_vec(py, v);
    Ok(if c == 1 {
        a.reshape([h, w])?.into_any()
    } else {
        a.reshape([h, w, c])?.into_any()
    })
}

/// The `symframe fit` job: per-pixel Ward or glTF parameters in the frames of an estimate.
#[pyfunction]
#[pyo3(signature = (path, frames, out, progress=None, threads=None, options=None))]
fn fit<'py>(
    py: Python<'py>,
    path: PathBuf,
    frames: PathBuf,
    out: PathBuf,
    progress: Option<Py<PyAny>>,
    threads: Option<usize>,
    options: Option<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let mut o = Options::new("fit", options);
    let d = symframe::FitParams::default();
    let holdout: usize = o.or("holdout", 0)?;
    let model: String = o.or("model", symframe::DEFAULT_MODEL.name().to_string())?;
    let exposure: Option<f64> = o.get("exposure")?;
    let roughness_min: f64 = o.or("roughness_min", d.roughness_min)?;
    let max_iterations: u32 = o.or("max_iterations", d.max_iterations)?;
    let max_peak_ratio: f64 = o.or("max_peak_ratio", d.max_peak_ratio)?;
    let mask: Option<PathBuf> = o.get("mask")?;
    let decode = options::decode(&mut o)?;
    let cache = options::cache(&mut o)?;
    o.finish()?;
    let model: symframe::FitModel = model.parse().map_err(PyValueError::new_err)?;
    if exposure.is_some_and(|e| !(e > 0.0 && e.is_finite())) {
        return Err(PyValueError::new_err(format!(
            "exposure must be positive and finite (or None: chosen from the data), got {}",
            exposure.unwrap_or_default()
        )));
    }
    if !(roughness_min > 0.0 && roughness_min <= 1.0) {
        return Err(PyValueError::new_err(format!(
            "roughness_min must be in (0, 1], got {roughness_min}"
        )));
    }
    if max_iterations == 0 {
        return Err(PyValueError::new_err("max_iterations must be at least 1"));
    }
    if !(max_peak_ratio >= 1.0 && max_peak_ratio.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "max_peak_ratio must be finite and at least 1, got {max_peak_ratio}"
        )));
    }
    let config = symframe_job::FitConfig {
        input: path,
        frames,
        output: out,
        holdout,
        exposure,
        params: symframe::FitParams {
            model,
            roughness_min,
            max_iterations,
            max_peak_ratio,
            ..d
        },
        mask,
        decode,
        cache,
    };
    let done = run_job(py, progress, threads, |ctl| symframe_job::fit(&config, ctl))?;
    let dict = PyDict::new(py);
    dict.set_item("report", to_python(py, &done.report)?)?;
    let m = done.maps;
    let (h, w) = (m.ward.height, m.ward.width);
    // An automatic fit returns both models' maps (NaN where the other was chosen) and the
    // choice per pixel (`model`: 0 none, 1 Ward, 2 glTF, as model.npy).
    let auto = config.params.model == symframe::FitModel::Auto;
    if auto {
        let codes: Vec<f32> = m.model.iter().map(|&c| c as f32).collect();
        dict.set_item("model", map_array(py, codes, h, w, 1)?)?;
    }
    let ward = m.gltf.is_none() || auto;
    if let Some(g) = m.gltf {
        dict.set_item("base_color", map_array(py, g.base_color, h, w, 3)?)?;
        dict.set_item("metallic", map_array(py, g.metallic, h, w, 1)?)?;
        dict.set_item("roughness", map_array(py, g.roughness, h, w, 1)?)?;
        dict.set_item("anisotropy_strength", map_array(py, g.anisotropy, h, w, 1)?)?;
    }
    if ward {
        dict.set_item("kd", map_array(py, m.ward.kd, h, w, 3)?)?;
        dict.set_item("ks", map_array(py, m.ward.ks, h, w, 3)?)?;
        dict.set_item("alpha_t", map_array(py, m.ward.alpha_t, h, w, 1)?)?;
        dict.set_item("alpha_b", map_array(py, m.ward.alpha_b, h, w, 1)?)?;
    }
    dict.set_item("normals", map_array(py, m.ward.normals, h, w, 3)?)?;
    dict.set_item("tangents", map_array(py, m.ward.tangents, h, w, 3)?)?;
    dict.set_item("residual", map_array(py, m.residual, h, w, 1)?)?;
    dict.set_item(
        "holdout_residual",
        map_array(py, m.holdout_residual, h, w, 1)?,
    )?;
    Ok(dict)
}

/// The `symframe relight` job: fitted maps rendered under `lights` (`N x 3`), edited; returns
/// the linear images (`N x H x W x 3` float32) written as `relit_NNN.exr`.
#[pyfunction]
#[pyo3(signature = (fit_dir, out, lights, options=None))]
fn relight<'py>(
    py: Python<'py>,
    fit_dir: PathBuf,
    out: PathBuf,
    lights: PyReadonlyArray2<'py, f64>,
    options: Option<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let mut o = Options::new("relight", options);
    let mut config = symframe_job::RelightConfig::new(fit_dir, out);
    config.diffuse_scale = o.or("diffuse_scale", config.diffuse_scale)?;
    config.specular_scale = o.or("specular_scale", config.specular_scale)?;
    config.roughness_scale = o.or("roughness_scale", config.roughness_scale)?;
    config.rotate_tangents = o.get("rotate_tangents")?;
    config.region = o.get("region")?;
    config.exposure = o.or("exposure", config.exposure)?;
    config.shadows = o.get("shadows")?;
    o.finish()?;
    for (name, v) in [
        ("specular_scale", config.specular_scale),
        ("diffuse_scale", config.diffuse_scale),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "{name} must be finite and >= 0, got {v}"
            )));
        }
    }
    if !(config.roughness_scale > 0.0 && config.roughness_scale.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "roughness_scale must be finite and > 0, got {}",
            config.roughness_scale
        )));
    }
    if !config.exposure.is_finite() || config.rotate_tangents.is_some_and(|d| !d.is_finite()) {
        return Err(PyValueError::new_err(
            "exposure and rotate_tangents must be finite",
        ));
    }
    config.lights = lights_of(&lights)?;
    if config.lights.is_empty()
        || config
            .lights
            .iter()
            .any(|l| !l.is_finite() || *l == DVec3::ZERO)
    {
        return Err(PyValueError::new_err(
            "lights must be N x 3 finite directions, none zero, N >= 1",
        ));
    }
    let (n, (w, h, data)) = run_job(py, None, None, |_| {
        let done = symframe_job::relight(&config)?;
        let mut data = Vec::new();
        let mut size = (0, 0);
        let exr = DecodeOptions {
            gamma: symframe_io::Gamma::Linear,
            saturation: f32::INFINITY,
            ..DecodeOptions::default()
        };
        for png in &done.pictures {
            let img = symframe_io::read_image(&png.with_extension("exr"), &exr)?;
            size = (img.width, img.height);
            data.extend(img.into_rgb());
        }
        Ok((done.pictures.len(), (size.0, size.1, data)))
    })?;
    Ok(PyArray1::from_vec(py, data)
        .reshape([n, h, w, 3])?
        .into_any())
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

/// A dataset's lights, image paths, mask and image size, read without decoding the stack.
#[pyclass(module = "symframe", name = "Dataset", frozen)]
struct Dataset {
    ds: symframe_io::Dataset,
    decode: DecodeOptions,
    width: usize,
    height: usize,
    mask: Option<Vec<bool>>,
}

#[pymethods]
impl Dataset {
    /// Unit light directions, `N x 3` float64 (camera frame, surface toward light).
    #[getter]
    fn lights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let flat: Vec<f64> = self.ds.lights.iter().flat_map(|l| l.to_array()).collect();
        Ok(PyArray1::from_vec(py, flat)
            .reshape([self.ds.lights.len(), 3])?
            .into_any())
    }

    /// The mask (`H x W` bool) of `mask.png` beside the input, or `None`.
    #[getter]
    fn mask<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.mask
            .as_ref()
            .map(|m| {
                Ok(PyArray1::from_vec(py, m.clone())
                    .reshape([self.height, self.width])?
                    .into_any())
            })
            .transpose()
    }

    /// `(N, H, W)`: lights, image height and width.
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        (self.ds.images.len(), self.height, self.width)
    }

    /// Image paths, one per light.
    #[getter]
    fn paths(&self) -> Vec<PathBuf> {
        self.ds.images.clone()
    }

    /// The file or folder the dataset was opened from.
    #[getter]
    fn source(&self) -> PathBuf {
        self.ds.source.clone()
    }

    /// The capture's noise model as the command line reads it from the images (quantisation,
    /// clip level, shot and read noise: report.json's `parameters.noise`), a dict to pass as
    /// `estimate(..., noise=...)` so that an in-memory estimate equals `estimate_path`'s.
    #[getter]
    fn noise<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let model = py
            .detach(|| symframe_io::capture_noise(&self.ds, &self.decode))
            .map_err(|e| to_py(e.into()))?;
        to_python(py, &model)
    }

    /// Decodes every image: `N x H x W x 3` float32, linear, divided by the light intensities,
    /// NaN where saturated or non-finite.
    #[pyo3(signature = (progress=None, threads=None))]
    fn images<'py>(
        &self,
        py: Python<'py>,
        progress: Option<Py<PyAny>>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (n, h, w) = self.shape();
        let stack = run_job(py, progress, threads, |ctl| {
            let done = std::sync::atomic::AtomicU64::new(0);
            let stack = symframe_io::load_stack(&self.ds, &self.decode, &|| {
                let d = done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
                (ctl.progress)(Progress {
                    stage: Stage::Decoding,
                    done: d,
                    total: n as u64,
                });
            })?;
            if (stack.width, stack.height, stack.n_lights) != (w, h, n) {
                anyhow::bail!(
                    "{}: the images changed while reading them",
                    self.ds.source.display()
                );
            }
            let mut out = Vec::with_capacity(n * h * w * 3);
            for i in 0..n {
                out.extend_from_slice(&stack.image(i));
            }
            Ok(out)
        })?;
        Ok(PyArray1::from_vec(py, stack)
            .reshape([n, h, w, 3])?
            .into_any())
    }

    fn __len__(&self) -> usize {
        self.ds.images.len()
    }

    fn __repr__(&self) -> String {
        let (n, h, w) = self.shape();
        format!(
            "symframe.Dataset('{}', {n} lights, {w}x{h}, mask={})",
            self.ds.source.display(),
            self.mask.is_some()
        )
    }
}

/// Opens an `.lp` file, a folder holding one, or a DiLiGenT-style folder.
#[pyfunction]
#[pyo3(signature = (path, linear=false, saturation=None))]
fn load(py: Python<'_>, path: PathBuf, linear: bool, saturation: Option<f32>) -> PyResult<Dataset> {
    let mut decode = DecodeOptions {
        gamma: if linear {
            symframe_io::Gamma::Linear
        } else {
            symframe_io::Gamma::Auto
        },
        ..DecodeOptions::default()
    };
    if let Some(s) = saturation {
        if !(s > 0.0 && s <= 1.0) {
            return Err(PyValueError::new_err(format!(
                "saturation must be in (0, 1], got {s}"
            )));
        }
        decode.saturation = s;
    }
    let (ds, width, height, mask) = py
        .detach(|| -> anyhow::Result<_> {
            let ds = symframe_io::open_dataset(&path)?;
            let first = ds
                .images
                .first()
                .with_context(|| format!("{}: no images", ds.source.display()))?;
            let img = symframe_io::read_image(first, &decode)?;
            let mask = match &ds.mask {
                Some(m) => Some(symframe_io::read_mask(m, img.width, img.height)?),
                None => None,
            };
            Ok((ds, img.width, img.height, mask))
        })
        .map_err(to_py)?;
    Ok(Dataset {
        ds,
        decode,
        width,
        height,
        mask,
    })
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
    let e = py.detach(|| symframe::evaluate(&n, &t, &g, gt.as_deref(), m.as_deref(), max_angle));
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
#[pyo3(signature = (fit_dir, out=None, frames=None))]
fn view(
    py: Python<'_>,
    fit_dir: PathBuf,
    out: Option<PathBuf>,
    frames: Option<PathBuf>,
) -> PyResult<PathBuf> {
    let mut config = symframe_job::ViewConfig::new(fit_dir);
    if let Some(out) = out {
        config.output = out;
    }
    config.frames = frames;
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
