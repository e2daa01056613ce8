"""The four `scipy.ndimage` filters the firmware uses, without importing `scipy.ndimage`.

Why: importing `scipy.ndimage` costs about 0.2 CPU s of every game's start
(0.45 s in all, a tenth of a short game): its array-API layer clones numpy's
namespace, which imports ``numpy.f2py``, ``numpy.testing``, ``numpy.ma`` and
``numpy.polynomial``, and its interpolation module imports `scipy.special`.
The filters themselves are scipy's compiled kernels, in the extension modules
``scipy.ndimage._nd_image`` and ``scipy.ndimage._ni_label``; this module loads
those two from scipy's directory (registered under their own names, so a later
``import scipy.ndimage`` reuses them) and repeats, for the arguments the
firmware passes, what scipy's Python wrappers do around them: the same
kernels on the same arrays give the same values, bit for bit
(``tests/test_ndimage.py`` compares each function with scipy's).

Where the kernels cannot be loaded (a scipy laid out otherwise), the public
`scipy.ndimage` functions are used instead, at the import's cost.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
from types import ModuleType

import numpy as np

__all__ = ["correlate1d", "gaussian_filter1d", "gaussian_weights", "label",
           "distance_transform_edt", "KERNELS"]

_MODE_CODES = {"nearest": 0, "wrap": 1, "reflect": 2, "grid-mirror": 2, "mirror": 3,
               "constant": 4, "grid-wrap": 1, "grid-constant": 4}
"""scipy's boundary mode codes for the 1-D filters (``_ni_support._extend_mode_to_code``
with ``is_filter=True``)."""


def _load(name: str) -> ModuleType | None:
    """scipy's extension module ``scipy.ndimage.<name>`` without its package's
    ``__init__``; None when it cannot be found or loaded."""
    full = f"scipy.ndimage.{name}"
    if full in sys.modules:
        return sys.modules[full]
    try:
        import scipy  # noqa: PLC0415 - the package alone (a few ms), for its directory
        folder = os.path.join(scipy.__path__[0], "ndimage")
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = os.path.join(folder, name + suffix)
            if os.path.exists(path):
                spec = importlib.util.spec_from_file_location(full, path)
                if spec is None or spec.loader is None:
                    return None
                module = importlib.util.module_from_spec(spec)
                sys.modules[full] = module  # one copy per process, whoever imports it
                try:
                    spec.loader.exec_module(module)
                except BaseException:
                    del sys.modules[full]
                    raise
                return module
    except (ImportError, OSError):
        return None
    return None


_nd_image = _load("_nd_image")
_ni_label = _load("_ni_label") if _nd_image is not None else None
KERNELS = (_nd_image is not None and _ni_label is not None
           and hasattr(_nd_image, "correlate1d")
           and hasattr(_nd_image, "euclidean_feature_transform")
           and hasattr(_ni_label, "_label"))
"""True when scipy's kernels are called directly (False: through `scipy.ndimage`)."""


def correlate1d(values: np.ndarray, weights: np.ndarray, axis: int, mode: str) -> np.ndarray:
    """``scipy.ndimage.correlate1d(values, weights, axis, mode=mode)`` (cval 0, origin 0)
    for a real array: a new array of ``values``' dtype.

    Raises:
        ValueError: a complex array, an unknown mode, or no weights.
    """
    if not KERNELS:
        from scipy import ndimage  # noqa: PLC0415
        return ndimage.correlate1d(values, weights, axis=axis, mode=mode)
    a = np.asarray(values)
    if a.dtype.kind == "c":
        raise ValueError("correlate1d takes a real array, got a complex one")
    if mode not in _MODE_CODES:
        raise ValueError(f"mode must be one of {', '.join(_MODE_CODES)}, got {mode!r}")
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.shape[0] < 1:
        raise ValueError(f"weights must be a non-empty 1-D array, got shape {w.shape}")
    if not w.flags.contiguous:
        w = w.copy()
    # what scipy's _get_output makes (the dtype's name: native byte order; `name` is a
    # Python property, so a native dtype is taken as it is)
    out = np.zeros(a.shape, dtype=a.dtype if a.dtype.isnative else a.dtype.name)
    _nd_image.correlate1d(a, w, axis % a.ndim, out, _MODE_CODES[mode], 0.0, 0)
    return out


def gaussian_weights(sigma: float) -> np.ndarray:
    """The weights ``scipy.ndimage.gaussian_filter1d`` (order 0, truncated at 4 sigma)
    correlates with, computed as scipy computes them: a new contiguous array.

    ``correlate1d(values, gaussian_weights(sigma), axis, mode)`` is
    `gaussian_filter1d`'s result; a caller that filters often with one sigma keeps the
    weights instead of computing them for every call.
    """
    radius = int(4.0 * float(sigma) + 0.5)
    x = np.arange(-radius, radius + 1)
    phi = np.exp(-0.5 / (sigma * sigma) * x ** 2)
    phi = phi / phi.sum()
    return phi[::-1].copy()


def gaussian_filter1d(values: np.ndarray, sigma: float, axis: int, mode: str) -> np.ndarray:
    """``scipy.ndimage.gaussian_filter1d(values, sigma, axis, mode=mode)`` (order 0,
    truncated at 4 sigma), its kernel computed as scipy computes it."""
    if not KERNELS:
        from scipy import ndimage  # noqa: PLC0415
        return ndimage.gaussian_filter1d(values, sigma, axis=axis, mode=mode)
    return correlate1d(values, gaussian_weights(sigma), axis, mode)


def label(mask: np.ndarray, structure: np.ndarray) -> tuple[np.ndarray, int]:
    """``scipy.ndimage.label(mask, structure)`` for a 2-D mask and a 3 x 3 structure:
    int32 labels and their count.

    Raises:
        ValueError: ``structure`` is not 3 x 3, or ``mask`` not 2-D.
    """
    if not KERNELS:
        from scipy import ndimage  # noqa: PLC0415
        return ndimage.label(mask, structure=structure)
    a = np.asarray(mask)
    s = np.asarray(structure, dtype=bool)
    if a.ndim != 2 or s.shape != (3, 3):
        raise ValueError(f"label takes a 2-D mask and a 3 x 3 structure, got {a.shape} "
                         f"and {s.shape}")
    out = np.empty(a.shape, np.int32)
    if a.size == 0:
        return out, 0
    return out, int(_ni_label._label(a, s, out))


def distance_transform_edt(mask: np.ndarray, sampling: float) -> np.ndarray:
    """``scipy.ndimage.distance_transform_edt(mask, sampling=sampling)`` for a 2-D mask
    and one sampling for both axes: the distance of each non-zero cell to the nearest
    zero cell, in the units of ``sampling``.

    The distances are scipy's floats: the same whole-cell offsets to the nearest zero
    cell (scipy's feature transform), scaled, squared and summed in the same order.
    They are formed one axis at a time against a broadcast row or column index instead
    of scipy's full index grid (two fewer whole-grid arrays, and no integer copy of the
    offsets).
    """
    if not KERNELS:
        from scipy import ndimage  # noqa: PLC0415
        return ndimage.distance_transform_edt(mask, sampling=sampling)
    a = np.where(mask, 1, 0).astype(np.int8)
    if a.ndim != 2:
        raise ValueError(f"distance_transform_edt takes a 2-D mask, got {a.ndim}-D")
    scale = float(sampling)
    ft = np.zeros((2, *a.shape), dtype=np.int32)
    _nd_image.euclidean_feature_transform(a, np.array([scale, scale]), ft)
    ny, nx = a.shape
    dy = np.subtract(ft[0], np.arange(ny, dtype=np.int32)[:, None], dtype=np.float64)
    dx = np.subtract(ft[1], np.arange(nx, dtype=np.int32), dtype=np.float64)
    dy *= scale
    dx *= scale
    dy *= dy
    dx *= dx
    dy += dx
    return np.sqrt(dy, out=dy)
