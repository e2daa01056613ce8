"""Who may say hello: the identity rules of docs/protocol.md section 4, as pure functions.

`admit` decides one ``hello`` from the facts the server knows about the link
and about the session the id already has; it reads no clock and changes
nothing, so every rule is testable alone. Tokens are compared with
`hmac.compare_digest` (constant time), once per hello. The server counts
refusals, closes links and blocks addresses (`server.guard`); a blocked
address's hellos are refused unless they prove a token, so failures from an
address a rover shares (NAT, a serial-to-TCP bridge) cannot lock it out.
"""

from __future__ import annotations

import hmac
from dataclasses import dataclass

from .config import ServerConfig
from .links.spec import is_loopback
from .protocol import Fault, FrameError, Hello

__all__ = ["Held", "admit", "ids_without_token", "beyond_loopback_refusal"]


@dataclass(frozen=True, slots=True)
class Held:
    """The link that the hello's id is bound to now."""

    other_link: bool
    """It is another link than the one the hello came on."""
    trusted_link: bool
    """It is a memory link (a simulated rover of this process)."""
    live: bool
    """The rover was heard on it within ``down_after_s``."""


def admit(hello: Hello, config: ServerConfig, *, trusted: bool, peer: str | None,
          bound_id: str | None, blocked_s: float, held: Held | None,
          sim_roles: set[str]) -> tuple[FrameError | None, bool]:
    """Whether ``hello`` may bind its link to its id: (refusal or None, proved by token).

    Args:
        trusted: the hello came on a memory link.
        peer: the TCP peer address, None for other links.
        bound_id: the id the link already speaks for, None before its first hello.
        blocked_s: how long the peer address stays blocked after failed hellos [s]; a
            hello with its id's token is admitted all the same.
        held: the link the id is bound to now, None when it has none.
        sim_roles: roles played by simulated rovers.
    """
    rid = hello.id
    if bound_id is not None and bound_id != rid:
        return FrameError(Fault.NOT_ALLOWED, f"this link speaks for {bound_id!r}; "
                          "one rover id per link"), False
    want = None if trusted else config.tokens.get(rid, config.tokens.get("*"))
    proved = want is not None and hmac.compare_digest((hello.token or "").encode(),
                                                      want.encode())
    if blocked_s > 0 and not proved:  # a backoff slows guessing; a right token is no guess
        return FrameError(Fault.AUTH, f"too many failed hellos from {peer}; "
                          f"try again in {blocked_s:.0f} s"), False
    if not trusted:
        if hello.role in sim_roles:
            return FrameError(Fault.AUTH, f"role {hello.role!r} is played by a simulated "
                              "rover"), False
        if held is not None and held.trusted_link:
            return FrameError(Fault.AUTH, f"id {rid!r} is a simulated rover's"), False
        if rid not in config.rovers and not config.open_enrolment:
            return FrameError(Fault.AUTH, f"unknown rover id {rid!r}: the server was not "
                              "given it"), False
    if trusted:
        return None, False
    if want is not None:
        if not proved:
            return FrameError(Fault.AUTH, f"bad or missing token for {rid!r}"), False
    elif peer and not is_loopback(peer):
        return FrameError(Fault.AUTH, f"{rid!r} has no token and this link is not "
                          "loopback"), False
    if held is not None and held.other_link and held.live and not proved:
        return FrameError(Fault.AUTH, f"{rid!r} is live on another link; without a token "
                          f"a new link may take over after {config.down_after_s:g} s of "
                          "silence"), False
    return None, proved


def ids_without_token(config: ServerConfig) -> str:
    """Who could say hello without a token under ``config``, in words; empty when every
    accepted id has one (the condition to listen beyond loopback)."""
    tokens = config.tokens
    if "*" in tokens:
        return ""
    if config.open_enrolment:
        return "any id (open enrolment)"
    return ", ".join(repr(m) for m in sorted(config.rovers - tokens.keys()))


def beyond_loopback_refusal(host: str, config: ServerConfig) -> str:
    """Why listening on the non-loopback ``host`` is refused under ``config`` ('' if it is not)."""
    if not config.tokens:
        return f"refusing to listen on {host}: not loopback and no rover tokens (give --token)"
    need = ids_without_token(config)
    if need:
        return (f"refusing to listen on {host}: not loopback and {need} has no token "
                "(give --token ID=TOKEN, or a shared --token)")
    return ""
