//! The `symframe fit` and `symframe relight` jobs from Python, their maps as numpy arrays.

use std::path::PathBuf;

use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use symframe_io::DecodeOptions;

use crate::arrays::{lights_of, map_array};
use crate::options::{self, Options};
use crate::runner::run_job;
use crate::to_python;

/// The `symframe fit` job: per-pixel Ward or glTF parameters in the frames of an estimate.
#[pyfunction]
#[pyo3(signature = (path, frames, out, progress=None, threads=None, options=None))]
pub(crate) fn fit<'py>(
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
    let model: String = o.or("model", symframe::FitModel::DEFAULT.name().to_string())?;
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
pub(crate) fn relight<'py>(
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
    config.from_samples = o
        .get::<PathBuf>("from_samples")?
        .map(|capture| (capture, DecodeOptions::default()));
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
