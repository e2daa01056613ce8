"""``hideseek replay FILE.mcap``: open a recording in the console (nothing is simulated).

Textual is imported only when the command runs.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE.mcap", help="a recording (hideseek run --record)")
    parser.add_argument("--at", type=float, default=None, metavar="T",
                        help="start at simulated time T [s] (default: the beginning)")
    parser.add_argument("--speed", choices=["1", "4", "16", "64"], default="1",
                        help="initial replay speed (default: %(default)s)")
    parser.add_argument("--paused", action="store_true", help="start paused")


def run(args: argparse.Namespace) -> int:
    from supervisors.recording.reading import RecordingReadError, read_recording
    from tui.replay.app import ReplayApp
    from tui.replay.system import ReplaySystem

    try:
        system = ReplaySystem(read_recording(args.file), speed=float(args.speed),
                              paused=args.paused, at=args.at)
    except RecordingReadError as exc:
        print(f"hideseek replay: {exc}", file=sys.stderr)
        return 2
    app = ReplayApp(system)
    app.run()
    return 0
