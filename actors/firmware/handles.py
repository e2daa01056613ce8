"""Bulk data by handle: put an object in the rover's buffer pool and post its handle.

The firmware passes bulk data (bytes, scans, map snapshots, frames) as a
32-bit handle to an immutable buffer, as C firmware passes a pointer to a
static buffer. The sender puts the object in the pool and posts the handle;
when the receiving queue refuses the message the sender takes the buffer
back, so a full queue never leaks a slot. The receiver takes the handle.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from actors import BufferPool, Message, PoolExhausted

__all__ = ["post"]


def post(pool: BufferPool, send: Callable[[Message], bool], command: int, obj: Any) -> bool:
    """Put ``obj`` in ``pool`` and ``send`` a ``command`` message with its handle.

    Args:
        pool: the rover's buffer pool.
        send: a non-blocking send of one message; False when it was not queued.
        command: the message's command (a `Cmd`).
        obj: the immutable object to pass.

    Returns:
        True when sent; False when the pool had no free slot or ``send`` refused
        the message (the slot is free again).
    """
    try:
        handle = pool.put(obj)
    except PoolExhausted:
        return False
    if send(Message.handle(command, handle)):
        return True
    pool.take(handle)
    return False
