"""Hello: binding a link to a rover's session, after the identity rules allow it.

`server.trust.admit` decides a ``hello`` from facts (pure); this part gathers
those facts from the live links and sessions, counts and answers refusals
(a link that keeps failing is closed, its address backed off), and on success
binds the link to the rover id's `ReliableSession` (kept per id, so a
reconnecting rover resumes where it left off; its ``session`` id, said in every
welcome, is new only when this server makes the session) and answers ``welcome``.
Sessions whose link is gone and that play no role are reclaimed.
"""

from __future__ import annotations

import trio

from .core import ServerCore
from .frames import MAX_MAP_CHUNKS
from .peers import Conn, Rover
from .protocol import (
    WELCOME,
    Fault,
    Frame,
    FrameError,
    Hello,
    ReliableSession,
    make_frame,
    read_data,
    session_id_for,
)
from .rover_telemetry import RoverTelemetry
from .trust import Held, admit

__all__ = ["Hellos", "PROTOCOL_NAME"]

PROTOCOL_NAME = "hideseek/1"


class Hellos(ServerCore):
    """The identity side of a `Server`: who a link speaks for."""

    def _auth_failed(self, conn: Conn, exc: FrameError, frame: Frame, rid: str) -> None:
        session = conn.rover.session if conn.rover else conn.pre
        session.send_error(exc, frame)
        conn.pre_due = conn.rover is None
        now = trio.current_time()
        self._count("auth_failed", exc.fault, conn.link, now, rid, exc.detail)
        conn.auth_failures += 1
        if conn.peer and not conn.trusted:
            self._backoff.failed(conn.peer, now)
        if conn.auth_failures >= self.config.auth_failures and not conn.trusted:
            conn.close(f"{conn.auth_failures} failed hellos")

    def _admit(self, conn: Conn, hello: Hello, now: float) -> tuple[FrameError | None, bool]:
        """`trust.admit` on this link and this server's sessions; then the session cap."""
        held = self._rovers.get(hello.id)
        facts = None
        if held is not None and held.conn is not None:
            facts = Held(other_link=held.conn is not conn, trusted_link=held.conn.trusted,
                         live=held.session.is_up(now))
        refusal, by_token = admit(
            hello, self.config, trusted=conn.trusted, peer=conn.peer,
            bound_id=conn.rover.id if conn.rover else None,
            blocked_s=self._backoff.blocked_for(conn.peer, now) if conn.peer else 0.0,
            held=facts, sim_roles=self._sim_roles)
        if refusal is None and held is None and len(self._rovers) >= self.config.max_sessions:
            self._reclaim(now, force=True)
            if len(self._rovers) >= self.config.max_sessions:
                refusal = FrameError(Fault.BUSY, "too many rover sessions; try again later")
        return refusal, by_token

    def _on_hello(self, conn: Conn, frame: Frame, now: float) -> None:
        try:
            hello: Hello = read_data(frame)
        except FrameError as exc:
            self._bad(conn, exc, frame)
            return
        refusal, _ = self._admit(conn, hello, now)
        if refusal is not None:
            self._auth_failed(conn, refusal, frame, hello.id)
            return
        if conn.peer:
            self._backoff.succeeded(conn.peer, now)
        if conn.pre_due:  # errors answered before this hello leave before the welcome
            conn.pre_due = False
            self._flush_conn(conn)
        rover = self._rovers.get(hello.id)
        if rover is None:
            rover = self._new_rover(hello.id, hello.role, now)
        old = rover.conn
        if old is not None and old is not conn:
            old.rover = None  # the old stream is stale: this one speaks for the rover
            if not old.trusted:
                old.close("another link said hello for its rover")
        if conn.trusted:
            self._sim_roles.add(hello.role)
        roles_before = dict(self._role)
        rover.role = hello.role
        rover.conn = conn
        rover.last_link = conn.link
        rover.gone_since = None
        conn.rover = rover
        self._role[hello.role] = hello.id
        origin = self.config.origins.get(hello.id, self.config.origins.get(hello.role))
        if origin is not None:
            self._start_poses[hello.role] = origin
        rover.session.reset_peer(hello.seq_base, hello.session)
        rover.session.receive(frame, now)
        welcome = {"server": PROTOCOL_NAME, "heartbeat_s": self.config.heartbeat_s,
                   "down_after_s": self.config.down_after_s,
                   "seq_base": rover.session.seq_base, "session": rover.session.session_id}
        asked = {s: v for s, v in self.config.telemetry.items() if s in (hello.streams or ())}
        if asked:  # only a rover that offers telemetry hears of it
            welcome["telemetry"] = asked
            welcome["telemetry_share"] = self.config.telemetry_share
        rover.telemetry = RoverTelemetry(tuple(asked)) if asked else None
        rover.faults = tuple(hello.faults or ())
        rover.session.send(make_frame(WELCOME, welcome))
        if rover.row is not None:
            self.store.close_rover_session(rover.row, now)
        rover.row = self.store.open_rover_session(hello.id, hello.role, conn.link, now)
        rover.stored = None
        if self._role != roles_before:
            self._save_game()
        self._emit("hello", hello.id, {"role": hello.role, "link": conn.link})

    def _new_rover(self, rid: str, role: str, now: float) -> Rover:
        rover = Rover(rid, role, ReliableSession(
            now=now, heartbeat_s=self.config.heartbeat_s, down_after_s=self.config.down_after_s,
            outbox_limit=MAX_MAP_CHUNKS, session_id=session_id_for(f"server/{rid}", now)))
        rover.gone_since = now
        self._rovers[rid] = rover
        return rover

    def _reclaim(self, now: float, *, force: bool = False) -> None:
        """Forget sessions whose link is gone and that play no role (all such when forced)."""
        playing = set(self._role.values())
        for rid, rover in list(self._rovers.items()):
            if rover.conn is None and rid not in playing and rover.gone_since is not None and (
                    force or now - rover.gone_since >= self.config.reclaim_after_s):
                del self._rovers[rid]
