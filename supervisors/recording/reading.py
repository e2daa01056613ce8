"""Read a hideseek recording back: its metadata and its messages, decoded.

`read_recording` loads a whole file (a furniture game is a few MB) into a
`Recording`: the run's `RunInfo`, the scenario text, the summary written at
the end, each channel's schema name and its messages in log-time order as
``(t [s], decoded JSON)``. The console's replay and the fork read files
through it; anyone else can use the ``mcap`` library directly
(docs/recording.md).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Any

import msgspec
from mcap.exceptions import McapError
from mcap.reader import make_reader

from .runinfo import RunInfo

__all__ = ["Recording", "read_recording", "RecordingReadError"]


class RecordingReadError(ValueError):
    """Raised by `read_recording` when a file is missing, not MCAP, or not a hideseek recording."""


@dataclass
class Recording:
    """A recording in memory (see the module docstring)."""

    path: str
    run: RunInfo
    """How the game was made (the ``hideseek.run`` record)."""
    scenario_toml: str
    """The scenario file's text ("" for generated and campaign rooms)."""
    summary: dict[str, str]
    """The ``hideseek.summary`` record: the game's report fields and the channel counts
    (empty when the recording was cut short)."""
    queues: dict[str, int] = field(default_factory=dict)
    """Mailbox -> capacity [messages] (the ``hideseek.queues`` record)."""
    schemas: dict[str, str] = field(default_factory=dict)
    """Topic -> schema name."""
    messages: dict[str, list[tuple[float, Any]]] = field(default_factory=dict)
    """Topic -> [(t [s], message)], oldest first (topics asked for only)."""
    start_s: float = 0.0
    """Time of the first message [s]."""
    end_s: float = 0.0
    """Time of the last message [s]."""

    def topic(self, name: str) -> list[tuple[float, Any]]:
        """The messages of a topic ([] when none, or not read)."""
        return self.messages.get(name, [])


def read_recording(path: str | os.PathLike[str], topics: Collection[str] | None = None
                   ) -> Recording:
    """Read a recording (``topics``: only these channels' messages; None: all).

    Raises:
        RecordingReadError: the file cannot be read, is not MCAP, or has no
            ``hideseek.run`` metadata.
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            summary = reader.get_summary()
            if "hideseek.run" not in meta:
                raise RecordingReadError(f"{path}: not a hideseek recording "
                                         "(no hideseek.run metadata)")
            run = RunInfo.from_metadata(meta["hideseek.run"],
                                        meta.get("hideseek.scenario", {}).get("toml", ""))
            rec = Recording(path, run, meta.get("hideseek.scenario", {}).get("toml", ""),
                            meta.get("hideseek.summary", {}),
                            {k: int(v) for k, v in meta.get("hideseek.queues", {}).items()})
            if summary is not None:
                for ch in summary.channels.values():
                    schema = summary.schemas.get(ch.schema_id)
                    rec.schemas[ch.topic] = schema.name if schema is not None else ""
                stats = summary.statistics
                if stats is not None and stats.message_count:
                    rec.start_s = stats.message_start_time / 1e9
                    rec.end_s = stats.message_end_time / 1e9
            decode = msgspec.json.decode
            wanted = None if topics is None else list(topics)
            for _schema, channel, message in reader.iter_messages(topics=wanted,
                                                                  log_time_order=True):
                rec.messages.setdefault(channel.topic, []).append(
                    (message.log_time / 1e9, decode(message.data)))
    except OSError as exc:
        raise RecordingReadError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (McapError, msgspec.DecodeError, ValueError, KeyError, EOFError, struct.error) as exc:
        if isinstance(exc, RecordingReadError):
            raise
        raise RecordingReadError(f"{path}: not a readable recording: {exc}") from None
    return rec
