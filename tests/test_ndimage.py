"""actors.firmware.ndimage: scipy's filters without importing scipy.ndimage, same values."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy import ndimage as sp

from actors.firmware import ndimage as fw


def _rng() -> np.random.Generator:
    return np.random.default_rng(17)


def test_the_kernels_are_called_directly() -> None:
    assert fw.KERNELS


@pytest.mark.parametrize("mode", ["constant", "nearest", "wrap", "reflect", "mirror"])
@pytest.mark.parametrize("axis", [0, 1, -1])
def test_correlate1d_gives_scipys_floats(mode: str, axis: int) -> None:
    rng = _rng()
    values = rng.random((37, 53))
    weights = np.convolve(np.convolve([0.25, 0.5, 0.25], [0.25, 0.5, 0.25]), [0.25, 0.5, 0.25])
    ours = fw.correlate1d(values, weights, axis=axis, mode=mode)
    theirs = sp.correlate1d(values, weights, axis=axis, mode=mode)
    assert ours.dtype == theirs.dtype
    assert np.array_equal(ours, theirs)


def test_correlate1d_of_a_strided_view_and_float32() -> None:
    rng = _rng()
    values = rng.random((40, 60))[::2, 1::3]
    w = np.array([0.1, 0.7, 0.2])[::-1]
    assert np.array_equal(fw.correlate1d(values, w, 1, "constant"),
                          sp.correlate1d(values, w, axis=1, mode="constant"))
    v32 = values.astype(np.float32)
    ours = fw.correlate1d(v32, w, 0, "nearest")
    assert ours.dtype == np.float32
    assert np.array_equal(ours, sp.correlate1d(v32, w, axis=0, mode="nearest"))


def test_correlate1d_refuses_a_bad_mode_and_empty_weights() -> None:
    with pytest.raises(ValueError, match="mode must be one of"):
        fw.correlate1d(np.zeros((3, 3)), [1.0], 0, "sideways")
    with pytest.raises(ValueError, match="non-empty 1-D"):
        fw.correlate1d(np.zeros((3, 3)), [], 0, "constant")


@pytest.mark.parametrize("sigma", [1, 1.0, 1.5, 2.3])
@pytest.mark.parametrize("mode", ["nearest", "wrap"])
def test_gaussian_filter1d_gives_scipys_floats(sigma: float, mode: str) -> None:
    values = _rng().random((9, 30, 24))
    for axis in range(3):
        assert np.array_equal(fw.gaussian_filter1d(values, sigma, axis=axis, mode=mode),
                              sp.gaussian_filter1d(values, sigma, axis=axis, mode=mode))


def test_label_gives_scipys_labels_and_count() -> None:
    eight = np.ones((3, 3), dtype=bool)
    four = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)
    mask = _rng().random((120, 90)) < 0.3
    for structure in (eight, four):
        ours, n = fw.label(mask, structure)
        theirs, m = sp.label(mask, structure=structure)
        assert n == m > 1
        assert ours.dtype == np.int32
        assert np.array_equal(ours, theirs)
    empty, n = fw.label(np.zeros((0, 4), dtype=bool), eight)
    assert n == 0 and empty.shape == (0, 4)


def test_distance_transform_edt_gives_scipys_distances() -> None:
    mask = _rng().random((70, 110)) < 0.97
    for sampling in (1, 5.0, 2.5):
        assert np.array_equal(fw.distance_transform_edt(mask, sampling=sampling),
                              sp.distance_transform_edt(mask, sampling=sampling))


def test_the_firmwares_filters_do_not_import_scipy_ndimage() -> None:
    """In a fresh process: the firmware's modules load the kernels alone, the kernels
    work, and a later ``import scipy.ndimage`` reuses the same extension modules."""
    code = ("import sys\n"
            "import numpy as np\n"
            "import actors.firmware.mapping.scan_match, actors.firmware.planning.frontier\n"
            "import actors.firmware.localisation.clusters\n"
            "from actors.firmware import ndimage as fw\n"
            "print('scipy.ndimage' in sys.modules, fw.KERNELS)\n"
            "v = np.arange(20.0).reshape(4, 5)\n"
            "ours = fw.correlate1d(v, [0.25, 0.5, 0.25], 1, 'constant')\n"
            "labels, n = fw.label(v > 7, np.ones((3, 3), bool))\n"
            "from scipy import ndimage as sp\n"
            "print(np.array_equal(ours, sp.correlate1d(v, [0.25, 0.5, 0.25], axis=1,"
            " mode='constant')), n,\n"
            "      sys.modules['scipy.ndimage._filters']._nd_image is fw._nd_image)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == ["False", "True", "True", "1", "True"]
