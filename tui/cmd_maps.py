"""``hideseek maps`` lists stored games and maps; ``hideseek export-map GAME`` exports one.

Both subcommands live here; `add_arguments` tells them apart by the parser's name.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--db", default="hideseek.db", metavar="FILE",
                        help="SQLite database (default %(default)s)")
    if parser.prog.endswith("export-map"):
        parser.add_argument("game", type=int, metavar="GAME", help="game id (see 'maps')")
        parser.add_argument("--format", choices=("pgm", "png"), default="pgm",
                            help="pgm (+ map_server YAML) or png (default %(default)s)")
        parser.add_argument("--out", default=".", metavar="DIR",
                            help="output directory (default: current)")
        parser.set_defaults(_maps_action="export")
    else:
        parser.set_defaults(_maps_action="list")


def run(args: argparse.Namespace) -> int:
    import os

    from server.store import Store, StoreError

    if not os.path.exists(args.db):
        print(f"hideseek: no database {args.db} (give --db FILE)", file=sys.stderr)
        return 2
    try:
        store = Store(args.db)
    except StoreError as exc:
        print(f"hideseek: {exc}", file=sys.stderr)
        return 2
    try:
        if args._maps_action == "list":
            return _list(store)
        return _export(store, args)
    finally:
        store.close()


def _list(store) -> int:
    games = store.games()
    maps = store.maps()
    print(f"{'game':>5} {'status':<12} {'phase':<10} {'maps':>4}  outcome")
    for g in games:
        n = sum(m.game_id == g.id for m in maps)
        print(f"{g.id:>5} {g.status:<12} {g.phase:<10} {n:>4}  {g.outcome}")
    print()
    print(f"{'map':>5} {'game':>5} {'size [cells]':>12} {'res [cm]':>8}  origin [cm]")
    for m in maps:
        print(f"{m.id:>5} {m.game_id if m.game_id is not None else '-':>5} "
              f"{f'{m.nx}x{m.ny}':>12} {m.resolution_cm:>8g}  "
              f"({m.origin_cm[0]:g}, {m.origin_cm[1]:g})")
    return 0


def _export(store, args) -> int:
    from server.export import write_pgm, write_png
    from server.store import StoreError

    try:
        grid = store.latest_map_of_game(args.game)
    except StoreError as exc:
        print(f"hideseek export-map: {exc}", file=sys.stderr)
        return 2
    name = f"game{args.game}"
    try:
        if args.format == "pgm":
            paths = write_pgm(grid, args.out, name)
        else:
            paths = (write_png(grid, args.out, name),)
    except OSError as exc:
        print(f"hideseek export-map: cannot write to {args.out}: {exc.strerror}", file=sys.stderr)
        return 1
    for p in paths:
        print(p)
    return 0
