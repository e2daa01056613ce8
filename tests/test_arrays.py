"""`actors.firmware.arrays.pad_border`: the same array as `np.pad` with a constant border."""

import numpy as np
import pytest

from actors.firmware.arrays import pad_border


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
