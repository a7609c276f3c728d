"""Type stub of the symframe package (see ``__init__.py`` for the full documentation)."""

import os
from typing import Any, Callable, Dict, List, Optional, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

PathLike = Union[str, os.PathLike[str]]
Progress = Callable[[str, int, int], Any]

__version__: str

class SymframeError(RuntimeError):
    """A job failed; the message is the command line's one-line error."""

class Dataset:
    """A capture's lights, image paths, mask and size (images decoded on request)."""

    @property
    def lights(self) -> npt.NDArray[np.float64]:
        """Unit light directions, N x 3 (camera frame, surface toward light)."""
    @property
    def mask(self) -> Optional[npt.NDArray[np.bool_]]:
        """H x W mask of the dataset's mask.png, or None."""
    @property
    def shape(self) -> Tuple[int, int, int]:
        """(N, H, W)."""
    @property
    def paths(self) -> List[str]:
        """Image paths, one per light."""
    @property
    def source(self) -> str:
        """The file or folder the dataset was opened from."""
    @property
    def noise(self) -> Dict[str, Any]:
        """The capture's noise model as the command line reads it (pass to estimate(noise=))."""
    def images(
        self, progress: Optional[Progress] = None, threads: Optional[int] = None
    ) -> npt.NDArray[np.float32]:
        """Every image decoded: N x H x W x 3 float32, linear, NaN where saturated."""
    def __len__(self) -> int: ...

class Maps(TypedDict, total=False):
    """What estimate and estimate_path return (a shard: ``report`` only)."""

    normals: npt.NDArray[np.float32]
    tangents: npt.NDArray[np.float32]
    confidence: npt.NDArray[np.float32]
    anisotropy: npt.NDArray[np.float32]
    source: npt.NDArray[np.uint8]
    report: Dict[str, Any]

def load(path: PathLike, *, linear: bool = False, saturation: Optional[float] = None) -> Dataset:
    """Opens an .lp file, a folder holding one, or a DiLiGenT-style folder."""

def estimate(
    images: npt.NDArray[np.floating[Any]],
    lights: npt.NDArray[np.floating[Any]],
    mask: Optional[npt.NDArray[np.bool_]] = None,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
    method: str = "symmetry",
    theta_d_max: float = 65.0,
    min_confidence: float = 0.0,
    min_anisotropy: float = 0.6,
    light_error: Optional[float] = None,
    noise: Optional[Dict[str, Any]] = None,
    min_domain: Optional[int] = None,
    cosine: str = "auto",
    cosine_power: float = 0.5,
    fallback: str = "auto",
    no_tangents: bool = False,
    reference: bool = False,
) -> Maps:
    """Normals and tangents of an N x H x W x 3 stack held in memory."""

def estimate_path(
    path: PathLike,
    out: Optional[PathLike] = None,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
    method: str = "symmetry",
    theta_d_max: float = 65.0,
    min_confidence: float = 0.0,
    min_anisotropy: float = 0.6,
    light_error: Optional[float] = None,
    noise: Optional[Dict[str, Any]] = None,
    min_domain: Optional[int] = None,
    cosine: str = "auto",
    cosine_power: float = 0.5,
    fallback: str = "auto",
    no_tangents: bool = False,
    reference: bool = False,
    mask: Optional[PathLike] = None,
    linear: bool = False,
    gamma: Optional[str] = None,
    saturation: float = 0.995,
    cache: Optional[PathLike] = None,
    no_keep_cache: bool = False,
    trust_mtime: bool = False,
    tiles: Optional[str] = None,
    tile_size: int = 32,
    decode_memory: int = 1024,
    cache_format: str = "auto",
    light_model: str = "auto",
    distance: Optional[float] = None,
    rig_tile: int = 8,
    rounds: int = 5,
) -> Maps:
    """The tiled, resumable `symframe estimate` job."""

def merge(
    shards: List[PathLike],
    out: PathLike,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
) -> Maps:
    """The `symframe merge` job: the shards' folders joined into the full maps in `out`."""

def evaluate(
    normals: npt.NDArray[np.floating[Any]],
    gt_normals: npt.NDArray[np.floating[Any]],
    tangents: Optional[npt.NDArray[np.floating[Any]]] = None,
    gt_tangents: Optional[npt.NDArray[np.floating[Any]]] = None,
    *,
    mask: Optional[npt.NDArray[np.bool_]] = None,
    max_angle: float = 60.0,
) -> Dict[str, Any]:
    """The figures of `symframe eval`."""

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
    """Renders a synthetic capture into a dataset folder; returns its .lp path."""

def fit(
    path: PathLike,
    frames: PathLike,
    out: PathLike,
    *,
    progress: Optional[Progress] = None,
    threads: Optional[int] = None,
    model: str = "gltf",
    exposure: Optional[float] = None,
    roughness_min: float = 0.07,
    holdout: int = 0,
    max_iterations: int = 60,
    max_peak_ratio: float = 8.0,
    mask: Optional[PathLike] = None,
    linear: bool = False,
    gamma: Optional[str] = None,
    saturation: float = 0.995,
    cache: Optional[PathLike] = None,
    no_keep_cache: bool = False,
) -> Dict[str, Any]:
    """The `symframe fit` job: glTF maps (base_color, metallic, roughness,
    anisotropy_strength) or Ward maps (kd, ks, alpha_t, alpha_b), frames and its report."""

def integrate(
    estimate: PathLike,
    out: PathLike,
    *,
    solver: str = "bilateral",
    k: float = 10.0,
    tolerance: float = 1e-7,
    use_confidence: bool = True,
    max_jump: float = 2.0,
) -> Dict[str, Any]:
    """The `symframe integrate` job: {"depth": H x W float32, "report": integrate.json}."""
    ...

def relight(
    fit_dir: PathLike,
    out: PathLike,
    lights: npt.ArrayLike,
    *,
    diffuse_scale: float = 1.0,
    specular_scale: float = 1.0,
    roughness_scale: float = 1.0,
    rotate_tangents: Optional[float] = None,
    region: Optional[PathLike] = None,
    exposure: float = 0.0,
    shadows: Optional[PathLike] = None,
) -> npt.NDArray[np.float32]:
    """The `symframe relight` job: N x H x W x 3 linear images, also written to `out`."""

def view(
    fit_dir: PathLike,
    out: Optional[PathLike] = None,
    *,
    frames: Optional[PathLike] = None,
    from_samples: Optional[PathLike] = None,
) -> str:
    """`symframe view`: the fit's self-contained HTML viewer page; returns its path."""
