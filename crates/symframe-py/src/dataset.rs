//! `Dataset`: a capture's lights, image paths, mask and size, read without decoding it, and its
//! stack and noise model on demand.

use std::path::PathBuf;

use anyhow::Context;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use symframe_io::DecodeOptions;
use symframe_job::{Progress, Stage};

use crate::runner::{run_job, to_py};
use crate::to_python;

/// A dataset's lights, image paths, mask and image size, read without decoding the stack.
#[pyclass(module = "symframe", name = "Dataset", frozen)]
pub(crate) struct Dataset {
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
pub(crate) fn load(
    py: Python<'_>,
    path: PathBuf,
    linear: bool,
    saturation: Option<f32>,
) -> PyResult<Dataset> {
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
