"""benchmarks.grid_replay: replaying recorded grid calls and batch checks into two versions."""

from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np
import pytest

from actors.firmware.drivers import lidar
from actors.firmware.mapping import occupancy
from actors.firmware.mapping.sensor_model import LogOddsModel
from benchmarks.grid_replay import Recording, load_base, main, replay_checks, replay_grid
from server.protocol.pose import Pose


def _recording() -> Recording:
    """Two grids, single batches and a window of three, a fill; and a few batch checks."""
    rng = np.random.default_rng(5)
    rec = Recording()
    for gid in (1, 2):
        rec.calls.append(("init", gid, ((400.0, 400.0, 5.0), {})))
    angles = np.arange(0.0, 99.0, 1.0, dtype=np.float32)
    for k in range(4):
        ranges = rng.uniform(20.0, 180.0, angles.size).astype(np.float32)
        rec.calls.append(("integrate", 1 + k % 2, (Pose(3.0 * k, -2.0 * k, 40.0 * k),
                                                   (angles + 99 * k) % 360, ranges)))
    sizes = [99, 99, 99]
    origins = np.array([[0.0, 1.0, 10.0], [2.0, 2.5, 10.0], [4.0, 4.0, 10.0]]).T.repeat(sizes, 1)
    rec.calls.append(("batches", 1, (origins, sizes, np.concatenate([angles, angles + 99,
                                                                      angles + 198]),
                                     rng.uniform(20.0, 180.0, 297))))
    rec.calls.append(("fill", 2, (0, 0, np.zeros((4, 4), dtype=np.int8))))
    for _ in range(5):
        rec.checks.append((angles, rng.uniform(50.0, 60.0, angles.size).astype(np.float32), 0))
    return rec


def test_this_tree_against_its_own_commit_replays_identically():
    """The committed versions of the grid and the checks give identical grids, change
    counts and verdicts on every call, and a time for every timed call."""
    base_occ, base_lidar = load_base("HEAD")
    rec = _recording()
    best, same = replay_grid(rec, {"base": base_occ, "this": occupancy}, reps=2)
    assert same
    timed = [kind in ("integrate", "batches") for kind, _, _ in rec.calls]
    assert all(np.isfinite(best["this"][timed])) and np.isinf(best["this"][~np.array(timed)]).all()
    per_check, same_verdicts = replay_checks(rec, {"base": base_lidar, "this": lidar}, reps=2)
    assert same_verdicts and per_check["this"] > 0


def test_a_version_that_samples_otherwise_is_told_apart():
    """A grid sampling every cell instead of every half cell leaves other grids: the
    replay says so."""
    coarse = SimpleNamespace(OccupancyGrid=functools.partial(
        occupancy.OccupancyGrid, model=LogOddsModel(ray_step=1.0)))
    _, same = replay_grid(_recording(), {"base": occupancy, "this": coarse}, reps=1)
    assert not same


def test_bad_revision_scenario_or_reps_is_one_error_line_and_status_2(capsys):
    with pytest.raises(ValueError, match="no-such-revision"):
        load_base("no-such-revision-xyz")
    assert main(["--base", "no-such-revision-xyz"]) == 2
    assert main(["--scenario", "nowhere"]) == 2
    assert main(["--reps", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("grid_replay: ") for line in err)
