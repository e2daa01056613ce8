"""The operator console of ``hideseek serve``: commands read from standard input.

One command a line (a prompt with line editing and history when standard input
is a terminal, `_tty_lines`; else lines from a pipe or file, `_pipe_lines`),
parsed by `parse_command_line` and carried out on the server (`run_console`):
``status`` and ``help`` print, ``fault``/``clear`` break or mend a rover or
its link (`run_fault`), every other command goes to ``Server.command``. A
line that is not a command prints one ``?`` line and the console reads on.
"""

from __future__ import annotations

import contextlib
import os
import sys

__all__ = ["CONSOLE_COMMANDS", "HELP", "format_status", "parse_command_line",
           "parse_fault_words", "run_console", "run_fault"]

CONSOLE_COMMANDS = ("start_mapping", "stop_mapping", "hide", "seek", "new_game", "fault",
                    "clear", "status", "help", "quit")
"""Every command the operator console takes."""
HELP = """\
  start_mapping                      the mapper explores the room
  stop_mapping                       the mapper stops and uploads what it has
  hide X Y [HEADING] [room|map]      send the hider there (cm, deg; map frame unless room)
  seek X Y [HEADING] [room|map] [within=CM]
                                     send the seeker to look there (within: search radius)
  fault ROVER/TARGET KIND [DURATION] [NAME=VALUE ...]
                                     break a rover's device, actor or link (s; status
                                     lists an attached rover's faults), e.g.
                                     fault mapper/link loss 60 percent=30
  clear ROVER/TARGET [KIND]          end the faults on a target (all kinds by default)
  new_game                           end this game (stopped by the operator), start another
  status                             game phase and each rover's link
  help                               this list
  quit                               stop the server (as Ctrl-C or Ctrl-D); the game resumes
                                     at the next start"""


def parse_command_line(line: str) -> tuple[str, dict]:
    """An operator line -> (command, kwargs). Raises ValueError with usage."""
    words = line.split()
    if not words:
        raise ValueError("empty command")
    name, rest = words[0], words[1:]
    if name not in CONSOLE_COMMANDS:
        raise ValueError(f"unknown command {name!r}; commands: {', '.join(CONSOLE_COMMANDS)}")
    if name in ("hide", "seek"):
        usage = f"usage: {name} X Y [HEADING] [room|map]"
        if name == "seek":
            usage += " [within=CM]"
        kw: dict = {}
        if name == "seek" and rest and rest[-1].startswith("within="):
            try:
                kw["within"] = float(rest.pop()[len("within="):])
            except ValueError:
                raise ValueError(f"seek: within=CM must be a number, {usage}") from None
        frame = "map"
        if rest and rest[-1] in ("room", "map"):
            frame = rest.pop()
        if len(rest) not in (2, 3):
            raise ValueError(usage)
        try:
            nums = [float(w) for w in rest]
        except ValueError:
            raise ValueError(f"{name}: X, Y and HEADING must be numbers, got {rest}") from None
        kw.update(x=nums[0], y=nums[1], frame=frame)
        if len(nums) == 3:
            kw["heading"] = nums[2]
        return name, kw
    if name in ("fault", "clear"):
        return name, parse_fault_words(name, rest)
    if rest:
        raise ValueError(f"{name} takes no arguments")
    return name, {}


def parse_fault_words(name: str, words: list[str]) -> dict:
    """``fault``/``clear`` arguments -> ``rover, target, kind, duration_s, params``.

    Raises:
        ValueError: naming the word that is wrong, with the usage.
    """
    usage = ("usage: fault ROVER/TARGET KIND [DURATION] [NAME=VALUE ...]" if name == "fault"
             else "usage: clear ROVER/TARGET [KIND]")
    if not words or words[0].count("/") != 1 or "" in words[0].split("/"):
        raise ValueError(usage)
    rover, target = words[0].split("/")
    rest = words[1:]
    if name == "clear":
        if len(rest) > 1:
            raise ValueError(usage)
        return {"rover": rover, "target": target, "kind": rest[0] if rest else "*"}
    if not rest:
        raise ValueError(usage)
    kind, rest = rest[0], rest[1:]
    duration = 0.0
    if rest and "=" not in rest[0]:
        try:
            duration = float(rest.pop(0))
        except ValueError:
            raise ValueError(f"fault: DURATION must be a number of seconds, {usage}") from None
        if not 0 <= duration <= 86400:
            raise ValueError(f"fault: DURATION must be within 0..86400 s, got {duration:g}")
    params = {}
    for word in rest:
        key, _, value = word.partition("=")
        try:
            params[key] = float(value)
        except ValueError:
            raise ValueError(f"fault: {word!r} is not NAME=NUMBER, {usage}") from None
    return {"rover": rover, "target": target, "kind": kind, "duration_s": duration,
            "params": params}


def format_status(snap) -> str:
    """A server snapshot as lines for people: the game, then one row per rover."""
    head = f"game {snap.game_id}: {snap.phase}" + (f" ({snap.reason})" if snap.reason else "")
    lines = [head]
    if snap.rovers:
        lines.append(f"  {'rover':<12} {'role':<7} {'link':<24} {'up':<4} {'rtt':>8} "
                     f"{'in':>6} {'out':>6} {'lost':>5} {'resent':>6} {'bad':>5}")
    for r in snap.rovers:
        st = r.stats
        faults = getattr(r, "faults", ())
        rtt = f"{st.rtt_s * 1000:.0f} ms" if st.rtt_s is not None else "-"
        lines.append(f"  {r.id:<12} {r.role:<7} {(r.link or '(none)'):<24} "
                     f"{'yes' if st.up else 'no':<4} {rtt:>8} {st.frames_in:>6} "
                     f"{st.frames_out:>6} {st.lost:>5} {st.resent:>6} {st.bad_frames:>5}")
        if faults:
            lines.append(f"  {'':<12} faults: {', '.join(faults)}")
    if not snap.rovers:
        lines.append("  no rover has said hello yet")
    refused = getattr(snap, "refused", {}) or {}
    lines.append(f"  connections {getattr(snap, 'connections', 0)}; refused since start: "
                 f"{refused.get('bad_frame', 0)} bad frames, "
                 f"{refused.get('auth_failed', 0)} failed hellos, "
                 f"{refused.get('conn_closed', 0)} links closed")
    return "\n".join(lines)


def run_fault(server, sim_system, name: str, kw: dict) -> str:
    """Carry out a parsed ``fault``/``clear``: an attached rover through the server, a
    simulated one through its world or runtime. Raises ValueError with the reason."""
    rover, target = kw["rover"], kw["target"]
    simulated = sim_system is not None and rover in sim_system.trees
    if not simulated:
        if name == "clear":
            return server.rover_fault(rover, "clear", target, kw["kind"])
        return server.rover_fault(rover, "inject", target, kw["kind"], kw["duration_s"],
                                  kw["params"])
    if name == "clear":
        return f"{sim_system.clear_fault(f'{rover}/{target}')} fault(s) cleared"
    fid = sim_system.inject_fault(f"{rover}/{target}", kw["kind"], kw["duration_s"],
                                  **kw["params"])
    return f"fault {fid}: {kw['kind']} on {rover}/{target}"


async def run_console(server, stop, sim_system=None) -> None:
    """Operator commands until end of input or ``quit``, then stop the server."""
    lines = _tty_lines() if sys.stdin.isatty() else _pipe_lines()
    async for line in lines:
        if not line:
            continue
        if line in ("quit", "exit"):
            break
        if line == "help":
            print(HELP, flush=True)
            continue
        if line == "status":
            print(format_status(server.snapshot()), flush=True)
            continue
        try:
            name, kw = parse_command_line(line)
        except ValueError as exc:
            print(f"? {exc}", flush=True)
            continue
        if name in ("fault", "clear"):
            try:
                print(run_fault(server, sim_system, name, kw), flush=True)
            except ValueError as exc:
                print(f"refused: {exc}", flush=True)
            continue
        result = await server.command(name, **kw)
        print("ok" if result.ok else f"refused: {result.reason}", flush=True)
    else:
        print("end of input: stopping the server", flush=True)
    stop.cancel()


async def _tty_lines():
    """Lines typed at a terminal, with a prompt, line editing and history (readline)."""
    import trio

    with contextlib.suppress(ImportError):
        import readline  # noqa: F401  (input() then edits lines and keeps history)
    while True:
        try:
            line = await trio.to_thread.run_sync(input, "hideseek> ", abandon_on_cancel=True)
        except EOFError:
            print(flush=True)
            return
        yield line.strip()


async def _pipe_lines():
    """Lines from a pipe or file on standard input, each at most 1024 bytes."""
    import trio

    try:
        stdin = trio.lowlevel.FdStream(os.dup(sys.stdin.fileno()))
    except (OSError, ValueError):
        return
    buf = b""
    async with stdin:
        while True:
            data = await stdin.receive_some(1024)
            if not data:
                if buf.strip():
                    yield buf.decode("utf-8", "replace").strip()
                return
            buf += data
            *lines, buf = buf.split(b"\n")
            buf = buf[-1024:]
            for raw in lines:
                yield raw.decode("utf-8", "replace").strip()
