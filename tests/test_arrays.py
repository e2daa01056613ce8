"""`actors.firmware.arrays`: `pad_border` gives the same array as `np.pad` with a constant
border, `nonzero_2d` the same indices as `np.nonzero`, `distinct` the same elements as
`np.unique`."""

import subprocess
import sys

import numpy as np
import pytest

from actors.firmware.arrays import distinct, nonzero_2d, pad_border


@pytest.mark.parametrize("dtype", [np.float64, np.float32, bool, np.int8, np.int32])
@pytest.mark.parametrize("width", [0, 1, 3])
def test_pad_border_equals_np_pad_with_a_constant(dtype: type, width: int) -> None:
    rng = np.random.default_rng(7)
    values = (rng.random((5, 8)) * 100).astype(dtype)
    for fill in (0, 1):
        want = np.pad(values, width, constant_values=fill)
        got = pad_border(values, width, fill)
        assert got.dtype == want.dtype and got.shape == want.shape
        assert got.tobytes() == want.tobytes()


def test_pad_border_returns_a_copy_and_keeps_its_input() -> None:
    values = np.ones((2, 3))
    padded = pad_border(values)
    padded[1, 1] = 5.0
    assert values[0, 0] == 1.0
    assert padded.flags.writeable and padded.shape == (4, 5)


def test_pad_border_refuses_other_shapes_and_negative_widths() -> None:
    with pytest.raises(ValueError, match="2-D"):
        pad_border(np.ones(4))
    with pytest.raises(ValueError, match="width"):
        pad_border(np.ones((2, 2)), -1)


@pytest.mark.parametrize("shape", [(0, 4), (3, 0), (1, 1), (7, 5), (60, 130)])
def test_nonzero_2d_gives_np_nonzeros_rows_and_columns(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(3)
    for share in (0.0, 0.05, 0.5, 1.0):
        values = np.where(rng.random(shape) < share, rng.random(shape), 0.0)
        for a in (values, values > 0, values[::2, ::-1]):  # views too
            want = np.nonzero(a)
            got = nonzero_2d(a)
            assert all(g.dtype == w.dtype and np.array_equal(g, w) for g, w in zip(got, want,
                                                                                    strict=True))


def test_nonzero_2d_counts_nan_and_not_negative_zero_as_np_nonzero_does() -> None:
    a = np.array([[0.0, -0.0, np.nan], [np.inf, 1e-320, -2.0]])
    for values in (a, a.astype(np.float32), np.array([[0, -1, 2], [0, 0, 7]])):
        want = np.nonzero(values)
        got = nonzero_2d(values)
        assert all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))


def test_nonzero_2d_refuses_other_shapes() -> None:
    with pytest.raises(ValueError, match="2-D"):
        nonzero_2d(np.ones(4))


def test_distinct_gives_np_uniques_elements() -> None:
    rng = np.random.default_rng(9)
    for values in (rng.integers(-50, 50, 300), rng.integers(0, 5, (7, 9)), np.zeros(0, int),
                   np.array([3]), rng.integers(0, 2**40, 100).astype(np.uint64),
                   rng.random(20) < 0.5):
        want = np.unique(values)
        got = distinct(values)
        assert got.dtype == want.dtype and np.array_equal(got, want)


def test_distinct_refuses_floats_and_leaves_numpy_ma_unimported() -> None:
    with pytest.raises(ValueError, match="integer"):
        distinct(np.array([0.5, 0.5]))
    code = ("import sys, numpy as np\n"
            "from actors.firmware.arrays import distinct\n"
            "distinct(np.array([2, 1, 2]))\n"
            "print('numpy.ma' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == ["False"]
