"""``hideseek serve``: run the game server for real rovers, log events as plain text.

Rovers attach over TCP (``--rover ID=tcp``: they connect to ``--listen
tcpin:HOST:PORT``; ``--rover ID=tcp:HOST:PORT``: the server connects to a rover
listening there), UDP (``--rover ID=udp``: they send datagrams to ``--listen
udpin:HOST:PORT``), serial (``--rover ID=serial:PORT,BAUD``; a
``/dev/serial/by-id/...`` name survives a renumbered adapter) or are simulated
in this process (``--rover ROLE=sim``: the ``--scenario`` room, in real time,
in-memory link). Link strings mean what they mean in MAVProxy
(`server.links.spec`).
Only the ids given with ``--rover`` may say hello over TCP, UDP or serial, unless
``--open-enrolment``; beyond loopback every such id needs a ``--token``.

The server plays on the database's newest game when it is unfinished (a
server stopped or killed mid-game resumes it; rovers reconnect and resync);
``--fresh-game`` starts a new one instead.

Operator commands are read from standard input, one per line (a prompt with
line editing and history when it is a terminal; `tui.serve_console`)::

    start_mapping | stop_mapping | new_game | status | help | quit
    hide X Y [HEADING] [room|map]      (cm, deg; map frame unless "room")
    seek X Y [HEADING] [room|map] [within=CM]
    fault ROVER/TARGET KIND [DURATION] [NAME=VALUE ...]
    clear ROVER/TARGET [KIND]

``fault`` breaks a rover: an attached one over the protocol (its advertised
faults, ``status`` lists them) or its link (target ``link``: loss, corrupt,
latency, down, applied by this server); a simulated one in its world or
runtime. ROVER is a rover id or the role it plays.

End of input (Ctrl-D) or ``quit`` stops the server as Ctrl-C does: the game
is kept, to be resumed by the next start. ``--no-console`` ignores standard
input (a server run unattended).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from typing import TYPE_CHECKING

from server.links.spec import LISTEN, SERVE_ROVER
from server.protocol import ROLES

if TYPE_CHECKING:
    from server.links.spec import LinkSpec

__all__ = ["add_arguments", "run", "parse_assignment", "parse_origin", "parse_listens",
           "check_listen", "DEFAULT_LISTEN", "DEFAULT_UDP_LISTEN"]

DEFAULT_LISTEN = "tcp:127.0.0.1:7878"
"""Where ``serve`` listens without ``--listen``."""
DEFAULT_UDP_LISTEN = "udp:127.0.0.1:7878"
"""... and for rovers on ``udp`` (``--rover ID=udp``)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", action="append", metavar="tcpin:HOST:PORT|udpin:HOST:PORT",
                        help=f"where rovers connect over TCP, or send over UDP: {LISTEN.forms} "
                             f"(repeatable; default {DEFAULT_LISTEN}, and {DEFAULT_UDP_LISTEN} "
                             f"with a rover on udp)")
    parser.add_argument("--rover", action="append", default=[], metavar="ID=LINK",
                        help=f"a rover and its link: {SERVE_ROVER.forms} (repeatable); only "
                             "these ids may say hello over TCP, UDP or serial")
    parser.add_argument("--db", default="hideseek.db", metavar="FILE",
                        help="SQLite database for games, maps and events (default %(default)s)")
    parser.add_argument("--token", action="append", default=[], metavar="[ID=]TOKEN",
                        help="token rovers must give in hello; ID=TOKEN for one rover "
                             "(repeatable). Beyond loopback every accepted id needs one")
    parser.add_argument("--open-enrolment", action="store_true",
                        help="welcome any rover id over TCP and serial, not only the --rover "
                             "ids (tokens still apply)")
    parser.add_argument("--fresh-game", action="store_true",
                        help="start a new game even when the database's newest game is "
                             "unfinished (by default it is resumed)")
    parser.add_argument("--max-connections", type=int, default=64, metavar="N",
                        help="TCP connections and UDP peers held at once at most (default "
                             "%(default)s)")
    parser.add_argument("--no-console", action="store_true",
                        help="ignore standard input (no operator commands; stop with a signal)")
    parser.add_argument("--origin", action="append", default=[], metavar="ID=X,Y,HEADING",
                        help="a rover's start pose in the room frame [cm, cm, deg] (repeatable)")
    parser.add_argument("--scenario", default="furniture", metavar="NAME|FILE",
                        help="the room of simulated rovers (--rover ROLE=sim) and the start "
                             "poses used as their origins (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=1,
                        help="seed of the simulated rovers' world (default 1)")
    parser.add_argument("--speed", type=float, default=1.0, metavar="N",
                        help="clock rate: 1 is real time (default); rovers over links must "
                             "run at the same rate (hideseek rover --speed N)")


def parse_assignment(text: str, what: str) -> tuple[str, str]:
    """``ID=VALUE`` -> (id, value). Raises ValueError naming ``what``."""
    key, sep, value = text.partition("=")
    if not sep or not key or not value:
        raise ValueError(f"{what} must be ID=VALUE, got {text!r}")
    return key.strip(), value.strip()


def parse_listens(texts: list[str]) -> list[tuple[str, LinkSpec]]:
    """``--listen`` values -> [(``tcp`` or ``udp``, address)]; ``none`` alone: no listening.

    Raises:
        ValueError: a value `LISTEN` does not take, or ``none`` beside an address.
    """
    from server.links.spec import parse_link_for

    if texts == ["none"]:
        return []
    out = []
    for text in texts:
        if text == "none":
            raise ValueError(f"--listen must be {LISTEN.forms}, got 'none' beside an address")
        spec = parse_link_for(text, LISTEN)
        out.append((spec.kind[:3], spec))
    return out


def parse_origin(text: str):
    """``ID=X,Y,HEADING`` -> (id, Pose)."""
    from server.protocol import Pose

    rid, value = parse_assignment(text, "--origin")
    parts = value.split(",")
    try:
        x, y, h = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"--origin must be ID=X,Y,HEADING with numbers, got {text!r}") from None
    return rid, Pose(x, y, h)


def run(args: argparse.Namespace) -> int:
    from server.store import Store, StoreError
    from tui.stopping import is_interrupt, leaves

    try:
        tokens = _tokens(args.token)
        origins = dict(parse_origin(o) for o in args.origin)
        rovers, listens, sim_roles = _links(args)
        config, scenario = _config(args, tokens, origins, rovers, listens, sim_roles)
        for proto, listen in listens:  # before the store: a refusal leaves the database as it was
            check_listen(proto, listen.host, listen.port)
        store = Store(args.db)
    except (ValueError, StoreError, OSError) as exc:
        print(f"hideseek serve: {exc}", file=sys.stderr)
        return 2

    from actors import running, scaled_clock

    sim = (scenario, args.seed, tuple(sim_roles)) if sim_roles else None
    clock = None if args.speed == 1.0 else scaled_clock(args.speed)
    try:
        running.run(_serve, store, config, listens, rovers, sim, not args.no_console,
                    clock=clock)
    except (OSError, ValueError, BaseExceptionGroup) as exc:
        leaf = leaves(exc)[0]
        if is_interrupt(exc) or not isinstance(leaf, OSError | ValueError):
            raise  # a stop by signal: tui.cli prints its one line
        print(f"hideseek serve: {getattr(leaf, 'strerror', None) or leaf}", file=sys.stderr)
        return 1
    finally:
        store.close()
    return 0


def _links(args: argparse.Namespace) -> tuple[list[tuple[str, LinkSpec]],
                                              list[tuple[str, LinkSpec]], list[str]]:
    """The rovers' links, where the server listens and the simulated roles, from the
    options: ``(rovers, listens, sim_roles)``.

    Raises:
        ValueError: a bad ``--rover``, ``--listen``, ``--speed`` or ``--max-connections``,
            a simulated rover's id that is no role or given twice, or a rover on a link
            no ``--listen`` serves.
    """
    from server.links.spec import parse_link_for

    rovers = [(rid, parse_link_for(link, SERVE_ROVER)) for rid, link in
              (parse_assignment(r, "--rover") for r in args.rover)]
    listens = parse_listens(args.listen or [DEFAULT_LISTEN])
    if not 0 < args.speed <= 1000:
        raise ValueError(f"--speed must be within 0..1000, got {args.speed:g}")
    if args.max_connections < 1:
        raise ValueError(f"--max-connections must be at least 1, got {args.max_connections}")
    sim_roles: list[str] = []
    for rid, spec in rovers:
        if spec.kind == "sim":
            if rid not in ROLES:
                raise ValueError(f"--rover {rid}=sim: a simulated rover's ID is its role, "
                                 f"one of {', '.join(ROLES)}")
            if rid in sim_roles:
                raise ValueError(f"--rover {rid}=sim given twice")
            sim_roles.append(rid)
    if args.listen is None and any(spec.kind == "udp" for _, spec in rovers):
        listens += parse_listens([DEFAULT_UDP_LISTEN])
    for kind in ("tcp", "udp"):
        if any(spec.kind == kind for _, spec in rovers) and not any(
                proto == kind for proto, _ in listens):
            raise ValueError(f"a rover on {kind} needs --listen {kind}:HOST:PORT")
    return rovers, listens, sim_roles


def _tokens(texts: list[str]) -> dict[str, str]:
    """``--token`` values -> {rover id or ``*`` (any rover): token}."""
    tokens: dict[str, str] = {}
    for t in texts:
        if "=" in t:
            rid, tok = parse_assignment(t, "--token")
            tokens[rid] = tok
        else:
            tokens["*"] = t
    return tokens


def _config(args: argparse.Namespace, tokens: dict[str, str], origins: dict,
            rovers: list[tuple[str, LinkSpec]], listens: list[tuple[str, LinkSpec]],
            sim_roles: list[str]):
    """The server's `ServerConfig` from the options, and the simulated rovers' scenario
    (None without any): ``(config, scenario)``.

    Raises:
        ValueError: a listening address beyond loopback the trust rules refuse, or a
            scenario that does not load.
    """
    from server.config import ServerConfig
    from server.links import is_loopback
    from server.trust import beyond_loopback_refusal

    config = ServerConfig(
        tokens=tokens, origins=origins,
        rovers=frozenset(rid for rid, spec in rovers if spec.kind != "sim"),
        open_enrolment=args.open_enrolment, simulated=tuple(sim_roles),
        max_connections=args.max_connections, resume=not args.fresh_game)
    for _, listen in listens:
        if not is_loopback(listen.host):
            refusal = beyond_loopback_refusal(listen.host, config)
            if refusal:
                raise ValueError(refusal)
    scenario = None
    if sim_roles:
        from supervisors.system import scenario_origins
        from world.scenario import ScenarioError, load_scenario

        try:
            scenario = load_scenario(args.scenario)
        except ScenarioError as exc:
            raise ValueError(str(exc)) from None
        config = _with_origins(config, {**scenario_origins(scenario), **origins})
    return config, scenario


def check_listen(proto: str, host: str, port: int) -> None:
    """Bind (and for TCP listen on) every address ``host:port`` resolves to, as the server
    will, and let go at once.

    Raises:
        ValueError: an address that is busy, not this machine's, or does not resolve:
            one line naming ``HOST:PORT`` and why.
    """
    import socket

    where = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    kind = socket.SOCK_STREAM if proto == "tcp" else socket.SOCK_DGRAM
    try:
        infos = socket.getaddrinfo(host or None, port, type=kind, flags=socket.AI_PASSIVE)
        for family, type_, proto_num, _, address in infos:
            with socket.socket(family, type_, proto_num) as sock:
                if kind == socket.SOCK_STREAM:  # as Trio's listeners: a port in TIME_WAIT is free
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                sock.bind(address)
                if kind == socket.SOCK_STREAM:
                    sock.listen(1)
    except OSError as exc:
        raise ValueError(f"cannot listen on {proto} {where}: {exc.strerror or exc}") from None


def _with_origins(config, origins):
    import dataclasses

    return dataclasses.replace(config, origins=origins)


def _banner(server, store) -> list[str]:
    """What the operator reads first: which game is played, and who may join."""
    lines = []
    if server.resumed is not None:
        game = store.game(server.resumed)
        how = ("killed or crashed" if server.resumed in store.interrupted
               else "stopped")
        lines.append(f"resuming game {game.id} in phase {game.phase} (its server {how}); "
                     "rovers reconnect and resync. --fresh-game starts a new one")
    else:
        lines.append(f"game {server.game_id}: new")
    cfg = server.config
    if cfg.open_enrolment:
        lines.append("open enrolment: any rover id may say hello")
    elif cfg.rovers:
        lines.append(f"rovers accepted over tcp/udp/serial: {', '.join(sorted(cfg.rovers))}")
    else:
        lines.append("no rover ids given (--rover ID=tcp|udp|serial:...): rovers from outside "
                     "are refused; --open-enrolment welcomes any id")
    return lines


async def _serve(store, config, listens, rovers, sim=None, console: bool = True) -> None:
    import trio

    from server.server import open_server
    from tui.serve_console import run_console

    sim_system = None
    async with open_server(store, config) as server, contextlib.AsyncExitStack() as stack:
        for line in _banner(server, store):
            print(line, flush=True)
        if sim is not None:
            from supervisors.system import open_sim_system

            scenario, seed, roles = sim
            sim_system = await stack.enter_async_context(open_sim_system(
                scenario, seed=seed, store=store, roles=roles, server=server))
            print(f"simulated in this process ({scenario.name}, seed {seed}): "
                  f"{', '.join(roles)}", flush=True)
        events = server.subscribe()
        for proto, listen in listens:
            start = server.listen_tcp if proto == "tcp" else server.listen_udp
            port = await start(listen.host, listen.port)
            print(f"listening on {proto}:{listen.host}:{port}", flush=True)
        for rid, spec in rovers:
            if spec.kind == "serial":
                server.start_serial(spec.url, spec.baud)
                print(f"rover {rid}: serial {spec.url} at {spec.baud} baud", flush=True)
            elif spec.kind == "tcp_out":  # a rover listening: the serial loop connects out
                server.start_serial(spec.url, spec.baud)
                print(f"rover {rid}: connecting to {spec.host}:{spec.port}", flush=True)
        if console:
            print("commands: start_mapping, stop_mapping, hide X Y [H] [room], seek X Y [H] "
                  "[room] [within=CM], fault ROVER/TARGET KIND [S] [NAME=V], clear "
                  "ROVER/TARGET, new_game, status, help, quit", flush=True)
        t0 = trio.current_time()
        async with trio.open_nursery() as nursery:
            if console:
                nursery.start_soon(run_console, server, nursery.cancel_scope, sim_system)
            async for event in events:
                if event.kind != "pose":
                    print(event.format(t0), flush=True)
