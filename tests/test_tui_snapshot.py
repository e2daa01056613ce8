"""The console contract: records check what they are given, and say how it is wrong."""

from __future__ import annotations

import numpy as np
import pytest

from tui.fake import FakeSystem
from tui.snapshot import (
    MAX_LOG_LINES,
    CommandResult,
    Controller,
    GridView,
    LogLine,
    Snapshot,
    System,
    TreeNode,
)


def grid(ny: int = 4, nx: int = 6) -> GridView:
    return GridView(np.full((ny, nx), -1, np.int8), 5.0, (-10.0, -5.0))


def test_grid_rejects_wrong_dtype_with_message():
    """A float grid is a TypeError naming the dtype."""
    with pytest.raises(TypeError, match="cells must have dtype int8, got float64"):
        GridView(np.zeros((3, 3)), 5.0, (0.0, 0.0))


def test_grid_rejects_non_positive_resolution():
    """Resolution must be positive."""
    with pytest.raises(ValueError, match="resolution_cm must be > 0, got 0"):
        GridView(np.zeros((3, 3), np.int8), 0, (0.0, 0.0))


def test_grid_cell_of_uses_lower_left_origin():
    """Row 0 is the lowest y, and the origin is the lower-left corner of cell [0, 0]."""
    g = grid()
    assert g.cell_of(-10.0, -5.0) == (0, 0)
    assert g.cell_of(-5.1, -0.1) == (0, 0)
    assert g.cell_of(-5.0, 0.0) == (1, 1)
    assert g.extent_cm() == (-10.0, -5.0, 20.0, 15.0)


def test_grid_value_at_outside_is_unknown():
    """Points outside the raster read as unknown, inside as the cell value."""
    cells = np.zeros((2, 2), np.int8)
    cells[1, 0] = 100
    g = GridView(cells, 10.0, (0.0, 0.0))
    assert g.value_at(5.0, 15.0) == 100
    assert g.value_at(15.0, 5.0) == 0
    assert g.value_at(-1.0, 5.0) == -1


def test_snapshot_rejects_unknown_phase():
    """The phase must be one of PHASES."""
    with pytest.raises(ValueError, match="phase must be one of .* got 'lost'"):
        Snapshot(0.0, 1.0, False, "s", 0, "lost")


def test_snapshot_rejects_bad_lidar_shape():
    """LIDAR points are an (n, 2) array."""
    with pytest.raises(TypeError, match=r"lidar_points must be a numpy array \(n, 2\)"):
        Snapshot(0.0, 1.0, False, "s", 0, "idle", lidar_points=np.zeros((3, 3)))


def test_snapshot_log_is_bounded():
    """A snapshot carries at most MAX_LOG_LINES lines."""
    lines = tuple(LogLine(i, 0.0, "a", "a", "x") for i in range(MAX_LOG_LINES + 1))
    with pytest.raises(ValueError, match="log holds at most"):
        Snapshot(0.0, 1.0, False, "s", 0, "idle", log=lines)


def test_command_result_status_is_checked():
    """Status is ok, refused or error."""
    with pytest.raises(ValueError, match="status must be ok, refused or error, got 'maybe'"):
        CommandResult("pause", "maybe")  # type: ignore[arg-type]


def test_tree_walk_is_depth_first_in_start_order():
    """walk() yields parents before children, children in order, with depths."""
    tree = TreeNode("root", "supervisor", "running", children=(
        TreeNode("a", "supervisor", "running", children=(TreeNode("a/x", "worker", "running"),)),
        TreeNode("b", "worker", "stopped"),
    ))
    assert [(d, n.name) for d, n in tree.walk()] == [(0, "root"), (1, "a"), (2, "a/x"), (1, "b")]


def test_fake_system_fulfils_the_protocols():
    """The fake is a System and a Controller (structurally)."""
    fake = FakeSystem()
    assert isinstance(fake, System)
    assert isinstance(fake, Controller)
    assert isinstance(fake.snapshot(), Snapshot)
