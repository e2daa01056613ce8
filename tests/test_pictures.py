"""Pictures (tui/pictures): a game drawn from its recording, a campaign's results as a page."""

from __future__ import annotations

import json
import pathlib

import numpy as np
from PIL import Image

from tests.test_shrink import _FAULTS, _ROOM
from tui.cli import main
from tui.pictures.game_image import FAULT_COLOUR
from tui.pictures.map_image import hex_rgb
from tui.widgets.map_pixels import ROVER_COLOURS


def _has_colour(px: np.ndarray, colour: str) -> bool:
    return bool((px == np.array(hex_rgb(colour), np.uint8)).all(axis=2).any())


def test_run_picture_draws_the_map_trajectories_and_fault_onsets(tmp_path: pathlib.Path,
                                                                  capsys) -> None:
    """A failing game with three faults: the picture holds the map, every rover's track and
    a fault mark; the game is the same one (its trace hash) as without the picture."""
    src = tmp_path / "three.toml"
    src.write_text(_ROOM + _FAULTS)
    game = ["run", "--scenario", str(src), "--seed", "7", "--budget", "120", "--json"]
    picture = tmp_path / "g.png"
    assert main([*game, "--picture", str(picture)]) == 1
    drawn = json.loads(capsys.readouterr().out)
    with Image.open(picture) as img:
        assert img.format == "PNG" and img.width >= 400 and img.height >= 300
        px = np.asarray(img.convert("RGB"))
    assert _has_colour(px, FAULT_COLOUR)
    assert all(_has_colour(px, ROVER_COLOURS[role]) for role in ("mapper", "hider", "seeker"))
    assert main(game) == 1
    assert json.loads(capsys.readouterr().out)["trace_hash"] == drawn["trace_hash"]


def test_a_picture_in_no_folder_is_one_line_and_status_2(tmp_path: pathlib.Path, capsys) -> None:
    assert main(["run", "--scenario", "empty", "--picture", str(tmp_path / "no" / "g.png")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("hideseek run: --picture must be a file in an existing folder")


def _campaign(tmp_path: pathlib.Path) -> tuple[pathlib.Path, dict]:
    """A 20-game campaign of stand-in games (`tests.test_campaign.fake_worker`: a game with
    an actor crash fails), stored; one failure given a shrunk schedule as --shrink stores it."""
    import argparse
    import sqlite3

    from tests.test_campaign import fake_worker
    from tui import cmd_campaign

    db = tmp_path / "c.sqlite"
    parser = argparse.ArgumentParser()
    cmd_campaign.add_arguments(parser)
    args = parser.parse_args(["--seed", "3", "--mode", "overlapping", "-n", "20", "--workers",
                              "0", "--replay-every", "0", "--out", str(db), "--json",
                              "--no-progress"])
    cmd_campaign.run(args, worker=fake_worker)
    with sqlite3.connect(db) as conn:
        (text,) = conn.execute("SELECT summary FROM campaigns").fetchone()
        summary = json.loads(text)
        first = summary["failures"][0]
        summary["shrunk"] = [{
            "ref": f"3:{first['index']}", "index": first["index"], "original": first["faults"],
            "shrunk": first["faults"][:1], "runs": 7, "exhausted": False, "reproduces": True,
            "file": "shrunk/campaign-3.toml",
            "reproduce": "hideseek run --scenario FILE --seed 9"}]
        conn.execute("UPDATE campaigns SET summary = ?", (json.dumps(summary),))
    return db, summary


def test_report_html_has_the_charts_every_failure_its_repro_and_the_links(
        tmp_path: pathlib.Path, capsys) -> None:
    import re

    db, summary = _campaign(tmp_path)
    page = tmp_path / "r.html"
    capsys.readouterr()
    assert main(["report", str(db), "--html", str(page)]) == 0
    failures = summary["failures"]
    assert 0 < len(failures) < 20
    assert capsys.readouterr().out == f"{page}: campaign 1, 20 games, {len(failures)} failures\n"
    html = page.read_text()
    # self-contained: no script, stylesheet or image fetched from anywhere
    assert "<script" not in html and "<link" not in html and "<img" not in html
    charts = re.findall(r'<svg [^>]*width="(\d+)" height="(\d+)"', html)
    assert len(charts) == 3 and all(int(w) == 640 and int(h) >= 50 for w, h in charts)
    assert "found rate by fault kind" in html and "found rate by room" in html
    assert "time to find" in html
    for f in failures:
        ref = re.search(r"--campaign (\S+)", f["reproduce"]).group(1)
        assert f"<code>hideseek run --campaign {ref}</code>" in html
    links = re.findall(r'href="#([\w-]+)"', html)
    ids = set(re.findall(r'id="([\w-]+)"', html))
    assert set(links) <= ids
    sections = {f"game-{f['index']}" for f in failures}
    assert sections <= ids and sections <= set(links)
    assert links.count("failures") == len(failures)  # each section links back
    first = failures[0]
    section = html.split(f'id="game-{first["index"]}"')[1].split("</section>")[0]
    assert f"shrunk to 1 of {len(first['faults'])} faults in 7 runs" in section
    assert "hideseek run --scenario shrunk/campaign-3.toml --seed 9" in section


def test_report_on_no_store_is_one_line_and_status_2(tmp_path: pathlib.Path, capsys) -> None:
    assert main(["report", str(tmp_path / "none.sqlite"), "--html", str(tmp_path / "r")]) == 2
    assert capsys.readouterr().err == f"hideseek report: no campaign store {tmp_path}/none.sqlite\n"
