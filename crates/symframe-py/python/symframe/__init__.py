"""symframe: per-pixel surface normals and tangents from photometric stacks by BRDF symmetry.

numpy in, numpy out; the same jobs as the ``symframe`` command line, with keyword options named
like its flags (``theta_d_max`` for ``--theta-d-max``). Computation runs with the GIL released;
Ctrl-C stops a job after the images or tiles in progress (``KeyboardInterrupt``; a tiled job
resumes when called again with the same arguments). A job that fails raises
:class:`SymframeError` with the command line's one-line message.

Example::

    import symframe
    ds = symframe.load("capture/lights.lp")
    result = symframe.estimate(ds.images(), ds.lights, ds.mask)
    normals = result["normals"]          # (H, W, 3) float32, NaN where no estimate

Progress: every job takes ``progress=callable(stage, done, total)``, called (at most about ten
times a second per stage, always for the first and last step) with the stage name
(``"decoding"``, ``"tiles"``, ``"merging"``) and its steps; an exception raised by it stops the
job like Ctrl-C and is re-raised.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from typing import Any, Callable, Dict, Optional, Union

import numpy as np

from . import _native
from ._native import Dataset, SymframeError

__all__ = [
    "Dataset",
    "SymframeError",
    "load",
    "estimate",
    "estimate_path",
    "evaluate",
    "fit",
    "merge",
    "relight",
    "integrate",
    "synth",
    "view",
    "__version__",
]

__version__: str = _native.__version__

PathLike = Union[str, "os.PathLike[str]"]
Progress = Callable[[str, int, int], Any]


def load(path: PathLike, *, linear: bool = False, saturation: Optional[float] = None) -> Dataset:
    """Opens a capture: an ``.lp`` light file, a folder holding one, or a DiLiGenT-style folder.

    Reads the light directions, the mask (``mask.png`` beside the input) and the first image's
    size; the images are decoded only by :meth:`Dataset.images`. ``linear`` and ``saturation``
    are the command line's ``--linear`` and ``--saturation`` (how 8-bit images are decoded and
    which integer samples count as saturated).
    """
    return _native.load(os.fspath(path), linear, saturation)


def _float_array(name: str, value: Any, ndim: int, last: Optional[int], dtype: Any) -> np.ndarray:
    """``value`` as a C-contiguous array of ``dtype``, after checking its type and shape."""
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{name} must be a numpy array, got {type(value).__name__}")
    if not np.issubdtype(value.dtype, np.floating):
        hint = ""
        if np.issubdtype(value.dtype, np.integer):
            hint = " (linear values: convert integer pixels yourself, e.g. a.astype(np.float32) / 65535)"
        raise TypeError(f"{name} must be a float array, got dtype {value.dtype}{hint}")
    if value.ndim != ndim or (last is not None and value.shape[-1] != last):
        want = {4: "N x H x W x 3", 3: "H x W x 3", 2: "N x 3"}[ndim]
        raise ValueError(f"{name} must be {want}, got shape {value.shape}")
    if value.size == 0:
        raise ValueError(f"{name} is empty (shape {value.shape})")
    return np.ascontiguousarray(value, dtype=dtype)


def _mask_array(mask: Any, shape: tuple) -> Optional[np.ndarray]:
    if mask is None:
        return None
    if not isinstance(mask, np.ndarray):
        raise TypeError(f"mask must be a numpy array or None, got {type(mask).__name__}")
    if mask.dtype != np.bool_:
        raise TypeError(f"mask must be a bool array, got dtype {mask.dtype} (use mask != 0)")
    if mask.shape != shape:
        raise ValueError(f"mask must be H x W = {shape[0]} x {shape[1]} like the images, got shape {mask.shape}")
    return np.ascontiguousarray(mask)


def estimate(
    images: np.ndarray,
    lights: np.ndarray,
    mask: Optional[np.ndarray] = None,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
    **options: Any,
) -> Dict[str, Any]:
    """Estimates normals and tangents of an image stack held in memory.

    ``images``: ``N x H x W x 3`` float array (linear radiance divided by the light intensity,
    NaN for samples to ignore); ``lights``: ``N x 3`` directions (camera frame: x right, y up,
    z toward the camera; surface toward light); ``mask``: ``H x W`` bool or ``None``.

    Options (the command line's flags of the method): ``method`` (``"symmetry"``, or a
    baseline: ``"woodham"``, ``"woodham-robust"``, ``"max-reflectance"``,
    ``"highlight-centroid"``), ``theta_d_max``, ``min_confidence``, ``min_anisotropy``,
    ``light_error`` (the lights' RMS error in degrees: the confidence counts it), ``noise`` (the
    capture's noise model, a dict as :attr:`Dataset.noise` reads it from the images; default
    noise-free), ``min_domain``, ``cosine`` (``"auto"``, ``"cross"``, ``"raw"``, ``"compensated"``),
    ``cosine_power``, ``fallback`` (``"auto"``, ``"none"``), ``no_tangents``, ``reference``;
    ``threads`` (worker threads, default all cores).

    Returns a dict: ``normals``, ``tangents`` (``H x W x 3`` float32, NaN where none),
    ``confidence``, ``anisotropy``, ``tangent_confidence`` (``H x W`` float32; the last 0 where
    there is no tangent), ``source`` (``H x W`` uint8: 0 none, 1 symmetry, 2 Lambertian,
    3 highlight, 4 lobe) and ``report`` (method, parameters, light and pixel
    counts). With ``noise=ds.noise`` the maps equal those of :func:`estimate_path` on the same
    data bit for bit (the command line reads the noise model from the images).
    """
    images = _float_array("images", images, 4, 3, np.float32)
    lights = _float_array("lights", lights, 2, 3, np.float64)
    if lights.shape[0] != images.shape[0]:
        raise ValueError(f"{images.shape[0]} images but {lights.shape[0]} lights")
    mask = _mask_array(mask, images.shape[1:3])
    return _native.estimate_arrays(images, lights, mask, progress, threads, options)


def estimate_path(
    path: PathLike,
    out: Optional[PathLike] = None,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
    **options: Any,
) -> Dict[str, Any]:
    """Runs the ``symframe estimate`` job: tiled, bounded memory, resumable.

    ``path``: an ``.lp`` file, a folder holding one, or a DiLiGenT-style folder. ``out``: the
    output folder, written as the command line writes it (maps as ``.npy``/``.exr``/``.png``,
    ``report.json``, the tile cache ``.symframe-cache``); an interrupted call resumes when made
    again with the same arguments. Without ``out`` the job runs in a temporary folder that is
    removed afterwards (nothing is kept for a rerun).

    Options: those of :func:`estimate`, and ``mask`` (a mask image path), ``linear``,
    ``gamma`` (``"srgb"`` or ``"linear"``: the curve of 8- and 16-bit images), ``saturation``,
    ``cache`` (folder), ``no_keep_cache``, ``trust_mtime``, ``tiles`` (``"K/N"``: one shard;
    then only ``report`` is returned), ``tile_size``, ``decode_memory`` (MiB), ``cache_format``
    (``"auto"``, ``"u8"``, ``"u16"``, ``"f32"`` or ``"f16"``, as ``--cache-format``).

    Near lights: where the folder holds ``light_positions.txt`` and ``K.txt`` they are used as
    ``symframe estimate`` uses them (the normals and tangents in the camera frame); options
    ``light_model`` (``"auto"``, ``"near"`` or ``"distant"``), ``distance`` (the depth of the
    object's centre along the optical axis, in the positions' unit; default the centre of the
    sphere through the lights), ``rig_tile`` and ``rounds``, as ``--light-model``,
    ``--distance``, ``--rig-tile`` and ``--rounds``.

    Returns the maps as :func:`estimate` does and ``report``: the content of ``report.json``
    (with near lights its ``near`` section, and ``depth``: ``H x W`` float32, the depth along
    the optical axis, NaN outside the mask).
    """
    if out is not None:
        return _native.estimate_path(os.fspath(path), os.fspath(out), progress, threads, options)
    tmp = tempfile.mkdtemp(prefix="symframe-")
    try:
        return _native.estimate_path(os.fspath(path), os.path.join(tmp, "out"), progress, threads, options)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def merge(
    shards: "list[PathLike]",
    out: PathLike,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
) -> Dict[str, Any]:
    """Runs the ``symframe merge`` job: joins the output folders of the shards of one
    :func:`estimate_path` job (``tiles="K/N"``, every ``K`` from 1 to ``N``) into the full maps.

    ``out`` is written as the command line writes it. Returns the maps as :func:`estimate_path`
    does (the same as an unsharded run's, bit for bit) and ``report``: the content of
    ``report.json``. Missing shards, shards of another job or the same shard twice raise
    :class:`SymframeError` naming the folder.
    """
    if isinstance(shards, (str, os.PathLike)):
        raise TypeError("shards must be a list of shard folders, not one path")
    folders = [os.fspath(s) for s in shards]
    if not folders:
        raise ValueError("shards is empty: give the output folders of every shard")
    return _native.merge(folders, os.fspath(out), progress, threads)


def evaluate(
    normals: np.ndarray,
    gt_normals: np.ndarray,
    tangents: Optional[np.ndarray] = None,
    gt_tangents: Optional[np.ndarray] = None,
    *,
    mask: Optional[np.ndarray] = None,
    max_angle: float = 60.0,
) -> Dict[str, Any]:
    """The figures of ``symframe eval``: estimated maps against ground truth.

    Maps are ``H x W x 3`` (NaN = none); only pixels inside ``mask`` whose true normal is
    within ``max_angle`` degrees of the view count. Returns ``pixels``, ``coverage``,
    ``normal_error`` (``count``, ``mean``, ``median``, ``p90``, ``max``, degrees),
    ``tangent_coverage``, ``tangent_error``, ``tangent_error_swap_free``, ``swapped_share``.
    """
    if not 0 < max_angle <= 90:
        raise ValueError(f"max_angle must be in (0, 90] degrees, got {max_angle}")
    normals = _float_array("normals", normals, 3, 3, np.float32)
    shape = normals.shape
    gt_normals = _float_array("gt_normals", gt_normals, 3, 3, np.float32)
    checked = {"gt_normals": gt_normals}
    if tangents is not None:
        tangents = checked["tangents"] = _float_array("tangents", tangents, 3, 3, np.float32)
    if gt_tangents is not None:
        gt_tangents = checked["gt_tangents"] = _float_array("gt_tangents", gt_tangents, 3, 3, np.float32)
    for name, a in checked.items():
        if a.shape != shape:
            raise ValueError(f"{name} has shape {a.shape} but normals have {shape}")
    mask = _mask_array(mask, shape[:2])
    return _native.evaluate(normals, gt_normals, tangents, gt_tangents, mask, float(max_angle))


def fit(
    path: PathLike,
    frames: PathLike,
    out: PathLike,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
    **options: Any,
) -> Dict[str, Any]:
    """Runs the ``symframe fit`` job: a BRDF per pixel in estimated frames.

    ``path``: the capture; ``frames``: the output folder of :func:`estimate_path` for it (its
    tile cache is reused, so nothing is decoded again); ``out``: the output folder (maps as
    ``.npy``, ``fit.json``). Options: ``model`` (``"auto"``, the default: per pixel
    whichever of the two models below predicts the pixel's validation lights better;
    ``"gltf"``: glTF 2.0 metallic-roughness with KHR_materials_anisotropy; ``"ward"``:
    anisotropic Ward), ``exposure`` (glTF and auto: the lights' intensity; ``None``, the
    default, chooses it from the data), ``roughness_min``, ``holdout`` (lights left out of the fit to judge it),
    ``max_iterations``, ``max_peak_ratio``, ``mask``, ``linear``, ``gamma``, ``saturation``, ``cache``,
    ``no_keep_cache``.

    Returns ``normals``, ``tangents``, ``residual``, ``holdout_residual``, ``report`` and the
    model's maps: glTF ``base_color`` (``H x W x 3``), ``metallic``, ``roughness``,
    ``anisotropy_strength`` (``H x W``); Ward ``kd``, ``ks`` (``H x W x 3``), ``alpha_t``,
    ``alpha_b`` (``H x W``); an automatic fit both (NaN where the other model was chosen)
    and ``model`` (``H x W``: 0 not fitted, 1 Ward, 2 glTF).
    """
    return _native.fit(os.fspath(path), os.fspath(frames), os.fspath(out), progress, threads, options)


def relight(fit_dir: PathLike, out: PathLike, lights: Any, **options: Any) -> np.ndarray:
    """Runs the ``symframe relight`` job: the fitted maps of :func:`fit` under new lights.

    ``lights``: ``N x 3`` directions (or one ``(x, y, z)``). Options: ``diffuse_scale``,
    ``specular_scale``, ``roughness_scale``, ``rotate_tangents`` (degrees), ``region`` (mask
    image limiting the rotation), ``exposure`` (stops, pictures only), ``shadows`` (a
    ``depth.npy`` of :func:`integrate` whose cast shadows darken the images),
    ``from_samples`` (a capture: its photographs relit themselves in the fit's frames, with no
    model and no edits, as ``symframe relight --from-samples``). Writes
    ``relit_NNN.exr``/``.png`` into ``out`` and returns the linear images, ``N x H x W x 3``
    float32.
    """
    lights = np.asarray(lights, dtype=np.float64)
    if lights.ndim == 1:
        lights = lights[None, :]
    lights = _float_array("lights", lights, 2, 3, np.float64)
    return _native.relight(os.fspath(fit_dir), os.fspath(out), lights, options)


def view(
    fit_dir: PathLike,
    out: Optional[PathLike] = None,
    *,
    frames: Optional[PathLike] = None,
    from_samples: Optional[PathLike] = None,
) -> str:
    """Runs ``symframe view``: writes one self-contained HTML page that relights the fit in
    ``fit_dir`` (a :func:`fit` output folder) in the browser, with the model and edits of
    :func:`relight`; returns its path.

    ``out``: the file (default ``fit_dir/viewer.html``). ``frames``: the estimate's output
    folder, for the confidence, anisotropy and source views (default: the one ``fit.json``
    records, if it is still there; otherwise a ``UserWarning`` says they are left out). The URL
    fragment sets the state, e.g. ``viewer.html#light=0.3,0.4,0.87&exposure=1``.
    ``from_samples``: a capture whose photographs the view ``samples`` relights themselves in
    the fit's frames, with no model, as :func:`relight` with ``from_samples`` (embedded in the
    page: up to 254 lights and 512 MiB of half floats).
    """
    return os.fspath(
        _native.view(
            os.fspath(fit_dir),
            None if out is None else os.fspath(out),
            None if frames is None else os.fspath(frames),
            None if from_samples is None else os.fspath(from_samples),
        )
    )


def integrate(estimate: PathLike, out: PathLike, **options: Any) -> Dict[str, Any]:
    """Runs the ``symframe integrate`` job: the normals of an :func:`estimate_path` folder to a
    height map and a mesh (``depth.npy``, ``depth.exr``, ``depth.png``, ``mesh.ply``,
    ``integrate.json`` in ``out``).

    Options: ``solver`` (``"bilateral"``, the default, or ``"poisson"``), ``k`` (bilateral
    sharpness, 10), ``tolerance`` (conjugate gradients, 1e-7), ``use_confidence`` (weight by
    ``confidence.npy``, True), ``max_jump`` (mesh discontinuities, 2 pixels). Returns
    ``{"depth": H x W float32 (NaN outside), "report": the content of integrate.json}``.
    """
    return _native.integrate(os.fspath(estimate), os.fspath(out), options)


def synth(
    out: PathLike,
    *,
    shape: str = "sphere",
    size: int = 64,
    lights: int = 1000,
    theta_d_max: float = 65.0,
    model: str = "ward",
    tangent_field: str = "circular",
    format: str = "exr",
) -> str:
    """Renders a synthetic capture into the dataset folder ``out`` (as ``symframe synth``).

    A ``"sphere"`` or ``"cylinder"`` of ``size`` pixels, the reflectance ``model`` spec of
    ``symframe synth --model`` (e.g. ``"ward:kd=0.5,ks=0.5,ax=0.1,ay=0.5"``, ``"lambertian"``),
    a ``"circular"`` or ``"radial"`` tangent field, ``lights`` lights uniform over the cone of
    halfway angles up to ``theta_d_max`` degrees, images as ``"exr"``, ``"png16"`` or
    ``"png8"``. Writes ``images/``, ``lights.lp``, ``gt_normals.npy``, ``gt_tangents.npy`` and
    ``mask.png``; returns the ``.lp`` path. A non-empty folder that synth did not write is
    refused.
    """
    return os.fspath(
        _native.synth(os.fspath(out), shape, size, lights, theta_d_max, model, tangent_field, format)
    )
