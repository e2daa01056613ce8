"""The map's pure drawing rules: heading glyphs and pixel classes."""

from __future__ import annotations

import numpy as np
import pytest

from tui.snapshot import GridView
from tui.widgets.map_view import classify, heading_glyph


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
