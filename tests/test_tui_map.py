"""The map's pure drawing rules: heading glyphs and pixel classes."""

from __future__ import annotations

import numpy as np
import pytest

from tui.snapshot import GridView
from tui.widgets.map_view import ZOOMS_CM, classify, fit_view, heading_glyph, known_extent


@pytest.mark.parametrize("heading,glyph", [
    (0, "→"), (44, "↗"), (90, "↑"), (180, "←"), (-90, "↓"), (270, "↓"), (359, "→"), (-135, "↙"),
])
def test_heading_glyph_points_the_way(heading, glyph):
    """Headings are counter-clockwise from +x, with +y up the screen."""
    assert heading_glyph(heading) == glyph


def grids():
    cells = np.array([[0, 100, -1, 0]], np.int8)     # map: free, occupied, unknown, free
    truth = np.array([[0, 0, 100, 100]], np.int8)    # truth: free, free, occupied, occupied
    return GridView(cells, 10.0, (0.0, 0.0)), GridView(truth, 10.0, (0.0, 0.0))


def test_classify_without_truth_is_the_map():
    """Free, occupied, unknown; outside the grid is unknown."""
    grid, _ = grids()
    xs = np.array([5.0, 15.0, 25.0, 35.0, 99.0])
    assert classify(grid, None, xs, np.full(5, 5.0)).tolist() == [1, 2, 0, 1, 0]


def test_classify_with_truth_marks_errors_and_unseen_obstacles():
    """Occupied-but-free-in-truth is a false obstacle (4), unknown obstacle is unseen (7),
    and an obstacle mapped free is missed (3)."""
    grid, truth = grids()
    xs = np.array([5.0, 15.0, 25.0, 35.0])
    assert classify(grid, truth, xs, np.full(4, 5.0)).tolist() == [1, 4, 7, 3]


def test_classify_without_a_map_is_all_unknown():
    """Before the first map update every pixel is unknown."""
    assert classify(None, None, np.zeros(3), np.zeros(3)).tolist() == [0, 0, 0]


def test_known_extent_is_the_known_cells_with_a_margin():
    """Only known cells count; one cell of margin on each side; None when none known."""
    cells = np.full((10, 10), -1, np.int8)
    grid = GridView(cells.copy(), 5.0, (-20.0, -10.0))
    assert known_extent(grid) is None
    cells[2, 3] = 0
    cells[4, 6] = 100
    grid = GridView(cells, 5.0, (-20.0, -10.0))
    # cols 3..6, rows 2..4 -> x from -20 + 2*5 to -20 + 8*5, y from -10 + 1*5 to -10 + 6*5
    assert known_extent(grid) == (-10.0, -5.0, 20.0, 20.0)


@pytest.mark.parametrize("extent,size,zoom", [
    ((0, 0, 400, 300), (68, 37), 4),     # 400 cm in 68 columns: 6 cm/px
    ((0, 0, 100, 100), (68, 37), 1),     # small room: 2.5 cm/px
    ((0, 0, 40000, 100), (68, 37), 12),  # too big for any step: the coarsest
])
def test_fit_view_picks_the_finest_zoom_that_shows_the_extent(extent, size, zoom):
    """The chosen pixel size shows the extent in width x 2*height pixels, centred."""
    index, centre = fit_view(extent, *size)
    assert index == zoom
    s = ZOOMS_CM[index]
    assert (extent[2] - extent[0]) / s <= size[0] or index == len(ZOOMS_CM) - 1
    if index > 0:
        finer = ZOOMS_CM[index - 1]
        assert ((extent[2] - extent[0]) / finer > size[0]
                or (extent[3] - extent[1]) / finer > 2 * size[1])
    assert centre == ((extent[0] + extent[2]) / 2, (extent[1] + extent[3]) / 2)
