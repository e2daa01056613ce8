"""The Ray engine: the same games as the local pool, infrastructure retries, bad addresses.

A local Ray instance (2 CPUs, no dashboard) is started once for the module;
the games are short (mapping budget 30 s in the empty room and the corridor).
"""

from __future__ import annotations

import os
import pathlib
import sys

import pytest

ray = pytest.importorskip("ray")

from supervisors.harness.campaign import CampaignConfig, run_campaign  # noqa: E402
from supervisors.harness.campaign.cluster import INSTALL_HINT, RayEngine  # noqa: E402
from supervisors.harness.campaign.engines import open_engine  # noqa: E402
from tests.test_campaign import fake_worker  # noqa: E402
from tui import cli  # noqa: E402

_QUICK = CampaignConfig(1, rooms=("empty", "corridor"), mapping_budget_s=30.0)
_MARKS = "HIDESEEK_TEST_MARKS"  # a folder the test workers leave marks in


@pytest.fixture(scope="module")
def local_ray(tmp_path_factory):
    marks = tmp_path_factory.mktemp("marks")
    os.environ[_MARKS] = str(marks)  # before ray.init: the workers inherit it
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             logging_level="warning")
    yield marks
    ray.shutdown()
    os.environ.pop(_MARKS, None)


def _mark(ref: str) -> pathlib.Path:
    return pathlib.Path(os.environ[_MARKS]) / ref.replace(":", "-").replace(",", "_")


def dies_once(ref: str, *, determinism: bool = False,
              wall_timeout_s: float | None = None) -> dict:
    """Kills its worker process the first time it sees a game (a lost node, as Ray sees it)."""
    mark = _mark(ref)
    if not mark.exists():
        mark.write_text("1")
        os._exit(1)
    mark.write_text(str(int(mark.read_text()) + 1))
    return fake_worker(ref, determinism=determinism, wall_timeout_s=wall_timeout_s)


def always_dies(ref: str, *, determinism: bool = False,
                wall_timeout_s: float | None = None) -> dict:
    os._exit(1)


def fails_counted(ref: str, *, determinism: bool = False,
                  wall_timeout_s: float | None = None) -> dict:
    """A game that fails (a result), counting how often it was played."""
    mark = _mark("failing-" + ref)
    mark.write_text(str(int(mark.read_text()) + 1) if mark.exists() else "1")
    out = fake_worker(ref, determinism=determinism, wall_timeout_s=wall_timeout_s)
    out.update(outcome="failed", reason="stand-in failure")
    return out


def test_ray_and_the_local_pool_give_the_same_trace_hashes(local_ray):
    with open_engine("ray") as engine:
        on_ray = {r["index"]: r for r in run_campaign(_QUICK, 4, engine=engine,
                                                      determinism_every=0)}
    pooled = {r["index"]: r for r in run_campaign(_QUICK, 4, workers=2, determinism_every=0)}
    assert sorted(on_ray) == sorted(pooled) == [0, 1, 2, 3]
    assert {i: r["trace_hash"] for i, r in on_ray.items()} == \
        {i: r["trace_hash"] for i, r in pooled.items()}
    assert all(r["trace_hash"] for r in on_ray.values())
    assert {i: r["outcome"] for i, r in on_ray.items()} == \
        {i: r["outcome"] for i, r in pooled.items()}


def test_a_task_whose_worker_died_is_retried_and_a_failed_game_is_not(local_ray):
    with RayEngine() as engine:
        got = list(run_campaign(CampaignConfig(5), 2, engine=engine, worker=dies_once,
                                determinism_every=0))
        failed = list(run_campaign(CampaignConfig(6), 2, engine=engine, worker=fails_counted,
                                   determinism_every=0))
    assert sorted(r["index"] for r in got) == [0, 1]
    assert all(not r["violations"] for r in got)
    assert [_mark(CampaignConfig(5).game_ref(i)).read_text() for i in (0, 1)] == ["2", "2"]
    assert [r["outcome"] for r in failed] == ["failed", "failed"]
    assert [_mark("failing-" + CampaignConfig(6).game_ref(i)).read_text()
            for i in (0, 1)] == ["1", "1"]


def test_a_game_lost_every_time_is_a_failure_not_a_crash(local_ray):
    with RayEngine() as engine:
        (r,) = run_campaign(CampaignConfig(7), 1, engine=engine, worker=always_dies,
                            determinism_every=0)
    assert r["index"] == 0 and r["outcome"] == "failed"
    assert r["violations"][0].startswith("harness.worker_lost:")
    assert r["reproduce"] == "hideseek run --campaign 7:0"


def test_an_unreachable_ray_address_is_one_line_and_status_2(capsys):
    status = cli.main(["campaign", "-n", "1", "--engine", "ray", "--address", "127.0.0.1:1",
                       "--out", ":memory:", "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.count("\n") == 0 and "cannot reach a Ray cluster" in err


def test_without_ray_the_ray_engine_says_how_to_install_it(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now raises ImportError
    status = cli.main(["campaign", "-n", "1", "--engine", "ray", "--out", ":memory:",
                       "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert status == 2 and err == f"hideseek campaign: {INSTALL_HINT}"
