"""``hideseek replay``: a recording in the console, read from the file.

``index`` answers "what did the recording say at t", ``system`` is the
console's `tui.snapshot.System` over it (time, seek, step), ``app`` the
console with the replay's keys. Nothing is simulated.
"""

from tui.replay.index import EVENT_KINDS, ReplayIndex
from tui.replay.system import MAX_SPEED, ReplaySystem

__all__ = ["EVENT_KINDS", "MAX_SPEED", "ReplayIndex", "ReplaySystem"]
