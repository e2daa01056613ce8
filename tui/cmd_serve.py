"""``hideseek serve``: run the game server for real rovers, log events as plain text.

Rovers attach over TCP (``--rover ID=tcp``: they connect to ``--listen``),
serial (``--rover ID=serial:PORT,BAUD``) or are simulated in this process
(``--rover ROLE=sim``: the ``--scenario`` room, in real time, in-memory link).

Operator commands are read from standard input, one per line::

    start_mapping | stop_mapping | new_game | status
    hide X Y [HEADING] [room|map]      (cm, deg; map frame unless "room")
    seek X Y [HEADING] [room|map]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

from server.protocol import ROLES

__all__ = ["add_arguments", "run", "parse_assignment", "parse_origin", "parse_command_line"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", default="tcp:127.0.0.1:7878", metavar="tcp:HOST:PORT",
                        help="where rovers connect over TCP (default %(default)s); 'none' to "
                             "not listen")
    parser.add_argument("--rover", action="append", default=[], metavar="ID=LINK",
                        help="a rover and its link: serial:PORT,BAUD, tcp or sim (repeatable)")
    parser.add_argument("--db", default="hideseek.db", metavar="FILE",
                        help="SQLite database for games, maps and events (default %(default)s)")
    parser.add_argument("--token", action="append", default=[], metavar="[ID=]TOKEN",
                        help="token rovers must give in hello; ID=TOKEN for one rover "
                             "(repeatable). Required to listen on a non-loopback address")
    parser.add_argument("--origin", action="append", default=[], metavar="ID=X,Y,HEADING",
                        help="a rover's start pose in the room frame [cm, cm, deg] (repeatable)")
    parser.add_argument("--scenario", default="furniture", metavar="NAME|FILE",
                        help="the room of simulated rovers (--rover ROLE=sim) and the start "
                             "poses used as their origins (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=1,
                        help="seed of the simulated rovers' world (default 1)")


def parse_assignment(text: str, what: str) -> tuple[str, str]:
    """``ID=VALUE`` -> (id, value). Raises ValueError naming ``what``."""
    key, sep, value = text.partition("=")
    if not sep or not key or not value:
        raise ValueError(f"{what} must be ID=VALUE, got {text!r}")
    return key.strip(), value.strip()


def parse_origin(text: str):
    """``ID=X,Y,HEADING`` -> (id, Pose2)."""
    from server.protocol import Pose2

    rid, value = parse_assignment(text, "--origin")
    parts = value.split(",")
    try:
        x, y, h = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"--origin must be ID=X,Y,HEADING with numbers, got {text!r}") from None
    return rid, Pose2(x, y, h)


def parse_command_line(line: str) -> tuple[str, dict]:
    """An operator line -> (command, kwargs). Raises ValueError with usage."""
    words = line.split()
    if not words:
        raise ValueError("empty command")
    name, rest = words[0], words[1:]
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
    if rest:
        raise ValueError(f"{name} takes no arguments")
    return name, {}


def run(args: argparse.Namespace) -> int:
    from server.links import is_loopback, parse_link
    from server.server import ServerConfig
    from server.store import Store, StoreError

    try:
        tokens: dict[str, str] = {}
        for t in args.token:
            if "=" in t:
                rid, tok = parse_assignment(t, "--token")
                tokens[rid] = tok
            else:
                tokens["*"] = t
        origins = dict(parse_origin(o) for o in args.origin)
        rovers = [(rid, parse_link(link)) for rid, link in
                  (parse_assignment(r, "--rover") for r in args.rover)]
        listen = None if args.listen == "none" else parse_link(args.listen)
        if listen is not None and listen.kind != "tcp_listen":
            raise ValueError(f"--listen must be tcp:HOST:PORT or none, got {args.listen!r}")
        if listen is not None and not is_loopback(listen.host) and not tokens:
            raise ValueError(f"refusing to listen on {listen.host}: not loopback and no rover "
                             "tokens (give --token)")
        sim_roles: list[str] = []
        for rid, spec in rovers:
            if spec.kind == "sim":
                if rid not in ROLES:
                    raise ValueError(f"--rover {rid}=sim: a simulated rover's ID is its role, "
                                     f"one of {', '.join(ROLES)}")
                if rid in sim_roles:
                    raise ValueError(f"--rover {rid}=sim given twice")
                sim_roles.append(rid)
            elif spec.kind not in ("serial", "tcp"):
                raise ValueError(f"--rover {rid}: a rover's link is serial:PORT,BAUD, tcp or sim")
        if any(spec.kind == "tcp" for _, spec in rovers) and listen is None:
            raise ValueError("a rover on tcp needs --listen")
        scenario = None
        if sim_roles:
            from supervisors.system import scenario_origins
            from world.scenario import ScenarioError, load_scenario

            try:
                scenario = load_scenario(args.scenario)
            except ScenarioError as exc:
                raise ValueError(str(exc)) from None
            origins = {**scenario_origins(scenario), **origins}
        store = Store(args.db)
    except (ValueError, StoreError, OSError) as exc:
        print(f"hideseek serve: {exc}", file=sys.stderr)
        return 2
    import trio

    config = ServerConfig(tokens=tokens, origins=origins)
    sim = (scenario, args.seed, tuple(sim_roles)) if sim_roles else None
    try:
        trio.run(_serve, store, config, listen, rovers, sim)
    except KeyboardInterrupt:
        return 0
    except (OSError, ValueError, BaseExceptionGroup) as exc:
        leaf = _first_leaf(exc)
        if isinstance(leaf, KeyboardInterrupt):
            return 0
        if not isinstance(leaf, OSError | ValueError):
            raise
        print(f"hideseek serve: {getattr(leaf, 'strerror', None) or leaf}", file=sys.stderr)
        return 1
    finally:
        store.close()
    return 0


def _first_leaf(exc: BaseException) -> BaseException:
    while isinstance(exc, BaseExceptionGroup):
        exc = exc.exceptions[0]
    return exc


async def _serve(store, config, listen, rovers, sim=None) -> None:
    import trio

    from server.server import open_server

    if store.interrupted:
        print(f"games interrupted by an earlier crash: {store.interrupted}", flush=True)
    async with open_server(store, config) as server, contextlib.AsyncExitStack() as stack:
        if sim is not None:
            from supervisors.system import open_sim_system

            scenario, seed, roles = sim
            await stack.enter_async_context(open_sim_system(
                scenario, seed=seed, store=store, roles=roles, server=server))
            print(f"simulated in this process ({scenario.name}, seed {seed}): "
                  f"{', '.join(roles)}", flush=True)
        events = server.subscribe()
        if listen is not None:
            port = await server.listen_tcp(listen.host, listen.port)
            print(f"listening on tcp:{listen.host}:{port}", flush=True)
        for rid, spec in rovers:
            if spec.kind == "serial":
                server.start_serial(spec.url, spec.baud)
                print(f"rover {rid}: serial {spec.url} at {spec.baud} baud", flush=True)
        print("commands: start_mapping, stop_mapping, hide X Y [H] [room], seek X Y [H] "
              "[room], new_game, status", flush=True)
        t0 = trio.current_time()
        async with trio.open_nursery() as nursery:
            nursery.start_soon(_read_commands, server)
            async for event in events:
                if event.kind != "pose":
                    print(event.format(t0), flush=True)


async def _read_commands(server) -> None:
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
                return
            buf += data
            *lines, buf = buf.split(b"\n")
            buf = buf[-1024:]
            for raw in lines:
                line = raw.decode("utf-8", "replace").strip()
                if not line:
                    continue
                if line == "status":
                    s = server.snapshot()
                    print(f"game {s.game_id} phase {s.phase} {s.reason}", flush=True)
                    for r in s.rovers:
                        st = r.stats
                        print(f"  {r.id} {r.role} {r.link} up={st.up} in={st.frames_in} "
                              f"out={st.frames_out} lost={st.lost} resent={st.resent} "
                              f"bad={st.bad_frames} rtt={st.rtt_s}", flush=True)
                    continue
                try:
                    name, kw = parse_command_line(line)
                except ValueError as exc:
                    print(f"? {exc}", flush=True)
                    continue
                result = await server.command(name, **kw)
                print("ok" if result.ok else f"refused: {result.reason}", flush=True)
