//! Numpy arrays of maps and lights.

use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use symframe::EstimateMaps;

use crate::SymframeError;

/// The maps a job kept in memory (it was asked to), else an error.
pub(crate) fn kept(maps: Option<EstimateMaps>) -> PyResult<EstimateMaps> {
    maps.ok_or_else(|| SymframeError::new_err("the job kept no maps in memory"))
}

/// The maps as numpy arrays in `dict`.
pub(crate) fn put_maps<'py>(
    py: Python<'py>,
    dict: &Bound<'py, PyDict>,
    maps: EstimateMaps,
) -> PyResult<()> {
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
pub(crate) fn lights_of(lights: &PyReadonlyArray2<f64>) -> PyResult<Vec<DVec3>> {
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

/// An `H x W x C` (or `H x W` for `C = 1`) float32 array of a flat map.
pub(crate) fn map_array<'py>(
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
