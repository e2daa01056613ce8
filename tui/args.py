"""Option values the commands share, checked where they are parsed.

Each function is an ``argparse`` ``type=``: a bad value becomes one line naming
the option's value and the rule (``hideseek run: argument --seed: ...``) and exit
status 2, before anything starts.
"""

from __future__ import annotations

import argparse
import os
import pathlib

__all__ = ["seed", "positive_seconds", "sqlite_file"]

_SEED_MAX = 2**32 - 1


def seed(text: str) -> int:
    """A run's seed: an integer within 0..2**32-1 (numpy's and Trio's generators take it).

    Raises:
        argparse.ArgumentTypeError: not such an integer.
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if not 0 <= value <= _SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be within 0..{_SEED_MAX}, got {value}")
    return value


def positive_seconds(text: str) -> float:
    """A duration [s] > 0.

    Raises:
        argparse.ArgumentTypeError: not a finite number > 0.
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be > 0 s, got {text!r}")
    return value


def sqlite_file(text: str) -> str:
    """A SQLite file to open or create (``:memory:`` for none): its folder must exist and
    be writable, and it must not be a folder itself.

    Raises:
        argparse.ArgumentTypeError: the file cannot be made there.
    """
    if text == ":memory:":
        return text
    path = pathlib.Path(text).expanduser()
    folder = path.parent
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory, not a file")
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"cannot create {text}: no directory {folder}")
    if path.exists() and not os.access(path, os.W_OK):
        raise argparse.ArgumentTypeError(f"cannot write {text}: permission denied")
    if not path.exists() and not os.access(folder, os.W_OK):
        raise argparse.ArgumentTypeError(f"cannot create {text}: {folder} is not writable")
    return str(path)
