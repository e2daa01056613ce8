"""A campaign's results as one self-contained HTML page (``hideseek report --html``).

The page holds, from the campaign store (`supervisors.harness.campaign.store`):
the campaign's settings and totals; charts (inline SVG, `tui.pictures.charts`) of
the found rate by fault kind and by room and of the time to find; a table of the
failures, each linked to its own section; and per failure its faults, what broke,
the command that plays it again (``hideseek run --campaign S:I``) and, when the
campaign shrank it (``--shrink``), the shrunk schedule and its file. Sections link
back to the table. Nothing is loaded from elsewhere: no script, no stylesheet, no
image file.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from html import escape
from typing import Any

from tui.pictures.charts import histogram, rate_bars

__all__ = ["campaign_html", "failure_anchor"]

_STYLE = """
body { font-family: sans-serif; margin: 1.5em auto; max-width: 60em; color: #222; }
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
table { border-collapse: collapse; } td, th { padding: 2px 8px; border-bottom: 1px solid #ddd;
text-align: left; vertical-align: top; } code, pre { background: #f4f4f4; padding: 1px 4px; }
section.failure { border-left: 4px solid #d9534f; padding-left: 1em; margin: 1em 0; }
.charts svg { display: block; margin: 1em 0; }
"""


def failure_anchor(index: int) -> str:
    """The id of game ``index``'s failure section (``#game-11``)."""
    return f"game-{index}"


def _failed(game: dict[str, Any]) -> bool:
    return game["outcome"] != "found" or bool(game["violations"])


def _kinds(game: dict[str, Any]) -> list[str]:
    """The fault kinds injected in a game (labels, ``lidar:dead``), each once; a fault whose
    start came after the game ended is not counted (as the campaign's summary does)."""
    return sorted({f.get("label") or f"{f['target']}:{f['kind']}" for f in game["faults"]
                   if f["at_s"] <= game["sim_s"] + 1e-9 or game["outcome"] == "failed"})


def _found_by(games: Sequence[dict[str, Any]], key) -> list[tuple[str, int, int]]:
    """(group, games found, games) per group; a game is in every group ``key`` gives it."""
    found: dict[str, int] = defaultdict(int)
    total: dict[str, int] = defaultdict(int)
    for g in games:
        for group in key(g):
            total[group] += 1
            found[group] += g["outcome"] == "found"
    return [(group, found[group], total[group]) for group in sorted(total)]


def _fault_line(f: dict[str, Any]) -> str:
    until = f" for {f['duration_s']:g} s" if f.get("duration_s") else " (until cleared)"
    return f"{f['target']} {f['kind']} at {f['at_s']:g} s{until}"


def campaign_html(campaign_id: int, summary: dict[str, Any] | None,
                  games: Sequence[dict[str, Any]], *, source: str = "") -> str:
    """The page (see the module docstring) for a stored campaign (`read_campaign`'s
    values); ``source`` names the store in the title."""
    config = (summary or {}).get("campaign", {})
    failures = [g for g in games if _failed(g)]
    shrunk = {s.get("index"): s for s in (summary or {}).get("shrunk") or []}
    found = sum(g["outcome"] == "found" for g in games)
    head = (f"campaign {campaign_id}" + (f", seed {config['seed']}" if "seed" in config else "")
            + (f" ({escape(source)})" if source else ""))
    out = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
           f"<title>hideseek {head}</title><style>{_STYLE}</style></head><body>",
           f"<h1>hideseek {head}</h1>",
           f"<p>{len(games)} games: {found} found, {len(failures)} failed "
           f"(not found, or an invariant broke)"
           + (f"; {config.get('mode')} faults of {', '.join(config.get('kinds', []))}"
              if config else "")
           + (f"; stopped early: {escape(str(summary['stopped_early']))}"
              if summary and summary.get("stopped_early") else "")
           + ".</p>"]
    times = [g["sim_s"] for g in games if g["outcome"] == "found"]
    out.append('<div class="charts">')
    out.append(rate_bars("found rate by fault kind", _found_by(games, lambda g: _kinds(g)
                                                              or ["(no fault)"])))
    out.append(rate_bars("found rate by room", _found_by(games, lambda g: [g["room"]])))
    out.append(histogram("time to find (games found)", times,
                         unit="simulated s from the game's start"))
    out.append("</div>")
    out.append(f'<h2 id="failures">Failures ({len(failures)})</h2>')
    if failures:
        out.append("<table><tr><th>game</th><th>room</th><th>outcome</th><th>faults</th>"
                   "<th>shrunk</th></tr>")
        for g in failures:
            s = shrunk.get(g["index"])
            shrunk_cell = ("-" if s is None else escape(s["error"]) if "error" in s
                           else f"{len(s['original'])} &rarr; {len(s['shrunk'])} faults")
            out.append(f'<tr><td><a href="#{failure_anchor(g["index"])}">{escape(g["ref"])}'
                       f'</a></td><td>{escape(g["room"])}</td><td>{escape(g["outcome"])}</td>'
                       f'<td>{len(g["faults"])}</td><td>{shrunk_cell}</td></tr>')
        out.append("</table>")
        for g in failures:
            out.append(_failure_section(g, shrunk.get(g["index"])))
    else:
        out.append("<p>none</p>")
    out.append("</body></html>")
    return "\n".join(out) + "\n"


def _failure_section(g: dict[str, Any], shrunk: dict[str, Any] | None) -> str:
    parts = [f'<section class="failure" id="{failure_anchor(g["index"])}">',
             f"<h3>game {escape(g['ref'])}: {escape(g['outcome'])} in {escape(g['room'])}</h3>"]
    if g["reason"]:
        parts.append(f"<p>{escape(g['reason'])}</p>")
    if g["violations"]:
        parts.append("<p>broke: " + "; ".join(escape(v) for v in g["violations"]) + "</p>")
    parts.append("<p>faults:</p><ul>" + "".join(f"<li>{escape(_fault_line(f))}</li>"
                                                 for f in g["faults"]) + "</ul>"
                 if g["faults"] else "<p>no faults</p>")
    parts.append(f"<p>play it again: <code>hideseek run --campaign {escape(g['ref'])}</code>"
                 "</p>")
    if shrunk is not None and "error" not in shrunk:
        lines = shrunk["shrunk"] or ["(none: it fails without its faults)"]
        parts.append(f"<p>shrunk to {len(shrunk['shrunk'])} of {len(shrunk['original'])} "
                     f"faults in {shrunk['runs']} runs"
                     + (" (ran out of runs: not minimal)" if shrunk.get("exhausted") else "")
                     + ":</p><ul>" + "".join(f"<li>{escape(line)}</li>" for line in lines)
                     + "</ul>")
        if shrunk.get("file"):
            command = shrunk["reproduce"].replace("FILE", shrunk["file"])
            parts.append(f"<p>the shrunk game: <code>{escape(command)}</code></p>")
    elif shrunk is not None:
        parts.append(f"<p>not shrunk: {escape(shrunk['error'])}</p>")
    parts.append('<p><a href="#failures">back to the failures</a></p></section>')
    return "\n".join(parts)
