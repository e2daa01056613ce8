"""``hideseek maps`` lists stored games and maps; ``hideseek export-map GAME`` exports one.

Both subcommands live here; `add_arguments` tells them apart by the parser's name.
Both open the database read-only, so they are safe on a live server's file and
never change a game it plays. ``export-map GAME`` writes the map the game
played on (the last upload it accepted); uploads the game ignored are listed
apart by ``maps`` and can be exported with ``--map ID``.
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
        parser.add_argument("--map", type=int, default=None, metavar="ID", dest="map_id",
                            help="export this stored map of the game instead of the one it "
                                 "played on (see 'maps')")
        parser.add_argument("--format", choices=("pgm", "png"), default="pgm",
                            help="pgm (+ map_server YAML) or png (default %(default)s)")
        parser.add_argument("--scale", type=int, default=None, metavar="N",
                            help="png: pixels per cell edge, 1..32 (default 5: 1 px per cm "
                                 "at 5 cm cells, a 4 x 3 m room 430 px wide)")
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
        store = Store(args.db, readonly=True)
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
    print(f"{'game':>5} {'status':<12} {'phase':<10} {'map':>5} {'maps':>4}  outcome")
    for g in games:
        n = sum(m.game_id == g.id for m in maps)
        played = g.map_id if g.map_id is not None else "-"
        print(f"{g.id:>5} {g.status:<12} {g.phase:<10} {played:>5} {n:>4}  {g.outcome}")
    print()
    played_ids = {g.map_id for g in games}
    print(f"{'map':>5} {'game':>5} {'size [cells]':>12} {'res [cm]':>8}  {'origin [cm]':<16} use")
    for m in maps:
        use = ("played" if m.id in played_ids else "replaced" if m.accepted
               else f"ignored: {m.note}")
        print(f"{m.id:>5} {m.game_id if m.game_id is not None else '-':>5} "
              f"{f'{m.nx}x{m.ny}':>12} {m.resolution_cm:>8g}  "
              f"{f'({m.origin_cm[0]:g}, {m.origin_cm[1]:g})':<16} {use}")
    return 0


def _export(store, args) -> int:
    from server.export import write_pgm
    from server.store import StoreError
    from tui.pictures.map_image import DEFAULT_SCALE, MAX_SCALE, export_png

    scale = DEFAULT_SCALE if args.scale is None else args.scale
    try:
        if args.scale is not None and args.format != "png":
            raise ValueError("--scale goes with --format png")
        if not 1 <= scale <= MAX_SCALE:
            raise ValueError(f"--scale must be within 1..{MAX_SCALE}, got {scale}")
        if args.map_id is None:
            map_id = store.game_map_id(args.game)
        else:
            map_id = args.map_id
            owner = next((m.game_id for m in store.maps() if m.id == map_id), None)
            if owner != args.game:
                raise StoreError(f"map {map_id} is not one of game {args.game}'s "
                                 "(see 'hideseek maps')")
        grid = store.load_map(map_id)
    except (StoreError, ValueError) as exc:
        print(f"hideseek export-map: {exc}", file=sys.stderr)
        return 2
    name = f"game{args.game}" if args.map_id is None else f"game{args.game}-map{map_id}"
    try:
        if args.format == "pgm":
            paths = write_pgm(grid, args.out, name)
        else:
            paths = (export_png(grid, args.out, name, scale=scale),)
    except OSError as exc:
        print(f"hideseek export-map: cannot write to {args.out}: {exc.strerror}", file=sys.stderr)
        return 1
    for p in paths:
        print(p)
    return 0
