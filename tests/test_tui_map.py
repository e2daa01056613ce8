"""The map's pure drawing rules: heading glyphs and pixel classes."""

from __future__ import annotations

import numpy as np
import pytest

from tui.snapshot import GridView
from tui.widgets.map_pixels import ZOOMS_CM, classify, fit_view, heading_glyph, known_extent


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


@pytest.mark.parametrize("zoom", [0, 3, 6, 9])
@pytest.mark.parametrize("with_truth", [False, True], ids=["map", "truth"])
def test_pixel_classes_per_cell_codes_match_sampling_every_point(monkeypatch, zoom, with_truth):
    """The fast path (classify each cell once, max of codes) draws exactly what
    classifying every sample point and taking the most significant draws."""
    import asyncio

    from textual.app import App, ComposeResult

    from tui.snapshot import Snapshot
    from tui.widgets import map_view
    from tui.widgets.map_view import MapView

    rng = np.random.default_rng(zoom)
    cells = rng.choice(np.array([-1, 0, 100], np.int8), size=(60, 80), p=[0.3, 0.5, 0.2])
    truth = rng.choice(np.array([0, 100], np.int8), size=(60, 80), p=[0.7, 0.3])
    snap = Snapshot(0.0, 1.0, False, "test", 0, "mapping",
                    map=GridView(cells, 5.0, (-200.0, -150.0)),
                    truth=GridView(truth, 5.0, (-200.0, -150.0)))

    class MapApp(App):
        def compose(self) -> ComposeResult:
            yield MapView()

    async def main() -> tuple[np.ndarray, np.ndarray]:
        app = MapApp()
        async with app.run_test(size=(50, 20)) as pilot:
            view = app.query_one(MapView)
            view.update_snapshot(snap)
            view.auto_fit = False
            view.zoom = zoom
            view.show_truth = with_truth
            view.center = (13.0, -7.0)
            await pilot.pause()
            fast = view.pixel_classes()
            monkeypatch.setattr(map_view, "same_raster", lambda a, b: False)
            view.snapshot = Snapshot(0.0, 1.0, False, "test", 0, "mapping", map=None)
            none = view.pixel_classes()
            view.snapshot = snap
            if not with_truth:  # the general path samples the map alone when truth is off
                view.show_truth = True
                view.snapshot = Snapshot(0.0, 1.0, False, "test", 0, "mapping", map=snap.map,
                                         truth=GridView(np.zeros((1, 1), np.int8), 1.0,
                                                        (1e6, 1e6)))
            slow = view.pixel_classes()
            assert (none == 0).all()
            return fast, slow

    fast, slow = asyncio.run(main())
    assert fast.shape == slow.shape and fast.shape[0] > 10
    assert len(np.unique(fast)) >= 2
    np.testing.assert_array_equal(fast, slow)
