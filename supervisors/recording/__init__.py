"""Recording games as MCAP, reading them back, and forking them.

Layering: ``schemas`` (channels and JSON Schemas, no project imports) <-
``runinfo`` (how a run was made; world.scenario) <- ``recorder`` (watches a
`SimSystem`, writes the file) and ``reading`` (reads a file back) <- ``fork``
(re-simulates a recording to a time, checks it, plays on with a change).
Wiring, like ``supervisors.system``: it reads the world and the server.
"""

from .recorder import Recorder, RecordingError
from .runinfo import RunInfo, code_version
from .schemas import CHANNELS, SCHEMAS

__all__ = ["CHANNELS", "SCHEMAS", "Recorder", "RecordingError", "RunInfo", "code_version"]
