"""Recording games as MCAP, reading them back, and forking them (docs/recording.md).

Layering: ``schemas`` (channels and JSON Schemas, no project imports) <-
``runinfo`` (how a run was made: world.scenario) and ``records`` (what is
written: Foxglove messages, checkpoints, game states) <- ``recorder`` (watches
a `SimSystem`, writes the file) and ``reading`` (reads a file back) <-
``fork`` (re-simulates a recording to a time, checks it, plays on with a
change) and ``play`` (one recorded headless game). Wiring, like
``supervisors.system``: it reads the world and the server.
"""

from .fork import ForkChecker, ForkDiverged, ForkError, fork_game, plan_fork
from .play import record_game
from .reading import Recording, RecordingReadError, read_recording
from .recorder import Recorder, RecordingError
from .runinfo import RunInfo, code_version
from .schemas import CHANNELS, SCHEMAS

__all__ = ["CHANNELS", "SCHEMAS", "ForkChecker", "ForkDiverged", "ForkError", "Recorder",
           "Recording", "RecordingError", "RecordingReadError", "RunInfo", "code_version",
           "fork_game", "plan_fork", "read_recording", "record_game"]
