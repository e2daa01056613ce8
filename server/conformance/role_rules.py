"""What each role does: ``mapping.start_stop``, ``map.upload``, ``map.download``,
``report.hide``, ``report.seek`` (and, on the way, the resend, reconnect and
duplicate phases, which need a reliable frame of the rover to work on).

The checker plays the map frame as the rover's own: ``origin`` is (0, 0, 0),
the map it sends is an open square around the rover's start, walled, with a
comb of single occupied cells along the walls (so the map needs two chunks),
and the destination lies `DESTINATION_CM` ahead of the start: a short drive.
"""

from __future__ import annotations

import msgspec
import numpy as np
import trio

from ..protocol import (
    CHUNK_B64_CHARS,
    Frame,
    FrameError,
    GridMap,
    MapAssembler,
    MapError,
    map_chunks,
    read_data,
)
from .context import Checker
from .peer import Seen
from .resync_rules import reconnect
from .session_rules import duplicate, resume_acks, withhold

__all__ = ["DESTINATION_CM", "checker_map", "run_mapper", "run_hider_seeker"]

DESTINATION_CM = 30.0
"""How far ahead of its start the hider or seeker is sent [cm]."""
_ORIGIN = {"x": 0.0, "y": 0.0, "heading": 0.0}


def checker_map() -> GridMap:
    """The map sent to a hider or seeker (see the module docstring): 4 m square at 5 cm."""
    n = 80
    cells = np.zeros((n, n), dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
    cells[1, 1:-1:2] = cells[-2, 1:-1:2] = cells[1:-1:2, 1] = cells[1:-1:2, -2] = 100
    cells[2, 2:-2:2] = cells[-3, 2:-2:2] = 100
    return GridMap(cells, 5.0, (-200.0, -200.0))


def _new_reliable(c: Checker, cmds: tuple[str, ...]):
    """A match for a rover frame of one of ``cmds`` with a ``seq`` not seen before."""
    seen_seq = {s.frame.seq for s in c.tx.frames() if s.frame.seq is not None}

    def match(s: Seen) -> bool:
        return (s.frame is not None and s.frame.cmd in cmds and s.frame.seq is not None
                and s.frame.seq not in seen_seq)
    return match


async def run_mapper(c: Checker) -> None:
    """origin, start, ``map_s`` of mapping, stop; the upload (first chunk withheld to
    watch its resends and carry the link drop), then a duplicate stop."""
    tx = c.tx
    await c.send("origin", "pose", _ORIGIN)
    await c.send("start", "none")
    await trio.sleep(c.opts.map_s)
    stop_seq, stop_at = await c.send("stop", "none")
    first = await withhold(c, c.opts.report_s, lambda s: s.frame.cmd == "map")
    if first is None:
        c.found.fail("mapping.start_stop", f"no map came within {c.opts.report_s:g} s of "
                     "stop", [tx.lines[stop_at]])
        c.found.skip("map.upload", "no map came")
        await resume_acks(c)
        return
    await reconnect(c, first)
    await resume_acks(c)
    if c.lost_link:
        return
    grid, chunks, why = await _collect_upload(c, first)
    if why:
        c.found.fail("map.upload", why, chunks[:4])
    else:
        assert grid is not None
        ny, nx = grid.shape
        c.found.ok("map.upload", f"map {first.frame.data.get('map_id')}: {len(chunks)} "
                   f"chunk(s), {nx}x{ny} cells at {grid.resolution_cm:g} cm, CRC right",
                   chunks[:2])
    if grid is not None or chunks:
        c.found.ok("mapping.start_stop", f"stop answered by a map upload "
                   f"{first.t - tx.lines[stop_at].t:.2f} s later", [tx.lines[stop_at], first])
    await duplicate(c, Frame("stop", "none", None), stop_seq, _new_reliable(c, ("map",)),
                    "a map upload")


async def _collect_upload(c: Checker, first: Seen) -> tuple[GridMap | None, list[Seen], str]:
    """The chunks of the upload ``first`` opens, as they arrive; (map, chunks, why not)."""
    tx = c.tx
    body = first.frame.data if isinstance(first.frame.data, dict) else {}
    map_id = body.get("map_id")
    count = body.get("count") if isinstance(body.get("count"), int) else 0

    def pieces() -> dict[int, Seen]:
        got: dict[int, Seen] = {}
        for s in tx.frames(tx.index(first), "map"):
            d = s.frame.data
            if isinstance(d, dict) and d.get("map_id") == map_id and isinstance(
                    d.get("index"), int):
                got.setdefault(d["index"], s)
        return got

    got = pieces()
    while len(got) < count:
        s = await tx.wait_for(lambda s: s.frame is not None and s.frame.cmd == "map",
                              c.opts.report_s, len(tx.lines))
        if s is None:
            break
        got = pieces()
    chunks = [got[k] for k in sorted(got)]
    if count < 1 or len(got) < count:
        return None, chunks, f"map {map_id}: {len(got)} of {count} chunks came"
    assembler = MapAssembler()
    grid = None
    for s in chunks:
        if s.frame.seq is None:
            return None, [s], "a map chunk without seq (chunks are reliable)"
        try:
            chunk = read_data(s.frame)
        except FrameError as exc:
            return None, [s], f"a chunk does not fit the catalogue: {exc.detail}"
        if len(chunk.b64) > CHUNK_B64_CHARS:
            return None, [s], f"chunk {chunk.index}: {len(chunk.b64)} base64 characters, " \
                              f"at most {CHUNK_B64_CHARS}"
        if chunk.count != count:
            return None, [s], f"chunk {chunk.index} says count {chunk.count}, the first {count}"
        try:
            grid = assembler.add(chunk)
        except MapError as exc:
            return None, [s], f"map {map_id}: {exc}"
    if grid is None:
        return None, chunks, f"map {map_id}: the chunks' headers differ"
    return grid, chunks, ""


async def run_hider_seeker(c: Checker) -> None:
    """origin, start, destination (as the server sends them); the map request withheld
    (resends, link drop), the map sent, a duplicate start, the report withheld for the
    resync that follows (`resync_rules.resync` takes it)."""
    tx = c.tx
    role = c.role
    dest = {"x": DESTINATION_CM, "y": 0.0, "heading": 0.0 if role == "hider" else None}
    c.peer.auto_ack = False  # the map request is the rover's first reliable frame
    await c.send("origin", "pose", _ORIGIN)
    start_seq, start_at = await c.send("start", "none")
    await c.send("destination", "pose", dest)
    request = await withhold(c, c.opts.connect_s,
                             lambda s: s.frame.cmd == "map_request")
    if request is None:
        c.found.fail("map.download", f"no map_request within {c.opts.connect_s:g} s of start",
                     [tx.lines[start_at]])
        await resume_acks(c)
        return
    await reconnect(c, request)
    await resume_acks(c)
    if c.lost_link:
        return
    at = len(tx.lines)
    c.peer.auto_ack = False  # the report may come at once: keep it unacknowledged for resync
    seqs = []
    for chunk in map_chunks(checker_map(), 1):
        seq, _ = await c.send(chunk.cmd, chunk.type, chunk.data)
        seqs.append(seq)
    acked = await tx.wait_for(lambda s: s.frame is not None and s.frame.ack is not None
                              and s.frame.ack >= seqs[-1], c.slack(2.0), at)
    if acked is None:
        c.found.fail("map.download", f"the map's {len(seqs)} chunks (seq {seqs[0]}.."
                     f"{seqs[-1]}) were not all acknowledged", [request])
    else:
        c.found.ok("map.download", f"map_request on start, {len(seqs)} chunks acknowledged",
                   [request, acked])
    await duplicate(c, Frame("start", "none", None), start_seq,
                    _new_reliable(c, ("map_request",)), "a second map_request")
    answers = ("arrived", "invalid_spot") if role == "hider" else ("found", "not_found")
    rule = "report.hide" if role == "hider" else "report.seek"
    report = await tx.wait_for(lambda s: s.frame is not None and s.frame.cmd in answers,
                               c.opts.report_s, at)
    if report is None:
        c.found.fail(rule, f"no {' or '.join(answers)} within {c.opts.report_s:g} s of the "
                     "destination")
        return
    try:
        read_data(report.frame)
        fits = ""
    except FrameError as exc:
        fits = exc.detail
    except msgspec.ValidationError as exc:  # pragma: no cover - read_data wraps these
        fits = str(exc)
    if fits:
        c.found.fail(rule, f"{report.frame.cmd} does not fit: {fits}", [report])
    elif report.frame.seq is None:
        c.found.fail(rule, f"{report.frame.cmd} came without seq (reports are reliable)",
                     [report])
    else:
        c.found.ok(rule, f"{report.frame.cmd} {report.t - tx.lines[start_at].t:.1f} s after "
                   "the destination", [report])
    c.pending = report
