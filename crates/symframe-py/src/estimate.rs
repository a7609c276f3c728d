//! Estimation from Python: in memory from numpy arrays (the core's estimators over bands of
//! rows) and the tiled job of `symframe estimate`; the maps as numpy arrays.

use std::path::PathBuf;

use numpy::{PyReadonlyArray2, PyReadonlyArray4, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use symframe::{BaselineMethod, EstimateMaps, Estimator, PixelMethod, PixelRecord, Rig, Stack};
use symframe_job::{EstimateConfig, EstimateOutcome, MethodConfig, Progress, Sources, Stage};

use crate::arrays::{kept, lights_of, map_array, put_maps};
use crate::options::{self, Options};
use crate::runner::run_job;
use crate::{json_to_py, to_python, SymframeError};

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
        records.extend(stack.run(method, band_mask, &|_| {}));
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
pub(crate) fn estimate_arrays<'py>(
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
                Stack::check_inputs(w, h, n, rig.n_input(), mask)?;
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
                Stack::check_inputs(w, h, n, b.unit_lights().len(), mask)?;
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
pub(crate) fn estimate_path<'py>(
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
