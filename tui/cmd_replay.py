"""``hideseek replay FILE.mcap``: open a recording in the console (nothing is simulated).

``F`` in the replay forks the game at the time shown: the replay closes, the
recorded game is played again to that time (checked against the recording),
and the live console opens there with the fault dialog. Exit status: 0, or 1
when the forked system stopped with an error, 2 bad input, 3 the fork left its
recording before its time.

Textual is imported only when the command runs.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from tui import stopping

if TYPE_CHECKING:
    from supervisors.recording.reading import Recording


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
        rec = read_recording(args.file)
        if args.at is not None and not rec.start_s <= args.at <= rec.end_s:
            raise ValueError(f"--at must be within the recording, {rec.start_s:.1f} to "
                             f"{rec.end_s:.1f} s, got {args.at:g}")
        system = ReplaySystem(rec, speed=float(args.speed), paused=args.paused, at=args.at)
    except (RecordingReadError, ValueError) as exc:
        print(f"hideseek replay: {exc}", file=sys.stderr)
        return 2
    app = ReplayApp(system)
    app.run()
    if app.stopped_by_signal:
        print(stopping.stopped_line("replay"), file=sys.stderr)
        return 0
    if app.fork_at is None:
        return 0
    return _fork(system.rec, app.fork_at)


def _fork(rec: Recording, at_s: float) -> int:
    """The live console on the game forked at ``at_s``."""
    from supervisors.recording.fork import ForkDiverged, ForkError
    from tui.replay.fork_live import ForkConsoleApp, ForkLiveSystem
    from world.scenario import ScenarioError

    try:
        system = ForkLiveSystem(rec, at_s)
    except (ForkError, ScenarioError) as exc:
        print(f"hideseek replay: {exc}", file=sys.stderr)
        return 2
    app = ForkConsoleApp(system)
    app.run()
    if app.stopped_by_signal:
        print(stopping.stopped_line("replay"), file=sys.stderr)
        return 0
    error = app.system_error
    if error is None:
        return 0
    print(f"hideseek replay: the forked system stopped: {type(error).__name__}: {error}",
          file=sys.stderr)
    return 3 if isinstance(error, ForkDiverged) else 1
